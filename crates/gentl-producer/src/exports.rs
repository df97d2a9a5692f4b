//! The producer's C entry points (the GenTL calls photopose's consumer
//! makes) over one process-wide state behind a mutex. The only `unsafe`
//! code of the crate: reading the consumer's arguments and writing its
//! output buffers, each as the standard defines them.

use photopose_frame::{Image, Pixels};
use photopose_gentl::abi::*;
use photopose_render::{RenderOptions, Renderer};
use std::collections::VecDeque;
use std::ffi::{c_char, c_void, CStr};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

struct Buffer {
    memory: *mut u8,
    size: usize,
    user: *mut c_void,
    frame_id: u64,
    filled: usize,
}

#[derive(Default)]
struct State {
    initialised: bool,
    tl_open: bool,
    if_open: bool,
    dev_open: bool,
    ds_open: bool,
    event: bool,
    acquiring: bool,
    buffers: Vec<Option<Buffer>>,
    input: VecDeque<usize>,
    delivered: u64,
    next_frame_id: u64,
    pfnc: u64,
    /// Deliveries after which the device "unplugs" once (test hook).
    unplug_after: Option<u64>,
    /// Unplugged: the stream fails until the device is opened again.
    gone: bool,
    renderer: Option<(Renderer, Image)>,
    last_error: String,
}

// SAFETY: the raw pointers in `State` are the consumer's announced memory
// and user pointers, only used under the state's mutex.
unsafe impl Send for State {}

static STATE: Mutex<Option<State>> = Mutex::new(None);

// Distinct, non-null handle values.
static TL: u8 = 1;
static IF: u8 = 2;
static DEV: u8 = 3;
static DS: u8 = 4;
static EVENT: u8 = 5;

fn handle(token: &'static u8) -> *mut c_void {
    std::ptr::from_ref(token).cast_mut().cast::<c_void>()
}

fn buffer_handle(index: usize) -> *mut c_void {
    // Opaque: index + 1 (never null); never dereferenced by anyone.
    (index + 1) as *mut c_void
}

fn buffer_index(h: *mut c_void) -> Option<usize> {
    (h as usize).checked_sub(1)
}

fn lock() -> MutexGuard<'static, Option<State>> {
    STATE.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Runs `f` on the state if the library is initialised.
fn with(f: impl FnOnce(&mut State) -> GC_ERROR) -> GC_ERROR {
    let mut guard = lock();
    match guard.as_mut() {
        Some(s) if s.initialised => f(s),
        _ => GC_ERR_NOT_INITIALIZED,
    }
}

fn fail(s: &mut State, code: GC_ERROR, text: &str) -> GC_ERROR {
    s.last_error = text.to_string();
    code
}

/// The frame size (0 × 0 before the device was first opened).
fn frame_size(s: &State) -> (u32, u32) {
    s.renderer
        .as_ref()
        .map_or((0, 0), |(_, img)| (img.width(), img.height()))
}

/// Writes `bytes` into the consumer's info buffer (`out`, `*size` bytes),
/// or only the needed size when `out` is null.
///
/// # Safety
/// `ty` and `size` are null or writable; `out` is null or writable for
/// `*size` bytes.
unsafe fn write_info(
    ty_value: INFO_DATATYPE,
    bytes: &[u8],
    ty: *mut INFO_DATATYPE,
    out: *mut c_void,
    size: *mut usize,
) -> GC_ERROR {
    if size.is_null() {
        return GC_ERR_INVALID_PARAMETER;
    }
    // SAFETY: per the contract above.
    unsafe {
        if !ty.is_null() {
            *ty = ty_value;
        }
        if out.is_null() {
            *size = bytes.len();
            return GC_ERR_SUCCESS;
        }
        if *size < bytes.len() {
            *size = bytes.len();
            return GC_ERR_BUFFER_TOO_SMALL;
        }
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), out.cast::<u8>(), bytes.len());
        *size = bytes.len();
    }
    GC_ERR_SUCCESS
}

/// A string with its NUL, for `write_info`.
fn c_bytes(s: &str) -> Vec<u8> {
    let mut v = s.as_bytes().to_vec();
    v.push(0);
    v
}

/// # Safety
/// As [`write_info`].
unsafe fn write_string(
    s: &str,
    ty: *mut INFO_DATATYPE,
    out: *mut c_void,
    size: *mut usize,
) -> GC_ERROR {
    // SAFETY: forwarded contract.
    unsafe { write_info(INFO_DATATYPE_STRING, &c_bytes(s), ty, out, size) }
}

/// # Safety
/// `id` is null or a NUL-terminated string.
unsafe fn id_is(id: *const c_char, want: &str) -> bool {
    // SAFETY: per the contract above.
    !id.is_null() && unsafe { CStr::from_ptr(id) }.to_bytes() == want.as_bytes()
}

/// # Safety
/// `p` is null or writable.
unsafe fn put<T>(p: *mut T, v: T) -> GC_ERROR {
    if p.is_null() {
        return GC_ERR_INVALID_PARAMETER;
    }
    // SAFETY: per the contract above.
    unsafe { p.write(v) };
    GC_ERR_SUCCESS
}

/// The modules of the GenTL chain; each has exactly one child (the system
/// one interface, the interface one device, the device one data stream).
#[derive(Clone, Copy)]
enum Module {
    System,
    Interface,
    Device,
    Stream,
}

impl Module {
    fn token(self) -> &'static u8 {
        match self {
            Module::System => &TL,
            Module::Interface => &IF,
            Module::Device => &DEV,
            Module::Stream => &DS,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Module::System => "system",
            Module::Interface => "interface",
            Module::Device => "device",
            Module::Stream => "data stream",
        }
    }

    fn open_flag(self, s: &mut State) -> &mut bool {
        match self {
            Module::System => &mut s.tl_open,
            Module::Interface => &mut s.if_open,
            Module::Device => &mut s.dev_open,
            Module::Stream => &mut s.ds_open,
        }
    }

    /// The one child and its id (the stream has none: buffers instead).
    fn child(self) -> Option<(Module, &'static str)> {
        match self {
            Module::System => Some((Module::Interface, crate::INTERFACE_ID)),
            Module::Interface => Some((Module::Device, crate::DEVICE_ID)),
            Module::Device => Some((Module::Stream, STREAM_ID)),
            Module::Stream => None,
        }
    }
}

/// The id of the device's one data stream.
const STREAM_ID: &str = "stream0";

/// Runs `f` on the state if `h` is `module`'s handle and it is open.
fn with_open(module: Module, h: *mut c_void, f: impl FnOnce(&mut State) -> GC_ERROR) -> GC_ERROR {
    with(|s| {
        if h != handle(module.token()) || !*module.open_flag(s) {
            let text = format!("not the open {}", module.name());
            return fail(s, GC_ERR_INVALID_HANDLE, &text);
        }
        f(s)
    })
}

/// `XXClose` of a module with a child: refused while the child is open.
fn close_module(module: Module, h: *mut c_void) -> GC_ERROR {
    with_open(module, h, |s| {
        if let Some((child, _)) = module.child() {
            if *child.open_flag(s) {
                let text = format!("{} still open", child.name());
                return fail(s, GC_ERR_RESOURCE_IN_USE, &text);
            }
        }
        *module.open_flag(s) = false;
        GC_ERR_SUCCESS
    })
}

/// `XXUpdateYYList`: the one child never changes.
///
/// # Safety
/// `changed` is null or writable.
unsafe fn update_child_list(module: Module, h: *mut c_void, changed: *mut bool8_t) -> GC_ERROR {
    with_open(module, h, |_| {
        if !changed.is_null() {
            // SAFETY: non-null, the consumer's flag.
            unsafe { *changed = 0 };
        }
        GC_ERR_SUCCESS
    })
}

/// `XXGetNumYYs`: one.
///
/// # Safety
/// `n` is null or writable.
unsafe fn count_children(module: Module, h: *mut c_void, n: *mut u32) -> GC_ERROR {
    // SAFETY: the consumer passes a writable count.
    with_open(module, h, |_| unsafe { put(n, 1) })
}

/// `XXGetYYID`: the one child's id at index 0.
///
/// # Safety
/// `size` is null or writable; `id` is null or writable for `*size` bytes.
unsafe fn child_id(
    module: Module,
    h: *mut c_void,
    index: u32,
    id: *mut c_char,
    size: *mut usize,
) -> GC_ERROR {
    with_open(module, h, |s| {
        let Some((child, child_id)) = module.child() else {
            return fail(s, GC_ERR_NOT_IMPLEMENTED, "no children");
        };
        if index != 0 {
            let text = format!("one {}", child.name());
            return fail(s, GC_ERR_INVALID_INDEX, &text);
        }
        // SAFETY: the consumer passes a buffer of `*size` bytes (or null).
        unsafe { write_string(child_id, std::ptr::null_mut(), id.cast(), size) }
    })
}

/// `XXOpenYY`: opens the one child named `id` (once), after `prepare`.
///
/// # Safety
/// `id` is null or NUL-terminated; `out` is null or writable.
unsafe fn open_child(
    module: Module,
    h: *mut c_void,
    id: *const c_char,
    out: *mut *mut c_void,
    prepare: impl FnOnce(&mut State) -> Result<(), GC_ERROR>,
) -> GC_ERROR {
    with_open(module, h, |s| {
        let Some((child, child_id)) = module.child() else {
            return fail(s, GC_ERR_NOT_IMPLEMENTED, "no children");
        };
        // SAFETY: the consumer passes a NUL-terminated id.
        if !unsafe { id_is(id, child_id) } {
            let text = format!("no such {}", child.name());
            return fail(s, GC_ERR_INVALID_ID, &text);
        }
        if *child.open_flag(s) {
            let text = format!("{} already open", child.name());
            return fail(s, GC_ERR_RESOURCE_IN_USE, &text);
        }
        if let Err(e) = prepare(s) {
            return e;
        }
        *child.open_flag(s) = true;
        // SAFETY: the consumer passes a writable handle.
        unsafe { put(out, handle(child.token())) }
    })
}

#[no_mangle]
unsafe extern "C" fn GCInitLib() -> GC_ERROR {
    let mut guard = lock();
    if guard.as_ref().is_some_and(|s| s.initialised) {
        return GC_ERR_RESOURCE_IN_USE;
    }
    let pfnc = std::env::var(crate::PFNC_VAR)
        .ok()
        .and_then(|v| {
            let v = v.trim();
            match v.strip_prefix("0x") {
                Some(hex) => u64::from_str_radix(hex, 16).ok(),
                None => v.parse().ok(),
            }
        })
        .unwrap_or(photopose_gentl::pixel::pfnc::MONO8);
    let unplug_after = std::env::var(crate::UNPLUG_VAR)
        .ok()
        .and_then(|v| v.trim().parse().ok());
    *guard = Some(State {
        initialised: true,
        pfnc,
        unplug_after,
        next_frame_id: 1,
        ..State::default()
    });
    GC_ERR_SUCCESS
}

#[no_mangle]
unsafe extern "C" fn GCCloseLib() -> GC_ERROR {
    let mut guard = lock();
    match guard.take() {
        Some(s) if s.initialised => GC_ERR_SUCCESS,
        _ => GC_ERR_NOT_INITIALIZED,
    }
}

#[no_mangle]
unsafe extern "C" fn GCGetLastError(
    code: *mut GC_ERROR,
    text: *mut c_char,
    size: *mut usize,
) -> GC_ERROR {
    let message = lock()
        .as_ref()
        .map(|s| s.last_error.clone())
        .unwrap_or_default();
    // SAFETY: the consumer passes a writable code, and a buffer of `*size` bytes.
    unsafe {
        if !code.is_null() {
            *code = GC_ERR_ERROR;
        }
        write_string(&message, std::ptr::null_mut(), text.cast::<c_void>(), size)
    }
}

#[no_mangle]
unsafe extern "C" fn TLOpen(tl: *mut TL_HANDLE) -> GC_ERROR {
    with(|s| {
        if s.tl_open {
            return fail(s, GC_ERR_RESOURCE_IN_USE, "system already open");
        }
        s.tl_open = true;
        // SAFETY: the consumer passes a writable handle.
        unsafe { put(tl, handle(&TL)) }
    })
}

#[no_mangle]
unsafe extern "C" fn TLClose(tl: TL_HANDLE) -> GC_ERROR {
    close_module(Module::System, tl)
}

#[no_mangle]
unsafe extern "C" fn TLUpdateInterfaceList(
    tl: TL_HANDLE,
    changed: *mut bool8_t,
    _timeout: u64,
) -> GC_ERROR {
    // SAFETY: the consumer passes a writable flag (or null).
    unsafe { update_child_list(Module::System, tl, changed) }
}

#[no_mangle]
unsafe extern "C" fn TLGetNumInterfaces(tl: TL_HANDLE, n: *mut u32) -> GC_ERROR {
    // SAFETY: the consumer passes a writable count.
    unsafe { count_children(Module::System, tl, n) }
}

#[no_mangle]
unsafe extern "C" fn TLGetInterfaceID(
    tl: TL_HANDLE,
    index: u32,
    id: *mut c_char,
    size: *mut usize,
) -> GC_ERROR {
    // SAFETY: the consumer passes a buffer of `*size` bytes (or null).
    unsafe { child_id(Module::System, tl, index, id, size) }
}

#[no_mangle]
unsafe extern "C" fn TLOpenInterface(
    tl: TL_HANDLE,
    id: *const c_char,
    iface: *mut IF_HANDLE,
) -> GC_ERROR {
    // SAFETY: the consumer passes a NUL-terminated id and a writable handle.
    unsafe { open_child(Module::System, tl, id, iface, |_| Ok(())) }
}

#[no_mangle]
unsafe extern "C" fn IFClose(iface: IF_HANDLE) -> GC_ERROR {
    close_module(Module::Interface, iface)
}

#[no_mangle]
unsafe extern "C" fn IFUpdateDeviceList(
    iface: IF_HANDLE,
    changed: *mut bool8_t,
    _timeout: u64,
) -> GC_ERROR {
    // SAFETY: the consumer passes a writable flag (or null).
    unsafe { update_child_list(Module::Interface, iface, changed) }
}

#[no_mangle]
unsafe extern "C" fn IFGetNumDevices(iface: IF_HANDLE, n: *mut u32) -> GC_ERROR {
    // SAFETY: the consumer passes a writable count.
    unsafe { count_children(Module::Interface, iface, n) }
}

#[no_mangle]
unsafe extern "C" fn IFGetDeviceID(
    iface: IF_HANDLE,
    index: u32,
    id: *mut c_char,
    size: *mut usize,
) -> GC_ERROR {
    // SAFETY: the consumer passes a buffer of `*size` bytes (or null).
    unsafe { child_id(Module::Interface, iface, index, id, size) }
}

#[no_mangle]
unsafe extern "C" fn IFGetDeviceInfo(
    iface: IF_HANDLE,
    id: *const c_char,
    cmd: DEVICE_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    out: *mut c_void,
    size: *mut usize,
) -> GC_ERROR {
    with_open(Module::Interface, iface, |s| {
        // SAFETY: the consumer passes a NUL-terminated id.
        if !unsafe { id_is(id, crate::DEVICE_ID) } {
            return fail(s, GC_ERR_INVALID_ID, "no such device");
        }
        let text = match cmd {
            DEVICE_INFO_ID => crate::DEVICE_ID,
            DEVICE_INFO_VENDOR => "photopose",
            DEVICE_INFO_MODEL => "rendered plate",
            DEVICE_INFO_TLTYPE => "Custom",
            DEVICE_INFO_DISPLAYNAME => "photopose rendered plate (test producer)",
            DEVICE_INFO_SERIAL_NUMBER => crate::SERIAL,
            DEVICE_INFO_VERSION => env!("CARGO_PKG_VERSION"),
            DEVICE_INFO_TIMESTAMP_FREQUENCY => {
                // SAFETY: the consumer's info buffer, `*size` bytes.
                return unsafe {
                    write_info(
                        INFO_DATATYPE_UINT64,
                        &1_000_000_000u64.to_ne_bytes(),
                        ty,
                        out,
                        size,
                    )
                };
            }
            _ => return fail(s, GC_ERR_NOT_IMPLEMENTED, "device info not implemented"),
        };
        // SAFETY: the consumer's info buffer, `*size` bytes.
        unsafe { write_string(text, ty, out, size) }
    })
}

#[no_mangle]
unsafe extern "C" fn IFOpenDevice(
    iface: IF_HANDLE,
    id: *const c_char,
    _flags: DEVICE_ACCESS_FLAGS,
    dev: *mut DEV_HANDLE,
) -> GC_ERROR {
    let prepare = |s: &mut State| {
        if s.renderer.is_none() {
            let camera = photopose_formats::default_camera();
            let field = photopose_field::design::default_plate();
            let options = RenderOptions {
                noise_dn: 2.0,
                blur_px: 0.6,
                seed: 7,
                ..RenderOptions::default()
            };
            match Renderer::new(camera, &field, options) {
                Ok(r) => {
                    let image = r.new_image();
                    s.renderer = Some((r, image));
                }
                Err(e) => return Err(fail(s, GC_ERR_ERROR, &e.to_string())),
            }
        }
        // Plugged in again.
        s.gone = false;
        Ok(())
    };
    // SAFETY: the consumer passes a NUL-terminated id and a writable handle.
    unsafe { open_child(Module::Interface, iface, id, dev, prepare) }
}

#[no_mangle]
unsafe extern "C" fn DevClose(dev: DEV_HANDLE) -> GC_ERROR {
    close_module(Module::Device, dev)
}

#[no_mangle]
unsafe extern "C" fn DevGetNumDataStreams(dev: DEV_HANDLE, n: *mut u32) -> GC_ERROR {
    // SAFETY: the consumer passes a writable count.
    unsafe { count_children(Module::Device, dev, n) }
}

#[no_mangle]
unsafe extern "C" fn DevGetDataStreamID(
    dev: DEV_HANDLE,
    index: u32,
    id: *mut c_char,
    size: *mut usize,
) -> GC_ERROR {
    // SAFETY: the consumer passes a buffer of `*size` bytes (or null).
    unsafe { child_id(Module::Device, dev, index, id, size) }
}

#[no_mangle]
unsafe extern "C" fn DevOpenDataStream(
    dev: DEV_HANDLE,
    id: *const c_char,
    ds: *mut DS_HANDLE,
) -> GC_ERROR {
    // SAFETY: the consumer passes a NUL-terminated id and a writable handle.
    unsafe { open_child(Module::Device, dev, id, ds, |_| Ok(())) }
}

#[no_mangle]
unsafe extern "C" fn DSClose(ds: DS_HANDLE) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        if s.buffers.iter().any(Option::is_some) {
            return fail(s, GC_ERR_RESOURCE_IN_USE, "buffers still announced");
        }
        if s.event {
            return fail(s, GC_ERR_RESOURCE_IN_USE, "event still registered");
        }
        s.ds_open = false;
        s.acquiring = false;
        s.buffers.clear();
        GC_ERR_SUCCESS
    })
}

#[no_mangle]
unsafe extern "C" fn DSGetInfo(
    ds: DS_HANDLE,
    cmd: STREAM_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    out: *mut c_void,
    size: *mut usize,
) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        let (w, h) = frame_size(s);
        let announced = s.buffers.iter().filter(|b| b.is_some()).count();
        let (t, v): (INFO_DATATYPE, u64) = match cmd {
            STREAM_INFO_PAYLOAD_SIZE => (INFO_DATATYPE_SIZET, u64::from(w) * u64::from(h)),
            STREAM_INFO_NUM_ANNOUNCED => (INFO_DATATYPE_SIZET, announced as u64),
            STREAM_INFO_NUM_QUEUED => (INFO_DATATYPE_SIZET, s.input.len() as u64),
            STREAM_INFO_NUM_DELIVERED => (INFO_DATATYPE_UINT64, s.delivered),
            STREAM_INFO_BUF_ANNOUNCE_MIN => (INFO_DATATYPE_SIZET, 1),
            STREAM_INFO_IS_GRABBING | STREAM_INFO_DEFINES_PAYLOADSIZE => {
                let b = if cmd == STREAM_INFO_IS_GRABBING {
                    s.acquiring
                } else {
                    true
                };
                // SAFETY: the consumer's info buffer, `*size` bytes.
                return unsafe { write_info(INFO_DATATYPE_BOOL8, &[u8::from(b)], ty, out, size) };
            }
            _ => return fail(s, GC_ERR_NOT_IMPLEMENTED, "stream info not implemented"),
        };
        let bytes = if t == INFO_DATATYPE_SIZET {
            (v as usize).to_ne_bytes().to_vec()
        } else {
            v.to_ne_bytes().to_vec()
        };
        // SAFETY: the consumer's info buffer, `*size` bytes.
        unsafe { write_info(t, &bytes, ty, out, size) }
    })
}

#[no_mangle]
unsafe extern "C" fn DSAnnounceBuffer(
    ds: DS_HANDLE,
    memory: *mut c_void,
    bytes: usize,
    user: *mut c_void,
    buffer: *mut BUFFER_HANDLE,
) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        if memory.is_null() || buffer.is_null() {
            return fail(s, GC_ERR_INVALID_PARAMETER, "null buffer");
        }
        let index = s.buffers.len();
        s.buffers.push(Some(Buffer {
            memory: memory.cast::<u8>(),
            size: bytes,
            user,
            frame_id: 0,
            filled: 0,
        }));
        // SAFETY: checked non-null above; the consumer's handle.
        unsafe { put(buffer, buffer_handle(index)) }
    })
}

#[no_mangle]
unsafe extern "C" fn DSRevokeBuffer(
    ds: DS_HANDLE,
    buffer: BUFFER_HANDLE,
    memory: *mut *mut c_void,
    user: *mut *mut c_void,
) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        let Some(i) =
            buffer_index(buffer).filter(|&i| s.buffers.get(i).is_some_and(Option::is_some))
        else {
            return fail(s, GC_ERR_INVALID_HANDLE, "unknown buffer");
        };
        if s.input.contains(&i) {
            return fail(s, GC_ERR_BUSY, "buffer still queued");
        }
        let Some(b) = s.buffers[i].take() else {
            return GC_ERR_INVALID_HANDLE;
        };
        // SAFETY: null or the consumer's writable pointers.
        unsafe {
            if !memory.is_null() {
                *memory = b.memory.cast::<c_void>();
            }
            if !user.is_null() {
                *user = b.user;
            }
        }
        GC_ERR_SUCCESS
    })
}

#[no_mangle]
unsafe extern "C" fn DSQueueBuffer(ds: DS_HANDLE, buffer: BUFFER_HANDLE) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        let Some(i) =
            buffer_index(buffer).filter(|&i| s.buffers.get(i).is_some_and(Option::is_some))
        else {
            return fail(s, GC_ERR_INVALID_HANDLE, "unknown buffer");
        };
        if s.input.contains(&i) {
            return fail(s, GC_ERR_INVALID_PARAMETER, "buffer already queued");
        }
        s.input.push_back(i);
        GC_ERR_SUCCESS
    })
}

#[no_mangle]
unsafe extern "C" fn DSFlushQueue(ds: DS_HANDLE, op: ACQ_QUEUE_TYPE) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        match op {
            // Frames are delivered as they are rendered: the output queue
            // is always empty.
            ACQ_QUEUE_ALL_DISCARD => s.input.clear(),
            ACQ_QUEUE_ALL_TO_INPUT | ACQ_QUEUE_UNQUEUED_TO_INPUT => {
                for i in 0..s.buffers.len() {
                    if s.buffers[i].is_some() && !s.input.contains(&i) {
                        s.input.push_back(i);
                    }
                }
            }
            ACQ_QUEUE_INPUT_TO_OUTPUT | ACQ_QUEUE_OUTPUT_DISCARD => {}
            _ => return fail(s, GC_ERR_INVALID_PARAMETER, "unknown queue operation"),
        }
        GC_ERR_SUCCESS
    })
}

#[no_mangle]
unsafe extern "C" fn DSStartAcquisition(
    ds: DS_HANDLE,
    _flags: ACQ_START_FLAGS,
    _count: u64,
) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        if s.acquiring {
            return fail(s, GC_ERR_RESOURCE_IN_USE, "already acquiring");
        }
        s.acquiring = true;
        GC_ERR_SUCCESS
    })
}

#[no_mangle]
unsafe extern "C" fn DSStopAcquisition(ds: DS_HANDLE, _flags: ACQ_STOP_FLAGS) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        if !s.acquiring {
            return fail(s, GC_ERR_RESOURCE_IN_USE, "not acquiring");
        }
        s.acquiring = false;
        GC_ERR_SUCCESS
    })
}

#[no_mangle]
unsafe extern "C" fn DSGetBufferInfo(
    ds: DS_HANDLE,
    buffer: BUFFER_HANDLE,
    cmd: BUFFER_INFO_CMD,
    ty: *mut INFO_DATATYPE,
    out: *mut c_void,
    size: *mut usize,
) -> GC_ERROR {
    with_open(Module::Stream, ds, |s| {
        let (w, h) = frame_size(s);
        let pfnc = s.pfnc;
        let Some(b) = buffer_index(buffer)
            .and_then(|i| s.buffers.get(i))
            .and_then(Option::as_ref)
        else {
            return fail(s, GC_ERR_INVALID_HANDLE, "unknown buffer");
        };
        let sizet = |v: usize| (INFO_DATATYPE_SIZET, v.to_ne_bytes().to_vec());
        let u64v = |v: u64| (INFO_DATATYPE_UINT64, v.to_ne_bytes().to_vec());
        let (t, bytes) = match cmd {
            BUFFER_INFO_BASE => (
                INFO_DATATYPE_PTR,
                (b.memory as usize).to_ne_bytes().to_vec(),
            ),
            BUFFER_INFO_SIZE => sizet(b.size),
            BUFFER_INFO_SIZE_FILLED => sizet(b.filled),
            BUFFER_INFO_WIDTH => sizet(w as usize),
            BUFFER_INFO_HEIGHT | BUFFER_INFO_DELIVERED_IMAGEHEIGHT => sizet(h as usize),
            BUFFER_INFO_XPADDING | BUFFER_INFO_IMAGEOFFSET => sizet(0),
            BUFFER_INFO_FRAMEID => u64v(b.frame_id),
            BUFFER_INFO_TIMESTAMP | BUFFER_INFO_TIMESTAMP_NS => {
                u64v(crate::timestamp_ns(b.frame_id))
            }
            BUFFER_INFO_PIXELFORMAT => u64v(pfnc),
            BUFFER_INFO_PIXELFORMAT_NAMESPACE => u64v(PIXELFORMAT_NAMESPACE_PFNC_32BIT),
            BUFFER_INFO_PAYLOADTYPE => sizet(PAYLOAD_TYPE_IMAGE as usize),
            BUFFER_INFO_IS_INCOMPLETE => (INFO_DATATYPE_BOOL8, vec![0u8]),
            _ => return fail(s, GC_ERR_NOT_IMPLEMENTED, "buffer info not implemented"),
        };
        // SAFETY: the consumer's info buffer, `*size` bytes.
        unsafe { write_info(t, &bytes, ty, out, size) }
    })
}

#[no_mangle]
unsafe extern "C" fn GCRegisterEvent(
    source: EVENTSRC_HANDLE,
    kind: EVENT_TYPE,
    event: *mut EVENT_HANDLE,
) -> GC_ERROR {
    with_open(Module::Stream, source, |s| {
        if kind != EVENT_NEW_BUFFER {
            return fail(s, GC_ERR_NOT_IMPLEMENTED, "only NEW_BUFFER events");
        }
        if s.event {
            return fail(s, GC_ERR_RESOURCE_IN_USE, "event already registered");
        }
        s.event = true;
        // SAFETY: the consumer passes a writable handle.
        unsafe { put(event, handle(&EVENT)) }
    })
}

#[no_mangle]
unsafe extern "C" fn GCUnregisterEvent(source: EVENTSRC_HANDLE, kind: EVENT_TYPE) -> GC_ERROR {
    with_open(Module::Stream, source, |s| {
        if kind != EVENT_NEW_BUFFER || !s.event {
            return fail(s, GC_ERR_NOT_AVAILABLE, "not registered");
        }
        s.event = false;
        GC_ERR_SUCCESS
    })
}

#[no_mangle]
unsafe extern "C" fn EventKill(event: EVENT_HANDLE) -> GC_ERROR {
    // Nothing waits inside the producer for longer than one poll.
    with(|s| {
        if event != handle(&EVENT) || !s.event {
            return fail(s, GC_ERR_INVALID_HANDLE, "not the registered event");
        }
        GC_ERR_SUCCESS
    })
}

/// Renders the next frame into queued buffer `i`.
fn fill(s: &mut State, i: usize) -> Result<(), String> {
    let id = s.next_frame_id;
    let Some((renderer, image)) = s.renderer.as_mut() else {
        return Err("device not open".into());
    };
    let pose = photopose_geometry::Exterior::from_kuka_pose(crate::truth_pose(id));
    renderer.render(&pose, image).map_err(|e| e.to_string())?;
    let Pixels::Mono8(pixels) = image.pixels() else {
        return Err("renderer gave a 16-bit image".into());
    };
    let Some(b) = s.buffers.get_mut(i).and_then(Option::as_mut) else {
        return Err("buffer revoked".into());
    };
    let n = pixels.len().min(b.size);
    // SAFETY: `b.memory` is the consumer's announced memory of `b.size`
    // bytes, queued with us (ours to write until delivered).
    unsafe { std::ptr::copy_nonoverlapping(pixels.as_ptr(), b.memory, n) };
    b.filled = n;
    b.frame_id = id;
    s.next_frame_id += 1;
    Ok(())
}

#[no_mangle]
unsafe extern "C" fn EventGetData(
    event: EVENT_HANDLE,
    out: *mut c_void,
    size: *mut usize,
    timeout_ms: u64,
) -> GC_ERROR {
    let deadline = Instant::now() + Duration::from_millis(timeout_ms.min(3_600_000));
    loop {
        let r = with(|s| {
            if event != handle(&EVENT) || !s.event {
                return fail(s, GC_ERR_INVALID_HANDLE, "not the registered event");
            }
            if s.gone {
                return fail(s, GC_ERR_IO, "device unplugged");
            }
            if s.unplug_after.is_some_and(|n| s.delivered >= n) {
                s.unplug_after = None;
                s.gone = true;
                return fail(s, GC_ERR_IO, "device unplugged");
            }
            if !s.acquiring {
                return GC_ERR_TIMEOUT;
            }
            let Some(i) = s.input.pop_front() else {
                return GC_ERR_TIMEOUT;
            };
            if let Err(e) = fill(s, i) {
                s.input.push_front(i);
                return fail(s, GC_ERR_ERROR, &e);
            }
            s.delivered += 1;
            let user = s.buffers[i]
                .as_ref()
                .map_or(std::ptr::null_mut(), |b| b.user);
            let data = EVENT_NEW_BUFFER_DATA {
                BufferHandle: buffer_handle(i),
                pUserPointer: user,
            };
            // SAFETY: the consumer's event buffer of `*size` bytes; the
            // structure is copied bytewise (it is packed).
            unsafe {
                let bytes = std::slice::from_raw_parts(
                    (&raw const data).cast::<u8>(),
                    std::mem::size_of::<EVENT_NEW_BUFFER_DATA>(),
                );
                write_info(
                    INFO_DATATYPE_UNKNOWN,
                    bytes,
                    std::ptr::null_mut(),
                    out,
                    size,
                )
            }
        });
        if r != GC_ERR_TIMEOUT || Instant::now() >= deadline {
            return r;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

// The device has no register space: the data stream defines the payload
// size and frames flow once the stream is started (as a frame grabber's
// producer with a free-running camera).

#[no_mangle]
unsafe extern "C" fn DevGetPort(dev: DEV_HANDLE, _port: *mut PORT_HANDLE) -> GC_ERROR {
    with_open(Module::Device, dev, |s| {
        fail(s, GC_ERR_NOT_IMPLEMENTED, "no remote device port")
    })
}

#[no_mangle]
unsafe extern "C" fn GCGetPortURL(
    _port: PORT_HANDLE,
    _url: *mut c_char,
    _size: *mut usize,
) -> GC_ERROR {
    with(|s| fail(s, GC_ERR_NOT_IMPLEMENTED, "no ports"))
}

#[no_mangle]
unsafe extern "C" fn GCReadPort(
    _port: PORT_HANDLE,
    _address: u64,
    _out: *mut c_void,
    _size: *mut usize,
) -> GC_ERROR {
    with(|s| fail(s, GC_ERR_NOT_IMPLEMENTED, "no ports"))
}

#[no_mangle]
unsafe extern "C" fn GCWritePort(
    _port: PORT_HANDLE,
    _address: u64,
    _bytes: *const c_void,
    _size: *mut usize,
) -> GC_ERROR {
    with(|s| fail(s, GC_ERR_NOT_IMPLEMENTED, "no ports"))
}
