//! The GigE Vision source (`[source.gige]`, the `gige` feature): the keys
//! of the section and their checks, mapped onto `photopose-acquire`'s
//! [`GigeConfig`], whose `Default` holds the one set of defaults. Opening
//! and reconnecting the camera is the acquisition crate's, and so is the
//! exposure control loop (`[source.gige.exposure_control]`, its defaults
//! in [`ExposureSettings::default`]).

use super::Bad;
use crate::config::ConfigError;
use photopose_acquire::exposure::SettingsError;
use photopose_acquire::{ExposureSettings, FeatureValue, GigeConfig, PixelDepth, Roi};
use serde::de::{MapAccess, Visitor};
use serde::{Deserialize, Deserializer};

/// `[source.gige]` as written: every key optional, an absent one takes
/// [`GigeConfig::default`]'s value.
#[derive(Debug, Deserialize, Clone, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct GigeSection {
    camera: Option<String>,
    pixel_format: Option<PixelFormatToml>,
    exposure_us: Option<f64>,
    gain: Option<f64>,
    frame_rate: Option<f64>,
    roi: Option<[u32; 4]>,
    packet_size: Option<u32>,
    packet_socket: Option<bool>,
    buffers: Option<u32>,
    lost_after_ms: Option<f64>,
    backoff_initial_ms: Option<f64>,
    backoff_max_ms: Option<f64>,
    transfer_ms: Option<f64>,
    #[serde(default)]
    features: Features,
    exposure_control: Option<ExposureControlSection>,
}

/// `[source.gige.exposure_control]` as written: every key optional, an
/// absent one takes [`ExposureSettings::default`]'s value; off unless
/// `enabled = true`.
#[derive(Debug, Deserialize, Clone, Default)]
#[serde(deny_unknown_fields)]
struct ExposureControlSection {
    enabled: Option<bool>,
    target_peak: Option<f64>,
    min_us: Option<f64>,
    max_us: Option<f64>,
    gain: Option<f64>,
    max_step_ratio: Option<f64>,
    dead_band: Option<f64>,
    every_frames: Option<u32>,
}

/// Validates `[source.gige.exposure_control]`: `None` when it is off.
fn exposure_control(
    s: Option<ExposureControlSection>,
    bad: Bad<'_>,
) -> Result<Option<ExposureSettings>, ConfigError> {
    let Some(s) = s else { return Ok(None) };
    let d = ExposureSettings::default();
    let settings = ExposureSettings {
        target_peak: s.target_peak.unwrap_or(d.target_peak),
        min_us: s.min_us.unwrap_or(d.min_us),
        max_us: s.max_us.unwrap_or(d.max_us),
        gain: s.gain.unwrap_or(d.gain),
        max_step_ratio: s.max_step_ratio.unwrap_or(d.max_step_ratio),
        dead_band: s.dead_band.unwrap_or(d.dead_band),
        every_frames: s.every_frames.unwrap_or(d.every_frames),
    };
    // Checked even when off, so that turning it on cannot surprise.
    if let Err(SettingsError::OutOfRange { key, value, reason }) = settings.check() {
        let key = match key {
            "target_peak" => "source.gige.exposure_control.target_peak",
            "min_us" => "source.gige.exposure_control.min_us",
            "max_us" => "source.gige.exposure_control.max_us",
            "gain" => "source.gige.exposure_control.gain",
            "max_step_ratio" => "source.gige.exposure_control.max_step_ratio",
            "dead_band" => "source.gige.exposure_control.dead_band",
            "every_frames" => "source.gige.exposure_control.every_frames",
            _ => "source.gige.exposure_control",
        };
        return Err(bad(key, value.to_string(), reason));
    }
    Ok(s.enabled.unwrap_or(false).then_some(settings))
}

/// `[source.gige.features]`: GenICam feature name → value, kept in the
/// order written (a selector must be written before the features it
/// selects, e.g. `TriggerSelector` before `TriggerMode`).
#[derive(Debug, Clone, Default)]
struct Features(Vec<(String, FeatureToml)>);

#[derive(Debug, Clone)]
enum FeatureToml {
    Bool(bool),
    Int(i64),
    Float(f64),
    Text(String),
}

impl<'de> Deserialize<'de> for Features {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct InOrder;
        impl<'de> Visitor<'de> for InOrder {
            type Value = Features;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a table of GenICam feature names and values (integer, float, boolean or string)")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Features, A::Error> {
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry::<String, toml::Value>()? {
                    let v = match v {
                        toml::Value::Boolean(b) => FeatureToml::Bool(b),
                        toml::Value::Integer(i) => FeatureToml::Int(i),
                        toml::Value::Float(f) => FeatureToml::Float(f),
                        toml::Value::String(t) => FeatureToml::Text(t),
                        other => {
                            return Err(serde::de::Error::custom(format!(
                                "`source.gige.features.{k}` = {other}: must be an integer, float, boolean or string"
                            )))
                        }
                    };
                    out.push((k, v));
                }
                Ok(Features(out))
            }
        }
        d.deserialize_map(InOrder)
    }
}

#[derive(Debug, Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
enum PixelFormatToml {
    Mono8,
    Mono16,
}

/// Validates `[source.gige]` into the acquisition crate's settings.
pub(crate) fn validate(g: GigeSection, bad: Bad<'_>) -> Result<GigeConfig, ConfigError> {
    let d = GigeConfig::default();
    let buffers = g.buffers.unwrap_or(d.buffers as u32);
    let millis =
        |v: Option<f64>, default: std::time::Duration| v.unwrap_or(default.as_secs_f64() * 1000.0);
    let lost_after_ms = millis(g.lost_after_ms, d.lost_after);
    let backoff_initial_ms = millis(g.backoff_initial_ms, d.backoff_initial);
    let backoff_max_ms = millis(g.backoff_max_ms, d.backoff_max);
    let positive = |key: &'static str, v: Option<f64>| match v {
        Some(x) if !(x.is_finite() && x > 0.0) => Err(bad(key, x.to_string(), "must be > 0")),
        _ => Ok(v),
    };
    let ms = |key: &'static str, v: f64, max: f64| {
        if v.is_finite() && v > 0.0 && v <= max {
            Ok(std::time::Duration::from_secs_f64(v / 1000.0))
        } else {
            Err(bad(key, v.to_string(), "must be in (0, 600000] ms"))
        }
    };
    if g.camera.as_deref().is_some_and(|c| c.trim().is_empty()) {
        return Err(bad(
            "source.gige.camera",
            "\"\"".into(),
            "must name a device id, address or serial (omit it for the first camera found)",
        ));
    }
    if let Some(gain) = g.gain {
        if !gain.is_finite() {
            return Err(bad("source.gige.gain", gain.to_string(), "must be finite"));
        }
    }
    let roi = match g.roi {
        Some([x, y, width, height]) => {
            if width == 0 || height == 0 || x.max(y).max(width).max(height) > 65_535 {
                return Err(bad(
                    "source.gige.roi",
                    format!("[{x}, {y}, {width}, {height}]"),
                    "must be [x, y, width, height] with a non-empty size below 65536",
                ));
            }
            Some(Roi {
                x,
                y,
                width,
                height,
            })
        }
        None => None,
    };
    if let Some(p) = g.packet_size {
        if !(576..=16_384).contains(&p) {
            return Err(bad(
                "source.gige.packet_size",
                p.to_string(),
                "must be 576..=16384 bytes",
            ));
        }
    }
    if !(2..=256).contains(&buffers) {
        return Err(bad(
            "source.gige.buffers",
            buffers.to_string(),
            "must be 2..=256",
        ));
    }
    let config = GigeConfig {
        camera: g.camera,
        pixel: match g.pixel_format {
            None => d.pixel,
            Some(PixelFormatToml::Mono8) => PixelDepth::Mono8,
            Some(PixelFormatToml::Mono16) => PixelDepth::Mono16,
        },
        exposure_us: positive("source.gige.exposure_us", g.exposure_us)?,
        gain: g.gain,
        frame_rate: positive("source.gige.frame_rate", g.frame_rate)?,
        roi,
        packet_size: g.packet_size,
        packet_socket: g.packet_socket.unwrap_or(d.packet_socket),
        buffers: buffers as usize,
        lost_after: ms("source.gige.lost_after_ms", lost_after_ms, 600_000.0)?,
        backoff_initial: ms(
            "source.gige.backoff_initial_ms",
            backoff_initial_ms,
            600_000.0,
        )?,
        backoff_max: ms("source.gige.backoff_max_ms", backoff_max_ms, 600_000.0)?,
        transfer: match g.transfer_ms {
            None => None,
            Some(t) if t.is_finite() && (0.0..=10_000.0).contains(&t) => {
                Some(std::time::Duration::from_secs_f64(t / 1000.0))
            }
            Some(t) => {
                return Err(bad(
                    "source.gige.transfer_ms",
                    t.to_string(),
                    "must be in [0, 10000] ms",
                ))
            }
        },
        // Set from `[source] latency_ms` by the seam.
        fixed_latency: None,
        features: features(g.features, bad)?,
        exposure_control: exposure_control(g.exposure_control, bad)?,
    };
    if config.backoff_max < config.backoff_initial {
        return Err(bad(
            "source.gige.backoff_max_ms",
            backoff_max_ms.to_string(),
            "must be ≥ backoff_initial_ms",
        ));
    }
    Ok(config)
}

/// Checks the names and values of `[source.gige.features]` (whether the
/// camera has them is checked against its node map at each opening).
fn features(f: Features, bad: Bad<'_>) -> Result<Vec<(String, FeatureValue)>, ConfigError> {
    let mut out = Vec::with_capacity(f.0.len());
    for (name, value) in f.0 {
        if name.is_empty() || !name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
            return Err(bad(
                "source.gige.features",
                format!("\"{name}\""),
                "must be GenICam feature names (letters, digits, '_')",
            ));
        }
        let value = match value {
            FeatureToml::Bool(v) => FeatureValue::Bool(v),
            FeatureToml::Int(v) => FeatureValue::Int(v),
            FeatureToml::Float(v) if v.is_finite() => FeatureValue::Float(v),
            FeatureToml::Float(v) => {
                return Err(bad(
                    "source.gige.features",
                    format!("{name} = {v}"),
                    "must be a finite number",
                ))
            }
            FeatureToml::Text(v) => FeatureValue::Text(v),
        };
        out.push((name, value));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use crate::config::{Config, Source};

    fn gige(section: &str) -> Result<photopose_acquire::GigeConfig, String> {
        let text = format!("[source]\nkind = \"gige\"\n[source.gige.exposure_control]\n{section}");
        match Config::parse(&text, "x.toml")
            .map_err(|e| e.to_string())?
            .source
        {
            Source::Gige(g) => Ok(g),
            other => panic!("not gige: {other:?}"),
        }
    }

    #[test]
    fn exposure_control_is_off_unless_enabled() {
        assert_eq!(gige("").unwrap().exposure_control, None);
        assert_eq!(
            gige("enabled = false\nmax_us = 900.0\n")
                .unwrap()
                .exposure_control,
            None
        );
        let s = gige(
            "enabled = true\ntarget_peak = 0.7\nmin_us = 50.0\nmax_us = 900.0\ngain = 0.8\n\
             max_step_ratio = 1.5\ndead_band = 0.05\nevery_frames = 2\n",
        )
        .unwrap()
        .exposure_control
        .unwrap();
        assert_eq!(
            s,
            photopose_acquire::ExposureSettings {
                target_peak: 0.7,
                min_us: 50.0,
                max_us: 900.0,
                gain: 0.8,
                max_step_ratio: 1.5,
                dead_band: 0.05,
                every_frames: 2,
            }
        );
        let d = gige("enabled = true\n").unwrap().exposure_control.unwrap();
        assert_eq!(d, photopose_acquire::ExposureSettings::default());
        assert_eq!(d.target_peak, 0.8);
    }

    #[test]
    fn exposure_control_errors_name_the_key() {
        for (section, key) in [
            (
                "target_peak = 1.2\n",
                "source.gige.exposure_control.target_peak",
            ),
            (
                "target_peak = 0.0\n",
                "source.gige.exposure_control.target_peak",
            ),
            ("min_us = -1.0\n", "source.gige.exposure_control.min_us"),
            (
                "min_us = 500.0\nmax_us = 100.0\n",
                "source.gige.exposure_control.max_us",
            ),
            ("gain = 0.0\n", "source.gige.exposure_control.gain"),
            ("gain = 1.01\n", "source.gige.exposure_control.gain"),
            (
                "max_step_ratio = 1.0\n",
                "source.gige.exposure_control.max_step_ratio",
            ),
            (
                "dead_band = 1.0\n",
                "source.gige.exposure_control.dead_band",
            ),
            (
                "every_frames = 0\n",
                "source.gige.exposure_control.every_frames",
            ),
            ("target = 0.5\n", "target"),
        ] {
            let e = gige(&format!("enabled = true\n{section}")).unwrap_err();
            assert!(
                e.starts_with("x.toml: ") && e.contains(key),
                "{section}: {e}"
            );
        }
    }
}
