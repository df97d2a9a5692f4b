//! The whole frame pipeline on rendered frames of the default plate seen by
//! the default camera: identities (never a wrong one), identification rates,
//! centroid accuracy and the pose against the render's truth within its own
//! reported precision.
//!
//! `cargo test -p photopose-locate --test rendered` runs a short sweep; the
//! long sweep of the acceptance figures (≥ 10,000 decoded coded targets) is
//! `cargo test --release -p photopose-locate --test rendered -- --ignored --nocapture`.

use photopose_field::design::default_plate;
use photopose_field::TargetKind;
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::rotation::angle_between;
use photopose_geometry::{Camera, Exterior, Vector3};
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_render::{RenderOptions, Renderer};

fn camera() -> Camera {
    photopose_formats::default_camera()
}

/// A camera pose looking at the plate from `distance` mm with the given
/// tilt (degrees from the plate normal), azimuth of the tilt and roll about
/// the viewing direction, aimed near the plate centre.
fn pose(rng: &mut SplitMix64, distance: f64, tilt_deg: f64) -> Exterior {
    let az = rng.unit() * std::f64::consts::TAU;
    let t = tilt_deg.to_radians();
    let aim = Vector3::new((rng.unit() - 0.5) * 120.0, (rng.unit() - 0.5) * 80.0, 0.0);
    let eye = aim + Vector3::new(t.sin() * az.cos(), t.sin() * az.sin(), t.cos()) * distance;
    let roll = rng.unit() * std::f64::consts::TAU;
    let up = Vector3::new(roll.cos(), roll.sin(), 0.0);
    let up = if (eye - aim).normalize().cross(&up).norm() < 0.2 {
        Vector3::new(-roll.sin(), roll.cos(), 0.0)
    } else {
        up
    };
    Exterior::look_at(eye, aim, up).unwrap()
}

#[derive(Default, Debug)]
struct Tally {
    frames: usize,
    poses: usize,
    within_3_sigma: usize,
    coded_visible_readable: usize,
    coded_decoded: usize,
    coded_identified_total: usize,
    uncoded_visible: usize,
    uncoded_identified: usize,
    wrong_ids: usize,
    centroid_sq: f64,
    centroid_n: usize,
    mahalanobis: Vec<f64>,
    normalised: [f64; 6],
}

/// χ²(6) quantile at 99.73 % (the probability of ±3σ in one dimension).
const CHI2_6_3SIGMA: f64 = 20.06;

fn sweep(frames: usize, seed: u64) -> Tally {
    let cam = camera();
    let field = default_plate();
    let mut renderer = Renderer::new(
        cam,
        &field,
        RenderOptions {
            noise_dn: 2.0,
            blur_px: 0.6,
            ..RenderOptions::default()
        },
    )
    .unwrap();
    let mut locator = Locator::new(cam, field.clone(), LocateOptions::default()).unwrap();
    let mut image = renderer.new_image();
    let mut rng = SplitMix64::new(seed);
    let mut tally = Tally::default();
    for f in 0..frames {
        let distance = 600.0 + rng.unit() * 900.0;
        let tilt = rng.unit() * 45.0;
        let truth_pose = pose(&mut rng, distance, tilt);
        renderer
            .set_options(RenderOptions {
                noise_dn: 2.0,
                blur_px: 0.6,
                seed: seed * 1000 + f as u64,
                ..RenderOptions::default()
            })
            .unwrap();
        renderer.render(&truth_pose, &mut image).unwrap();
        let truth = renderer.truth();
        let loc = locator.locate(image.view()).unwrap();
        tally.frames += 1;
        let by_id = |id: u64| truth.iter().find(|t| t.id == id).unwrap();
        for t in loc.targets {
            let tr = by_id(t.id);
            let d = (t.col - tr.col).hypot(t.row - tr.row);
            if d.is_nan() || d >= 1.0 {
                tally.wrong_ids += 1;
                eprintln!(
                    "frame {f}: id {} at ({:.2}, {:.2}), truth at ({:.2}, {:.2})",
                    t.id, t.col, t.row, tr.col, tr.row
                );
                continue;
            }
            // Dots at least 8 px across in every direction.
            if 2.0 * minor_radius(&cam, &truth_pose, t.id, &field) >= 8.0 {
                tally.centroid_sq += d * d;
                tally.centroid_n += 1;
                if std::env::var_os("PHOTOPOSE_AXES").is_some() {
                    let det = &loc.detections.targets[t.detection];
                    let (ca, sa) = (det.angle.cos(), det.angle.sin());
                    let (ex, ey) = (t.col - tr.col, t.row - tr.row);
                    eprintln!(
                        "axes {:.3} {:.3} {:.5} {:.5}",
                        det.semi_major,
                        det.semi_minor,
                        ex * ca + ey * sa,
                        -ex * sa + ey * ca
                    );
                }
                if std::env::var_os("PHOTOPOSE_DIAG").is_some() {
                    let det = &loc.detections.targets[t.detection];
                    eprintln!(
                        "centroid {:?} r={:.1} minor={:.1} peak={} err={:.4} dcol={:.4} drow={:.4}",
                        t.kind,
                        tr.radius_px,
                        det.semi_minor,
                        det.peak,
                        d,
                        t.col - tr.col,
                        t.row - tr.row
                    );
                }
            }
        }
        for tr in truth.iter().filter(|t| t.visible) {
            let found = loc.targets.iter().any(|t| t.id == tr.id);
            if !found && std::env::var_os("PHOTOPOSE_DIAG").is_some() {
                let det = loc
                    .detections
                    .targets
                    .iter()
                    .find(|d| (d.col - tr.col).hypot(d.row - tr.row) < 3.0);
                let rej = loc
                    .detections
                    .rejected
                    .iter()
                    .find(|d| (d.col - tr.col).hypot(d.row - tr.row) < 3.0);
                eprintln!(
                    "frame {f}: missed {:?} {} r={:.1}px at ({:.1},{:.1}); detection {:?}; rejection {:?}",
                    tr.kind, tr.id, tr.radius_px, tr.col, tr.row, det.map(|d| (d.col - tr.col, d.row - tr.row, d.kind, d.id, d.code)), rej.map(|r| r.reason)
                );
            }
            match tr.kind {
                TargetKind::Coded => {
                    tally.coded_identified_total += found as usize;
                    // A code sector at mid-ring (2.5 r) at least 3 px long.
                    if 2.0
                        * std::f64::consts::PI
                        * 2.5
                        * minor_radius(&cam, &truth_pose, tr.id, &field)
                        / 12.0
                        >= 3.0
                    {
                        tally.coded_visible_readable += 1;
                        tally.coded_decoded += found as usize;
                    }
                }
                TargetKind::Uncoded => {
                    tally.uncoded_visible += 1;
                    tally.uncoded_identified += found as usize;
                }
            }
        }
        if let (PoseStatus::Ok, Some(p)) = (loc.status, loc.pose) {
            tally.poses += 1;
            let s = p.std_center();
            let sr = p.std_rotation_deg();
            let dc = p.exterior.center - truth_pose.center;
            let err = p.exterior.deviation_from(&truth_pose);
            // Jointly: the Mahalanobis distance of the six errors under the
            // reported covariance, against the χ²(6) quantile of 3σ (99.73 %).
            let m2 = p.mahalanobis_sq(&truth_pose);
            let ok = m2 <= CHI2_6_3SIGMA;
            tally.mahalanobis.push(m2);
            for k in 0..6 {
                tally.normalised[k] += err[k] / p.covariance[(k, k)].sqrt();
            }
            tally.within_3_sigma += ok as usize;
            if !ok {
                eprintln!(
                    "frame {f}: pose off (d² = {m2:.1}; {distance:.0} mm, tilt {tilt:.0}°, σ0 {:.3} px, {} points): dc {:?} σ {:?} (σ° {:?}), angle {:.5}°",
                    p.sigma0_px,
                    p.n_points,
                    dc.as_slice(),
                    s.as_slice(),
                    sr.as_slice(),
                    angle_between(&p.exterior.rotation, &truth_pose.rotation).to_degrees()
                );
            }
        } else {
            eprintln!("frame {f}: no pose: {:?}", loc.status);
        }
    }
    tally
}

/// Smallest image radius of a target's dot, px (16 rim points projected).
fn minor_radius(cam: &Camera, e: &Exterior, id: u64, field: &photopose_field::Field) -> f64 {
    let t = field.get(id).unwrap();
    let c = e.project_pixel(cam, &t.position).unwrap();
    (0..16)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 16.0;
            let q = t.position + Vector3::new(a.cos(), a.sin(), 0.0) * t.radius;
            (e.project_pixel(cam, &q).unwrap() - c).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

fn check(t: &Tally) {
    eprintln!("{t:#?}");
    assert_eq!(t.wrong_ids, 0, "wrong ids");
    assert!(t.poses == t.frames, "a pose in every frame");
    let coded_rate = t.coded_decoded as f64 / t.coded_visible_readable.max(1) as f64;
    let uncoded_rate = t.uncoded_identified as f64 / t.uncoded_visible.max(1) as f64;
    let rms = (t.centroid_sq / t.centroid_n.max(1) as f64).sqrt();
    eprintln!(
        "decode rate {:.4} ({} / {}), uncoded identified {:.4} ({} / {}), centroid RMS {:.4} px over {} targets, poses within 3σ {} / {}",
        coded_rate, t.coded_decoded, t.coded_visible_readable, uncoded_rate, t.uncoded_identified, t.uncoded_visible, rms, t.centroid_n, t.within_3_sigma, t.poses
    );
    assert!(coded_rate >= 0.99, "decode rate {coded_rate}");
    assert!(
        uncoded_rate >= 0.99,
        "uncoded identification rate {uncoded_rate}"
    );
    assert!(rms <= 0.02, "centroid RMS {rms} px");
    eprintln!(
        "mean normalised error per unknown: {:?}",
        t.normalised.map(|x| x / t.poses as f64)
    );
    let mut m = t.mahalanobis.clone();
    m.sort_by(f64::total_cmp);
    eprintln!(
        "Mahalanobis d² of the pose error: median {:.2} (χ²(6): 5.35), 90 % {:.2} (10.64), 99 % {:.2} (16.81)",
        m[m.len() / 2],
        m[m.len() * 9 / 10],
        m[m.len() * 99 / 100]
    );
    assert!(
        t.within_3_sigma as f64 >= 0.99 * t.poses as f64 || t.poses - t.within_3_sigma <= 1,
        "poses within 3σ: {} of {}",
        t.within_3_sigma,
        t.poses
    );
}

#[test]
fn short_sweep_identifies_and_resects() {
    check(&sweep(8, 1));
}

#[test]
#[ignore = "long sweep for the acceptance figures: run in release with --ignored"]
fn long_sweep_ten_thousand_coded_targets() {
    let t = sweep(420, 2);
    assert!(
        t.coded_identified_total >= 10_000,
        "only {} coded targets decoded",
        t.coded_identified_total
    );
    check(&t);
}
