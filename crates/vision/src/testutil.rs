//! Synthetic frames for the unit tests: area-sampled dots and coded targets
//! under an affine view, Gaussian blur, Gaussian noise from a seeded
//! generator, quantised to 8 or 16 bits.

use photopose_field::codes;
use photopose_frame::{Image, Pixels};

/// A seeded generator (splitmix64) with Gaussian samples.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// How a target is seen: pixel offset `(dcol, drow)` of plate point
/// `(X, Y)` (mm, `Y` up, seen from +Z) is `M · (X, Y)` with `M` row-major.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub m: [f64; 4],
}

impl View {
    /// Frontal, `s` px per mm, plate `Y` up in the picture (row down).
    pub fn frontal(s: f64) -> Self {
        View {
            m: [s, 0.0, 0.0, -s],
        }
    }
    /// Tilted: the plate is foreshortened by `cos(tilt)` along direction
    /// `dir` (in the image), and rotated in-plane by `roll`.
    pub fn tilted(s: f64, tilt: f64, dir: f64, roll: f64) -> Self {
        // Image (u, v) with v up: R(dir) diag(1, cos tilt) R(-dir) R(roll) s.
        let (sd, cd) = dir.sin_cos();
        let (sr, cr) = roll.sin_cos();
        let k = tilt.cos();
        // F = R(dir) diag(k, 1) R(-dir): foreshorten along dir.
        let f = [
            cd * cd * k + sd * sd,
            cd * sd * (k - 1.0),
            cd * sd * (k - 1.0),
            sd * sd * k + cd * cd,
        ];
        let r = [cr, -sr, sr, cr];
        let a = mul(f, r);
        // (u, v) → (col, row) = (u, -v).
        View {
            m: [s * a[0], s * a[1], -s * a[2], -s * a[3]],
        }
    }
    /// The mirror image (col ↦ −col).
    pub fn mirrored(self) -> Self {
        View {
            m: [-self.m[0], -self.m[1], self.m[2], self.m[3]],
        }
    }
    fn inverse(&self) -> [f64; 4] {
        let [a, b, c, d] = self.m;
        let det = a * d - b * c;
        [d / det, -b / det, -c / det, a / det]
    }
}

fn mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] + a[1] * b[2],
        a[0] * b[1] + a[1] * b[3],
        a[2] * b[0] + a[3] * b[2],
        a[2] * b[1] + a[3] * b[3],
    ]
}

/// A target to draw.
#[derive(Clone, Copy, Debug)]
pub struct Drawn {
    pub col: f64,
    pub row: f64,
    /// Dot radius, mm.
    pub radius: f64,
    pub view: View,
    /// Ring bits, canonical value rotated by `phase` sectors; `None`: uncoded.
    pub code: Option<u16>,
    /// Angle (radians, counter-clockwise from +X) at which the first-read
    /// sector starts.
    pub phase: f64,
}

impl Drawn {
    /// Reflectance at plate point `(x, y)` (units of the radius).
    fn value(&self, x: f64, y: f64) -> f64 {
        let rho2 = x * x + y * y;
        if rho2 <= 1.0 {
            return 1.0;
        }
        let Some(v) = self.code else { return 0.0 };
        if !(4.0..9.0).contains(&rho2) {
            return 0.0;
        }
        let a = (y.atan2(x) - self.phase).rem_euclid(std::f64::consts::TAU);
        let k = ((a / (std::f64::consts::PI / 6.0)) as u32).min(11);
        codes::sector_bit(v, k) as u8 as f64
    }
}

/// A floating-point scene.
pub struct Scene {
    pub w: usize,
    pub h: usize,
    pub v: Vec<f64>,
}

/// Sub-samples per pixel side when area-sampling.
const SS: usize = 8;

impl Scene {
    pub fn new(w: usize, h: usize, background: f64) -> Self {
        Scene {
            w,
            h,
            v: vec![background; w * h],
        }
    }

    /// Adds `amplitude × reflectance`, area-sampled.
    pub fn draw(&mut self, t: &Drawn, amplitude: f64) {
        let inv = t.view.inverse();
        let reach = if t.code.is_some() { 3.05 } else { 1.05 } * t.radius;
        let ext = (t.view.m.iter().map(|x| x.abs()).fold(0.0, f64::max) * 2.0 * reach).ceil() + 2.0;
        let c0 = (t.col - ext).floor().max(0.0) as usize;
        let r0 = (t.row - ext).floor().max(0.0) as usize;
        let c1 = ((t.col + ext).ceil() as usize).min(self.w - 1);
        let r1 = ((t.row + ext).ceil() as usize).min(self.h - 1);
        for row in r0..=r1 {
            for col in c0..=c1 {
                let mut acc = 0.0;
                for sy in 0..SS {
                    for sx in 0..SS {
                        let dc = col as f64 - 0.5 + (sx as f64 + 0.5) / SS as f64 - t.col;
                        let dr = row as f64 - 0.5 + (sy as f64 + 0.5) / SS as f64 - t.row;
                        let x = (inv[0] * dc + inv[1] * dr) / t.radius;
                        let y = (inv[2] * dc + inv[3] * dr) / t.radius;
                        acc += t.value(x, y);
                    }
                }
                self.v[row * self.w + col] += amplitude * acc / (SS * SS) as f64;
            }
        }
    }

    /// Sets a rectangle `[c0, c1) × [r0, r1)` to `value`.
    pub fn fill_rect(&mut self, c0: usize, r0: usize, c1: usize, r1: usize, value: f64) {
        for row in r0..r1.min(self.h) {
            for col in c0..c1.min(self.w) {
                self.v[row * self.w + col] = value;
            }
        }
    }

    /// Sets the pixels whose centres lie within `half_width` of the line
    /// through `(c, r)` with direction `angle` to `value`.
    pub fn bar(&mut self, c: f64, r: f64, angle: f64, half_width: f64, value: f64) {
        let (s, co) = angle.sin_cos();
        for row in 0..self.h {
            for col in 0..self.w {
                let d = -(col as f64 - c) * s + (row as f64 - r) * co;
                if d.abs() <= half_width {
                    self.v[row * self.w + col] = value;
                }
            }
        }
    }

    /// Gaussian blur, σ in pixels.
    pub fn blur(&mut self, sigma: f64) {
        if sigma <= 0.0 {
            return;
        }
        let k = (3.0 * sigma).ceil() as isize;
        let kern: Vec<f64> = (-k..=k)
            .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
            .collect();
        let norm: f64 = kern.iter().sum();
        let (w, h) = (self.w as isize, self.h as isize);
        let mut tmp = vec![0.0; self.v.len()];
        for r in 0..h {
            for c in 0..w {
                let mut s = 0.0;
                for (j, kv) in kern.iter().enumerate() {
                    let cc = (c + j as isize - k).clamp(0, w - 1);
                    s += kv * self.v[(r * w + cc) as usize];
                }
                tmp[(r * w + c) as usize] = s / norm;
            }
        }
        for r in 0..h {
            for c in 0..w {
                let mut s = 0.0;
                for (j, kv) in kern.iter().enumerate() {
                    let rr = (r + j as isize - k).clamp(0, h - 1);
                    s += kv * tmp[(rr * w + c) as usize];
                }
                self.v[(r * w + c) as usize] = s / norm;
            }
        }
    }

    /// Adds Gaussian noise.
    pub fn noise(&mut self, sigma: f64, rng: &mut Rng) {
        for v in &mut self.v {
            *v += sigma * rng.gauss();
        }
    }

    pub fn to_mono8(&self) -> Image {
        let px = self
            .v
            .iter()
            .map(|&v| v.round().clamp(0.0, 255.0) as u8)
            .collect();
        Image::from_pixels(self.w as u32, self.h as u32, 255, Pixels::Mono8(px)).unwrap()
    }

    /// 16-bit with saturation `max`, values scaled by `gain`.
    pub fn to_mono16(&self, max: u16, gain: f64) -> Image {
        let px = self
            .v
            .iter()
            .map(|&v| (v * gain).round().clamp(0.0, max as f64) as u16)
            .collect();
        Image::from_pixels(self.w as u32, self.h as u32, max, Pixels::Mono16(px)).unwrap()
    }
}

/// The window `width × height` whose first pixel is full-frame
/// `(col0, row0)` of a row-major frame with rows `stride` pixels apart.
pub fn window<P>(
    frame: &[P],
    stride: usize,
    (col0, row0, width, height): (usize, usize, usize, usize),
) -> crate::pixel::Plane<'_, P> {
    crate::pixel::Plane {
        data: &frame[row0 * stride + col0..],
        width,
        height,
        stride,
        col0,
        row0,
    }
}
