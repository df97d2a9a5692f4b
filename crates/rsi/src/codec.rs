//! The RSI wire format: a streaming, allocation-free parser of the
//! controller's `<Rob>` datagrams (by element and attribute name, tolerant of
//! the variants of `docs/rsi.md`, "Protocol facts") and a writer of `<Sen>` replies into a
//! caller-owned buffer. Pure: no IO.

use crate::xml::{Token, Tokenizer, XmlError};
use thiserror::Error;

/// Largest datagram accepted (64 KiB, `docs/rsi.md`).
pub const MAX_DATAGRAM: usize = 64 * 1024;

/// A Cartesian pose or correction as KUKA sends it: `X, Y, Z` (mm),
/// `A, B, C` (degrees).
pub type Pose6 = [f64; 6];

/// The attribute names of a Cartesian pose element, in [`Pose6`] order.
pub const POSE_ATTRS: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

/// Largest plausible magnitude of a position in `RIst`/`RSol`, mm (100 m:
/// any robot, with a linear track, stays far inside it). Larger values
/// reject the datagram.
pub const MAX_POSITION_MM: f64 = 1.0e5;

/// Largest plausible magnitude of an angle in `RIst`/`RSol`, degrees.
pub const MAX_ANGLE_DEG: f64 = 360.0;

/// Largest `Delay D` accepted (the controller's late-reply count; it stops
/// RSI after its `Timeout`, which is far smaller).
pub const MAX_DELAY: u64 = u32::MAX as u64;

/// Why a datagram was rejected or a reply could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum CodecError {
    /// The datagram is empty (or only whitespace).
    #[error("empty datagram")]
    Empty,
    /// The datagram is larger than [`MAX_DATAGRAM`].
    #[error("datagram of {len} bytes exceeds the {MAX_DATAGRAM}-byte limit")]
    Oversize {
        /// Its length.
        len: usize,
    },
    /// The datagram ends before its root element is closed.
    #[error("truncated datagram at byte {at}: {what}")]
    Truncated {
        /// Byte offset.
        at: usize,
        /// What was open.
        what: &'static str,
    },
    /// Not well-formed XML.
    #[error("malformed datagram at byte {at}: {what}")]
    Syntax {
        /// Byte offset.
        at: usize,
        /// What was wrong.
        what: &'static str,
    },
    /// The root element is not `<Rob>`.
    #[error("root element at byte {at} is not <Rob>")]
    NotRob {
        /// Byte offset.
        at: usize,
    },
    /// A number that does not parse.
    #[error("bad number in <{element}> attribute {attr} at byte {at}")]
    BadNumber {
        /// The element.
        element: &'static str,
        /// The attribute.
        attr: &'static str,
        /// Byte offset of the element.
        at: usize,
    },
    /// A number that parses but lies outside the plausible range
    /// ([`MAX_POSITION_MM`], [`MAX_ANGLE_DEG`], [`MAX_DELAY`]).
    #[error("<{element}> attribute {attr} at byte {at} is out of range")]
    OutOfRange {
        /// The element.
        element: &'static str,
        /// The attribute.
        attr: &'static str,
        /// Byte offset of the element.
        at: usize,
    },
    /// An element the sensor reads (`RIst`, `RSol`, `Delay`, `IPOC`) appears
    /// twice.
    #[error("<{element}> at byte {at} appears twice")]
    Duplicate {
        /// The element.
        element: &'static str,
        /// Byte offset of the second one.
        at: usize,
    },
    /// A correction value to be written is not finite (never sent).
    #[error("correction value {index} is not finite")]
    NonFinite {
        /// Index in `X Y Z A B C`.
        index: usize,
    },
    /// A pose element lacks one of `X Y Z A B C`.
    #[error("<{element}> at byte {at} lacks attribute {attr}")]
    MissingAttribute {
        /// The element.
        element: &'static str,
        /// The missing attribute.
        attr: &'static str,
        /// Byte offset of the element.
        at: usize,
    },
    /// The `<IPOC>` element is missing.
    #[error("no <IPOC> element")]
    MissingIpoc,
    /// The `<IPOC>` content is not exactly one unsigned integer of at most
    /// 20 digits fitting 64 bits (no comments, elements or further text
    /// inside).
    #[error("<IPOC> at byte {at} is not an unsigned integer")]
    BadIpoc {
        /// Byte offset.
        at: usize,
    },
    /// The reply does not fit the caller's buffer.
    #[error("reply needs more than the {capacity}-byte buffer")]
    BufferTooSmall {
        /// The buffer's size.
        capacity: usize,
    },
}

impl CodecError {
    /// A short stable name of the kind of error (for counters and logs).
    pub fn kind(&self) -> &'static str {
        match self {
            CodecError::Empty => "empty",
            CodecError::Oversize { .. } => "oversize",
            CodecError::Truncated { .. } => "truncated",
            CodecError::Syntax { .. } => "syntax",
            CodecError::NotRob { .. } => "not_rob",
            CodecError::BadNumber { .. } => "bad_number",
            CodecError::OutOfRange { .. } => "out_of_range",
            CodecError::Duplicate { .. } => "duplicate",
            CodecError::NonFinite { .. } => "non_finite",
            CodecError::MissingAttribute { .. } => "missing_attribute",
            CodecError::MissingIpoc => "missing_ipoc",
            CodecError::BadIpoc { .. } => "bad_ipoc",
            CodecError::BufferTooSmall { .. } => "buffer_too_small",
        }
    }
}

fn from_xml(e: XmlError) -> CodecError {
    if e.truncated {
        CodecError::Truncated {
            at: e.at,
            what: e.what,
        }
    } else {
        CodecError::Syntax {
            at: e.at,
            what: e.what,
        }
    }
}

/// The controller's interpolation counter, kept as the digits received so
/// that the reply echoes it verbatim (leading zeros included).
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Ipoc {
    digits: [u8; 20],
    len: u8,
    value: u64,
}

impl Ipoc {
    /// From the text of an `<IPOC>` element (surrounding whitespace ignored).
    pub fn parse(text: &[u8]) -> Option<Ipoc> {
        let t = text.trim_ascii();
        if t.is_empty() || t.len() > 20 || !t.iter().all(u8::is_ascii_digit) {
            return None;
        }
        let mut value: u64 = 0;
        for &d in t {
            value = value.checked_mul(10)?.checked_add(u64::from(d - b'0'))?;
        }
        let mut digits = [0u8; 20];
        digits[..t.len()].copy_from_slice(t);
        Some(Ipoc {
            digits,
            len: t.len() as u8,
            value,
        })
    }

    /// From a value (printed without leading zeros).
    pub fn from_value(value: u64) -> Ipoc {
        let mut buf = [0u8; 20];
        let mut n = value;
        let mut i = 20;
        loop {
            i -= 1;
            buf[i] = b'0' + (n % 10) as u8;
            n /= 10;
            if n == 0 {
                break;
            }
        }
        let len = 20 - i;
        let mut digits = [0u8; 20];
        digits[..len].copy_from_slice(&buf[i..]);
        Ipoc {
            digits,
            len: len as u8,
            value,
        }
    }

    /// The numeric value.
    pub fn value(&self) -> u64 {
        self.value
    }

    /// The digits as received.
    pub fn as_str(&self) -> &str {
        // Only ASCII digits are ever stored.
        std::str::from_utf8(&self.digits[..self.len as usize]).unwrap_or("0")
    }
}

impl std::fmt::Debug for Ipoc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Ipoc({})", self.as_str())
    }
}

/// What the sensor needs from one `<Rob>` datagram.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobFrame {
    /// `RIst`: the actual TCP pose, if sent.
    pub rist: Option<Pose6>,
    /// `RSol`: the commanded TCP pose, if sent.
    pub rsol: Option<Pose6>,
    /// `Delay D`: the controller's late-reply count, if sent.
    pub delay: Option<u64>,
    /// `IPOC`, echoed verbatim in the reply.
    pub ipoc: Ipoc,
}

impl RobFrame {
    /// A KR C2 first datagram holding only `<IPOC>`.
    pub fn is_ipoc_only(&self) -> bool {
        self.rist.is_none() && self.rsol.is_none() && self.delay.is_none()
    }
}

fn number(v: &[u8]) -> Option<f64> {
    let s = std::str::from_utf8(v).ok()?.trim();
    let x: f64 = s.parse().ok()?;
    x.is_finite().then_some(x)
}

fn pose(
    attrs: crate::xml::Attrs<'_>,
    element: &'static str,
    at: usize,
) -> Result<Pose6, CodecError> {
    let mut out = [0.0; 6];
    let mut seen = [false; 6];
    for a in attrs.iter() {
        let (n, v) = a.map_err(from_xml)?;
        if let Some(i) = POSE_ATTRS.iter().position(|p| p.as_bytes() == n) {
            let attr = POSE_ATTRS[i];
            if seen[i] {
                return Err(CodecError::Duplicate { element, at });
            }
            let x = number(v).ok_or(CodecError::BadNumber { element, attr, at })?;
            let limit = if i < 3 {
                MAX_POSITION_MM
            } else {
                MAX_ANGLE_DEG
            };
            if x.abs() > limit {
                return Err(CodecError::OutOfRange { element, attr, at });
            }
            out[i] = x;
            seen[i] = true;
        }
    }
    if let Some(i) = seen.iter().position(|s| !s) {
        return Err(CodecError::MissingAttribute {
            element,
            attr: POSE_ATTRS[i],
            at,
        });
    }
    Ok(out)
}

/// Parses one `<Rob>` datagram. Elements are found by name at any depth
/// below the root, in any order; unknown elements and attributes are
/// skipped; the root's `Type`/`TYPE` is not checked (the controller names
/// itself). The elements the sensor reads must appear at most once, hold
/// plausible finite numbers, and `<IPOC>` must hold nothing but its digits:
/// anything else rejects the whole datagram (it is never answered as if
/// valid). Never allocates.
pub fn parse_rob(datagram: &[u8]) -> Result<RobFrame, CodecError> {
    if datagram.len() > MAX_DATAGRAM {
        return Err(CodecError::Oversize {
            len: datagram.len(),
        });
    }
    if datagram.trim_ascii().is_empty() {
        return Err(CodecError::Empty);
    }
    let mut t = Tokenizer::new(datagram);
    let mut depth = 0usize;
    let mut root_seen = false;
    let mut root_closed = false;
    // (offset of the <IPOC> tag, offset of its content, depth inside it)
    let mut in_ipoc: Option<(usize, usize)> = None;
    let mut ipoc: Option<Ipoc> = None;
    let mut ipoc_seen = false;
    let mut rist = None;
    let mut rsol = None;
    let mut delay = None;
    loop {
        let at = t.position();
        let Some(tok) = t.next().map_err(from_xml)? else {
            break;
        };
        match tok {
            Token::Text(txt) => {
                if in_ipoc.is_none() && !txt.trim_ascii().is_empty() && depth == 0 {
                    return Err(CodecError::Syntax {
                        at,
                        what: "text outside the root element",
                    });
                }
            }
            Token::Start { name, attrs, empty } => {
                if root_closed {
                    return Err(CodecError::Syntax {
                        at,
                        what: "content after the root element",
                    });
                }
                if let Some((ip_at, _)) = in_ipoc {
                    // No element inside <IPOC>.
                    return Err(CodecError::BadIpoc { at: ip_at });
                }
                if !root_seen {
                    if name != b"Rob" {
                        return Err(CodecError::NotRob { at });
                    }
                    root_seen = true;
                } else {
                    match name {
                        b"RIst" => {
                            if rist.is_some() {
                                return Err(CodecError::Duplicate {
                                    element: "RIst",
                                    at,
                                });
                            }
                            rist = Some(pose(attrs, "RIst", at)?);
                        }
                        b"RSol" => {
                            if rsol.is_some() {
                                return Err(CodecError::Duplicate {
                                    element: "RSol",
                                    at,
                                });
                            }
                            rsol = Some(pose(attrs, "RSol", at)?);
                        }
                        b"Delay" => {
                            if delay.is_some() {
                                return Err(CodecError::Duplicate {
                                    element: "Delay",
                                    at,
                                });
                            }
                            delay = Some(delay_value(attrs, at)?);
                        }
                        b"IPOC" => {
                            if ipoc_seen {
                                return Err(CodecError::Duplicate {
                                    element: "IPOC",
                                    at,
                                });
                            }
                            ipoc_seen = true;
                            if empty {
                                return Err(CodecError::BadIpoc { at });
                            }
                            in_ipoc = Some((at, t.position()));
                        }
                        _ => {}
                    }
                }
                if !empty {
                    depth += 1;
                } else if depth == 0 {
                    root_closed = true;
                }
            }
            Token::End { name } => {
                if depth == 0 {
                    return Err(CodecError::Syntax {
                        at,
                        what: "end tag without a start tag",
                    });
                }
                if let Some((ip_at, content)) = in_ipoc.take() {
                    // The raw bytes between <IPOC> and this end tag: a
                    // comment, a declaration or a second text run makes
                    // them more than the digits and is refused.
                    if name != b"IPOC" {
                        return Err(CodecError::BadIpoc { at: ip_at });
                    }
                    ipoc = Some(
                        Ipoc::parse(&datagram[content..at])
                            .ok_or(CodecError::BadIpoc { at: ip_at })?,
                    );
                }
                depth -= 1;
                if depth == 0 {
                    if name != b"Rob" {
                        return Err(CodecError::Syntax {
                            at,
                            what: "root end tag is not </Rob>",
                        });
                    }
                    root_closed = true;
                }
            }
        }
    }
    if !root_seen {
        return Err(CodecError::Syntax {
            at: 0,
            what: "no element",
        });
    }
    if !root_closed {
        return Err(CodecError::Truncated {
            at: datagram.len(),
            what: "root element not closed",
        });
    }
    let ipoc = ipoc.ok_or(CodecError::MissingIpoc)?;
    Ok(RobFrame {
        rist,
        rsol,
        delay,
        ipoc,
    })
}

/// `<Delay D="k"/>`: a non-negative integer up to [`MAX_DELAY`].
fn delay_value(attrs: crate::xml::Attrs<'_>, at: usize) -> Result<u64, CodecError> {
    let d = attrs
        .get(b"D")
        .map_err(from_xml)?
        .ok_or(CodecError::MissingAttribute {
            element: "Delay",
            attr: "D",
            at,
        })?;
    let d = number(d)
        .filter(|x| *x >= 0.0 && x.fract() == 0.0)
        .ok_or(CodecError::BadNumber {
            element: "Delay",
            attr: "D",
            at,
        })?;
    if d > MAX_DELAY as f64 {
        return Err(CodecError::OutOfRange {
            element: "Delay",
            attr: "D",
            at,
        });
    }
    Ok(d as u64)
}

/// How the `<Sen>` reply is spelled: the root's `Type` (SENTYPE), the
/// Cartesian correction element and its six attribute names, further
/// RECEIVE elements sent as zeros, and the decimals printed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SenFormat {
    /// Root `Type` attribute: must equal the controller's SENTYPE.
    pub sentype: String,
    /// Correction element name (`RKorr`).
    pub correction_element: String,
    /// Attribute names for `X, Y, Z, A, B, C` of the correction.
    pub correction_attrs: [String; 6],
    /// Other RECEIVE elements `(element, attributes)`, written with zeros so
    /// that the reply matches the context.
    pub zero_elements: Vec<(String, Vec<String>)>,
    /// Fixed decimals of every number (4–6 in practice).
    pub decimals: usize,
}

impl Default for SenFormat {
    fn default() -> Self {
        SenFormat {
            sentype: "ImFree".into(),
            correction_element: "RKorr".into(),
            correction_attrs: POSE_ATTRS.map(String::from),
            zero_elements: Vec::new(),
            decimals: 4,
        }
    }
}

struct Cursor<'a> {
    buf: &'a mut [u8],
    len: usize,
}

impl std::fmt::Write for Cursor<'_> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let end = self.len + s.len();
        if end > self.buf.len() {
            return Err(std::fmt::Error);
        }
        self.buf[self.len..end].copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// Counts the bytes a reply would take.
struct Counter(usize);

impl std::fmt::Write for Counter {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.0 += s.len();
        Ok(())
    }
}

impl SenFormat {
    /// Writes `<Sen Type="..."><RKorr X=".." .../>...<IPOC>..</IPOC></Sen>`
    /// into `out`, returning the number of bytes written. A non-finite
    /// correction value is refused ([`CodecError::NonFinite`]), never
    /// printed. Never allocates.
    pub fn write(
        &self,
        correction: &Pose6,
        ipoc: &Ipoc,
        out: &mut [u8],
    ) -> Result<usize, CodecError> {
        if let Some(index) = correction.iter().position(|v| !v.is_finite()) {
            return Err(CodecError::NonFinite { index });
        }
        let capacity = out.len();
        let mut c = Cursor { buf: out, len: 0 };
        self.write_to(&mut c, correction, ipoc)
            .map_err(|_| CodecError::BufferTooSmall { capacity })?;
        Ok(c.len)
    }

    /// The longest reply this format can produce when every correction
    /// value's magnitude is at most `max_abs` (and the IPOC has its 20
    /// digits): the size of the reply buffer.
    pub fn reply_len_bound(&self, max_abs: f64) -> usize {
        let mut n = Counter(0);
        let v = -max_abs.abs();
        let ipoc = Ipoc::from_value(u64::MAX);
        // Writing into a counter never fails.
        let _ = self.write_to(&mut n, &[v; 6], &ipoc);
        n.0
    }

    fn write_to(
        &self,
        c: &mut impl std::fmt::Write,
        corr: &Pose6,
        ipoc: &Ipoc,
    ) -> std::fmt::Result {
        let d = self.decimals;
        write!(
            c,
            "<Sen Type=\"{}\"><{}",
            self.sentype, self.correction_element
        )?;
        for (name, v) in self.correction_attrs.iter().zip(corr) {
            // Never print "-0.0000": round first, then drop the sign of zero.
            let scale = 10f64.powi(d as i32);
            let r = (v * scale).round() / scale;
            let r = if r == 0.0 { 0.0 } else { r };
            write!(c, " {name}=\"{r:.d$}\"")?;
        }
        c.write_str("/>")?;
        for (el, attrs) in &self.zero_elements {
            if attrs.is_empty() {
                // A RECEIVE tag without '.': the value is the element's text.
                write!(c, "<{el}>{:.d$}</{el}>", 0.0)?;
                continue;
            }
            write!(c, "<{el}")?;
            for a in attrs {
                write!(c, " {a}=\"{:.d$}\"", 0.0)?;
            }
            c.write_str("/>")?;
        }
        write!(c, "<IPOC>{}</IPOC></Sen>", ipoc.as_str())
    }
}

/// A parsed `<Sen>` reply (the controller's side of the exchange; used by
/// the simulated controller).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SenFrame {
    /// The root's `Type` equals the expected SENTYPE.
    pub type_matches: bool,
    /// The correction element's six values, if present and complete.
    pub correction: Option<Pose6>,
    /// The echoed IPOC.
    pub ipoc: Ipoc,
}

/// Parses a `<Sen>` reply, checking its `Type` against `sentype` and reading
/// the correction from element `element` (attributes `X..C`).
pub fn parse_sen(datagram: &[u8], sentype: &str, element: &str) -> Result<SenFrame, CodecError> {
    if datagram.len() > MAX_DATAGRAM {
        return Err(CodecError::Oversize {
            len: datagram.len(),
        });
    }
    let mut t = Tokenizer::new(datagram);
    let mut depth = 0usize;
    let mut type_matches = false;
    let mut root = false;
    let mut closed = false;
    let mut correction = None;
    let mut in_ipoc = None;
    let mut ipoc = None;
    loop {
        let at = t.position();
        let Some(tok) = t.next().map_err(from_xml)? else {
            break;
        };
        match tok {
            Token::Start { name, attrs, empty } => {
                if !root {
                    if name != b"Sen" {
                        return Err(CodecError::Syntax {
                            at,
                            what: "root element is not <Sen>",
                        });
                    }
                    root = true;
                    let ty = match attrs.get(b"Type").map_err(from_xml)? {
                        Some(v) => Some(v),
                        None => attrs.get(b"TYPE").map_err(from_xml)?,
                    };
                    type_matches = ty == Some(sentype.as_bytes());
                } else if name == element.as_bytes() {
                    correction = Some(pose(attrs, "correction", at)?);
                } else if name == b"IPOC" && !empty {
                    in_ipoc = Some(at);
                }
                if !empty {
                    depth += 1;
                }
            }
            Token::End { name } => {
                if name == b"IPOC" {
                    in_ipoc = None;
                }
                depth = depth.checked_sub(1).ok_or(CodecError::Syntax {
                    at,
                    what: "end tag without a start tag",
                })?;
                if depth == 0 {
                    closed = true;
                }
            }
            Token::Text(txt) => {
                if let Some(a) = in_ipoc {
                    ipoc = Some(Ipoc::parse(txt).ok_or(CodecError::BadIpoc { at: a })?);
                }
            }
        }
    }
    if !closed {
        return Err(CodecError::Truncated {
            at: datagram.len(),
            what: "root element not closed",
        });
    }
    Ok(SenFrame {
        type_matches,
        correction,
        ipoc: ipoc.ok_or(CodecError::MissingIpoc)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TYPICAL: &[u8] = b"<Rob Type=\"KUKA\"><RIst X=\"445.0\" Y=\"0.0\" Z=\"790.0\" A=\"180.0\" B=\"0.0\" C=\"180.0\"/><RSol X=\"445.0\" Y=\"0.0\" Z=\"790.0\" A=\"180.0\" B=\"0.0\" C=\"180.0\"/><AIPos A1=\"0.0\" A2=\"-90.0\" A3=\"90.0\" A4=\"0.0\" A5=\"90.0\" A6=\"0.0\"/><ASPos A1=\"0.0\" A2=\"-90.0\" A3=\"90.0\" A4=\"0.0\" A5=\"90.0\" A6=\"0.0\"/><Delay D=\"0\"/><IPOC>123645634563</IPOC></Rob>";

    #[test]
    fn parses_the_spec_example() {
        let f = parse_rob(TYPICAL).unwrap();
        assert_eq!(f.rist, Some([445.0, 0.0, 790.0, 180.0, 0.0, 180.0]));
        assert_eq!(f.rsol, f.rist);
        assert_eq!(f.delay, Some(0));
        assert_eq!(f.ipoc.value(), 123_645_634_563);
        assert_eq!(f.ipoc.as_str(), "123645634563");
    }

    #[test]
    fn variants_of_the_spec() {
        // TYPE, attribute order, decimals, extra elements, whitespace, nesting.
        let d = b"<Rob TYPE='KUKA'>\n <Tech T21=\"1\"/>\n <RSol C=\"1.123456789\" B=\"-2\" A=\"3.5e1\" Z=\"790\" Y=\"0.00000\" X=\"445.12\"></RSol>\n <Delay D=\"3\"/><DiL>5</DiL>\n <IPOC> 0004 </IPOC>\n</Rob>\n";
        let f = parse_rob(d).unwrap();
        assert_eq!(f.rsol, Some([445.12, 0.0, 790.0, 35.0, -2.0, 1.123456789]));
        assert_eq!(f.rist, None);
        assert_eq!(f.delay, Some(3));
        assert_eq!(f.ipoc.as_str(), "0004");
        assert_eq!(f.ipoc.value(), 4);
        // KR C2's first datagram.
        let f = parse_rob(b"<Rob Type=\"KUKA\"><IPOC>99</IPOC></Rob>").unwrap();
        assert!(f.is_ipoc_only());
    }

    #[test]
    fn clear_errors() {
        let cut = &TYPICAL[..TYPICAL.len() - 20];
        assert!(
            matches!(parse_rob(cut), Err(CodecError::Truncated { .. })),
            "{:?}",
            parse_rob(cut)
        );
        assert!(matches!(
            parse_rob(&TYPICAL[..30]),
            Err(CodecError::Truncated { .. })
        ));
        assert_eq!(parse_rob(b"  "), Err(CodecError::Empty));
        assert!(matches!(
            parse_rob(b"<Sen><IPOC>1</IPOC></Sen>"),
            Err(CodecError::NotRob { .. })
        ));
        assert_eq!(
            parse_rob(b"<Rob><Delay D=\"0\"/></Rob>"),
            Err(CodecError::MissingIpoc)
        );
        assert!(matches!(
            parse_rob(b"<Rob><IPOC>12a</IPOC></Rob>"),
            Err(CodecError::BadIpoc { .. })
        ));
        assert!(matches!(
            parse_rob(b"<Rob><IPOC>123456789012345678901</IPOC></Rob>"),
            Err(CodecError::BadIpoc { .. })
        ));
        assert!(matches!(
            parse_rob(b"<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\"/><IPOC>1</IPOC></Rob>"),
            Err(CodecError::MissingAttribute {
                element: "RIst",
                attr: "C",
                ..
            })
        ));
        assert!(matches!(
            parse_rob(b"<Rob><RIst X=\"1,0\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>1</IPOC></Rob>"),
            Err(CodecError::BadNumber { element: "RIst", attr: "X", .. })
        ));
        let big = vec![b' '; MAX_DATAGRAM + 1];
        assert_eq!(
            parse_rob(&big),
            Err(CodecError::Oversize {
                len: MAX_DATAGRAM + 1
            })
        );
        assert!(parse_rob(b"\x00\xff garbage").is_err());
        assert!(matches!(
            parse_rob(b"<Rob><IPOC>1</IPOC></Rob><Rob>"),
            Err(CodecError::Syntax { .. })
        ));
    }

    #[test]
    fn malformed_numbers_and_ipocs_are_refused() {
        let bad_ipoc = |d: &[u8]| matches!(parse_rob(d), Err(CodecError::BadIpoc { .. }));
        // Text split by a comment, a comment alone, an element, CDATA.
        assert!(bad_ipoc(b"<Rob><IPOC>12<!---->99</IPOC></Rob>"));
        assert!(bad_ipoc(b"<Rob><IPOC><!-- -->99</IPOC></Rob>"));
        assert!(bad_ipoc(b"<Rob><IPOC>9<b/>9</IPOC></Rob>"));
        assert!(bad_ipoc(b"<Rob><IPOC><![CDATA[99]]></IPOC></Rob>"));
        assert!(bad_ipoc(b"<Rob><IPOC></IPOC></Rob>"));
        assert!(matches!(
            parse_rob(b"<Rob><IPOC>1</IPOC><IPOC>2</IPOC></Rob>"),
            Err(CodecError::Duplicate {
                element: "IPOC",
                ..
            })
        ));
        let p = "X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"";
        let twice = format!("<Rob><RSol {p}/><RSol {p}/><IPOC>1</IPOC></Rob>");
        assert!(matches!(
            parse_rob(twice.as_bytes()),
            Err(CodecError::Duplicate {
                element: "RSol",
                ..
            })
        ));
        assert!(matches!(
            parse_rob(b"<Rob><RIst X=\"1\" X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>1</IPOC></Rob>"),
            Err(CodecError::Duplicate { element: "RIst", .. })
        ));
        for (d, attr) in [("1e300", "D"), ("4294967296", "D")] {
            let doc = format!("<Rob><Delay D=\"{d}\"/><IPOC>1</IPOC></Rob>");
            assert!(
                matches!(parse_rob(doc.as_bytes()), Err(CodecError::OutOfRange { element: "Delay", attr: a, .. }) if a == attr),
                "{doc}"
            );
        }
        for d in ["NaN", "-1", "1.5", "inf"] {
            let doc = format!("<Rob><Delay D=\"{d}\"/><IPOC>1</IPOC></Rob>");
            assert!(
                matches!(parse_rob(doc.as_bytes()), Err(CodecError::BadNumber { .. })),
                "{doc}"
            );
        }
        let huge =
            "<Rob><RSol X=\"1e300\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>1</IPOC></Rob>";
        assert!(matches!(
            parse_rob(huge.as_bytes()),
            Err(CodecError::OutOfRange {
                element: "RSol",
                attr: "X",
                ..
            })
        ));
        let angle =
            "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"720\" C=\"6\"/><IPOC>1</IPOC></Rob>";
        assert!(matches!(
            parse_rob(angle.as_bytes()),
            Err(CodecError::OutOfRange { attr: "B", .. })
        ));
        // The largest valid values still pass.
        let d = format!("<Rob><Delay D=\"{MAX_DELAY}\"/><IPOC> 18446744073709551615 </IPOC></Rob>");
        let f = parse_rob(d.as_bytes()).unwrap();
        assert_eq!((f.delay, f.ipoc.value()), (Some(MAX_DELAY), u64::MAX));
    }

    #[test]
    fn non_finite_values_are_never_written() {
        let fmt = SenFormat::default();
        let mut buf = [0u8; 256];
        let ipoc = Ipoc::from_value(1);
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(
                fmt.write(&[0.0, 0.0, bad, 0.0, 0.0, 0.0], &ipoc, &mut buf),
                Err(CodecError::NonFinite { index: 2 })
            );
        }
        let bound = fmt.reply_len_bound(4.0);
        let n = fmt
            .write(&[-4.0; 6], &Ipoc::from_value(u64::MAX), &mut buf)
            .unwrap();
        assert_eq!(n, bound);
        assert!(fmt.reply_len_bound(1234.5) > bound);
    }

    #[test]
    fn writes_the_spec_reply() {
        let fmt = SenFormat::default();
        let mut buf = [0u8; 256];
        let ipoc = Ipoc::parse(b"123645634563").unwrap();
        let n = fmt
            .write(&[0.0256, 0.0, -0.00001, 0.0, 0.0, 0.0], &ipoc, &mut buf)
            .unwrap();
        assert_eq!(
            std::str::from_utf8(&buf[..n]).unwrap(),
            "<Sen Type=\"ImFree\"><RKorr X=\"0.0256\" Y=\"0.0000\" Z=\"0.0000\" A=\"0.0000\" B=\"0.0000\" C=\"0.0000\"/><IPOC>123645634563</IPOC></Sen>"
        );
        let mut small = [0u8; 40];
        assert_eq!(
            fmt.write(&[0.0; 6], &ipoc, &mut small),
            Err(CodecError::BufferTooSmall { capacity: 40 })
        );
    }

    #[test]
    fn custom_names_and_zero_elements() {
        let fmt = SenFormat {
            sentype: "Cam".into(),
            correction_element: "Korr".into(),
            correction_attrs: ["x", "y", "z", "a", "b", "c"].map(String::from),
            zero_elements: vec![("DiO".into(), vec!["D".into()])],
            decimals: 6,
        };
        let mut buf = [0u8; 512];
        let n = fmt
            .write(
                &[1.0, -2.5, 0.0, 0.001, 0.0, 0.0],
                &Ipoc::from_value(7),
                &mut buf,
            )
            .unwrap();
        assert_eq!(
            std::str::from_utf8(&buf[..n]).unwrap(),
            "<Sen Type=\"Cam\"><Korr x=\"1.000000\" y=\"-2.500000\" z=\"0.000000\" a=\"0.001000\" b=\"0.000000\" c=\"0.000000\"/><DiO D=\"0.000000\"/><IPOC>7</IPOC></Sen>"
        );
    }

    #[test]
    fn reply_parses_back() {
        let fmt = SenFormat::default();
        let mut buf = [0u8; 256];
        let n = fmt
            .write(
                &[1.5, 0.0, 0.0, 0.0, 0.0, -0.25],
                &Ipoc::from_value(42),
                &mut buf,
            )
            .unwrap();
        let f = parse_sen(&buf[..n], "ImFree", "RKorr").unwrap();
        assert!(f.type_matches);
        assert_eq!(f.correction, Some([1.5, 0.0, 0.0, 0.0, 0.0, -0.25]));
        assert_eq!(f.ipoc.value(), 42);
        assert!(!parse_sen(&buf[..n], "Other", "RKorr").unwrap().type_matches);
        assert!(parse_sen(&buf[..n - 3], "ImFree", "RKorr").is_err());
    }

    #[test]
    fn ipoc_round_trip() {
        for v in [0u64, 1, 9, 10, 123_645_634_563, u64::MAX] {
            let i = Ipoc::from_value(v);
            assert_eq!(i.value(), v);
            assert_eq!(Ipoc::parse(i.as_str().as_bytes()), Some(i));
        }
        assert_eq!(Ipoc::parse(b"18446744073709551616"), None);
    }

    mod props {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig { cases: 2000, rng_algorithm: proptest::test_runner::RngAlgorithm::ChaCha, ..ProptestConfig::default() })]

            #[test]
            fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
                let _ = parse_rob(&bytes);
            }

            #[test]
            fn mutated_datagrams_never_panic(cut in 0usize..300, pos in 0usize..300, b in any::<u8>()) {
                let mut d = TYPICAL.to_vec();
                let p = pos % d.len();
                d[p] = b;
                d.truncate(cut.max(1).min(d.len()));
                let _ = parse_rob(&d);
            }

            #[test]
            fn any_pose_round_trips(x in -3000.0f64..3000.0, a in -180.0f64..180.0, ipoc in any::<u64>()) {
                let d = format!("<Rob Type=\"KUKA\"><RSol X=\"{x}\" Y=\"1\" Z=\"2\" A=\"{a}\" B=\"0\" C=\"0\"/><IPOC>{ipoc}</IPOC></Rob>");
                let f = parse_rob(d.as_bytes()).unwrap();
                prop_assert_eq!(f.rsol.unwrap()[0], x);
                prop_assert_eq!(f.rsol.unwrap()[3], a);
                prop_assert_eq!(f.ipoc.value(), ipoc);
            }
        }
    }
}
