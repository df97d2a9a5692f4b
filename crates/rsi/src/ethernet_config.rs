//! The controller-side `RSI_EthernetConfig.xml`: its CONFIG values (port,
//! SENTYPE, ONLYSEND) and SEND/RECEIVE element lists, turned into the
//! reply's spelling ([`SenFormat`]) so both sides agree, and checked against
//! the correction mode (HOLDON pairing). Pure: parses text handed in.

use crate::codec::{SenFormat, POSE_ATTRS};
use crate::law::CorrectionMode;
use crate::xml::{Token, Tokenizer};
use thiserror::Error;

/// Why an `RSI_EthernetConfig.xml` was rejected.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
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
    #[error("RSI_EthernetConfig.xml line {line}: bad {key} {value:?}")]
    BadValue {
        /// The key or attribute.
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

fn line_of(text: &str, at: usize) -> usize {
    text.as_bytes()[..at.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
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

impl EthernetConfig {
    /// Parses the file's text.
    pub fn parse(text: &str) -> Result<EthernetConfig, EthernetConfigError> {
        let mut t = Tokenizer::new(text.as_bytes());
        let mut path: Vec<String> = Vec::new();
        let mut ip = None;
        let mut port: Option<(String, usize)> = None;
        let mut sentype = None;
        let mut only_send: Option<(String, usize)> = None;
        let mut send = Vec::new();
        let mut receive = Vec::new();
        loop {
            let at = t.position();
            let tok = t.next().map_err(|e| EthernetConfigError::Xml {
                line: line_of(text, e.at),
                what: e.what.to_string(),
            })?;
            let Some(tok) = tok else { break };
            let line = line_of(text, at);
            match tok {
                Token::Start { name, attrs, empty } => {
                    let name = String::from_utf8_lossy(name).into_owned();
                    if name.eq_ignore_ascii_case("ELEMENT") {
                        let section = path.iter().find(|p| {
                            p.eq_ignore_ascii_case("SEND") || p.eq_ignore_ascii_case("RECEIVE")
                        });
                        let xml_err = |e: crate::xml::XmlError| EthernetConfigError::Xml {
                            line: line_of(text, e.at),
                            what: e.what.to_string(),
                        };
                        let tag = attrs.get(b"TAG").map_err(xml_err)?.ok_or(
                            EthernetConfigError::BadValue {
                                key: "TAG",
                                value: String::new(),
                                line,
                            },
                        )?;
                        let tag = String::from_utf8_lossy(tag).trim().to_string();
                        match section.map(|s| s.to_ascii_uppercase()).as_deref() {
                            Some("SEND") => send.push(tag),
                            Some("RECEIVE") => {
                                let h = match attrs.get(b"HOLDON").map_err(xml_err)? {
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
                                receive.push(ReceiveTag {
                                    element,
                                    attribute,
                                    holdon: h,
                                    line,
                                });
                            }
                            _ => {}
                        }
                    }
                    if !empty {
                        path.push(name);
                    }
                }
                Token::End { .. } => {
                    path.pop();
                }
                Token::Text(txt) => {
                    let in_config =
                        path.len() >= 2 && path[path.len() - 2].eq_ignore_ascii_case("CONFIG");
                    if !in_config {
                        continue;
                    }
                    let v = String::from_utf8_lossy(txt).trim().to_string();
                    match path.last().map(|s| s.to_ascii_uppercase()).as_deref() {
                        Some("IP_NUMBER") => ip = Some(v),
                        Some("PORT") => port = Some((v, line)),
                        Some("SENTYPE") => sentype = Some(v),
                        Some("ONLYSEND") => only_send = Some((v, line)),
                        _ => {}
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
        let sentype = sentype
            .filter(|s| !s.is_empty())
            .ok_or(EthernetConfigError::Missing { key: "SENTYPE" })?;
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
    /// with all of `X Y Z A B C` (`RKorr` preferred if several).
    pub fn correction_element(&self) -> Option<&str> {
        let mut found: Option<&str> = None;
        for r in &self.receive {
            let e = r.element.as_str();
            let full = POSE_ATTRS.iter().all(|a| {
                self.receive
                    .iter()
                    .any(|q| q.element == e && q.attribute.as_deref() == Some(a))
            });
            if full && (found.is_none() || e == "RKorr") {
                found = Some(e);
            }
        }
        found
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
        for r in self.receive.iter().filter(|r| r.element != corr) {
            match zero.iter_mut().find(|(e, _)| *e == r.element) {
                Some((_, attrs)) => attrs.extend(r.attribute.clone()),
                None => zero.push((r.element.clone(), r.attribute.clone().into_iter().collect())),
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
    /// needs `HOLDON="1"`, relative `HOLDON="0"`), `RSol` missing from SEND.
    pub fn warnings(&self, mode: CorrectionMode) -> Vec<String> {
        let mut w = Vec::new();
        let corr = self.correction_element();
        for r in self
            .receive
            .iter()
            .filter(|r| Some(r.element.as_str()) == corr)
        {
            let tag = format!("{}.{}", r.element, r.attribute.as_deref().unwrap_or(""));
            match (mode, r.holdon) {
                (CorrectionMode::Absolute, Some(true)) | (CorrectionMode::Relative, Some(false)) => {}
                (CorrectionMode::Absolute, h) => w.push(format!(
                    "line {}: {tag} has HOLDON={}; absolute mode needs HOLDON=\"1\" (one late packet would snap the robot back)",
                    r.line,
                    if h == Some(false) { "0" } else { "unset" }
                )),
                (CorrectionMode::Relative, h) => w.push(format!(
                    "line {}: {tag} has HOLDON={}; relative mode needs HOLDON=\"0\" (a held increment keeps moving the robot)",
                    r.line,
                    if h == Some(true) { "1" } else { "unset" }
                )),
            }
        }
        if !self.send.iter().any(|s| s.ends_with("RSol")) {
            w.push(
                "SEND list has no DEF_RSol: the commanded pose is unknown, corrections stay frozen"
                    .into(),
            );
        }
        w
    }
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
        assert!(
            w[0].contains("line 14") && w[0].contains("RKorr.X"),
            "{}",
            w[0]
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
