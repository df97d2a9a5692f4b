//! Tracking mode against the whole-frame path on rendered frames of the
//! default camera and plate: the same ids and the same pose (within a tenth
//! of its σ) from a prediction; a prediction a grid step off is refused,
//! never turned into a pose (the allocation test is in no_alloc.rs).

use photopose_field::design::default_plate;
use photopose_geometry::{Exterior, Vector3};
use photopose_locate::track::{Motion, Prior, TrackLost, TrackOptions};
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_render::{RenderOptions, Renderer};
use photopose_vision::{Detector, DetectorOptions};

fn poses() -> [Exterior; 3] {
    [
        Exterior::from_kuka_pose([0.0, 0.0, 1000.0, 0.0, 0.0, 0.0]),
        Exterior::from_kuka_pose([40.0, -30.0, 900.0, 30.0, 10.0, -5.0]),
        Exterior::from_kuka_pose([-60.0, 50.0, 1100.0, -120.0, -12.0, 8.0]),
    ]
}

fn shifted(e: &Exterior, by: Vector3<f64>) -> Exterior {
    Exterior::new(e.rotation, e.center + by)
}

#[test]
fn a_tracked_frame_gives_the_whole_frame_pose_and_ids() {
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let mut renderer = Renderer::new(camera, &field, RenderOptions::default()).unwrap();
    let mut locator = Locator::new(camera, field, LocateOptions::default()).unwrap();
    for truth in poses() {
        let mut img = renderer.new_image();
        renderer.render(&truth, &mut img).unwrap();
        let whole = locator.locate(img.view()).unwrap();
        assert_eq!(*whole.status, PoseStatus::Ok);
        let full = *whole.pose.unwrap();
        let threshold = whole.detections.threshold;
        let mut ids: Vec<u64> = whole.targets.iter().map(|t| t.id).collect();
        ids.sort_unstable();
        // Predicted 0.8 mm off, as from the motion of a moving robot.
        let prior = Prior {
            exterior: shifted(&full.exterior, Vector3::new(0.5, -0.4, 0.5)),
            covariance: full.covariance,
            motion_px: 2.0,
            threshold,
        };
        let tracked = *locator
            .track(img.view(), &prior, &TrackOptions::default())
            .unwrap();
        let sigma = full.std_center();
        for k in 0..3 {
            let d = (tracked.exterior.center[k] - full.exterior.center[k]).abs();
            assert!(d <= 1e-3 * sigma[k], "axis {k}: {d} mm vs σ {}", sigma[k]);
        }
        let dr = (tracked.exterior.rotation - full.exterior.rotation)
            .abs()
            .max();
        assert!(dr < 1e-3 * full.std_rotation_deg().max().to_radians());
        assert_eq!(tracked.n_points, full.n_points);
        let mut tracked_ids = locator_ids(&locator);
        tracked_ids.sort_unstable();
        assert_eq!(tracked_ids, ids);
    }
}

fn locator_ids(locator: &Locator) -> Vec<u64> {
    locator.identified().iter().map(|t| t.id).collect()
}

#[test]
fn a_prediction_a_grid_step_off_is_refused() {
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let mut renderer = Renderer::new(camera, &field, RenderOptions::default()).unwrap();
    let mut locator = Locator::new(camera, field.clone(), LocateOptions::default()).unwrap();
    let truth = poses()[0];
    let mut img = renderer.new_image();
    renderer.render(&truth, &mut img).unwrap();
    let whole = locator.locate(img.view()).unwrap();
    let full = *whole.pose.unwrap();
    let threshold = whole.detections.threshold;
    // The plate's grid pitch: the distance from a target to its nearest
    // neighbour.
    let t = field.targets();
    let pitch = t
        .iter()
        .enumerate()
        .flat_map(|(i, a)| {
            t[i + 1..]
                .iter()
                .map(move |b| (a.position - b.position).norm())
        })
        .fold(f64::INFINITY, f64::min);
    assert!((pitch - 32.0).abs() < 1e-9, "{pitch}");
    // Off by a grid step along and across the rows: every window catches
    // a neighbour, and the coded targets' rings refuse the prediction
    // (another id, or none confirmed).
    for (dx, dy) in [
        (pitch, 0.0),
        (0.0, pitch),
        (-pitch, pitch),
        (0.0, -2.0 * pitch),
    ] {
        let prior = Prior {
            exterior: shifted(&full.exterior, Vector3::new(dx, dy, 0.0)),
            covariance: full.covariance,
            motion_px: 0.0,
            threshold,
        };
        let outcome = locator.track(img.view(), &prior, &TrackOptions::default());
        assert_eq!(outcome.err(), Some(TrackLost::CodeMismatch), "({dx}, {dy})");
    }
    // Off by fractions of it: refused, or accepted only as the true pose.
    for (dx, dy) in [(10.0, 0.0), (7.0, -7.0), (0.5 * pitch, 0.0)] {
        let prior = Prior {
            exterior: shifted(&full.exterior, Vector3::new(dx, dy, 0.0)),
            covariance: full.covariance,
            motion_px: 0.0,
            threshold,
        };
        match locator.track(img.view(), &prior, &TrackOptions::default()) {
            Err(TrackLost::TooFewTargets { .. } | TrackLost::CodeMismatch | TrackLost::Jump) => {}
            Err(other) => panic!("({dx}, {dy}): {other:?}"),
            Ok(r) => {
                let d = (r.exterior.center - full.exterior.center).norm();
                assert!(d < 0.05, "({dx}, {dy}): a pose {d} mm off was accepted");
            }
        }
    }
}

#[test]
fn motion_predicts_constant_velocity() {
    let a = Exterior::from_kuka_pose([0.0, 0.0, 1000.0, 0.0, 0.0, 0.0]);
    let b = Exterior::from_kuka_pose([1.0, -2.0, 1000.5, 0.2, 0.0, 0.0]);
    let c = Exterior::from_kuka_pose([2.0, -4.0, 1001.0, 0.4, 0.0, 0.0]);
    let m = Motion {
        last: (10, b),
        before: Some((9, a)),
    };
    let (p, shift) = m.predict(11, 12.0, 0.00645, 1000.0);
    assert!((p.center - c.center).norm() < 1e-9);
    assert!((p.rotation - c.rotation).abs().max() < 1e-9);
    assert!(shift > 0.0);
    // A frame between the two (finished after the later one): back along
    // the same motion.
    let (p, back) = m.predict(9, 12.0, 0.00645, 1000.0);
    assert!((p.center - a.center).norm() < 1e-9);
    assert!((p.rotation - a.rotation).abs().max() < 1e-9);
    assert!((back - shift).abs() < 1e-9 * shift);
    let still = Motion {
        last: (10, b),
        before: None,
    };
    assert_eq!(still.predict(11, 12.0, 0.00645, 1000.0).0, b);
}

/// The differences of two poses in units of `full`'s σ: `Xc, Yc, Zc` and
/// the small rotations `ω` (`R_t = R_f (I + [ω]ₓ)`, as in the covariance).
fn sigma_units(
    tracked: &photopose_geometry::ResectionReport,
    full: &photopose_geometry::ResectionReport,
) -> [f64; 6] {
    let d = full.exterior.rotation.transpose() * tracked.exterior.rotation;
    let omega = [
        (d[(2, 1)] - d[(1, 2)]) / 2.0,
        (d[(0, 2)] - d[(2, 0)]) / 2.0,
        (d[(1, 0)] - d[(0, 1)]) / 2.0,
    ];
    let mut out = [0.0; 6];
    for k in 0..3 {
        out[k] =
            (tracked.exterior.center[k] - full.exterior.center[k]) / full.covariance[(k, k)].sqrt();
        out[3 + k] = omega[k] / full.covariance[(3 + k, 3 + k)].sqrt();
    }
    out
}

#[test]
fn tracked_poses_along_a_moving_circle_equal_the_whole_frame_within_a_tenth_of_sigma() {
    // The camera 1000 mm above the plate moving 0.2 mm per frame along a
    // 40 mm circle, every frame with its own noise: each frame is tracked
    // from the pose predicted by the two before it with the threshold of
    // the first frame's whole-frame pass, and located whole on its own.
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let mut renderer = Renderer::new(camera, &field, RenderOptions::default()).unwrap();
    // The detector holds its threshold level, as the daemon's do with
    // tracking on.
    let options = DetectorOptions {
        threshold_hold: 1.0,
        ..DetectorOptions::for_field(&field)
    };
    let detector = Detector::new(camera.sensor.width, camera.sensor.height, options).unwrap();
    let mut locator =
        Locator::with_detector(camera, field, LocateOptions::default(), detector).unwrap();
    let (c, px) = (camera.interior.c, camera.sensor.pixel_size);
    let at = |k: u64| {
        let phi = 0.005 * k as f64;
        Exterior::from_kuka_pose([40.0 * phi.cos(), 40.0 * phi.sin(), 1000.0, 0.0, 0.0, 0.0])
    };
    let mut img = renderer.new_image();
    renderer.render(&at(0), &mut img).unwrap();
    let whole = locator.locate(img.view()).unwrap();
    let first = *whole.pose.unwrap();
    let threshold = whole.detections.threshold;
    let mut motion = Motion {
        last: (0, first.exterior),
        before: None,
    };
    let mut covariance = first.covariance;
    let mut worst = [0.0f64; 6];
    for k in 1..=6u64 {
        renderer
            .set_options(RenderOptions {
                seed: 100 + k,
                ..RenderOptions::default()
            })
            .unwrap();
        renderer.render(&at(k), &mut img).unwrap();
        let (exterior, motion_px) = motion.predict(k, c, px, 1000.0);
        let prior = Prior {
            exterior,
            covariance,
            motion_px,
            threshold,
        };
        let tracked = *locator
            .track(img.view(), &prior, &TrackOptions::default())
            .unwrap_or_else(|e| panic!("frame {k}: {e:?}"));
        let whole = locator.locate(img.view()).unwrap();
        assert_eq!(*whole.status, PoseStatus::Ok);
        let full = *whole.pose.unwrap();
        assert_eq!(tracked.n_points, full.n_points, "frame {k}");
        for (w, d) in worst.iter_mut().zip(sigma_units(&tracked, &full)) {
            *w = w.max(d.abs());
        }
        covariance = tracked.covariance;
        motion = Motion {
            last: (k, tracked.exterior),
            before: Some(motion.last),
        };
    }
    assert!(
        worst.iter().all(|&w| w <= 0.1),
        "largest differences (Xc, Yc, Zc, ωX, ωY, ωZ) in σ: {worst:?}"
    );
}

/// An over-exposed frame (targets at four times full scale: most pixels
/// of every dot clipped) with the saturated roll-off on tracked from a prediction: every target, coded ones included,
/// has the centre the whole frame gives it (the saturated roll-off applied
/// alike; compared before the eccentricity correction, which depends on
/// the pose it starts from), and the pose is the whole frame's.
#[test]
fn an_over_exposed_frame_tracked_has_the_whole_frame_centres() {
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let mut renderer = Renderer::new(
        camera,
        &field,
        RenderOptions {
            target: 4.0,
            seed: 11,
            ..RenderOptions::default()
        },
    )
    .unwrap();
    // With the roll-off below saturation on (off by default).
    let options = DetectorOptions {
        saturated_knee: 0.7,
        ..DetectorOptions::for_field(&field)
    };
    let detector = Detector::new(camera.sensor.width, camera.sensor.height, options).unwrap();
    let mut locator =
        Locator::with_detector(camera, field, LocateOptions::default(), detector).unwrap();
    let truth = Exterior::from_kuka_pose([20.0, -10.0, 800.0, 10.0, 4.0, -3.0]);
    let mut img = renderer.new_image();
    renderer.render(&truth, &mut img).unwrap();
    let whole = locator.locate(img.view()).unwrap();
    assert_eq!(*whole.status, PoseStatus::Ok);
    let full = *whole.pose.unwrap();
    let threshold = whole.detections.threshold;
    let mut centres: Vec<(u64, f64, f64, bool)> = whole
        .targets
        .iter()
        .map(|t| (t.id, t.blob_col, t.blob_row, t.saturated))
        .collect();
    centres.sort_by_key(|c| c.0);
    let saturated_coded = whole
        .targets
        .iter()
        .filter(|t| t.saturated && t.kind == photopose_field::TargetKind::Coded)
        .count();
    assert!(
        saturated_coded >= 5,
        "{saturated_coded} saturated coded targets"
    );
    let prior = Prior {
        exterior: shifted(&full.exterior, Vector3::new(0.3, 0.2, -0.3)),
        covariance: full.covariance,
        motion_px: 1.0,
        threshold,
    };
    let tracked = *locator
        .track(img.view(), &prior, &TrackOptions::default())
        .unwrap();
    let mut got: Vec<(u64, f64, f64, bool)> = locator
        .identified()
        .iter()
        .map(|t| (t.id, t.blob_col, t.blob_row, t.saturated))
        .collect();
    got.sort_by_key(|c| c.0);
    assert_eq!(got.len(), centres.len());
    for (g, w) in got.iter().zip(&centres) {
        assert_eq!(g.0, w.0);
        assert_eq!(g.3, w.3, "target {}: saturated flag", g.0);
        assert!(
            (g.1 - w.1).abs() < 1e-9 && (g.2 - w.2).abs() < 1e-9,
            "target {} (saturated {}): tracked ({}, {}), whole frame ({}, {})",
            g.0,
            g.3,
            g.1,
            g.2,
            w.1,
            w.2
        );
    }
    let sigma = full.std_center();
    for k in 0..3 {
        let d = (tracked.exterior.center[k] - full.exterior.center[k]).abs();
        assert!(d <= 0.1 * sigma[k], "axis {k}: {d} mm vs σ {}", sigma[k]);
    }
}
