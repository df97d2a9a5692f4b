//! With the recording on, the frame path still allocates nothing once
//! warm: the tap copies each frame into a buffer of the preallocated pool
//! and the sink each pose line (and the frame's targets, from the result's
//! pooled list) into a pooled buffer. Only the writer thread
//! (`record`: protobuf encoding, MCAP chunks, compression) allocates, so
//! this test's allocator counts every thread but that one.

use photopose_field::design::default_plate;
use photopose_pipeline::config::Source;
use photopose_pipeline::sink::record::RecordLink;
use photopose_pipeline::source::SyntheticSource;
use photopose_pipeline::{Config, Pipeline, Supervision};
use photopose_testkit::{allocations_outside, exclude_thread, CountingAllocator};
use std::net::UdpSocket;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_frame_path_does_not_allocate_while_recording() {
    // The writer thread encodes and compresses: off the frame path.
    exclude_thread("record");
    let dir = std::env::temp_dir().join(format!("photopose-noalloc-rec-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.mcap");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut cfg = Config::parse(
        &format!(
            r#"
[source]
kind = "synthetic"
[source.synthetic]
rate_hz = 20.0
frames = 0
radius_mm = 40.0
period_s = 2.0
[pipeline]
workers = 2
slots = 6
overflow = "block"
max_age_ms = 5000.0
[output]
udp = ["{}"]
[record]
path = "{}"
compression = "lz4"
"#,
            rx.local_addr().unwrap(),
            path.display()
        ),
        "test",
    )
    .unwrap();
    let Source::Synthetic(syn) = cfg.source.clone() else {
        panic!("synthetic source expected")
    };
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let source = SyntheticSource::new(camera, &field, syn).unwrap();
    let bytes = camera.sensor.width as usize * camera.sensor.height as usize;
    let link = RecordLink::start(&cfg.record, Default::default(), bytes).unwrap();
    let source = link.tap(Box::new(source), &cfg.record);
    cfg.record.link = Some(link.clone());
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, source, Supervision::none()).unwrap();
    let mut buf = [0u8; 8192];
    let mut receive = |n: usize| {
        let mut got = 0;
        let t0 = Instant::now();
        while got < n {
            assert!(t0.elapsed() < Duration::from_secs(60), "poses stopped");
            if rx.recv(&mut buf).is_ok() {
                got += 1;
            }
        }
    };
    receive(30);
    let before = allocations_outside();
    receive(40);
    let allocated = allocations_outside() - before;
    pipeline.stop();
    pipeline.join();
    link.close();
    let stats = link.stats();
    let frames = stats.frames.load(Ordering::Relaxed);
    assert!(frames > 0, "frames were recorded");
    // The targets went with the poses of the recorded frames.
    assert!(stats.annotations.load(Ordering::Relaxed) > 0);
    assert_eq!(
        allocated, 0,
        "allocations on the frame path while recording"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
