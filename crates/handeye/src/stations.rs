//! The station file: CSV with a header row, one station a row (parsed from
//! text handed in; the binary reads the file).
//!
//! ```text
//! station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c,image,cam_x,cam_y,cam_z,cam_a,cam_b,cam_c,cam_std_x,cam_std_y,cam_std_z,cam_std_rx,cam_std_ry,cam_std_rz
//! s01,812.4,-120.0,655.1,172.0,-3.5,178.2,frames/s01.pgm,,,,,,,,,,,,
//! s02,790.0,-80.2,640.7,150.3,5.1,-171.9,,12.1,-40.3,598.2,20.4,3.1,-176.0,0.031,0.045,0.012,0.004,0.003,0.0008
//! ```
//!
//! - `station`: a name (no comma), unique in the file.
//! - `robot_x … robot_c`: the TCP in the robot base as the controller
//!   reports it (`RIst`): KUKA `X, Y, Z, A, B, C`, mm and degrees.
//! - either `image`: a frame taken at the station (path relative to the
//!   station file), from which photopose measures the camera pose;
//! - or `cam_x … cam_c`: the camera pose in the plate as photopose reports
//!   it (`camera_xyzabc_mm_deg` of `photopose resect`: the projection
//!   centre and `A, B, C` of `Rᵀ`), with optionally `cam_std_x … cam_std_z`
//!   (mm) and `cam_std_rx … cam_std_rz` (degrees, rotations about the
//!   plate's axes: `pose.std_position_mm` and `pose.std_rotation_deg` of
//!   `photopose resect`).
//!
//! Only `station` and the six `robot_*` columns are required in the header;
//! the others may be left out (all of a group or none). An unknown column is
//! an error naming it. Blank lines and lines starting with `#` are skipped.

use crate::{CameraPose, HandEyeError, Station};
use photopose_geometry::pose::{isometry_from_xyzabc, xyzabc_from_isometry};

/// The header of a station file with every column, in the order
/// [`StationRow::csv_line`] writes them.
pub const STATIONS_HEADER: &str = "station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c,image,\
cam_x,cam_y,cam_z,cam_a,cam_b,cam_c,cam_std_x,cam_std_y,cam_std_z,cam_std_rx,cam_std_ry,cam_std_rz";

const ROBOT: [&str; 6] = [
    "robot_x", "robot_y", "robot_z", "robot_a", "robot_b", "robot_c",
];
const CAM: [&str; 6] = ["cam_x", "cam_y", "cam_z", "cam_a", "cam_b", "cam_c"];
const CAM_STD: [&str; 6] = [
    "cam_std_x",
    "cam_std_y",
    "cam_std_z",
    "cam_std_rx",
    "cam_std_ry",
    "cam_std_rz",
];

/// Where a station's camera pose comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum CameraSource {
    /// A frame to locate (path as written in the file).
    Image(String),
    /// The camera pose in the plate, KUKA `X … C` (mm, degrees), with the
    /// standard deviations of the centre (mm) and of the rotations about the
    /// plate's axes (degrees) if the file gives them.
    Pose {
        /// `cam_x … cam_c`.
        xyzabc: [f64; 6],
        /// `cam_std_x … cam_std_rz`.
        std: Option<[f64; 6]>,
    },
}

/// One row of a station file.
#[derive(Debug, Clone, PartialEq)]
pub struct StationRow {
    /// 1-based line in the file (0 for a row made in memory).
    pub line: usize,
    /// The station's name.
    pub name: String,
    /// The TCP in the base, KUKA `X … C` (mm, degrees).
    pub robot_xyzabc: [f64; 6],
    /// The camera pose or the frame to measure it from.
    pub camera: CameraSource,
}

impl StationRow {
    /// The row of a measured station (pose columns, standard deviations
    /// from the diagonal of the camera pose's covariance).
    pub fn from_station(station: &Station) -> Self {
        let c = &station.camera.covariance;
        let std = std::array::from_fn(|k| {
            let s = c[(k, k)].max(0.0).sqrt();
            if k >= 3 {
                s.to_degrees()
            } else {
                s
            }
        });
        StationRow {
            line: 0,
            name: station.name.clone(),
            robot_xyzabc: xyzabc_from_isometry(&station.robot),
            camera: CameraSource::Pose {
                xyzabc: xyzabc_from_isometry(&station.camera.pose),
                std: Some(std),
            },
        }
    }

    /// The row as one line of [`STATIONS_HEADER`]'s columns (no newline).
    /// Numbers are written so that they read back exactly. A name with a
    /// comma, a line break or a leading `#` cannot be written.
    pub fn csv_line(&self) -> Result<String, HandEyeError> {
        check_name(&self.name).map_err(|what| HandEyeError::StationFile {
            origin: "<station>".into(),
            line: self.line,
            what,
        })?;
        let mut out = self.name.clone();
        let mut push = |v: &dyn std::fmt::Display| {
            out.push(',');
            out.push_str(&v.to_string());
        };
        for v in self.robot_xyzabc {
            push(&v);
        }
        match &self.camera {
            CameraSource::Image(path) => {
                if path.contains([',', '\n', '\r']) {
                    return Err(HandEyeError::StationFile {
                        origin: "<station>".into(),
                        line: self.line,
                        what: format!("image path `{path}` contains a comma or line break"),
                    });
                }
                push(path);
                for _ in 0..12 {
                    push(&"");
                }
            }
            CameraSource::Pose { xyzabc, std } => {
                push(&"");
                for v in xyzabc {
                    push(v);
                }
                match std {
                    Some(s) => s.iter().for_each(|v| push(v)),
                    None => (0..6).for_each(|_| push(&"")),
                }
            }
        }
        Ok(out)
    }

    /// The station of a row with the camera pose given; missing standard
    /// deviations are `default_std` (centre mm, rotations degrees). `None`
    /// for a row that names an image.
    pub fn to_station(&self, default_std: [f64; 6]) -> Option<Station> {
        let CameraSource::Pose { xyzabc, std } = &self.camera else {
            return None;
        };
        let s = std.unwrap_or(default_std);
        Some(Station {
            name: self.name.clone(),
            robot: isometry_from_xyzabc(self.robot_xyzabc),
            camera: CameraPose::with_stds(
                isometry_from_xyzabc(*xyzabc),
                [s[0], s[1], s[2]],
                [s[3], s[4], s[5]],
            ),
        })
    }
}

fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("empty station name".into());
    }
    if name.contains([',', '\n', '\r']) || name.starts_with('#') || name.trim() != name {
        return Err(format!(
            "station name `{name}` must not contain a comma or line break, start with `#` or \
             have surrounding spaces"
        ));
    }
    Ok(())
}

/// Parses a station file's text; `origin` names it in errors.
pub fn parse_stations(text: &str, origin: &str) -> Result<Vec<StationRow>, HandEyeError> {
    let err = |line: usize, what: String| HandEyeError::StationFile {
        origin: origin.into(),
        line,
        what,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(k, l)| (k + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let (hline, header) = lines
        .next()
        .ok_or_else(|| err(0, "empty file: no header row".into()))?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let known: Vec<&str> = std::iter::once("station")
        .chain(ROBOT)
        .chain(std::iter::once("image"))
        .chain(CAM)
        .chain(CAM_STD)
        .collect();
    for (k, n) in names.iter().enumerate() {
        if !known.contains(n) {
            return Err(err(
                hline,
                format!("unknown column `{n}` (the columns are: {STATIONS_HEADER})"),
            ));
        }
        if names[..k].contains(n) {
            return Err(err(hline, format!("column `{n}` given twice")));
        }
    }
    let col = |n: &str| names.iter().position(|h| *h == n);
    let group = |g: &[&str; 6]| -> Result<Option<[usize; 6]>, HandEyeError> {
        let found: Vec<Option<usize>> = g.iter().map(|n| col(n)).collect();
        if found.iter().all(Option::is_none) {
            return Ok(None);
        }
        if let Some(k) = found.iter().position(Option::is_none) {
            return Err(err(
                hline,
                format!(
                    "column `{}` is missing (give all of {} or none)",
                    g[k],
                    g.join(",")
                ),
            ));
        }
        Ok(Some(std::array::from_fn(|k| found[k].unwrap_or(0))))
    };
    let station_col =
        col("station").ok_or_else(|| err(hline, "column `station` is missing".into()))?;
    let robot_cols = group(&ROBOT)?
        .ok_or_else(|| err(hline, format!("columns {} are missing", ROBOT.join(","))))?;
    let image_col = col("image");
    let cam_cols = group(&CAM)?;
    let std_cols = group(&CAM_STD)?;
    if image_col.is_none() && cam_cols.is_none() {
        return Err(err(
            hline,
            "neither an `image` column nor the camera pose columns cam_x..cam_c: \
             a station needs one of them"
                .into(),
        ));
    }

    let mut rows: Vec<StationRow> = Vec::new();
    // Station name → its line: duplicates found in constant time per row.
    let mut lines_of: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for (line, text) in lines {
        let fields: Vec<&str> = text.split(',').map(str::trim).collect();
        if fields.len() != names.len() {
            return Err(err(
                line,
                format!("{} fields, the header has {}", fields.len(), names.len()),
            ));
        }
        let name = fields[station_col].to_string();
        check_name(&name).map_err(|w| err(line, w))?;
        if let Some(first) = lines_of.get(&name) {
            return Err(err(
                line,
                format!("station `{name}` is also on line {first}"),
            ));
        }
        lines_of.insert(name.clone(), line);
        let number = |c: usize| -> Result<Option<f64>, HandEyeError> {
            let f = fields[c];
            if f.is_empty() {
                return Ok(None);
            }
            match f.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(Some(v)),
                _ => Err(err(
                    line,
                    format!("column `{}`: `{f}` is not a finite number", names[c]),
                )),
            }
        };
        let six = |cols: [usize; 6]| -> Result<Option<[f64; 6]>, HandEyeError> {
            let v: Vec<Option<f64>> = cols.iter().map(|&c| number(c)).collect::<Result<_, _>>()?;
            if v.iter().all(Option::is_none) {
                return Ok(None);
            }
            if let Some(k) = v.iter().position(Option::is_none) {
                return Err(err(line, format!("column `{}` is empty", names[cols[k]])));
            }
            Ok(Some(std::array::from_fn(|k| v[k].unwrap_or(0.0))))
        };
        let robot = six(robot_cols)?
            .ok_or_else(|| err(line, "the robot pose (robot_x..robot_c) is empty".into()))?;
        let image = image_col
            .map(|c| fields[c])
            .filter(|f| !f.is_empty())
            .map(str::to_string);
        let pose = cam_cols.map(six).transpose()?.flatten();
        let std = std_cols.map(six).transpose()?.flatten();
        if let Some(s) = std {
            if let Some(k) = s.iter().position(|v| *v <= 0.0) {
                return Err(err(
                    line,
                    format!("column `{}`: {} must be positive", CAM_STD[k], s[k]),
                ));
            }
        }
        let camera = match (image, pose) {
            (Some(_), Some(_)) => {
                return Err(err(
                    line,
                    "both `image` and the camera pose cam_x..cam_c are given: give one".into(),
                ))
            }
            (None, None) => {
                return Err(err(
                    line,
                    "neither `image` nor the camera pose cam_x..cam_c is given".into(),
                ))
            }
            (Some(path), None) => {
                if std.is_some() {
                    return Err(err(
                        line,
                        "cam_std_* given with an image: the image's resection gives them".into(),
                    ));
                }
                CameraSource::Image(path)
            }
            (None, Some(xyzabc)) => CameraSource::Pose { xyzabc, std },
        };
        rows.push(StationRow {
            line,
            name,
            robot_xyzabc: robot,
            camera,
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_err(text: &str, want: &str) {
        match parse_stations(text, "st.csv") {
            Err(e) => assert!(e.to_string().contains(want), "{e} lacks `{want}`"),
            Ok(r) => panic!("accepted: {r:?}"),
        }
    }

    #[test]
    fn rows_round_trip_through_the_writer() {
        let text = format!(
            "{STATIONS_HEADER}\n\
             s01,812.4,-120,655.1,172,-3.5,178.2,frames/s01.pgm,,,,,,,,,,,,\n\
             # a comment\n\
             s02,790,-80.2,640.7,150.3,5.1,-171.9,,12.1,-40.3,598.2,20.4,3.1,-176,0.031,0.045,0.012,0.004,0.003,0.0008\n\
             s03,790,-80.2,640.7,150.3,5.1,-171.9,,12.1,-40.3,598.2,20.4,3.1,-176,,,,,,\n"
        );
        let rows = parse_stations(&text, "st.csv").unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[0].camera, CameraSource::Image("frames/s01.pgm".into()));
        assert_eq!(rows[1].line, 4);
        let mut again = String::from(STATIONS_HEADER);
        for r in &rows {
            again.push('\n');
            again.push_str(&r.csv_line().unwrap());
        }
        let back = parse_stations(&again, "again.csv").unwrap();
        for (a, b) in rows.iter().zip(&back) {
            assert_eq!(
                (&a.name, a.robot_xyzabc, &a.camera),
                (&b.name, b.robot_xyzabc, &b.camera)
            );
        }
    }

    #[test]
    fn a_station_round_trips_exactly_through_a_line() {
        let s = Station {
            name: "live-7".into(),
            robot: isometry_from_xyzabc([812.4, -120.0, 655.1, 172.0, -3.5, 178.2]),
            camera: CameraPose::with_stds(
                isometry_from_xyzabc([12.1, -40.3, 598.2, 20.4, 3.1, -176.0]),
                [0.031, 0.045, 0.012],
                [0.004, 0.003, 0.0008],
            ),
        };
        let line = StationRow::from_station(&s).csv_line().unwrap();
        let rows = parse_stations(&format!("{STATIONS_HEADER}\n{line}\n"), "x").unwrap();
        let back = rows[0].to_station([1.0; 6]).unwrap();
        assert_eq!(back.name, s.name);
        assert!((back.robot.translation.vector - s.robot.translation.vector).norm() < 1e-12);
        assert!(back.robot.rotation.angle_to(&s.robot.rotation) < 1e-12);
        assert!((back.camera.covariance - s.camera.covariance).abs().max() < 1e-15);
    }

    #[test]
    fn bad_files_name_the_column_and_line() {
        check_err("station,robot_x\n", "column `robot_y` is missing");
        check_err(
            "station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c,image,colour\n",
            "unknown column `colour`",
        );
        let h = "station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c,image";
        check_err(
            &format!("{h}\ns1,1,2,3,4,5,x,a.pgm\n"),
            "st.csv:2: column `robot_c`: `x`",
        );
        check_err(
            &format!("{h}\ns1,1,2,3,4,5,6\n"),
            "st.csv:2: 7 fields, the header has 8",
        );
        check_err(&format!("{h}\ns1,1,2,3,4,5,6,\n"), "neither `image`");
        check_err(
            &format!("{h}\ns1,1,2,3,4,5,6,a.pgm\ns1,1,2,3,4,5,6,b.pgm\n"),
            "st.csv:3: station `s1` is also on line 2",
        );
        check_err(
            &format!("{h}\ns1,1,2,,4,5,6,a.pgm\n"),
            "column `robot_z` is empty",
        );
        check_err("", "no header row");
        check_err(
            "station,robot_x,robot_y,robot_z,robot_a,robot_b,robot_c\n",
            "neither an `image` column",
        );
    }
}
