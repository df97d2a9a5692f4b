//! Every loader reads real files with limits: devices, FIFOs and
//! directories are refused without blocking, oversized files are refused by
//! size, and an image's declared size is checked against the camera before
//! any pixel is allocated.

use photopose_formats::hand_eye::load_hand_eye;
use photopose_formats::{
    default_camera, load_camera, load_field, load_image, load_image_for, load_observations,
    read_text, FileKind, FormatError,
};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photopose-limits-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn text(p: &Path, kind: FileKind) -> Result<String, FormatError> {
    Ok(read_text(p, kind)?)
}

/// A loader: the error text of reading a path, `None` if it was accepted.
type Loader = fn(&Path) -> Option<String>;

/// Every loader of the crate, by the kind of file it reads.
fn loaders() -> Vec<(&'static str, Loader)> {
    fn e<T>(r: Result<T, FormatError>) -> Option<String> {
        r.err().map(|e| e.to_string())
    }
    vec![
        ("camera file", |p| e(load_camera(p))),
        ("field file", |p| e(load_field(p))),
        ("hand-eye file", |p| e(load_hand_eye(p))),
        ("observation file", |p| e(load_observations(p))),
        ("image file", |p| e(load_image(p))),
        ("image file", |p| e(load_image_for(p, &default_camera()))),
        ("pose file", |p| e(text(p, FileKind::Poses))),
        ("station file", |p| e(text(p, FileKind::Stations))),
        ("controller file", |p| e(text(p, FileKind::ControllerFile))),
    ]
}

/// Runs `f` on its own thread; fails the test if it takes longer than
/// `limit` (a blocking read never returns).
fn within<T: Send + 'static>(limit: Duration, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(limit)
        .expect("the read did not return in time (blocked)")
}

#[cfg(target_os = "linux")]
#[test]
fn dev_zero_is_refused_by_every_loader() {
    for (kind, load) in loaders() {
        let e = within(Duration::from_secs(10), move || {
            load(Path::new("/dev/zero"))
        })
        .unwrap_or_else(|| panic!("{kind}: /dev/zero accepted"));
        assert!(
            e.starts_with("/dev/zero: cannot read the ")
                && e.contains(kind)
                && e.contains("it is a character device, not a regular file"),
            "{kind}: {e}"
        );
    }
}

#[cfg(unix)]
#[test]
fn a_fifo_is_refused_without_blocking() {
    let dir = scratch("fifo");
    let fifo = dir.join("camera.toml");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(made.success());
    for (kind, load) in loaders() {
        let p = fifo.clone();
        // Nobody ever writes to the FIFO: opening it for reading would block.
        let e = within(Duration::from_secs(10), move || load(&p))
            .unwrap_or_else(|| panic!("{kind}: a FIFO accepted"));
        assert!(
            e.contains("it is a FIFO (named pipe), not a regular file") && e.contains(kind),
            "{kind}: {e}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_directory_is_refused_by_every_loader() {
    let dir = scratch("dir");
    for (kind, load) in loaders() {
        let e = load(&dir).unwrap_or_else(|| panic!("{kind}: a directory accepted"));
        assert!(e.contains("it is a directory"), "{kind}: {e}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn oversized_files_are_refused_by_size_without_reading() {
    let dir = scratch("big");
    for (kind, load) in loaders() {
        let limit = match kind {
            "camera file" => FileKind::Camera.limit(),
            "field file" => FileKind::Field.limit(),
            "hand-eye file" => FileKind::HandEye.limit(),
            "observation file" => FileKind::Observations.limit(),
            "image file" => FileKind::Image.limit(),
            "pose file" => FileKind::Poses.limit(),
            "station file" => FileKind::Stations.limit(),
            _ => FileKind::ControllerFile.limit(),
        };
        // A sparse file: its size is known without writing or reading it.
        let p = dir.join("big");
        let f = std::fs::File::create(&p).unwrap();
        f.set_len(limit + 1).unwrap();
        drop(f);
        let e = within(Duration::from_secs(10), move || load(&p))
            .unwrap_or_else(|| panic!("{kind}: an oversized file accepted"));
        assert!(
            e.contains(&format!("too large for the {kind}")) && e.contains(" bytes, the limit is "),
            "{kind}: {e}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A 62-byte greyscale PNG declaring `width × height` 8-bit pixels.
fn tiny_png(width: u32, height: u32) -> Vec<u8> {
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let start = out.len();
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
        let crc = crc32fast::hash(&out[start..]);
        out.extend_from_slice(&crc.to_be_bytes());
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = width.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &[0x78, 0x9c, 0x63, 0x60, 0]);
    chunk(&mut out, b"IEND", &[]);
    out
}

#[test]
fn image_files_declaring_huge_sizes_are_refused_from_their_headers() {
    let dir = scratch("huge");
    let png = dir.join("huge.png");
    let bytes = tiny_png(100_000, 100_000);
    assert_eq!(bytes.len(), 62);
    std::fs::write(&png, &bytes).unwrap();
    let pgm = dir.join("huge.pgm");
    std::fs::write(&pgm, b"P5\n100000 100000\n255\n\0\0\0\0").unwrap();
    for p in [&png, &pgm] {
        let e = load_image_for(p, &default_camera())
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            format!(
                "{}: image is 100000×100000, camera file says 1300×1030",
                p.display()
            )
        );
        let e = load_image(p).unwrap_err().to_string();
        assert!(
            e.contains("100000×100000 is larger than an image is read"),
            "{e}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_image_file_larger_than_the_sensor_needs_is_refused_by_size() {
    let dir = scratch("padded");
    let p = dir.join("padded.pgm");
    // The default camera's 16-bit raster is 2.7 MB; 8 MB cannot be its image.
    let f = std::fs::File::create(&p).unwrap();
    f.set_len(8 << 20).unwrap();
    drop(f);
    let e = load_image_for(&p, &default_camera())
        .unwrap_err()
        .to_string();
    let limit = 4 * 1300 * 1030 + (1 << 20);
    assert_eq!(
        e,
        format!(
            "{}: too large for the image file: 8388608 bytes, the limit is {limit} bytes",
            p.display()
        )
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
