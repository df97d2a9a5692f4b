//! A small ray-casting renderer of a test field for the vision tests (the
//! project's renderer is `photopose-render`; this one is independent of it,
//! so the two check each other): every sub-pixel sample is traced back
//! through the camera model (distortion included) onto the plate `Z = 0`
//! and looks up the target pattern of `docs/coded-targets.md`. The truth of a
//! target is the projection of its centre.

#![allow(dead_code)]

use photopose_field::{codes, Field, TargetKind};
use photopose_frame::{Image, Pixels};
use photopose_geometry::{Camera, Exterior, Vector3};

/// One target's truth.
#[derive(Debug, Clone, Copy)]
pub struct Truth {
    pub id: u64,
    pub kind: TargetKind,
    pub col: f64,
    pub row: f64,
    /// Whether the whole target (quiet zone included) is inside the frame.
    pub inside: bool,
}

/// Rendering parameters.
#[derive(Debug, Clone, Copy)]
pub struct Look {
    pub background: f64,
    pub amplitude: f64,
    pub blur: f64,
    pub noise: f64,
    /// Sub-samples per pixel side.
    pub ss: usize,
    pub seed: u64,
}

impl Default for Look {
    fn default() -> Self {
        Look {
            background: 15.0,
            amplitude: 180.0,
            blur: 0.6,
            noise: 2.0,
            ss: 4,
            seed: 1,
        }
    }
}

fn reflectance(kind: TargetKind, value: u16, x: f64, y: f64) -> f64 {
    let rho2 = x * x + y * y;
    if rho2 <= 1.0 {
        return 1.0;
    }
    if kind == TargetKind::Uncoded || !(4.0..9.0).contains(&rho2) {
        return 0.0;
    }
    let a = y.atan2(x).rem_euclid(std::f64::consts::TAU);
    let k = ((a / (std::f64::consts::PI / 6.0)) as u32).min(11);
    codes::sector_bit(value, k) as u8 as f64
}

/// Renders `field` seen by `camera` from `ext` as an 8-bit frame.
pub fn render(camera: &Camera, ext: &Exterior, field: &Field, look: &Look) -> (Image, Vec<Truth>) {
    let (w, h) = (camera.sensor.width as usize, camera.sensor.height as usize);
    let mut img = vec![0.0f64; w * h];
    let mut truth = Vec::new();
    let rt = ext.rotation.transpose();
    let c = camera.interior.c;
    let ss = look.ss.max(1);
    for t in field.targets() {
        let Some(p) = ext.project_pixel(camera, &t.position) else {
            continue;
        };
        // Extent: project the quiet-zone circle's bounding points.
        // The detector needs the ring zone (to 2.6 r) of every target inside
        // the frame, and the quiet zone (4 r) of coded ones.
        let reach = match t.kind {
            TargetKind::Coded => t.quiet_radius(),
            TargetKind::Uncoded => 2.6 * t.radius,
        };
        let mut ext_px: f64 = 0.0;
        for (dx, dy) in [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)] {
            let q = t.position + Vector3::new(dx * reach, dy * reach, 0.0);
            if let Some(pq) = ext.project_pixel(camera, &q) {
                ext_px = ext_px.max((pq - p).norm());
            }
        }
        let inside = camera.contains_pixel(p, ext_px + 1.0);
        truth.push(Truth {
            id: t.id,
            kind: t.kind,
            col: p.x,
            row: p.y,
            inside,
        });
        let value = if t.kind == TargetKind::Coded {
            codes::value_of(t.id).unwrap_or(0)
        } else {
            0
        };
        let e = ext_px * 1.1 + 2.0;
        let c0 = (p.x - e).floor().max(0.0) as usize;
        let r0 = (p.y - e).floor().max(0.0) as usize;
        let c1 = ((p.x + e).ceil().max(0.0) as usize).min(w - 1);
        let r1 = ((p.y + e).ceil().max(0.0) as usize).min(h - 1);
        if c0 > c1 || r0 > r1 {
            continue;
        }
        for row in r0..=r1 {
            for col in c0..=c1 {
                let mut acc = 0.0;
                for sy in 0..ss {
                    for sx in 0..ss {
                        let pc = col as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64;
                        let pr = row as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64;
                        let ideal = camera.correct_pixel(pc, pr);
                        let d = rt * Vector3::new(ideal.x, ideal.y, -c);
                        if d.z.abs() < 1e-12 {
                            continue;
                        }
                        let s = -ext.center.z / d.z;
                        if s <= 0.0 {
                            continue;
                        }
                        let q = ext.center + s * d - t.position;
                        acc += reflectance(t.kind, value, q.x / t.radius, q.y / t.radius);
                    }
                }
                img[row * w + col] += look.amplitude * acc / (ss * ss) as f64;
            }
        }
    }
    blur(&mut img, w, h, look.blur);
    let mut state = look.seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut gauss = move || {
        let mut u = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (u1, u2) = (u(), u());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let px = img
        .iter()
        .map(|&v| {
            (look.background + v + look.noise * gauss())
                .round()
                .clamp(0.0, 255.0) as u8
        })
        .collect();
    (
        Image::from_pixels(w as u32, h as u32, 255, Pixels::Mono8(px)).unwrap(),
        truth,
    )
}

fn blur(v: &mut [f64], w: usize, h: usize, sigma: f64) {
    if sigma <= 0.0 {
        return;
    }
    let k = (3.0 * sigma).ceil() as usize;
    let kern: Vec<f64> = (0..=2 * k)
        .map(|i| {
            let d = i as f64 - k as f64;
            (-d * d / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let norm: f64 = kern.iter().sum();
    let mut tmp = vec![0.0; v.len()];
    for r in 0..h {
        let line = &v[r * w..(r + 1) * w];
        if line.iter().all(|&x| x == 0.0) {
            continue;
        }
        for c in 0..w {
            let mut s = 0.0;
            for (j, kv) in kern.iter().enumerate() {
                let cc = (c + j).saturating_sub(k).min(w - 1);
                s += kv * line[cc];
            }
            tmp[r * w + c] = s / norm;
        }
    }
    for r in 0..h {
        for c in 0..w {
            let mut s = 0.0;
            for (j, kv) in kern.iter().enumerate() {
                let rr = (r + j).saturating_sub(k).min(h - 1);
                s += kv * tmp[rr * w + c];
            }
            v[r * w + c] = s / norm;
        }
    }
}
