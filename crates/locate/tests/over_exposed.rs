//! Over-exposed frames: a ring light that drives the nearest targets to
//! twice the full scale (clipped at the saturation level), 8- and 16-bit,
//! on the default camera and on a 2448 × 2048 one. Every frame is posed,
//! the pose lies within 3σ of the render's truth (jointly: Mahalanobis
//! distance under the reported covariance against the χ²(6) quantile of
//! 99.73 %), no target gets a wrong id, and the saturated targets are
//! flagged and counted.

use photopose_field::design::default_plate;
use photopose_frame::Image;
use photopose_geometry::{Camera, Distortion, Exterior, Interior, Sensor, Vector3};
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_render::{RenderOptions, Renderer};
use photopose_vision::{Detector, DetectorOptions};

/// χ²(6) quantile at 99.73 % (the probability of ±3σ in one dimension).
const CHI2_6_3SIGMA: f64 = 20.06;

/// A 5 MP machine-vision camera (2448 × 2048, 3.45 µm) with a 12 mm lens.
fn big_camera() -> Camera {
    Camera::new(
        Sensor {
            width: 2448,
            height: 2048,
            pixel_size: 0.00345,
        },
        Interior {
            c: 12.0,
            x0: 0.012,
            y0: -0.009,
        },
        Distortion {
            k1: -1.0e-4,
            k2: 2.0e-7,
            ..Distortion::default()
        },
    )
    .unwrap()
}

/// Looking at the plate from `distance` mm, tilted by `tilt_deg` towards
/// azimuth `az_deg`, aimed at `(x, y)` on the plate.
fn pose(distance: f64, tilt_deg: f64, az_deg: f64, x: f64, y: f64) -> Exterior {
    let (t, a) = (tilt_deg.to_radians(), az_deg.to_radians());
    let aim = Vector3::new(x, y, 0.0);
    let eye = aim + Vector3::new(t.sin() * a.cos(), t.sin() * a.sin(), t.cos()) * distance;
    let up = Vector3::new(-a.sin(), a.cos(), 0.0);
    Exterior::look_at(eye, aim, up).unwrap()
}

const POSES: [(f64, f64, f64, f64, f64); 3] = [
    (900.0, 0.0, 0.0, 0.0, 0.0),
    (750.0, 20.0, 40.0, 30.0, -20.0),
    (1100.0, 35.0, 200.0, -40.0, 25.0),
];

#[derive(Debug, Default)]
struct Tally {
    frames: usize,
    posed: usize,
    within_3_sigma: usize,
    wrong_ids: usize,
    identified: usize,
    saturated: usize,
    /// Sum of the saturated targets' radial errors, px.
    radial: f64,
}

/// Renders every pose at `peak` × full scale into `image` and locates it.
fn run(camera: Camera, image: &mut Image, noise_dn: f64, locator: &mut Locator) -> Tally {
    let field = default_plate();
    let mut renderer = Renderer::new(camera, &field, RenderOptions::default()).unwrap();
    let mut t = Tally::default();
    for (k, &(d, tilt, az, x, y)) in POSES.iter().enumerate() {
        renderer
            .set_options(RenderOptions {
                target: 2.0,
                noise_dn,
                seed: 40 + k as u64,
                ..RenderOptions::default()
            })
            .unwrap();
        let truth_pose = pose(d, tilt, az, x, y);
        renderer.render(&truth_pose, image).unwrap();
        let truth = renderer.truth();
        let loc = locator.locate(image.view()).unwrap();
        t.frames += 1;
        for id in loc.targets {
            let tr = truth.iter().find(|g| g.id == id.id).unwrap();
            if (id.col - tr.col).hypot(id.row - tr.row) >= 1.0 {
                t.wrong_ids += 1;
                eprintln!("wrong id {} at ({:.1}, {:.1})", id.id, id.col, id.row);
            }
        }
        // Radial error of the saturated targets (a bias of their centres
        // towards or away from the image centre shows as a scale error,
        // i.e. in the distance).
        let (cx, cy) = (
            camera.sensor.width as f64 / 2.0,
            camera.sensor.height as f64 / 2.0,
        );
        for id in loc.targets.iter().filter(|x| x.saturated) {
            let tr = truth.iter().find(|g| g.id == id.id).unwrap();
            let (rx, ry) = (tr.col - cx, tr.row - cy);
            let r = rx.hypot(ry).max(1.0);
            t.radial += ((id.col - tr.col) * rx + (id.row - tr.row) * ry) / r;
        }
        t.identified += loc.targets.len();
        t.saturated += loc.n_saturated;
        assert_eq!(
            loc.n_saturated,
            loc.targets.iter().filter(|x| x.saturated).count()
        );
        let (PoseStatus::Ok, Some(p)) = (loc.status, loc.pose) else {
            eprintln!("frame {k}: no pose: {:?}", loc.status);
            continue;
        };
        t.posed += 1;
        let dc = p.exterior.center - truth_pose.center;
        let err = p.exterior.deviation_from(&truth_pose);
        let m2 = p.mahalanobis_sq(&truth_pose);
        eprintln!(
            "frame {k}: {} targets ({} saturated), σ0 {:.3} px, centre error {:.4} mm (σ {:?}), d² {m2:.2}, error / σ {:?}",
            loc.targets.len(),
            loc.n_saturated,
            p.sigma0_px,
            dc.norm(),
            p.std_center().as_slice(),
            (0..6)
                .map(|i| format!("{:.2}", err[i] / p.covariance[(i, i)].sqrt()))
                .collect::<Vec<_>>()
        );
        t.within_3_sigma += (m2 <= CHI2_6_3SIGMA) as usize;
    }
    t
}

fn check(what: &str, t: &Tally) {
    eprintln!("{what}: {t:?}");
    assert_eq!(t.wrong_ids, 0, "{what}: wrong ids");
    assert_eq!(t.posed, t.frames, "{what}: a pose in every frame");
    assert_eq!(t.within_3_sigma, t.posed, "{what}: poses within 3σ");
    assert!(
        t.saturated * 5 >= t.identified,
        "{what}: the frames are over-exposed ({} of {} targets saturated)",
        t.saturated,
        t.identified
    );
    let radial = t.radial / t.saturated as f64;
    assert!(
        radial.abs() < 0.002,
        "{what}: saturated centres biased radially by {radial:.4} px"
    );
}

fn locator(camera: Camera, options: DetectorOptions) -> Locator {
    let field = default_plate();
    let detector = Detector::new(camera.sensor.width, camera.sensor.height, options).unwrap();
    Locator::with_detector(camera, field, LocateOptions::default(), detector).unwrap()
}

#[test]
fn over_exposed_frames_of_the_default_camera_are_posed() {
    let camera = photopose_formats::default_camera();
    let options = DetectorOptions::for_field(&default_plate());
    let (w, h) = (camera.sensor.width, camera.sensor.height);
    let mut l = locator(camera, options);
    let t = run(camera, &mut Image::new_mono8(w, h), 2.0, &mut l);
    check("default camera, 8-bit", &t);
    // A 12-bit camera in a 16-bit container, noise scaled alike.
    let t = run(camera, &mut Image::new_mono16(w, h, 4095), 32.0, &mut l);
    check("default camera, 12 of 16 bit", &t);
    // Before: blobs with a saturated pixel were rejected, and these frames
    // gave no pose.
    let mut before = locator(
        camera,
        DetectorOptions {
            measure_saturated: false,
            ..options
        },
    );
    let t = run(camera, &mut Image::new_mono8(w, h), 2.0, &mut before);
    assert!(t.posed < t.frames, "{t:?}");
}

#[test]
fn over_exposed_frames_of_a_5_megapixel_camera_are_posed() {
    let camera = big_camera();
    let options = DetectorOptions::for_field(&default_plate());
    let (w, h) = (camera.sensor.width, camera.sensor.height);
    let mut l = locator(camera, options);
    let t = run(camera, &mut Image::new_mono8(w, h), 2.0, &mut l);
    check("2448 × 2048, 8-bit", &t);
    let t = run(
        camera,
        &mut Image::new_mono16(w, h, u16::MAX),
        2.0 * 257.0,
        &mut l,
    );
    check("2448 × 2048, 16-bit", &t);
}
