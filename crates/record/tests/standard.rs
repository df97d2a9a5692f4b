//! Recordings use the standard Foxglove schemas (a reader needs only the
//! schemas inside the file), carry attachments and metadata, round-trip
//! mono16 frames, compress with zstd or lz4; first-format recordings are
//! still read.

use photopose_frame::{Image, Pixels};
use photopose_record::{
    Attachment, Compression, FrameMeta, PoseRecord, RecordOptions, Recorder, Recording,
};
use std::collections::BTreeMap;

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("photopose-std-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn mono16(k: u16) -> Image {
    let px: Vec<u16> = (0..32 * 8).map(|i| (i * 13 + k) % 4096).collect();
    Image::from_pixels(32, 8, 4095, Pixels::Mono16(px)).unwrap()
}

#[test]
fn frames_and_poses_are_foxglove_messages_with_attachments_and_metadata() {
    let dir = scratch("schemas");
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let path = dir.join(format!("{}.mcap", compression.name()));
        let options = RecordOptions {
            compression,
            attachments: vec![Attachment {
                name: "camera.toml".into(),
                media_type: "application/toml".into(),
                data: b"x = 1\n".to_vec(),
            }],
            metadata: BTreeMap::from([("version".to_string(), "9.9".to_string())]),
        };
        let mut rec = Recorder::create_with(&path, &options).unwrap();
        for k in 0..3u16 {
            let meta = FrameMeta {
                seq: u64::from(k),
                camera_time_ns: u64::from(k) * 10,
                host_time_ns: 1_000 + u64::from(k),
                ..FrameMeta::default()
            };
            rec.write(meta, &mono16(k)).unwrap();
            rec.write_pose(&PoseRecord {
                seq: u64::from(k),
                camera_time_ns: u64::from(k) * 10,
                host_time_ns: 1_000 + u64::from(k),
                pose: (k != 1).then_some(([1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])),
                json: b"{\"seq\":0}\n",
            })
            .unwrap();
        }
        rec.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let mut per_schema = BTreeMap::<String, usize>::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let s = m.channel.schema.as_ref().unwrap();
            *per_schema.entry(s.name.clone()).or_default() += 1;
        }
        assert_eq!(per_schema["foxglove.RawImage"], 3);
        assert_eq!(per_schema["foxglove.PoseInFrame"], 2);
        assert_eq!(per_schema["photopose.PoseMessage"], 3);
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.attachment_indexes.len(), 1);
        assert_eq!(summary.metadata_indexes.len(), 1);
        if compression != Compression::None {
            let chunk = &summary.chunk_indexes[0];
            assert_eq!(chunk.compression, compression.name());
        }
        let recording = Recording::open(&path).unwrap();
        assert_eq!(recording.len(), 3);
        let (meta, image) = recording.frame(2).unwrap();
        assert_eq!(meta.seq, 2);
        assert_eq!(meta.camera_time_ns, 20);
        assert_eq!(meta.host_time_ns, 1_002);
        assert_eq!(image, mono16(2));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn first_format_recordings_are_still_read() {
    let dir = scratch("v1");
    let path = dir.join("v1.mcap");
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .create(file)
        .unwrap();
    let channel = w
        .add_channel(
            0,
            photopose_record::TOPIC,
            photopose_record::ENCODING,
            &BTreeMap::new(),
        )
        .unwrap();
    let mut d = Vec::new();
    d.extend_from_slice(&5u64.to_le_bytes());
    d.extend_from_slice(&50u64.to_le_bytes());
    d.extend_from_slice(&500u64.to_le_bytes());
    d.extend_from_slice(&4u32.to_le_bytes());
    d.extend_from_slice(&2u32.to_le_bytes());
    d.push(1);
    d.extend_from_slice(&255u16.to_le_bytes());
    d.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
    let header = mcap::records::MessageHeader {
        channel_id: channel,
        sequence: 5,
        log_time: 500,
        publish_time: 50,
    };
    w.write_to_known_channel(&header, &d).unwrap();
    w.finish().unwrap();
    drop(w);
    let recording = Recording::open(&path).unwrap();
    let (meta, image) = recording.frame(0).unwrap();
    assert_eq!(
        (meta.seq, meta.camera_time_ns, meta.host_time_ns),
        (5, 50, 500)
    );
    assert_eq!(image.pixels(), &Pixels::Mono8(vec![1, 2, 3, 4, 5, 6, 7, 8]));
    std::fs::remove_dir_all(&dir).unwrap();
}
