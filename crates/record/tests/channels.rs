//! The channels beside the frames: each frame's times (exposure instants
//! included) come back from a recording exactly; the targets of a frame are
//! a `foxglove.ImageAnnotations` with the frame's time, coded and uncoded
//! targets apart and the ids as text; RSI cycles are JSON with their
//! schema in the file.

use foxglove::Decode;
use photopose_frame::{Image, Pixels};
use photopose_record::{
    pose_messages, FrameMeta, PoseRecord, Recorder, Recording, RsiCycle, TargetMark,
    ANNOTATIONS_TOPIC, RSI_TOPIC,
};

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("photopose-record-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn image() -> Image {
    Image::from_pixels(32, 24, 255, Pixels::Mono8(vec![7; 32 * 24])).unwrap()
}

fn meta(k: u64) -> FrameMeta {
    FrameMeta {
        // Past 32 bits: the MCAP sequence cannot hold it alone.
        seq: (1 << 33) + k,
        camera_frame_id: 40 + k,
        camera_time_ns: 5_000 + k,
        host_time_ns: 1_700_000_000_000_000_000 + 1_000_000 * k,
        host_mono_ns: 9_000_000_000 + 1_000_000 * k,
        exposure_mono_ns: 8_999_000_000 + 1_000_000 * k,
        exposure_sigma_ns: 20_000,
        exposure_ns: 500_000,
    }
}

#[test]
fn frame_times_come_back_exactly() {
    let dir = scratch("times");
    let path = dir.join("t.mcap");
    let mut rec = Recorder::create(&path).unwrap();
    for k in 0..3 {
        rec.write(meta(k), &image()).unwrap();
    }
    rec.finish().unwrap();
    let r = Recording::open(&path).unwrap();
    assert_eq!(r.len(), 3);
    for k in 0..3 {
        let (m, w, h) = r.meta(k as usize);
        assert_eq!((m, w, h), (meta(k), 32, 24));
        assert_eq!(
            m.exposure_utc_ns(),
            Some(1_700_000_000_000_000_000 + 1_000_000 * k - 1_000_000)
        );
    }
}

#[test]
fn targets_and_rsi_cycles_have_channels_of_their_own() {
    let dir = scratch("channels");
    let path = dir.join("c.mcap");
    let mut rec = Recorder::create(&path).unwrap();
    rec.write(meta(0), &image()).unwrap();
    let marks = [
        TargetMark {
            id: 3,
            coded: true,
            col_px: 10.5,
            row_px: 4.25,
            used: true,
        },
        TargetMark {
            id: 117,
            coded: false,
            col_px: 20.0,
            row_px: 12.0,
            used: false,
        },
    ];
    rec.write_pose(&PoseRecord {
        seq: meta(0).seq,
        camera_time_ns: meta(0).camera_time_ns,
        host_time_ns: meta(0).host_time_ns,
        pose: None,
        json: b"{\"seq\":1}\n",
    })
    .unwrap();
    rec.write_targets(&meta(0), &marks).unwrap();
    let cycle = RsiCycle {
        ipoc: 123_456,
        arrival_utc_ns: 1_700_000_000_000_000_123,
        arrival_mono_ns: 42,
        rist_xyzabc: Some([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]),
        rsol_xyzabc: None,
        delay: Some(0),
        correction_sent_xyzabc: [0.0; 6],
        correction_total_xyzabc: [0.0; 6],
        error_xyzabc: None,
        state: "measure_only",
        slew_limited: false,
        clamped: false,
    };
    rec.write_rsi(&cycle).unwrap();
    rec.finish().unwrap();

    let bytes = std::fs::read(&path).unwrap();
    let (mut annotations, mut cycles) = (Vec::new(), Vec::new());
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        if m.channel.topic == ANNOTATIONS_TOPIC {
            assert_eq!(schema.name, "foxglove.ImageAnnotations");
            assert_eq!(m.log_time, meta(0).host_time_ns);
            annotations.push(foxglove::messages::ImageAnnotations::decode(&m.data[..]).unwrap());
        }
        if m.channel.topic == RSI_TOPIC {
            assert_eq!(
                (schema.name.as_str(), schema.encoding.as_str()),
                ("photopose.RsiCycle", "jsonschema")
            );
            assert_eq!(m.log_time, cycle.arrival_utc_ns);
            cycles.push(serde_json::from_slice::<serde_json::Value>(&m.data).unwrap());
        }
    }
    assert_eq!(annotations.len(), 1);
    let a = &annotations[0];
    let texts: Vec<&str> = a.texts.iter().map(|t| t.text.as_str()).collect();
    assert_eq!(texts, ["c3", "117"]);
    // One points group for the coded targets, one for the uncoded.
    assert_eq!(a.points.len(), 2);
    assert_eq!(
        (a.points[0].points[0].x, a.points[0].points[0].y),
        (10.5, 4.25)
    );
    assert_eq!(
        (a.points[1].points[0].x, a.points[1].points[0].y),
        (20.0, 12.0)
    );
    assert_ne!(a.points[0].fill_color, a.points[1].fill_color);
    assert_eq!(cycles.len(), 1);
    assert_eq!(cycles[0]["ipoc"], 123_456);
    assert_eq!(cycles[0]["rsol_xyzabc"], serde_json::Value::Null);
    assert_eq!(cycles[0]["state"], "measure_only");
    // The pose messages read back as they were written, without newline.
    assert_eq!(pose_messages(&path).unwrap(), [b"{\"seq\":1}".to_vec()]);
}
