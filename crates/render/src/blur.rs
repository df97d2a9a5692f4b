//! The Gaussian blur of a frame's excess brightness: the kernel, and the
//! separable blur restricted to the boxes the targets touched (the
//! background is uniform, so blurring it changes nothing).

/// The normalised Gaussian kernel of σ = `sigma` px (3.5 σ either side)
/// into `kernel`; empty for no blur.
pub(crate) fn gaussian_kernel(sigma: f64, kernel: &mut Vec<f32>) {
    kernel.clear();
    if sigma > 0.0 {
        let k = (3.5 * sigma).ceil() as i32;
        for i in -k..=k {
            kernel.push((-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32);
        }
        let sum: f32 = kernel.iter().sum();
        kernel.iter_mut().for_each(|x| *x /= sum);
    }
}

/// Blurs the excess brightness inside the touched boxes (the background
/// is uniform, so blurring it changes nothing).
pub(crate) fn blur(
    kernel: &[f32],
    excess: &mut [f32],
    scratch: &mut [f32],
    boxes: &mut [[usize; 4]],
    w: usize,
    h: usize,
) {
    if kernel.is_empty() {
        return;
    }
    let k = kernel.len() / 2;
    for b in boxes.iter_mut() {
        let [c0, r0, c1, r1] = *b;
        let (c0, c1) = (c0.saturating_sub(k), (c1 + k).min(w - 1));
        let (r0, r1) = (r0.saturating_sub(k), (r1 + k).min(h - 1));
        *b = [c0, r0, c1, r1];
        for row in r0..=r1 {
            let line = &excess[row * w..(row + 1) * w];
            for col in c0..=c1 {
                let s = if col >= k && col + k < w {
                    // The whole window on the sensor: a plain dot product.
                    kernel
                        .iter()
                        .zip(&line[col - k..=col + k])
                        .map(|(kv, v)| kv * v)
                        .sum()
                } else {
                    let mut s = 0.0f32;
                    for (j, kv) in kernel.iter().enumerate() {
                        s += kv * line[(col + j).saturating_sub(k).min(w - 1)];
                    }
                    s
                };
                scratch[row * w + col] = s;
            }
        }
    }
    // Vertical pass, a row at a time (vectorises along the row). Rows
    // outside every box hold no excess: the horizontal pass left them
    // zero in `scratch`.
    for &[c0, r0, c1, r1] in boxes.iter() {
        for row in r0..=r1 {
            let dst = &mut excess[row * w + c0..=row * w + c1];
            dst.fill(0.0);
            for (j, kv) in kernel.iter().enumerate() {
                let rr = (row + j).saturating_sub(k).min(h - 1);
                let src = &scratch[rr * w + c0..=rr * w + c1];
                for (d, s) in dst.iter_mut().zip(src) {
                    *d += kv * s;
                }
            }
        }
    }
    // Clear the horizontal pass for the next frame.
    for &[c0, r0, c1, r1] in boxes.iter() {
        for row in r0..=r1 {
            scratch[row * w + c0..=row * w + c1].fill(0.0);
        }
    }
}
