//! The default plate seen by the built-in camera at several poses (frontal
//! to 45° oblique, 0.6 to 1.5 m), rendered by the ray-casting renderer of
//! `common` with blur σ = 0.6 px and noise σ = 2 DN: centroid RMS against
//! the projected target centres, decode rate of coded targets, and no wrong
//! id, no spurious target, no ring part reported as a target.

mod common;

use common::{render, Look};
use photopose_field::{design::default_plate, TargetKind};
use photopose_geometry::{Camera, Exterior, Vector3};
use photopose_vision::{Detector, DetectorOptions};

/// The camera of `config/camera.toml`.
fn camera() -> Camera {
    Camera::reference()
}

/// A camera at `distance` from the plate centre, tilted by `tilt_deg`
/// towards azimuth `azimuth_deg`, rolled so the image's up is the plate's +Y.
fn pose(distance: f64, tilt_deg: f64, azimuth_deg: f64) -> Exterior {
    let (t, a) = (tilt_deg.to_radians(), azimuth_deg.to_radians());
    let eye = Vector3::new(t.sin() * a.cos(), t.sin() * a.sin(), t.cos()) * distance;
    let up = if tilt_deg.abs() < 1e-9 {
        Vector3::y()
    } else {
        Vector3::z()
    };
    Exterior::look_at(eye, Vector3::zeros(), up).unwrap()
}

#[derive(Default, Debug)]
struct Tally {
    matched: usize,
    sq: f64,
    /// Targets at least 8 px across (minor axis) and their squared errors.
    matched_big: usize,
    sq_big: f64,
    coded: usize,
    decoded: usize,
    wrong_ids: usize,
    spurious: usize,
    kind_errors: usize,
    missed: usize,
    /// Known limitation: an isolated ring sector of a coded target whose
    /// dot lies outside the frame is reported as an uncoded target.
    cut_ring_parts: usize,
}

fn run(poses: &[(f64, f64, f64)]) -> Tally {
    let cam = camera();
    let field = default_plate();
    let mut det = Detector::new(1300, 1030, DetectorOptions::for_field(&field)).unwrap();
    let mut all = Tally::default();
    for (k, &(d, tilt, az)) in poses.iter().enumerate() {
        let ext = pose(d, tilt, az);
        let (img, truth) = render(
            &cam,
            &ext,
            &field,
            &Look {
                seed: k as u64 + 1,
                ..Look::default()
            },
        );
        let out = det.detect(img.view()).unwrap();
        let mut t = Tally::default();
        for x in &out.targets {
            let best = truth
                .iter()
                .map(|g| ((g.col - x.col).hypot(g.row - x.row), g))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            match best {
                Some((dist, g)) if dist < 1.0 => {
                    if let Some(id) = x.id {
                        if id != g.id {
                            t.wrong_ids += 1;
                            eprintln!(
                                "WRONG id {id} for target {} at {:.1} {:.1}",
                                g.id, g.col, g.row
                            );
                        }
                    }
                    if g.inside {
                        t.matched += 1;
                        t.sq += dist * dist;
                        if 2.0 * x.semi_minor >= 8.0 {
                            t.matched_big += 1;
                            t.sq_big += dist * dist;
                        }
                        if x.kind != g.kind {
                            t.kind_errors += 1;
                        }
                    }
                }
                _ => {
                    // On the ring of a coded target cut by the frame?
                    let on_cut_ring = truth.iter().any(|g| {
                        g.kind == TargetKind::Coded
                            && !g.inside
                            && (g.col - x.col).hypot(g.row - x.row) < 40.0
                    });
                    if on_cut_ring {
                        t.cut_ring_parts += 1;
                        eprintln!("ring part of a cut coded target reported: {x:?}");
                    } else {
                        t.spurious += 1;
                        eprintln!("spurious target {x:?}");
                    }
                }
            }
        }
        for g in truth.iter().filter(|g| g.inside) {
            let found = out
                .targets
                .iter()
                .find(|x| (g.col - x.col).hypot(g.row - x.row) < 1.0);
            match found {
                None => {
                    t.missed += 1;
                    let near: Vec<_> = out
                        .rejected
                        .iter()
                        .filter(|r| (g.col - r.col).hypot(g.row - r.row) < 5.0)
                        .collect();
                    eprintln!("missed {g:?}: {near:?}");
                }
                Some(x) if g.kind == TargetKind::Coded => {
                    t.coded += 1;
                    if x.id == Some(g.id) {
                        t.decoded += 1;
                    } else {
                        eprintln!(
                            "unread coded {} at {:.1} {:.1}: {:?}",
                            g.id, g.col, g.row, x.code
                        );
                    }
                }
                Some(_) => {}
            }
        }
        eprintln!(
            "pose {d} mm, tilt {tilt}°, az {az}°: {} targets inside, matched {}, missed {}, RMS {:.4} px ({:.4} px over {} targets ≥ 8 px across), decoded {}/{}, wrong ids {}, spurious {}, kind errors {}",
            truth.iter().filter(|g| g.inside).count(),
            t.matched,
            t.missed,
            (t.sq / t.matched.max(1) as f64).sqrt(),
            (t.sq_big / t.matched_big.max(1) as f64).sqrt(),
            t.matched_big,
            t.decoded,
            t.coded,
            t.wrong_ids,
            t.spurious,
            t.kind_errors
        );
        all.matched += t.matched;
        all.matched_big += t.matched_big;
        all.sq_big += t.sq_big;
        all.sq += t.sq;
        all.coded += t.coded;
        all.decoded += t.decoded;
        all.wrong_ids += t.wrong_ids;
        all.spurious += t.spurious;
        all.kind_errors += t.kind_errors;
        all.missed += t.missed;
        all.cut_ring_parts += t.cut_ring_parts;
    }
    all
}

fn check(all: &Tally) {
    let rms = (all.sq / all.matched as f64).sqrt();
    let rms_big = (all.sq_big / all.matched_big as f64).sqrt();
    eprintln!("overall: {all:?}, RMS {rms:.4} px, ≥ 8 px across {rms_big:.4} px");
    assert_eq!(all.wrong_ids, 0, "wrong ids");
    assert_eq!(all.spurious, 0, "spurious targets");
    assert_eq!(all.kind_errors, 0, "coded/uncoded confusions");
    assert_eq!(all.missed, 0, "targets inside the frame missed");
    assert!(
        rms_big <= 0.02,
        "centroid RMS {rms_big:.4} px (≥ 8 px across)"
    );
    assert!(rms <= 0.03, "centroid RMS {rms:.4} px (all)");
    assert!(
        all.decoded as f64 >= 0.95 * all.coded as f64,
        "decoded {} of {}",
        all.decoded,
        all.coded
    );
}

/// A few poses, quick enough in debug builds.
#[test]
fn default_plate_at_a_few_poses() {
    check(&run(&[
        (1000.0, 0.0, 0.0),
        (600.0, 20.0, 60.0),
        (1500.0, 45.0, 200.0),
    ]));
}

/// The full sweep: run with `cargo test --release -p photopose-vision --test plate -- --ignored`.
#[test]
#[ignore = "a sweep of 24 frames: run in release"]
fn default_plate_sweep() {
    let mut poses = Vec::new();
    for &d in &[600.0, 800.0, 1000.0, 1250.0, 1500.0] {
        for (i, &tilt) in [0.0, 15.0, 30.0, 45.0].iter().enumerate() {
            poses.push((d, tilt, 37.0 + 83.0 * i as f64 + d / 10.0));
        }
    }
    check(&run(&poses));
}
