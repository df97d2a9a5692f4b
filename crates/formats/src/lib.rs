//! photopose-formats: reading and writing the project's files.
//!
//! Owns the camera TOML file, loading of test-field CSV files and the
//! observation CSV (`id,col,row`). Parsing functions take text and an origin
//! (file name) for error messages; `load_*` functions read the file first.

pub mod camera;
pub mod observations;

pub use camera::{camera_to_toml, load_camera, parse_camera};
pub use observations::{load_observations, parse_observations, PixelObservation};

use std::path::Path;
use thiserror::Error;

/// A file that could not be used, with what and where.
#[derive(Debug, Error)]
pub enum FormatError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The path.
        path: String,
        /// The IO error.
        source: std::io::Error,
    },
    /// The camera file is not valid.
    #[error("{origin}: {what}")]
    Camera {
        /// File name.
        origin: String,
        /// What is wrong, with the key.
        what: String,
    },
    /// The test field is not valid.
    #[error(transparent)]
    Field(#[from] photopose_field::FieldError),
    /// An observation file is not valid.
    #[error("{origin}:{line}: {what}")]
    Observations {
        /// File name.
        origin: String,
        /// 1-based line (0: the whole file).
        line: usize,
        /// What is wrong.
        what: String,
    },
}

/// Reads a text file, naming it in the error.
pub fn read_text(path: &Path) -> Result<String, FormatError> {
    std::fs::read_to_string(path).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Loads a test field CSV file.
pub fn load_field(path: &Path) -> Result<photopose_field::Field, FormatError> {
    let text = read_text(path)?;
    Ok(photopose_field::Field::parse_csv(
        &text,
        &path.display().to_string(),
    )?)
}
