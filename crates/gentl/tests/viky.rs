//! The GenTL consumer against a third-party producer: `viky.cti`, the
//! software producer shipped in the official `genicam` wheel (3 simulated
//! devices, 400×400 RGBa8, about 20 frames/s, buffer timestamps 0).
//! `.ci/deps.sh` installs it at [`VIKY`]; without it these tests say so
//! and pass without running.
//!
//! Checked: the devices are listed; ≥ 100 frames are acquired (RGBa8
//! converted to grey), in order, with strictly increasing host monotonic
//! times (viky's own timestamps are 0, so the source leaves
//! `camera_time_ns` at 0 and the host times are what orders frames);
//! stopping and reopening the same device streams again; once every
//! source is dropped no GenTL handle or announced buffer is left open;
//! a device that does not exist is reported with the devices found.

use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_frame::Pixels;
use photopose_gentl::{list_devices, open_handles, GentlConfig, GentlSource};
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Where `.ci/deps.sh` puts viky.
const VIKY: &str = "/opt/photopose-test/gentl/viky.cti";

/// One producer state per process: the tests take turns.
static SERIAL: Mutex<()> = Mutex::new(());

fn viky() -> Option<&'static Path> {
    let p = Path::new(VIKY);
    if p.is_file() {
        Some(p)
    } else {
        eprintln!("skipped: {VIKY} is absent (installed by .ci/deps.sh)");
        None
    }
}

fn config(device: Option<&str>) -> GentlConfig {
    GentlConfig {
        device: device.map(str::to_string),
        buffers: 4,
        timeout: Duration::from_secs(5),
        backoff_initial: Duration::from_millis(50),
        backoff_max: Duration::from_millis(500),
        ..GentlConfig::new(VIKY.into())
    }
}

/// Acquires `n` frames (bounded: 60 s), returning their host monotonic times.
fn acquire(source: &mut GentlSource, slot: &mut Slot, n: usize) -> Vec<(u64, u64)> {
    let t0 = Instant::now();
    let mut got = Vec::new();
    let mut last = String::new();
    while got.len() < n {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "only {} of {n} frames within 60 s ({:?}; last: {last})",
            got.len(),
            source.stats()
        );
        match source.next_frame(slot, Duration::from_millis(500)) {
            Ok(()) => {
                assert_eq!((slot.image().width(), slot.image().height()), (400, 400));
                assert!(matches!(slot.image().pixels(), Pixels::Mono8(_)));
                got.push((slot.meta.seq, slot.meta.host_mono_ns));
            }
            Err(e @ (SourceError::Timeout(_) | SourceError::Unavailable { .. })) => {
                last = e.to_string()
            }
            Err(e) => panic!("viky: {e}"),
        }
    }
    got
}

#[test]
fn viky_lists_its_three_devices() {
    let Some(path) = viky() else { return };
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let devices = list_devices(path).unwrap();
    assert_eq!(devices.len(), 3, "{devices:#?}");
    for d in &devices {
        assert!(!d.id.is_empty() && !d.interface.is_empty(), "{d:?}");
    }
    let serials: Vec<_> = devices.iter().filter_map(|d| d.serial.clone()).collect();
    assert_eq!(serials.len(), 3, "{devices:#?}");
    assert!(open_handles().is_zero() || open_handles().devices == 0);
}

#[test]
fn viky_streams_stops_reopens_and_leaks_nothing() {
    let Some(_) = viky() else { return };
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let mut slot = Slot::new(photopose_frame::Image::new_mono8(400, 400));
    let mut source = GentlSource::new("viky", config(None)).unwrap();
    source.start().unwrap();
    let first = acquire(&mut source, &mut slot, 100);
    {
        let opened = source.opened().expect("streaming");
        assert_eq!(
            opened.stream_info(photopose_gentl::abi::STREAM_INFO_NUM_ANNOUNCED),
            Some(opened.buffer_count() as u64),
            "the producer holds our buffers"
        );
    }
    let during = open_handles();
    assert_eq!(during.devices, 1, "{during:?}");
    assert_eq!(during.streams, 1, "{during:?}");
    assert!(during.buffers >= 4, "{during:?}");
    for w in first.windows(2) {
        assert!(w[1].0 > w[0].0, "sequence numbers increase: {w:?}");
        assert!(w[1].1 > w[0].1, "host monotonic times increase: {w:?}");
    }
    assert_eq!(slot.meta.camera_time_ns, 0, "viky gives no timestamps");
    // Stop, then the same source again.
    source.stop();
    let t0 = Instant::now();
    while open_handles().devices != 0 {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "{:?}",
            open_handles()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_eq!(open_handles().buffers, 0, "buffers revoked at stop");
    source.start().unwrap();
    let again = acquire(&mut source, &mut slot, 20);
    assert!(
        again[0].0 > first.last().unwrap().0,
        "seq goes on across the reopening"
    );
    let stats = source.stats();
    assert_eq!(stats.opens, 2, "{stats:?}");
    assert!(stats.frames >= 120, "{stats:?}");
    drop(source);
    assert!(
        open_handles().is_zero(),
        "nothing left open: {:?}",
        open_handles()
    );
}

#[test]
fn viky_device_by_serial_and_an_absent_device() {
    let Some(path) = viky() else { return };
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let devices = list_devices(path).unwrap();
    let last = devices.last().unwrap();
    let serial = last.serial.clone().unwrap();
    let mut slot = Slot::new(photopose_frame::Image::new_mono8(400, 400));
    let mut source = GentlSource::new("viky", config(Some(&serial))).unwrap();
    source.start().unwrap();
    acquire(&mut source, &mut slot, 5);
    assert_eq!(source.opened().unwrap().info().id, last.id);
    drop(source);

    let mut source = GentlSource::new("viky", config(Some("no-such-camera"))).unwrap();
    source.start().unwrap();
    let t0 = Instant::now();
    let reason = loop {
        assert!(t0.elapsed() < Duration::from_secs(20), "no answer");
        match source.next_frame(&mut slot, Duration::from_millis(200)) {
            Err(SourceError::Unavailable { reason }) if reason.contains("no device") => {
                break reason
            }
            Err(SourceError::Timeout(_) | SourceError::Unavailable { .. }) => {}
            other => panic!("{other:?}"),
        }
    };
    assert!(
        reason.contains("no-such-camera") && reason.contains(&last.id),
        "{reason}"
    );
    drop(source);
    assert!(open_handles().is_zero(), "{:?}", open_handles());
}
