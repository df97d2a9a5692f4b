//! The safe GenTL module chain: system → interface → device → data stream.
//!
//! - [`System`]: one per producer file in the process (`GCInitLib` and
//!   `TLOpen` once, shared by every source and listing using that file;
//!   closed with its interfaces when the last user is gone);
//! - [`list_devices`]: every device of every interface, with vendor,
//!   model, serial number and interface (for `photopose camera list`);
//! - [`Opened`]: one device opened with its first data stream, our
//!   preallocated buffers announced and queued, the NEW_BUFFER event
//!   registered and acquisition started; [`Opened::next`] waits for a
//!   filled buffer, lends its bytes and queues it again; [`Opened::close`]
//!   stops, flushes, revokes, unregisters and closes in the standard's
//!   order.
//!
//! Discovery and opening go through a lock per system (producers are
//! thread-safe, but interface handles are shared); nothing here runs on
//! the frame path except [`Opened::next`].

use crate::abi;
use crate::error::GentlError;
use crate::ffi::{Announced, CallError, Handle, Kind, Library};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::time::{Duration, Instant};

/// Libraries loaded in this process, never unloaded (see `ffi::Library`).
static LIBRARIES: Mutex<Vec<(PathBuf, &'static Library)>> = Mutex::new(Vec::new());
/// Open systems by producer file.
static SYSTEMS: Mutex<Vec<(PathBuf, Weak<System>)>> = Mutex::new(Vec::new());

fn library(path: &Path) -> Result<&'static Library, GentlError> {
    let mut libs = LIBRARIES.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some((_, lib)) = libs.iter().find(|(p, _)| p == path) {
        return Ok(lib);
    }
    let lib: &'static Library = Box::leak(Box::new(Library::load(path)?));
    libs.push((path.to_path_buf(), lib));
    Ok(lib)
}

/// Checks that `path` is a regular file (the error names it).
pub fn check_producer_file(path: &Path) -> Result<PathBuf, GentlError> {
    let missing = |reason: String| GentlError::MissingProducer {
        path: path.to_path_buf(),
        reason,
    };
    let meta = std::fs::metadata(path).map_err(|e| missing(e.to_string()))?;
    if !meta.is_file() {
        return Err(missing("not a regular file".into()));
    }
    std::fs::canonicalize(path).map_err(|e| missing(e.to_string()))
}

/// An initialised producer with its system (transport layer) module open.
pub struct System {
    lib: &'static Library,
    tl: Handle,
    /// Interfaces opened so far (id, handle), closed with the system;
    /// the lock also serialises discovery and opening.
    interfaces: Mutex<Vec<(String, Handle)>>,
}

impl std::fmt::Debug for System {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("System")
            .field("producer", &self.lib.path())
            .finish()
    }
}

impl System {
    /// The system of the producer at `path`: the one already open in this
    /// process, or a new one (loads the file, `GCInitLib`, `TLOpen`).
    pub fn open(path: &Path) -> Result<Arc<System>, GentlError> {
        let path = check_producer_file(path)?;
        let t0 = Instant::now();
        loop {
            let mut systems = SYSTEMS.lock().unwrap_or_else(PoisonError::into_inner);
            match systems.iter().position(|(p, _)| *p == path) {
                Some(i) => {
                    if let Some(s) = systems[i].1.upgrade() {
                        return Ok(s);
                    }
                    // Its last user is closing it: wait until it is closed
                    // (the producer refuses a second GCInitLib meanwhile).
                    drop(systems);
                    if t0.elapsed() > Duration::from_secs(30) {
                        return Err(GentlError::InvalidProducer {
                            path,
                            reason: "its previous use did not close within 30 s".into(),
                        });
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                None => {
                    let lib = library(&path)?;
                    lib.init().map_err(|e| GentlError::call(&path, e))?;
                    let tl = match lib.tl_open() {
                        Ok(tl) => tl,
                        Err(e) => {
                            let _ = lib.close_lib();
                            return Err(GentlError::call(&path, e));
                        }
                    };
                    let s = Arc::new(System {
                        lib,
                        tl,
                        interfaces: Mutex::new(Vec::new()),
                    });
                    systems.push((path, Arc::downgrade(&s)));
                    return Ok(s);
                }
            }
        }
    }

    /// The producer file.
    pub fn path(&self) -> &Path {
        self.lib.path()
    }

    fn err(&self, e: CallError) -> GentlError {
        GentlError::call(self.lib.path(), e)
    }

    /// Every device of every interface (ids fresh from the producer; the
    /// caller holds the interfaces' lock).
    fn discover(
        &self,
        interfaces: &mut Vec<(String, Handle)>,
        timeout: Duration,
    ) -> Result<Vec<(Handle, String)>, GentlError> {
        let ms = timeout.as_millis().min(u128::from(u32::MAX)) as u64;
        let ids = self
            .lib
            .interface_ids(self.tl, ms)
            .map_err(|e| self.err(e))?;
        let mut devices = Vec::new();
        for id in ids {
            let iface = match interfaces.iter().find(|(i, _)| *i == id) {
                Some(&(_, h)) => h,
                None => {
                    let h = self
                        .lib
                        .open_interface(self.tl, &id)
                        .map_err(|e| self.err(e))?;
                    interfaces.push((id.clone(), h));
                    h
                }
            };
            for dev in self.lib.device_ids(iface, ms).map_err(|e| self.err(e))? {
                devices.push((iface, dev));
            }
        }
        Ok(devices)
    }

    fn info(&self, iface_id: &str, iface: Handle, id: &str) -> DeviceInfo {
        let s = |cmd| self.lib.device_info(iface, id, cmd);
        DeviceInfo {
            id: id.to_string(),
            interface: iface_id.to_string(),
            vendor: s(abi::DEVICE_INFO_VENDOR),
            model: s(abi::DEVICE_INFO_MODEL),
            serial: s(abi::DEVICE_INFO_SERIAL_NUMBER),
            display_name: s(abi::DEVICE_INFO_DISPLAYNAME),
            transport: s(abi::DEVICE_INFO_TLTYPE),
        }
    }

    /// Every device the producer sees, with what it says of each.
    pub fn devices(&self, timeout: Duration) -> Result<Vec<DeviceInfo>, GentlError> {
        let mut interfaces = self
            .interfaces
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        let found = self.discover(&mut interfaces, timeout)?;
        Ok(found
            .iter()
            .map(|(iface, id)| {
                let iface_id = interfaces
                    .iter()
                    .find(|(_, h)| h == iface)
                    .map(|(i, _)| i.as_str())
                    .unwrap_or_default();
                self.info(iface_id, *iface, id)
            })
            .collect())
    }

    /// Opens the device whose id or serial number is `wanted` (the first
    /// device found when `None`) with its first data stream, announces
    /// `buffers` buffers of ours (more if the producer asks for more) of
    /// the stream's payload size (`payload_size` when it does not say),
    /// queues them and starts acquisition.
    pub fn open_device(
        self: &Arc<System>,
        wanted: Option<&str>,
        buffers: usize,
        payload_size: Option<usize>,
        timeout: Duration,
    ) -> Result<Opened, GentlError> {
        let (iface, info) = {
            let mut interfaces = self
                .interfaces
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            let found = self.discover(&mut interfaces, timeout)?;
            let infos: Vec<(Handle, DeviceInfo)> = found
                .iter()
                .map(|(iface, id)| {
                    let iface_id = interfaces
                        .iter()
                        .find(|(_, h)| h == iface)
                        .map(|(i, _)| i.clone())
                        .unwrap_or_default();
                    (*iface, self.info(&iface_id, *iface, id))
                })
                .collect();
            let pick = infos.iter().find(|(_, d)| match wanted {
                None => true,
                Some(w) => d.id == w || d.serial.as_deref() == Some(w),
            });
            match pick {
                Some((iface, d)) => (*iface, d.clone()),
                None => {
                    return Err(GentlError::NoDevice {
                        path: self.path().to_path_buf(),
                        wanted: wanted.map_or("at all".into(), |w| format!("\"{w}\"")),
                        found: if infos.is_empty() {
                            "none".into()
                        } else {
                            infos
                                .iter()
                                .map(|(_, d)| {
                                    format!(
                                        "{} (serial {})",
                                        d.id,
                                        d.serial.as_deref().unwrap_or("?")
                                    )
                                })
                                .collect::<Vec<_>>()
                                .join(", ")
                        },
                    })
                }
            }
        };
        let lib = self.lib;
        let dev = lib
            .open_device(iface, &info.id, abi::DEVICE_ACCESS_EXCLUSIVE)
            .or_else(|_| lib.open_device(iface, &info.id, abi::DEVICE_ACCESS_CONTROL))
            .map_err(|e| self.err(e))?;
        let mut opened = Opened {
            system: Arc::clone(self),
            info,
            dev: Some(dev),
            ds: None,
            event: None,
            buffers: None,
            started: false,
            remote: None,
            camera_started: false,
            timestamp_hz: None,
        };
        opened.timestamp_hz = lib
            .device_info_u64(iface, &opened.info.id, abi::DEVICE_INFO_TIMESTAMP_FREQUENCY)
            .filter(|&hz| hz > 0);
        // On a failure below, dropping `opened` closes what it got.
        opened.set_up(buffers, payload_size)?;
        Ok(opened)
    }
}

impl Drop for System {
    fn drop(&mut self) {
        // Held while closing, so a new opening of the same file waits.
        let mut systems = SYSTEMS.lock().unwrap_or_else(PoisonError::into_inner);
        let interfaces = std::mem::take(
            &mut *self
                .interfaces
                .lock()
                .unwrap_or_else(PoisonError::into_inner),
        );
        for (id, h) in interfaces {
            if let Err(e) = self.lib.close(Kind::Interface, h) {
                tracing::debug!(interface = %id, error = %e, "closing a GenTL interface");
            }
        }
        if let Err(e) = self.lib.close(Kind::System, self.tl) {
            tracing::debug!(error = %e, "closing a GenTL system");
        }
        if let Err(e) = self.lib.close_lib() {
            tracing::debug!(error = %e, "closing a GenTL producer");
        }
        systems.retain(|(p, w)| !(p == self.lib.path() && w.strong_count() == 0));
    }
}

/// What a producer says of one device.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DeviceInfo {
    /// The device id (unique within its interface; `[source.gentl] device`).
    pub id: String,
    /// The interface (frame grabber, port) it is on.
    pub interface: String,
    /// Vendor name.
    pub vendor: Option<String>,
    /// Model name.
    pub model: Option<String>,
    /// Serial number (`[source.gentl] device` takes it too).
    pub serial: Option<String>,
    /// The producer's display name.
    pub display_name: Option<String>,
    /// Transport layer type (`CL`, `CXP`, `GEV`, `U3V`, `Mixed`, `Custom`).
    pub transport: Option<String>,
}

/// Every device the producer at `producer` sees (opens the producer for
/// the call unless it is open in this process already).
pub fn list_devices(producer: &Path) -> Result<Vec<DeviceInfo>, GentlError> {
    System::open(producer)?.devices(Duration::from_secs(1))
}

/// A filled buffer's description (`DSGetBufferInfo`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Delivered {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels (the delivered height when the producer says it).
    pub height: u32,
    /// PFNC pixel format.
    pub pfnc: u64,
    /// The pixel format's namespace (0 when the producer does not say).
    pub namespace: u64,
    /// Bytes written.
    pub filled: usize,
    /// Where the image starts in the buffer.
    pub image_offset: usize,
    /// Padding at the end of each line, bytes.
    pub x_padding: usize,
    /// The producer marked it incomplete.
    pub incomplete: bool,
    /// The device's frame id, if given.
    pub frame_id: Option<u64>,
    /// The device's timestamp, ns (converted from ticks when the producer
    /// gives no ns value), if given and not 0.
    pub timestamp_ns: Option<u64>,
}

/// Why [`Opened::next`] gave no frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WaitError {
    /// No buffer within the timeout.
    Timeout,
    /// The stream failed (device lost, aborted): the device must be
    /// reopened.
    Failed(GentlError),
}

/// A device opened with its data stream streaming into our buffers.
pub struct Opened {
    system: Arc<System>,
    info: DeviceInfo,
    dev: Option<Handle>,
    ds: Option<Handle>,
    event: Option<Handle>,
    buffers: Option<Announced>,
    started: bool,
    /// The camera's registers and description, when readable.
    remote: Option<(Handle, String)>,
    /// `AcquisitionStart` was executed on the camera.
    camera_started: bool,
    timestamp_hz: Option<u64>,
}

impl std::fmt::Debug for Opened {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Opened")
            .field("producer", &self.system.path())
            .field("device", &self.info)
            .finish()
    }
}

impl Opened {
    fn set_up(&mut self, buffers: usize, payload_size: Option<usize>) -> Result<(), GentlError> {
        let lib = self.system.lib;
        let device = self.info.id.clone();
        let stream_err = |reason: &str| GentlError::Stream {
            device: device.clone(),
            reason: reason.into(),
        };
        let id = lib
            .first_stream_id(self.dev.ok_or_else(|| stream_err("closed"))?)
            .map_err(|e| self.system.err(e))?
            .ok_or_else(|| stream_err("it has no data stream"))?;
        let ds = lib
            .open_stream(self.dev.ok_or_else(|| stream_err("closed"))?, &id)
            .map_err(|e| self.system.err(e))?;
        self.ds = Some(ds);
        self.remote = self.describe_remote();
        let payload = lib
            .stream_info(ds, abi::STREAM_INFO_PAYLOAD_SIZE)
            .filter(|&n| n > 0)
            .or_else(|| self.read_feature("PayloadSize").filter(|&n| n > 0))
            .or(payload_size.map(|n| n as u64))
            .ok_or_else(|| {
                stream_err(
                    "its data stream does not define the payload size (the remote device's \
                     PayloadSize does): set `payload_size` (bytes of one frame)",
                )
            })?;
        let min = lib
            .stream_info(ds, abi::STREAM_INFO_BUF_ANNOUNCE_MIN)
            .unwrap_or(1) as usize;
        let align = lib
            .stream_info(ds, abi::STREAM_INFO_BUF_ALIGNMENT)
            .unwrap_or(8) as usize;
        let count = buffers.max(min).min(1024);
        match Announced::new(lib, ds, count, payload as usize, align) {
            Ok(a) => self.buffers = Some(a),
            Err((e, partial)) => {
                self.buffers = Some(partial);
                return Err(self.system.err(e));
            }
        }
        self.event = Some(
            lib.register_new_buffer(ds)
                .map_err(|e| self.system.err(e))?,
        );
        lib.start(ds).map_err(|e| self.system.err(e))?;
        self.started = true;
        // The camera itself (a frame grabber's producer starts only the
        // grabber): its AcquisitionStart, when its description has one.
        match self.execute("AcquisitionStart") {
            Some(Ok(())) => self.camera_started = true,
            Some(Err(e)) => return Err(self.system.err(e)),
            None => tracing::debug!(device = %self.info.id,
                "no AcquisitionStart register found: the camera is expected to stream by itself"),
        }
        Ok(())
    }

    /// The camera's port and description file (best effort: `None` when
    /// the producer has no remote port or the file is not readable here).
    fn describe_remote(&self) -> Option<(Handle, String)> {
        let lib = self.system.lib;
        let port = lib.remote_port(self.dev?).ok()?;
        let url = lib.port_url(port).ok()?;
        let xml = match crate::genapi::parse_url(&url)? {
            crate::genapi::Url::Local {
                name,
                address,
                length,
            } => {
                if name.to_ascii_lowercase().ends_with(".zip") || length > 64 << 20 {
                    tracing::debug!(%url, "camera description is zipped or too large: not read");
                    return None;
                }
                let mut bytes = vec![0u8; length];
                lib.read_port(port, address, &mut bytes).ok()?;
                String::from_utf8_lossy(&bytes)
                    .trim_end_matches('\0')
                    .to_string()
            }
            crate::genapi::Url::File(path) => std::fs::read_to_string(path).ok()?,
        };
        Some((port, xml))
    }

    /// An integer feature of the camera read from its register.
    fn read_feature(&self, feature: &str) -> Option<u64> {
        let (port, xml) = self.remote.as_ref()?;
        let reg = crate::genapi::integer(xml, feature)?;
        let mut bytes = [0u8; 8];
        let n = reg.length.min(8);
        self.system
            .lib
            .read_port(*port, reg.address, &mut bytes[..n])
            .ok()?;
        Some(reg.decode(&bytes[..n]))
    }

    /// Executes a command feature of the camera (`None` when its
    /// description has no such register).
    fn execute(&self, feature: &str) -> Option<Result<(), CallError>> {
        let (port, xml) = self.remote.as_ref()?;
        let (reg, value) = crate::genapi::command(xml, feature)?;
        Some(
            self.system
                .lib
                .write_port(*port, reg.address, &reg.encode(value)),
        )
    }

    /// What the producer says of the device.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// The producer file.
    pub fn producer(&self) -> &Path {
        self.system.path()
    }

    /// Buffers announced to the stream.
    pub fn buffer_count(&self) -> usize {
        self.buffers.as_ref().map_or(0, Announced::len)
    }

    /// A number the data stream reports (`DSGetInfo`: `STREAM_INFO_*`).
    pub fn stream_info(&self, cmd: i32) -> Option<u64> {
        self.ds.and_then(|ds| self.system.lib.stream_info(ds, cmd))
    }

    /// Waits up to `timeout` for the next filled buffer, lends `f` its
    /// description and image bytes (from the image offset, `filled` bytes),
    /// then queues the buffer again. No allocation.
    pub fn next<R>(
        &mut self,
        timeout: Duration,
        f: impl FnOnce(&Delivered, &[u8]) -> R,
    ) -> Result<R, WaitError> {
        let lib = self.system.lib;
        let (Some(ds), Some(event), Some(buffers)) = (self.ds, self.event, self.buffers.as_ref())
        else {
            return Err(WaitError::Failed(GentlError::Stream {
                device: self.info.id.clone(),
                reason: "not streaming".into(),
            }));
        };
        let ms = timeout.as_millis().clamp(1, u128::from(u32::MAX)) as u64;
        let (buffer, index) = match lib.wait_new_buffer(event, ms) {
            Ok(b) => b,
            Err(e) if e.is_timeout() => return Err(WaitError::Timeout),
            Err(e) => return Err(WaitError::Failed(self.system.err(e))),
        };
        let n = |cmd| lib.buffer_info(ds, buffer, cmd);
        let timestamp_ns = n(abi::BUFFER_INFO_TIMESTAMP_NS)
            .filter(|&t| t > 0)
            .or_else(|| {
                let ticks = n(abi::BUFFER_INFO_TIMESTAMP).filter(|&t| t > 0)?;
                let hz = self.timestamp_hz.unwrap_or(1_000_000_000);
                Some((u128::from(ticks) * 1_000_000_000 / u128::from(hz)) as u64)
            });
        let height = n(abi::BUFFER_INFO_DELIVERED_IMAGEHEIGHT)
            .filter(|&h| h > 0)
            .or_else(|| n(abi::BUFFER_INFO_HEIGHT))
            .unwrap_or(0);
        let d = Delivered {
            width: n(abi::BUFFER_INFO_WIDTH)
                .unwrap_or(0)
                .min(u64::from(u32::MAX)) as u32,
            height: height.min(u64::from(u32::MAX)) as u32,
            pfnc: n(abi::BUFFER_INFO_PIXELFORMAT).unwrap_or(0),
            namespace: n(abi::BUFFER_INFO_PIXELFORMAT_NAMESPACE).unwrap_or(0),
            filled: n(abi::BUFFER_INFO_SIZE_FILLED).unwrap_or(0) as usize,
            image_offset: n(abi::BUFFER_INFO_IMAGEOFFSET).unwrap_or(0) as usize,
            x_padding: n(abi::BUFFER_INFO_XPADDING).unwrap_or(0) as usize,
            incomplete: n(abi::BUFFER_INFO_IS_INCOMPLETE).unwrap_or(0) != 0,
            frame_id: n(abi::BUFFER_INFO_FRAMEID),
            timestamp_ns,
        };
        let (out, queued) = buffers.consume(lib, index, buffer, d.filled, |bytes| {
            f(&d, bytes.get(d.image_offset..).unwrap_or(&[]))
        });
        if let Err(e) = queued {
            return Err(WaitError::Failed(self.system.err(e)));
        }
        out.ok_or_else(|| {
            WaitError::Failed(GentlError::Stream {
                device: self.info.id.clone(),
                reason: format!(
                    "the producer delivered a buffer not announced by us (user pointer {index})"
                ),
            })
        })
    }

    /// Stops acquisition, flushes the queues, revokes and frees the
    /// buffers, unregisters the event, closes the stream and the device
    /// (dropping does the same). Errors are logged: closing goes as far as
    /// it can.
    pub fn close(self) {
        drop(self);
    }

    fn shut(&mut self) {
        let lib = self.system.lib;
        let id = self.info.id.clone();
        let log = |what: &str, e: CallError| {
            tracing::debug!(device = %id, error = %e, "GenTL {what}");
        };
        if self.camera_started {
            if let Some(Err(e)) = self.execute("AcquisitionStop") {
                log("camera stop", e);
            }
            self.camera_started = false;
        }
        if let Some(ds) = self.ds.take() {
            // Stop (if started) and flush every queue before revoking.
            if let Err(e) = lib.stop(ds) {
                if self.started {
                    log("stop", e);
                }
            }
            self.started = false;
            if let Some(event) = self.event.take() {
                if let Err(e) = lib.unregister_new_buffer(ds, event) {
                    log("unregister", e);
                }
            }
            if let Some(b) = self.buffers.take() {
                if let Err(e) = b.revoke(lib) {
                    log("revoke", e);
                }
            }
            if let Err(e) = lib.close(Kind::Stream, ds) {
                log("stream close", e);
            }
        }
        if let Some(dev) = self.dev.take() {
            if let Err(e) = lib.close(Kind::Device, dev) {
                log("device close", e);
            }
        }
    }
}

impl Drop for Opened {
    fn drop(&mut self) {
        self.shut();
    }
}
