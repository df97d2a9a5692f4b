//! No allocation per frame once warm: a counting allocator (counting only
//! in the whole process; this binary holds one test) watches a producer, a consumer and a source
//! pass thousands of frames through the ring.

use photopose_acquire::ring::{Overflow, Ring};
use photopose_acquire::source::{CountingSource, FrameSource, SystemClock};
use photopose_frame::Image;
use std::time::Duration;

#[global_allocator]
static GLOBAL: photopose_testkit::CountingAllocator = photopose_testkit::CountingAllocator;

#[test]
fn no_allocation_per_frame_once_warm() {
    for policy in [Overflow::DropNewest, Overflow::DropOldest] {
        let (mut p, c) = Ring::build(3, policy, || Image::new_mono8(64, 48));
        let mut src = CountingSource::new(64, 48, None, None, SystemClock);
        src.start().unwrap();
        let mut run = |n: u64| {
            for k in 0..n {
                src.next_frame(p.slot_mut(), Duration::from_millis(10))
                    .unwrap();
                p.publish();
                // Consume every third frame (with and without waiting):
                // the ring overflows and drops the rest.
                match k % 6 {
                    0 => drop(c.try_recv()),
                    3 => drop(c.recv_timeout(Duration::from_millis(1))),
                    _ => {}
                }
            }
        };
        run(100);
        let before = photopose_testkit::allocations();
        run(10_000);
        let n = photopose_testkit::allocations() - before;
        assert_eq!(n, 0, "{policy:?}: {n} allocations in 10 000 frames");
        assert!(c.counters().snapshot().dropped > 0);
    }
}
