//! The GigE source against real GigE Vision peers on loopback: aravis'
//! `arv-fake-gv-camera-0.8` as a child process (streaming, loss and
//! reconnection), and the in-process fake camera serving a given image.
//!
//! Every peer answers on 127.0.0.1's GigE Vision port, so the scenarios run
//! one after the other inside a single test function, never concurrently.
//! A missing `arv-fake-gv-camera-0.8` fails the test (run `.ci/deps.sh`).

use photopose_acquire::exposure::SATURATED_PEAK;
use photopose_acquire::fake::FakeGigeCamera;
use photopose_acquire::grabber::{spawn_grabber, GrabberExit};
use photopose_acquire::ring::{Overflow, Ring};
use photopose_acquire::source::FrameSource;
use photopose_acquire::{ExposureSettings, GigeConfig, GigeSource, PixelDepth, Roi, Slot};
use photopose_frame::{FrameMeta, Image, Pixels};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const FAKE: &str = "arv-fake-gv-camera-0.8";
const TOOL: &str = "arv-tool-0.8";
/// The device id `arv-fake-gv-camera-0.8` serves.
const FAKE_ID: &str = "Aravis-Fake-GV01";
/// Its serial number.
const FAKE_SERIAL: &str = "GV01";

/// An `arv-fake-gv-camera-0.8 -i 127.0.0.1` child, killed on drop.
struct FakeProcess {
    child: Child,
}

fn missing_tool(bin: &str, e: &std::io::Error) -> ! {
    panic!(
        "cannot run `{bin}` ({e}): the GigE Vision tests need Debian's aravis-tools \
         and aravis-tools-cli; run .ci/deps.sh"
    )
}

impl FakeProcess {
    /// Starts the fake camera and waits until it answers GigE Vision
    /// control requests.
    fn start() -> Self {
        let child = Command::new(FAKE)
            .args(["-i", "127.0.0.1"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| missing_tool(FAKE, &e));
        let mut me = FakeProcess { child };
        let t0 = Instant::now();
        loop {
            if let Ok(Some(status)) = me.child.try_wait() {
                panic!(
                    "{FAKE} exited at once ({status}): is another GigE Vision peer on 127.0.0.1?"
                );
            }
            let out = Command::new(TOOL)
                .args(["-a", "127.0.0.1", "control", "Width"])
                .stdin(Stdio::null())
                .output()
                .unwrap_or_else(|e| missing_tool(TOOL, &e));
            if out.status.success() && String::from_utf8_lossy(&out.stdout).contains("Width") {
                return me;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "{FAKE} did not answer within 10 s"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for FakeProcess {
    fn drop(&mut self) {
        self.kill();
    }
}

fn init_tracing() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "photopose_acquire=info".into()),
        )
        .with_test_writer()
        .try_init();
}

fn wait_for(what: &str, limit: Duration, mut done: impl FnMut() -> bool) -> Duration {
    let t0 = Instant::now();
    while !done() {
        assert!(t0.elapsed() < limit, "{what}: not within {limit:?}");
        std::thread::sleep(Duration::from_millis(10));
    }
    t0.elapsed()
}

#[test]
fn gige_source_against_fake_cameras() {
    init_tracing();
    streams_without_loss();
    streams_mono16();
    stamps_exposure_instants();
    waits_for_an_absent_camera();
    survives_losing_the_camera();
    serves_given_images_in_process();
    steers_the_exposure_in_process();
    refuses_exposure_limits_the_camera_lacks();
}

/// Several seconds at 20 frames/s through the grabber into the ring, opened
/// by serial number: every frame after the first arrives.
fn streams_without_loss() {
    let _fake = FakeProcess::start();
    let rate = 20.0;
    let config = GigeConfig {
        camera: Some(FAKE_SERIAL.into()),
        frame_rate: Some(rate),
        roi: Some(Roi {
            x: 0,
            y: 0,
            width: 512,
            height: 512,
        }),
        exposure_us: Some(2000.0),
        gain: Some(1.0),
        ..GigeConfig::default()
    };
    let source = GigeSource::new("gv-stream", config).unwrap();
    let counters = source.counters();
    let (producer, consumer) = Ring::build(4, Overflow::DropOldest, || Image::new_mono8(512, 512));
    let stop = Arc::new(AtomicBool::new(false));
    let grabber = spawn_grabber("grab-stream", source, producer, Arc::clone(&stop)).unwrap();

    let worker = {
        let consumer = consumer.clone();
        let stop = Arc::clone(&stop);
        std::thread::Builder::new()
            .name("worker".into())
            .spawn(move || {
                let mut seqs = Vec::new();
                let mut stamps = Vec::new();
                while !stop.load(Ordering::Acquire) {
                    if let Ok(f) = consumer.recv_timeout(Duration::from_millis(100)) {
                        assert_eq!((f.image().width(), f.image().height()), (512, 512));
                        seqs.push(f.meta.seq);
                        stamps.push(f.meta.camera_time_ns);
                    }
                }
                (seqs, stamps)
            })
            .unwrap()
    };
    wait_for("first frame", Duration::from_secs(10), || {
        counters.snapshot().frames > 0
    });
    let t0 = Instant::now();
    let f0 = counters.snapshot().frames;
    std::thread::sleep(Duration::from_secs(5));
    let f1 = counters.snapshot().frames;
    let secs = t0.elapsed().as_secs_f64();
    stop.store(true, Ordering::Release);
    let (_source, exit) = grabber.join();
    assert!(matches!(exit, GrabberExit::Stopped), "{exit:?}");
    let (seqs, stamps) = worker.join().unwrap();

    let stats = counters.snapshot();
    let ring = consumer.counters().snapshot();
    let measured = (f1 - f0) as f64 / secs;
    eprintln!(
        "stream: {measured:.1} frames/s asked {rate}; source {stats:?}; ring {ring:?}; \
         worker saw {} frames",
        seqs.len()
    );
    assert!(
        measured > 0.85 * rate && measured < 1.15 * rate,
        "rate {measured:.1} frames/s, asked {rate}"
    );
    assert_eq!(stats.missing, 0, "frames missed after the first: {stats:?}");
    assert_eq!(stats.opens, 1);
    assert_eq!(stats.losses, 0);
    assert_eq!(ring.dropped, 0, "a worker keeps up with 20 frames/s");
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "gap in {seqs:?}");
    assert!(
        stamps.windows(2).all(|w| w[1] > w[0]),
        "camera timestamps increase"
    );
    assert_eq!(consumer.free_slots(), 4, "every slot back in the pool");
}

/// Mono16 on request: 16-bit frames, none missed.
fn streams_mono16() {
    let _fake = FakeProcess::start();
    let config = GigeConfig {
        camera: Some(FAKE_ID.into()),
        pixel: PixelDepth::Mono16,
        frame_rate: Some(20.0),
        ..GigeConfig::default()
    };
    let mut source = GigeSource::new("gv-mono16", config).unwrap();
    // A slot of the right size and depth: no reallocation.
    let mut slot = Slot::new(Image::new_mono16(512, 512, u16::MAX));
    let before = slot_ptr(&slot);
    source.start().unwrap();
    let mut got = 0;
    let t0 = Instant::now();
    while got < 20 {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "{:?}",
            source.stats()
        );
        match source.next_frame(&mut slot, Duration::from_millis(200)) {
            Ok(()) => {
                got += 1;
                assert!(matches!(slot.image().pixels(), Pixels::Mono16(_)));
                assert_eq!((slot.image().width(), slot.image().height()), (512, 512));
            }
            Err(e) => assert!(!e.is_fatal(), "{e}"),
        }
    }
    assert_eq!(
        slot_ptr(&slot),
        before,
        "frames copied into the caller's slot"
    );
    source.stop();
    let stats = source.stats();
    eprintln!("mono16: {stats:?}");
    assert_eq!(stats.missing, 0);
}

/// Every frame of the fake camera (its timestamps on its own clock) gets a
/// mid-exposure instant on the host's monotonic clock: increasing, before
/// its reception, behind it by about the modelled delay (half the 2 ms
/// exposure plus the 512×512 payload at 1 Gbit/s, 2.1 ms) within 20 ms, and
/// with the same shortest delay in both halves of the run within 5 ms (the
/// mapping tracks the host clock).
fn stamps_exposure_instants() {
    let _fake = FakeProcess::start();
    let config = GigeConfig {
        camera: Some(FAKE_ID.into()),
        frame_rate: Some(25.0),
        exposure_us: Some(2000.0),
        roi: Some(Roi {
            x: 0,
            y: 0,
            width: 512,
            height: 512,
        }),
        ..GigeConfig::default()
    };
    let mut source = GigeSource::new("gv-times", config).unwrap();
    let mut slot = Slot::new(Image::new_mono8(512, 512));
    source.start().unwrap();
    let mut metas = Vec::new();
    let t0 = Instant::now();
    while metas.len() < 60 {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "{:?}",
            source.stats()
        );
        match source.next_frame(&mut slot, Duration::from_millis(200)) {
            Ok(()) => metas.push(slot.meta),
            Err(e) => assert!(!e.is_fatal(), "{e}"),
        }
    }
    source.stop();
    let model_ns = 1_000_000 + 512 * 512 * 8;
    for (k, m) in metas.iter().enumerate() {
        assert!(
            m.camera_time_ns != 0 && m.host_mono_ns != 0,
            "frame {k}: {m:?}"
        );
        assert!(
            m.exposure_mono_ns != 0 && m.exposure_sigma_ns != 0,
            "frame {k}: {m:?}"
        );
        assert!(m.exposure_mono_ns < m.host_mono_ns, "frame {k}: {m:?}");
        assert!(m.exposure_utc_ns().is_some());
        let behind = m.host_mono_ns - m.exposure_mono_ns;
        assert!(
            behind >= model_ns && behind - model_ns < 20_000_000,
            "frame {k}: exposure {behind} ns before reception"
        );
        let exposure = m.exposure_ns;
        assert!(
            (1_000_000..=3_000_000).contains(&exposure),
            "exposure {exposure} ns"
        );
    }
    assert!(
        metas
            .windows(2)
            .all(|w| w[1].exposure_mono_ns > w[0].exposure_mono_ns),
        "mapped exposure instants increase"
    );
    // The mapping keeps to the host clock: the shortest delay from a mapped
    // exposure instant to its reception is the same in the run's first and
    // second halves. (A reception the scheduler holds back only lengthens
    // its own delay, which the shortest of each half leaves out: comparing
    // two single frames failed once on a loaded machine, 5.2 ms apart.)
    let shortest = |m: &[FrameMeta]| {
        m.iter()
            .map(|m| m.host_mono_ns - m.exposure_mono_ns)
            .min()
            .expect("frames")
    };
    let (first, second) = metas[10..].split_at(25);
    let (a, b) = (shortest(first) as f64, shortest(second) as f64);
    assert!(
        (a - b).abs() < 5e6,
        "shortest delays {a} ns and {b} ns in the two halves"
    );
}

fn slot_ptr(slot: &Slot) -> usize {
    match slot.image().pixels() {
        Pixels::Mono8(v) => v.as_ptr() as usize,
        Pixels::Mono16(v) => v.as_ptr() as usize,
    }
}

/// No camera at start: the grabber runs and reports it unavailable; the
/// camera appears; frames flow.
fn waits_for_an_absent_camera() {
    let config = GigeConfig {
        camera: Some(FAKE_ID.into()),
        frame_rate: Some(25.0),
        backoff_max: Duration::from_millis(500),
        ..GigeConfig::default()
    };
    let source = GigeSource::new("gv-absent", config).unwrap();
    let counters = source.counters();
    let (producer, consumer) = Ring::build(4, Overflow::DropNewest, || Image::new_mono8(512, 512));
    let stop = Arc::new(AtomicBool::new(false));
    let grabber = spawn_grabber("grab-absent", source, producer, Arc::clone(&stop)).unwrap();
    wait_for(
        "camera reported unavailable",
        Duration::from_secs(10),
        || grabber.counters().unavailable.get() > 0,
    );
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(counters.snapshot().frames, 0);
    assert!(!grabber.is_finished());
    let _fake = FakeProcess::start();
    let first = wait_for(
        "frames once the camera is there",
        Duration::from_secs(10),
        || consumer.try_recv().is_some(),
    );
    eprintln!(
        "absent at start: first frame {:.2} s after the camera answered; {:?}",
        first.as_secs_f64(),
        counters.snapshot()
    );
    stop.store(true, Ordering::Release);
    let (_source, exit) = grabber.join();
    assert!(matches!(exit, GrabberExit::Stopped), "{exit:?}");
}

/// Kills the camera mid-stream: the loss is reported, a new camera is
/// started, and frames flow again through the same source object.
fn survives_losing_the_camera() {
    let mut fake = FakeProcess::start();
    let config = GigeConfig {
        camera: Some(FAKE_ID.into()),
        frame_rate: Some(25.0),
        lost_after: Duration::from_secs(1),
        backoff_initial: Duration::from_millis(100),
        backoff_max: Duration::from_millis(800),
        ..GigeConfig::default()
    };
    let source = GigeSource::new("gv-lose", config).unwrap();
    let counters = source.counters();
    let (producer, consumer) = Ring::build(4, Overflow::DropOldest, || Image::new_mono8(512, 512));
    let stop = Arc::new(AtomicBool::new(false));
    let grabber = spawn_grabber("grab-lose", source, producer, Arc::clone(&stop)).unwrap();
    // Drain the ring like a worker would.
    let drain = {
        let consumer = consumer.clone();
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            let mut last = None;
            while !stop.load(Ordering::Acquire) {
                if let Ok(f) = consumer.recv_timeout(Duration::from_millis(50)) {
                    assert!(last.is_none_or(|l| f.meta.seq > l), "seq goes back");
                    last = Some(f.meta.seq);
                }
            }
        })
    };

    wait_for("frames before the loss", Duration::from_secs(10), || {
        counters.snapshot().frames >= 20
    });
    let before = counters.snapshot();
    fake.kill();
    let killed = Instant::now();
    let detect = wait_for("loss reported", Duration::from_secs(10), || {
        grabber.counters().losses.get() >= 1
    });
    assert!(!counters.snapshot().connected);
    // Absent for a while: the source keeps trying, the grabber keeps running.
    std::thread::sleep(Duration::from_secs(2));
    assert!(!grabber.is_finished());
    let absent = counters.snapshot();
    assert_eq!(absent.frames, before.frames.max(absent.frames));

    let _fake2 = FakeProcess::start();
    let restarted = Instant::now();
    let frames_at_restart = counters.snapshot().frames;
    let resume = wait_for("frames after the restart", Duration::from_secs(15), || {
        counters.snapshot().frames > frames_at_restart + 10
    });
    let after = counters.snapshot();
    eprintln!(
        "loss: detected {:.2} s after the kill; frames again {:.2} s after the new camera \
         answered (10 frames at 25/s included); {:.1} s kill to recovery; before {before:?}, after {after:?}",
        detect.as_secs_f64(),
        resume.as_secs_f64(),
        killed.elapsed().as_secs_f64() - restarted.elapsed().as_secs_f64() + resume.as_secs_f64(),
    );
    assert_eq!(after.losses, 1);
    assert!(after.opens >= 2);
    assert!(after.connected);
    stop.store(true, Ordering::Release);
    let t = Instant::now();
    let (_source, exit) = grabber.join();
    drain.join().unwrap();
    assert!(matches!(exit, GrabberExit::Stopped), "{exit:?}");
    eprintln!("loss: grabber joined in {:.2} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    drop(_source);
    eprintln!(
        "loss: source dropped in {:.2} s (waits for the dead camera's close)",
        t.elapsed().as_secs_f64()
    );
    let ring = consumer.counters().snapshot();
    assert_eq!(
        ring.frames_in,
        ring.delivered + ring.dropped + ring.queued()
    );
}

/// The in-process fake camera puts a given image on the real GigE stream.
fn serves_given_images_in_process() {
    let (w, h) = (320u32, 240u32);
    let pattern = |k: u32| {
        let px = (0..w * h).map(|i| ((i * 7 + k * 13) % 251) as u8).collect();
        Image::from_pixels(w, h, 255, Pixels::Mono8(px)).unwrap()
    };
    let first = pattern(1);
    let camera = FakeGigeCamera::start("PPTEST01", &first).unwrap();
    let config = GigeConfig {
        camera: Some(camera.serial().into()),
        frame_rate: Some(30.0),
        ..GigeConfig::default()
    };
    let mut source = GigeSource::new("gv-inproc", config).unwrap();
    let mut slot = Slot::new(Image::new_mono8(w, h));
    source.start().unwrap();

    let next = |source: &mut GigeSource, slot: &mut Slot| {
        let t0 = Instant::now();
        loop {
            match source.next_frame(slot, Duration::from_millis(200)) {
                Ok(()) => return,
                Err(e) if !e.is_fatal() && t0.elapsed() < Duration::from_secs(10) => {}
                Err(e) => panic!("no frame from the in-process camera: {e}"),
            }
        }
    };
    for _ in 0..10 {
        next(&mut source, &mut slot);
        assert_eq!(*slot.image(), first, "frame carries the given image");
    }
    let second = pattern(2);
    camera.set_image(&second).unwrap();
    let mut switched = false;
    for _ in 0..30 {
        next(&mut source, &mut slot);
        if *slot.image() == second {
            switched = true;
            break;
        }
        assert_eq!(*slot.image(), first);
    }
    assert!(switched, "the new image reaches the stream");
    for _ in 0..5 {
        next(&mut source, &mut slot);
        assert_eq!(*slot.image(), second);
    }
    source.stop();
    let stats = source.stats();
    // A 1.3 MB frame can be lost on a loaded loopback (UDP): it is counted
    // as missing, never delivered wrong; more than one is not load.
    assert!(stats.missing <= 1, "{stats:?}");
    drop(source);
    drop(camera);
}

/// The exposure control loop on a real GigE Vision peer (the in-process
/// camera, whose exposure feature is `ExposureTimeAbs`): the opening
/// brings the exposure inside the loop's limits; frames without a
/// measurement change nothing; peaks offered on the source's link, as a
/// detection worker offers them, steer the exposure down while the frames
/// read clipped and up while they read dim, one step at a time, never
/// outside the limits, and the frames carry the exposure in effect.
fn steers_the_exposure_in_process() {
    let image = Image::new_mono8(320, 240);
    let camera = FakeGigeCamera::start("PPEXPO01", &image).unwrap();
    let settings = ExposureSettings {
        min_us: 200.0,
        max_us: 3000.0,
        gain: 1.0,
        max_step_ratio: 2.0,
        every_frames: 1,
        ..ExposureSettings::default()
    };
    let config = GigeConfig {
        camera: Some(camera.serial().into()),
        frame_rate: Some(50.0),
        exposure_us: Some(5000.0),
        exposure_control: Some(settings),
        ..GigeConfig::default()
    };
    let mut source = GigeSource::new("gv-expo", config).unwrap();
    let link = source
        .exposure_link()
        .expect("a GigE source reports its exposure");
    assert!(link.steering());
    let mut slot = Slot::new(Image::new_mono8(320, 240));
    source.start().unwrap();
    fn next(source: &mut GigeSource, slot: &mut Slot) {
        let t0 = Instant::now();
        loop {
            match source.next_frame(slot, Duration::from_millis(200)) {
                Ok(()) => return,
                Err(e) if !e.is_fatal() && t0.elapsed() < Duration::from_secs(10) => {}
                Err(e) => panic!("no frame from the in-process camera: {e}"),
            }
        }
    }
    next(&mut source, &mut slot);
    assert_eq!(
        camera.exposure_us(),
        Some(3000),
        "brought inside the limits at opening"
    );
    assert!((link.exposure_s.get() - 3e-3).abs() < 1e-9);
    assert_eq!(slot.meta.exposure_ns, 3_000_000);
    for _ in 0..10 {
        next(&mut source, &mut slot);
    }
    assert_eq!(
        camera.exposure_us(),
        Some(3000),
        "no measurement, no change"
    );
    assert_eq!(link.writes.get(), 0);
    // Feeds `peak` for every frame until the exposure reaches `end` µs
    // (and two seconds more frames change nothing); the exposures seen.
    let mut steer = |slot: &mut Slot, peak: f32, end: u32| {
        let mut seen = vec![camera.exposure_us().unwrap()];
        let t0 = Instant::now();
        while *seen.last().unwrap() != end {
            assert!(
                t0.elapsed() < Duration::from_secs(10),
                "{seen:?} never reaches {end} µs"
            );
            next(&mut source, slot);
            link.offer(slot.meta.seq, peak);
            let now = camera.exposure_us().unwrap();
            if now != *seen.last().unwrap() {
                seen.push(now);
            }
        }
        for _ in 0..20 {
            next(&mut source, slot);
            link.offer(slot.meta.seq, peak);
        }
        assert_eq!(camera.exposure_us(), Some(end), "stays at the limit");
        assert!(seen.iter().all(|us| (200..=3000).contains(us)), "{seen:?}");
        seen
    };
    let down = steer(&mut slot, SATURATED_PEAK, 200);
    assert_eq!(
        down,
        [3000, 1500, 750, 375, 200],
        "halved per step while clipped"
    );
    assert_eq!(
        slot.meta.exposure_ns, 200_000,
        "frames carry the exposure in effect"
    );
    let up = steer(&mut slot, 0.2, 3000);
    assert_eq!(
        up,
        [200, 400, 800, 1600, 3000],
        "doubled per step while dim"
    );
    assert_eq!(link.writes.get(), 8);
    assert_eq!(link.write_failures.get(), 0);
    assert!((link.exposure_s.get() - 3e-3).abs() < 1e-9);
    source.stop();
    drop(source);
    drop(camera);
}

/// Exposure control limits that miss the camera's exposure range refuse
/// the configuration at opening (fatal, naming the keys), like a camera
/// without an exposure feature.
fn refuses_exposure_limits_the_camera_lacks() {
    let image = Image::new_mono8(320, 240);
    let camera = FakeGigeCamera::start("PPEXPO03", &image).unwrap();
    let config = GigeConfig {
        camera: Some(camera.serial().into()),
        exposure_control: Some(ExposureSettings {
            min_us: 1.0,
            max_us: 5.0,
            ..ExposureSettings::default()
        }),
        ..GigeConfig::default()
    };
    let mut source = GigeSource::new("gv-expo-range", config).unwrap();
    let mut slot = Slot::new(Image::new_mono8(320, 240));
    source.start().unwrap();
    let t0 = Instant::now();
    let refused = loop {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "not refused within 10 s"
        );
        match source.next_frame(&mut slot, Duration::from_millis(200)) {
            Err(e) if e.is_fatal() => break e.to_string(),
            Ok(()) => panic!("frames despite exposure limits the camera lacks"),
            Err(_) => {}
        }
    };
    assert!(
        refused.contains("source.gige.exposure_control.min_us/max_us")
            && refused.contains("ExposureTimeAbs"),
        "{refused}"
    );
    source.stop();
    drop(source);
    drop(camera);
}
