//! Windows of a frame: the default plate rendered by `photopose-render` is
//! detected through the whole-frame view and through windows (of a padded
//! buffer, of a part of the frame, of a frame larger than the detector's
//! capacity); the results are compared in full-frame pixel coordinates.

use photopose_field::design::default_plate;
use photopose_frame::{Image, ImageView, Pixels};
use photopose_geometry::{Camera, Exterior};
use photopose_render::{RenderOptions, Renderer};
use photopose_vision::{Detection, Detections, Detector, DetectorOptions, VisionError};

const W: u32 = 1300;
const H: u32 = 1030;

/// The camera of `config/camera.toml`.
fn camera() -> Camera {
    Camera::reference()
}

/// The default plate from 1.5 m, slightly oblique: it fills the middle of
/// the frame with a dark border all round.
fn plate_frame() -> Image {
    let field = default_plate();
    let mut r = Renderer::new(camera(), &field, RenderOptions::default()).unwrap();
    let mut img = r.new_image();
    let pose = Exterior::from_kuka_pose([20.0, -15.0, 1500.0, 3.0, 1.0, -1.0]);
    r.render(&pose, &mut img).unwrap();
    let least = r
        .truth()
        .iter()
        .map(|t| t.margin_px)
        .fold(f64::INFINITY, f64::min);
    assert!(least > 60.0, "{least}");
    img
}

fn detector() -> Detector {
    Detector::new(W, H, DetectorOptions::for_field(&default_plate())).unwrap()
}

/// The bounding box `[c0, r0, c1, r1]` of the detected targets.
fn extent(d: &Detections) -> [f64; 4] {
    d.targets.iter().fold(
        [f64::INFINITY, f64::INFINITY, 0.0, 0.0],
        |[c0, r0, c1, r1], t| [c0.min(t.col), r0.min(t.row), c1.max(t.col), r1.max(t.row)],
    )
}

/// Whether a target lies at least `margin` px inside the window.
fn inside(t: &Detection, v: &ImageView<'_>, margin: f64) -> bool {
    let (c0, r0) = v.origin();
    let (c0, r0) = (c0 as f64, r0 as f64);
    t.col - margin >= c0
        && t.row - margin >= r0
        && t.col + margin <= c0 + v.width() as f64 - 1.0
        && t.row + margin <= r0 + v.height() as f64 - 1.0
}

#[test]
fn the_plate_through_a_window_of_a_padded_buffer_is_detected_bit_for_bit() {
    let img = plate_frame();
    let mut det = detector();
    let whole = det.detect(img.view()).unwrap().clone();
    assert_eq!(whole.targets.len(), 230, "{:?}", whole.rejected);
    assert!(whole.targets.iter().filter(|t| t.id.is_some()).count() >= 28);

    // The frame copied into a larger buffer: rows 1300 + 57 apart, the
    // frame starting at column 37 of row 23 of the buffer.
    let Pixels::Mono8(px) = img.pixels() else {
        panic!("8-bit frame")
    };
    let stride = W as usize + 57;
    let first = 23 * stride + 37;
    let mut buf = vec![255u8; first + H as usize * stride];
    for (row, line) in px.chunks_exact(W as usize).enumerate() {
        buf[first + row * stride..][..W as usize].copy_from_slice(line);
    }
    let padded = ImageView::mono8(&buf[first..], W, H, stride).unwrap();
    // The whole frame through it: everything identical, threshold included.
    assert_eq!(det.detect(padded).unwrap(), &whole);

    // A window of it holding the plate, at an offset, with the whole
    // frame's threshold: the same targets, bit for bit, in full-frame
    // coordinates.
    let [c0, r0, c1, r1] = extent(&whole);
    let (x, y) = ((c0 - 45.0) as u32, (r0 - 45.0) as u32);
    let (w, h) = ((c1 + 45.0) as u32 - x, (r1 + 45.0) as u32 - y);
    assert!(
        x > 100 && y > 100 && w < W - 200 && h < H - 200,
        "{x} {y} {w} {h}"
    );
    let window = padded.window(x, y, w, h).unwrap();
    assert_eq!(window.origin(), (x, y));
    let found = det.detect_with(window, &whole.threshold).unwrap().clone();
    assert_eq!(found.targets, whole.targets);
    assert_eq!(found.status, whole.status);
    // The window of the unpadded frame gives the same.
    let plain = img.view().window(x, y, w, h).unwrap();
    assert_eq!(det.detect_with(plain, &whole.threshold).unwrap(), &found);
}

#[test]
fn a_window_reports_the_targets_inside_it_as_the_whole_frame_does() {
    let img = plate_frame();
    let mut det = detector();
    let whole = det.detect(img.view()).unwrap().clone();
    let threshold = det.threshold(img.view()).unwrap();
    assert_eq!(threshold, whole.threshold);
    // Clear of a window's edge: the measuring window, the code ring and its
    // quiet zone, and the rings of cut neighbours.
    let big = whole
        .targets
        .iter()
        .map(|t| t.semi_major)
        .fold(0.0, f64::max);
    let margin = 8.0 * big + 4.0;
    let [c0, r0, c1, r1] = extent(&whole);
    // Windows cutting through the plate (odd and even origins and sizes).
    let (pw, ph) = (c1 - c0, r1 - r0);
    for (fx, fy, fw, fh) in [
        (0.1, 0.15, 0.5, 0.45),
        (0.45, 0.4, 0.55, 0.7),
        (0.3, 0.05, 0.3, 0.9),
    ] {
        let x = (c0 + fx * pw) as u32;
        let y = (r0 + fy * ph) as u32;
        let (w, h) = ((fw * pw) as u32 + 1, (fh * ph) as u32);
        let view = img.view().window(x, y, w, h).unwrap();
        let found = det.detect_with(view, &whole.threshold).unwrap();
        let expected: Vec<&Detection> = whole
            .targets
            .iter()
            .filter(|t| inside(t, &view, margin))
            .collect();
        assert!(expected.len() >= 15, "{x} {y} {w} {h}: {}", expected.len());
        let got: Vec<&Detection> = found
            .targets
            .iter()
            .filter(|t| inside(t, &view, margin))
            .collect();
        assert_eq!(got, expected, "window {w}×{h} at ({x}, {y})");
        // Nothing reported outside the window.
        assert!(found.targets.iter().all(|t| inside(t, &view, 0.0)));
    }
}

#[test]
fn a_window_of_a_frame_larger_than_the_capacity_is_served() {
    let img = plate_frame();
    let mut det = detector();
    let whole = det.detect(img.view()).unwrap().clone();
    // A 2000 × 1500 frame with the rendered one at (350, 200).
    let (bw, bh, ox, oy) = (2000u32, 1500u32, 350u32, 200u32);
    let Pixels::Mono8(px) = img.pixels() else {
        panic!("8-bit frame")
    };
    let mut big = vec![13u8; (bw * bh) as usize];
    for (row, line) in px.chunks_exact(W as usize).enumerate() {
        let at = (oy as usize + row) * bw as usize + ox as usize;
        big[at..at + W as usize].copy_from_slice(line);
    }
    let big = Image::from_pixels(bw, bh, 255, Pixels::Mono8(big)).unwrap();
    let e = det.detect(big.view()).unwrap_err();
    assert!(
        matches!(
            e,
            VisionError::Size {
                got_width: 2000,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("2000×1500") && e.to_string().contains("1300×1030"));
    let [c0, r0, c1, r1] = extent(&whole);
    let (x, y) = ((c0 - 45.0) as u32 + ox, (r0 - 45.0) as u32 + oy);
    let (w, h) = ((c1 - c0) as u32 + 90, (r1 - r0) as u32 + 90);
    let window = big.view().window(x, y, w, h).unwrap();
    let found = det.detect_with(window, &whole.threshold).unwrap();
    assert_eq!(found.targets.len(), whole.targets.len());
    // The same targets, moved by the offset (computed at other magnitudes,
    // so equal to rounding only).
    for (a, b) in found.targets.iter().zip(&whole.targets) {
        assert!((a.col - (b.col + ox as f64)).abs() < 1e-9, "{a:?} {b:?}");
        assert!((a.row - (b.row + oy as f64)).abs() < 1e-9, "{a:?} {b:?}");
        assert_eq!(
            (a.id, a.kind, a.area, a.peak),
            (b.id, b.kind, b.area, b.peak)
        );
        assert_eq!(a.background, b.background);
    }
}
