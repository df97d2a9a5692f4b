//! With the recording on, the frame path still allocates nothing once
//! warm: the tap copies each frame into a buffer of the preallocated pool
//! and the sink each pose line into a pooled buffer. Only the writer thread
//! (`record`: protobuf encoding, MCAP chunks, compression) allocates, so
//! this test's allocator counts every thread but that one.

// A global allocator implements an unsafe trait (it only forwards to
// `System`), and reading the thread's name goes through libc.
#![allow(unsafe_code)]

use photopose_field::design::default_plate;
use photopose_pipeline::config::Source;
use photopose_pipeline::sink::record::RecordLink;
use photopose_pipeline::source::SyntheticSource;
use photopose_pipeline::{Config, Pipeline, Supervision};
use std::alloc::{GlobalAlloc, Layout, System};
use std::net::UdpSocket;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

static COUNTED: AtomicUsize = AtomicUsize::new(0);

/// Whether the calling thread is the recording's writer (its name, read
/// with `prctl` through libc: no allocation).
fn on_writer_thread() -> bool {
    let mut name = [0u8; 16];
    // SAFETY: the buffer has the 16 bytes the call writes at most.
    let r = unsafe {
        libc::pthread_getname_np(libc::pthread_self(), name.as_mut_ptr().cast(), name.len())
    };
    r == 0 && name.starts_with(b"record\0")
}

struct FramePathAllocator;

// SAFETY: every call forwards to `System` unchanged; counting reads the
// thread's name and touches an atomic.
unsafe impl GlobalAlloc for FramePathAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !on_writer_thread() {
            COUNTED.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract, forwarded.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !on_writer_thread() {
            COUNTED.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract, forwarded.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if !on_writer_thread() {
            COUNTED.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract, forwarded.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract, forwarded.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: FramePathAllocator = FramePathAllocator;

#[test]
fn the_frame_path_does_not_allocate_while_recording() {
    let dir = std::env::temp_dir().join(format!("photopose-noalloc-rec-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.mcap");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut cfg = Config::parse(
        &format!(
            r#"
[source]
kind = "synthetic"
[source.synthetic]
rate_hz = 20.0
frames = 0
radius_mm = 40.0
period_s = 2.0
[pipeline]
workers = 2
slots = 6
overflow = "block"
max_age_ms = 5000.0
[output]
udp = ["{}"]
[record]
path = "{}"
compression = "lz4"
"#,
            rx.local_addr().unwrap(),
            path.display()
        ),
        "test",
    )
    .unwrap();
    let Source::Synthetic(syn) = cfg.source.clone() else {
        panic!("synthetic source expected")
    };
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let source = SyntheticSource::new(camera, &field, syn).unwrap();
    let bytes = camera.sensor.width as usize * camera.sensor.height as usize;
    let link = RecordLink::start(&cfg.record, Default::default(), bytes).unwrap();
    let source = link.tap(Box::new(source), &cfg.record);
    cfg.record.link = Some(link.clone());
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, source, Supervision::none()).unwrap();
    let mut buf = [0u8; 8192];
    let mut receive = |n: usize| {
        let mut got = 0;
        let t0 = Instant::now();
        while got < n {
            assert!(t0.elapsed() < Duration::from_secs(60), "poses stopped");
            if rx.recv(&mut buf).is_ok() {
                got += 1;
            }
        }
    };
    receive(30);
    let before = COUNTED.load(Ordering::Relaxed);
    receive(40);
    let allocated = COUNTED.load(Ordering::Relaxed) - before;
    pipeline.stop();
    pipeline.join();
    link.close();
    let stats = link.stats();
    let frames = stats.frames.load(Ordering::Relaxed);
    assert!(frames > 0, "frames were recorded");
    assert_eq!(
        allocated, 0,
        "allocations on the frame path while recording"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
