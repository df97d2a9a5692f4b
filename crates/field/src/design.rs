//! Plate design: a rectangular grid of targets with coded targets on a
//! coarser sub-grid, respecting the quiet zones and using the even codes.

use crate::codes;
use crate::field::{Field, FieldError, Target, TargetKind};
use nalgebra::Vector3;

/// Parameters of a designed plate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateDesign {
    /// Grid columns.
    pub cols: u32,
    /// Grid rows.
    pub rows: u32,
    /// Grid spacing, mm.
    pub spacing: f64,
    /// Centre-dot radius of coded targets, mm.
    pub coded_radius: f64,
    /// Centre-dot radius of uncoded targets, mm.
    pub uncoded_radius: f64,
    /// A coded target every `coded_step` grid cells in both directions.
    pub coded_step: u32,
    /// Column and row of the first coded target.
    pub coded_offset: (u32, u32),
    /// Leave the four corner cells empty.
    pub skip_corners: bool,
    /// First id of the uncoded targets.
    pub first_uncoded_id: u64,
}

impl Default for PlateDesign {
    /// The default plate of photopose: 18 × 13 grid at 32 mm (544 × 384 mm),
    /// 30 coded targets (r = 3 mm) and 200 uncoded targets (r = 2.5 mm), in
    /// the plane `Z = 0` centred on the origin: the set-up of the reference
    /// paper's table 1 seen from about 1 m with a 12 mm lens.
    fn default() -> Self {
        PlateDesign {
            cols: 18,
            rows: 13,
            spacing: 32.0,
            coded_radius: 3.0,
            uncoded_radius: 2.5,
            coded_step: 3,
            coded_offset: (1, 0),
            skip_corners: true,
            first_uncoded_id: 1001,
        }
    }
}

impl PlateDesign {
    /// Builds the field; errors if the design breaks a quiet zone or needs
    /// more than the 178 even codes.
    pub fn build(&self) -> Result<Field, FieldError> {
        let mut even = codes::even_ids();
        let mut next_uncoded = self.first_uncoded_id;
        let mut targets = Vec::new();
        let x0 = -(self.cols as f64 - 1.0) * self.spacing / 2.0;
        let y0 = (self.rows as f64 - 1.0) * self.spacing / 2.0;
        for row in 0..self.rows {
            for col in 0..self.cols {
                let corner =
                    (col == 0 || col == self.cols - 1) && (row == 0 || row == self.rows - 1);
                if corner && self.skip_corners {
                    continue;
                }
                let coded = self.coded_step > 0
                    && col >= self.coded_offset.0
                    && row >= self.coded_offset.1
                    && (col - self.coded_offset.0).is_multiple_of(self.coded_step)
                    && (row - self.coded_offset.1).is_multiple_of(self.coded_step);
                let position = Vector3::new(
                    x0 + col as f64 * self.spacing,
                    y0 - row as f64 * self.spacing,
                    0.0,
                );
                let (id, kind, radius) = if coded {
                    let id = even.next().ok_or(FieldError::Row {
                        origin: "plate design".into(),
                        line: 0,
                        what: "more coded targets than the 178 even codes".into(),
                    })?;
                    (id, TargetKind::Coded, self.coded_radius)
                } else {
                    next_uncoded += 1;
                    (next_uncoded - 1, TargetKind::Uncoded, self.uncoded_radius)
                };
                targets.push(Target {
                    id,
                    position,
                    kind,
                    radius,
                });
            }
        }
        let field = Field::new(targets)?;
        field.check_quiet_zones()?;
        Ok(field)
    }
}

/// The default plate (see [`PlateDesign::default`]).
pub fn default_plate() -> Field {
    PlateDesign::default()
        .build()
        .expect("the default plate design is valid")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_plate_has_30_coded_and_200_uncoded_even_codes() {
        let f = default_plate();
        assert_eq!(f.coded().count(), 30);
        assert_eq!(f.uncoded().count(), 200);
        assert!(f.coded().all(|t| codes::is_even(t.id)));
        f.check_quiet_zones().unwrap();
    }

    #[test]
    fn crowded_design_is_refused() {
        let d = PlateDesign {
            spacing: 10.0,
            ..PlateDesign::default()
        };
        assert!(matches!(d.build(), Err(FieldError::Overlap { .. })));
    }
}
