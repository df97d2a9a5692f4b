//! Unit tests of the renderer: determinism, truth, geometric fidelity of the
//! rendered dots, the code-ring drawing.

use super::*;
use crate::pattern::{analytic_coverage, reflectance, square_share_below, Flat};
use nalgebra::{Matrix2, Vector2, Vector3};
use photopose_field::design::default_plate;
use photopose_field::{codes, TargetKind};
use photopose_frame::Image;
use photopose_geometry::{Camera, Distortion, Exterior, Interior, Sensor};

fn camera(distortion: Distortion) -> Camera {
    Camera::new(
        Sensor {
            width: 1300,
            height: 1030,
            pixel_size: 0.0067,
        },
        Interior {
            c: 12.0,
            x0: 0.02,
            y0: -0.015,
        },
        distortion,
    )
    .unwrap()
}

fn strong() -> Distortion {
    Distortion {
        k1: -2.5e-3,
        k2: 2.0e-5,
        p1: 3.0e-5,
        p2: -2.0e-5,
        b1: 1.0e-4,
        ..Distortion::default()
    }
}

/// Background-subtracted intensity-weighted centroid inside `radius` px.
fn centroid(img: &Image, col: f64, row: f64, radius: f64, background: f64) -> (f64, f64) {
    let (mut s, mut sc, mut sr) = (0.0, 0.0, 0.0);
    let r = radius.ceil() as i64 + 1;
    for dr in -r..=r {
        for dc in -r..=r {
            let (c, rr) = (col.round() as i64 + dc, row.round() as i64 + dr);
            if (c as f64 - col).hypot(rr as f64 - row) > radius {
                continue;
            }
            let v = img.get(c as u32, rr as u32) as f64 - background;
            s += v;
            sc += v * c as f64;
            sr += v * rr as f64;
        }
    }
    (sc / s, sr / s)
}

fn exact() -> RenderOptions {
    RenderOptions {
        supersample: 4,
        noise_dn: 0.0,
        blur_px: 0.0,
        ..RenderOptions::default()
    }
}

/// The centroid of the image of the disc of radius `r` around `centre` (in
/// the plane `Z = 0`), computed *forwards*, independently of the renderer:
/// plate points on a polar grid are projected through the camera model and
/// weighted by the area they cover in the image (the Jacobian determinant
/// of the plate → pixel mapping, by central differences).
fn forward_centroid(cam: &Camera, e: &Exterior, centre: Vector3<f64>, r: f64) -> (f64, f64) {
    let (nr, na) = (48, 192);
    let px = |x: f64, y: f64| e.project_pixel(cam, &Vector3::new(x, y, 0.0)).unwrap();
    let (mut s, mut sc, mut sr) = (0.0, 0.0, 0.0);
    let h = 1e-3;
    for i in 0..nr {
        let rho = (i as f64 + 0.5) / nr as f64 * r;
        for j in 0..na {
            let phi = (j as f64 + 0.5) / na as f64 * std::f64::consts::TAU;
            let (x, y) = (centre.x + rho * phi.cos(), centre.y + rho * phi.sin());
            let q = px(x, y);
            let dx = (px(x + h, y) - px(x - h, y)) / (2.0 * h);
            let dy = (px(x, y + h) - px(x, y - h)) / (2.0 * h);
            let area = (dx.x * dy.y - dx.y * dy.x).abs() * rho;
            s += area;
            sc += area * q.x;
            sr += area * q.y;
        }
    }
    (sc / s, sr / s)
}

/// Checks the rendered uncoded dots of a noise-free, blur-free frame:
/// their intensity-weighted centroids lie within `tol_model` px (worst) of
/// the forward-computed centroids of the dots' images, and within
/// `tol_truth` px of the truth (the image of the circle's centre). The two
/// differ by the perspective eccentricity of a projected circle and the
/// curvature of the lens distortion across a dot: physics, not renderer
/// error, and visible at oblique views. What remains against the model
/// (≈ 0.004 px frontal) is the sampling bias of a centroid over
/// pixel-integrated values of a dot 4–5 px in radius without blur ("pixel
/// locking"), which a real image has as well; the pixel values themselves
/// are exact area integrals (see `analytic_coverage_matches_...`).
fn check_centroids(cam: Camera, e: Exterior, tol_model: f64, tol_truth: f64) {
    let field = default_plate();
    let mut r = Renderer::new(cam, &field, exact()).unwrap();
    let mut img = Image::new_mono16(1300, 1030, 65535);
    r.render(&e, &mut img).unwrap();
    let bg = r.options().background * 65535.0;
    let (mut worst_model, mut worst_truth): (f64, f64) = (0.0, 0.0);
    let mut n = 0;
    for (t, f) in r.truth().iter().zip(field.targets()) {
        if !(t.visible && t.kind == TargetKind::Uncoded) {
            continue;
        }
        // Inside 1.5 dot radii: the dot and part of its dark surround (no
        // ring around an uncoded target).
        let (c, rr) = centroid(&img, t.col, t.row, 1.5 * t.radius_px, bg);
        let (fc, fr) = forward_centroid(&cam, &e, f.position, f.radius);
        worst_model = worst_model.max((c - fc).hypot(rr - fr));
        worst_truth = worst_truth.max((c - t.col).hypot(rr - t.row));
        n += 1;
    }
    assert!(n > 50, "only {n} visible targets");
    assert!(
        worst_model < tol_model && worst_truth < tol_truth,
        "centroid error over {n} targets: worst {worst_model} px from the model's dot image, \
         worst {worst_truth} px from the image of the centre"
    );
}

#[test]
fn frontal_dots_are_centred_on_the_truth() {
    check_centroids(
        camera(Distortion::default()),
        Exterior::from_kuka_pose([5.0, -3.0, 1000.0, 0.0, 0.0, 0.0]),
        0.006,
        0.006,
    );
}

#[test]
fn oblique_dots_with_strong_distortion_are_where_the_model_puts_them() {
    // 45° to the plate, 920 mm away, a lens with 6 % distortion in the
    // corners.
    let e = Exterior::look_at(
        Vector3::new(0.0, -650.0, 650.0),
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::z(),
    )
    .unwrap();
    check_centroids(camera(strong()), e, 0.01, 0.02);
}

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() {
    let field = default_plate();
    let cam = camera(strong());
    let e = Exterior::from_kuka_pose([10.0, 20.0, 950.0, 20.0, 5.0, -4.0]);
    let mut r = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
    let mut a = r.new_image();
    let mut b = r.new_image();
    r.render(&e, &mut a).unwrap();
    r.render(&e, &mut b).unwrap();
    assert_eq!(a, b);
    r.set_options(RenderOptions {
        seed: 2,
        ..RenderOptions::default()
    })
    .unwrap();
    r.render(&e, &mut b).unwrap();
    assert_ne!(a, b);
}

#[test]
fn truth_is_the_projection_of_the_centres() {
    let field = default_plate();
    let cam = camera(strong());
    let e = Exterior::from_kuka_pose([-30.0, 20.0, 900.0, 30.0, 10.0, 5.0]);
    let mut r = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
    let mut img = r.new_image();
    let returned = r.render(&e, &mut img).unwrap().to_vec();
    assert_eq!(returned, r.truth());
    assert_eq!(r.truth().len(), field.len());
    for (t, f) in r.truth().iter().zip(field.targets()) {
        assert_eq!(t.id, f.id);
        let p = e.project_pixel(&cam, &f.position).unwrap();
        assert!((p.x - t.col).abs() < 1e-9 && (p.y - t.row).abs() < 1e-9);
        if t.visible {
            assert!(cam.contains_pixel(p, 5.0));
        }
    }
}

#[test]
fn code_sectors_are_drawn_counter_clockwise_from_plus_x() {
    // Camera looking straight down with its axes along the plate's: plate +X
    // is image +col, plate +Y is image -row.
    let field = default_plate();
    let cam = camera(Distortion::default());
    let e = Exterior::from_kuka_pose([0.0, 0.0, 800.0, 0.0, 0.0, 0.0]);
    let mut r = Renderer::new(cam, &field, exact()).unwrap();
    let mut img = r.new_image();
    r.render(&e, &mut img).unwrap();
    let mut checked = 0;
    for (t, f) in r.truth().iter().zip(field.targets()) {
        if f.kind != TargetKind::Coded || !t.visible {
            continue;
        }
        let value = codes::value_of(f.id).unwrap();
        for k in 0..12u32 {
            let a = (k as f64 + 0.5) * std::f64::consts::PI / 6.0;
            let rho = 2.5 * t.radius_px;
            let (c, rr) = (t.col + rho * a.cos(), t.row - rho * a.sin());
            let v = img.get(c.round() as u32, rr.round() as u32);
            let bright = v > 128;
            assert_eq!(
                bright,
                codes::sector_bit(value, k),
                "target {} sector {k}: {v}",
                f.id
            );
        }
        checked += 1;
    }
    assert!(checked >= 10, "only {checked} coded targets checked");
}

#[test]
fn wrong_size_and_bad_options_are_errors() {
    let field = default_plate();
    let cam = camera(Distortion::default());
    let mut r = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
    let mut small = Image::new_mono8(640, 480);
    let e = Exterior::from_kuka_pose([0.0, 0.0, 1000.0, 0.0, 0.0, 0.0]);
    let err = r.render(&e, &mut small).unwrap_err().to_string();
    assert!(
        err.contains("640×480") && err.contains("1300×1030"),
        "{err}"
    );
    let bad = RenderOptions {
        blur_px: -1.0,
        ..RenderOptions::default()
    };
    assert!(Renderer::new(cam, &field, bad)
        .unwrap_err()
        .to_string()
        .contains("blur_px"));
}

#[test]
fn visible_means_the_whole_outline_is_on_the_sensor() {
    // Close and tilted: the frame cuts through the plate.
    let field = default_plate();
    let cam = camera(strong());
    let e = Exterior::from_kuka_pose([60.0, -40.0, 600.0, 10.0, 8.0, -6.0]);
    let mut r = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
    let mut img = r.new_image();
    r.render(&e, &mut img).unwrap();
    let (mut inside, mut cut) = (0, 0);
    for (t, f) in r.truth().iter().zip(field.targets()) {
        // The outline, densely: every point on the sensor iff visible
        // (up to the 32-point polygon's sag, a few hundredths of a pixel).
        let worst = (0..720)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 720.0;
                let p = f.position + Vector3::new(a.cos(), a.sin(), 0.0) * f.quiet_radius();
                let q = e.project_pixel(&cam, &p).unwrap();
                (q.x + 0.5)
                    .min(q.y + 0.5)
                    .min(1299.5 - q.x)
                    .min(1029.5 - q.y)
            })
            .fold(f64::INFINITY, f64::min);
        if worst > -20.0 {
            assert!(
                (worst - t.margin_px).abs() < 0.05,
                "{}: {worst} vs {}",
                t.id,
                t.margin_px
            );
        }
        assert_eq!(t.visible, t.margin_px >= 0.0);
        if t.visible {
            inside += 1;
        } else if worst > -20.0 {
            cut += 1;
        }
    }
    assert!(
        inside > 50 && cut > 3,
        "{inside} visible, {cut} cut by the frame"
    );
}

#[test]
fn square_share_is_the_area_below_a_line() {
    use photopose_geometry::rng::SplitMix64;
    let mut rng = SplitMix64::new(3);
    for _ in 0..200 {
        let g = Vector2::new(rng.normal() * 2.0, rng.normal());
        let t = rng.normal();
        // Brute force on a 400 × 400 grid.
        let n = 400;
        let mut below = 0;
        for i in 0..n {
            for j in 0..n {
                let d = Vector2::new(
                    (i as f64 + 0.5) / n as f64 - 0.5,
                    (j as f64 + 0.5) / n as f64 - 0.5,
                );
                below += usize::from(g.dot(&d) < t);
            }
        }
        let want = below as f64 / (n * n) as f64;
        let got = square_share_below(g, t);
        assert!((got - want).abs() < 0.005, "g {g:?} t {t}: {got} vs {want}");
    }
}

#[test]
fn analytic_coverage_matches_dense_sampling_of_the_pattern() {
    // Pixels of a coded target under a general affine pixel → plate map:
    // where one edge crosses the pixel, the analytic share equals dense
    // sampling of the same affine map up to the edge's curvature across the
    // pixel (about 1/(24 R) of a pixel for an image radius of R px, and of
    // opposite sign on opposite sides of a dot, so centroids keep it out).
    use photopose_geometry::rng::SplitMix64;
    let t = Flat {
        id: 42,
        kind: TargetKind::Coded,
        at: Vector2::zeros(),
        radius: 1.0,
        code: codes::value_of(42).unwrap(),
        edges: 0xfff,
    };
    let mut rng = SplitMix64::new(9);
    let mut checked = 0;
    for _ in 0..4000 {
        let local = Vector2::new(rng.normal() * 2.0, rng.normal() * 2.0);
        // Dots of 5 to 12 px radius foreshortened up to 2:1 (down to 2.5 px
        // across), any rotation.
        let scale = 0.08 + 0.12 * rng.unit();
        let squash = 1.0 + rng.unit();
        let turn = nalgebra::Rotation2::new(rng.unit() * 6.3).into_inner();
        let jac = turn * Matrix2::new(scale, 0.0, 0.0, scale * squash);
        let Some(a) = analytic_coverage(&t, local, &jac) else {
            continue;
        };
        let n = 128;
        let mut acc = 0.0;
        for i in 0..n {
            for j in 0..n {
                let d = Vector2::new(
                    (i as f64 + 0.5) / n as f64 - 0.5,
                    (j as f64 + 0.5) / n as f64 - 0.5,
                );
                acc += reflectance(&t, local + jac * d);
            }
        }
        let want = acc / (n * n) as f64;
        assert!(
            (a - want).abs() < 0.003,
            "at {local:?}, jac {jac:?}: analytic {a}, sampled {want}"
        );
        checked += 1;
    }
    assert!(checked > 1000, "{checked}");
}

/// Peak grey value inside `radius` px of `(col, row)`.
fn peak(img: &Image, col: f64, row: f64, radius: f64) -> u16 {
    let r = radius.ceil() as i64;
    let mut best = 0;
    for dr in -r..=r {
        for dc in -r..=r {
            let (c, rr) = (col.round() as i64 + dc, row.round() as i64 + dr);
            if c >= 0 && rr >= 0 && c < 1300 && rr < 1030 {
                best = best.max(img.get(c as u32, rr as u32));
            }
        }
    }
    best
}

#[test]
fn over_exposure_clips_at_the_saturation_level() {
    let field = default_plate();
    let e = Exterior::from_kuka_pose([0.0, 0.0, 900.0, 0.0, 0.0, 0.0]);
    let mut img = Image::new_mono8(1300, 1030);
    let mut r = Renderer::new(camera(Distortion::default()), &field, exact()).unwrap();
    r.render(&e, &mut img).unwrap();
    let visible: Vec<_> = r.truth().iter().filter(|t| t.visible).copied().collect();
    assert!(visible.len() > 100);
    // At 80 % of the full scale nothing clips ...
    assert!(visible
        .iter()
        .all(|t| peak(&img, t.col, t.row, t.radius_px * 0.5) < 255));
    // ... at twice the full scale every dot is clipped at the saturation
    // level (8 and 16 bit).
    r.set_options(RenderOptions {
        target: 2.0,
        ..exact()
    })
    .unwrap();
    r.render(&e, &mut img).unwrap();
    assert!(visible
        .iter()
        .all(|t| peak(&img, t.col, t.row, t.radius_px * 0.5) == 255));
    let mut img16 = Image::new_mono16(1300, 1030, 4095);
    r.render(&e, &mut img16).unwrap();
    assert!(visible
        .iter()
        .all(|t| peak(&img16, t.col, t.row, t.radius_px * 0.5) == 4095));
}

#[test]
fn the_ring_lights_beam_dims_targets_off_axis() {
    let field = default_plate();
    let cam = camera(Distortion::default());
    let e = Exterior::from_kuka_pose([0.0, 0.0, 600.0, 0.0, 0.0, 0.0]);
    let axis = -e.rotation.row(2).transpose();
    let options = RenderOptions {
        auto_exposure: false,
        reference_distance_mm: 600.0,
        target: 0.5,
        ..exact()
    };
    let mut flat = Renderer::new(cam, &field, options).unwrap();
    let mut beam = Renderer::new(
        cam,
        &field,
        RenderOptions {
            beam_half_angle_deg: 12.0,
            ..options
        },
    )
    .unwrap();
    let (mut a, mut b) = (
        Image::new_mono16(1300, 1030, 65535),
        Image::new_mono16(1300, 1030, 65535),
    );
    flat.render(&e, &mut a).unwrap();
    beam.render(&e, &mut b).unwrap();
    let bg = options.background * 65535.0;
    let m = 0.5f64.ln() / 12f64.to_radians().cos().ln();
    let mut n = 0;
    for (t, f) in flat.truth().iter().zip(field.targets()) {
        if !t.visible || t.radius_px < 4.0 {
            continue;
        }
        let cos = (f.position - e.center).normalize().dot(&axis);
        let (pa, pb) = (
            peak(&a, t.col, t.row, 1.0) as f64 - bg,
            peak(&b, t.col, t.row, 1.0) as f64 - bg,
        );
        let want = cos.powf(m);
        assert!(
            (pb / pa - want).abs() < 0.01,
            "target {}: {:.4} vs cos^m {:.4}",
            t.id,
            pb / pa,
            want
        );
        n += 1;
    }
    assert!(n > 50);
    assert!(flat
        .set_options(RenderOptions {
            beam_half_angle_deg: 90.0,
            ..options
        })
        .is_err());
}

/// A camera moving 2 mm sideways (and turning 0.05°) during the exposure
/// at 900 mm: each dot is smeared along its image path (≈ 4 px), centred
/// where the still dot at mid-exposure is, its second moment along the
/// path grown by the line's `len² / 12` and unchanged across it. (Over
/// much longer paths the ring light's gain varies along the path and
/// moves the centroid towards the brighter end: physics, not error.)
#[test]
fn motion_blur_smears_along_the_path_with_the_truth_at_mid_exposure() {
    let field = default_plate();
    let cam = camera(Distortion::default());
    let start = Exterior::from_kuka_pose([-1.0, 0.0, 900.0, 0.0, 0.0, 0.0]);
    let end = Exterior::from_kuka_pose([1.0, 0.0, 900.0, 0.05, 0.0, 0.0]);
    let mid = crate::interpolate(&start, &end, 0.5);
    let options = RenderOptions {
        blur_px: 0.6,
        ..exact()
    };
    let mut r = Renderer::new(cam, &field, options).unwrap();
    let mut still = Image::new_mono16(1300, 1030, 65535);
    let mut moving = Image::new_mono16(1300, 1030, 65535);
    let truth_mid = r.render(&mid, &mut still).unwrap().to_vec();
    let truth = r.render_moving(&start, &end, &mut moving).unwrap().to_vec();
    assert!(truth == truth_mid, "the truth is that of mid-exposure");
    // Same path, same bytes; a path of no length is a still frame.
    let mut again = Image::new_mono16(1300, 1030, 65535);
    r.render_moving(&start, &end, &mut again).unwrap();
    assert!(again.pixels() == moving.pixels());
    r.render_moving(&mid, &mid, &mut again).unwrap();
    assert!(again.pixels() == still.pixels());
    let bg = options.background * 65535.0;
    let mut n = 0;
    for (t, f) in truth.iter().zip(field.targets()) {
        if !(t.visible && t.kind == TargetKind::Uncoded) {
            continue;
        }
        // The image path of this target over the exposure.
        let a = start.project_pixel(&cam, &f.position).unwrap();
        let b = end.project_pixel(&cam, &f.position).unwrap();
        let len = (b - a).norm();
        assert!(len > 3.0, "{len}");
        let u = (b - a) / len;
        let reach = 1.5 * t.radius_px + len / 2.0;
        // The smeared dot is centred where the still dot at mid-exposure is
        // (whose centroid differs from the truth by the eccentricity).
        let (c, rr) = centroid(&moving, t.col, t.row, reach, bg);
        let (sc0, sr0) = centroid(&still, t.col, t.row, reach, bg);
        assert!(
            (c - sc0).hypot(rr - sr0) < 0.01,
            "target {}: ({c:.3}, {rr:.3}) vs ({sc0:.3}, {sr0:.3})",
            t.id
        );
        assert!((c - t.col).hypot(rr - t.row) < 0.1);
        // Second moments along and across the motion: the still dot's plus
        // the line's len²/12 along it.
        let moments = |img: &Image| {
            let (mut s, mut along, mut across) = (0.0, 0.0, 0.0);
            let r = reach.ceil() as i64 + 1;
            for dr in -r..=r {
                for dc in -r..=r {
                    let (cc, rw) = (t.col.round() as i64 + dc, t.row.round() as i64 + dr);
                    let (x, y) = (cc as f64 - t.col, rw as f64 - t.row);
                    if x.hypot(y) > reach {
                        continue;
                    }
                    let v = img.get(cc as u32, rw as u32) as f64 - bg;
                    let (p, q) = (x * u.x + y * u.y, -x * u.y + y * u.x);
                    s += v;
                    along += v * p * p;
                    across += v * q * q;
                }
            }
            (along / s, across / s)
        };
        let (sa, sc) = moments(&still);
        let (ma, mc) = moments(&moving);
        assert!(
            (ma - sa - len * len / 12.0).abs() < 0.05 * len * len / 12.0 + 0.02,
            "target {}: along {ma:.3} vs {sa:.3} + {:.3}",
            t.id,
            len * len / 12.0
        );
        assert!(
            (mc - sc).abs() < 0.05,
            "target {}: across {mc:.3} vs {sc:.3}",
            t.id
        );
        n += 1;
    }
    assert!(n > 50);
}
