//! The hand-eye file (TOML, `docs/hand-eye.md`): the camera in the robot's
//! TCP frame (`X = T_tcp←camera`) and the plate in the robot's base frame
//! (`Z = T_base←plate`) as KUKA `X, Y, Z, A, B, C` with their standard
//! deviations, and the figures of the fit that produced them. Written by
//! `photopose calibrate hand-eye`, read by the daemon. Unknown and missing
//! keys, and values out of range (a translation beyond 100 m, an angle
//! beyond ±360°, an absurd standard deviation), are errors that name the
//! file and the key.
//!
//! ```toml
//! # photopose hand-eye calibration (frames: see docs/hand-eye.md)
//! [camera_in_tcp]          # X = T_tcp←camera
//! xyzabc = [35.0, -80.0, 160.0, 91.0, 2.5, 178.5]   # mm, deg (KUKA A,B,C)
//! std_xyzabc = [0.02, 0.02, 0.03, 0.002, 0.002, 0.002]
//! [plate_in_base]          # Z = T_base←plate
//! xyzabc = [1100.0, 200.0, 15.0, 25.0, 0.8, -0.6]
//! std_xyzabc = [0.03, 0.03, 0.02, 0.002, 0.002, 0.002]
//! [fit]                    # optional
//! stations = 12
//! sigma0 = 1.02
//! rms_mm = 0.01
//! rms_deg = 0.001
//! ```

use crate::FormatError;
use nalgebra::Isometry3;
use photopose_geometry::pose::isometry_from_xyzabc;
use serde::Deserialize;
use std::path::Path;

/// One transform of the hand-eye file.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transform {
    /// The frame in its parent: KUKA `X, Y, Z, A, B, C` (mm, degrees,
    /// `M = Rz(A) Ry(B) Rx(C)`).
    pub xyzabc: [f64; 6],
    /// Standard deviations of `xyzabc` (mm, degrees).
    pub std_xyzabc: [f64; 6],
}

impl Transform {
    /// The transform as an isometry (child → parent).
    pub fn isometry(&self) -> Isometry3<f64> {
        isometry_from_xyzabc(self.xyzabc)
    }
}

/// The figures of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fit {
    /// Stations used.
    pub stations: u32,
    /// A-posteriori σ0 of the fit.
    pub sigma0: f64,
    /// RMS of the TCP position discrepancy per station, mm.
    pub rms_mm: f64,
    /// RMS of the TCP rotation discrepancy per station, degrees.
    pub rms_deg: f64,
}

/// The contents of a hand-eye file.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandEyeFile {
    /// `X = T_tcp←camera`: the camera (projection centre, axes of `Rᵀ`) in
    /// the TCP (flange) frame.
    pub camera_in_tcp: Transform,
    /// `Z = T_base←plate`: the plate in the robot's base frame.
    pub plate_in_base: Transform,
    /// The fit that produced the file (absent in a hand-written file).
    #[serde(default)]
    pub fit: Option<Fit>,
}

/// Largest translation of a transform, mm (100 m: beyond any robot cell).
pub const MAX_TRANSLATION_MM: f64 = 100_000.0;
/// Largest KUKA angle `A`, `B`, `C`, degrees.
pub const MAX_ANGLE_DEG: f64 = 360.0;
/// Largest standard deviation of a translation (and RMS of the fit), mm.
pub const MAX_STD_MM: f64 = 1000.0;
/// Largest standard deviation of an angle (and RMS of the fit), degrees.
pub const MAX_STD_DEG: f64 = 180.0;
/// Largest σ0 of the fit.
pub const MAX_SIGMA0: f64 = 1.0e6;
/// The names of the six values of `xyzabc`.
const AXES: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

/// Parses hand-eye TOML text; `origin` names the file in errors. Values are
/// range-checked, naming the key: translations within ±[`MAX_TRANSLATION_MM`],
/// angles within ±[`MAX_ANGLE_DEG`], standard deviations finite, ≥ 0 and at
/// most [`MAX_STD_MM`] / [`MAX_STD_DEG`].
pub fn parse_hand_eye(text: &str, origin: &str) -> Result<HandEyeFile, FormatError> {
    let err = |what: String| FormatError::HandEye {
        origin: origin.into(),
        what,
    };
    let f: HandEyeFile = toml::from_str(text).map_err(|e| {
        let at = e
            .span()
            .map(|s| {
                let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                format!("line {line}: ")
            })
            .unwrap_or_default();
        err(format!("{at}{}", e.message()))
    })?;
    for (table, t) in [
        ("camera_in_tcp", &f.camera_in_tcp),
        ("plate_in_base", &f.plate_in_base),
    ] {
        for (k, (&v, &sd)) in t.xyzabc.iter().zip(&t.std_xyzabc).enumerate() {
            let (name, limit, std_limit, unit) = if k < 3 {
                (AXES[k], MAX_TRANSLATION_MM, MAX_STD_MM, "mm")
            } else {
                (AXES[k], MAX_ANGLE_DEG, MAX_STD_DEG, "°")
            };
            if !v.is_finite() {
                return Err(err(format!(
                    "{table}.xyzabc[{k}] ({name}) = {v} is not a finite number"
                )));
            }
            if v.abs() > limit {
                return Err(err(format!(
                    "{table}.xyzabc[{k}] ({name}) = {v} is outside ±{limit} {unit}"
                )));
            }
            if !(sd.is_finite() && (0.0..=std_limit).contains(&sd)) {
                return Err(err(format!(
                    "{table}.std_xyzabc[{k}] ({name}) = {sd} is not a standard deviation \
                     (finite, 0..={std_limit} {unit})"
                )));
            }
        }
    }
    if let Some(fit) = &f.fit {
        for (key, v, max) in [
            ("fit.sigma0", fit.sigma0, MAX_SIGMA0),
            ("fit.rms_mm", fit.rms_mm, MAX_STD_MM),
            ("fit.rms_deg", fit.rms_deg, MAX_STD_DEG),
        ] {
            if !(v.is_finite() && (0.0..=max).contains(&v)) {
                return Err(err(format!("{key} = {v} must be finite and in 0..={max}")));
            }
        }
        if fit.stations < 3 {
            return Err(err(format!(
                "fit.stations = {}: a hand-eye fit has at least 3",
                fit.stations
            )));
        }
    }
    Ok(f)
}

/// Loads a hand-eye file.
pub fn load_hand_eye(path: &Path) -> Result<HandEyeFile, FormatError> {
    let text = crate::read_text(path, crate::FileKind::HandEye)?;
    parse_hand_eye(&text, &path.display().to_string())
}

fn list(v: &[f64; 6]) -> String {
    let items: Vec<String> = v.iter().map(|x| crate::camera::toml_float(*x)).collect();
    format!("[{}]", items.join(", "))
}

/// The TOML text of a hand-eye file (round-trips through
/// [`parse_hand_eye`] exactly).
pub fn hand_eye_to_toml(f: &HandEyeFile) -> String {
    let mut s = String::from("# photopose hand-eye calibration (frames: see docs/hand-eye.md)\n");
    s += "[camera_in_tcp]          # X = T_tcp←camera\n";
    s += &format!(
        "xyzabc = {}      # mm, deg (KUKA A,B,C)\n",
        list(&f.camera_in_tcp.xyzabc)
    );
    s += &format!("std_xyzabc = {}\n", list(&f.camera_in_tcp.std_xyzabc));
    s += "[plate_in_base]          # Z = T_base←plate\n";
    s += &format!("xyzabc = {}\n", list(&f.plate_in_base.xyzabc));
    s += &format!("std_xyzabc = {}\n", list(&f.plate_in_base.std_xyzabc));
    if let Some(fit) = &f.fit {
        s += &format!(
            "[fit]\nstations = {}\nsigma0 = {}\nrms_mm = {}\nrms_deg = {}\n",
            fit.stations,
            crate::camera::toml_float(fit.sigma0),
            crate::camera::toml_float(fit.rms_mm),
            crate::camera::toml_float(fit.rms_deg)
        );
    }
    s
}

/// Writes a hand-eye file.
pub fn save_hand_eye(path: &Path, f: &HandEyeFile) -> Result<(), FormatError> {
    std::fs::write(path, hand_eye_to_toml(f)).map_err(|source| FormatError::Write {
        path: path.display().to_string(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn sample() -> HandEyeFile {
        HandEyeFile {
            camera_in_tcp: Transform {
                xyzabc: [35.012345678901, -80.0, 160.25, 91.0, 2.5, 178.5],
                std_xyzabc: [0.021, 0.019, 0.034, 0.0021, 0.0018, 0.0025],
            },
            plate_in_base: Transform {
                xyzabc: [1100.0, 200.0, 15.0, 25.0, 0.8, -0.6],
                std_xyzabc: [0.03, 0.031, 0.02, 0.002, 0.0021, 0.0019],
            },
            fit: Some(Fit {
                stations: 12,
                sigma0: 1.02,
                rms_mm: 0.011,
                rms_deg: 0.0012,
            }),
        }
    }

    #[test]
    fn round_trips_exactly() {
        let f = sample();
        let text = hand_eye_to_toml(&f);
        assert!(text.starts_with("# photopose hand-eye calibration"));
        assert_eq!(parse_hand_eye(&text, "he.toml").unwrap(), f);
        let no_fit = HandEyeFile { fit: None, ..f };
        assert_eq!(
            parse_hand_eye(&hand_eye_to_toml(&no_fit), "he.toml").unwrap(),
            no_fit
        );
    }

    #[test]
    fn round_trips_through_a_file() {
        let path = std::env::temp_dir().join(format!("photopose-he-{}.toml", std::process::id()));
        save_hand_eye(&path, &sample()).unwrap();
        assert_eq!(load_hand_eye(&path).unwrap(), sample());
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn isometry_follows_kuka_abc() {
        let t = Transform {
            xyzabc: [1.0, 2.0, 3.0, 90.0, 0.0, 0.0],
            std_xyzabc: [0.0; 6],
        };
        let iso = t.isometry();
        // A = 90°: the frame's x axis is the parent's y axis.
        let x = iso.rotation * Vector3::x();
        assert!((x - Vector3::y()).norm() < 1e-12);
        assert_eq!(iso.translation.vector, Vector3::new(1.0, 2.0, 3.0));
    }

    fn check_err(text: &str, want: &str) {
        let e = parse_hand_eye(text, "he.toml").unwrap_err().to_string();
        assert!(e.starts_with("he.toml: "), "{e}");
        assert!(e.contains(want), "`{e}` lacks `{want}`");
    }

    #[test]
    fn bad_files_name_the_key() {
        let good = hand_eye_to_toml(&sample());
        check_err(
            &good.replace("rms_deg", "rms_grad"),
            "unknown field `rms_grad`",
        );
        check_err(
            &good.replacen("std_xyzabc = [0.021", "std_xyzabc = [-0.021", 1),
            "camera_in_tcp.std_xyzabc[0] (X) = -0.021",
        );
        check_err(
            &good.replace("[plate_in_base]", "[plate_in_world]"),
            "unknown field `plate_in_world`",
        );
        check_err(
            &good.replace("stations = 12", "stations = 2"),
            "fit.stations = 2",
        );
        check_err(
            "[camera_in_tcp]\nxyzabc = [1, 2, 3, 4, 5, 6]\nstd_xyzabc = [0, 0, 0, 0, 0, 0]\n",
            "missing field `plate_in_base`",
        );
        check_err(
            "[camera_in_tcp]\nxyzabc = [1, 2, 3]\nstd_xyzabc = [0, 0, 0, 0, 0, 0]\n",
            "line 2",
        );
    }

    #[test]
    fn huge_but_finite_values_are_refused_naming_the_key() {
        let good = hand_eye_to_toml(&sample());
        check_err(
            &good.replace("xyzabc = [35.012345678901,", "xyzabc = [1.7e308,"),
            "camera_in_tcp.xyzabc[0] (X) = 170000000000000000000",
        );
        check_err(
            &good.replace(
                "xyzabc = [1100.0, 200.0, 15.0,",
                "xyzabc = [1100.0, -1.7e308, 15.0,",
            ),
            "plate_in_base.xyzabc[1] (Y) = -1700000000000000",
        );
        check_err(
            &good.replace(
                "xyzabc = [1100.0, 200.0, 15.0,",
                "xyzabc = [1100.0, 200.0, 100000.5,",
            ),
            "plate_in_base.xyzabc[2] (Z) = 100000.5 is outside ±100000 mm",
        );
        check_err(
            &good.replace("91.0, 2.5, 178.5]", "91.0, 2.5, 1e300]"),
            "camera_in_tcp.xyzabc[5] (C) = 1000000",
        );
        check_err(
            &good.replace("25.0, 0.8, -0.6]", "25.0, -361.0, -0.6]"),
            "plate_in_base.xyzabc[4] (B) = -361 is outside ±360 °",
        );
        check_err(
            &good.replacen("std_xyzabc = [0.021", "std_xyzabc = [1e6", 1),
            "camera_in_tcp.std_xyzabc[0] (X) = 1000000 is not a standard deviation",
        );
        check_err(
            &good.replace("0.002, 0.0021, 0.0019]", "0.002, 0.0021, 181.0]"),
            "plate_in_base.std_xyzabc[5] (C) = 181",
        );
        check_err(
            &good.replace("rms_mm = 0.011", "rms_mm = 1e9"),
            "fit.rms_mm = 1000000000",
        );
        // The limits themselves are accepted.
        let edge = good
            .replace(
                "xyzabc = [1100.0, 200.0, 15.0,",
                "xyzabc = [100000.0, -100000.0, 15.0,",
            )
            .replace("25.0, 0.8, -0.6]", "360.0, -360.0, 359.9]");
        parse_hand_eye(&edge, "he.toml").unwrap();
    }
}
