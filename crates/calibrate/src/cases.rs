//! The cameras the calibration is proven on (tests, the timing example and
//! the acceptance run): besides the shipped default camera, a strongly
//! distorted lens with its principal point off centre.

use photopose_geometry::{Camera, Distortion, Interior, Sensor};

/// A 12 mm lens with strong radial (K1 −2.5e-3), decentring and affinity
/// terms and its principal point 0.15 mm, −0.10 mm off centre, on `sensor`.
pub fn strong_lens(sensor: Sensor) -> Camera {
    Camera::new(
        sensor,
        Interior {
            c: 12.0,
            x0: 0.15,
            y0: -0.1,
        },
        Distortion {
            k1: -2.5e-3,
            k2: 2.0e-5,
            k3: -1.0e-7,
            p1: 3.0e-5,
            p2: -2.0e-5,
            b1: 1.0e-4,
            b2: -5.0e-5,
        },
    )
    .expect("the strong lens is a valid camera")
}
