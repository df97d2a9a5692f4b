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
