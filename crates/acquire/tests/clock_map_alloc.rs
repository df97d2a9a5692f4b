//! The clock mapping allocates nothing per frame once built: a counting
//! allocator (one test in this binary) watches thousands of updates,
//! a clock jump among them, on the test's own thread (the harness's other
//! threads allocated a few times under load: not the clock map's).

use photopose_acquire::clock_map::{ClockMap, ClockMapConfig};

#[global_allocator]
static GLOBAL: photopose_testkit::CountingAllocator = photopose_testkit::CountingAllocator;

#[test]
fn updates_allocate_nothing_once_built() {
    let mut map = ClockMap::new(ClockMapConfig::default());
    let jitter = |k: u64| k.wrapping_mul(2_654_435_761) % 500_000;
    for k in 0..200u64 {
        map.update(k * 40_000_000, 1_000_000 + k * 40_000_000 + jitter(k));
    }
    let before = photopose_testkit::allocations_on_this_thread();
    for k in 200..5000u64 {
        let m = map.update(k * 40_000_000, 1_000_000 + k * 40_000_000 + jitter(k));
        assert!(m.warm);
        assert!(map.floor(k * 40_000_000).is_some());
    }
    // A restarted camera clock: a new epoch, still without allocating.
    let m = map.update(5, 300_000_000_000);
    assert!(m.reset);
    let n = photopose_testkit::allocations_on_this_thread() - before;
    assert_eq!(n, 0, "{n} allocations in 4801 updates");
}
