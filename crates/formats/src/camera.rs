//! The camera file (TOML, `docs/conventions.md`): `[sensor]`, `[interior]`,
//! optional `[distortion]`. Unknown keys and missing required keys are errors
//! that name the file and the key.
//!
//! Values are range-checked at load, naming the key: sensor sides
//! 2..=65535 px, pixel size 0.1–100 µm, principal distance 0.1–10 000 mm,
//! the principal point on the sensor, and distortion parameters whose
//! correction stays finite and smaller than the sensor diagonal at every
//! corner of the sensor.

use crate::FormatError;
use photopose_geometry::{Camera, Distortion, Interior, Sensor};
use serde::Deserialize;
use std::path::Path;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    sensor: SensorToml,
    interior: InteriorToml,
    #[serde(default)]
    distortion: DistortionToml,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorToml {
    width: i64,
    height: i64,
    pixel_size: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct InteriorToml {
    c: f64,
    x0: f64,
    y0: f64,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
struct DistortionToml {
    k1: f64,
    k2: f64,
    k3: f64,
    p1: f64,
    p2: f64,
    b1: f64,
    b2: f64,
}

/// Parses camera TOML text; `origin` names the file in errors.
pub fn parse_camera(text: &str, origin: &str) -> Result<Camera, FormatError> {
    let err = |what: String| FormatError::Camera {
        origin: origin.into(),
        what,
    };
    let f: File = toml::from_str(text).map_err(|e| {
        // toml's message names the key and shows the line; keep it on one line.
        let msg = e.message().to_string();
        let at = e
            .span()
            .map(|s| {
                let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                format!("line {line}: ")
            })
            .unwrap_or_default();
        err(format!("{at}{msg}"))
    })?;
    let dim = |key: &str, v: i64| -> Result<u32, FormatError> {
        match u32::try_from(v) {
            Ok(n) if (2..=MAX_SENSOR_SIDE).contains(&n) => Ok(n),
            _ => Err(err(format!(
                "{key} = {v} must be a pixel count in 2..={MAX_SENSOR_SIDE}"
            ))),
        }
    };
    let within = |key: &str, v: f64, (lo, hi): (f64, f64), unit: &str| {
        if v.is_finite() && (lo..=hi).contains(&v) {
            Ok(())
        } else {
            Err(err(format!("{key} = {v} must be {lo}..={hi} {unit}")))
        }
    };
    within(
        "sensor.pixel_size",
        f.sensor.pixel_size,
        PIXEL_SIZE_MM,
        "mm",
    )?;
    within("interior.c", f.interior.c, PRINCIPAL_DISTANCE_MM, "mm")?;
    let sensor = Sensor {
        width: dim("sensor.width", f.sensor.width)?,
        height: dim("sensor.height", f.sensor.height)?,
        pixel_size: f.sensor.pixel_size,
    };
    let d = f.distortion;
    let camera = Camera::new(
        sensor,
        Interior {
            c: f.interior.c,
            x0: f.interior.x0,
            y0: f.interior.y0,
        },
        Distortion {
            k1: d.k1,
            k2: d.k2,
            k3: d.k3,
            p1: d.p1,
            p2: d.p2,
            b1: d.b1,
            b2: d.b2,
        },
    )
    .map_err(|e| err(e.to_string()))?;
    check_distortion(&camera).map_err(err)?;
    Ok(camera)
}

/// Largest sensor side of a camera file, px.
pub const MAX_SENSOR_SIDE: u32 = 65_535;
/// Range of the pixel size, mm (0.1–100 µm).
pub const PIXEL_SIZE_MM: (f64, f64) = (1e-4, 0.1);
/// Range of the principal distance, mm.
pub const PRINCIPAL_DISTANCE_MM: (f64, f64) = (0.1, 10_000.0);

/// Checks that the distortion correction is finite and smaller than the
/// sensor diagonal at the four sensor corners (the farthest points from the
/// principal point, where the polynomial terms are largest); the error
/// names the parameter whose term is largest there.
fn check_distortion(camera: &Camera) -> Result<(), String> {
    let s = &camera.sensor;
    let (w, h) = (s.width as f64 - 1.0, s.height as f64 - 1.0);
    let diagonal = (s.width as f64).hypot(s.height as f64) * s.pixel_size;
    let d = &camera.distortion;
    for (col, row) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
        let m = camera.pixel_to_image(col, row);
        let (x, y) = (m.x - camera.interior.x0, m.y - camera.interior.y0);
        let size = d.correction(x, y).norm();
        if size.is_finite() && size <= diagonal {
            continue;
        }
        // The term of each parameter alone at this corner names the key.
        let zero = Distortion::default();
        let terms = [
            ("distortion.k1", d.k1, Distortion { k1: d.k1, ..zero }),
            ("distortion.k2", d.k2, Distortion { k2: d.k2, ..zero }),
            ("distortion.k3", d.k3, Distortion { k3: d.k3, ..zero }),
            ("distortion.p1", d.p1, Distortion { p1: d.p1, ..zero }),
            ("distortion.p2", d.p2, Distortion { p2: d.p2, ..zero }),
            ("distortion.b1", d.b1, Distortion { b1: d.b1, ..zero }),
            ("distortion.b2", d.b2, Distortion { b2: d.b2, ..zero }),
        ];
        let mut worst = ("distortion", 0.0, f64::NEG_INFINITY);
        for (key, coefficient, alone) in terms {
            let v = alone.correction(x, y).norm();
            let v = if v.is_nan() { f64::INFINITY } else { v };
            if v > worst.2 {
                worst = (key, coefficient, v);
            }
        }
        let (key, coefficient, value) = worst;
        return Err(format!(
            "{key} = {coefficient:e}: the distortion correction at sensor corner \
             ({col}, {row}) is {size:.3e} mm (this term alone {value:.3e} mm), more than the \
             sensor diagonal of {diagonal:.3} mm"
        ));
    }
    Ok(())
}

/// The text of the project's default camera (`config/camera.toml`).
pub const DEFAULT_CAMERA_TOML: &str = include_str!("../../../config/camera.toml");

/// The project's default camera (`config/camera.toml`), built in.
pub fn default_camera() -> Camera {
    parse_camera(DEFAULT_CAMERA_TOML, "<built-in config/camera.toml>")
        .expect("the shipped config/camera.toml is valid (checked by a test)")
}

/// Loads a camera file.
pub fn load_camera(path: &Path) -> Result<Camera, FormatError> {
    let text = crate::read_text(path, crate::FileKind::Camera)?;
    parse_camera(&text, &path.display().to_string())
}

/// The TOML text of a camera (round-trips through [`parse_camera`]).
pub fn camera_to_toml(cam: &Camera) -> String {
    let d = &cam.distortion;
    format!(
        "[sensor]\nwidth = {}          # px\nheight = {}         # px\npixel_size = {}   # mm\n\n\
         [interior]\nc = {}              # principal distance, mm\nx0 = {}             # principal point, mm from the image centre\ny0 = {}\n\n\
         [distortion]          # Brown/Fraser parameters, mm-based\nk1 = {}\nk2 = {}\nk3 = {}\np1 = {}\np2 = {}\nb1 = {}\nb2 = {}\n",
        cam.sensor.width,
        cam.sensor.height,
        toml_float(cam.sensor.pixel_size),
        toml_float(cam.interior.c),
        toml_float(cam.interior.x0),
        toml_float(cam.interior.y0),
        toml_float(d.k1),
        toml_float(d.k2),
        toml_float(d.k3),
        toml_float(d.p1),
        toml_float(d.p2),
        toml_float(d.b1),
        toml_float(d.b2)
    )
}

/// A number as a TOML float that reads back to the same `f64`: the
/// shortest round-trip digits, with a `.0` where they would read as an
/// integer.
pub(crate) fn toml_float(v: f64) -> String {
    let s = v.to_string();
    if v.is_finite() && !s.contains(['.', 'e', 'E']) {
        s + ".0"
    } else if v.is_nan() {
        "nan".into()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "[sensor]\nwidth = 1300\nheight = 1030\npixel_size = 0.0067\n[interior]\nc = 12.0\nx0 = 0.0\ny0 = 0.0\n";

    #[test]
    fn the_shipped_default_camera_is_valid() {
        let cam = default_camera();
        assert_eq!((cam.sensor.width, cam.sensor.height), (1300, 1030));
    }

    #[test]
    fn missing_distortion_means_zero_and_round_trips() {
        let cam = parse_camera(GOOD, "cam.toml").unwrap();
        assert!(cam.distortion.is_zero());
        let mut strong = cam;
        strong.distortion.k1 = -2.5e-3;
        strong.distortion.b2 = 1.0 / 3.0;
        assert_eq!(parse_camera(&camera_to_toml(&strong), "x").unwrap(), strong);
    }

    #[test]
    fn errors_name_file_and_key() {
        let cases = [
            (
                GOOD.replace("pixel_size = 0.0067", "pixel_size = -0.0067"),
                "sensor.pixel_size",
            ),
            (GOOD.replace("c = 12.0", "c = 12.0\nfocal = 3.0"), "focal"),
            (GOOD.replace("x0 = 0.0\n", ""), "x0"),
            (GOOD.replace("width = 1300", "width = -5"), "sensor.width"),
            (format!("{GOOD}[distortion]\nk4 = 1.0\n"), "k4"),
            (GOOD.replace("c = 12.0", "c = \"twelve\""), "line 6"),
        ];
        for (text, want) in cases {
            let e = parse_camera(&text, "cam.toml").unwrap_err().to_string();
            assert!(
                e.starts_with("cam.toml: ") && e.contains(want),
                "{e:?} lacks {want:?}"
            );
        }
    }

    #[test]
    fn values_outside_physical_ranges_are_refused_naming_the_key() {
        let cases = [
            (GOOD.replace("c = 12.0", "c = 0.05"), "interior.c = 0.05 must be 0.1..=10000 mm"),
            (GOOD.replace("c = 12.0", "c = 1e308"), "interior.c = 1000"),
            (
                GOOD.replace("pixel_size = 0.0067", "pixel_size = 0.00001"),
                "sensor.pixel_size = 0.00001 must be 0.0001..=0.1 mm",
            ),
            (
                GOOD.replace("pixel_size = 0.0067", "pixel_size = 0.5"),
                "sensor.pixel_size = 0.5",
            ),
            (
                GOOD.replace("width = 1300", "width = 65536"),
                "sensor.width = 65536 must be a pixel count in 2..=65535",
            ),
            (
                GOOD.replace("height = 1030", "height = 1"),
                "sensor.height = 1 must be",
            ),
            (
                format!("{GOOD}[distortion]\nk1 = 1e300\n"),
                "distortion.k1 = 1e300: the distortion correction at sensor corner (0, 0) is inf mm",
            ),
            (
                format!("{GOOD}[distortion]\nk3 = 1.0\n"),
                "distortion.k3 = 1e0: the distortion correction at sensor corner",
            ),
            (
                format!("{GOOD}[distortion]\nk2 = 1e-2\nb2 = 0.001\n"),
                "distortion.k2 = 1e-2",
            ),
            (format!("{GOOD}[distortion]\nb1 = 5.0\n"), "distortion.b1 = 5e0"),
            (format!("{GOOD}[distortion]\np2 = 1.0\n"), "more than the sensor diagonal of 11.113 mm"),
        ];
        for (text, want) in cases {
            let e = parse_camera(&text, "cam.toml").unwrap_err().to_string();
            assert!(
                e.starts_with("cam.toml: ") && e.contains(want),
                "{e:?} lacks {want:?}"
            );
        }
        // The ranges' ends are accepted, and so is a strong real lens.
        for ok in [
            GOOD.replace("c = 12.0", "c = 0.1"),
            GOOD.replace("c = 12.0", "c = 10000.0"),
            GOOD.replace("pixel_size = 0.0067", "pixel_size = 0.0001"),
            GOOD.replace("width = 1300", "width = 65535"),
            format!("{GOOD}[distortion]\nk1 = -2.5e-3\nk2 = 1e-5\np1 = 1e-4\nb1 = 1e-3\n"),
        ] {
            parse_camera(&ok, "cam.toml").unwrap();
        }
    }

    #[test]
    fn a_camera_file_is_read_with_its_limit() {
        let dir = std::env::temp_dir().join(format!("photopose-cam-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("padded.toml");
        // A valid camera file padded with comments beyond the camera limit.
        let mut text = GOOD.to_string();
        while text.len() as u64 <= crate::FileKind::Camera.limit() {
            text.push_str("# ................................................................\n");
        }
        std::fs::write(&p, &text).unwrap();
        let e = load_camera(&p).unwrap_err().to_string();
        assert!(e.contains("too large for the camera file"), "{e}");
        std::fs::write(&p, GOOD).unwrap();
        load_camera(&p).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
