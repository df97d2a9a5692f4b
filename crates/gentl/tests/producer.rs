//! The GenTL consumer against the workspace's test producer
//! (`photopose-gentl-producer`, built as a `.cti` next to this test):
//! device listing, frames with the producer's frame ids and timestamps,
//! nothing left open after dropping the source, no allocation per frame
//! once warm, and clear errors for a missing or invalid producer file.

use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_frame::{Image, Pixels};
use photopose_gentl::{list_devices, open_handles, GentlConfig, GentlError, GentlSource};
use photopose_gentl_producer as producer;
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[global_allocator]
static GLOBAL: photopose_testkit::CountingAllocator = photopose_testkit::CountingAllocator;

/// One producer state per process: the tests take turns.
static SERIAL: Mutex<()> = Mutex::new(());

/// The test producer cargo built for this test (a dev-dependency).
fn test_producer() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap();
    let name = "libphotopose_gentl_producer.so";
    [deps.join(name), deps.join("..").join(name)]
        .into_iter()
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("{name} not built next to {}", exe.display()))
}

fn config() -> GentlConfig {
    GentlConfig {
        buffers: 3,
        timeout: Duration::from_secs(10),
        ..GentlConfig::new(test_producer())
    }
}

fn next(source: &mut GentlSource, slot: &mut Slot) {
    let t0 = Instant::now();
    loop {
        assert!(t0.elapsed() < Duration::from_secs(60), "no frame in 60 s");
        match source.next_frame(slot, Duration::from_millis(500)) {
            Ok(()) => return,
            Err(SourceError::Timeout(_) | SourceError::Unavailable { .. }) => {}
            Err(e) => panic!("{e}"),
        }
    }
}

#[test]
fn the_test_producer_lists_its_device() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let devices = list_devices(&test_producer()).unwrap();
    assert_eq!(devices.len(), 1, "{devices:?}");
    let d = &devices[0];
    assert_eq!(d.id, producer::DEVICE_ID);
    assert_eq!(d.serial.as_deref(), Some(producer::SERIAL));
    assert_eq!(d.interface, producer::INTERFACE_ID);
    assert_eq!(d.vendor.as_deref(), Some("photopose"));
    assert!(d.model.is_some());
}

#[test]
fn frames_carry_ids_and_timestamps_and_nothing_leaks_or_allocates() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let camera = photopose_formats::default_camera();
    let (w, h) = (camera.sensor.width, camera.sensor.height);
    let mut slot = Slot::new(Image::new_mono8(w, h));
    let mut source = GentlSource::new(
        "render",
        GentlConfig {
            device: Some(producer::SERIAL.into()),
            ..config()
        },
    )
    .unwrap();
    source.start().unwrap();
    next(&mut source, &mut slot);
    let first = slot.meta;
    assert_eq!(first.camera_frame_id, 1);
    assert_eq!(first.camera_time_ns, producer::timestamp_ns(1));
    assert!(first.host_mono_ns > 0 && first.host_time_ns > 0);
    assert!(matches!(slot.image().pixels(), Pixels::Mono8(_)));
    assert_eq!((slot.image().width(), slot.image().height()), (w, h));
    // Warm: the next frames allocate nothing on this thread.
    let before = photopose_testkit::allocations();
    for k in 2..=4u64 {
        next(&mut source, &mut slot);
        assert_eq!(slot.meta.camera_frame_id, k);
        assert_eq!(slot.meta.seq, k - 1);
        assert_eq!(slot.meta.camera_time_ns, producer::timestamp_ns(k));
    }
    let allocated = photopose_testkit::allocations() - before;
    assert_eq!(allocated, 0, "allocations while acquiring 3 frames");
    let stats = source.stats();
    assert_eq!((stats.frames, stats.missing, stats.incomplete), (4, 0, 0));
    drop(source);
    assert!(
        open_handles().is_zero(),
        "nothing left open: {:?}",
        open_handles()
    );
}

#[test]
fn a_missing_or_invalid_producer_is_named() {
    let dir = std::env::temp_dir().join(format!("photopose-gentl-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let missing = dir.join("absent.cti");
    let e = GentlSource::new("x", GentlConfig::new(missing.clone())).unwrap_err();
    assert!(matches!(e, GentlError::MissingProducer { .. }), "{e}");
    assert!(e.to_string().contains(&*missing.to_string_lossy()), "{e}");
    // Not a shared library at all.
    let text = dir.join("text.cti");
    std::fs::write(&text, "not a producer\n").unwrap();
    let e = GentlSource::new("x", GentlConfig::new(text.clone())).unwrap_err();
    assert!(matches!(e, GentlError::InvalidProducer { .. }), "{e}");
    assert!(e.to_string().contains("text.cti"), "{e}");
    // A shared library that is no GenTL producer: the C library itself.
    let libc = [
        "/lib/x86_64-linux-gnu/libc.so.6",
        "/usr/lib/x86_64-linux-gnu/libc.so.6",
    ]
    .into_iter()
    .map(PathBuf::from)
    .find(|p| p.is_file());
    if let Some(libc) = libc {
        let e = GentlSource::new("x", GentlConfig::new(libc)).unwrap_err();
        assert!(e.to_string().contains("exports no `GCInitLib`"), "{e}");
    }
}
