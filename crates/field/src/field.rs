//! The test field: targets with ids, positions, kinds and radii, and the CSV
//! format of `docs/conventions.md` (`id,x,y,z,kind,radius`, mm).

use crate::codes;
use nalgebra::Vector3;
use std::collections::HashMap;
use std::fmt::Write as _;
use thiserror::Error;

/// Coded (centre dot with a 12-sector code ring) or uncoded (dot only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TargetKind {
    /// Dot with code ring; its id is the code number.
    Coded,
    /// Dot alone.
    Uncoded,
}

impl TargetKind {
    /// The word used in files.
    pub fn as_str(self) -> &'static str {
        match self {
            TargetKind::Coded => "coded",
            TargetKind::Uncoded => "uncoded",
        }
    }
}

/// One target of the plate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Unique positive id (code number for coded targets).
    pub id: u64,
    /// Centre of the dot in the field frame, mm.
    pub position: Vector3<f64>,
    /// Coded or not.
    pub kind: TargetKind,
    /// Radius of the bright centre dot, mm.
    pub radius: f64,
}

impl Target {
    /// Radius of the outermost bright part of the target (code ring or
    /// dot), mm.
    pub fn bright_radius(&self) -> f64 {
        match self.kind {
            TargetKind::Coded => 3.0 * self.radius,
            TargetKind::Uncoded => self.radius,
        }
    }

    /// Radius of the dark quiet zone around the target, mm.
    pub fn quiet_radius(&self) -> f64 {
        match self.kind {
            TargetKind::Coded => 4.0 * self.radius,
            TargetKind::Uncoded => 2.0 * self.radius,
        }
    }
}

/// A problem with a test field, naming where it is.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum FieldError {
    /// The text is empty or has no header.
    #[error("{origin}: empty test field (expected header `id,x,y,z,kind,radius`)")]
    Empty {
        /// File name or other origin.
        origin: String,
    },
    /// The header is not the expected one.
    #[error("{origin}:1: header is `{found}`, expected `id,x,y,z,kind,radius`")]
    Header {
        /// Origin.
        origin: String,
        /// The header found.
        found: String,
    },
    /// A row could not be read.
    #[error("{origin}:{line}: {what}")]
    Row {
        /// Origin.
        origin: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// Two targets too close (one reaches into the other's quiet zone).
    #[error("targets {a} and {b} overlap: {distance:.2} mm apart, quiet zones need {need:.2} mm")]
    Overlap {
        /// First id.
        a: u64,
        /// Second id.
        b: u64,
        /// Their distance.
        distance: f64,
        /// The distance they need.
        need: f64,
    },
}

/// The test field (calibration plate).
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    targets: Vec<Target>,
    index: HashMap<u64, usize>,
}

impl Field {
    /// A field from targets; ids must be unique and coded ids valid codes.
    pub fn new(targets: Vec<Target>) -> Result<Self, FieldError> {
        let mut index = HashMap::with_capacity(targets.len());
        for (k, t) in targets.iter().enumerate() {
            let row = |what: String| FieldError::Row {
                origin: "field".into(),
                line: k + 1,
                what,
            };
            validate_target(t).map_err(row)?;
            if index.insert(t.id, k).is_some() {
                return Err(row(format!("duplicate id {}", t.id)));
            }
        }
        Ok(Field { targets, index })
    }

    /// Parses the CSV text of a test field; `origin` names it in errors.
    pub fn parse_csv(text: &str, origin: &str) -> Result<Self, FieldError> {
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let Some((_, header)) = lines.next() else {
            return Err(FieldError::Empty {
                origin: origin.into(),
            });
        };
        let cols: Vec<&str> = header.split(',').map(str::trim).collect();
        if cols != ["id", "x", "y", "z", "kind", "radius"] {
            return Err(FieldError::Header {
                origin: origin.into(),
                found: header.into(),
            });
        }
        let mut targets = Vec::new();
        let mut index = HashMap::new();
        for (line, text) in lines {
            let err = |what: String| FieldError::Row {
                origin: origin.into(),
                line,
                what,
            };
            let f: Vec<&str> = text.split(',').map(str::trim).collect();
            if f.len() != 6 {
                return Err(err(format!("expected 6 columns, found {}", f.len())));
            }
            let id: u64 = f[0]
                .parse()
                .map_err(|_| err(format!("id `{}` is not a positive integer", f[0])))?;
            let num = |name: &str, s: &str| -> Result<f64, FieldError> {
                let v: f64 = s
                    .parse()
                    .map_err(|_| err(format!("{name} `{s}` is not a number")))?;
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(err(format!("{name} `{s}` is not finite")))
                }
            };
            let position = Vector3::new(num("x", f[1])?, num("y", f[2])?, num("z", f[3])?);
            let kind = match f[4] {
                "coded" => TargetKind::Coded,
                "uncoded" => TargetKind::Uncoded,
                other => {
                    return Err(err(format!(
                        "kind `{other}` is neither `coded` nor `uncoded`"
                    )))
                }
            };
            let radius = num("radius", f[5])?;
            let t = Target {
                id,
                position,
                kind,
                radius,
            };
            validate_target(&t).map_err(err)?;
            if let Some(prev) = index.insert(id, targets.len()) {
                return Err(err(format!(
                    "duplicate id {id} (first on data row {})",
                    prev + 1
                )));
            }
            targets.push(t);
        }
        if targets.is_empty() {
            return Err(FieldError::Empty {
                origin: origin.into(),
            });
        }
        Ok(Field { targets, index })
    }

    /// The CSV text of the field.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("id,x,y,z,kind,radius\n");
        for t in &self.targets {
            let _ = writeln!(
                s,
                "{},{},{},{},{},{}",
                t.id,
                t.position.x,
                t.position.y,
                t.position.z,
                t.kind.as_str(),
                t.radius
            );
        }
        s
    }

    /// All targets in file order.
    pub fn targets(&self) -> &[Target] {
        &self.targets
    }

    /// The target with `id`.
    pub fn get(&self, id: u64) -> Option<&Target> {
        self.index.get(&id).map(|&k| &self.targets[k])
    }

    /// Index of the target with `id` in [`Field::targets`].
    pub fn index_of(&self, id: u64) -> Option<usize> {
        self.index.get(&id).copied()
    }

    /// Number of targets.
    pub fn len(&self) -> usize {
        self.targets.len()
    }

    /// Whether the field has no targets.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    /// Coded targets.
    pub fn coded(&self) -> impl Iterator<Item = &Target> {
        self.targets.iter().filter(|t| t.kind == TargetKind::Coded)
    }

    /// Uncoded targets.
    pub fn uncoded(&self) -> impl Iterator<Item = &Target> {
        self.targets
            .iter()
            .filter(|t| t.kind == TargetKind::Uncoded)
    }

    /// Checks that no bright part of a target (dot or code ring) reaches
    /// into another's quiet zone (targets assumed in one plane; distances
    /// are measured in 3-D).
    pub fn check_quiet_zones(&self) -> Result<(), FieldError> {
        for (i, a) in self.targets.iter().enumerate() {
            for b in &self.targets[i + 1..] {
                let d = (a.position - b.position).norm();
                let need = (a.quiet_radius() + b.bright_radius())
                    .max(b.quiet_radius() + a.bright_radius());
                if d < need {
                    return Err(FieldError::Overlap {
                        a: a.id,
                        b: b.id,
                        distance: d,
                        need,
                    });
                }
            }
        }
        Ok(())
    }
}

fn validate_target(t: &Target) -> Result<(), String> {
    if t.id == 0 {
        return Err("id 0 is not allowed (ids are positive)".into());
    }
    if !(t.radius.is_finite() && t.radius > 0.0) {
        return Err(format!(
            "radius {} must be a positive length in mm",
            t.radius
        ));
    }
    if !t.position.iter().all(|v| v.is_finite()) {
        return Err("coordinates must be finite".into());
    }
    if t.kind == TargetKind::Coded && codes::value_of(t.id).is_none() {
        return Err(format!(
            "coded target id {} is not a code number (1..=350)",
            t.id
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_spec_example_and_round_trips() {
        let text =
            "id,x,y,z,kind,radius\n17,120.0,40.0,0.0,coded,4.0\n1001,130.0,40.0,0.0,uncoded,1.5\n";
        let f = Field::parse_csv(text, "plate.csv").unwrap();
        assert_eq!(f.len(), 2);
        assert_eq!(f.get(17).unwrap().kind, TargetKind::Coded);
        let again = Field::parse_csv(&f.to_csv(), "again").unwrap();
        assert_eq!(f, again);
    }

    #[test]
    fn a_code_ring_in_a_quiet_zone_is_an_overlap() {
        // Coded r = 3 (ring to 9 mm, quiet zone 12), uncoded r = 5 (quiet
        // zone 10): 18 mm apart the dots keep clear of each other's quiet
        // zones (12 + 5, 10 + 3), but the ring reaches into the uncoded
        // target's quiet zone (10 + 9 = 19 > 18).
        let text = "id,x,y,z,kind,radius\n2,0,0,0,coded,3\n1001,18,0,0,uncoded,5\n";
        let f = Field::parse_csv(text, "p.csv").unwrap();
        assert!(matches!(
            f.check_quiet_zones(),
            Err(FieldError::Overlap { .. })
        ));
        let ok = Field::parse_csv(
            "id,x,y,z,kind,radius\n2,0,0,0,coded,3\n1001,19,0,0,uncoded,5\n",
            "p.csv",
        )
        .unwrap();
        ok.check_quiet_zones().unwrap();
    }

    #[test]
    fn errors_name_file_and_line() {
        let cases = [
            ("", "empty"),
            ("id,x,y\n", "header"),
            (
                "id,x,y,z,kind,radius\n1,0,0,0,coded,1\n1,5,0,0,coded,1\n",
                "plate.csv:3: duplicate id 1",
            ),
            (
                "id,x,y,z,kind,radius\n1,abc,0,0,coded,1\n",
                "plate.csv:2: x `abc`",
            ),
            ("id,x,y,z,kind,radius\n1,NaN,0,0,coded,1\n", "not finite"),
            (
                "id,x,y,z,kind,radius\n999,0,0,0,coded,1\n",
                "not a code number",
            ),
            ("id,x,y,z,kind,radius\n1,0,0,0,round,1\n", "kind `round`"),
            ("id,x,y,z,kind,radius\n1,0,0,0,coded,-1\n", "radius"),
        ];
        for (text, want) in cases {
            let e = Field::parse_csv(text, "plate.csv").unwrap_err().to_string();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
    }
}
