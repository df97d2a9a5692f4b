//! Once warm, a frame allocates nothing on its way through the daemon: from
//! the source's hand-over into the ring, through a detection worker (locate,
//! whole or tracked from the latest pose, the pose result) and the ordered output (message, JSON line) to the
//! sinks' hand-off (UDP datagrams to a real socket). A counting global
//! allocator watches every thread of this process while frames flow.

use photopose_field::design::default_plate;
use photopose_pipeline::config::Source;
use photopose_pipeline::source::SyntheticSource;
use photopose_pipeline::{Config, Pipeline, Supervision};
use photopose_testkit::{allocations, CountingAllocator};
use std::net::UdpSocket;
use std::time::{Duration, Instant};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn frames_flow_from_source_to_sinks_without_allocating() {
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let cfg = Config::parse(
        &format!(
            r#"
[source]
kind = "synthetic"
[source.synthetic]
rate_hz = 50.0
frames = 0
radius_mm = 40.0
period_s = 2.0
[pipeline]
workers = 2
slots = 6
overflow = "block"
max_age_ms = 5000.0
[tracking]
enabled = true
[output]
udp = ["{}"]
"#,
            rx.local_addr().unwrap()
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
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, Box::new(source), Supervision::none())
            .unwrap();
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
    // Warm: every buffer, queue and cache has grown to its size.
    receive(60);
    let before = allocations();
    let poses_before = pipeline.counters().poses_ok.get();
    let tracked_before = pipeline.counters().frames_tracked.get();
    receive(100);
    let allocated = allocations() - before;
    let poses = pipeline.counters().poses_ok.get() - poses_before;
    let tracked = pipeline.counters().frames_tracked.get() - tracked_before;
    pipeline.stop();
    pipeline.join();
    assert!(poses >= 90, "{poses} poses measured in the window");
    assert!(tracked >= poses / 2, "{tracked} of {poses} frames tracked");
    assert_eq!(allocated, 0, "allocations while {poses} frames flowed");
}
