//! Unit tests of the correction law against a pure simulated robot.
#![allow(clippy::needless_range_loop)] // component-wise checks read best indexed

use super::*;
use nalgebra::Vector3;

fn hand_eye() -> HandEye {
    HandEye {
        tcp_from_camera: pose_to_isometry(&[30.0, -20.0, 120.0, 10.0, 5.0, -3.0]),
        base_from_plate: pose_to_isometry(&[900.0, 100.0, -300.0, 90.0, 0.0, 180.0]),
    }
}

const NOMINAL: Pose6 = [445.0, 10.0, 790.0, 170.0, 5.0, 175.0];
const ERROR: Pose6 = [0.8, -0.5, 0.3, 0.05, -0.03, 0.02];

/// A robot whose actual TCP is the commanded (+ correction) pose moved by a
/// fixed error in the base frame.
struct Robot {
    frame: CorrFrame,
    mode: CorrectionMode,
    total: Pose6,
    rsol_includes: bool,
}

impl Robot {
    fn commanded(&self) -> Isometry3<f64> {
        apply_correction(&pose_to_isometry(&NOMINAL), &self.total, self.frame)
    }
    fn actual(&self) -> Isometry3<f64> {
        apply_correction(&self.commanded(), &ERROR, CorrFrame::Base)
    }
    fn rsol(&self) -> Pose6 {
        if self.rsol_includes {
            isometry_to_pose(&self.commanded())
        } else {
            NOMINAL
        }
    }
    fn receive(&mut self, send: &Pose6) {
        for i in 0..6 {
            match self.mode {
                CorrectionMode::Relative => self.total[i] += send[i],
                CorrectionMode::Absolute => self.total[i] = send[i],
            }
        }
    }
}

fn measurement(he: &HandEye, actual: &Isometry3<f64>, time_s: f64, seq: u64) -> Measurement {
    Measurement {
        plate_from_camera: he.camera_in_plate(actual),
        std_mm: 0.01,
        std_deg: 0.001,
        n_targets: 40,
        time_s,
        seq,
    }
}

fn residual(he: &HandEye, robot: &Robot) -> (f64, f64) {
    let _ = he;
    let nominal = pose_to_isometry(&NOMINAL);
    let a = robot.actual();
    let dt = (a.translation.vector - nominal.translation.vector).norm();
    let dr = a.rotation.angle_to(&nominal.rotation).to_degrees();
    (dt, dr)
}

/// Runs `cycles` cycles at 4 ms with a camera every 10 cycles whose frame is
/// 3 cycles old; returns the residual and checks the limits every cycle.
fn run_loop(cfg: LawConfig, rsol_includes: bool, cycles: usize) -> (f64, f64, CorrectionLaw) {
    let he = hand_eye();
    let mut law = CorrectionLaw::new(cfg, he);
    let mut robot = Robot {
        frame: cfg.frame,
        mode: cfg.mode,
        total: [0.0; 6],
        rsol_includes,
    };
    let mut snapshots: Vec<(f64, Isometry3<f64>)> = Vec::new();
    let mut latest: Option<Measurement> = None;
    let mut seq = 0;
    for k in 0..cycles {
        let now = k as f64 * 0.004;
        snapshots.push((now, robot.actual()));
        if k % 10 == 0 && k >= 3 {
            let (t, a) = snapshots[k - 3];
            seq += 1;
            latest = Some(measurement(&he, &a, t, seq));
        }
        let before = law.total();
        let out = law.cycle(now, Some(robot.rsol()), latest.as_ref());
        for i in 0..6 {
            let lim = if i < 3 {
                cfg.max_step_mm
            } else {
                cfg.max_step_deg
            };
            let clamp = if i < 3 { cfg.clamp_mm } else { cfg.clamp_deg };
            assert!(
                (out.total[i] - before[i]).abs() <= lim + 1e-12,
                "slew at cycle {k}"
            );
            assert!(out.total[i].abs() <= clamp + 1e-12, "clamp at cycle {k}");
        }
        robot.receive(&out.send);
    }
    let (dt, dr) = residual(&he, &robot);
    (dt, dr, law)
}

#[test]
fn hand_eye_round_trip() {
    let he = hand_eye();
    let tcp = pose_to_isometry(&NOMINAL);
    let back = he.tcp_in_base(&he.camera_in_plate(&tcp));
    assert!((back.translation.vector - tcp.translation.vector).norm() < 1e-9);
    assert!(back.rotation.angle_to(&tcp.rotation) < 1e-12);
}

#[test]
fn corrections_apply_and_remove() {
    let p = pose_to_isometry(&NOMINAL);
    let c = [1.0, -2.0, 0.5, 0.3, -0.2, 0.1];
    for frame in [CorrFrame::Base, CorrFrame::Tool] {
        let q = remove_correction(&apply_correction(&p, &c, frame), &c, frame);
        assert!((q.translation.vector - p.translation.vector).norm() < 1e-9);
        assert!(q.rotation.angle_to(&p.rotation) < 1e-12);
        // The error of a slightly corrected pose is minus the correction.
        let small = [0.01, -0.02, 0.005, 0.001, -0.002, 0.0015];
        let e = pose_error(&p, &apply_correction(&p, &small, frame), frame);
        for i in 0..6 {
            assert!((e[i] + small[i]).abs() < 1e-6, "{frame:?} {i}: {e:?}");
        }
    }
}

#[test]
fn pose_conversions_round_trip() {
    let p = [1.0, 2.0, 3.0, 170.0, -40.0, 20.0];
    let q = isometry_to_pose(&pose_to_isometry(&p));
    for i in 0..6 {
        assert!((p[i] - q[i]).abs() < 1e-9);
    }
    let v = pose_to_isometry(&p).translation.vector;
    assert_eq!(v, Vector3::new(1.0, 2.0, 3.0));
}

#[test]
fn converges_in_every_mode_and_frame() {
    // The total lives on the printed grid: the loop settles within a unit
    // or two of it (an integrator on a grid has that dead band).
    for (decimals, tol_mm, tol_deg) in [(6, 1e-4, 1e-5), (4, 4e-4, 4e-4)] {
        for mode in [CorrectionMode::Relative, CorrectionMode::Absolute] {
            for frame in [CorrFrame::Base, CorrFrame::Tool] {
                for includes in [false, true] {
                    let cfg = LawConfig {
                        mode,
                        frame,
                        rsol_includes_correction: includes,
                        decimals,
                        ..LawConfig::default()
                    };
                    let (dt, dr, law) = run_loop(cfg, includes, 1500);
                    assert!(
                        dt < tol_mm && dr < tol_deg,
                        "{decimals} {mode:?} {frame:?} {includes}: {dt} mm {dr}°, total {:?}",
                        law.total()
                    );
                }
            }
        }
    }
}

#[test]
fn wrong_rsol_assumption_does_not_converge() {
    // The law's rsol_includes_correction must match the controller: the
    // mismatched pairing chases its own correction (the test of the test).
    let cfg = LawConfig {
        rsol_includes_correction: false,
        ..LawConfig::default()
    };
    let (dt, _, _) = run_loop(cfg, true, 1500);
    assert!(dt > 1e-3, "{dt}");
}

#[test]
fn clamp_holds_the_total() {
    let cfg = LawConfig {
        clamp_mm: 0.4,
        clamp_deg: 0.01,
        ..LawConfig::default()
    };
    let (dt, _, law) = run_loop(cfg, false, 1500);
    assert!(dt > 0.3, "{dt}");
    let t = law.total();
    assert!(
        (t[0] + 0.4).abs() < 1e-12 && (t[1] - 0.4).abs() < 1e-12,
        "{t:?}"
    );
}

#[test]
fn stale_freezes_and_resume_does_not_jump() {
    for mode in [CorrectionMode::Relative, CorrectionMode::Absolute] {
        let cfg = LawConfig {
            mode,
            ..LawConfig::default()
        };
        let he = hand_eye();
        let mut law = CorrectionLaw::new(cfg, he);
        let actual = pose_to_isometry(&[446.0, 10.0, 790.0, 170.0, 5.0, 175.0]);
        let m = measurement(&he, &actual, 0.0, 1);
        let mut last = [0.0; 6];
        for k in 0..10 {
            let out = law.cycle(k as f64 * 0.004, Some(NOMINAL), Some(&m));
            assert_eq!(out.status, LawStatus::Tracking);
            last = out.total;
        }
        assert!((last[0] + 0.5).abs() < 1e-12, "{last:?}");
        // 0.2 s later the same measurement is too old: frozen.
        let out = law.cycle(0.21, Some(NOMINAL), Some(&m));
        assert_eq!(out.status, LawStatus::Stale(StaleReason::TooOld));
        assert_eq!(out.total, last);
        match mode {
            CorrectionMode::Absolute => assert_eq!(out.send, last),
            CorrectionMode::Relative => assert_eq!(out.send, [0.0; 6]),
        }
        // Resumes from where it stood, one slew step at most.
        let m2 = measurement(&he, &actual, 0.3, 2);
        let out = law.cycle(0.3, Some(NOMINAL), Some(&m2));
        assert_eq!(out.status, LawStatus::Tracking);
        assert!((out.total[0] - last[0]).abs() <= cfg.max_step_mm + 1e-12);
    }
}

#[test]
fn quality_gates() {
    let cfg = LawConfig::default();
    let he = hand_eye();
    let mut law = CorrectionLaw::new(cfg, he);
    let good = measurement(&he, &pose_to_isometry(&NOMINAL), 0.0, 1);
    let out = law.cycle(0.0, Some(NOMINAL), None);
    assert_eq!(out.status, LawStatus::Stale(StaleReason::NoMeasurement));
    let few = Measurement {
        n_targets: 3,
        ..good
    };
    assert_eq!(
        law.cycle(0.0, Some(NOMINAL), Some(&few)).status,
        LawStatus::Stale(StaleReason::TooFewTargets)
    );
    let vague = Measurement {
        std_deg: 0.5,
        ..good
    };
    assert_eq!(
        law.cycle(0.0, Some(NOMINAL), Some(&vague)).status,
        LawStatus::Stale(StaleReason::TooUncertain)
    );
    assert_eq!(
        law.cycle(0.0, None, Some(&good)).status,
        LawStatus::Stale(StaleReason::NoCommand)
    );
    assert_eq!(
        law.cycle(0.0, Some(NOMINAL), Some(&good)).status,
        LawStatus::Tracking
    );
    for code in 0..8 {
        assert_eq!(LawStatus::from_code(code).unwrap().code(), code);
    }
}

#[test]
fn measure_only_sends_zero_but_reports_the_error() {
    let cfg = LawConfig {
        measure_only: true,
        mode: CorrectionMode::Absolute,
        ..LawConfig::default()
    };
    let he = hand_eye();
    let mut law = CorrectionLaw::new(cfg, he);
    let m = measurement(
        &he,
        &pose_to_isometry(&[447.0, 10.0, 790.0, 170.0, 5.0, 175.0]),
        0.0,
        1,
    );
    let out = law.cycle(0.0, Some(NOMINAL), Some(&m));
    assert_eq!(out.status, LawStatus::MeasureOnly);
    assert_eq!(out.send, [0.0; 6]);
    assert!((out.error.unwrap()[0] + 2.0).abs() < 1e-9);
}

#[test]
fn a_huge_hand_eye_freezes_and_never_enters_the_total() {
    // Finite translations of 1.7e308 mm compose to a non-finite error.
    let huge = HandEye {
        tcp_from_camera: pose_to_isometry(&[1.7e308, -1.7e308, 1.7e308, 90.0, 10.0, 0.0]),
        base_from_plate: pose_to_isometry(&[-1.7e308, 1.7e308, 1.7e308, 30.0, 0.0, 0.0]),
    };
    let he = hand_eye();
    for mode in [CorrectionMode::Relative, CorrectionMode::Absolute] {
        let cfg = LawConfig {
            mode,
            ..LawConfig::default()
        };
        let mut law = CorrectionLaw::new(cfg, huge);
        let m = measurement(&he, &pose_to_isometry(&NOMINAL), 0.0, 1);
        for k in 0..5 {
            let out = law.cycle(k as f64 * 0.004, Some(NOMINAL), Some(&m));
            assert!(
                out.error.unwrap().iter().any(|v| !v.is_finite()),
                "{:?}",
                out.error
            );
            assert_eq!(out.status, LawStatus::FrozenInvalid);
            assert_eq!(out.send, [0.0; 6]);
            assert_eq!(out.total, [0.0; 6]);
            assert!(law.admissible(&out.send));
        }
        assert_eq!(LawStatus::FrozenInvalid.name(), "frozen_invalid");
    }
    // A good hand-eye: an implausible measurement freezes, a good one then
    // tracks from the unchanged total.
    let mut law = CorrectionLaw::new(LawConfig::default(), he);
    let good = measurement(
        &he,
        &pose_to_isometry(&[446.0, 10.0, 790.0, 170.0, 5.0, 175.0]),
        0.0,
        1,
    );
    for k in 0..3 {
        law.cycle(k as f64 * 0.004, Some(NOMINAL), Some(&good));
    }
    let held = law.total();
    let far = measurement(
        &he,
        &pose_to_isometry(&[1e6, 10.0, 790.0, 170.0, 5.0, 175.0]),
        0.02,
        2,
    );
    let out = law.cycle(0.02, Some(NOMINAL), Some(&far));
    assert_eq!(out.status, LawStatus::FrozenInvalid);
    assert_eq!(law.total(), held);
    let good2 = Measurement {
        seq: 3,
        time_s: 0.024,
        ..good
    };
    let out = law.cycle(0.024, Some(NOMINAL), Some(&good2));
    assert_eq!(out.status, LawStatus::Tracking);
    assert!(out.total.iter().all(|v| v.is_finite()));
}

#[test]
fn relative_increments_carry_the_rounding_remainder() {
    // A slew limit of 0.00337° per cycle is not a whole number of printed
    // digits: rounding each increment on its own would add up to 2.0178°.
    let cfg = LawConfig {
        max_step_deg: 0.00337,
        clamp_deg: 2.0,
        max_age_s: 60.0,
        ..LawConfig::default()
    };
    let he = hand_eye();
    let mut law = CorrectionLaw::new(cfg, he);
    let turned = measurement(
        &he,
        &pose_to_isometry(&[445.0, 10.0, 790.0, 180.0, 5.0, 175.0]),
        0.0,
        1,
    );
    let mut sum = 0i64;
    for k in 0..1000 {
        let out = law.cycle(k as f64 * 0.004, Some(NOMINAL), Some(&turned));
        // What the controller receives: the printed increment.
        let printed: f64 = format!("{:.4}", out.send[3]).parse().unwrap();
        let units = (printed * 1e4).round() as i64;
        assert!(units.abs() <= 33, "cycle {k}: {units}");
        sum += units;
        assert!(sum.abs() <= 20_000, "cycle {k}: {sum}");
        assert_eq!(sum, (law.total()[3] * 1e4).round() as i64);
    }
    assert_eq!(sum, -20_000);
}
