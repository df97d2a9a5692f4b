//! The camera file (TOML, `docs/conventions.md`): `[sensor]`, `[interior]`,
//! optional `[distortion]`, and optional `[calibration]`: how a calibrated
//! camera's parameters were found (σ of each parameter, σ0, images,
//! observations, date, tool, input files with their SHA-256; written by
//! `photopose calibrate camera`, checked here, never used for numerics).
//! Unknown keys and missing required keys are errors
//! that name the file and the key.
//!
//! Values are range-checked at load, naming the key: sensor sides
//! 2..=65535 px, pixel size 0.1–100 µm, principal distance 0.1–10 000 mm,
//! the principal point on the sensor, and distortion parameters whose
//! correction stays finite and smaller than the sensor diagonal at every
//! corner of the sensor.

use crate::provenance::{self, InputFile};
use crate::FormatError;
use photopose_geometry::{Camera, Distortion, Interior, Sensor};
use serde::Deserialize;
use std::fmt::Write;
use std::path::Path;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    sensor: SensorToml,
    interior: InteriorToml,
    #[serde(default)]
    distortion: DistortionToml,
    calibration: Option<CalibrationRecord>,
}

/// The names of the camera parameters a calibration estimates, in the
/// order of the file, with their units.
pub const PARAMETERS: [(&str, &str); 10] = [
    ("c", "mm"),
    ("x0", "mm"),
    ("y0", "mm"),
    ("k1", "mm^-2"),
    ("k2", "mm^-4"),
    ("k3", "mm^-6"),
    ("p1", "mm^-1"),
    ("p2", "mm^-1"),
    ("b1", "1"),
    ("b2", "1"),
];

/// A-posteriori standard deviations of the camera parameters, in the units
/// of the parameters (`c`, `x0`, `y0` mm; `k1` mm⁻², `k2` mm⁻⁴, `k3` mm⁻⁶;
/// `p1`, `p2` mm⁻¹; `b1`, `b2` unitless); a fixed parameter has none.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParameterStd {
    /// σ of `c`, mm.
    pub c: Option<f64>,
    /// σ of `x0`, mm.
    pub x0: Option<f64>,
    /// σ of `y0`, mm.
    pub y0: Option<f64>,
    /// σ of `k1`, mm⁻².
    pub k1: Option<f64>,
    /// σ of `k2`, mm⁻⁴.
    pub k2: Option<f64>,
    /// σ of `k3`, mm⁻⁶.
    pub k3: Option<f64>,
    /// σ of `p1`, mm⁻¹.
    pub p1: Option<f64>,
    /// σ of `p2`, mm⁻¹.
    pub p2: Option<f64>,
    /// σ of `b1`.
    pub b1: Option<f64>,
    /// σ of `b2`.
    pub b2: Option<f64>,
}

impl ParameterStd {
    /// The values in the order of [`PARAMETERS`].
    pub fn values(&self) -> [Option<f64>; 10] {
        [
            self.c, self.x0, self.y0, self.k1, self.k2, self.k3, self.p1, self.p2, self.b1, self.b2,
        ]
    }

    /// Standard deviations from values in the order of [`PARAMETERS`].
    pub fn from_values(v: [Option<f64>; 10]) -> ParameterStd {
        let [c, x0, y0, k1, k2, k3, p1, p2, b1, b2] = v;
        ParameterStd {
            c,
            x0,
            y0,
            k1,
            k2,
            k3,
            p1,
            p2,
            b1,
            b2,
        }
    }
}

/// The `[calibration]` section of a calibrated camera file: how the
/// parameters were found.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationRecord {
    /// When: UTC, RFC 3339.
    pub date: String,
    /// Tool and version (`photopose 0.1.0`).
    pub tool: String,
    /// Images used by the adjustment.
    pub images: u32,
    /// Image points used (observations of targets).
    pub observations: u32,
    /// A-posteriori σ0 of an image coordinate, px.
    pub sigma0_px: f64,
    /// The same, mm in the image plane.
    pub sigma0_mm: f64,
    /// Parameters held at their initial value.
    #[serde(default)]
    pub fixed: Vec<String>,
    /// Standard deviations of the estimated parameters (`[calibration.std]`).
    pub std: ParameterStd,
    /// Input files: the images, the initial camera, the field
    /// (`[[calibration.inputs]]`).
    #[serde(default)]
    pub inputs: Vec<InputFile>,
}

/// A camera file: the camera and, for a calibrated camera, its record.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraFile {
    /// The camera.
    pub camera: Camera,
    /// The `[calibration]` section, when the file has one.
    pub calibration: Option<CalibrationRecord>,
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
    parse_camera_file(text, origin).map(|f| f.camera)
}

/// Parses camera TOML text with its `[calibration]` section, if any;
/// `origin` names the file in errors.
pub fn parse_camera_file(text: &str, origin: &str) -> Result<CameraFile, FormatError> {
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
    if let Some(c) = &f.calibration {
        check_record(c).map_err(err)?;
    }
    Ok(CameraFile {
        camera,
        calibration: f.calibration,
    })
}

/// Checks the values of a `[calibration]` section, naming the key.
fn check_record(c: &CalibrationRecord) -> Result<(), String> {
    provenance::parse_rfc3339(&c.date).map_err(|e| format!("calibration.date = {e}"))?;
    for (key, v) in [("sigma0_px", c.sigma0_px), ("sigma0_mm", c.sigma0_mm)] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(format!("calibration.{key} = {v} must be a finite σ ≥ 0"));
        }
    }
    for ((name, unit), v) in PARAMETERS.iter().zip(c.std.values()) {
        if let Some(v) = v {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "calibration.std.{name} = {v} must be a finite σ ≥ 0 {unit}"
                ));
            }
        }
    }
    for (k, name) in c.fixed.iter().enumerate() {
        if !PARAMETERS.iter().any(|(p, _)| p == name) {
            return Err(format!(
                "calibration.fixed[{k}] = \"{name}\" is not a camera parameter (c, x0, y0, k1, k2, k3, p1, p2, b1, b2)"
            ));
        }
    }
    for (k, input) in c.inputs.iter().enumerate() {
        if !provenance::is_sha256_hex(&input.sha256) {
            return Err(format!(
                "calibration.inputs[{k}].sha256 = \"{}\" must be 64 hex digits",
                input.sha256
            ));
        }
    }
    Ok(())
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
    load_camera_file(path).map(|f| f.camera)
}

/// Loads a camera file with its `[calibration]` section, if any.
pub fn load_camera_file(path: &Path) -> Result<CameraFile, FormatError> {
    let text = crate::read_text(path, crate::FileKind::Camera)?;
    parse_camera_file(&text, &path.display().to_string())
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

/// A TOML string (quoted and escaped).
fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// The TOML text of a calibrated camera: the parameters, then the
/// `[calibration]` section (round-trips through [`parse_camera_file`]).
pub fn camera_file_to_toml(file: &CameraFile) -> String {
    let mut s = camera_to_toml(&file.camera);
    let Some(c) = &file.calibration else {
        return s;
    };
    let _ = write!(
        s,
        "\n[calibration]         # how these parameters were found\n\
         date = {}\n\
         tool = {}\n\
         images = {}\n\
         observations = {}    # image points used\n\
         sigma0_px = {}     # a-posteriori σ0 of an image coordinate, px\n\
         sigma0_mm = {}     # the same, mm\n\
         fixed = [{}]         # held at their initial value\n\
         \n[calibration.std]     # a-posteriori standard deviations, units of the parameters\n",
        toml_string(&c.date),
        toml_string(&c.tool),
        c.images,
        c.observations,
        toml_float(c.sigma0_px),
        toml_float(c.sigma0_mm),
        c.fixed
            .iter()
            .map(|f| toml_string(f))
            .collect::<Vec<_>>()
            .join(", "),
    );
    for ((name, unit), v) in PARAMETERS.iter().zip(c.std.values()) {
        if let Some(v) = v {
            let _ = writeln!(s, "{name} = {}   # {unit}", toml_float(v));
        }
    }
    for input in &c.inputs {
        let _ = write!(
            s,
            "\n[[calibration.inputs]]\npath = {}\nsha256 = {}\n",
            toml_string(&input.path),
            toml_string(&input.sha256)
        );
    }
    s
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
        // The reference camera of the examples and tests is this one.
        assert_eq!(cam, photopose_geometry::Camera::reference());
        let ideal = photopose_geometry::Camera::reference_ideal();
        assert_eq!(
            (ideal.sensor, ideal.interior.c),
            (cam.sensor, cam.interior.c)
        );
        assert!(ideal.distortion.is_zero());
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

    fn calibrated() -> CameraFile {
        let mut camera = parse_camera(GOOD, "cam.toml").unwrap();
        camera.distortion.k1 = -2.5e-3;
        CameraFile {
            camera,
            calibration: Some(CalibrationRecord {
                date: "2026-11-24T16:08:08Z".into(),
                tool: "photopose 0.1.0".into(),
                images: 12,
                observations: 2345,
                sigma0_px: 0.031,
                sigma0_mm: 0.031 * 0.0067,
                fixed: vec!["k3".into()],
                std: ParameterStd {
                    c: Some(1.5e-4),
                    x0: Some(2.0e-4),
                    k1: Some(3.0e-7),
                    ..ParameterStd::default()
                },
                inputs: vec![InputFile {
                    path: "images/v \"1\".pgm".into(),
                    sha256: crate::provenance::sha256_hex(b"v1"),
                }],
            }),
        }
    }

    #[test]
    fn a_calibration_section_round_trips_and_plain_loading_accepts_it() {
        let file = calibrated();
        let text = camera_file_to_toml(&file);
        assert!(text.contains("[calibration.std]") && text.contains("c = 0.00015   # mm"));
        assert!(text.contains("k1 = 0.0000003   # mm^-2"), "{text}");
        assert_eq!(parse_camera_file(&text, "cam.toml").unwrap(), file);
        assert_eq!(parse_camera(&text, "cam.toml").unwrap(), file.camera);
        // Without a section: none, and the plain writer stays as it was.
        let plain = CameraFile {
            calibration: None,
            ..file
        };
        assert_eq!(camera_file_to_toml(&plain), camera_to_toml(&plain.camera));
        assert_eq!(
            parse_camera_file(&camera_to_toml(&plain.camera), "x").unwrap(),
            plain
        );
    }

    #[test]
    fn a_bad_calibration_section_is_refused_naming_the_key() {
        let text = camera_file_to_toml(&calibrated());
        let cases = [
            (text.replace("k1 = 0.0000003", "k4 = 0.0000003"), "k4"),
            (
                text.replace("images = 12", "images = 12\nweather = 1"),
                "weather",
            ),
            (
                text.replace("2026-11-24T16:08:08Z", "yesterday"),
                "calibration.date",
            ),
            (
                text.replace("c = 0.00015", "c = -0.00015"),
                "calibration.std.c = -0.00015",
            ),
            (
                text.replace("[\"k3\"]", "[\"k9\"]"),
                "calibration.fixed[0] = \"k9\"",
            ),
            (
                text.replace(&crate::provenance::sha256_hex(b"v1"), "beef"),
                "calibration.inputs[0].sha256",
            ),
            (
                text.replace("sigma0_px = 0.031", "sigma0_px = nan"),
                "calibration.sigma0_px",
            ),
        ];
        for (bad, want) in cases {
            let e = parse_camera_file(&bad, "cam.toml").unwrap_err().to_string();
            assert!(
                e.starts_with("cam.toml: ") && e.contains(want),
                "{e:?} lacks {want:?}"
            );
        }
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
