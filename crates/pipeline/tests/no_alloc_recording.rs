//! With the recording on, the frame path still allocates nothing once
//! warm: the tap copies each frame into a buffer of the preallocated pool
//! and the sink each pose line (and the frame's targets, from the result's
//! pooled list) into a pooled buffer. Only the writer thread
//! (`record`: protobuf encoding, MCAP chunks, compression) allocates, so
//! this test's allocator counts every thread but that one.

mod common;
use common::{synthetic_source, Poses};
use photopose_pipeline::sink::record::RecordLink;
use photopose_pipeline::{Pipeline, Supervision};
use photopose_testkit::{allocations_outside, exclude_thread, CountingAllocator};
use std::sync::atomic::Ordering;

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_frame_path_does_not_allocate_while_recording() {
    // The writer thread encodes and compresses: off the frame path.
    exclude_thread("record");
    let dir = std::env::temp_dir().join(format!("photopose-noalloc-rec-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.mcap");
    let mut udp = Poses::bind();
    let mut cfg = udp.config(
        20.0,
        &format!(
            r#"
[record]
path = "{}"
compression = "lz4"
"#,
            path.display()
        ),
    );
    let (camera, field, source) = synthetic_source(&cfg);
    let bytes = camera.sensor.width as usize * camera.sensor.height as usize;
    let link = RecordLink::start(&cfg.record, Default::default(), bytes).unwrap();
    let source = link.tap(Box::new(source), &cfg.record);
    cfg.record.link = Some(link.clone());
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, source, Supervision::none()).unwrap();
    udp.receive(30);
    let before = allocations_outside();
    udp.receive(40);
    let allocated = allocations_outside() - before;
    pipeline.stop();
    pipeline.join();
    link.close();
    let stats = link.stats();
    let frames = stats.frames.load(Ordering::Relaxed);
    assert!(frames > 0, "frames were recorded");
    // The targets went with the poses of the recorded frames.
    assert!(stats.annotations.load(Ordering::Relaxed) > 0);
    assert_eq!(
        allocated, 0,
        "allocations on the frame path while recording"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
