//! Recordings round-trip frames exactly; damaged files give errors that name
//! the file and the problem.

use photopose_frame::{Image, Pixels};
use photopose_record::{FrameMeta, Recorder, Recording};

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("photopose-record-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn image(k: u8) -> Image {
    let px: Vec<u8> = (0..64 * 48).map(|i| (i as u8).wrapping_mul(k)).collect();
    Image::from_pixels(64, 48, 255, Pixels::Mono8(px)).unwrap()
}

#[test]
fn frames_and_metadata_round_trip() {
    let dir = scratch("rt");
    let path = dir.join("r.mcap");
    let mut rec = Recorder::create(&path).unwrap();
    for k in 0..5u64 {
        let meta = FrameMeta {
            seq: 100 + k,
            camera_time_ns: k * 10_000_000,
            host_time_ns: 1_700_000_000_000_000_000 + k,
            ..FrameMeta::default()
        };
        rec.write(meta, &image(k as u8 + 1)).unwrap();
    }
    let wide = Image::from_pixels(
        64,
        48,
        4095,
        Pixels::Mono16((0..64 * 48).map(|i| (i % 4096) as u16).collect()),
    )
    .unwrap();
    rec.write(
        FrameMeta {
            seq: 200,
            camera_time_ns: 1,
            host_time_ns: 2,
            ..FrameMeta::default()
        },
        &wide,
    )
    .unwrap();
    rec.finish().unwrap();
    let r = Recording::open(&path).unwrap();
    assert_eq!(r.len(), 6);
    let mut img = Image::new_mono8(64, 48);
    for k in 0..5u64 {
        let meta = r.copy_into(k as usize, &mut img).unwrap();
        assert_eq!(meta.seq, 100 + k);
        assert_eq!(meta.camera_time_ns, k * 10_000_000);
        assert_eq!(img, image(k as u8 + 1));
    }
    let mut img16 = Image::new_mono16(64, 48, 4095);
    r.copy_into(5, &mut img16).unwrap();
    assert_eq!(img16, wide);
    // A wrong-size slot is refused with both sizes.
    let mut small = Image::new_mono8(32, 24);
    let e = r.copy_into(0, &mut small).unwrap_err().to_string();
    assert!(e.contains("64×48") && e.contains("32×24"), "{e}");
}

#[test]
fn damaged_recordings_are_named_errors() {
    let dir = scratch("bad");
    let good = dir.join("good.mcap");
    let mut rec = Recorder::create(&good).unwrap();
    rec.write(
        FrameMeta {
            seq: 0,
            camera_time_ns: 0,
            host_time_ns: 0,
            ..FrameMeta::default()
        },
        &image(3),
    )
    .unwrap();
    rec.finish().unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let cases = [
        (
            "truncated.mcap",
            bytes[..bytes.len() / 2].to_vec(),
            "not a readable MCAP recording",
        ),
        (
            "text.mcap",
            b"hello, not a recording".to_vec(),
            "not a readable MCAP recording",
        ),
        ("empty.mcap", Vec::new(), "not a readable MCAP recording"),
    ];
    for (name, data, want) in cases {
        let p = dir.join(name);
        std::fs::write(&p, data).unwrap();
        let e = Recording::open(&p).unwrap_err().to_string();
        assert!(e.contains(name) && e.contains(want), "{e}");
    }
    let e = Recording::open(&dir.join("missing.mcap"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.mcap"), "{e}");
    // A valid container without frames.
    let empty = dir.join("noframes.mcap");
    Recorder::create(&empty).unwrap().finish().unwrap();
    let e = Recording::open(&empty).unwrap_err().to_string();
    assert!(e.contains("no frames"), "{e}");
}
