//! The calibration report: σ0, every parameter with its standard deviation,
//! correlations above 0.9 named, residual RMS per image and overall, the
//! images skipped and the observations rejected; as a serialisable value
//! (the command writes it as JSON) and as text.

use crate::calibrate::{Calibration, Skipped};
use crate::params::{values, Fixed, Param};
use serde::Serialize;
use std::cmp::Ordering;
use std::fmt::Write;

/// Natural order of names: digit runs compare as numbers (`v1, v2, …,
/// v10`), the rest as text. The one sort of image names, for the report's
/// lines, the plots and the command's inputs.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    alphanumeric_sort::compare_str(a, b)
}

/// Correlations above this are named.
pub const CORRELATION_LIMIT: f64 = 0.9;

/// An image whose residual RMS exceeds this multiple of the median is named.
pub const BAD_IMAGE_RATIO: f64 = 3.0;

/// One camera parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterLine {
    /// Key of the camera file.
    pub name: &'static str,
    /// Adjusted value.
    pub value: f64,
    /// A-posteriori standard deviation (`None` when fixed).
    pub std: Option<f64>,
    /// Held at its initial value.
    pub fixed: bool,
    /// Unit.
    pub unit: &'static str,
}

/// A pair of strongly correlated parameters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Correlation {
    /// First parameter.
    pub a: &'static str,
    /// Second parameter.
    pub b: &'static str,
    /// Correlation coefficient.
    pub rho: f64,
}

/// One image.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageLine {
    /// Its name.
    pub image: String,
    /// Observations used.
    pub n_used: usize,
    /// RMS of the image-coordinate residuals of the used observations, px.
    pub rms_px: f64,
    /// Target ids rejected by data snooping.
    pub rejected_ids: Vec<u64>,
    /// Adjusted camera pose in the field, KUKA X, Y, Z, A, B, C (mm, degrees).
    pub pose_xyzabc: [f64; 6],
}

/// The report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// A-posteriori σ0 of an image coordinate, px.
    pub sigma0_px: f64,
    /// The same, mm.
    pub sigma0_mm: f64,
    /// RMS of all used image-coordinate residuals, px.
    pub rms_px: f64,
    /// Observations used (target images).
    pub n_observations: usize,
    /// Unknowns net of any datum defect.
    pub n_unknowns: usize,
    /// Observations rejected by data snooping.
    pub n_rejected: usize,
    /// Iterations of the adjustment, all runs.
    pub iterations: usize,
    /// Identification rounds.
    pub rounds: usize,
    /// The parameters.
    pub parameters: Vec<ParameterLine>,
    /// Correlations above [`CORRELATION_LIMIT`].
    pub correlations: Vec<Correlation>,
    /// Images used.
    pub images: Vec<ImageLine>,
    /// Images skipped (not readable, plate not found, no start).
    pub skipped: Vec<Skipped>,
    /// Warnings for the user.
    pub warnings: Vec<String>,
}

impl Report {
    /// The report of a calibration; `skipped_before` are images the caller
    /// could not even detect in (unreadable files), reported first.
    pub fn new(cal: &Calibration, fixed: &Fixed, skipped_before: &[Skipped]) -> Report {
        let r = &cal.result;
        let ps = r.camera.sensor.pixel_size;
        let v = values(&r.camera);
        let cov = &r.covariance;
        let parameters = Param::ALL
            .iter()
            .map(|&p| {
                let i = p.index();
                let is_fixed = fixed.is_fixed(p);
                ParameterLine {
                    name: p.name(),
                    value: v[i],
                    std: (!is_fixed).then(|| cov[(i, i)].max(0.0).sqrt()),
                    fixed: is_fixed,
                    unit: p.unit(),
                }
            })
            .collect();
        let mut correlations = Vec::new();
        for (a, pa) in Param::ALL.iter().enumerate() {
            for (b, pb) in Param::ALL.iter().enumerate().skip(a + 1) {
                let d = (cov[(a, a)] * cov[(b, b)]).sqrt();
                if d > 0.0 {
                    let rho = cov[(a, b)] / d;
                    if rho.abs() > CORRELATION_LIMIT {
                        correlations.push(Correlation {
                            a: pa.name(),
                            b: pb.name(),
                            rho,
                        });
                    }
                }
            }
        }
        let mut total = 0.0;
        let mut count = 0usize;
        let mut images: Vec<ImageLine> = cal
            .images
            .iter()
            .map(|im| {
                let used: Vec<_> = im.residuals.iter().filter(|x| x.used).collect();
                let ss: f64 = used.iter().map(|x| x.dcol * x.dcol + x.drow * x.drow).sum();
                total += ss;
                count += used.len();
                ImageLine {
                    image: im.name.clone(),
                    n_used: used.len(),
                    rms_px: (ss / (2 * used.len().max(1)) as f64).sqrt(),
                    rejected_ids: im
                        .residuals
                        .iter()
                        .filter(|x| !x.used)
                        .map(|x| x.id)
                        .collect(),
                    pose_xyzabc: im.exterior.to_kuka_pose(),
                }
            })
            .collect();
        images.sort_by(|a, b| natural_cmp(&a.image, &b.image));
        let mut warnings: Vec<String> = correlations
            .iter()
            .map(|c| {
                format!(
                    "{} and {} are correlated {:+.3}: they are hard to separate with these images (fix one, or add tilted and rolled images)",
                    c.a, c.b, c.rho
                )
            })
            .collect();
        for p in Param::ALL {
            let i = p.index();
            if fixed.is_fixed(p) || matches!(p, Param::C) {
                continue;
            }
            let sd = cov[(i, i)].max(0.0).sqrt();
            if v[i] != 0.0 && sd > v[i].abs() {
                warnings.push(format!(
                    "{} = {:.3e} is smaller than its standard deviation {:.1e}: not significant (consider --fix {})",
                    p.name(),
                    v[i],
                    sd,
                    p.name()
                ));
            }
        }
        // An image that fits far worse than the others (moved, refocused,
        // a wrong identification the snooping could not take out).
        let mut rms: Vec<f64> = images.iter().map(|i| i.rms_px).collect();
        rms.sort_by(f64::total_cmp);
        if let Some(&median) = rms.get(rms.len() / 2) {
            for im in &images {
                if im.rms_px > BAD_IMAGE_RATIO * median && im.rms_px > 0.05 {
                    warnings.push(format!(
                        "image {} fits badly: residual RMS {:.3} px against a median of {:.3} px (did the camera move or refocus?)",
                        im.image, im.rms_px, median
                    ));
                }
            }
        }
        let mut skipped = skipped_before.to_vec();
        skipped.extend(cal.skipped.iter().cloned());
        for s in &skipped {
            warnings.push(format!("image {} skipped: {}", s.image, s.reason));
        }
        Report {
            sigma0_px: r.sigma0 / ps,
            sigma0_mm: r.sigma0,
            rms_px: (total / (2 * count.max(1)) as f64).sqrt(),
            n_observations: r.n_observations,
            n_unknowns: r.n_unknowns,
            n_rejected: images.iter().map(|i| i.rejected_ids.len()).sum(),
            iterations: r.iterations,
            rounds: cal.rounds,
            parameters,
            correlations,
            images,
            skipped,
            warnings,
        }
    }

    /// The report as text for a person.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "camera calibration: {} images, {} observations, {} unknowns, {} rejected, {} iterations",
            self.images.len(),
            self.n_observations,
            self.n_unknowns,
            self.n_rejected,
            self.iterations
        );
        let _ = writeln!(
            s,
            "sigma0 = {:.4} px ({:.3e} mm), residual RMS = {:.4} px",
            self.sigma0_px, self.sigma0_mm, self.rms_px
        );
        let _ = writeln!(s, "\nparameter          value            std");
        for p in &self.parameters {
            match p.std {
                Some(sd) => {
                    let _ = writeln!(
                        s,
                        "  {:<4} {:>+16.9e}  ± {:.2e} {}",
                        p.name, p.value, sd, p.unit
                    );
                }
                None => {
                    let _ = writeln!(s, "  {:<4} {:>+16.9e}  (fixed) {}", p.name, p.value, p.unit);
                }
            }
        }
        if !self.correlations.is_empty() {
            let _ = writeln!(s, "\ncorrelations above {CORRELATION_LIMIT}:");
            for c in &self.correlations {
                let _ = writeln!(s, "  {} / {}: {:+.3}", c.a, c.b, c.rho);
            }
        }
        let _ = writeln!(s, "\nimage residuals:");
        for im in &self.images {
            let _ = write!(
                s,
                "  {}: {} used, RMS {:.4} px",
                im.image, im.n_used, im.rms_px
            );
            if !im.rejected_ids.is_empty() {
                let ids: Vec<String> = im.rejected_ids.iter().map(u64::to_string).collect();
                let _ = write!(s, ", rejected ids {}", ids.join(", "));
            }
            let _ = writeln!(s);
        }
        for sk in &self.skipped {
            let _ = writeln!(s, "  {}: SKIPPED: {}", sk.image, sk.reason);
        }
        if !self.warnings.is_empty() {
            let _ = writeln!(s, "\nwarnings:");
            for w in &self.warnings {
                let _ = writeln!(s, "  - {w}");
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_counts_digit_runs_as_numbers() {
        let mut names = vec![
            "v10.pgm", "v2.pgm", "v1.pgm", "v11.pgm", "a/v9.pgm", "v1b.pgm",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            ["a/v9.pgm", "v1.pgm", "v1b.pgm", "v2.pgm", "v10.pgm", "v11.pgm"]
        );
    }
}
