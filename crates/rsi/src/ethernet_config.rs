//! The controller-side `RSI_EthernetConfig.xml`: its CONFIG values (port,
//! SENTYPE, ONLYSEND) and SEND/RECEIVE element lists, turned into the
//! reply's spelling ([`SenFormat`]) so both sides agree, and checked against
//! the correction mode (HOLDON pairing). Pure: parses text handed in, in
//! time linear in its length (one pass of the tokenizer, lines counted
//! incrementally, element lists indexed by hash maps).

use crate::codec::{SenFormat, POSE_ATTRS};
use crate::law::CorrectionMode;
use crate::warning::RsiWarning;
use crate::xml::{is_xml_name, Attrs, Token, Tokenizer, XmlError};
use std::collections::HashMap;
use thiserror::Error;

/// Why an `RSI_EthernetConfig.xml` was rejected.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum EthernetConfigError {
    /// Not well-formed XML.
    #[error("RSI_EthernetConfig.xml line {line}: {what}")]
    Xml {
        /// 1-based line.
        line: usize,
        /// What was wrong.
        what: String,
    },
    /// A required CONFIG key is missing.
    #[error("RSI_EthernetConfig.xml: missing <{key}> in <CONFIG>")]
    Missing {
        /// The key.
        key: &'static str,
    },
    /// A value that does not parse.
    #[error("RSI_EthernetConfig.xml line {line}: bad {key} \"{value}\"")]
    BadValue {
        /// The key or attribute.
        key: &'static str,
        /// The value found.
        value: String,
        /// 1-based line.
        line: usize,
    },
    /// A name the reply would carry (SENTYPE, a RECEIVE element or
    /// attribute) that is not an XML name.
    #[error("RSI_EthernetConfig.xml line {line}: {key} \"{value}\" is not an XML name (a letter or '_', then letters, digits, '_', '-', '.')")]
    NotAName {
        /// The key or attribute (`SENTYPE`, `TAG`).
        key: &'static str,
        /// The value found.
        value: String,
        /// 1-based line.
        line: usize,
    },
    /// No RECEIVE element carries a full Cartesian correction.
    #[error("RSI_EthernetConfig.xml: no RECEIVE element has all of X, Y, Z, A, B, C (e.g. RKorr.X ... RKorr.C)")]
    NoCorrection,
    /// The controller only streams (`ONLYSEND=TRUE`): nothing can be corrected.
    #[error("RSI_EthernetConfig.xml: ONLYSEND is TRUE, the controller expects no replies")]
    OnlySend,
}

/// One `<ELEMENT>` of the RECEIVE list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReceiveTag {
    /// The element name (`RKorr` of `RKorr.X`).
    pub element: String,
    /// The attribute (`X` of `RKorr.X`), `None` for a tag without '.'.
    pub attribute: Option<String>,
    /// `HOLDON`, if given.
    pub holdon: Option<bool>,
    /// 1-based line.
    pub line: usize,
}

/// The parts of the controller's config the sensor needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EthernetConfig {
    /// `IP_NUMBER`: the sensor PC's address as the controller knows it.
    pub ip_number: Option<String>,
    /// `PORT`: the port the sensor listens on.
    pub port: u16,
    /// `SENTYPE`: the reply's root `Type`.
    pub sentype: String,
    /// `ONLYSEND`.
    pub only_send: bool,
    /// SEND tags as written (`DEF_RIst`, ...).
    pub send: Vec<String>,
    /// RECEIVE tags in order.
    pub receive: Vec<ReceiveTag>,
}

/// 1-based line numbers of byte offsets that never decrease: each byte is
/// counted once (an offset before the last one is counted from the start,
/// which only an error report can ask for).
struct Lines<'a> {
    text: &'a [u8],
    pos: usize,
    line: usize,
    work: u64,
}

impl Lines<'_> {
    fn at(&mut self, at: usize) -> usize {
        let at = at.min(self.text.len());
        if at < self.pos {
            self.pos = 0;
            self.line = 1;
        }
        let newlines = self.text[self.pos..at]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.work += (at - self.pos) as u64;
        self.line += newlines;
        self.pos = at;
        self.line
    }
}

fn holdon(v: &[u8], line: usize) -> Result<bool, EthernetConfigError> {
    match v.trim_ascii() {
        b"1" => Ok(true),
        b"0" => Ok(false),
        other => Err(EthernetConfigError::BadValue {
            key: "HOLDON",
            value: String::from_utf8_lossy(other).into_owned(),
            line,
        }),
    }
}

/// Where an open element sits, as far as the file's meaning goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Open {
    Config,
    Send,
    Receive,
    /// A key directly inside `<CONFIG>`.
    Key(Key),
    Other,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Key {
    IpNumber,
    Port,
    Sentype,
    OnlySend,
    Unused,
}

fn classify(name: &[u8], parent: Option<Open>) -> Open {
    let is = |n: &str| name.eq_ignore_ascii_case(n.as_bytes());
    if parent == Some(Open::Config) {
        return Open::Key(if is("IP_NUMBER") {
            Key::IpNumber
        } else if is("PORT") {
            Key::Port
        } else if is("SENTYPE") {
            Key::Sentype
        } else if is("ONLYSEND") {
            Key::OnlySend
        } else {
            Key::Unused
        });
    }
    if is("CONFIG") {
        Open::Config
    } else if is("SEND") {
        Open::Send
    } else if is("RECEIVE") {
        Open::Receive
    } else {
        Open::Other
    }
}

impl EthernetConfig {
    /// Parses the file's text.
    pub fn parse(text: &str) -> Result<EthernetConfig, EthernetConfigError> {
        Self::parse_with_work(text).0
    }

    /// [`EthernetConfig::parse`], also returning the work done: the bytes
    /// scanned by every pass over the text (tokens, attribute lookups, line
    /// counting) plus one per element-list operation. Linear in the text's
    /// length; tests hold it to a small multiple of it.
    pub fn parse_with_work(text: &str) -> (Result<EthernetConfig, EthernetConfigError>, u64) {
        let mut lines = Lines {
            text: text.as_bytes(),
            pos: 0,
            line: 1,
            work: 0,
        };
        let mut work = 0u64;
        let r = Self::parse_inner(text, &mut lines, &mut work);
        (r, work + lines.work)
    }

    fn parse_inner(
        text: &str,
        lines: &mut Lines<'_>,
        work: &mut u64,
    ) -> Result<EthernetConfig, EthernetConfigError> {
        let mut t = Tokenizer::new(text.as_bytes());
        let mut path: Vec<Open> = Vec::new();
        // Depth (path length) at which the outermost SEND or RECEIVE opened.
        let mut section: Option<(Open, usize)> = None;
        let mut ip: Option<String> = None;
        let mut port: Option<(String, usize)> = None;
        let mut sentype: Option<(String, usize)> = None;
        let mut only_send: Option<(String, usize)> = None;
        let mut send = Vec::new();
        let mut receive = Vec::new();
        loop {
            let at = t.position();
            let tok = match t.next() {
                Ok(tok) => tok,
                Err(e) => {
                    return Err(EthernetConfigError::Xml {
                        line: lines.at(e.at),
                        what: e.what.to_string(),
                    })
                }
            };
            let Some(tok) = tok else { break };
            *work += (t.position() - at) as u64;
            let line = lines.at(at);
            match tok {
                Token::Start { name, attrs, empty } => {
                    let open = classify(name, path.last().copied());
                    if name.eq_ignore_ascii_case(b"ELEMENT") {
                        match section {
                            Some((Open::Send, _)) => {
                                let tag = tag_of(attrs, line, lines, work)?;
                                send.push(tag);
                            }
                            Some((Open::Receive, _)) => {
                                receive.push(receive_tag(attrs, line, lines, work)?);
                            }
                            _ => {}
                        }
                    }
                    if !empty {
                        if section.is_none() && matches!(open, Open::Send | Open::Receive) {
                            section = Some((open, path.len()));
                        }
                        path.push(open);
                    }
                }
                Token::End { .. } => {
                    path.pop();
                    if section.is_some_and(|(_, d)| path.len() <= d) {
                        section = None;
                    }
                }
                Token::Text(txt) => {
                    let Some(Open::Key(key)) = path.last() else {
                        continue;
                    };
                    let slot = match key {
                        Key::IpNumber => {
                            let v = String::from_utf8_lossy(txt);
                            let v = v.trim();
                            if !v.is_empty() {
                                ip = Some(v.to_string());
                            }
                            continue;
                        }
                        Key::Port => &mut port,
                        Key::Sentype => &mut sentype,
                        Key::OnlySend => &mut only_send,
                        Key::Unused => continue,
                    };
                    let v = String::from_utf8_lossy(txt);
                    let v = v.trim();
                    // Text split by a comment is joined.
                    match slot {
                        Some((s, _)) => s.push_str(v),
                        None => *slot = Some((v.to_string(), line)),
                    }
                }
            }
        }
        let (pv, pl) = port.ok_or(EthernetConfigError::Missing { key: "PORT" })?;
        let port =
            pv.parse::<u16>()
                .ok()
                .filter(|p| *p != 0)
                .ok_or(EthernetConfigError::BadValue {
                    key: "PORT",
                    value: pv.clone(),
                    line: pl,
                })?;
        let (sentype, sl) = sentype
            .filter(|(s, _)| !s.is_empty())
            .ok_or(EthernetConfigError::Missing { key: "SENTYPE" })?;
        if !is_xml_name(sentype.as_bytes()) {
            return Err(EthernetConfigError::NotAName {
                key: "SENTYPE",
                value: sentype,
                line: sl,
            });
        }
        let only_send = match only_send {
            None => false,
            Some((v, l)) => match v.to_ascii_uppercase().as_str() {
                "TRUE" => true,
                "FALSE" => false,
                _ => {
                    return Err(EthernetConfigError::BadValue {
                        key: "ONLYSEND",
                        value: v,
                        line: l,
                    })
                }
            },
        };
        Ok(EthernetConfig {
            ip_number: ip,
            port,
            sentype,
            only_send,
            send,
            receive,
        })
    }

    /// The RECEIVE element that carries the Cartesian correction: the one
    /// with all of `X Y Z A B C` (`RKorr` preferred if several, else the
    /// first complete one in file order).
    pub fn correction_element(&self) -> Option<&str> {
        let mut seen: HashMap<&str, u8> = HashMap::new();
        let mut order: Vec<&str> = Vec::new();
        for r in &self.receive {
            let bits = seen.entry(r.element.as_str()).or_insert_with(|| {
                order.push(r.element.as_str());
                0
            });
            if let Some(i) = r
                .attribute
                .as_deref()
                .and_then(|a| POSE_ATTRS.iter().position(|p| *p == a))
            {
                *bits |= 1 << i;
            }
        }
        let full = |e: &&str| seen.get(e) == Some(&0b11_1111);
        if full(&"RKorr") {
            return Some("RKorr");
        }
        order.into_iter().find(full)
    }

    /// The reply's spelling: SENTYPE, the correction element, the other
    /// RECEIVE elements as zeros, `decimals` fixed decimals.
    pub fn sen_format(&self, decimals: usize) -> Result<SenFormat, EthernetConfigError> {
        if self.only_send {
            return Err(EthernetConfigError::OnlySend);
        }
        let corr = self
            .correction_element()
            .ok_or(EthernetConfigError::NoCorrection)?;
        let mut zero: Vec<(String, Vec<String>)> = Vec::new();
        let mut index: HashMap<&str, usize> = HashMap::new();
        for r in self.receive.iter().filter(|r| r.element != corr) {
            match index.get(r.element.as_str()) {
                Some(&k) => zero[k].1.extend(r.attribute.clone()),
                None => {
                    index.insert(r.element.as_str(), zero.len());
                    zero.push((r.element.clone(), r.attribute.clone().into_iter().collect()));
                }
            }
        }
        Ok(SenFormat {
            sentype: self.sentype.clone(),
            correction_element: corr.to_string(),
            correction_attrs: POSE_ATTRS.map(String::from),
            zero_elements: zero,
            decimals,
        })
    }

    /// Consistency warnings for running in `mode`: HOLDON pairing (absolute
    /// needs `HOLDON="1"`, relative `HOLDON="0"`), `RSol` missing from SEND,
    /// a RECEIVE element with only part of the six correction attributes.
    pub fn warnings(&self, mode: CorrectionMode) -> Vec<RsiWarning> {
        let mut w = Vec::new();
        let corr = self.correction_element();
        for r in self
            .receive
            .iter()
            .filter(|r| Some(r.element.as_str()) == corr)
        {
            let fits = matches!(
                (mode, r.holdon),
                (CorrectionMode::Absolute, Some(true)) | (CorrectionMode::Relative, Some(false))
            );
            if !fits {
                w.push(RsiWarning::Holdon {
                    line: r.line,
                    tag: format!("{}.{}", r.element, r.attribute.as_deref().unwrap_or("")),
                    holdon: r.holdon,
                    mode,
                });
            }
        }
        if !self.send.iter().any(|s| s.ends_with("RSol")) {
            w.push(RsiWarning::NoRsol);
        }
        // Elements (other than the correction) with part of X..C, in file
        // order: bit i set when POSE_ATTRS[i] is present.
        let mut partial: Vec<(&str, usize, u8)> = Vec::new();
        let mut index: HashMap<&str, usize> = HashMap::new();
        for r in self
            .receive
            .iter()
            .filter(|r| Some(r.element.as_str()) != corr)
        {
            let Some(bit) = r
                .attribute
                .as_deref()
                .and_then(|a| POSE_ATTRS.iter().position(|p| *p == a))
            else {
                continue;
            };
            let k = *index.entry(r.element.as_str()).or_insert_with(|| {
                partial.push((r.element.as_str(), r.line, 0));
                partial.len() - 1
            });
            partial[k].2 |= 1 << bit;
        }
        for (element, line, bits) in partial {
            w.push(RsiWarning::PartialCorrection {
                line,
                element: element.to_string(),
                missing: POSE_ATTRS
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| bits & (1 << i) == 0)
                    .map(|(_, a)| a.to_string())
                    .collect(),
            });
        }
        w
    }
}

fn xml_err<'l, 't>(
    lines: &'l mut Lines<'t>,
) -> impl FnMut(XmlError) -> EthernetConfigError + use<'l, 't> {
    move |e| EthernetConfigError::Xml {
        line: lines.at(e.at),
        what: e.what.to_string(),
    }
}

/// An attribute of an `<ELEMENT>`, counting the bytes looked at.
fn attr<'a>(
    attrs: Attrs<'a>,
    name: &[u8],
    lines: &mut Lines<'_>,
    work: &mut u64,
) -> Result<Option<&'a [u8]>, EthernetConfigError> {
    *work += attrs.raw_len() as u64;
    attrs.get(name).map_err(xml_err(lines))
}

fn tag_of(
    attrs: Attrs<'_>,
    line: usize,
    lines: &mut Lines<'_>,
    work: &mut u64,
) -> Result<String, EthernetConfigError> {
    let tag = attr(attrs, b"TAG", lines, work)?.ok_or(EthernetConfigError::BadValue {
        key: "TAG",
        value: String::new(),
        line,
    })?;
    Ok(String::from_utf8_lossy(tag).trim().to_string())
}

fn receive_tag(
    attrs: Attrs<'_>,
    line: usize,
    lines: &mut Lines<'_>,
    work: &mut u64,
) -> Result<ReceiveTag, EthernetConfigError> {
    let tag = tag_of(attrs, line, lines, work)?;
    let h = match attr(attrs, b"HOLDON", lines, work)? {
        Some(v) => Some(holdon(v, line)?),
        None => None,
    };
    let (element, attribute) = match tag.split_once('.') {
        Some((e, a)) => (e.to_string(), Some(a.to_string())),
        None => (tag.clone(), None),
    };
    if element.is_empty() || attribute.as_deref() == Some("") {
        return Err(EthernetConfigError::BadValue {
            key: "TAG",
            value: tag,
            line,
        });
    }
    if !is_xml_name(element.as_bytes())
        || !attribute
            .as_deref()
            .is_none_or(|a| is_xml_name(a.as_bytes()))
    {
        return Err(EthernetConfigError::NotAName {
            key: "TAG",
            value: tag,
            line,
        });
    }
    *work += 1;
    Ok(ReceiveTag {
        element,
        attribute,
        holdon: h,
        line,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const SPEC: &str = r#"<ROOT>
  <CONFIG>
    <IP_NUMBER>192.168.1.20</IP_NUMBER>
    <PORT>49152</PORT>
    <SENTYPE>ImFree</SENTYPE>
    <ONLYSEND>FALSE</ONLYSEND>
  </CONFIG>
  <SEND><ELEMENTS>
    <ELEMENT TAG="DEF_RIst" TYPE="DOUBLE" INDX="INTERNAL"/>
    <ELEMENT TAG="DEF_RSol" TYPE="DOUBLE" INDX="INTERNAL"/>
    <ELEMENT TAG="DEF_Delay" TYPE="LONG" INDX="INTERNAL"/>
  </ELEMENTS></SEND>
  <RECEIVE><ELEMENTS>
    <ELEMENT TAG="RKorr.X" TYPE="DOUBLE" INDX="1" HOLDON="1"/>
    <ELEMENT TAG="RKorr.Y" TYPE="DOUBLE" INDX="2" HOLDON="1"/>
    <ELEMENT TAG="RKorr.Z" TYPE="DOUBLE" INDX="3" HOLDON="1"/>
    <ELEMENT TAG="RKorr.A" TYPE="DOUBLE" INDX="4" HOLDON="1"/>
    <ELEMENT TAG="RKorr.B" TYPE="DOUBLE" INDX="5" HOLDON="1"/>
    <!-- a comment with <ELEMENT TAG="nope"/> inside -->
    <ELEMENT TAG="RKorr.C" TYPE="DOUBLE" INDX="6" HOLDON="1"/>
    <ELEMENT TAG="DiO" TYPE="LONG" INDX="7" HOLDON="1"/>
  </ELEMENTS></RECEIVE>
</ROOT>
"#;

    #[test]
    fn parses_the_spec_file() {
        let c = EthernetConfig::parse(SPEC).unwrap();
        assert_eq!(c.port, 49152);
        assert_eq!(c.sentype, "ImFree");
        assert_eq!(c.ip_number.as_deref(), Some("192.168.1.20"));
        assert!(!c.only_send);
        assert_eq!(c.send, ["DEF_RIst", "DEF_RSol", "DEF_Delay"]);
        assert_eq!(c.receive.len(), 7);
        assert_eq!(c.correction_element(), Some("RKorr"));
        let f = c.sen_format(4).unwrap();
        assert_eq!(f.sentype, "ImFree");
        assert_eq!(f.correction_element, "RKorr");
        assert_eq!(f.zero_elements, vec![("DiO".to_string(), vec![])]);
        assert!(c.warnings(CorrectionMode::Absolute).is_empty());
        let w = c.warnings(CorrectionMode::Relative);
        assert_eq!(w.len(), 6, "{w:?}");
        let line = w[0].to_string();
        assert!(
            line.contains("line 14") && line.contains("RKorr.X"),
            "{line}"
        );
    }

    #[test]
    fn errors_name_the_key_and_line() {
        let bad = SPEC.replace("<PORT>49152</PORT>", "<PORT>49x52</PORT>");
        assert_eq!(
            EthernetConfig::parse(&bad),
            Err(EthernetConfigError::BadValue {
                key: "PORT",
                value: "49x52".into(),
                line: 4
            })
        );
        let bad = SPEC.replace("<SENTYPE>ImFree</SENTYPE>", "");
        assert_eq!(
            EthernetConfig::parse(&bad),
            Err(EthernetConfigError::Missing { key: "SENTYPE" })
        );
        let bad = SPEC.replace(
            "HOLDON=\"1\"/>\n    <ELEMENT TAG=\"RKorr.Y\"",
            "HOLDON=\"yes\"/>\n    <ELEMENT TAG=\"RKorr.Y\"",
        );
        assert!(matches!(
            EthernetConfig::parse(&bad),
            Err(EthernetConfigError::BadValue {
                key: "HOLDON",
                line: 14,
                ..
            })
        ));
        let bad = SPEC.replace("RKorr.C", "RKorr.Q");
        assert_eq!(
            EthernetConfig::parse(&bad).unwrap().sen_format(4),
            Err(EthernetConfigError::NoCorrection)
        );
        let bad = SPEC.replace("<ONLYSEND>FALSE", "<ONLYSEND>TRUE");
        assert_eq!(
            EthernetConfig::parse(&bad).unwrap().sen_format(4),
            Err(EthernetConfigError::OnlySend)
        );
        assert!(matches!(
            EthernetConfig::parse("<ROOT><CONFIG><PORT>1</PORT"),
            Err(EthernetConfigError::Xml { .. })
        ));
    }
}
