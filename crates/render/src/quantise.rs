//! From brightness to grey values: the background level, the targets'
//! excess brightness and seeded Gaussian noise, clamped to the saturation
//! level and rounded into an 8- or 16-bit frame.

use crate::noise::Normal;
use crate::RenderOptions;
use photopose_frame::{Image, Pixels};

/// Background, excess, noise → grey values of `out` (its first `n`
/// pixels); clears the excess.
pub(crate) fn quantise(
    options: &RenderOptions,
    excess: &mut [f32],
    normal: &mut Normal,
    n: usize,
    out: &mut Image,
) {
    let level = Level {
        max: out.max_value() as f32,
        bg: options.background as f32 * out.max_value() as f32,
        noise: options.noise_dn as f32,
    };
    normal.reseed(options.seed);
    match out.pixels_mut() {
        Pixels::Mono8(data) => level.fill(&mut data[..n], &excess[..n], normal, |v| v as u8),
        Pixels::Mono16(data) => level.fill(&mut data[..n], &excess[..n], normal, |v| v as u16),
    }
    excess[..n].fill(0.0);
}

/// Grey levels of a frame: saturation, background, noise σ (all DN).
struct Level {
    max: f32,
    bg: f32,
    noise: f32,
}

impl Level {
    /// Writes `bg + excess·max + noise·N(0,1)`, clamped to `[0, max]` and
    /// rounded (half up: offset by ½, then `cast` truncates).
    #[inline(always)]
    fn fill<T>(&self, out: &mut [T], excess: &[f32], normal: &mut Normal, cast: impl Fn(f32) -> T) {
        let value = |e: f32, z: f32| {
            cast((self.bg + e * self.max + self.noise * z).clamp(0.0, self.max) + 0.5)
        };
        let mut oc = out.chunks_exact_mut(4);
        let mut ec = excess.chunks_exact(4);
        for (o, e) in (&mut oc).zip(&mut ec) {
            let z = normal.next4();
            for j in 0..4 {
                o[j] = value(e[j], z[j]);
            }
        }
        for (o, e) in oc.into_remainder().iter_mut().zip(ec.remainder()) {
            *o = value(*e, normal.next());
        }
    }
}
