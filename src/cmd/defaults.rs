//! The built-in defaults: the camera and plate shipped in `config/`, used
//! when a command is not given `--camera` or `--field`.

use anyhow::{Context, Result};
use photopose_field::Field;
use photopose_geometry::Camera;
use std::path::Path;

/// The default plate's text (`config/plate.csv`).
pub const PLATE_CSV: &str = include_str!("../../config/plate.csv");

/// The camera from `path`, or the built-in default.
pub fn camera(path: Option<&Path>) -> Result<Camera> {
    match path {
        Some(p) => Ok(photopose_formats::load_camera(p)?),
        None => Ok(photopose_formats::default_camera()),
    }
}

/// The field from `path`, or the built-in default plate.
pub fn field(path: Option<&Path>) -> Result<Field> {
    match path {
        Some(p) => Ok(photopose_formats::load_field(p)?),
        None => {
            Field::parse_csv(PLATE_CSV, "<built-in config/plate.csv>").context("built-in plate")
        }
    }
}
