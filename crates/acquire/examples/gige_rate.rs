//! Measures the GigE path end to end on loopback: the in-process fake
//! camera serving a fixed image → `GigeSource` → grabber thread → ring →
//! one worker. Prints delivered, missed and dropped frames and the rate.
//!
//! `cargo run -p photopose-acquire --example gige_rate --release -- [WIDTH HEIGHT FPS SECONDS]`
//! (defaults 1300 1030 50 5). Needs no external process; nothing else may
//! serve GigE Vision on 127.0.0.1 meanwhile. With `EXTERNAL=1`, it uses an
//! `arv-fake-gv-camera-0.8 -i 127.0.0.1` started beforehand instead (its
//! test pattern, ROI set to the size asked).

use photopose_acquire::fake::FakeGigeCamera;
use photopose_acquire::grabber::spawn_grabber;
use photopose_acquire::ring::{Overflow, Ring};
use photopose_acquire::{GigeConfig, GigeSource};
use photopose_frame::Image;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("numbers: WIDTH HEIGHT FPS SECONDS"))
        .collect();
    let arg = |i: usize, d: f64| args.get(i).copied().unwrap_or(d);
    let (w, h, fps, secs) = (
        arg(0, 1300.0) as u32,
        arg(1, 1030.0) as u32,
        arg(2, 50.0),
        arg(3, 5.0),
    );

    let external = std::env::var_os("EXTERNAL").is_some_and(|v| v == "1");
    let image = Image::new_mono8(w, h);
    let camera = (!external).then(|| FakeGigeCamera::start("RATE01", &image).expect("fake camera"));
    let config = GigeConfig {
        camera: Some(match &camera {
            Some(c) => c.serial().into(),
            None => "Aravis-Fake-GV01".into(),
        }),
        frame_rate: Some(fps),
        roi: external.then_some(photopose_acquire::Roi {
            x: 0,
            y: 0,
            width: w,
            height: h,
        }),
        ..GigeConfig::default()
    };
    let source = GigeSource::new("gv-rate", config).expect("config");
    let counters = source.counters();
    let (producer, consumer) = Ring::build(8, Overflow::DropOldest, || Image::new_mono8(w, h));
    let stop = Arc::new(AtomicBool::new(false));
    let grabber = spawn_grabber("grab-rate", source, producer, Arc::clone(&stop)).expect("thread");
    let worker = {
        let stop = Arc::clone(&stop);
        let consumer = consumer.clone();
        std::thread::spawn(move || {
            let mut n = 0u64;
            let mut gaps = 0u64;
            let mut last: Option<u64> = None;
            while !stop.load(Ordering::Acquire) {
                if let Ok(f) = consumer.recv_timeout(Duration::from_millis(100)) {
                    if let Some(l) = last {
                        gaps += f.meta.seq - l - 1;
                    }
                    last = Some(f.meta.seq);
                    n += 1;
                }
            }
            (n, gaps)
        })
    };
    let t = Instant::now();
    while counters.snapshot().frames == 0 {
        assert!(t.elapsed() < Duration::from_secs(15), "no frame");
        std::thread::sleep(Duration::from_millis(10));
    }
    let f0 = counters.snapshot().frames;
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(secs));
    let f1 = counters.snapshot().frames;
    let elapsed = t0.elapsed().as_secs_f64();
    stop.store(true, Ordering::Release);
    let _ = grabber.join();
    let (seen, gaps) = worker.join().expect("worker");
    let ring = consumer.counters().snapshot();
    println!(
        "{w}×{h} Mono8 at {fps} frames/s asked: {:.1} frames/s delivered over {elapsed:.1} s; \
         source {:?}; ring {ring:?}; worker saw {seen}, seq gaps {gaps}",
        (f1 - f0) as f64 / elapsed,
        counters.snapshot()
    );
}
