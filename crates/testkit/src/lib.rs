//! photopose-testkit: support for the tests of the other crates (a
//! dev-dependency only).
//!
//! [`CountingAllocator`] is the global allocator of the "no allocation per
//! frame once warm" tests: it forwards to the system allocator and counts
//! allocations. The `unsafe` that a global allocator needs is quarantined
//! here.
#![allow(unsafe_code)] // a global allocator must implement an unsafe trait; it only forwards to `System`

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

/// A global allocator that counts allocations. Install it in a test binary:
///
/// ```ignore
/// #[global_allocator]
/// static GLOBAL: photopose_testkit::CountingAllocator = photopose_testkit::CountingAllocator;
/// ```
#[derive(Debug)]
pub struct CountingAllocator;

// SAFETY: every call forwards to `System` with the caller's layout and
// pointer unchanged; counting touches only an atomic.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Allocations (including reallocations) counted so far in this process.
pub fn allocations() -> usize {
    ALLOCATIONS.load(Ordering::Relaxed)
}
