//! Once warm, a frame allocates nothing on its way through the daemon: from
//! the source's hand-over into the ring, through a detection worker (locate,
//! whole or tracked from the latest pose, the pose result) and the ordered output (message, JSON line) to the
//! sinks' hand-off (UDP datagrams to a real socket). A counting global
//! allocator watches every thread of this process while frames flow.

mod common;
use common::{synthetic_source, Poses};
use photopose_pipeline::{Pipeline, Supervision};
use photopose_testkit::{allocations, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn frames_flow_from_source_to_sinks_without_allocating() {
    let mut udp = Poses::bind();
    let cfg = udp.config(
        50.0,
        r#"
[tracking]
enabled = true
"#,
    );
    let (camera, field, source) = synthetic_source(&cfg);
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, Box::new(source), Supervision::none())
            .unwrap();
    // Warm: every buffer, queue and cache has grown to its size.
    udp.receive(60);
    let before = allocations();
    let poses_before = pipeline.counters().poses_ok.get();
    let tracked_before = pipeline.counters().frames_tracked.get();
    udp.receive(100);
    let allocated = allocations() - before;
    let poses = pipeline.counters().poses_ok.get() - poses_before;
    let tracked = pipeline.counters().frames_tracked.get() - tracked_before;
    pipeline.stop();
    pipeline.join();
    assert!(poses >= 90, "{poses} poses measured in the window");
    assert!(tracked >= poses / 2, "{tracked} of {poses} frames tracked");
    assert_eq!(allocated, 0, "allocations while {poses} frames flowed");
}
