//! Opening and closing a GigE Vision camera through aravis: discovery
//! (serialised, it is global state), configuration, the stream with its
//! buffers; closing a camera that may be dead (each register access then
//! blocks about 2.5 s) — done on the source's helper threads, never on the
//! frame path.

use super::config::{FeatureValue, GigeConfig, PixelDepth};
use crate::exposure::ExposureSettings;
use crate::ffi;
use aravis::prelude::*;
use aravis::{AcquisitionMode, Buffer, Camera, DeviceError, PixelFormat, Stream};
use glib::prelude::Cast;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// Aravis' device discovery is global state: one opening at a time.
static OPEN_LOCK: Mutex<()> = Mutex::new(());

/// An opened, streaming camera.
pub(super) struct Opened {
    pub(super) camera: Camera,
    pub(super) stream: Stream,
    pub(super) control_lost: Arc<AtomicBool>,
    pub(super) id: String,
    pub(super) took: Duration,
    /// The exposure time the camera reports (`ExposureTime`), ns; 0 when
    /// it cannot be read.
    pub(super) exposure_ns: u64,
    /// Bytes per frame on the wire (the payload).
    pub(super) payload: usize,
    /// With exposure control: the camera's exposure feature and the
    /// range the loop may set, µs (its limits within the camera's).
    pub(super) exposure_control: Option<ExposureNode>,
}

/// The exposure feature the control loop writes, found at opening.
#[derive(Debug, Clone, Copy)]
pub(super) struct ExposureNode {
    /// `ExposureTime` (SFNC) or `ExposureTimeAbs` (older cameras).
    pub(super) feature: &'static str,
    /// The loop's limits narrowed to the camera's range, µs.
    pub(super) range: (f64, f64),
}

pub(super) enum OpenError {
    /// Not there (or not answering): try again later.
    Absent(String),
    /// The camera refuses the configuration: fatal.
    Config { what: String, reason: String },
}

pub(super) fn transient(e: &glib::Error) -> bool {
    matches!(
        e.kind::<DeviceError>(),
        Some(
            DeviceError::Timeout
                | DeviceError::TransferError
                | DeviceError::NotConnected
                | DeviceError::NotFound
                | DeviceError::ProtocolError
        )
    )
}

pub(super) fn setting(what: &str) -> impl Fn(glib::Error) -> OpenError + '_ {
    move |e| {
        if transient(&e) {
            OpenError::Absent(format!("{what}: {e}"))
        } else {
            OpenError::Config {
                what: what.into(),
                reason: e.to_string(),
            }
        }
    }
}

pub(super) fn open(
    config: &GigeConfig,
    resolved: &mut Option<String>,
) -> Result<Opened, OpenError> {
    let t0 = Instant::now();
    let guard = OPEN_LOCK.lock().unwrap_or_else(PoisonError::into_inner);
    // A serial number is resolved to its device id by one discovery (about
    // 1 s); the id found is kept, so reopening the same camera is fast.
    let t_find = Instant::now();
    let name = match (resolved.clone(), config.camera.as_deref()) {
        (Some(id), _) => Some(id),
        (None, Some(want)) => {
            Some(ffi::device_id_of_serial(want).unwrap_or_else(|| want.to_string()))
        }
        (None, None) => None,
    };
    let find_ms = t_find.elapsed().as_millis() as u64;
    let camera = Camera::new(name.as_deref()).map_err(|e| {
        OpenError::Absent(format!(
            "opening {}: {e}",
            name.as_deref().unwrap_or("the first camera")
        ))
    })?;
    if config.camera.is_some() {
        resolved.clone_from(&name);
    }
    tracing::debug!(
        name = name.as_deref().unwrap_or("-"),
        find_ms,
        open_ms = t0.elapsed().as_millis() as u64,
        "camera found"
    );
    drop(guard);
    let id = camera
        .device_id()
        .map(|s| s.to_string())
        .unwrap_or_else(|_| config.camera.clone().unwrap_or_default());

    let format = match config.pixel {
        PixelDepth::Mono8 => PixelFormat::MONO_8,
        PixelDepth::Mono16 => PixelFormat::MONO_16,
    };
    camera
        .set_pixel_format(format)
        .map_err(setting("pixel format"))?;
    if let Some(r) = config.roi {
        camera
            .set_region(r.x as i32, r.y as i32, r.width as i32, r.height as i32)
            .map_err(setting("roi"))?;
    }
    if let Some(us) = config.exposure_us {
        camera.set_exposure_time(us).map_err(setting("exposure"))?;
    }
    if let Some(g) = config.gain {
        camera.set_gain(g).map_err(setting("gain"))?;
    }
    if let Some(fps) = config.frame_rate {
        camera.set_frame_rate(fps).map_err(setting("frame rate"))?;
    }
    for (name, value) in &config.features {
        set_feature(&camera, name, value)?;
    }
    let exposure_control = match &config.exposure_control {
        Some(settings) => Some(exposure_node(&camera, settings)?),
        None => None,
    };
    if camera.is_gv_device() {
        if let Some(p) = config.packet_size {
            camera
                .gv_set_packet_size(p as i32)
                .map_err(setting("packet size"))?;
        }
        if !config.packet_socket {
            // Must precede create_stream.
            camera.gv_set_stream_options(aravis::GvStreamOption::PACKET_SOCKET_DISABLED);
        }
    }
    camera
        .set_acquisition_mode(AcquisitionMode::Continuous)
        .map_err(setting("acquisition mode"))?;
    let payload = camera.payload().map_err(setting("payload"))? as usize;
    // What the camera really uses (it may round the asked value); the
    // exposure instant is its middle.
    let exposure_us = match exposure_control {
        Some(node) => camera.float(node.feature),
        None => camera.exposure_time(),
    };
    let exposure_ns = match exposure_us {
        Ok(us) if us.is_finite() && us > 0.0 => (us * 1e3).round() as u64,
        _ => 0,
    };

    let stream = camera.create_stream().map_err(setting("stream"))?;
    if let Some(gv) = stream.downcast_ref::<aravis::GvStream>() {
        gv.set_socket_buffer(aravis::GvStreamSocketBuffer::Auto);
    }
    for _ in 0..config.buffers {
        stream.push_buffer(Buffer::new_allocate(payload));
    }

    let control_lost = Arc::new(AtomicBool::new(false));
    if let Some(device) = camera.device() {
        let flag = Arc::clone(&control_lost);
        device.connect_control_lost(move |_| flag.store(true, Ordering::Release));
    }
    camera.start_acquisition().map_err(setting("start"))?;
    Ok(Opened {
        camera,
        stream,
        control_lost,
        id,
        took: t0.elapsed(),
        exposure_ns,
        payload,
        exposure_control,
    })
}

/// Finds the exposure feature the control loop writes (`ExposureTime`,
/// else `ExposureTimeAbs`), turns the camera's own automatic exposure off
/// where it has one, narrows the loop's limits to the camera's range and
/// brings the exposure inside them. A camera with neither feature, or
/// whose range misses the limits, refuses the configuration.
fn exposure_node(camera: &Camera, settings: &ExposureSettings) -> Result<ExposureNode, OpenError> {
    const WHAT: &str = "source.gige.exposure_control";
    let Some(device) = camera.device() else {
        return Err(OpenError::Config {
            what: WHAT.into(),
            reason: "the camera has no device to steer the exposure on".into(),
        });
    };
    let writable = |name: &str| {
        device.feature(name).is_some_and(|node| {
            node.downcast_ref::<aravis::GcFeatureNode>()
                .is_none_or(|f| f.actual_access_mode() != aravis::GcAccessMode::Ro)
        })
    };
    let Some(feature) = ["ExposureTime", "ExposureTimeAbs"]
        .into_iter()
        .find(|name| writable(name))
    else {
        return Err(OpenError::Config {
            what: WHAT.into(),
            reason: "the camera has no writable ExposureTime or ExposureTimeAbs feature".into(),
        });
    };
    if device.feature("ExposureAuto").is_some() {
        // The camera's own loop would fight ours.
        if let Err(e) = camera.set_string("ExposureAuto", "Off") {
            if transient(&e) {
                return Err(OpenError::Absent(format!("ExposureAuto: {e}")));
            }
            tracing::warn!(error = %e, "ExposureAuto could not be turned off; the camera's automatic exposure may fight the control loop");
        }
    }
    let (lo, hi) = match camera.float_bounds(feature) {
        Ok((lo, hi)) if lo.is_finite() && hi.is_finite() && lo <= hi => (lo, hi),
        _ => (0.0, f64::MAX),
    };
    let (min, max) = (settings.min_us.max(lo), settings.max_us.min(hi));
    if min > max {
        return Err(OpenError::Config {
            what: format!("{WHAT}.min_us/max_us"),
            reason: format!(
                "[{}, {}] µs misses the camera's {feature} range [{lo}, {hi}] µs",
                settings.min_us, settings.max_us
            ),
        });
    }
    let now = camera.float(feature).map_err(setting(feature))?;
    if !(now.is_finite() && (min..=max).contains(&now)) {
        let inside = if now.is_finite() {
            now.clamp(min, max)
        } else {
            min
        };
        camera
            .set_float(feature, inside)
            .map_err(setting(feature))?;
        tracing::info!(
            feature,
            from_us = now,
            to_us = inside,
            "exposure brought inside the control loop's limits"
        );
    }
    Ok(ExposureNode {
        feature,
        range: (min, max),
    })
}

/// Writes one GenICam feature of `[source.gige.features]`: the feature must
/// be in the camera's node map, an enumeration's value one of its entries,
/// and the camera must take it; otherwise the opening fails naming the
/// feature (a configuration error, not a reason to retry).
fn set_feature(camera: &Camera, name: &str, value: &FeatureValue) -> Result<(), OpenError> {
    let what = format!("source.gige.features.{name}");
    let refused = |reason: String| OpenError::Config {
        what: what.clone(),
        reason,
    };
    let Some(device) = camera.device() else {
        return Err(refused(
            "the camera has no device to set features on".into(),
        ));
    };
    let Some(node) = device.feature(name) else {
        return Err(refused(
            "no such feature in the camera's node map (arv-tool-0.8 features lists them)".into(),
        ));
    };
    if let Some(f) = node.downcast_ref::<aravis::GcFeatureNode>() {
        if f.actual_access_mode() == aravis::GcAccessMode::Ro {
            return Err(refused("the feature is read-only".into()));
        }
    }
    if let (Some(e), FeatureValue::Text(v)) = (node.downcast_ref::<aravis::GcEnumeration>(), value)
    {
        let entries: Vec<String> = e
            .dup_available_string_values()
            .map(|l| l.iter().map(|s| s.to_string()).collect())
            .unwrap_or_default();
        if !entries.is_empty() && !entries.iter().any(|x| x == v) {
            return Err(refused(format!(
                "\"{v}\" is not one of its entries ({})",
                entries.join(", ")
            )));
        }
    }
    let written = match value {
        FeatureValue::Int(v) => camera.set_integer(name, *v),
        FeatureValue::Float(v) => camera.set_float(name, *v),
        FeatureValue::Bool(v) => camera.set_boolean(name, *v),
        FeatureValue::Text(v) => camera.set_string(name, v),
    };
    // An integer the camera silently clamps or rounds is a value it refused.
    let written = written.and_then(|()| match value {
        FeatureValue::Int(v) => camera
            .integer(name)
            .map(|kept| (kept != *v).then_some(kept)),
        _ => Ok(None),
    });
    match written {
        Ok(None) => {
            tracing::debug!(feature = name, %value, "feature set");
            Ok(())
        }
        Ok(Some(kept)) => Err(refused(format!("{value} refused: the camera keeps {kept}"))),
        Err(e) if transient(&e) => Err(OpenError::Absent(format!("{what}: {e}"))),
        Err(e) => Err(refused(format!("{value} refused: {e}"))),
    }
}

/// One camera a discovery found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraInfo {
    /// The device id `[source.gige] camera` takes (as `arv-tool-0.8` lists it).
    pub id: String,
    /// Vendor.
    pub vendor: String,
    /// Model.
    pub model: String,
    /// Serial number (also accepted by `[source.gige] camera`).
    pub serial: String,
    /// Network address (GigE Vision) or bus address.
    pub address: String,
    /// Transport as aravis names it (`GigEVision`, `USB3Vision`, `Fake`).
    pub protocol: String,
}

/// The cameras aravis finds now (GigE Vision and USB3 Vision), by one
/// discovery, serialised with every opening in the process.
pub fn list_cameras() -> Vec<CameraInfo> {
    let _guard = OPEN_LOCK.lock().unwrap_or_else(PoisonError::into_inner);
    crate::ffi::devices()
        .into_iter()
        .map(
            |[id, vendor, model, serial, address, protocol]| CameraInfo {
                id,
                vendor,
                model,
                serial,
                address,
                protocol,
            },
        )
        .collect()
}

/// Stops (unless `lost`) and drops a camera: slow if the camera is dead,
/// so never on the acquisition path. A lost camera gets no "stop": its
/// address may already serve a restarted camera, which a stale handle
/// would talk to.
pub(super) fn close(o: Opened, lost: bool) {
    let t0 = Instant::now();
    if !lost {
        let _ = o.camera.stop_acquisition();
    }
    drop(o.stream);
    drop(o.camera);
    tracing::debug!(camera = %o.id, lost, took_ms = t0.elapsed().as_millis() as u64, "camera closed");
}
