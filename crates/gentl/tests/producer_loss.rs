//! A GenTL device lost while streaming (the test producer's stream fails
//! after 3 frames, as an unplugged camera's does): the source reports the
//! loss once, closes the device off the frame path, reopens it with
//! back-off and streams again, `seq` going on; nothing is left open at
//! the end. One test in this binary: the producer reads its test hook
//! from the environment at `GCInitLib`.

use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_frame::Image;
use photopose_gentl::{open_handles, GentlConfig, GentlSource};
use std::time::{Duration, Instant};

fn test_producer() -> std::path::PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap();
    let name = "libphotopose_gentl_producer.so";
    [deps.join(name), deps.join("..").join(name)]
        .into_iter()
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("{name} not built next to {}", exe.display()))
}

#[test]
fn a_lost_device_is_reported_once_and_reopened() {
    // The only test of this binary: no other thread reads the environment.
    std::env::set_var(photopose_gentl_producer::UNPLUG_VAR, "3");
    let mut source = GentlSource::new(
        "loss",
        GentlConfig {
            buffers: 2,
            timeout: Duration::from_secs(10),
            backoff_initial: Duration::from_millis(20),
            backoff_max: Duration::from_millis(200),
            ..GentlConfig::new(test_producer())
        },
    )
    .unwrap();
    let mut slot = Slot::new(Image::new_mono8(8, 8));
    source.start().unwrap();
    let (mut seqs, mut lost) = (Vec::new(), Vec::new());
    let t0 = Instant::now();
    while seqs.len() < 6 {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "frames {seqs:?}, losses {lost:?}, {:?}",
            source.stats()
        );
        match source.next_frame(&mut slot, Duration::from_millis(200)) {
            Ok(()) => seqs.push(slot.meta.seq),
            Err(SourceError::Lost { reason }) => lost.push(reason),
            Err(SourceError::Timeout(_) | SourceError::Unavailable { .. }) => {}
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(lost.len(), 1, "one loss reported: {lost:?}");
    assert!(lost[0].contains("GC_ERR_IO"), "{lost:?}");
    assert_eq!(
        seqs,
        vec![0, 1, 2, 3, 4, 5],
        "seq goes on across the reopening"
    );
    let stats = source.stats();
    assert_eq!((stats.losses, stats.opens), (1, 2), "{stats:?}");
    drop(source);
    assert!(open_handles().is_zero(), "{:?}", open_handles());
}
