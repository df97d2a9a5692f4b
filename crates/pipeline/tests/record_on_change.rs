//! `[record] frames = "on_change"`: the recording keeps the first frame
//! and each frame whose status differs from the one before (ok → too few
//! targets → ok), and each recorded frame's targets as one image
//! annotation with the frame's time; the results carry the identified
//! targets.

use photopose_acquire::{FrameSource, Slot, SourceError};
use photopose_field::design::default_plate;
use photopose_frame::Pixels;
use photopose_pipeline::config::Source;
use photopose_pipeline::sink::record::RecordLink;
use photopose_pipeline::source::SyntheticSource;
use photopose_pipeline::{Config, Pipeline, Supervision};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// The synthetic frames, with frames 5..10 blanked (too few targets).
struct Blanked(SyntheticSource);

impl FrameSource for Blanked {
    fn start(&mut self) -> Result<(), SourceError> {
        self.0.start()
    }

    fn next_frame(&mut self, slot: &mut Slot, timeout: Duration) -> Result<(), SourceError> {
        self.0.next_frame(slot, timeout)?;
        if (5..10).contains(&slot.meta.seq) {
            match slot.image_mut().pixels_mut() {
                Pixels::Mono8(p) => p.fill(0),
                Pixels::Mono16(p) => p.fill(0),
            }
        }
        Ok(())
    }

    fn stop(&mut self) {
        self.0.stop()
    }

    fn describe(&self) -> String {
        "synthetic, frames 5..10 blank".into()
    }
}

#[test]
fn on_change_records_the_frames_where_the_status_changes() {
    let dir = std::env::temp_dir().join(format!("photopose-onchange-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.mcap");
    let mut cfg = Config::parse(
        &format!(
            r#"
[source]
kind = "synthetic"
[source.synthetic]
rate_hz = 100.0
frames = 15
[pipeline]
workers = 1
slots = 4
overflow = "block"
[output]
udp = []
[record]
path = "{}"
frames = "on_change"
compression = "lz4"
"#,
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
    let source = Blanked(SyntheticSource::new(camera, &field, syn).unwrap());
    let bytes = camera.sensor.width as usize * camera.sensor.height as usize;
    let link = RecordLink::start(&cfg.record, Default::default(), bytes).unwrap();
    let source = link.tap(Box::new(source), &cfg.record);
    cfg.record.link = Some(link.clone());
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, source, Supervision::none()).unwrap();
    let t0 = Instant::now();
    while !pipeline.finished() {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "the pipeline did not finish"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    pipeline.join();
    link.close();
    let stats = link.stats();
    assert_eq!(stats.frames.load(Ordering::Relaxed), 3);
    assert_eq!(stats.poses.load(Ordering::Relaxed), 15);
    assert_eq!(stats.annotations.load(Ordering::Relaxed), 3);

    let bytes = std::fs::read(&path).unwrap();
    let (mut images, mut annotated) = (Vec::new(), Vec::new());
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        match m.channel.topic.as_str() {
            "/camera/image" => images.push((m.sequence, m.log_time)),
            "/camera/targets" => {
                use foxglove::Decode;
                let a = foxglove::messages::ImageAnnotations::decode(&m.data[..]).unwrap();
                annotated.push((m.sequence, m.log_time, a.texts.len()));
            }
            _ => {}
        }
    }
    assert_eq!(
        images.iter().map(|i| i.0).collect::<Vec<_>>(),
        [0, 5, 10],
        "first frame, ok → too few targets, too few targets → ok"
    );
    // One annotation per recorded frame, at its time; the ok frames show
    // their targets (coded and uncoded), the blank one none.
    assert_eq!(
        annotated.iter().map(|a| (a.0, a.1)).collect::<Vec<_>>(),
        images
    );
    assert!(annotated[0].2 > 30, "{annotated:?}");
    assert_eq!(annotated[1].2, 0, "{annotated:?}");
    assert!(annotated[2].2 > 30, "{annotated:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}
