//! The GenTL source (`[source.gentl]`, the `gentl` feature): frame
//! grabbers (Camera Link, CoaXPress) and other cameras through the
//! vendor's GenTL producer. The keys of the section and their checks,
//! mapped onto `photopose-gentl`'s [`GentlConfig`], whose constructor holds
//! the one set of defaults; loading the producer and streaming are that
//! crate's.

use super::Bad;
use crate::config::ConfigError;
use photopose_gentl::{find_producer, GentlConfig, GentlError, PRODUCER_PATH_VAR};
use serde::Deserialize;
use std::path::PathBuf;
use std::time::Duration;

/// `[source.gentl]` as written: every key optional.
#[derive(Debug, Deserialize, Clone, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct GentlSection {
    producer: Option<PathBuf>,
    device: Option<String>,
    buffers: Option<u32>,
    payload_size: Option<u64>,
    timeout_ms: Option<f64>,
    backoff_initial_ms: Option<f64>,
    backoff_max_ms: Option<f64>,
}

const PRODUCER: &str = "source.gentl.producer";

/// Validates `[source.gentl]`; the producer is `producer`, or the one
/// `.cti` in the directories of `GENICAM_GENTL64_PATH`.
pub(crate) fn validate(g: GentlSection, bad: Bad<'_>) -> Result<GentlConfig, ConfigError> {
    let search = std::env::var_os(PRODUCER_PATH_VAR);
    let producer =
        find_producer(g.producer.as_deref(), search.as_deref(), PRODUCER).map_err(|e| match e {
            GentlError::MissingProducer { path, reason } => bad(
                PRODUCER,
                format!("\"{}\" ({reason})", path.display()),
                "must name a GenTL producer (.cti) file",
            ),
            GentlError::AmbiguousProducer { found, .. } => bad(
                PRODUCER,
                format!("(absent; {PRODUCER_PATH_VAR} holds {found})"),
                "must name one producer when GENICAM_GENTL64_PATH holds several",
            ),
            other => bad(
                PRODUCER,
                format!("(absent; {other})"),
                "must name a GenTL producer (.cti), or GENICAM_GENTL64_PATH a directory holding one",
            ),
        })?;
    let d = GentlConfig::new(producer);
    if g.device.as_deref().is_some_and(|c| c.trim().is_empty()) {
        return Err(bad(
            "source.gentl.device",
            "\"\"".into(),
            "must name a device id or serial number (omit it for the first device found)",
        ));
    }
    let buffers = g.buffers.unwrap_or(d.buffers as u32);
    if !(2..=256).contains(&buffers) {
        return Err(bad(
            "source.gentl.buffers",
            buffers.to_string(),
            "must be 2..=256",
        ));
    }
    if let Some(p) = g.payload_size {
        if !(1..=1 << 30).contains(&p) {
            return Err(bad(
                "source.gentl.payload_size",
                p.to_string(),
                "must be 1..=1073741824 bytes",
            ));
        }
    }
    let ms = |key: &'static str, v: Option<f64>, default: Duration| {
        let v = v.unwrap_or(default.as_secs_f64() * 1000.0);
        if v.is_finite() && v > 0.0 && v <= 600_000.0 {
            Ok(Duration::from_secs_f64(v / 1000.0))
        } else {
            Err(bad(key, v.to_string(), "must be in (0, 600000] ms"))
        }
    };
    let config = GentlConfig {
        device: g.device,
        buffers: buffers as usize,
        payload_size: g.payload_size.map(|p| p as usize),
        timeout: ms("source.gentl.timeout_ms", g.timeout_ms, d.timeout)?,
        backoff_initial: ms(
            "source.gentl.backoff_initial_ms",
            g.backoff_initial_ms,
            d.backoff_initial,
        )?,
        backoff_max: ms(
            "source.gentl.backoff_max_ms",
            g.backoff_max_ms,
            d.backoff_max,
        )?,
        ..d
    };
    if config.backoff_max < config.backoff_initial {
        return Err(bad(
            "source.gentl.backoff_max_ms",
            format!("{}", config.backoff_max.as_secs_f64() * 1000.0),
            "must be ≥ backoff_initial_ms",
        ));
    }
    Ok(config)
}

#[cfg(test)]
mod tests {
    use crate::config::{Config, Source};

    fn parse(section: &str) -> Result<Config, String> {
        Config::parse(
            &format!("[source]\nkind = \"gentl\"\n[source.gentl]\n{section}"),
            "test.toml",
        )
        .map_err(|e| e.to_string())
    }

    #[test]
    fn the_section_is_checked_naming_key_and_file() {
        let dir = std::env::temp_dir().join(format!("photopose-gentl-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cti = dir.join("vendor.cti");
        std::fs::write(&cti, b"x").unwrap();
        let ok = parse(&format!(
            "producer = \"{}\"\ndevice = \"CAM1\"\nbuffers = 4\ntimeout_ms = 500.0\n",
            cti.display()
        ))
        .unwrap();
        let Source::Gentl(g) = ok.source else {
            panic!("gentl expected")
        };
        assert_eq!(g.producer, cti);
        assert_eq!(g.device.as_deref(), Some("CAM1"));
        assert_eq!(g.buffers, 4);
        assert_eq!(g.timeout, std::time::Duration::from_millis(500));
        // A producer file that is not there: key, file and path named.
        let e = parse("producer = \"/nonexistent/vendor.cti\"\n").unwrap_err();
        assert!(
            e.contains("test.toml")
                && e.contains("source.gentl.producer")
                && e.contains("/nonexistent/vendor.cti"),
            "{e}"
        );
        let e = parse(&format!("producer = \"{}\"\nbuffers = 1\n", cti.display())).unwrap_err();
        assert!(e.contains("source.gentl.buffers"), "{e}");
        let e = parse(&format!(
            "producer = \"{}\"\ndevice = \" \"\n",
            cti.display()
        ))
        .unwrap_err();
        assert!(e.contains("source.gentl.device"), "{e}");
        let e = parse(&format!(
            "producer = \"{}\"\ncamera = \"x\"\n",
            cti.display()
        ))
        .unwrap_err();
        assert!(e.contains("camera"), "unknown key refused: {e}");
        let e = parse(&format!(
            "producer = \"{}\"\ntimeout_ms = 0.0\n",
            cti.display()
        ))
        .unwrap_err();
        assert!(e.contains("source.gentl.timeout_ms"), "{e}");
    }
}
