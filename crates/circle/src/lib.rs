//! photopose-circle: the ISO 230-4 circular test of a robot from measured
//! poses, and the simulated robot cell that produces such poses.
//!
//! [`analyse`] takes poses in the plate (field) frame — the camera's, or the
//! TCP's after [`pose::tcp_from_camera`] with a hand-eye transform — and fits
//! the least-squares plane of their positions, then the least-squares circle
//! in that plane (ISO 230-4: algebraic start, then Gauss–Newton on the
//! orthogonal distances). It reports the centre, radius, each sample's phase
//! angle, radial and out-of-plane deviation, ISO 230-4's circular
//! deviation `G` (radial range about the least-squares centre) and, with
//! the nominal circle given, its radial deviation `F`, the
//! orientation deviations along the path (small rotations about the field's
//! axes from the mean orientation), and each of these profiles also through
//! a Fourier (harmonic) filter in the phase angle ([`harmonics`]).
//! [`report`] writes the result as text and JSON, [`plot`] draws the
//! figure-2 style SVG plots. [`cell`] is the simulated cell: circular path,
//! robot error model, camera mount.
//!
//! Invariant: no IO (no files, sockets, threads or clocks); same input, same
//! output; random numbers only from seeded generators.

pub mod analysis;
pub mod cell;
pub mod error;
pub mod fit;
pub mod harmonics;
pub mod plot;
pub mod pose;
pub mod report;

pub use analysis::{
    analyse, AnalysisOptions, CircleTest, Direction, NominalCircle, Profile, RadialDeviation,
    SampleDeviation,
};
pub use error::CircleError;
pub use nalgebra::Isometry3;
