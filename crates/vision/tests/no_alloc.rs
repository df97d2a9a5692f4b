//! Once warm, `Detector::detect` allocates nothing: a counting global
//! allocator watches a run over frames with dots, coded targets, noise,
//! rejections and degenerate content, in 8 and 16 bits, whole and through
//! windows of varying size below the capacity (of the frames and of a
//! larger frame), with the window's own threshold or a given one.

use photopose_field::codes;
use photopose_frame::{Image, ImageView, Pixels};
use photopose_testkit::{allocations, CountingAllocator};
use photopose_vision::{CodeSet, Detector, DetectorOptions, TargetKind};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

const W: usize = 400;
const H: usize = 300;

/// A frame with uncoded dots, coded targets (frontal), a bright bar and a
/// saturated blob, over a noisy background; with `dim` the row of uncoded
/// dots is dim (found through the local threshold).
fn frame(seed: u64, dim: bool) -> Vec<f64> {
    let mut v = vec![15.0; W * H];
    let mut state = seed;
    let mut rnd = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut draw = |cx: f64, cy: f64, r: f64, code: Option<u16>, amp: f64| {
        let reach = if code.is_some() { 3.2 * r } else { 1.2 * r };
        let (c0, c1) = ((cx - reach) as usize, (cx + reach) as usize + 1);
        let (r0, r1) = ((cy - reach) as usize, (cy + reach) as usize + 1);
        for row in r0..=r1 {
            for col in c0..=c1 {
                let mut acc = 0.0;
                for s in 0..16 {
                    let x = (col as f64 - 0.5 + ((s % 4) as f64 + 0.5) / 4.0 - cx) / r;
                    let y = -(row as f64 - 0.5 + ((s / 4) as f64 + 0.5) / 4.0 - cy) / r;
                    let rho = x.hypot(y);
                    let lit = if rho <= 1.0 {
                        true
                    } else if let (Some(c), true) = (code, (2.0..3.0).contains(&rho)) {
                        let a = y.atan2(x).rem_euclid(std::f64::consts::TAU);
                        let k = ((a / (std::f64::consts::PI / 6.0)) as u32).min(11);
                        codes::sector_bit(c, k)
                    } else {
                        false
                    };
                    acc += lit as u8 as f64;
                }
                v[row * W + col] += amp * acc / 16.0;
            }
        }
    };
    for k in 0..12 {
        let (cx, cy) = (40.0 + 30.0 * k as f64 + rnd(), 40.0 + rnd());
        draw(cx, cy, 4.0 + rnd(), None, if dim { 45.0 } else { 180.0 });
    }
    for (k, id) in [2u64, 17, 42, 200].into_iter().enumerate() {
        draw(
            60.0 + 90.0 * k as f64 + rnd(),
            150.0 + rnd(),
            5.0,
            codes::value_of(id),
            180.0,
        );
    }
    draw(300.0, 250.0, 6.0, None, 400.0); // saturated: measured and flagged
    for col in 20..200 {
        v[250 * W + col] = 200.0; // a line
    }
    for x in v.iter_mut() {
        *x += 4.0 * (rnd() - 0.5);
    }
    v
}

fn mono8(v: &[f64]) -> Image {
    let px = v
        .iter()
        .map(|&x| x.round().clamp(0.0, 255.0) as u8)
        .collect();
    Image::from_pixels(W as u32, H as u32, 255, Pixels::Mono8(px)).unwrap()
}

fn mono16(v: &[f64]) -> Image {
    let px = v
        .iter()
        .map(|&x| (x * 16.0).round().clamp(0.0, 4095.0) as u16)
        .collect();
    Image::from_pixels(W as u32, H as u32, 4095, Pixels::Mono16(px)).unwrap()
}

#[test]
fn detect_allocates_nothing_once_warm() {
    let mut frames = Vec::new();
    for seed in 0..3 {
        let v = frame(seed, false);
        frames.push(mono8(&v));
        frames.push(mono16(&v));
    }
    frames.push(Image::new_mono8(W as u32, H as u32));
    let mut sat = Image::new_mono8(W as u32, H as u32);
    if let Pixels::Mono8(p) = sat.pixels_mut() {
        p.iter_mut().for_each(|x| *x = 255);
    }
    frames.push(sat);

    let options = DetectorOptions {
        codes: CodeSet::from_ids([2, 17, 42, 200]),
        ..DetectorOptions::default()
    };
    let mut detector = Detector::new(W as u32, H as u32, options).unwrap();
    // Warm-up (nothing should allocate here either, but only the steady
    // state is the contract).
    let first = detector.detect(frames[0].view()).unwrap();
    assert_eq!(first.targets.len(), 17, "{:?}", first.targets);
    assert_eq!(first.n_saturated, 1);
    assert_eq!(
        first
            .targets
            .iter()
            .filter(|t| t.kind == TargetKind::Coded && t.id.is_some())
            .count(),
        4
    );
    assert!(!first.rejected.is_empty());

    let before = allocations();
    let mut found = 0;
    for _ in 0..3 {
        for f in &frames {
            found += detector.detect(f.view()).unwrap().targets.len();
        }
    }
    let after = allocations();
    assert_eq!(after - before, 0, "allocations during detection");
    assert_eq!(found, 3 * 6 * 17);

    // Dim dots next to bright targets: the local threshold finds them,
    // without allocating either.
    let dim: Vec<Image> = (0..2)
        .flat_map(|seed| {
            let v = frame(seed, true);
            [mono8(&v), mono16(&v)]
        })
        .collect();
    let global = {
        let mut d = Detector::new(
            W as u32,
            H as u32,
            DetectorOptions {
                local_threshold: 0.0,
                ..options
            },
        )
        .unwrap();
        d.detect(dim[0].view()).unwrap().targets.len()
    };
    let d = detector.detect(dim[0].view()).unwrap();
    assert!(d.local_levels);
    assert_eq!(d.targets.len(), 17, "{:?}", d.rejected);
    assert!(global < 17, "the global threshold alone finds {global}");
    let before = allocations();
    for f in &dim {
        let d = detector.detect(f.view()).unwrap();
        assert!(d.local_levels && d.targets.len() == 17);
    }
    assert_eq!(allocations() - before, 0, "allocations with local levels");
    frames.extend(dim);

    // Windows of varying size below the capacity, with their own threshold
    // and with the whole frame's; then windows of a frame twice as wide
    // (a padded buffer), which is larger than the capacity.
    let thresholds: Vec<_> = frames
        .iter()
        .map(|f| detector.threshold(f.view()).unwrap())
        .collect();
    let wide = {
        let Pixels::Mono8(p) = frames[0].pixels() else {
            panic!("8-bit")
        };
        let mut buf = vec![15u8; 2 * W * H];
        for (row, line) in p.chunks_exact(W).enumerate() {
            buf[2 * W * row + W..2 * W * (row + 1)].copy_from_slice(line);
        }
        buf
    };
    let windows = [
        (0, 0, W as u32, H as u32),
        (10, 7, 250, 180),
        (133, 41, 31, 200),
        (1, 1, 398, 298),
        (200, 150, 200, 150),
        (57, 3, 8, 8),
        (390, 290, 10, 10),
    ];
    let before = allocations();
    let mut n_windows = 0;
    for (f, t) in frames.iter().zip(&thresholds) {
        for &(x, y, w, h) in &windows {
            let view = f.view().window(x, y, w, h).unwrap();
            found += detector.detect(view).unwrap().targets.len();
            found += detector.detect_with(view, t).unwrap().targets.len();
            n_windows += 1;
        }
    }
    let padded = ImageView::mono8(&wide, 2 * W as u32, H as u32, 2 * W).unwrap();
    for &(x, y, w, h) in &windows {
        let view = padded.window(x + W as u32, y, w, h).unwrap();
        found += detector.detect(view).unwrap().targets.len();
        found += detector
            .detect_with(view, &thresholds[0])
            .unwrap()
            .targets
            .len();
    }
    let after = allocations();
    assert_eq!(after - before, 0, "allocations during detection in windows");
    assert!(n_windows == frames.len() * windows.len() && found > 3 * 6 * 16);
    // The whole frame placed in the larger one is still the same frame.
    let view = padded.window(W as u32, 0, W as u32, H as u32).unwrap();
    let d = detector.detect(view).unwrap().clone();
    let first = detector.detect(frames[0].view()).unwrap();
    assert_eq!(d.targets.len(), first.targets.len());
    for (a, b) in d.targets.iter().zip(&first.targets) {
        assert!((a.col - W as f64 - b.col).abs() < 1e-9 && a.row == b.row);
    }
}
