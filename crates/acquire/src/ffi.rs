//! The crate's only `unsafe` code, quarantined here: reading an aravis
//! buffer's payload in place (the safe `image_data()` allocates a `Vec` per
//! frame), and the fill-pattern callback of the in-process GigE Vision fake
//! camera (reached through `aravis-sys`).

use aravis::Buffer;
use glib::translate::ToGlibPtr;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, PoisonError};

/// The payload bytes of a popped buffer, borrowed for as long as the buffer.
pub(crate) fn payload(buffer: &Buffer) -> &[u8] {
    let (ptr, len) = buffer.data();
    if ptr.is_null() || len == 0 {
        return &[];
    }
    // SAFETY: `arv_buffer_get_data` returns the buffer's own data block and
    // its size. The block is owned by the `ArvBuffer`, which `buffer` keeps
    // alive for the returned borrow. A buffer popped by the application is
    // not written by the stream thread until it is pushed back, and pushing
    // it back takes the `Buffer` by value, which the borrow forbids.
    unsafe { std::slice::from_raw_parts(ptr, len) }
}

/// The bytes the fill callback writes into every frame, shared between the
/// test and the fake camera's thread.
pub(crate) type FillBytes = Arc<Mutex<Vec<u8>>>;

/// Installs `bytes` as the fill pattern of `camera`: every frame the camera
/// sends starts with them, cut to the frame's `width * height` bytes (Mono8);
/// bytes beyond a shorter pattern are left as they were.
///
/// Returns the owner of the callback's data: keep it alive as long as the
/// camera may fill frames (drop the camera first, then it).
pub(crate) fn set_fill(camera: &aravis::FakeCamera, bytes: FillBytes) -> FillGuard {
    let data = Box::into_raw(Box::new(bytes));
    let raw: *mut aravis_sys::ArvFakeCamera = camera.to_glib_none().0;
    // SAFETY: `raw` is a live `ArvFakeCamera` (borrowed from `camera`);
    // `fill` matches `ArvFakeCameraFillPattern`; `data` points to a boxed
    // `FillBytes` that stays valid until `FillGuard` is dropped, which its
    // owner does only after the camera that calls `fill` is gone.
    unsafe {
        aravis_sys::arv_fake_camera_set_fill_pattern(raw, Some(fill), data.cast::<c_void>());
    }
    FillGuard { data }
}

/// Owns the fill callback's data (see [`set_fill`]).
pub(crate) struct FillGuard {
    data: *mut FillBytes,
}

// SAFETY: the pointer is to a `Box<FillBytes>` (an `Arc<Mutex<..>>`, Send
// and Sync); the guard only frees it.
unsafe impl Send for FillGuard {}

impl Drop for FillGuard {
    fn drop(&mut self) {
        // SAFETY: `data` came from `Box::into_raw` in `set_fill` and is freed
        // only here, once; the camera that used it is dropped before.
        drop(unsafe { Box::from_raw(self.data) });
    }
}

unsafe extern "C" fn fill(
    buffer: *mut aravis_sys::ArvBuffer,
    data: *mut c_void,
    _exposure_time_us: u32,
    _gain: u32,
    _pixel_format: aravis_sys::ArvPixelFormat,
) {
    if buffer.is_null() || data.is_null() {
        return;
    }
    // SAFETY: `data` is the `FillBytes` installed by `set_fill`, alive while
    // the camera runs. `buffer` is the buffer being filled: the fake camera
    // has checked, before calling us, that its data block holds at least
    // `width * height` bytes (the Mono8 payload), so that many are ours to
    // write during this call. (`arv_buffer_get_data`'s size is the received
    // size, not yet set at this point, so it is not used.)
    unsafe {
        let bytes = &*data.cast::<FillBytes>();
        let width = aravis_sys::arv_buffer_get_image_width(buffer).max(0) as usize;
        let height = aravis_sys::arv_buffer_get_image_height(buffer).max(0) as usize;
        let mut received = 0usize;
        let dst = aravis_sys::arv_buffer_get_data(buffer, &mut received);
        if dst.is_null() {
            return;
        }
        let src = bytes.lock().unwrap_or_else(PoisonError::into_inner);
        let n = (width * height).min(src.len());
        std::ptr::copy_nonoverlapping(src.as_ptr(), dst, n);
    }
}

/// The device id of the camera whose serial number is `serial`, from a
/// fresh discovery. Call with the crate's opening lock held (discovery is
/// global state in aravis).
pub(crate) fn device_id_of_serial(serial: &str) -> Option<String> {
    // SAFETY: aravis' device list is global, unsynchronised state; every
    // caller in this crate holds `gige::OPEN_LOCK`, and nothing else in the
    // process is expected to enumerate devices concurrently. The returned
    // strings are owned by the list and copied before the next update.
    unsafe {
        aravis_sys::arv_update_device_list();
        let n = aravis_sys::arv_get_n_devices();
        (0..n).find_map(|i| {
            let s = aravis_sys::arv_get_device_serial_nbr(i);
            let id = aravis_sys::arv_get_device_id(i);
            if s.is_null() || id.is_null() {
                return None;
            }
            let s = std::ffi::CStr::from_ptr(s).to_string_lossy();
            (s == serial).then(|| std::ffi::CStr::from_ptr(id).to_string_lossy().into_owned())
        })
    }
}

/// Every device a fresh discovery finds, as (id, vendor, model, serial,
/// address, protocol); an unknown value is empty. Call with the crate's
/// opening lock held (discovery is global state in aravis).
pub(crate) fn devices() -> Vec<[String; 6]> {
    let text = |p: *const std::ffi::c_char| {
        if p.is_null() {
            String::new()
        } else {
            // SAFETY: a non-null string of aravis' device list, valid until
            // the next update of the list, which the caller's lock excludes;
            // it is copied at once.
            unsafe { std::ffi::CStr::from_ptr(p) }
                .to_string_lossy()
                .into_owned()
        }
    };
    // SAFETY: as in `device_id_of_serial`: the list is global state, and
    // every caller holds `gige::OPEN_LOCK`; indices stay below the count
    // of the update just made.
    unsafe {
        aravis_sys::arv_update_device_list();
        let n = aravis_sys::arv_get_n_devices();
        (0..n)
            .map(|i| {
                [
                    text(aravis_sys::arv_get_device_id(i)),
                    text(aravis_sys::arv_get_device_vendor(i)),
                    text(aravis_sys::arv_get_device_model(i)),
                    text(aravis_sys::arv_get_device_serial_nbr(i)),
                    text(aravis_sys::arv_get_device_address(i)),
                    text(aravis_sys::arv_get_device_protocol(i)),
                ]
            })
            .collect()
    }
}
