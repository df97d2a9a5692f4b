//! The crate's only `unsafe` code, quarantined here: loading a GenTL
//! producer (`.cti`) with `libloading`, calling its C functions, and owning
//! the memory announced to a data stream. Everything outside this module is
//! safe Rust over the types below:
//!
//! - [`Library`]: a loaded producer and its function table (every symbol
//!   looked up once, a missing one named with the file);
//! - [`Handle`]: an opaque module handle (system, interface, device, data
//!   stream, event), only ever passed back to the library that made it;
//! - [`Announced`]: buffers of our memory announced to one data stream,
//!   revoked and freed together.
//!
//! Live handles and announced buffers are counted process-wide
//! ([`open_handles`]) so tests can prove that closing leaks nothing.

use crate::abi;
use crate::error::GentlError;
use std::alloc::Layout;
use std::ffi::{c_char, c_void, CStr, CString};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicI64, Ordering};

/// What kind of module a handle belongs to (for the counts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    System,
    Interface,
    Device,
    Stream,
    Event,
}

static OPEN: [AtomicI64; 5] = [
    AtomicI64::new(0),
    AtomicI64::new(0),
    AtomicI64::new(0),
    AtomicI64::new(0),
    AtomicI64::new(0),
];
static BUFFERS: AtomicI64 = AtomicI64::new(0);
static LIBS_INITIALISED: AtomicI64 = AtomicI64::new(0);

fn count(kind: Kind, delta: i64) {
    OPEN[kind as usize].fetch_add(delta, Ordering::Relaxed);
}

/// Live GenTL objects of this process, as opened minus closed by photopose.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OpenHandles {
    /// Producers initialised (`GCInitLib` without `GCCloseLib`).
    pub libraries: i64,
    /// System (transport layer) handles.
    pub systems: i64,
    /// Interface handles.
    pub interfaces: i64,
    /// Device handles.
    pub devices: i64,
    /// Data stream handles.
    pub streams: i64,
    /// Registered events.
    pub events: i64,
    /// Buffers announced and not revoked.
    pub buffers: i64,
}

impl OpenHandles {
    /// Whether nothing is open.
    pub fn is_zero(&self) -> bool {
        *self == OpenHandles::default()
    }
}

/// The process's live GenTL objects (see [`OpenHandles`]).
pub fn open_handles() -> OpenHandles {
    let get = |k: Kind| OPEN[k as usize].load(Ordering::Relaxed);
    OpenHandles {
        libraries: LIBS_INITIALISED.load(Ordering::Relaxed),
        systems: get(Kind::System),
        interfaces: get(Kind::Interface),
        devices: get(Kind::Device),
        streams: get(Kind::Stream),
        events: get(Kind::Event),
        buffers: BUFFERS.load(Ordering::Relaxed),
    }
}

/// An opaque GenTL handle. Only the [`Library`] that returned it may be
/// given it back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Handle(*mut c_void);

// SAFETY: a GenTL handle is an opaque token; the standard requires every
// producer to be thread-safe (any call from any thread), and photopose never
// dereferences the pointer.
unsafe impl Send for Handle {}
// SAFETY: as above: shared use only passes the token to the producer.
unsafe impl Sync for Handle {}

/// The producer's function table.
struct Table {
    gc_init_lib: abi::GCInitLib,
    gc_close_lib: abi::GCCloseLib,
    gc_get_last_error: abi::GCGetLastError,
    gc_register_event: abi::GCRegisterEvent,
    gc_read_port: abi::GCReadPort,
    gc_write_port: abi::GCWritePort,
    gc_get_port_url: abi::GCGetPortURL,
    dev_get_port: abi::DevGetPort,
    gc_unregister_event: abi::GCUnregisterEvent,
    event_get_data: abi::EventGetData,
    event_kill: abi::EventKill,
    tl_open: abi::TLOpen,
    tl_close: abi::TLClose,
    tl_update_interface_list: abi::TLUpdateInterfaceList,
    tl_get_num_interfaces: abi::TLGetNumInterfaces,
    tl_get_interface_id: abi::TLGetInterfaceID,
    tl_open_interface: abi::TLOpenInterface,
    if_close: abi::IFClose,
    if_update_device_list: abi::IFUpdateDeviceList,
    if_get_num_devices: abi::IFGetNumDevices,
    if_get_device_id: abi::IFGetDeviceID,
    if_get_device_info: abi::IFGetDeviceInfo,
    if_open_device: abi::IFOpenDevice,
    dev_close: abi::DevClose,
    dev_get_num_data_streams: abi::DevGetNumDataStreams,
    dev_get_data_stream_id: abi::DevGetDataStreamID,
    dev_open_data_stream: abi::DevOpenDataStream,
    ds_close: abi::DSClose,
    ds_get_info: abi::DSGetInfo,
    ds_announce_buffer: abi::DSAnnounceBuffer,
    ds_revoke_buffer: abi::DSRevokeBuffer,
    ds_queue_buffer: abi::DSQueueBuffer,
    ds_flush_queue: abi::DSFlushQueue,
    ds_start_acquisition: abi::DSStartAcquisition,
    ds_stop_acquisition: abi::DSStopAcquisition,
    ds_get_buffer_info: abi::DSGetBufferInfo,
}

/// A loaded GenTL producer. Never unloaded: a producer may leave threads
/// or handlers behind that unloading would pull the code from under; the
/// library stays mapped for the life of the process (one mapping per file,
/// see [`crate::system`]), and `GCInitLib`/`GCCloseLib` bracket each use.
pub(crate) struct Library {
    path: PathBuf,
    f: Table,
    _lib: libloading::Library,
}

/// A GenTL call that failed: which, its code, and the producer's text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct CallError {
    pub(crate) call: &'static str,
    pub(crate) code: i32,
    pub(crate) text: String,
}

impl CallError {
    pub(crate) fn is_timeout(&self) -> bool {
        self.code == abi::GC_ERR_TIMEOUT
    }
}

impl std::fmt::Display for CallError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} failed: {} ({})",
            self.call,
            abi::error_name(self.code),
            self.code
        )?;
        if !self.text.is_empty() {
            write!(f, ": {}", self.text)?;
        }
        Ok(())
    }
}

type Call<T> = Result<T, CallError>;

impl Library {
    /// Loads the producer at `path` and looks up every call photopose uses.
    pub(crate) fn load(path: &Path) -> Result<Library, GentlError> {
        let invalid = |reason: String| GentlError::InvalidProducer {
            path: path.to_path_buf(),
            reason,
        };
        // SAFETY: loading a shared library runs its initialisers; a GenTL
        // producer is a library made to be loaded into a consumer this way
        // (the standard's only way to use one). Which file is loaded is the
        // operator's configuration.
        let lib = unsafe { libloading::Library::new(path) }.map_err(|e| invalid(e.to_string()))?;
        macro_rules! sym {
            ($name:literal, $ty:ty) => {{
                // SAFETY: the symbol is the GenTL function of that name, whose
                // C signature the standard fixes and `abi` declares as `$ty`;
                // the pointer is copied out and used only while `lib` (kept in
                // the returned `Library`, never unloaded) is alive.
                let s: Result<libloading::Symbol<'_, $ty>, _> =
                    unsafe { lib.get(concat!($name, "\0").as_bytes()) };
                *s.map_err(|_| invalid(format!("it exports no `{}`: not a GenTL producer", $name)))?
            }};
        }
        let f = Table {
            gc_init_lib: sym!("GCInitLib", abi::GCInitLib),
            gc_close_lib: sym!("GCCloseLib", abi::GCCloseLib),
            gc_get_last_error: sym!("GCGetLastError", abi::GCGetLastError),
            gc_register_event: sym!("GCRegisterEvent", abi::GCRegisterEvent),
            gc_read_port: sym!("GCReadPort", abi::GCReadPort),
            gc_write_port: sym!("GCWritePort", abi::GCWritePort),
            gc_get_port_url: sym!("GCGetPortURL", abi::GCGetPortURL),
            dev_get_port: sym!("DevGetPort", abi::DevGetPort),
            gc_unregister_event: sym!("GCUnregisterEvent", abi::GCUnregisterEvent),
            event_get_data: sym!("EventGetData", abi::EventGetData),
            event_kill: sym!("EventKill", abi::EventKill),
            tl_open: sym!("TLOpen", abi::TLOpen),
            tl_close: sym!("TLClose", abi::TLClose),
            tl_update_interface_list: sym!("TLUpdateInterfaceList", abi::TLUpdateInterfaceList),
            tl_get_num_interfaces: sym!("TLGetNumInterfaces", abi::TLGetNumInterfaces),
            tl_get_interface_id: sym!("TLGetInterfaceID", abi::TLGetInterfaceID),
            tl_open_interface: sym!("TLOpenInterface", abi::TLOpenInterface),
            if_close: sym!("IFClose", abi::IFClose),
            if_update_device_list: sym!("IFUpdateDeviceList", abi::IFUpdateDeviceList),
            if_get_num_devices: sym!("IFGetNumDevices", abi::IFGetNumDevices),
            if_get_device_id: sym!("IFGetDeviceID", abi::IFGetDeviceID),
            if_get_device_info: sym!("IFGetDeviceInfo", abi::IFGetDeviceInfo),
            if_open_device: sym!("IFOpenDevice", abi::IFOpenDevice),
            dev_close: sym!("DevClose", abi::DevClose),
            dev_get_num_data_streams: sym!("DevGetNumDataStreams", abi::DevGetNumDataStreams),
            dev_get_data_stream_id: sym!("DevGetDataStreamID", abi::DevGetDataStreamID),
            dev_open_data_stream: sym!("DevOpenDataStream", abi::DevOpenDataStream),
            ds_close: sym!("DSClose", abi::DSClose),
            ds_get_info: sym!("DSGetInfo", abi::DSGetInfo),
            ds_announce_buffer: sym!("DSAnnounceBuffer", abi::DSAnnounceBuffer),
            ds_revoke_buffer: sym!("DSRevokeBuffer", abi::DSRevokeBuffer),
            ds_queue_buffer: sym!("DSQueueBuffer", abi::DSQueueBuffer),
            ds_flush_queue: sym!("DSFlushQueue", abi::DSFlushQueue),
            ds_start_acquisition: sym!("DSStartAcquisition", abi::DSStartAcquisition),
            ds_stop_acquisition: sym!("DSStopAcquisition", abi::DSStopAcquisition),
            ds_get_buffer_info: sym!("DSGetBufferInfo", abi::DSGetBufferInfo),
        };
        Ok(Library {
            path: path.to_path_buf(),
            f,
            _lib: lib,
        })
    }

    /// The file this library was loaded from.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// The producer's text for its last error on this thread.
    fn last_error(&self) -> String {
        let mut code = 0i32;
        let mut text = [0u8; 512];
        let mut size = text.len();
        // SAFETY: `code` and `text` are valid for writes of their sizes;
        // `size` tells the producer the buffer's length.
        let r = unsafe {
            (self.f.gc_get_last_error)(&mut code, text.as_mut_ptr().cast::<c_char>(), &mut size)
        };
        if r != abi::GC_ERR_SUCCESS {
            return String::new();
        }
        c_text(&text)
    }

    fn check(&self, call: &'static str, code: abi::GC_ERROR) -> Call<()> {
        if code == abi::GC_ERR_SUCCESS {
            Ok(())
        } else {
            let text = if code == abi::GC_ERR_TIMEOUT {
                String::new()
            } else {
                self.last_error()
            };
            Err(CallError { call, code, text })
        }
    }

    /// `GCInitLib`.
    pub(crate) fn init(&self) -> Call<()> {
        // SAFETY: no arguments; the standard allows it once before any other call.
        self.check("GCInitLib", unsafe { (self.f.gc_init_lib)() })?;
        LIBS_INITIALISED.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// `GCCloseLib`.
    pub(crate) fn close_lib(&self) -> Call<()> {
        // SAFETY: no arguments; called once per successful `init`, after
        // every handle of the library is closed.
        let r = self.check("GCCloseLib", unsafe { (self.f.gc_close_lib)() });
        LIBS_INITIALISED.fetch_sub(1, Ordering::Relaxed);
        r
    }

    /// `TLOpen`.
    pub(crate) fn tl_open(&self) -> Call<Handle> {
        let mut h = std::ptr::null_mut();
        // SAFETY: `h` is valid for the write of one handle.
        self.check("TLOpen", unsafe { (self.f.tl_open)(&mut h) })?;
        count(Kind::System, 1);
        Ok(Handle(h))
    }

    /// Closes a handle of `kind` (system, interface, device, stream).
    pub(crate) fn close(&self, kind: Kind, h: Handle) -> Call<()> {
        // SAFETY: `h` is a handle of `kind` this library returned and that
        // was not closed yet (the owners in `system` close each once).
        let (call, r) = unsafe {
            match kind {
                Kind::System => ("TLClose", (self.f.tl_close)(h.0)),
                Kind::Interface => ("IFClose", (self.f.if_close)(h.0)),
                Kind::Device => ("DevClose", (self.f.dev_close)(h.0)),
                Kind::Stream => ("DSClose", (self.f.ds_close)(h.0)),
                Kind::Event => return Ok(()),
            }
        };
        count(kind, -1);
        self.check(call, r)
    }

    /// `TLUpdateInterfaceList`, `TLGetNumInterfaces`, then every
    /// `TLGetInterfaceID`.
    pub(crate) fn interface_ids(&self, tl: Handle, timeout_ms: u64) -> Call<Vec<String>> {
        let mut changed = 0u8;
        // SAFETY: `tl` is an open system handle; `changed` is writable.
        self.check("TLUpdateInterfaceList", unsafe {
            (self.f.tl_update_interface_list)(tl.0, &mut changed, timeout_ms)
        })?;
        let mut n = 0u32;
        // SAFETY: `tl` is open; `n` is writable.
        self.check("TLGetNumInterfaces", unsafe {
            (self.f.tl_get_num_interfaces)(tl.0, &mut n)
        })?;
        (0..n)
            .map(|i| {
                self.string("TLGetInterfaceID", |buf, size| {
                    // SAFETY: `tl` is open; `buf`/`size` describe a writable buffer.
                    unsafe { (self.f.tl_get_interface_id)(tl.0, i, buf, size) }
                })
            })
            .collect()
    }

    /// `TLOpenInterface`.
    pub(crate) fn open_interface(&self, tl: Handle, id: &str) -> Call<Handle> {
        let id = c_string(id);
        let mut h = std::ptr::null_mut();
        // SAFETY: `tl` is open; `id` is NUL-terminated and outlives the call;
        // `h` is writable.
        self.check("TLOpenInterface", unsafe {
            (self.f.tl_open_interface)(tl.0, id.as_ptr(), &mut h)
        })?;
        count(Kind::Interface, 1);
        Ok(Handle(h))
    }

    /// `IFUpdateDeviceList`, `IFGetNumDevices`, then every `IFGetDeviceID`.
    pub(crate) fn device_ids(&self, iface: Handle, timeout_ms: u64) -> Call<Vec<String>> {
        let mut changed = 0u8;
        // SAFETY: `iface` is an open interface; `changed` is writable.
        self.check("IFUpdateDeviceList", unsafe {
            (self.f.if_update_device_list)(iface.0, &mut changed, timeout_ms)
        })?;
        let mut n = 0u32;
        // SAFETY: `iface` is open; `n` is writable.
        self.check("IFGetNumDevices", unsafe {
            (self.f.if_get_num_devices)(iface.0, &mut n)
        })?;
        (0..n)
            .map(|i| {
                self.string("IFGetDeviceID", |buf, size| {
                    // SAFETY: `iface` is open; `buf`/`size` describe a writable buffer.
                    unsafe { (self.f.if_get_device_id)(iface.0, i, buf, size) }
                })
            })
            .collect()
    }

    /// A string of `IFGetDeviceInfo` (`None` when the producer has none).
    pub(crate) fn device_info(
        &self,
        iface: Handle,
        device: &str,
        cmd: abi::DEVICE_INFO_CMD,
    ) -> Option<String> {
        let id = c_string(device);
        self.string("IFGetDeviceInfo", |buf, size| {
            let mut ty = 0;
            // SAFETY: `iface` is open; `id` is NUL-terminated; `buf`/`size`
            // describe a writable buffer; `ty` is writable.
            unsafe {
                (self.f.if_get_device_info)(
                    iface.0,
                    id.as_ptr(),
                    cmd,
                    &mut ty,
                    buf.cast::<c_void>(),
                    size,
                )
            }
        })
        .ok()
        .filter(|s| !s.is_empty())
    }

    /// A 64-bit number of `IFGetDeviceInfo` (`None` when the producer has none).
    pub(crate) fn device_info_u64(
        &self,
        iface: Handle,
        device: &str,
        cmd: abi::DEVICE_INFO_CMD,
    ) -> Option<u64> {
        let id = c_string(device);
        self.number(|ty, out, size| {
            // SAFETY: `iface` is open; `id` is NUL-terminated; `out`/`size`
            // describe a writable 8-byte buffer; `ty` is writable.
            unsafe { (self.f.if_get_device_info)(iface.0, id.as_ptr(), cmd, ty, out, size) }
        })
    }

    /// `IFOpenDevice`.
    pub(crate) fn open_device(
        &self,
        iface: Handle,
        id: &str,
        access: abi::DEVICE_ACCESS_FLAGS,
    ) -> Call<Handle> {
        let id = c_string(id);
        let mut h = std::ptr::null_mut();
        // SAFETY: `iface` is open; `id` is NUL-terminated; `h` is writable.
        self.check("IFOpenDevice", unsafe {
            (self.f.if_open_device)(iface.0, id.as_ptr(), access, &mut h)
        })?;
        count(Kind::Device, 1);
        Ok(Handle(h))
    }

    /// The first data stream's id of a device (`DevGetNumDataStreams`,
    /// `DevGetDataStreamID`).
    pub(crate) fn first_stream_id(&self, dev: Handle) -> Call<Option<String>> {
        let mut n = 0u32;
        // SAFETY: `dev` is an open device; `n` is writable.
        self.check("DevGetNumDataStreams", unsafe {
            (self.f.dev_get_num_data_streams)(dev.0, &mut n)
        })?;
        if n == 0 {
            return Ok(None);
        }
        self.string("DevGetDataStreamID", |buf, size| {
            // SAFETY: `dev` is open; `buf`/`size` describe a writable buffer.
            unsafe { (self.f.dev_get_data_stream_id)(dev.0, 0, buf, size) }
        })
        .map(Some)
    }

    /// `DevOpenDataStream`.
    pub(crate) fn open_stream(&self, dev: Handle, id: &str) -> Call<Handle> {
        let id = c_string(id);
        let mut h = std::ptr::null_mut();
        // SAFETY: `dev` is open; `id` is NUL-terminated; `h` is writable.
        self.check("DevOpenDataStream", unsafe {
            (self.f.dev_open_data_stream)(dev.0, id.as_ptr(), &mut h)
        })?;
        count(Kind::Stream, 1);
        Ok(Handle(h))
    }

    /// The device's remote port (`DevGetPort`): the camera's registers.
    /// Not a handle to close (it lives as long as the device).
    pub(crate) fn remote_port(&self, dev: Handle) -> Call<Handle> {
        let mut h = std::ptr::null_mut();
        // SAFETY: `dev` is an open device; `h` is writable.
        self.check("DevGetPort", unsafe {
            (self.f.dev_get_port)(dev.0, &mut h)
        })?;
        Ok(Handle(h))
    }

    /// The first URL of a port's description file (`GCGetPortURL`).
    pub(crate) fn port_url(&self, port: Handle) -> Call<String> {
        self.string("GCGetPortURL", |buf, size| {
            // SAFETY: `port` is a live port; `buf`/`size` describe a writable buffer.
            unsafe { (self.f.gc_get_port_url)(port.0, buf, size) }
        })
    }

    /// `GCReadPort` of `out.len()` bytes at `address`.
    pub(crate) fn read_port(&self, port: Handle, address: u64, out: &mut [u8]) -> Call<()> {
        let mut size = out.len();
        // SAFETY: `port` is a live port; `out` is writable for `size` bytes.
        self.check("GCReadPort", unsafe {
            (self.f.gc_read_port)(
                port.0,
                address,
                out.as_mut_ptr().cast::<c_void>(),
                &mut size,
            )
        })
    }

    /// `GCWritePort` of `bytes` at `address`.
    pub(crate) fn write_port(&self, port: Handle, address: u64, bytes: &[u8]) -> Call<()> {
        let mut size = bytes.len();
        // SAFETY: `port` is a live port; `bytes` is readable for `size` bytes.
        self.check("GCWritePort", unsafe {
            (self.f.gc_write_port)(port.0, address, bytes.as_ptr().cast::<c_void>(), &mut size)
        })
    }

    /// A number of `DSGetInfo` (`None` when the producer has none).
    pub(crate) fn stream_info(&self, ds: Handle, cmd: abi::STREAM_INFO_CMD) -> Option<u64> {
        self.number(|ty, out, size| {
            // SAFETY: `ds` is an open data stream; `out`/`size` describe a
            // writable 8-byte buffer; `ty` is writable.
            unsafe { (self.f.ds_get_info)(ds.0, cmd, ty, out, size) }
        })
    }

    /// A number of `DSGetBufferInfo` (`None` when the producer has none).
    pub(crate) fn buffer_info(
        &self,
        ds: Handle,
        buffer: Handle,
        cmd: abi::BUFFER_INFO_CMD,
    ) -> Option<u64> {
        self.number(|ty, out, size| {
            // SAFETY: `ds` is an open data stream and `buffer` one of its
            // announced buffers; `out`/`size` describe a writable 8-byte
            // buffer; `ty` is writable.
            unsafe { (self.f.ds_get_buffer_info)(ds.0, buffer.0, cmd, ty, out, size) }
        })
    }

    /// `GCRegisterEvent(NEW_BUFFER)` on a data stream.
    pub(crate) fn register_new_buffer(&self, ds: Handle) -> Call<Handle> {
        let mut h = std::ptr::null_mut();
        // SAFETY: `ds` is an open data stream (an event source); `h` is writable.
        self.check("GCRegisterEvent", unsafe {
            (self.f.gc_register_event)(ds.0, abi::EVENT_NEW_BUFFER, &mut h)
        })?;
        count(Kind::Event, 1);
        Ok(Handle(h))
    }

    /// `EventKill` (wakes a waiter) then `GCUnregisterEvent(NEW_BUFFER)`.
    pub(crate) fn unregister_new_buffer(&self, ds: Handle, event: Handle) -> Call<()> {
        // SAFETY: `event` is the live NEW_BUFFER event of `ds`; after this
        // call nothing uses it again.
        let r = unsafe {
            (self.f.event_kill)(event.0);
            (self.f.gc_unregister_event)(ds.0, abi::EVENT_NEW_BUFFER)
        };
        count(Kind::Event, -1);
        self.check("GCUnregisterEvent", r)
    }

    /// Waits up to `timeout_ms` for the next filled buffer: its handle and
    /// the user pointer it was announced with.
    pub(crate) fn wait_new_buffer(&self, event: Handle, timeout_ms: u64) -> Call<(Handle, usize)> {
        let mut data = abi::EVENT_NEW_BUFFER_DATA {
            BufferHandle: std::ptr::null_mut(),
            pUserPointer: std::ptr::null_mut(),
        };
        let mut size = std::mem::size_of::<abi::EVENT_NEW_BUFFER_DATA>();
        // SAFETY: `event` is a live NEW_BUFFER event; `data` is writable for
        // `size` bytes, the size of the structure the standard defines.
        self.check("EventGetData", unsafe {
            (self.f.event_get_data)(
                event.0,
                (&raw mut data).cast::<c_void>(),
                &mut size,
                timeout_ms,
            )
        })?;
        let (buffer, user) = (data.BufferHandle, data.pUserPointer);
        Ok((Handle(buffer), user as usize))
    }

    /// `DSQueueBuffer`.
    pub(crate) fn queue(&self, ds: Handle, buffer: Handle) -> Call<()> {
        // SAFETY: `ds` is open and `buffer` one of its announced buffers,
        // delivered to us and not queued: its memory is the producer's again.
        self.check("DSQueueBuffer", unsafe {
            (self.f.ds_queue_buffer)(ds.0, buffer.0)
        })
    }

    /// `DSStartAcquisition` (continuous).
    pub(crate) fn start(&self, ds: Handle) -> Call<()> {
        // SAFETY: `ds` is an open data stream with announced, queued buffers.
        self.check("DSStartAcquisition", unsafe {
            (self.f.ds_start_acquisition)(ds.0, abi::ACQ_START_FLAGS_DEFAULT, abi::GENTL_INFINITE)
        })
    }

    /// `DSStopAcquisition`, then `DSFlushQueue(ALL_DISCARD)`.
    pub(crate) fn stop(&self, ds: Handle) -> Call<()> {
        // SAFETY: `ds` is an open data stream.
        let stopped = self.check("DSStopAcquisition", unsafe {
            (self.f.ds_stop_acquisition)(ds.0, abi::ACQ_STOP_FLAGS_DEFAULT)
        });
        // SAFETY: as above.
        let flushed = self.check("DSFlushQueue", unsafe {
            (self.f.ds_flush_queue)(ds.0, abi::ACQ_QUEUE_ALL_DISCARD)
        });
        stopped.and(flushed)
    }

    /// A string from a call that fills a caller's buffer, asking its size
    /// first when 256 bytes are too few.
    fn string(
        &self,
        call: &'static str,
        f: impl Fn(*mut c_char, *mut usize) -> abi::GC_ERROR,
    ) -> Call<String> {
        let mut buf = vec![0u8; 256];
        let mut size = buf.len();
        let mut r = f(buf.as_mut_ptr().cast::<c_char>(), &mut size);
        if r == abi::GC_ERR_BUFFER_TOO_SMALL || (r == abi::GC_ERR_SUCCESS && size > buf.len()) {
            // Ask the size (a null buffer), then read into one that large.
            size = 0;
            r = f(std::ptr::null_mut(), &mut size);
            if r == abi::GC_ERR_SUCCESS {
                buf = vec![0u8; size.clamp(1, 1 << 16)];
                size = buf.len();
                r = f(buf.as_mut_ptr().cast::<c_char>(), &mut size);
            }
        }
        self.check(call, r)?;
        Ok(c_text(&buf))
    }

    /// A number from an info call into an 8-byte buffer, read by the type
    /// the producer says it wrote.
    fn number(
        &self,
        f: impl Fn(*mut abi::INFO_DATATYPE, *mut c_void, *mut usize) -> abi::GC_ERROR,
    ) -> Option<u64> {
        let mut out = [0u8; 8];
        let mut size = out.len();
        let mut ty = abi::INFO_DATATYPE_UNKNOWN;
        let r = f(&mut ty, out.as_mut_ptr().cast::<c_void>(), &mut size);
        if r != abi::GC_ERR_SUCCESS {
            return None;
        }
        let v = u64::from_ne_bytes(out);
        Some(match (ty, size) {
            (abi::INFO_DATATYPE_BOOL8, _) | (_, 1) => u64::from(out[0]),
            (abi::INFO_DATATYPE_INT32 | abi::INFO_DATATYPE_UINT32, _) | (_, 4) => {
                u64::from(u32::from_ne_bytes([out[0], out[1], out[2], out[3]]))
            }
            _ => v,
        })
    }
}

/// The text before the first NUL of a buffer.
fn c_text(buf: &[u8]) -> String {
    CStr::from_bytes_until_nul(buf)
        .map(|c| c.to_string_lossy().into_owned())
        .unwrap_or_else(|_| String::from_utf8_lossy(buf).into_owned())
}

/// A C string of an id (ids come from the producer and hold no NUL; one
/// that does is cut there).
fn c_string(s: &str) -> CString {
    CString::new(s.split('\0').next().unwrap_or_default()).unwrap_or_default()
}

/// Buffers of our own memory announced to one data stream. The memory is
/// allocated once per opening and freed only after the producer gave each
/// buffer back (`DSRevokeBuffer`), so it outlives every use the producer
/// can make of it.
pub(crate) struct Announced {
    ds: Handle,
    layout: Layout,
    buffers: Vec<(Handle, *mut u8)>,
}

// SAFETY: the raw pointers are to memory this value owns exclusively (the
// producer writes it only while a buffer is queued, which the owner
// controls); moving the owner to another thread moves that ownership.
unsafe impl Send for Announced {}

impl Announced {
    /// Allocates `count` buffers of `size` bytes (aligned to `align`),
    /// announces each with its index as user pointer, and queues them all.
    pub(crate) fn new(
        lib: &Library,
        ds: Handle,
        count: usize,
        size: usize,
        align: usize,
    ) -> Result<Announced, (CallError, Announced)> {
        let align = align.clamp(8, 4096).next_power_of_two();
        let layout =
            Layout::from_size_align(size.max(1), align).unwrap_or_else(|_| Layout::new::<u64>());
        let mut this = Announced {
            ds,
            layout,
            buffers: Vec::with_capacity(count),
        };
        for index in 0..count {
            // SAFETY: the layout has a non-zero size.
            let memory = unsafe { std::alloc::alloc_zeroed(layout) };
            if memory.is_null() {
                std::alloc::handle_alloc_error(layout);
            }
            let mut h = std::ptr::null_mut();
            // SAFETY: `ds` is open; `memory` is valid for `layout.size()`
            // bytes until revoked (we free it only after `DSRevokeBuffer`);
            // the user pointer is an index, never dereferenced by anyone.
            let r = unsafe {
                (lib.f.ds_announce_buffer)(
                    ds.0,
                    memory.cast::<c_void>(),
                    layout.size(),
                    index as *mut c_void,
                    &mut h,
                )
            };
            if let Err(e) = lib.check("DSAnnounceBuffer", r) {
                // SAFETY: never announced: still only ours.
                unsafe { std::alloc::dealloc(memory, layout) };
                return Err((e, this));
            }
            BUFFERS.fetch_add(1, Ordering::Relaxed);
            this.buffers.push((Handle(h), memory));
            if let Err(e) = lib.queue(ds, Handle(h)) {
                return Err((e, this));
            }
        }
        Ok(this)
    }

    /// Lends `f` the bytes (`filled` at most) of the delivered buffer
    /// announced as `index` (checked against its handle), then queues the
    /// buffer again. `None` from `f`'s side when the buffer is not one of
    /// ours; the queueing's result either way.
    pub(crate) fn consume<R>(
        &self,
        lib: &Library,
        index: usize,
        handle: Handle,
        filled: usize,
        f: impl FnOnce(&[u8]) -> R,
    ) -> (Option<R>, Call<()>) {
        let out = match self.buffers.get(index) {
            Some(&(h, memory)) if h == handle => {
                // SAFETY: `memory` is our allocation of `layout.size()`
                // bytes. The producer delivered this buffer (NEW_BUFFER
                // event) and writes it again only once it is queued, which
                // happens below, after the slice lent to `f` is gone.
                let bytes =
                    unsafe { std::slice::from_raw_parts(memory, filled.min(self.layout.size())) };
                Some(f(bytes))
            }
            _ => None,
        };
        (out, lib.queue(self.ds, handle))
    }

    /// Buffers announced.
    pub(crate) fn len(&self) -> usize {
        self.buffers.len()
    }

    /// Revokes every buffer from the (stopped, flushed) stream and frees
    /// its memory. A buffer the producer refuses to give back is leaked
    /// rather than freed under it.
    pub(crate) fn revoke(mut self, lib: &Library) -> Call<()> {
        let mut result = Ok(());
        for (h, memory) in self.buffers.drain(..) {
            let mut base = std::ptr::null_mut();
            let mut private = std::ptr::null_mut();
            // SAFETY: `h` is announced on `self.ds`, which is stopped and
            // flushed (no buffer in the producer's queues); `base` and
            // `private` are writable.
            let r = unsafe { (lib.f.ds_revoke_buffer)(self.ds.0, h.0, &mut base, &mut private) };
            match lib.check("DSRevokeBuffer", r) {
                Ok(()) => {
                    BUFFERS.fetch_sub(1, Ordering::Relaxed);
                    // SAFETY: revoked: the producer no longer holds `memory`,
                    // allocated with `self.layout` in `new`.
                    unsafe { std::alloc::dealloc(memory, self.layout) };
                }
                Err(e) => {
                    tracing::warn!(producer = %lib.path().display(), error = %e,
                        "a GenTL buffer was not revoked: its memory is leaked, not freed under the producer");
                    result = Err(e);
                }
            }
        }
        result
    }
}

impl Drop for Announced {
    fn drop(&mut self) {
        if !self.buffers.is_empty() {
            // Not revoked (the library was gone): the producer may still
            // hold the memory, so it is leaked, never freed under it.
            tracing::warn!(
                buffers = self.buffers.len(),
                "GenTL buffers dropped without revoking: memory leaked"
            );
        }
    }
}

/// Now on the host's monotonic clock (`CLOCK_MONOTONIC`), ns.
pub(crate) fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if r != 0 {
        return 0;
    }
    (ts.tv_sec as u64).saturating_mul(1_000_000_000) + ts.tv_nsec as u64
}
