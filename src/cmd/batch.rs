//! What the batch commands (`resect`, `detect`) share: the error line of a
//! failed input, loading a frame checked against the camera, and the exit
//! status of a batch (docs/conventions.md: non-zero if any input failed).

use photopose_frame::Image;
use photopose_geometry::Camera;
use serde::Serialize;
use std::path::Path;
use std::process::ExitCode;

/// The output line of a failed input.
#[derive(Serialize)]
pub struct ErrorLine<'a> {
    /// The input path.
    pub image: &'a str,
    /// Always false.
    pub ok: bool,
    /// What and why.
    pub error: String,
}

impl<'a> ErrorLine<'a> {
    /// The line for `image` failing with `error`.
    pub fn new(image: &'a str, error: String) -> Self {
        ErrorLine {
            image,
            ok: false,
            error,
        }
    }
}

/// Loads an image file of the camera's sensor size (checked from the
/// file's header before any pixel is decoded); the error names the file.
pub fn load_frame(path: &Path, camera: &Camera) -> Result<Image, String> {
    photopose_formats::load_image_for(path, camera).map_err(|e| e.to_string())
}

/// The exit status of a batch with `failed` failed inputs.
pub fn exit_status(failed: usize) -> ExitCode {
    if failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}
