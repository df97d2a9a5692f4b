//! The errors of the circular test and the cell model.

use thiserror::Error;

/// Why a circular test or a cell could not be computed.
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum CircleError {
    /// Fewer samples than the fit needs.
    #[error("{what}: {got} samples, at least {need} needed")]
    TooFewSamples {
        /// What was being fitted.
        what: &'static str,
        /// Samples given.
        got: usize,
        /// Samples needed.
        need: usize,
    },
    /// A sample holds a value that is not a finite number.
    #[error("sample {index}: {what} is not finite")]
    NotFinite {
        /// Index of the sample.
        index: usize,
        /// Which value.
        what: &'static str,
    },
    /// The positions do not span a plane (all on one line or one point).
    #[error("the positions do not span a plane (spread across the line {spread_mm:.3e} mm)")]
    Collinear {
        /// Root-mean-square spread of the positions off their best line, mm.
        spread_mm: f64,
    },
    /// The circle fit did not settle.
    #[error(
        "the circle fit did not converge in {iterations} iterations (last step {step_mm:.3e} mm)"
    )]
    NotConverged {
        /// Iterations done.
        iterations: usize,
        /// Size of the last step, mm.
        step_mm: f64,
    },
    /// A parameter of the analysis or of the cell model is out of range.
    #[error("{name} = {value}: {why}")]
    BadParameter {
        /// The parameter's name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong with it.
        why: &'static str,
    },
}
