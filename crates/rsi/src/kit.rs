//! The KUKA integration kit (`photopose rsi kit`): the controller-side files
//! that fit a daemon configuration — the KRL program (`.src` + `.dat`), the
//! RSI context (`.rsix`: ETHERNET → POSCORR, POSCORRMON) and
//! `RSI_EthernetConfig.xml` — generated from the `[rsi]` section (or its
//! `ethernet_config` file) so that port, SENTYPE, element names, HOLDON,
//! IPO mode and the POSCORR limits agree with what the daemon does. Pure:
//! the texts are returned, the caller writes them. The XML files are
//! written with `quick-xml`.

use crate::codec::POSE_ATTRS;
use crate::config::{ConfigError, RsiConfig, RsiSettings};
use crate::ethernet_config::EthernetConfig;
use crate::law::{CorrFrame, CorrectionMode};
use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, BytesText, Event};
use quick_xml::Writer;
use std::io;
use std::net::IpAddr;
use thiserror::Error;

/// The file name of the controller's Ethernet configuration in the kit
/// (referenced by the context's ETHERNET object).
pub const ETHERNET_FILE: &str = "RSI_EthernetConfig.xml";
/// The RSI context's file name (referenced by the KRL program).
pub const CONTEXT_FILE: &str = "photopose.rsix";
/// The KRL module's name (`photopose.src`, `photopose.dat`).
pub const KRL_MODULE: &str = "photopose";
/// What `IP_NUMBER` holds when the sensor PC's address is not known.
pub const SENSOR_IP_PLACEHOLDER: &str = "SENSOR_PC_IP";
/// The SEND list the kit writes: the actual pose, the commanded pose and
/// the late-packet counter.
pub const SEND_TAGS: [&str; 3] = ["DEF_RIst", "DEF_RSol", "DEF_Delay"];

/// Why the kit cannot be generated.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum KitError {
    /// The `[rsi]` section (or its controller file) is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// `cycle_ms` is neither of the controller's two IPO modes.
    #[error("[rsi] cycle_ms = {cycle_ms}: a KUKA controller runs RSI at 4 ms (#IPO_FAST) or 12 ms (#IPO)")]
    Cycle {
        /// The configured cycle, ms.
        cycle_ms: f64,
    },
    /// `Timeout` out of range.
    #[error("timeout {timeout}: the ETHERNET object's Timeout must be 1..=10000 late packets")]
    Timeout {
        /// The value given.
        timeout: u32,
    },
    /// Writing the XML failed (never expected: the writer writes to memory).
    #[error("writing {file}: {what}")]
    Write {
        /// The file being written.
        file: &'static str,
        /// What went wrong.
        what: String,
    },
}

/// How the kit is written beyond what the configuration says.
#[derive(Debug, Clone, PartialEq)]
pub struct KitOptions {
    /// The sensor PC's address as the controller reaches it (`IP_NUMBER`);
    /// `None`: `bind` when it is a specific address, else the controller
    /// file's `IP_NUMBER`, else a placeholder.
    pub sensor_ip: Option<IpAddr>,
    /// The ETHERNET object's `Timeout`: late packets before RSI stops.
    pub timeout: u32,
    /// Where the configuration came from, for the files' comments.
    pub origin: String,
}

impl Default for KitOptions {
    fn default() -> Self {
        KitOptions {
            sensor_ip: None,
            timeout: 100,
            origin: "the built-in configuration".into(),
        }
    }
}

/// One generated file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KitFile {
    /// The file name (no folder).
    pub name: &'static str,
    /// Its contents.
    pub text: String,
}

/// The generated kit.
#[derive(Debug, Clone, PartialEq)]
pub struct Kit {
    /// The files, in the order an integrator copies them.
    pub files: Vec<KitFile>,
    /// What the integrator must still do or know (a placeholder left, a
    /// limit that cuts), one sentence each.
    pub notes: Vec<String>,
    /// The POSCORR and POSCORRMON limits written into the context.
    pub limits: KitLimits,
}

/// The limits of the context, derived from the daemon's configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KitLimits {
    /// POSCORR `LowerLimX/Y/Z` = −this, `UpperLimX/Y/Z` = +this, mm
    /// (`poscorr_limit_mm`).
    pub poscorr_mm: f64,
    /// POSCORR `MaxRotAngle`, degrees (`poscorr_limit_deg`).
    pub poscorr_deg: f64,
    /// POSCORRMON `MaxTrans`, mm: the farthest POSCORR lets the TCP go (its
    /// box's diagonal, rounded up to 1 µm), so the monitor never fires
    /// below POSCORR's limit nor below the daemon's clamp.
    pub monitor_mm: f64,
    /// POSCORRMON `MaxRotAngle`, degrees (POSCORR's).
    pub monitor_deg: f64,
}

/// Which IPO mode a cycle is.
fn ipo_mode(cycle_ms: f64) -> Result<&'static str, KitError> {
    if (cycle_ms - 4.0).abs() < 1e-9 {
        Ok("#IPO_FAST")
    } else if (cycle_ms - 12.0).abs() < 1e-9 {
        Ok("#IPO")
    } else {
        Err(KitError::Cycle { cycle_ms })
    }
}

/// `RefCorrSys` of POSCORR: KUKA's coordinate-system enumeration as the
/// context stores it (World 0, Base 1, RobRoot 2, Tool 3).
fn ref_corr_sys(frame: CorrFrame) -> &'static str {
    match frame {
        CorrFrame::Base => "1",
        CorrFrame::Tool => "3",
    }
}

fn mode_krl(mode: CorrectionMode) -> &'static str {
    match mode {
        CorrectionMode::Relative => "#RELATIVE",
        CorrectionMode::Absolute => "#ABSOLUTE",
    }
}

/// `v` rounded up to 0.001 (a monitor limit must never fall below what
/// it guards).
fn up_to_um(v: f64) -> f64 {
    (v * 1000.0).ceil() / 1000.0
}

/// A number as the files print it: shortest form, rounded up to 0.001.
fn num(v: f64) -> String {
    format!("{}", up_to_um(v))
}

/// Generates the kit for `config` (`ethernet_xml`: the text of the file its
/// `ethernet_config` names, as for [`RsiConfig::settings`]).
pub fn generate(
    config: &RsiConfig,
    ethernet_xml: Option<&str>,
    options: &KitOptions,
) -> Result<Kit, KitError> {
    let settings = config.settings(ethernet_xml)?;
    let ipo = ipo_mode(config.cycle_ms)?;
    if !(1..=10_000).contains(&options.timeout) {
        return Err(KitError::Timeout {
            timeout: options.timeout,
        });
    }
    let existing = match ethernet_xml {
        Some(xml) => Some(EthernetConfig::parse(xml).map_err(ConfigError::from)?),
        None => None,
    };
    let mut notes = Vec::new();
    let bind_ip = settings.bind.ip();
    let sensor_ip = options
        .sensor_ip
        .or((!bind_ip.is_unspecified()).then_some(bind_ip))
        .map(|ip| ip.to_string())
        .or_else(|| existing.as_ref().and_then(|e| e.ip_number.clone()));
    if sensor_ip.is_none() {
        notes.push(format!(
            "{ETHERNET_FILE}: IP_NUMBER is the placeholder {SENSOR_IP_PLACEHOLDER} ([rsi] bind = \"{bind_ip}\" names no address): replace it with the sensor PC's address as the controller reaches it, or run the kit again with --sensor-ip ADDR"
        ));
    }
    if let Some(e) = &existing {
        let corr = e.correction_element();
        let dropped: Vec<String> = e
            .send
            .iter()
            .filter(|s| !SEND_TAGS.contains(&s.as_str()))
            .cloned()
            .chain(
                e.receive
                    .iter()
                    .filter(|r| Some(r.element.as_str()) != corr)
                    .map(|r| match &r.attribute {
                        Some(a) => format!("{}.{a}", r.element),
                        None => r.element.clone(),
                    }),
            )
            .collect();
        if !dropped.is_empty() {
            notes.push(format!(
                "{ETHERNET_FILE}: the kit's file carries only the correction; the existing file's other elements are not in it: {}",
                dropped.join(", ")
            ));
        }
    }
    let limits = KitLimits {
        poscorr_mm: config.poscorr_limit_mm,
        poscorr_deg: config.poscorr_limit_deg,
        monitor_mm: up_to_um(config.poscorr_limit_mm * 3f64.sqrt()),
        monitor_deg: config.poscorr_limit_deg,
    };
    // The three angles at their clamp together turn up to √3 × clamp_deg
    // (small angles): POSCORR's single MaxRotAngle would cut below the clamp.
    let joint_deg = settings.law.clamp_deg * 3f64.sqrt();
    if joint_deg > limits.poscorr_deg {
        notes.push(format!(
            "POSCORR MaxRotAngle {} deg is below the {:.3} deg that A, B and C at clamp_deg = {} reach together: POSCORR may cut a correction the daemon allows; lower clamp_deg to {:.3} or raise poscorr_limit_deg",
            num(limits.poscorr_deg),
            joint_deg,
            settings.law.clamp_deg,
            limits.poscorr_deg / 3f64.sqrt()
        ));
    }
    let ethernet = ethernet_file(&settings, sensor_ip.as_deref(), options)?;
    let context = context_file(&settings, &limits, options)?;
    let (src, dat) = krl_files(&settings, ipo, options);
    Ok(Kit {
        files: vec![
            KitFile {
                name: ETHERNET_FILE,
                text: ethernet,
            },
            KitFile {
                name: CONTEXT_FILE,
                text: context,
            },
            KitFile {
                name: "photopose.src",
                text: src,
            },
            KitFile {
                name: "photopose.dat",
                text: dat,
            },
        ],
        notes,
        limits,
    })
}

type Xml = Writer<Vec<u8>>;

fn start(w: &mut Xml, name: &str, attrs: &[(&str, &str)]) -> io::Result<()> {
    let mut e = BytesStart::new(name);
    e.extend_attributes(attrs.iter().copied());
    w.write_event(Event::Start(e))
}

fn end(w: &mut Xml, name: &str) -> io::Result<()> {
    w.write_event(Event::End(BytesEnd::new(name)))
}

fn empty(w: &mut Xml, name: &str, attrs: &[(&str, &str)]) -> io::Result<()> {
    let mut e = BytesStart::new(name);
    e.extend_attributes(attrs.iter().copied());
    w.write_event(Event::Empty(e))
}

fn text_element(w: &mut Xml, name: &str, text: &str) -> io::Result<()> {
    start(w, name, &[])?;
    w.write_event(Event::Text(BytesText::new(text)))?;
    end(w, name)
}

fn comment(w: &mut Xml, text: &str) -> io::Result<()> {
    w.write_event(Event::Comment(BytesText::from_escaped(format!(" {text} "))))
}

fn document(
    file: &'static str,
    body: impl FnOnce(&mut Xml) -> io::Result<()>,
) -> Result<String, KitError> {
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    let written = w
        .write_event(Event::Decl(BytesDecl::new("1.0", Some("utf-8"), None)))
        .and_then(|()| body(&mut w));
    let fail = |what: String| KitError::Write { file, what };
    written.map_err(|e| fail(e.to_string()))?;
    let mut text = String::from_utf8(w.into_inner()).map_err(|e| fail(e.to_string()))?;
    text.push('\n');
    Ok(text)
}

fn ethernet_file(
    s: &RsiSettings,
    sensor_ip: Option<&str>,
    options: &KitOptions,
) -> Result<String, KitError> {
    let holdon = match s.law.mode {
        CorrectionMode::Relative => "0",
        CorrectionMode::Absolute => "1",
    };
    let port = s.bind.port().to_string();
    document(ETHERNET_FILE, |w| {
        comment(
            w,
            &format!(
                "RSI Ethernet configuration for photopose, generated by `photopose rsi kit` from {}. Copy to C:\\KRC\\ROBOTER\\Config\\User\\Common\\SensorInterface on the controller. The daemon reads this same file as [rsi] ethernet_config.",
                options.origin.replace("--", "- -")
            ),
        )?;
        start(w, "ROOT", &[])?;
        start(w, "CONFIG", &[])?;
        match sensor_ip {
            Some(ip) => {
                comment(w, "the sensor PC (photopose) as the controller reaches it")?;
                text_element(w, "IP_NUMBER", ip)?;
            }
            None => {
                comment(
                    w,
                    "ADAPT: replace with the sensor PC's IP address (or run photopose rsi kit with sensor-ip)",
                )?;
                text_element(w, "IP_NUMBER", SENSOR_IP_PLACEHOLDER)?;
            }
        }
        text_element(w, "PORT", &port)?;
        comment(w, "SENTYPE is the Type of the sensor's replies")?;
        text_element(w, "SENTYPE", &s.sen.sentype)?;
        text_element(w, "ONLYSEND", "FALSE")?;
        end(w, "CONFIG")?;
        start(w, "SEND", &[])?;
        start(w, "ELEMENTS", &[])?;
        for tag in SEND_TAGS {
            // The late-packet counter is a whole number.
            let ty = if tag == "DEF_Delay" { "LONG" } else { "DOUBLE" };
            empty(
                w,
                "ELEMENT",
                &[("TAG", tag), ("TYPE", ty), ("INDX", "INTERNAL")],
            )?;
        }
        end(w, "ELEMENTS")?;
        end(w, "SEND")?;
        start(w, "RECEIVE", &[])?;
        start(w, "ELEMENTS", &[])?;
        comment(
            w,
            &format!(
                "the correction, {} mode: HOLDON=\"{holdon}\"",
                match s.law.mode {
                    CorrectionMode::Relative => "relative",
                    CorrectionMode::Absolute => "absolute",
                }
            ),
        )?;
        for (i, a) in POSE_ATTRS.iter().enumerate() {
            let tag = format!("{}.{a}", s.sen.correction_element);
            let indx = (i + 1).to_string();
            empty(
                w,
                "ELEMENT",
                &[
                    ("TAG", tag.as_str()),
                    ("TYPE", "DOUBLE"),
                    ("INDX", indx.as_str()),
                    ("HOLDON", holdon),
                ],
            )?;
        }
        end(w, "ELEMENTS")?;
        end(w, "RECEIVE")?;
        end(w, "ROOT")
    })
}

fn context_file(
    s: &RsiSettings,
    limits: &KitLimits,
    options: &KitOptions,
) -> Result<String, KitError> {
    let mm = num(limits.poscorr_mm);
    let neg_mm = format!("-{mm}");
    let deg = num(limits.poscorr_deg);
    let timeout = options.timeout.to_string();
    document(CONTEXT_FILE, |w| {
        comment(
            w,
            &format!(
                "RSI context for photopose, generated by `photopose rsi kit` from {}: ETHERNET (the sensor's correction) into POSCORR, watched by POSCORRMON. Limits match the daemon's poscorr_limit_mm/deg; its clamp sits inside them. Copy to C:\\KRC\\ROBOTER\\Config\\User\\Common\\SensorInterface; open it in RSIVisual to review.",
                options.origin.replace("--", "- -")
            ),
        )?;
        start(w, "RsiContext", &[])?;
        start(w, "RsiObjects", &[])?;
        start(
            w,
            "RsiObject",
            &[
                ("ObjTypeId", "64"),
                ("ObjType", "Ethernet"),
                ("ObjId", "Ethernet_1"),
            ],
        )?;
        start(w, "Parameters", &[])?;
        empty(
            w,
            "Parameter",
            &[
                ("IsRuntime", "false"),
                ("Name", "ConfigFile"),
                ("ParamId", "0"),
                ("ParamValue", ETHERNET_FILE),
            ],
        )?;
        comment(w, "late or missing replies tolerated before RSI stops")?;
        empty(
            w,
            "Parameter",
            &[
                ("Name", "Timeout"),
                ("ParamId", "0"),
                ("ParamValue", timeout.as_str()),
            ],
        )?;
        end(w, "Parameters")?;
        end(w, "RsiObject")?;
        start(
            w,
            "RsiObject",
            &[
                ("ObjTypeId", "27"),
                ("ObjType", "PosCorr"),
                ("ObjId", "PosCorr_1"),
            ],
        )?;
        start(w, "Inputs", &[])?;
        for i in 0..6 {
            let idx = i.to_string();
            empty(
                w,
                "Input",
                &[
                    ("InIdx", idx.as_str()),
                    ("OutObjId", "Ethernet_1"),
                    ("OutIdx", idx.as_str()),
                ],
            )?;
        }
        end(w, "Inputs")?;
        start(w, "Parameters", &[])?;
        let params: [(&str, &str); 7] = [
            ("LowerLimX", &neg_mm),
            ("LowerLimY", &neg_mm),
            ("LowerLimZ", &neg_mm),
            ("UpperLimX", &mm),
            ("UpperLimY", &mm),
            ("UpperLimZ", &mm),
            ("MaxRotAngle", &deg),
        ];
        for (id, (name, value)) in params.iter().enumerate() {
            let id = id.to_string();
            empty(
                w,
                "Parameter",
                &[("Name", name), ("ParamId", &id), ("ParamValue", value)],
            )?;
        }
        comment(
            w,
            &format!(
                "RefCorrSys: the daemon's frame = \"{}\" (1 Base, 3 Tool)",
                match s.law.frame {
                    CorrFrame::Base => "base",
                    CorrFrame::Tool => "tool",
                }
            ),
        )?;
        empty(
            w,
            "Parameter",
            &[
                ("IsRuntime", "false"),
                ("Name", "RefCorrSys"),
                ("ParamId", "0"),
                ("ParamValue", ref_corr_sys(s.law.frame)),
            ],
        )?;
        end(w, "Parameters")?;
        end(w, "RsiObject")?;
        start(
            w,
            "RsiObject",
            &[
                ("ObjTypeId", "81"),
                ("ObjType", "PosCorrMon"),
                ("ObjId", "PosCorrMon_1"),
            ],
        )?;
        start(w, "Parameters", &[])?;
        let max_trans = num(limits.monitor_mm);
        let max_rot = num(limits.monitor_deg);
        empty(
            w,
            "Parameter",
            &[
                ("IsRuntime", "false"),
                ("Name", "MaxTrans"),
                ("ParamId", "0"),
                ("ParamValue", max_trans.as_str()),
            ],
        )?;
        empty(
            w,
            "Parameter",
            &[
                ("IsRuntime", "false"),
                ("Name", "MaxRotAngle"),
                ("ParamId", "1"),
                ("ParamValue", max_rot.as_str()),
            ],
        )?;
        end(w, "Parameters")?;
        end(w, "RsiObject")?;
        end(w, "RsiObjects")?;
        start(w, "Editor", &[])?;
        start(w, "Links", &[])?;
        for (i, a) in POSE_ATTRS.iter().enumerate() {
            let from = format!("Out{}", i + 1);
            let to = format!("Corr{a}");
            empty(
                w,
                "Link",
                &[
                    ("From", "Ethernet_1"),
                    ("FromPort", from.as_str()),
                    ("To", "PosCorr_1"),
                    ("ToPort", to.as_str()),
                ],
            )?;
        }
        end(w, "Links")?;
        start(w, "Nodes", &[])?;
        for (name, ty, at) in [
            ("Ethernet_1", "Ethernet", "-400,-180"),
            ("PosCorr_1", "PosCorr", "200,-180"),
            ("PosCorrMon_1", "PosCorrMon", "500,-180"),
        ] {
            empty(w, "Node", &[("Location", at), ("Name", name), ("Type", ty)])?;
        }
        end(w, "Nodes")?;
        end(w, "Editor")?;
        end(w, "RsiContext")
    })
}

fn krl_files(s: &RsiSettings, ipo: &str, options: &KitOptions) -> (String, String) {
    let mode = mode_krl(s.law.mode);
    let cycle_ms = s.cycle.as_secs_f64() * 1e3;
    let origin = options.origin.replace('\n', " ");
    let src = format!(
        "&ACCESS RVP
&REL 1
DEF {KRL_MODULE}( )
; photopose RSI correction, generated by `photopose rsi kit` from
; {origin}.
; Mode {mode} and {ipo} ({cycle_ms} ms) match the daemon's [rsi] mode and
; cycle_ms: change them there and generate the kit again, not here.
; ADAPT before the first run:
;  - the tool and base below ($TOOL/$BASE) and the start position;
;  - the motion: RSI_MOVECORR() is a motion made of the correction
;    alone and lasts until RSI stops it (Timeout, a STOP object); to
;    correct a programmed path, put your LIN/CIRC motions between RSI_ON
;    and RSI_OFF instead;
;  - commission first with the daemon's measure_only = true.
DECL INT ret
DECL INT CONTID

BAS(#INITMOV, 0)

; ADAPT: the TCP and base the correction is applied to
; $TOOL = TOOL_DATA[1]
; $BASE = BASE_DATA[1]
; ADAPT: the start position
PTP $POS_ACT

; create the context from {CONTEXT_FILE} (reads {ETHERNET_FILE})
ret = RSI_CREATE(\"{CONTEXT_FILE}\", CONTID, TRUE)
IF (ret <> RSIOK) THEN
  HALT
ENDIF

; switch the correction on: {mode}, {ipo}
ret = RSI_ON({mode}, {ipo})
IF (ret <> RSIOK) THEN
  HALT
ENDIF

; the sensor-guided motion: runs until RSI stops
RSI_MOVECORR()

; switch the correction off and free the context
ret = RSI_OFF()
IF (ret <> RSIOK) THEN
  HALT
ENDIF
RSI_DELETE(CONTID)

END
"
    );
    let dat = format!(
        "&ACCESS RVP
&REL 1
DEFDAT {KRL_MODULE} PUBLIC
; Data of {KRL_MODULE}.src (generated by `photopose rsi kit`).
; ADAPT: declare positions taught for the program here.
ENDDAT
"
    );
    (src, dat)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(mode: CorrectionMode) -> RsiConfig {
        RsiConfig {
            enabled: true,
            bind: "192.168.1.20".into(),
            port: Some(59152),
            controllers: vec!["192.168.1.10".into()],
            sentype: Some("PhotoPose".into()),
            mode,
            ..RsiConfig::default()
        }
    }

    fn file<'k>(kit: &'k Kit, name: &str) -> &'k str {
        &kit.files.iter().find(|f| f.name == name).unwrap().text
    }

    #[test]
    fn the_ethernet_file_is_one_the_daemon_accepts() {
        for mode in [CorrectionMode::Relative, CorrectionMode::Absolute] {
            let c = config(mode);
            let kit = generate(&c, None, &KitOptions::default()).unwrap();
            let xml = file(&kit, ETHERNET_FILE);
            let e = EthernetConfig::parse(xml).unwrap();
            assert_eq!(e.port, 59152);
            assert_eq!(e.sentype, "PhotoPose");
            assert_eq!(e.ip_number.as_deref(), Some("192.168.1.20"));
            assert!(e.warnings(mode).is_empty(), "{:?}", e.warnings(mode));
            let from_file = RsiConfig {
                port: None,
                sentype: None,
                ethernet_config: Some(ETHERNET_FILE.into()),
                ..c.clone()
            };
            let s = from_file.settings(Some(xml)).unwrap();
            assert_eq!(s, RsiConfig { ..c }.settings(None).unwrap());
        }
    }

    #[test]
    fn a_controller_file_is_followed_and_what_is_left_out_said() {
        let xml = "<ROOT><CONFIG><IP_NUMBER>10.0.0.9</IP_NUMBER><PORT>50000</PORT><SENTYPE>Cell</SENTYPE></CONFIG>\
            <SEND><ELEMENTS><ELEMENT TAG=\"DEF_RSol\"/><ELEMENT TAG=\"DEF_Tech.C1\"/></ELEMENTS></SEND><RECEIVE><ELEMENTS>\
            <ELEMENT TAG=\"Corr.X\" HOLDON=\"0\"/><ELEMENT TAG=\"Corr.Y\" HOLDON=\"0\"/><ELEMENT TAG=\"Corr.Z\" HOLDON=\"0\"/>\
            <ELEMENT TAG=\"Corr.A\" HOLDON=\"0\"/><ELEMENT TAG=\"Corr.B\" HOLDON=\"0\"/><ELEMENT TAG=\"Corr.C\" HOLDON=\"0\"/>\
            <ELEMENT TAG=\"DiO\" HOLDON=\"0\"/></ELEMENTS></RECEIVE></ROOT>";
        let c = RsiConfig {
            bind: "0.0.0.0".into(),
            ethernet_config: Some("RSI_EthernetConfig.xml".into()),
            ..RsiConfig::default()
        };
        let kit = generate(&c, Some(xml), &KitOptions::default()).unwrap();
        let e = EthernetConfig::parse(file(&kit, ETHERNET_FILE)).unwrap();
        assert_eq!((e.port, e.sentype.as_str()), (50000, "Cell"));
        assert_eq!(e.correction_element(), Some("Corr"));
        assert_eq!(
            e.ip_number.as_deref(),
            Some("10.0.0.9"),
            "kept from the file"
        );
        assert!(
            kit.notes.iter().any(|n| n.contains("DEF_Tech.C1, DiO")),
            "{:?}",
            kit.notes
        );
    }

    #[test]
    fn krl_follows_mode_and_cycle() {
        let kit = generate(
            &config(CorrectionMode::Absolute),
            None,
            &KitOptions::default(),
        )
        .unwrap();
        let src = file(&kit, "photopose.src");
        assert!(src.contains("RSI_ON(#ABSOLUTE, #IPO_FAST)"), "{src}");
        for call in [
            "RSI_CREATE(\"photopose.rsix\"",
            "RSI_MOVECORR()",
            "RSI_OFF()",
            "RSI_DELETE(",
        ] {
            assert!(src.contains(call), "{call}: {src}");
        }
        let slow = RsiConfig {
            cycle_ms: 12.0,
            session_idle_ms: 100.0,
            ..config(CorrectionMode::Relative)
        };
        let kit = generate(&slow, None, &KitOptions::default()).unwrap();
        assert!(file(&kit, "photopose.src").contains("RSI_ON(#RELATIVE, #IPO)"));
        let odd = RsiConfig {
            cycle_ms: 8.0,
            ..config(CorrectionMode::Relative)
        };
        assert_eq!(
            generate(&odd, None, &KitOptions::default()),
            Err(KitError::Cycle { cycle_ms: 8.0 })
        );
    }

    #[test]
    fn a_wildcard_bind_leaves_a_placeholder_and_a_note() {
        let c = RsiConfig {
            bind: "0.0.0.0".into(),
            ..config(CorrectionMode::Relative)
        };
        let kit = generate(&c, None, &KitOptions::default()).unwrap();
        let xml = file(&kit, ETHERNET_FILE);
        assert!(xml.contains(SENSOR_IP_PLACEHOLDER), "{xml}");
        assert!(kit.notes.iter().any(|n| n.contains("--sensor-ip")));
        let with_ip = KitOptions {
            sensor_ip: Some("10.1.2.3".parse().unwrap()),
            ..KitOptions::default()
        };
        let kit = generate(&c, None, &with_ip).unwrap();
        assert!(file(&kit, ETHERNET_FILE).contains("<IP_NUMBER>10.1.2.3</IP_NUMBER>"));
        assert!(kit.notes.is_empty(), "{:?}", kit.notes);
    }

    #[test]
    fn limits_hold_the_clamp() {
        let kit = generate(
            &config(CorrectionMode::Relative),
            None,
            &KitOptions::default(),
        )
        .unwrap();
        let l = kit.limits;
        let law = crate::law::LawConfig::default();
        assert!(law.clamp_mm < l.poscorr_mm);
        assert!(law.clamp_mm * 3f64.sqrt() <= l.monitor_mm);
        assert!(law.clamp_deg < l.poscorr_deg && l.poscorr_deg <= l.monitor_deg);
        let rsix = file(&kit, CONTEXT_FILE);
        assert!(
            rsix.contains("Name=\"LowerLimX\" ParamId=\"0\" ParamValue=\"-5\""),
            "{rsix}"
        );
        assert!(
            rsix.contains("Name=\"MaxTrans\" ParamId=\"0\" ParamValue=\"8.661\""),
            "{rsix}"
        );
        // A rotation clamp POSCORR would cut is said.
        let tight = RsiConfig {
            clamp_deg: 4.0,
            ..config(CorrectionMode::Relative)
        };
        let kit = generate(&tight, None, &KitOptions::default()).unwrap();
        assert!(
            kit.notes.iter().any(|n| n.contains("MaxRotAngle")),
            "{:?}",
            kit.notes
        );
    }
}
