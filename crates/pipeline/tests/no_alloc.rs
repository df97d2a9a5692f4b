//! Once warm, a frame allocates nothing on its way through the daemon: from
//! the source's hand-over into the ring, through a detection worker (locate,
//! whole or tracked from the latest pose, the pose result) and the ordered output (message, JSON line) to the
//! sinks' hand-off (UDP datagrams to a real socket), with the workers
//! measuring each frame's peak for an exposure control loop. A counting
//! global allocator watches every thread of this process while frames flow.

mod common;
use common::{synthetic_source, Poses};
use photopose_acquire::ExposureLink;
use photopose_pipeline::{FrameSource, Pipeline, Slot, SourceError, Supervision};
use photopose_testkit::{allocations, CountingAllocator};
use std::sync::Arc;
use std::time::Duration;

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// A source whose exposure is steered: the workers offer each frame's
/// peak on its link (what a GigE source with exposure control asks).
struct Steered<S> {
    inner: S,
    link: Arc<ExposureLink>,
}

impl<S: FrameSource> FrameSource for Steered<S> {
    fn start(&mut self) -> Result<(), SourceError> {
        self.inner.start()
    }
    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        self.inner.next_frame(slot, timeout)
    }
    fn stop(&mut self) {
        self.inner.stop()
    }
    fn describe(&self) -> String {
        self.inner.describe()
    }
    fn exposure_link(&self) -> Option<Arc<ExposureLink>> {
        Some(Arc::clone(&self.link))
    }
}

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
    let link = Arc::new(ExposureLink::new(true));
    let source = Steered {
        inner: source,
        link: Arc::clone(&link),
    };
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, Box::new(source), Supervision::none())
            .unwrap();
    // Warm: every buffer, queue and cache has grown to its size.
    udp.receive(60);
    let measured_before = link.latest().expect("frames' peaks offered").0;
    let before = allocations();
    let poses_before = pipeline.counters().poses_ok.get();
    let tracked_before = pipeline.counters().frames_tracked.get();
    udp.receive(100);
    let allocated = allocations() - before;
    let (measured, peak) = link.latest().unwrap();
    let poses = pipeline.counters().poses_ok.get() - poses_before;
    let tracked = pipeline.counters().frames_tracked.get() - tracked_before;
    pipeline.stop();
    pipeline.join();
    assert!(poses >= 90, "{poses} poses measured in the window");
    assert!(tracked >= poses / 2, "{tracked} of {poses} frames tracked");
    assert!(
        measured.wrapping_sub(measured_before) >= 90,
        "peaks of frames {measured_before}..{measured} offered"
    );
    assert!(
        peak > 0.3 && peak <= 1.0,
        "the rendered targets' peak: {peak}"
    );
    assert_eq!(allocated, 0, "allocations while {poses} frames flowed");
}
