//! The closed loop over real UDP on loopback: the simulated KUKA controller
//! (4 ms, its own clock) ⇄ the RSI server; a camera thread renders a frame
//! at the robot's *actual* camera pose (photopose-render), locates it
//! (photopose-locate) and publishes the pose into the slot, as the daemon
//! does. The corrections must drive the TCP error below 0.05 mm and
//! 0.005°, never exceed the slew limit or the clamp, and every one of the
//! cycles must be answered in time.
//!
//! This is the crate's one long test: 10,000 cycles (40 s) by default;
//! `PHOTOPOSE_RSI_CYCLES=3000` shortens it. Timeliness depends on the
//! machine (a shared, loaded 2-core VM stalls even SCHED_FIFO threads), and
//! tests make no strict timing assertions: the default test runs the
//! controller without a Timeout and bounds late replies to 1 % (a server that
//! waited on vision would be late nearly every cycle); the strict version —
//! KUKA's default Timeout of 10 and zero late replies — is the ignored test
//! run by hand on a quiet machine:
//! `cargo test --release -p photopose-rsi --test closed_loop -- --ignored --nocapture`.

mod common;

use common::{cycles, exterior_of, hand_eye, nominal_tcp, settings};
use photopose_field::design::default_plate;
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_render::{RenderOptions, Renderer};
use photopose_rsi::controller::{SimConfig, SimController};
use photopose_rsi::law::CorrectionMode;
use photopose_rsi::server::{RsiClock, RsiServer};
use photopose_rsi::{latest_slot, Measurement};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[test]
fn closed_loop_with_rendered_frames_converges_within_the_limits() {
    closed_loop(false);
}

#[test]
#[ignore = "strict timing: run by hand on a quiet machine"]
fn closed_loop_strict_zero_late_replies() {
    closed_loop(true);
}

fn closed_loop(strict: bool) {
    let n_cycles = cycles(10_000);
    let he = hand_eye();
    let clock = RsiClock::new();
    let s = settings(|c| {
        c.mode = CorrectionMode::Relative;
        c.gain = 0.5;
        c.max_age_ms = 2000.0;
        c.max_std_mm = 0.5;
        c.max_std_deg = 0.05;
        c.realtime_priority = Some(50);
    });
    let law = s.law;
    let (mut publisher, reader) = latest_slot();
    let server = RsiServer::spawn(s.clone(), he, reader, clock).unwrap();
    let mut sim_cfg = SimConfig::new(server.local_addr());
    sim_cfg.cycles = n_cycles;
    sim_cfg.nominal = nominal_tcp(&he);
    sim_cfg.sen = s.sen.clone();
    sim_cfg.realtime_priority = Some(60);
    sim_cfg.timeout = if strict { 10 } else { u64::MAX };
    let sim = SimController::spawn(sim_cfg, clock).unwrap();

    // The camera: render at the actual pose, locate, publish.
    let done = Arc::new(AtomicBool::new(false));
    let camera_thread = {
        let (sim, done) = (sim.probe(), done.clone());
        std::thread::spawn(move || {
            let cam = photopose_formats::default_camera();
            let field = default_plate();
            let mut renderer = Renderer::new(cam, &field, RenderOptions::default()).unwrap();
            let mut locator = Locator::new(cam, field.clone(), LocateOptions::default()).unwrap();
            let mut image = renderer.new_image();
            let (mut frames, mut failed, mut seconds) = (0u64, 0u64, 0.0);
            while !done.load(Ordering::Relaxed) && !sim.is_finished() {
                let state = sim.state();
                let t0 = std::time::Instant::now();
                renderer
                    .set_options(RenderOptions {
                        noise_dn: 2.0,
                        blur_px: 0.6,
                        seed: frames + 1,
                        ..RenderOptions::default()
                    })
                    .unwrap();
                renderer
                    .render(&exterior_of(&he, &state.actual), &mut image)
                    .unwrap();
                let loc = locator.locate(image.view()).unwrap();
                frames += 1;
                match (loc.status, loc.pose) {
                    (PoseStatus::Ok, Some(report)) => {
                        publisher.publish(&Measurement::from_report(report, state.time_s, frames));
                    }
                    _ => failed += 1,
                }
                seconds += t0.elapsed().as_secs_f64();
            }
            (frames, failed, seconds)
        })
    };
    let report = sim.join().unwrap();
    done.store(true, Ordering::Relaxed);
    let (frames, failed, seconds) = camera_thread.join().unwrap();
    let stats = server.stop();

    let n = report.errors.len();
    let tail = &report.errors[n * 3 / 4..];
    let max_t = tail.iter().map(|e| e.0).fold(0.0, f64::max);
    let max_r = tail.iter().map(|e| e.1).fold(0.0, f64::max);
    let converged_at = report
        .errors
        .iter()
        .rposition(|e| e.0 >= 0.05 || e.1 >= 0.005)
        .map_or(0, |k| k + 1);
    eprintln!(
        "closed loop: {} cycles ({} skipped by the simulator), {} late, {} mismatched; {frames} frames ({failed} failed, {:.0} ms each); \
         initial error {:.3} mm {:.4}°, last quarter max {max_t:.4} mm {max_r:.5}°, below 0.05 mm / 0.005° for good from cycle {converged_at}; \
         max step {:?}, max total {:?}; latency p50 {:?} p99 {:?} p99.9 {:?} µs",
        report.cycles,
        report.skipped,
        report.late,
        report.mismatched,
        1e3 * seconds / frames.max(1) as f64,
        report.errors[0].0,
        report.errors[0].1,
        report.max_step,
        report.max_total,
        stats.latency_p50_us,
        stats.latency_p99_us,
        stats.latency_p999_us,
    );
    assert!(
        !report.stopped_by_timeout,
        "the controller stopped: {report:?}"
    );
    assert_eq!(report.cycles + report.skipped, n_cycles);
    if strict {
        assert_eq!(
            report.late, 0,
            "late replies at cycles {:?}",
            report.late_cycles
        );
        assert_eq!(report.mismatched, 0, "mismatched replies");
    } else {
        assert!(
            report.late * 100 <= report.cycles,
            "{} late of {}",
            report.late,
            report.cycles
        );
    }
    assert!(
        frames > 10 && failed == 0,
        "{frames} frames, {failed} failed"
    );
    assert!(
        max_t < 0.05 && max_r < 0.005,
        "residual {max_t} mm {max_r}°"
    );
    assert!(converged_at < n * 3 / 4);
    // Slew limit and clamp (replies carry 4 decimals: the rounding of one
    // value is allowed).
    assert_eq!(report.limits_broken(&law), None);
    assert_eq!(stats.garbage + stats.unlisted, 0);
}
