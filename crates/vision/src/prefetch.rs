//! A hint to the processor to start fetching a cache line (tracking mode
//! reads small windows scattered over a frame that is mostly not in the
//! cache; asking for the next windows' lines while the current one is
//! measured hides most of the memory's latency behind arithmetic).
//!
//! The only `unsafe` of this crate (allowed for this module alone): the
//! prefetch instruction takes a raw pointer, so its intrinsic is an
//! `unsafe fn`. It reads nothing into the program, never faults (not even
//! for an invalid address) and changes no result; the pointers given here
//! come from slices anyway. On other architectures it does nothing.

/// Asks for the cache line holding `data[0]` (nothing for an empty slice).
#[inline(always)]
pub(crate) fn line<T>(data: &[T]) {
    #[cfg(target_arch = "x86_64")]
    if let Some(p) = data.first() {
        // SAFETY: `_mm_prefetch` needs SSE, part of every x86-64 processor
        // (the baseline this crate is built for); a prefetch never
        // dereferences its pointer in a way the program can observe and
        // cannot fault.
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            _mm_prefetch::<_MM_HINT_T0>((p as *const T).cast::<i8>());
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = data;
}
