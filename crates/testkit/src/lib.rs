//! photopose-testkit: support for the tests of the other crates (a
//! dev-dependency only).
//!
//! [`CountingAllocator`] is the global allocator of the "no allocation per
//! frame once warm" tests: it forwards to the system allocator and counts
//! allocations. The `unsafe` that a global allocator needs is quarantined
//! here.
#![allow(unsafe_code)] // a global allocator must implement an unsafe trait (it only forwards to `System`); reading the thread name goes through libc

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);
/// Allocations made on threads other than the one named in [`EXCLUDED`].
static OUTSIDE: AtomicUsize = AtomicUsize::new(0);
/// A thread name (NUL-terminated, at most 16 bytes with the NUL) whose
/// allocations [`allocations_outside`] leaves out.
static EXCLUDED: OnceLock<[u8; 16]> = OnceLock::new();

/// Leaves the allocations of the threads named `name` (at most 15 bytes,
/// the kernel's limit) out of [`allocations_outside`]: e.g. a writer
/// thread that encodes and compresses off the frame path. Set once per
/// test binary.
pub fn exclude_thread(name: &str) {
    let mut n = [0u8; 16];
    let len = name.len().min(15);
    n[..len].copy_from_slice(&name.as_bytes()[..len]);
    let _ = EXCLUDED.set(n);
}

/// Whether the calling thread carries the excluded name; read with
/// `pthread_getname_np` (no allocation, unlike `std::thread::current`).
fn on_excluded_thread() -> bool {
    let Some(excluded) = EXCLUDED.get() else {
        return false;
    };
    let mut name = [0u8; 16];
    // SAFETY: the buffer has the 16 bytes the call writes at most.
    let r = unsafe {
        libc::pthread_getname_np(libc::pthread_self(), name.as_mut_ptr().cast(), name.len())
    };
    r == 0 && name == *excluded
}

thread_local! {
    /// Allocations made on this thread (const-initialised, no destructor:
    /// reading it never allocates, so the allocator may touch it).
    static ON_THIS_THREAD: Cell<usize> = const { Cell::new(0) };
}

fn count() {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    if !on_excluded_thread() {
        OUTSIDE.fetch_add(1, Ordering::Relaxed);
    }
    // (Absent while a thread is being torn down: not counted there.)
    let _ = ON_THIS_THREAD.try_with(|n| n.set(n.get() + 1));
}

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
        count();
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as ours, forwarded.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Allocations (including reallocations) so far on every thread but the
/// one named by [`exclude_thread`] (all of them when none is).
pub fn allocations_outside() -> usize {
    OUTSIDE.load(Ordering::Relaxed)
}

/// Allocations (including reallocations) counted so far in this process.
pub fn allocations() -> usize {
    ALLOCATIONS.load(Ordering::Relaxed)
}

/// Allocations (including reallocations) counted so far on the calling
/// thread: for code that runs on the test's own thread, unaffected by
/// what the test harness's other threads allocate meanwhile.
pub fn allocations_on_this_thread() -> usize {
    ON_THIS_THREAD.try_with(Cell::get).unwrap_or(0)
}
