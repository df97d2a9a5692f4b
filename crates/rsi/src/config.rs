//! The `[rsi]` section of the daemon's TOML config ([`RsiConfig`], unknown
//! keys rejected) and its validation into the server's settings
//! ([`RsiSettings`]), optionally merged with the controller's own
//! `RSI_EthernetConfig.xml` (its text handed in). Pure.

use crate::codec::{SenFormat, MAX_DATAGRAM, POSE_ATTRS};
use crate::ethernet_config::{EthernetConfig, EthernetConfigError};
use crate::law::{CorrFrame, CorrectionMode, LawConfig};
use crate::warning::RsiWarning;
use crate::xml::is_xml_name;
use serde::{Deserialize, Serialize};
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::time::Duration;
use thiserror::Error;

/// An IP address as written, or the address a host name resolves to now
/// (its IPv4 address if it has one).
fn host_ip(text: &str) -> Option<IpAddr> {
    use std::net::ToSocketAddrs;
    if let Ok(ip) = text.parse::<IpAddr>() {
        return Some(ip);
    }
    if text.is_empty() {
        return None;
    }
    let found: Vec<IpAddr> = (text, 0u16)
        .to_socket_addrs()
        .ok()?
        .map(|a| a.ip())
        .collect();
    found
        .iter()
        .find(|ip| ip.is_ipv4())
        .or(found.first())
        .copied()
}

/// Why the `[rsi]` section was rejected.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The TOML does not parse or has an unknown key.
    #[error("[rsi]: {0}")]
    Toml(String),
    /// A key's value is out of range or malformed.
    #[error("[rsi] {key} = {value}: {why}")]
    Invalid {
        /// The key.
        key: &'static str,
        /// The value as written.
        value: String,
        /// Why it is wrong.
        why: &'static str,
    },
    /// A key given both in `[rsi]` and by the controller's file.
    #[error("[rsi] {key} is taken from ethernet_config; remove it from [rsi]")]
    Conflict {
        /// The key.
        key: &'static str,
    },
    /// `ethernet_config` is set but its text was not handed in.
    #[error("[rsi] ethernet_config is set but the file's text was not read")]
    EthernetNotRead,
    /// The controller's file is invalid.
    #[error(transparent)]
    Ethernet(#[from] EthernetConfigError),
    /// The reply the controller's RECEIVE list asks for is larger than a
    /// datagram may be.
    #[error("the reply for this RECEIVE list takes up to {len} bytes, more than the {limit}-byte datagram limit: remove RECEIVE elements")]
    ReplyTooLarge {
        /// The longest reply, bytes.
        len: usize,
        /// The limit, bytes.
        limit: usize,
    },
}

/// The `[rsi]` section. Every key has a default; unknown keys are errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RsiConfig {
    /// Run the RSI server.
    pub enabled: bool,
    /// Local IP address to bind (`"0.0.0.0"`: all interfaces).
    pub bind: String,
    /// UDP port; taken from `ethernet_config`'s `PORT` when that is set.
    pub port: Option<u16>,
    /// Controller IP addresses that are answered; datagrams from any other
    /// address are dropped. Must not be empty when enabled.
    pub controllers: Vec<String>,
    /// Path of the controller's `RSI_EthernetConfig.xml`: port, SENTYPE and
    /// element names then come from it (and must not be set here).
    pub ethernet_config: Option<PathBuf>,
    /// Reply root `Type` (the controller's SENTYPE), default `"ImFree"`.
    pub sentype: Option<String>,
    /// Reply correction element, default `"RKorr"`.
    pub correction_element: Option<String>,
    /// Fixed decimals printed in replies, 4–6.
    pub decimals: usize,
    /// `"relative"` (pair with HOLDON="0") or `"absolute"` (HOLDON="1").
    pub mode: CorrectionMode,
    /// POSCORR frame the controller applies RKorr in: `"base"` or `"tool"`.
    pub frame: CorrFrame,
    /// Answer with zero correction (commissioning).
    pub measure_only: bool,
    /// The controller's RSol already includes the RSI correction.
    pub rsol_includes_correction: bool,
    /// Share of each new measurement's error taken, (0, 1].
    pub gain: f64,
    /// Per-cycle slew limit of each translation component, mm.
    pub max_step_mm: f64,
    /// Per-cycle slew limit of each angle component, degrees.
    pub max_step_deg: f64,
    /// Total clamp of each translation component, mm (< `poscorr_limit_mm`).
    pub clamp_mm: f64,
    /// Total clamp of each angle component, degrees (< `poscorr_limit_deg`).
    pub clamp_deg: f64,
    /// The controller's POSCORR translation limit, mm (default ±5).
    pub poscorr_limit_mm: f64,
    /// The controller's POSCORR `MaxRotAngle`, degrees (default 5).
    pub poscorr_limit_deg: f64,
    /// A measurement older than this freezes the correction, ms.
    pub max_age_ms: f64,
    /// A measurement with fewer targets freezes the correction.
    pub min_targets: u32,
    /// A measurement with a position std above this freezes, mm.
    pub max_std_mm: f64,
    /// A measurement with a rotation std above this freezes, degrees.
    pub max_std_deg: f64,
    /// The controller's cycle, ms (4 with `#IPO_FAST`, 12 with `#IPO`): the
    /// reference of the jitter statistics.
    pub cycle_ms: f64,
    /// Silence after which the controller session may restart, ms: a
    /// datagram from another port of a listed address, or a smaller IPOC,
    /// opens a new session only after the current one has not advanced for
    /// this long (RSI restarted on the controller).
    pub session_idle_ms: f64,
    /// How long before a `<Rob>` datagram arrives the controller sampled
    /// its `RIst`/`RSol` (at the start of its cycle), ms: each cycle is
    /// placed on the host clock at its arrival minus this.
    pub controller_latency_ms: f64,
    /// Feed-forward of the error's rate over the measurement's age (off
    /// by default; see docs/rsi.md).
    pub feed_forward: bool,
    /// Compare each measurement with the programmed pose at its exposure
    /// instant (default); `false` compares it with the newest cycle's, as a
    /// system that ignores the frame's age would (a contrast for demos and
    /// commissioning; see docs/rsi.md).
    pub compensate_latency: bool,
    /// SCHED_FIFO priority (1–99) of the RSI thread; failing to get it is a
    /// warning.
    pub realtime_priority: Option<u8>,
    /// CPU core to pin the RSI thread to.
    pub cpu: Option<usize>,
    /// The hand-eye file (`photopose calibrate hand-eye`): `X` and `Z` of
    /// the correction law. The daemon requires it when enabled and reads it.
    pub hand_eye: Option<PathBuf>,
}

impl Default for RsiConfig {
    fn default() -> Self {
        let law = LawConfig::default();
        RsiConfig {
            enabled: false,
            bind: "0.0.0.0".into(),
            port: None,
            controllers: Vec::new(),
            ethernet_config: None,
            sentype: None,
            correction_element: None,
            decimals: 4,
            mode: law.mode,
            frame: law.frame,
            measure_only: law.measure_only,
            rsol_includes_correction: law.rsol_includes_correction,
            gain: law.gain,
            max_step_mm: law.max_step_mm,
            max_step_deg: law.max_step_deg,
            clamp_mm: law.clamp_mm,
            clamp_deg: law.clamp_deg,
            poscorr_limit_mm: 5.0,
            poscorr_limit_deg: 5.0,
            max_age_ms: law.max_age_s * 1e3,
            min_targets: law.min_targets,
            max_std_mm: law.max_std_mm,
            max_std_deg: law.max_std_deg,
            cycle_ms: 4.0,
            session_idle_ms: 100.0,
            controller_latency_ms: law.controller_latency_s * 1e3,
            feed_forward: law.feed_forward,
            compensate_latency: law.compensate_latency,
            realtime_priority: None,
            cpu: None,
            hand_eye: None,
        }
    }
}

/// Everything the server needs, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct RsiSettings {
    /// Local address and port.
    pub bind: SocketAddr,
    /// Addresses answered.
    pub controllers: Vec<IpAddr>,
    /// Reply spelling.
    pub sen: SenFormat,
    /// The correction law's parameters.
    pub law: LawConfig,
    /// The controller's cycle.
    pub cycle: Duration,
    /// Silence after which the controller session may restart.
    pub session_idle: Duration,
    /// SCHED_FIFO priority.
    pub realtime_priority: Option<u8>,
    /// CPU core to pin to.
    pub cpu: Option<usize>,
    /// Consistency warnings to report (HOLDON pairing, ...): the same list
    /// for `check-config` and `run`.
    pub warnings: Vec<RsiWarning>,
}

impl RsiSettings {
    /// The size of the reply buffer: the longest reply this format writes
    /// for corrections inside the clamp.
    pub fn reply_capacity(&self) -> usize {
        self.sen
            .reply_len_bound(self.law.clamp_mm.max(self.law.clamp_deg))
    }
}

fn positive(key: &'static str, v: f64) -> Result<f64, ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(ConfigError::Invalid {
            key,
            value: v.to_string(),
            why: "must be a positive number",
        })
    }
}

/// A positive number at most `max`.
fn positive_up_to(
    key: &'static str,
    v: f64,
    max: f64,
    why: &'static str,
) -> Result<f64, ConfigError> {
    let v = positive(key, v)?;
    if v > max {
        return Err(ConfigError::Invalid {
            key,
            value: v.to_string(),
            why,
        });
    }
    Ok(v)
}

/// Largest POSCORR translation limit accepted, mm.
pub const MAX_POSCORR_MM: f64 = 1000.0;
/// Largest POSCORR rotation limit accepted, degrees.
pub const MAX_POSCORR_DEG: f64 = 180.0;

impl RsiConfig {
    /// Parses a TOML document whose `[rsi]` table is this section (other
    /// tables are ignored; unknown keys inside `[rsi]` are errors).
    pub fn from_toml(text: &str) -> Result<RsiConfig, ConfigError> {
        #[derive(Deserialize)]
        struct Doc {
            #[serde(default)]
            rsi: RsiConfig,
        }
        toml::from_str::<Doc>(text)
            .map(|d| d.rsi)
            .map_err(|e| ConfigError::Toml(e.to_string()))
    }

    /// Validates the section into settings. `ethernet_xml` is the text of
    /// the file named by `ethernet_config` (the caller reads it).
    pub fn settings(&self, ethernet_xml: Option<&str>) -> Result<RsiSettings, ConfigError> {
        let bad = |key: &'static str, value: String, why: &'static str| ConfigError::Invalid {
            key,
            value,
            why,
        };
        let ip: IpAddr = host_ip(&self.bind).ok_or_else(|| {
            bad(
                "bind",
                format!("\"{}\"", self.bind),
                "not an IP address or a host name that resolves",
            )
        })?;
        let mut controllers = Vec::new();
        for c in &self.controllers {
            // An IPv4-mapped IPv6 address is its IPv4 address.
            controllers.push(
                host_ip(c)
                    .ok_or_else(|| {
                        bad(
                            "controllers",
                            format!("\"{c}\""),
                            "not an IP address or a host name that resolves",
                        )
                    })?
                    .to_canonical(),
            );
        }
        let mut warnings = Vec::new();
        let bind_ip = ip.to_canonical();
        for c in &controllers {
            let unreachable = match (bind_ip, c) {
                (IpAddr::V4(_), IpAddr::V6(_)) => {
                    Some("an IPv6 controller never reaches an IPv4 bind address")
                }
                (IpAddr::V6(b), IpAddr::V4(_)) if !b.is_unspecified() => Some(
                    "an IPv4 controller never reaches a specific IPv6 bind address (bind \"::\" or an IPv4 address)",
                ),
                _ => None,
            };
            if let Some(why) = unreachable {
                return Err(bad("controllers", c.to_string(), why));
            }
        }
        if matches!(bind_ip, IpAddr::V6(b) if b.is_unspecified())
            && controllers.iter().any(IpAddr::is_ipv4)
        {
            warnings.push(RsiWarning::DualStackBind { bind: ip });
        }
        if self.enabled && controllers.is_empty() {
            return Err(bad(
                "controllers",
                "[]".into(),
                "name at least one controller address",
            ));
        }
        if !(4..=6).contains(&self.decimals) {
            return Err(bad(
                "decimals",
                self.decimals.to_string(),
                "must be 4, 5 or 6",
            ));
        }
        let (port, sen) = match (&self.ethernet_config, ethernet_xml) {
            (Some(_), None) => return Err(ConfigError::EthernetNotRead),
            (Some(_), Some(xml)) => {
                if self.port.is_some() {
                    return Err(ConfigError::Conflict { key: "port" });
                }
                if self.sentype.is_some() {
                    return Err(ConfigError::Conflict { key: "sentype" });
                }
                if self.correction_element.is_some() {
                    return Err(ConfigError::Conflict {
                        key: "correction_element",
                    });
                }
                let e = EthernetConfig::parse(xml)?;
                warnings.extend(e.warnings(self.mode));
                // Where the controller sends against where the daemon
                // listens (a wildcard bind hears every address).
                if let Some(Ok(target)) = e.ip_number.as_deref().map(str::parse::<IpAddr>) {
                    if !bind_ip.is_unspecified() && target.to_canonical() != bind_ip {
                        warnings.push(RsiWarning::IpNumber {
                            ip_number: target.to_string(),
                            bind: ip,
                        });
                    }
                }
                (e.port, e.sen_format(self.decimals)?)
            }
            (None, _) => {
                let port = self.port.filter(|p| *p != 0).ok_or_else(|| {
                    bad(
                        "port",
                        self.port
                            .map_or_else(|| "(not set)".to_string(), |p| p.to_string()),
                        "set a port (or ethernet_config)",
                    )
                })?;
                let sentype = self.sentype.clone().unwrap_or_else(|| "ImFree".into());
                let element = self
                    .correction_element
                    .clone()
                    .unwrap_or_else(|| "RKorr".into());
                for (key, v) in [("sentype", &sentype), ("correction_element", &element)] {
                    if !is_xml_name(v.as_bytes()) {
                        return Err(bad(
                            key,
                            format!("\"{v}\""),
                            "must be an XML name (a letter or '_', then letters, digits, '_', '-', '.')",
                        ));
                    }
                }
                (
                    port,
                    SenFormat {
                        sentype,
                        correction_element: element,
                        correction_attrs: POSE_ATTRS.map(String::from),
                        zero_elements: Vec::new(),
                        decimals: self.decimals,
                    },
                )
            }
        };
        if !(self.gain.is_finite() && self.gain > 0.0 && self.gain <= 1.0) {
            return Err(bad("gain", self.gain.to_string(), "must be in (0, 1]"));
        }
        let poscorr_mm = positive_up_to(
            "poscorr_limit_mm",
            self.poscorr_limit_mm,
            MAX_POSCORR_MM,
            "must be at most 1000 mm",
        )?;
        let poscorr_deg = positive_up_to(
            "poscorr_limit_deg",
            self.poscorr_limit_deg,
            MAX_POSCORR_DEG,
            "must be at most 180 degrees",
        )?;
        let clamp_mm = positive("clamp_mm", self.clamp_mm)?;
        let clamp_deg = positive("clamp_deg", self.clamp_deg)?;
        if clamp_mm >= poscorr_mm {
            return Err(bad(
                "clamp_mm",
                clamp_mm.to_string(),
                "must be below poscorr_limit_mm",
            ));
        }
        if clamp_deg >= poscorr_deg {
            return Err(bad(
                "clamp_deg",
                clamp_deg.to_string(),
                "must be below poscorr_limit_deg",
            ));
        }
        let max_step_mm = positive("max_step_mm", self.max_step_mm)?;
        let max_step_deg = positive("max_step_deg", self.max_step_deg)?;
        if max_step_mm > clamp_mm {
            return Err(bad(
                "max_step_mm",
                max_step_mm.to_string(),
                "must not exceed clamp_mm",
            ));
        }
        if max_step_deg > clamp_deg {
            return Err(bad(
                "max_step_deg",
                max_step_deg.to_string(),
                "must not exceed clamp_deg",
            ));
        }
        // A step below one printed digit would never move the robot.
        let quantum = 10f64.powi(-(self.decimals as i32));
        for (key, v) in [("max_step_mm", max_step_mm), ("max_step_deg", max_step_deg)] {
            if v < quantum {
                return Err(bad(
                    key,
                    v.to_string(),
                    "must be at least one printed digit (10^-decimals)",
                ));
            }
        }
        let cycle_ms = positive_up_to(
            "cycle_ms",
            self.cycle_ms,
            1000.0,
            "must be at most 1000 ms (4 with #IPO_FAST, 12 with #IPO)",
        )?;
        let session_idle_ms = positive_up_to(
            "session_idle_ms",
            self.session_idle_ms,
            60_000.0,
            "must be at most 60000 ms",
        )?;
        if session_idle_ms < 2.0 * cycle_ms {
            return Err(bad(
                "session_idle_ms",
                session_idle_ms.to_string(),
                "must be at least two cycles (2 x cycle_ms)",
            ));
        }
        let max_age_ms = positive_up_to(
            "max_age_ms",
            self.max_age_ms,
            3_600_000.0,
            "must be at most one hour",
        )?;
        if !(self.controller_latency_ms.is_finite()
            && (0.0..=1000.0).contains(&self.controller_latency_ms))
        {
            return Err(bad(
                "controller_latency_ms",
                self.controller_latency_ms.to_string(),
                "must be in [0, 1000] ms",
            ));
        }
        if self.min_targets < 4 {
            return Err(bad(
                "min_targets",
                self.min_targets.to_string(),
                "must be at least 4 (a pose needs four targets)",
            ));
        }
        let max_std_mm = positive("max_std_mm", self.max_std_mm)?;
        let max_std_deg = positive("max_std_deg", self.max_std_deg)?;
        if let Some(p) = self.realtime_priority {
            if !(1..=99).contains(&p) {
                return Err(bad("realtime_priority", p.to_string(), "must be 1..=99"));
            }
        }
        let settings = RsiSettings {
            bind: SocketAddr::new(ip, port),
            controllers,
            sen,
            law: LawConfig {
                mode: self.mode,
                frame: self.frame,
                gain: self.gain,
                max_step_mm,
                max_step_deg,
                clamp_mm,
                clamp_deg,
                max_age_s: max_age_ms * 1e-3,
                min_targets: self.min_targets,
                max_std_mm,
                max_std_deg,
                measure_only: self.measure_only,
                rsol_includes_correction: self.rsol_includes_correction,
                decimals: self.decimals as u32,
                cycle_s: cycle_ms * 1e-3,
                controller_latency_s: self.controller_latency_ms * 1e-3,
                feed_forward: self.feed_forward,
                compensate_latency: self.compensate_latency,
            },
            cycle: Duration::from_secs_f64(cycle_ms * 1e-3),
            session_idle: Duration::from_secs_f64(session_idle_ms * 1e-3),
            realtime_priority: self.realtime_priority,
            cpu: self.cpu,
            warnings,
        };
        let len = settings.reply_capacity();
        if len > MAX_DATAGRAM {
            return Err(ConfigError::ReplyTooLarge {
                len,
                limit: MAX_DATAGRAM,
            });
        }
        Ok(settings)
    }

    /// The consistency warnings of a valid section (HOLDON against the
    /// mode, no `RSol` sent, dual-stack bind), as data: what `run` logs and
    /// `check-config` prints. `ethernet_xml` as for [`RsiConfig::settings`].
    pub fn warnings(&self, ethernet_xml: Option<&str>) -> Result<Vec<RsiWarning>, ConfigError> {
        self.settings(ethernet_xml).map(|s| s.warnings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const XML: &str = "<ROOT><CONFIG><PORT>59152</PORT><SENTYPE>Cam</SENTYPE></CONFIG><SEND><ELEMENTS><ELEMENT TAG=\"DEF_RSol\"/></ELEMENTS></SEND><RECEIVE><ELEMENTS>\
        <ELEMENT TAG=\"RKorr.X\" HOLDON=\"0\"/><ELEMENT TAG=\"RKorr.Y\" HOLDON=\"0\"/><ELEMENT TAG=\"RKorr.Z\" HOLDON=\"0\"/>\
        <ELEMENT TAG=\"RKorr.A\" HOLDON=\"0\"/><ELEMENT TAG=\"RKorr.B\" HOLDON=\"0\"/><ELEMENT TAG=\"RKorr.C\" HOLDON=\"0\"/></ELEMENTS></RECEIVE></ROOT>";

    #[test]
    fn default_round_trips_through_toml() {
        let d = RsiConfig::default();
        let text = format!("[rsi]\n{}", toml::to_string(&d).unwrap());
        assert_eq!(RsiConfig::from_toml(&text).unwrap(), d);
        assert_eq!(RsiConfig::from_toml("").unwrap(), d);
    }

    #[test]
    fn host_names_are_resolved_for_bind_and_controllers() {
        let c = RsiConfig::from_toml(
            "[rsi]\nenabled = true\nport = 49152\nbind = \"localhost\"\ncontrollers = [\"localhost\"]\n",
        )
        .unwrap();
        let s = c.settings(None).unwrap();
        assert_eq!(s.bind, "127.0.0.1:49152".parse().unwrap());
        assert_eq!(s.controllers, vec!["127.0.0.1".parse::<IpAddr>().unwrap()]);
        let c = RsiConfig::from_toml(
            "[rsi]\nenabled = true\nport = 49152\ncontrollers = [\"no-such-robot.invalid\"]\n",
        )
        .unwrap();
        let e = c.settings(None).unwrap_err().to_string();
        assert!(
            e.contains("controllers") && e.contains("no-such-robot.invalid"),
            "{e}"
        );
    }

    #[test]
    fn unknown_key_is_named() {
        let e = RsiConfig::from_toml("[rsi]\nport = 1\ngian = 0.5\n").unwrap_err();
        assert!(e.to_string().contains("gian"), "{e}");
    }

    #[test]
    fn settings_from_keys() {
        let c = RsiConfig::from_toml("[rsi]\nenabled = true\nport = 49152\ncontrollers = [\"127.0.0.1\"]\nmode = \"absolute\"\nframe = \"tool\"\n").unwrap();
        let s = c.settings(None).unwrap();
        assert_eq!(s.bind, "0.0.0.0:49152".parse().unwrap());
        assert_eq!(s.law.mode, CorrectionMode::Absolute);
        assert_eq!(s.law.frame, CorrFrame::Tool);
        assert_eq!(s.sen.sentype, "ImFree");
        assert_eq!(s.cycle, Duration::from_millis(4));
    }

    #[test]
    fn settings_from_the_controller_file() {
        let c = RsiConfig {
            enabled: true,
            controllers: vec!["10.0.0.2".into()],
            ethernet_config: Some("RSI_EthernetConfig.xml".into()),
            ..RsiConfig::default()
        };
        let s = c.settings(Some(XML)).unwrap();
        assert_eq!(s.bind.port(), 59152);
        assert_eq!(s.sen.sentype, "Cam");
        assert!(s.warnings.is_empty(), "{:?}", s.warnings);
        let abs = RsiConfig {
            mode: CorrectionMode::Absolute,
            ..c.clone()
        };
        assert_eq!(abs.settings(Some(XML)).unwrap().warnings.len(), 6);
        assert_eq!(c.settings(None), Err(ConfigError::EthernetNotRead));
        let both = RsiConfig { port: Some(1), ..c };
        assert_eq!(
            both.settings(Some(XML)),
            Err(ConfigError::Conflict { key: "port" })
        );
    }

    #[test]
    fn validation_names_the_key() {
        let base = RsiConfig {
            port: Some(49152),
            ..RsiConfig::default()
        };
        let cases: Vec<(RsiConfig, &str)> = vec![
            (
                RsiConfig {
                    clamp_mm: 6.0,
                    ..base.clone()
                },
                "clamp_mm",
            ),
            (
                RsiConfig {
                    clamp_deg: 5.0,
                    ..base.clone()
                },
                "clamp_deg",
            ),
            (
                RsiConfig {
                    gain: 0.0,
                    ..base.clone()
                },
                "gain",
            ),
            (
                RsiConfig {
                    max_step_mm: 10.0,
                    ..base.clone()
                },
                "max_step_mm",
            ),
            (
                RsiConfig {
                    decimals: 2,
                    ..base.clone()
                },
                "decimals",
            ),
            (
                RsiConfig {
                    bind: "no-such-host.invalid".into(),
                    ..base.clone()
                },
                "bind",
            ),
            (
                RsiConfig {
                    enabled: true,
                    ..base.clone()
                },
                "controllers",
            ),
            (
                RsiConfig {
                    port: None,
                    ..base.clone()
                },
                "port",
            ),
            (
                RsiConfig {
                    max_age_ms: -1.0,
                    ..base.clone()
                },
                "max_age_ms",
            ),
            (
                RsiConfig {
                    realtime_priority: Some(0),
                    ..base.clone()
                },
                "realtime_priority",
            ),
        ];
        for (c, key) in cases {
            match c.settings(None) {
                Err(ConfigError::Invalid { key: k, .. }) => assert_eq!(k, key),
                other => panic!("{key}: {other:?}"),
            }
        }
    }

    #[test]
    fn absurd_values_are_refused_naming_the_key() {
        let base = RsiConfig {
            port: Some(49152),
            ..RsiConfig::default()
        };
        type Edit = fn(&mut RsiConfig);
        let edits: Vec<(&str, Edit)> = vec![
            ("poscorr_limit_mm", |c| c.poscorr_limit_mm = 1.7e308),
            ("poscorr_limit_deg", |c| c.poscorr_limit_deg = f64::INFINITY),
            ("gain", |c| c.gain = f64::NAN),
            ("gain", |c| c.gain = 1.5),
            ("max_step_mm", |c| c.max_step_mm = f64::NAN),
            ("max_step_deg", |c| c.max_step_deg = 0.00001),
            ("clamp_mm", |c| c.clamp_mm = -1.0),
            ("cycle_ms", |c| c.cycle_ms = 1e308),
            ("max_age_ms", |c| c.max_age_ms = f64::INFINITY),
            ("max_std_mm", |c| c.max_std_mm = 0.0),
            ("min_targets", |c| c.min_targets = 3),
            ("max_std_deg", |c| c.max_std_deg = f64::NAN),
            ("session_idle_ms", |c| c.session_idle_ms = 5.0),
            ("session_idle_ms", |c| c.session_idle_ms = f64::NAN),
            ("controller_latency_ms", |c| c.controller_latency_ms = -1.0),
            ("controller_latency_ms", |c| {
                c.controller_latency_ms = f64::NAN
            }),
            ("controller_latency_ms", |c| c.controller_latency_ms = 1e4),
            ("sentype", |c| c.sentype = Some("Im\"Free".into())),
            ("sentype", |c| c.sentype = Some("1st".into())),
            ("correction_element", |c| {
                c.correction_element = Some("R Korr".into())
            }),
            ("controllers", |c| {
                c.bind = "127.0.0.1".into();
                c.controllers = vec!["fe80::1".into()];
            }),
            ("controllers", |c| {
                c.bind = "::1".into();
                c.controllers = vec!["10.0.0.2".into()];
            }),
        ];
        for (key, edit) in edits {
            let mut c = base.clone();
            edit(&mut c);
            match c.settings(None) {
                Err(ConfigError::Invalid { key: k, .. }) => assert_eq!(k, key),
                other => panic!("{key}: {other:?}"),
            }
        }
    }

    #[test]
    fn v4_mapped_controllers_and_dual_stack_binds() {
        let c = RsiConfig {
            enabled: true,
            bind: "::".into(),
            port: Some(49152),
            controllers: vec!["::ffff:10.0.0.2".into(), "10.0.0.3".into()],
            ..RsiConfig::default()
        };
        let s = c.settings(None).unwrap();
        assert_eq!(
            s.controllers,
            vec![
                "10.0.0.2".parse::<IpAddr>().unwrap(),
                "10.0.0.3".parse().unwrap()
            ]
        );
        let w = c.warnings(None).unwrap();
        assert_eq!(w, s.warnings);
        assert!(matches!(w[..], [RsiWarning::DualStackBind { .. }]), "{w:?}");
        assert!(w[0].to_string().contains("bindv6only"), "{}", w[0]);
        // An IPv4 bind with a v4-mapped controller is fine.
        let c = RsiConfig {
            bind: "0.0.0.0".into(),
            ..c
        };
        assert!(c.settings(None).unwrap().warnings.is_empty());
    }

    #[test]
    fn the_reply_buffer_follows_the_receive_list() {
        let mut xml = XML.replace("</ELEMENTS></RECEIVE>", "");
        for k in 0..5000 {
            xml.push_str(&format!("<ELEMENT TAG=\"Out{k}\" HOLDON=\"0\"/>"));
        }
        xml.push_str("</ELEMENTS></RECEIVE></ROOT>");
        let xml = xml.replacen("</ROOT>", "", 1);
        let c = RsiConfig {
            enabled: true,
            controllers: vec!["10.0.0.2".into()],
            ethernet_config: Some("RSI_EthernetConfig.xml".into()),
            ..RsiConfig::default()
        };
        match c.settings(Some(&xml)) {
            Err(ConfigError::ReplyTooLarge { len, limit }) => {
                assert!(len > limit && limit == MAX_DATAGRAM, "{len} {limit}")
            }
            other => panic!("{other:?}"),
        }
        // The spec's reply fits its bound exactly at the clamp.
        let s = c.settings(Some(XML)).unwrap();
        let mut buf = vec![0u8; s.reply_capacity()];
        let v = -s.law.clamp_mm;
        let n = s
            .sen
            .write(&[v; 6], &crate::codec::Ipoc::from_value(u64::MAX), &mut buf)
            .unwrap();
        assert_eq!(n, buf.len());
    }

    #[test]
    fn holdon_warnings_are_data_for_check_config_and_run() {
        let c = RsiConfig {
            enabled: true,
            controllers: vec!["10.0.0.2".into()],
            ethernet_config: Some("RSI_EthernetConfig.xml".into()),
            mode: CorrectionMode::Absolute,
            ..RsiConfig::default()
        };
        let w = c.warnings(Some(XML)).unwrap();
        assert_eq!(w.len(), 6);
        assert!(matches!(
            &w[0],
            RsiWarning::Holdon {
                holdon: Some(false),
                mode: CorrectionMode::Absolute,
                ..
            }
        ));
        assert!(
            w[0].to_string().contains("RKorr.X has HOLDON=0"),
            "{}",
            w[0]
        );
        let no_rsol = XML.replace("DEF_RSol", "DEF_RIst");
        let c = RsiConfig {
            mode: CorrectionMode::Relative,
            ..c
        };
        assert_eq!(
            c.warnings(Some(&no_rsol)).unwrap(),
            vec![RsiWarning::NoRsol]
        );
        // A second element with part of a correction is said (it is
        // answered with zeros), with its line and what it lacks.
        let partial = XML.replace(
            "</ELEMENTS></RECEIVE>",
            "<ELEMENT TAG=\"Shift.X\" HOLDON=\"0\"/><ELEMENT TAG=\"Shift.Y\" HOLDON=\"0\"/></ELEMENTS></RECEIVE>",
        );
        let w = c.warnings(Some(&partial)).unwrap();
        assert!(
            matches!(&w[..], [RsiWarning::PartialCorrection { element, missing, .. }]
                if element == "Shift" && missing.join(" ") == "Z A B C"),
            "{w:?}"
        );
        assert!(w[0].to_string().contains("Shift lacks Z A B C"), "{}", w[0]);
        // IP_NUMBER (where the controller sends) against a specific bind.
        let ip = XML.replace("<CONFIG>", "<CONFIG><IP_NUMBER>10.0.0.7</IP_NUMBER>");
        let bound = RsiConfig {
            bind: "10.0.0.5".into(),
            ..c.clone()
        };
        let w = bound.warnings(Some(&ip)).unwrap();
        assert!(matches!(&w[..], [RsiWarning::IpNumber { .. }]), "{w:?}");
        assert!(w[0].to_string().contains("IP_NUMBER 10.0.0.7"), "{}", w[0]);
        let same = RsiConfig {
            bind: "10.0.0.7".into(),
            ..c.clone()
        };
        assert!(same.warnings(Some(&ip)).unwrap().is_empty());
        assert!(
            c.warnings(Some(&ip)).unwrap().is_empty(),
            "a wildcard bind hears it"
        );
        // A SENTYPE with a quote is refused at load.
        let quoted = XML.replace("<SENTYPE>Cam", "<SENTYPE>Ca\"m");
        assert!(matches!(
            c.settings(Some(&quoted)),
            Err(ConfigError::Ethernet(EthernetConfigError::NotAName {
                key: "SENTYPE",
                ..
            }))
        ));
    }
}
