//! photopose-formats: reading and writing the project's files.
//!
//! Owns the camera TOML file, loading of test-field CSV files, the
//! observation CSV (`id,col,row`), image files (greyscale PGM and PNG),
//! the provenance of reports ([`provenance`]: tool, date, input hashes)
//! and reading files with limits ([`file`](mod@file): every file photopose reads goes
//! through [`read_text`] or [`read_bytes`]). Parsing functions take text and
//! an origin (file name) for error messages; `load_*` functions read the file
//! first.

pub mod camera;
pub mod file;
pub mod hand_eye;
pub mod image;
pub mod observations;
pub mod provenance;

pub use camera::{
    camera_file_to_toml, camera_to_toml, default_camera, load_camera, load_camera_file,
    parse_camera, parse_camera_file, CalibrationRecord, CameraFile, ParameterStd,
};
pub use file::{read_bytes, read_bytes_into, read_bytes_limited, read_text, FileError, FileKind};
pub use image::{
    check_size, decode_image, decode_image_for, decode_pgm, decode_png, encode_pgm, encode_png,
    load_image, load_image_for, save_image, ImageFormat, ImageLimits, ImageReader,
};
pub use observations::{load_observations, parse_observations, PixelObservation};

use std::path::Path;
use thiserror::Error;

/// A file that could not be used, with what and where.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FormatError {
    /// The file could not be read (missing, not a regular file, too large,
    /// not text, IO error).
    #[error(transparent)]
    File(#[from] FileError),
    /// The file could not be written.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The path.
        path: String,
        /// The IO error.
        source: std::io::Error,
    },
    /// An image file ends before its data does.
    #[error("{origin}: truncated: {what} needs {expected} bytes, the file has {found}")]
    Truncated {
        /// File name.
        origin: String,
        /// What the bytes were needed for.
        what: String,
        /// Bytes the file should have (at least).
        expected: usize,
        /// Bytes it has.
        found: usize,
    },
    /// An image file's header cannot be read.
    #[error("{origin}: corrupt image header: {what}")]
    ImageHeader {
        /// File name.
        origin: String,
        /// What is wrong.
        what: String,
    },
    /// An image file's pixel data are invalid (a bad compressed stream,
    /// values above the header's `maxval`).
    #[error("{origin}: corrupt image data: {what}")]
    ImageData {
        /// File name.
        origin: String,
        /// What is wrong.
        what: String,
    },
    /// A valid image of a kind photopose does not read (colour, palette, ...).
    #[error("{origin}: unsupported image: {what}")]
    UnsupportedImage {
        /// File name.
        origin: String,
        /// The kind of image and what is supported.
        what: String,
    },
    /// An image whose size differs from the camera's sensor.
    #[error(
        "{origin}: image is {width}×{height}, camera file says {camera_width}×{camera_height}"
    )]
    ImageSize {
        /// File name.
        origin: String,
        /// Image width, px.
        width: u32,
        /// Image height, px.
        height: u32,
        /// Sensor width of the camera file, px.
        camera_width: u32,
        /// Sensor height of the camera file, px.
        camera_height: u32,
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
    /// The hand-eye file is not valid.
    #[error("{origin}: {what}")]
    HandEye {
        /// File name.
        origin: String,
        /// What is wrong, with the key.
        what: String,
    },
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

/// Loads a test field CSV file.
pub fn load_field(path: &Path) -> Result<photopose_field::Field, FormatError> {
    let text = read_text(path, FileKind::Field)?;
    Ok(photopose_field::Field::parse_csv(
        &text,
        &path.display().to_string(),
    )?)
}
