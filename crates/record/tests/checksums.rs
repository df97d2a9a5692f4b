//! A recording with flipped bits is refused at open, naming the file and
//! the checksum that failed; recordings are read with a size limit and only
//! as regular files.

use photopose_frame::{Image, Pixels};
use photopose_record::{Compression, FrameMeta, RecordError, RecordOptions, Recorder, Recording};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photopose-crc-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A frame whose pixels are a recognisable ramp.
fn frame(k: u8) -> Image {
    let px: Vec<u8> = (0..64 * 48)
        .map(|i| (i as u8).wrapping_add(k.wrapping_mul(17)))
        .collect();
    Image::from_pixels(64, 48, 255, Pixels::Mono8(px)).unwrap()
}

fn record(path: &Path, frames: u8) {
    // Uncompressed, so the test can find a frame's pixels in the file.
    let options = RecordOptions {
        compression: Compression::None,
        ..RecordOptions::default()
    };
    let mut rec = Recorder::create_with(path, &options).unwrap();
    for k in 0..frames {
        let meta = FrameMeta {
            seq: k as u64,
            camera_time_ns: k as u64 * 1_000_000,
            host_time_ns: 7,
            ..FrameMeta::default()
        };
        rec.write(meta, &frame(k)).unwrap();
    }
    rec.finish().unwrap();
}

/// Offset of the first record with `opcode` walking the records from the
/// leading magic (opcode, u64 length, body).
fn first_record(bytes: &[u8], opcode: u8) -> usize {
    let mut at = 8;
    while at + 9 <= bytes.len() {
        if bytes[at] == opcode {
            return at;
        }
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        at += 9 + len;
    }
    panic!("no record {opcode:#x}");
}

#[test]
fn a_flipped_bit_in_a_frame_is_a_chunk_crc_error_naming_the_file() {
    let dir = scratch("chunk");
    let good = dir.join("good.mcap");
    record(&good, 3);
    Recording::open(&good).unwrap();
    let mut bytes = std::fs::read(&good).unwrap();
    // The second frame's pixels, inside the (uncompressed) chunk.
    let pixels = match frame(1).pixels() {
        Pixels::Mono8(p) => p[..64].to_vec(),
        Pixels::Mono16(_) => unreachable!(),
    };
    let at = bytes
        .windows(pixels.len())
        .position(|w| w == pixels.as_slice())
        .expect("the frame's pixels are in the file");
    let chunk = first_record(&bytes, 0x06);
    assert!(at > chunk, "the pixels lie inside the chunk");
    bytes[at + 10] ^= 0x08;
    let bad = dir.join("flipped.mcap");
    std::fs::write(&bad, &bytes).unwrap();
    let e = Recording::open(&bad).expect_err("a flipped bit is refused");
    assert!(matches!(e, RecordError::Corrupt { .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.starts_with(&format!(
            "{}: corrupt recording: a chunk's CRC is ",
            bad.display()
        )),
        "{msg}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_flipped_bit_outside_the_chunk_records_is_a_data_section_crc_error() {
    let dir = scratch("data");
    let good = dir.join("good.mcap");
    record(&good, 2);
    let mut bytes = std::fs::read(&good).unwrap();
    // The chunk's message_start_time: in the chunk record's header, which
    // the chunk CRC (over the records inside) does not cover.
    let chunk = first_record(&bytes, 0x06);
    bytes[chunk + 9] ^= 0x01;
    let bad = dir.join("header.mcap");
    std::fs::write(&bad, &bytes).unwrap();
    let e = Recording::open(&bad)
        .expect_err("a flipped bit is refused")
        .to_string();
    assert!(
        e.starts_with(&format!(
            "{}: corrupt recording: the data section's CRC is ",
            bad.display()
        )),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn recordings_are_read_with_a_limit_and_as_regular_files_only() {
    let dir = scratch("limit");
    let good = dir.join("good.mcap");
    record(&good, 2);
    let size = std::fs::metadata(&good).unwrap().len();
    assert_eq!(Recording::open_limited(&good, size).unwrap().len(), 2);
    let e = Recording::open_limited(&good, size - 1)
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        format!(
            "{}: too large for the recording: {size} bytes, the limit is {} bytes",
            good.display(),
            size - 1
        )
    );
    let e = Recording::open(&dir).unwrap_err().to_string();
    assert!(e.contains("it is a directory, not a regular file"), "{e}");
    #[cfg(target_os = "linux")]
    {
        let e = Recording::open(Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/dev/zero: cannot read the recording: it is a character device"),
            "{e}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
