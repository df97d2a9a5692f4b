//! Reply latency of the RSI server (datagram received → reply sent) over
//! many cycles, against the simulated controller on loopback, optionally
//! while other threads run `locate()` on rendered frames at full speed and
//! publish into the slot (an approximation of the daemon's vision pipeline).
//!
//!     cargo run --release -p photopose-rsi --example rsi_latency -- \
//!         [--cycles 100000] [--cycle-us 4000] [--load-threads 1] [--rt]
//!
//! Prints p50 / p99 / p99.9 / max of the reply latency, the inter-arrival
//! times, the controller's late and mismatched counts and the frame rate of
//! the load.

use photopose_field::design::default_plate;
use photopose_geometry::Exterior;
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_render::{RenderOptions, Renderer};
use photopose_rsi::controller::{SimConfig, SimController};
use photopose_rsi::law::{isometry_to_pose, pose_to_isometry};
use photopose_rsi::server::{RsiClock, RsiServer};
use photopose_rsi::{latest_slot, HandEye, Measurement, RsiConfig};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

struct Args {
    cycles: u64,
    cycle_us: u64,
    load_threads: usize,
    rt: bool,
}

fn args() -> Args {
    let mut a = Args {
        cycles: 100_000,
        cycle_us: 4000,
        load_threads: 1,
        rt: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut num = |name: &str| -> u64 {
            it.next()
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{name} needs a number"))
        };
        match k.as_str() {
            "--cycles" => a.cycles = num("--cycles"),
            "--cycle-us" => a.cycle_us = num("--cycle-us"),
            "--load-threads" => a.load_threads = num("--load-threads") as usize,
            "--rt" => a.rt = true,
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

fn main() {
    let a = args();
    let he = HandEye {
        tcp_from_camera: pose_to_isometry(&[10.0, 60.0, 120.0, 90.0, 2.0, -1.0]),
        base_from_plate: pose_to_isometry(&[1400.0, -250.0, -400.0, 30.0, 0.0, 0.0]),
    };
    let cam_pose = Exterior::look_at(
        nalgebra::Vector3::new(60.0, -40.0, 800.0),
        nalgebra::Vector3::zeros(),
        nalgebra::Vector3::new(0.0, 1.0, 0.0),
    )
    .expect("camera pose");
    let nominal =
        isometry_to_pose(&he.tcp_in_base(&photopose_geometry::pose::camera_pose(&cam_pose)));

    // Frames for the load, rendered before the clock starts.
    let cam = photopose_formats::default_camera();
    let field = default_plate();
    let mut renderer = Renderer::new(cam, &field, RenderOptions::default()).expect("renderer");
    let mut frames = Vec::new();
    for k in 0..4u64 {
        let d = k as f64;
        let e = Exterior::look_at(
            nalgebra::Vector3::new(60.0 + 5.0 * d, -40.0, 800.0 - 10.0 * d),
            nalgebra::Vector3::zeros(),
            nalgebra::Vector3::new(0.0, 1.0, 0.0),
        )
        .expect("pose");
        renderer
            .set_options(RenderOptions {
                seed: k + 1,
                noise_dn: 2.0,
                ..RenderOptions::default()
            })
            .expect("options");
        let mut img = renderer.new_image();
        renderer.render(&e, &mut img).expect("render");
        frames.push(img);
    }
    let frames = Arc::new(frames);

    let clock = RsiClock::new();
    let mut cfg = RsiConfig {
        enabled: true,
        bind: "127.0.0.1".into(),
        port: Some(1),
        controllers: vec!["127.0.0.1".into()],
        max_age_ms: 1000.0,
        ..RsiConfig::default()
    };
    if a.rt {
        cfg.realtime_priority = Some(80);
    }
    let mut settings = cfg.settings(None).expect("settings");
    settings.bind.set_port(0);
    let (publisher, reader) = latest_slot();
    let publisher = Arc::new(Mutex::new(publisher));
    let server = RsiServer::spawn(settings.clone(), he, reader, clock).expect("server");

    let stop = Arc::new(AtomicBool::new(false));
    let located = Arc::new(AtomicU64::new(0));
    let load: Vec<_> = (0..a.load_threads)
        .map(|t| {
            let (frames, stop, located, publisher) = (
                frames.clone(),
                stop.clone(),
                located.clone(),
                publisher.clone(),
            );
            std::thread::spawn(move || {
                let mut locator =
                    Locator::new(cam, default_plate(), LocateOptions::default()).expect("locator");
                let mut k = t;
                while !stop.load(Ordering::Relaxed) {
                    let img = &frames[k % frames.len()];
                    k += 1;
                    let loc = locator.locate(img.view()).expect("locate");
                    if let (PoseStatus::Ok, Some(r)) = (loc.status, loc.pose) {
                        let n = located.fetch_add(1, Ordering::Relaxed) + 1;
                        let m = Measurement::from_report(r, clock.now_s(), n);
                        // The slot has one publisher; the pipeline's ordered
                        // output would be that one thread.
                        if let Ok(mut p) = publisher.lock() {
                            p.publish(&m);
                        }
                    }
                }
            })
        })
        .collect();

    let mut sim_cfg = SimConfig::new(server.local_addr());
    sim_cfg.cycles = a.cycles;
    sim_cfg.cycle = Duration::from_micros(a.cycle_us);
    sim_cfg.nominal = nominal;
    sim_cfg.timeout = u64::MAX;
    if a.rt {
        sim_cfg.realtime_priority = Some(90);
    }
    eprintln!(
        "{} cycles of {} µs, {} locate() load thread(s), real-time {}: about {:.0} s",
        a.cycles,
        a.cycle_us,
        a.load_threads,
        a.rt,
        a.cycles as f64 * a.cycle_us as f64 * 1e-6
    );
    let t0 = Instant::now();
    let sim = SimController::spawn(sim_cfg, clock).expect("controller");
    let report = sim.join().expect("controller run");
    let elapsed = t0.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    for h in load {
        let _ = h.join();
    }
    let st = server.stop();
    let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.0}"));
    println!(
        "reply latency (received → sent) over {} replies: p50 {} µs, p99 {} µs, p99.9 {} µs, max {:.0} µs",
        st.replies,
        f(st.latency_p50_us),
        f(st.latency_p99_us),
        f(st.latency_p999_us),
        st.latency_max_us
    );
    println!(
        "inter-arrival: p50 {} µs, p99.9 {} µs, max {:.0} µs; drained {}, IPOC irregular {}",
        f(st.interarrival_p50_us),
        f(st.interarrival_p999_us),
        st.interarrival_max_us,
        st.drained,
        st.ipoc_irregular
    );
    println!(
        "controller: {} cycles sent, {} slots skipped by the simulator itself, {} late, {} mismatched",
        report.cycles, report.skipped, report.late, report.mismatched
    );
    println!(
        "load: {} frames located in {:.1} s ({:.1} frames/s)",
        located.load(Ordering::Relaxed),
        elapsed,
        located.load(Ordering::Relaxed) as f64 / elapsed
    );
}
