//! Replay of a recording end to end: two replays at full speed give the
//! same poses bit for bit, every frame in order, none lost with the
//! `block` policy; the poses agree with the synthetic truth.

use photopose_field::design::default_plate;
use photopose_pipeline::config::Source;
use photopose_pipeline::source::{FrameSource, ReplaySource, Slot, SourceError, SyntheticSource};
use photopose_pipeline::{Config, Pipeline};
use photopose_record::Recorder;
use std::net::UdpSocket;
use std::time::Duration;

fn camera() -> photopose_geometry::Camera {
    photopose_formats::default_camera()
}

fn replay_config(path: &std::path::Path, udp: &str) -> Config {
    Config::parse(
        &format!(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"{}\"\nspeed = \"max\"\n[pipeline]\nworkers = 2\nslots = 6\noverflow = \"block\"\n[output]\nudp = [\"{udp}\"]\n",
            path.display()
        ),
        "test",
    )
    .unwrap()
}

/// Runs a replay to its end and returns the UDP messages.
fn replay_once(path: &std::path::Path, frames: usize) -> Vec<serde_json::Value> {
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let cfg = replay_config(path, &rx.local_addr().unwrap().to_string());
    let Source::Replay(r) = &cfg.source else {
        panic!("replay source expected")
    };
    let source = ReplaySource::open(&camera(), r).unwrap();
    let pipeline = Pipeline::start(&cfg, camera(), default_plate(), Box::new(source)).unwrap();
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    while out.len() < frames {
        let n = rx.recv(&mut buf).unwrap();
        out.push(serde_json::from_slice::<serde_json::Value>(&buf[..n]).unwrap());
    }
    let c = pipeline.join();
    assert_eq!(c.frames_dropped.get(), 0);
    out
}

/// Records 12 synthetic frames of the moving circle into `dir`; returns the
/// file, the source's settings and the frames.
fn record_circle(
    dir: &std::path::Path,
) -> (
    std::path::PathBuf,
    photopose_pipeline::config::Synthetic,
    Vec<photopose_frame::Image>,
) {
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join("circle.mcap");
    let cfg = Config::parse(
        "[source]\nkind = \"synthetic\"\n[source.synthetic]\nrate_hz = 1000.0\nframes = 12\nradius_mm = 60.0\nperiod_s = 0.012\n",
        "test",
    )
    .unwrap();
    let Source::Synthetic(syn) = cfg.source.clone() else {
        panic!()
    };
    let mut src = SyntheticSource::new(camera(), &default_plate(), syn.clone()).unwrap();
    let mut rec = Recorder::create(&path).unwrap();
    let mut frame = Slot::new(photopose_frame::Image::new_mono8(1300, 1030));
    let mut frames = Vec::new();
    loop {
        match src.next_frame(&mut frame, Duration::from_secs(1)) {
            Ok(()) => {}
            Err(SourceError::Ended) => break,
            Err(e) => panic!("synthetic source: {e}"),
        }
        rec.write(frame.meta, frame.image()).unwrap();
        frames.push(frame.image().clone());
    }
    rec.finish().unwrap();
    (path, syn, frames)
}

#[test]
fn a_replay_lends_its_frames_to_the_slots_unchanged() {
    let dir = std::env::temp_dir().join(format!("photopose-replay-lend-{}", std::process::id()));
    let (path, _, frames) = record_circle(&dir);
    let cfg = Config::parse(
        &format!(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"{}\"\nspeed = \"max\"\npasses = 2\n",
            path.display()
        ),
        "test",
    )
    .unwrap();
    let Source::Replay(r) = &cfg.source else {
        panic!("replay source expected")
    };
    let mut source = ReplaySource::open(&camera(), r).unwrap();
    let mut slot = Slot::new(photopose_frame::Image::new_mono8(1300, 1030));
    for k in 0..2 * frames.len() {
        source
            .next_frame(&mut slot, Duration::from_secs(1))
            .unwrap();
        assert!(slot.is_shared(), "frame {k} is lent, not copied");
        assert_eq!(slot.image(), &frames[k % frames.len()], "frame {k}");
        assert_eq!(slot.meta.seq, k as u64);
    }
    assert!(matches!(
        source.next_frame(&mut slot, Duration::from_secs(1)),
        Err(SourceError::Ended)
    ));
    // A source writing the slot next writes the slot's own pixels.
    slot.image_mut();
    assert!(!slot.is_shared());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn two_replays_give_identical_poses() {
    let dir = std::env::temp_dir().join(format!("photopose-replay-{}", std::process::id()));
    let (path, syn, _) = record_circle(&dir);
    let a = replay_once(&path, 12);
    let b = replay_once(&path, 12);
    for (x, y) in a.iter().zip(&b) {
        for k in ["seq", "status", "pose"] {
            assert_eq!(x[k], y[k], "key {k} differs between replays");
        }
        for k in ["camera_clock_ns", "handover_utc_ns", "exposure_utc_ns"] {
            assert_eq!(
                x["time"][k], y["time"][k],
                "time.{k} differs between replays"
            );
        }
    }
    let seqs: Vec<u64> = a.iter().map(|v| v["seq"].as_u64().unwrap()).collect();
    assert_eq!(seqs, (0..12).collect::<Vec<_>>());
    for v in &a {
        let truth = SyntheticSource::pose_at(&syn, v["seq"].as_u64().unwrap());
        let c: Vec<f64> = v["pose"]["position_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        for k in 0..3 {
            assert!(
                (c[k] - truth.center[k]).abs() < 0.05,
                "{c:?} vs {:?}",
                truth.center
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
