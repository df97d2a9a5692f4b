//! photopose-geometry: the pure mathematical core of photopose.
//!
//! Everything here follows `docs/conventions.md` to the letter:
//! millimetres, image coordinates with `y'` up, the Brown/Fraser correction
//! applied to *measured* coordinates, the collinearity equations with `R`
//! mapping object vectors into the camera frame, and the Cayley /
//! Hamilton-normalised quaternion rotation `R = (I + S)(I - S)^-1`.
//!
//! Every pose conversion of photopose lives here ([`pose`], [`rotation`]):
//! KUKA `X, Y, Z, A, B, C` ↔ matrix ↔ isometry, exterior orientation ↔
//! camera pose, quaternions, the one re-orthonormalisation and the
//! propagation of covariances through them. Other crates call these.
//!
//! Module layers (imports point downwards only): `camera`, `rotation`,
//! `rng`, `error` → `exterior`, `observation` → `pose`, `linearised`,
//! `closed_form` → `precision` → `resection`.
//!
//! Invariant: this crate does no IO (no files, sockets, threads or clocks) and
//! its solvers do not allocate once their workspace exists.

pub mod camera;
pub mod closed_form;
pub mod error;
pub mod exterior;
pub mod linearised;
pub mod observation;
pub mod pose;
pub mod precision;
pub mod resection;
pub mod rng;
pub mod rotation;
pub mod simulation;

pub use camera::{Camera, DistortSeed, Distortion, Interior, Sensor};
pub use error::GeometryError;
pub use exterior::Exterior;
pub use nalgebra::{
    Isometry3, Matrix2, Matrix3, Matrix6, Point3, Rotation3, UnitQuaternion, Vector2, Vector3,
    Vector6,
};
pub use observation::Observation;
pub use resection::{Resection, ResectionOptions, ResectionReport};
