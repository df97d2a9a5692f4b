//! The ten interior-orientation and distortion parameters of the camera
//! model as unknowns of the adjustment: their names (those of the camera
//! file), units, values in a [`Camera`] and which of them are fixed.

use crate::error::CalibrateError;
use photopose_geometry::Camera;

/// Number of camera parameters.
pub const N_PARAMS: usize = 10;

/// A camera parameter, in the order of the adjustment's unknowns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Param {
    /// Principal distance `c`, mm.
    C,
    /// Principal point `x0`, mm.
    X0,
    /// Principal point `y0`, mm.
    Y0,
    /// Radial `K1`, mm⁻².
    K1,
    /// Radial `K2`, mm⁻⁴.
    K2,
    /// Radial `K3`, mm⁻⁶.
    K3,
    /// Decentring `P1`, mm⁻¹.
    P1,
    /// Decentring `P2`, mm⁻¹.
    P2,
    /// Affinity `b1`.
    B1,
    /// Shear `b2`.
    B2,
}

impl Param {
    /// All parameters in unknown order.
    pub const ALL: [Param; N_PARAMS] = [
        Param::C,
        Param::X0,
        Param::Y0,
        Param::K1,
        Param::K2,
        Param::K3,
        Param::P1,
        Param::P2,
        Param::B1,
        Param::B2,
    ];

    /// The key of the camera file (`c`, `x0`, …, `b2`).
    pub fn name(self) -> &'static str {
        match self {
            Param::C => "c",
            Param::X0 => "x0",
            Param::Y0 => "y0",
            Param::K1 => "k1",
            Param::K2 => "k2",
            Param::K3 => "k3",
            Param::P1 => "p1",
            Param::P2 => "p2",
            Param::B1 => "b1",
            Param::B2 => "b2",
        }
    }

    /// Unit of the parameter.
    pub fn unit(self) -> &'static str {
        match self {
            Param::C | Param::X0 | Param::Y0 => "mm",
            Param::K1 => "mm^-2",
            Param::K2 => "mm^-4",
            Param::K3 => "mm^-6",
            Param::P1 | Param::P2 => "mm^-1",
            Param::B1 | Param::B2 => "1",
        }
    }

    /// Position among the unknowns.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The parameter of a name (case-insensitive).
    pub fn parse(name: &str) -> Result<Param, CalibrateError> {
        let n = name.trim().to_ascii_lowercase();
        Param::ALL
            .into_iter()
            .find(|p| p.name() == n)
            .ok_or_else(|| CalibrateError::UnknownParameter(name.to_string()))
    }
}

/// The parameter values of a camera, in unknown order.
pub fn values(camera: &Camera) -> [f64; N_PARAMS] {
    let (i, d) = (&camera.interior, &camera.distortion);
    [i.c, i.x0, i.y0, d.k1, d.k2, d.k3, d.p1, d.p2, d.b1, d.b2]
}

/// `camera` with its parameters set to `v` (sensor kept). Unchecked: the
/// adjustment may pass through values [`Camera::new`] would refuse.
pub fn with_values(camera: &Camera, v: &[f64; N_PARAMS]) -> Camera {
    let mut c = *camera;
    c.interior.c = v[0];
    c.interior.x0 = v[1];
    c.interior.y0 = v[2];
    c.distortion.k1 = v[3];
    c.distortion.k2 = v[4];
    c.distortion.k3 = v[5];
    c.distortion.p1 = v[6];
    c.distortion.p2 = v[7];
    c.distortion.b1 = v[8];
    c.distortion.b2 = v[9];
    c
}

/// Which parameters are fixed at their initial value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Fixed([bool; N_PARAMS]);

impl Fixed {
    /// Nothing fixed.
    pub fn none() -> Self {
        Fixed::default()
    }

    /// Parses a comma-separated list such as `k3,b1,b2` (empty: nothing fixed).
    pub fn parse_list(list: &str) -> Result<Self, CalibrateError> {
        let mut f = Fixed::none();
        for name in list.split(',').filter(|s| !s.trim().is_empty()) {
            f.fix(Param::parse(name)?);
        }
        Ok(f)
    }

    /// Fixes `p`.
    pub fn fix(&mut self, p: Param) {
        self.0[p.index()] = true;
    }

    /// Frees `p`.
    pub fn free(&mut self, p: Param) {
        self.0[p.index()] = false;
    }

    /// Whether `p` is fixed.
    pub fn is_fixed(&self, p: Param) -> bool {
        self.0[p.index()]
    }

    /// The free parameters in unknown order.
    pub fn free_params(&self) -> Vec<Param> {
        Param::ALL
            .into_iter()
            .filter(|p| !self.is_fixed(*p))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_values_round_trip() {
        for p in Param::ALL {
            assert_eq!(Param::parse(&p.name().to_uppercase()).unwrap(), p);
        }
        let e = Param::parse("k4").unwrap_err();
        assert!(e.to_string().contains("k4"), "{e}");
        let f = Fixed::parse_list("k3, b1,b2").unwrap();
        assert_eq!(f.free_params().len(), 7);
        assert!(f.is_fixed(Param::B2) && !f.is_fixed(Param::K2));
        let cam = photopose_geometry::Camera::new(
            photopose_geometry::Sensor {
                width: 100,
                height: 80,
                pixel_size: 0.01,
            },
            photopose_geometry::Interior {
                c: 8.0,
                x0: 0.01,
                y0: -0.02,
            },
            photopose_geometry::Distortion {
                k1: 1.0,
                k2: 2.0,
                k3: 3.0,
                p1: 4.0,
                p2: 5.0,
                b1: 6.0,
                b2: 7.0,
            },
        )
        .unwrap();
        assert_eq!(with_values(&cam, &values(&cam)), cam);
    }
}
