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
    for code in 0..10 {
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

/// A robot moving along a programmed path (40 mm/s along X and 2°/s about
/// Z) with a fixed path error, sampled by the controller 1 ms before each
/// datagram arrives; the camera's frames are exposed between cycles at
/// irregular instants and published 15–25 ms later. Comparing each frame
/// with the programmed pose *at its exposure* (interpolated), the loop
/// settles on the path; the nearest earlier cycle's pose at its arrival
/// would be 1–5 ms behind the exposure (0.04–0.2 mm at 40 mm/s) and leave
/// that much error.
#[test]
fn a_moving_robot_settles_on_the_path_with_the_pose_at_the_exposure() {
    const V_MM_S: f64 = 40.0;
    const W_DEG_S: f64 = 2.0;
    let programmed = |t: f64| -> Pose6 {
        [
            NOMINAL[0] + V_MM_S * t,
            NOMINAL[1],
            NOMINAL[2],
            NOMINAL[3] + W_DEG_S * t,
            NOMINAL[4],
            NOMINAL[5],
        ]
    };
    for mode in [CorrectionMode::Relative, CorrectionMode::Absolute] {
        let cfg = LawConfig {
            mode,
            decimals: 6,
            ..LawConfig::default()
        };
        let latency = cfg.controller_latency_s;
        let he = hand_eye();
        let mut law = CorrectionLaw::new(cfg, he);
        // (sample instant, total applied from then on).
        let mut applied: Vec<(f64, Pose6)> = Vec::new();
        let mut total = [0.0; 6];
        let actual_at = |t: f64, applied: &[(f64, Pose6)]| -> Isometry3<f64> {
            let c = applied
                .iter()
                .rev()
                .find(|(s, _)| *s <= t)
                .map_or([0.0; 6], |(_, c)| *c);
            let commanded = apply_correction(&pose_to_isometry(&programmed(t)), &c, cfg.frame);
            apply_correction(&commanded, &ERROR, CorrFrame::Base)
        };
        let mut latest: Option<Measurement> = None;
        let mut pending: Vec<Measurement> = Vec::new();
        let mut seq = 0;
        let mut last_residual = f64::INFINITY;
        for k in 0..3000usize {
            let arrival = 1.0 + k as f64 * 0.004;
            let sample = arrival - latency;
            applied.push((sample, total));
            // A frame every 10 cycles, exposed at an irregular instant
            // between two samples, published 15–25 ms later.
            if k % 10 == 0 && k > 20 {
                let t_e = sample - 0.0123 - 0.000_37 * (k % 11) as f64;
                seq += 1;
                let mut m = measurement(&he, &actual_at(t_e, &applied), t_e, seq);
                m.time_s = t_e;
                pending.push(m);
            }
            if let Some(i) = pending.iter().position(|m| m.time_s + 0.02 <= arrival) {
                latest = Some(pending.remove(i));
            }
            let out = law.cycle(arrival, Some(programmed(sample)), latest.as_ref());
            assert!(
                matches!(
                    out.status,
                    LawStatus::Tracking | LawStatus::Stale(StaleReason::NoMeasurement)
                ),
                "cycle {k}: {:?}",
                out.status
            );
            for i in 0..6 {
                match mode {
                    CorrectionMode::Relative => total[i] += out.send[i],
                    CorrectionMode::Absolute => total[i] = out.send[i],
                }
            }
            if k > 2500 {
                let a = actual_at(arrival, &applied);
                let p = pose_to_isometry(&programmed(arrival));
                last_residual = (a.translation.vector - p.translation.vector).norm();
                assert!(
                    last_residual < 2e-3,
                    "{mode:?} cycle {k}: {last_residual} mm"
                );
                assert!(a.rotation.angle_to(&p.rotation).to_degrees() < 2e-4);
            }
        }
        assert!(last_residual.is_finite());
    }
}

#[test]
fn exposures_outside_the_history_are_stale_with_their_own_reasons() {
    let cfg = LawConfig::default();
    let he = hand_eye();
    let mut law = CorrectionLaw::new(cfg, he);
    let at_nominal = pose_to_isometry(&NOMINAL);
    // The session starts at 10 s (sampled at 9.999 s); a frame exposed
    // more than a cycle before is older than the history.
    let early = measurement(&he, &at_nominal, 9.994, 1);
    let out = law.cycle(10.0, Some(NOMINAL), Some(&early));
    assert_eq!(out.status, LawStatus::Stale(StaleReason::BeforeHistory));
    assert_eq!(out.status.name(), "stale_before_history");
    // A frame exposed 9.5 ms after the newest sample (more than a cycle):
    // not yet; tracked as soon as the cycles reach it.
    let ahead = measurement(&he, &at_nominal, 10.0125, 2);
    let out = law.cycle(10.004, Some(NOMINAL), Some(&ahead));
    assert_eq!(out.status, LawStatus::Stale(StaleReason::AheadOfHistory));
    assert_eq!(out.status.name(), "stale_ahead_of_history");
    let out = law.cycle(10.008, Some(NOMINAL), Some(&ahead));
    assert_eq!(out.status, LawStatus::Stale(StaleReason::AheadOfHistory));
    let out = law.cycle(10.012, Some(NOMINAL), Some(&ahead));
    assert_eq!(out.status, LawStatus::Tracking);
    assert!(out.commanded.is_some());
    // A frame older than the history holds (its cycles overwritten).
    let cap = law.history_capacity();
    for k in 0..cap + 5 {
        law.cycle(10.016 + k as f64 * 0.004, Some(NOMINAL), None);
    }
    let newest = law.past(0).unwrap().time_s;
    assert!((newest - (10.016 + (cap + 4) as f64 * 0.004 - 0.001)).abs() < 1e-9);
    assert!(law.past(cap).is_none());
    let cfg_long = LawConfig {
        max_age_s: 300.0,
        ..cfg
    };
    let mut law = CorrectionLaw::new(cfg_long, he);
    assert_eq!(law.history_capacity(), HISTORY_MAX);
    for k in 0..HISTORY_MAX + 10 {
        law.cycle(k as f64 * 0.004, Some(NOMINAL), None);
    }
    let old = measurement(&he, &at_nominal, 0.02, 3);
    let out = law.cycle((HISTORY_MAX + 10) as f64 * 0.004, Some(NOMINAL), Some(&old));
    assert_eq!(out.status, LawStatus::Stale(StaleReason::BeforeHistory));
}

#[test]
fn the_history_covers_max_age() {
    for (age, cycle) in [(0.2, 0.004), (0.2, 0.012), (2.0, 0.004), (0.01, 0.004)] {
        let cfg = LawConfig {
            max_age_s: age,
            cycle_s: cycle,
            ..LawConfig::default()
        };
        let n = history_len(&cfg);
        assert!(n as f64 * cycle >= age + cycle, "{age} {cycle}: {n}");
        assert!(n >= HISTORY_MIN);
    }
}

#[test]
fn a_frame_just_after_the_newest_cycle_carries_the_motion_on() {
    let cfg = LawConfig {
        measure_only: true,
        ..LawConfig::default()
    };
    let he = hand_eye();
    let mut law = CorrectionLaw::new(cfg, he);
    let at = |x: f64| [x, 10.0, 790.0, 170.0, 5.0, 175.0];
    law.cycle(1.000, Some(at(100.0)), None);
    // Samples at 0.999 and 1.003 (x 100 → 101.6); a frame at 1.005.
    let m = measurement(&he, &pose_to_isometry(&at(102.4)), 1.005, 1);
    let out = law.cycle(1.004, Some(at(101.6)), Some(&m));
    let c = out.commanded.unwrap();
    assert!((c[0] - 102.4).abs() < 1e-9, "{c:?}");
    assert!(out.error.unwrap()[0].abs() < 1e-9);
    assert_eq!(out.commanded_ipoc, Some((0, 0)));
}

#[test]
fn feed_forward_predicts_a_changing_error_and_is_off_by_default() {
    // The path error grows at 10 mm/s along X; each frame is 30 ms old at
    // its cycle. With feed-forward (gain 1) the target is the error
    // predicted at this cycle's sample; without it, the error of 30 ms ago.
    assert!(!LawConfig::default().feed_forward);
    for ff in [false, true] {
        let cfg = LawConfig {
            gain: 1.0,
            feed_forward: ff,
            max_step_mm: 10.0,
            decimals: 6,
            ..LawConfig::default()
        };
        let he = hand_eye();
        let mut law = CorrectionLaw::new(cfg, he);
        let mut applied: Vec<(f64, Pose6)> = Vec::new();
        let mut total = [0.0; 6];
        let actual_at = |t: f64, applied: &[(f64, Pose6)]| {
            let c = applied
                .iter()
                .rev()
                .find(|(s, _)| *s <= t)
                .map_or([0.0; 6], |(_, c)| *c);
            let p = pose_to_isometry(&[
                NOMINAL[0] + 10.0 * t + c[0],
                NOMINAL[1],
                NOMINAL[2],
                NOMINAL[3],
                NOMINAL[4],
                NOMINAL[5],
            ]);
            he.camera_in_plate(&p)
        };
        let mut seq = 0;
        let mut last = None;
        for k in 0..=15usize {
            let arrival = 0.1 + k as f64 * 0.004;
            let sample = arrival - cfg.controller_latency_s;
            applied.push((sample, total));
            let mut latest = None;
            if k == 10 || k == 15 {
                let t_e = sample - 0.03;
                seq += 1;
                latest = Some(Measurement {
                    plate_from_camera: actual_at(t_e, &applied),
                    std_mm: 0.01,
                    std_deg: 0.001,
                    n_targets: 40,
                    time_s: t_e,
                    seq,
                });
            }
            let out = law.cycle(arrival, Some(NOMINAL), latest.as_ref());
            total = out.total;
            last = Some((sample, out.total[0]));
        }
        let (sample, x) = last.unwrap();
        let expect = if ff {
            -10.0 * sample
        } else {
            -10.0 * (sample - 0.03)
        };
        assert!((x - expect).abs() < 1e-5, "ff {ff}: {x} vs {expect}");
    }
}

mod props {
    //! The property of the law's time base: the commanded pose a
    //! measurement is compared with is the interpolation at its exposure
    //! instant between the two cycles sampled around it — never another
    //! cycle's pose.
    use super::*;
    use nalgebra::UnitQuaternion;
    use proptest::prelude::*;

    fn pose() -> impl Strategy<Value = Pose6> {
        (
            -800.0..800.0f64,
            -800.0..800.0f64,
            0.0..1500.0f64,
            -180.0..180.0f64,
            -80.0..80.0f64,
            -180.0..180.0f64,
        )
            .prop_map(|(x, y, z, a, b, c)| [x, y, z, a, b, c])
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        #[test]
        fn the_commanded_pose_is_the_interpolation_at_the_exposure(
            cycles in proptest::collection::vec((pose(), 0.003..0.005f64), 2..40),
            latency in 0.0..0.003f64,
            at in 0.0..1.0f64,
            includes in any::<bool>(),
        ) {
            let cfg = LawConfig {
                controller_latency_s: latency,
                rsol_includes_correction: includes,
                ..LawConfig::default()
            };
            let he = hand_eye();
            let mut law = CorrectionLaw::new(cfg, he);
            // The samples the test itself keeps: (instant, RSol).
            let mut samples: Vec<(f64, Pose6)> = Vec::new();
            let mut arrival = 50.0;
            for (rsol, dt) in &cycles[..cycles.len() - 1] {
                arrival += dt;
                samples.push((arrival - latency, *rsol));
                let out = law.cycle_at(arrival, samples.len() as u64, Some(*rsol), None);
                prop_assert_eq!(out.status, LawStatus::Stale(StaleReason::NoMeasurement));
                prop_assert_eq!(out.total, [0.0; 6]);
            }
            let (rsol, dt) = cycles[cycles.len() - 1];
            arrival += dt;
            samples.push((arrival - latency, rsol));
            // An exposure anywhere from the oldest sample to the newest.
            let (first, last) = (samples[0].0, samples[samples.len() - 1].0);
            let t_e = first + at * (last - first);
            let m = measurement(&he, &pose_to_isometry(&NOMINAL), t_e, 1);
            let out = law.cycle_at(arrival, samples.len() as u64, Some(rsol), Some(&m));
            prop_assert_eq!(out.status, LawStatus::Tracking);
            // The bracket, found independently of the law.
            let i = samples.iter().rposition(|(s, _)| *s <= t_e).unwrap();
            let j = (i + 1).min(samples.len() - 1);
            let (ta, a) = samples[i];
            let (tb, b) = samples[j];
            let f = if tb > ta { (t_e - ta) / (tb - ta) } else { 0.0 };
            let (pa, pb) = (pose_to_isometry(&a), pose_to_isometry(&b));
            let want_t = pa.translation.vector.lerp(&pb.translation.vector, f);
            let want_r: UnitQuaternion<f64> = pa.rotation.slerp(&pb.rotation, f);
            let got = pose_to_isometry(&out.commanded.unwrap());
            prop_assert!((got.translation.vector - want_t).norm() < 1e-6,
                "translation {:?} vs {:?} (f {})", got.translation.vector, want_t, f);
            prop_assert!(got.rotation.angle_to(&want_r) < 1e-9,
                "rotation off by {} rad (f {})", got.rotation.angle_to(&want_r), f);
            prop_assert_eq!(out.commanded_ipoc, Some((i as u64 + 1, j as u64 + 1)));
        }
    }
}

#[test]
fn without_latency_compensation_the_newest_cycle_is_compared() {
    // A robot moving along X at 40 mm/s, one cycle every 4 ms; a frame
    // exposed 15 ms before the newest sample.
    let programmed = |t: f64| -> Pose6 {
        let mut p = NOMINAL;
        p[0] += 40.0 * t;
        p
    };
    for compensate in [true, false] {
        let cfg = LawConfig {
            compensate_latency: compensate,
            measure_only: true,
            ..LawConfig::default()
        };
        let latency = cfg.controller_latency_s;
        let he = hand_eye();
        let mut law = CorrectionLaw::new(cfg, he);
        let mut out = None;
        for k in 0..20u64 {
            let arrival = 1.0 + k as f64 * 0.004;
            let sample = arrival - latency;
            let m = measurement(
                &he,
                &pose_to_isometry(&programmed(sample - 0.015)),
                sample - 0.015,
                1,
            );
            out = Some(law.cycle_at(
                arrival,
                k + 1,
                Some(programmed(sample)),
                (k == 19).then_some(&m),
            ));
        }
        let out = out.unwrap();
        let newest = 1.0 + 19.0 * 0.004 - latency;
        let want = if compensate { newest - 0.015 } else { newest };
        let got = out.commanded.unwrap();
        assert!(
            (got[0] - programmed(want)[0]).abs() < 1e-9,
            "{compensate}: {got:?}"
        );
        // Compensated: the measured TCP is on the path (no error); naive:
        // off by the 15 ms of travel, 0.6 mm.
        let e = out.error.unwrap();
        let want_e = if compensate { 0.0 } else { 0.6 };
        assert!((e[0].abs() - want_e).abs() < 1e-6, "{compensate}: {e:?}");
    }
}
