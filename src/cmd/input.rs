//! Where the commands that read images get them: image files (PGM, PNG)
//! and MCAP recordings, one home for both. A path ending in `.mcap` (or a
//! file starting with the MCAP magic) is a recording: each of its frames
//! (or those `--frames` selects by sequence number) is one input, named
//! `FILE#SEQ`; any other path is one image file. Every frame is checked
//! against the camera's sensor size.

use photopose_formats::provenance::{hash_file, sha256_hex, InputFile};
use photopose_formats::{decode_image_for, read_bytes_limited, FileKind, FormatError, ImageLimits};
use photopose_frame::Image;
use photopose_geometry::Camera;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The magic bytes an MCAP file starts with.
const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// Whether `path` is a recording: its name ends in `.mcap`, or the file
/// starts with the MCAP magic.
pub fn is_recording(path: &Path) -> bool {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
    {
        return true;
    }
    // Only a regular file is looked into (opening a FIFO would wait for a
    // writer); anything else is refused by the reader it goes to.
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return false;
    }
    let mut head = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|()| head == MCAP_MAGIC)
}

/// Which frames of a recording to take, by sequence number (`--frames`):
/// a comma-separated list of `N` and `A-B` (inclusive).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameSelection(Vec<(u64, u64)>);

impl std::str::FromStr for FrameSelection {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let mut ranges = Vec::new();
        for part in s.split(',').map(str::trim) {
            let number = |t: &str| {
                t.trim().parse::<u64>().map_err(|_| {
                    format!("`{part}` in `{s}`: expected N or A-B (frame sequence numbers)")
                })
            };
            let range = match part.split_once('-') {
                Some((a, b)) => (number(a)?, number(b)?),
                None => {
                    let n = number(part)?;
                    (n, n)
                }
            };
            if range.0 > range.1 {
                return Err(format!("`{part}` in `{s}`: the range runs backwards"));
            }
            ranges.push(range);
        }
        Ok(FrameSelection(ranges))
    }
}

impl FrameSelection {
    /// Whether frame `seq` is selected.
    pub fn contains(&self, seq: u64) -> bool {
        self.0.iter().any(|&(a, b)| (a..=b).contains(&seq))
    }
}

/// Calls `each` with every input of `paths` in order: its name (the file,
/// or `FILE#SEQ` for a recording's frame) and its frame or why it could
/// not be read. `frames` selects the frames of recordings (all when
/// `None`). An error of `each` ends the walk.
pub fn for_each_frame<E>(
    paths: &[PathBuf],
    camera: &Camera,
    frames: Option<&FrameSelection>,
    each: impl FnMut(&str, Result<Image, String>) -> Result<(), E>,
) -> Result<(), E> {
    walk(paths, camera, frames, None, each)
}

/// As [`for_each_frame`], also pushing onto `hashes` the SHA-256 of every
/// input file that can be read, in order: an image file is read once, its
/// hash and its frame from the same bytes.
pub fn for_each_frame_hashed<E>(
    paths: &[PathBuf],
    camera: &Camera,
    frames: Option<&FrameSelection>,
    hashes: &mut Vec<InputFile>,
    each: impl FnMut(&str, Result<Image, String>) -> Result<(), E>,
) -> Result<(), E> {
    walk(paths, camera, frames, Some(hashes), each)
}

/// One image file for `camera`, read once: its hash (when it could be
/// read) and its frame.
fn read_image(path: &Path, camera: &Camera) -> (Option<InputFile>, Result<Image, String>) {
    let limits = ImageLimits::of(camera);
    let name = path.display().to_string();
    match read_bytes_limited(path, FileKind::Image, limits.file_limit()) {
        Ok(bytes) => {
            let hash = InputFile {
                path: name.clone(),
                sha256: sha256_hex(&bytes),
            };
            let frame = decode_image_for(&bytes, &name, limits).map_err(|e| e.to_string());
            (Some(hash), frame)
        }
        // Refused for this camera (too large, ...): hashed as any image
        // file when it can be read at all, as before.
        Err(e) => (
            hash_file(path, FileKind::Image).ok(),
            Err(FormatError::from(e).to_string()),
        ),
    }
}

fn walk<E>(
    paths: &[PathBuf],
    camera: &Camera,
    frames: Option<&FrameSelection>,
    mut hashes: Option<&mut Vec<InputFile>>,
    mut each: impl FnMut(&str, Result<Image, String>) -> Result<(), E>,
) -> Result<(), E> {
    for path in paths {
        let name = path.display().to_string();
        if !is_recording(path) {
            let frame = match hashes.as_deref_mut() {
                Some(hashes) => {
                    let (hash, frame) = read_image(path, camera);
                    hashes.extend(hash);
                    frame
                }
                None => photopose_formats::load_image_for(path, camera).map_err(|e| e.to_string()),
            };
            each(&name, frame)?;
            continue;
        }
        if let Some(hashes) = hashes.as_deref_mut() {
            // A recording is read frame by frame, so hashed on its own.
            hashes.extend(hash_file(path, FileKind::Recording).ok());
        }
        let recording = match photopose_record::Recording::open(path) {
            Ok(r) => r,
            Err(e) => {
                each(&name, Err(e.to_string()))?;
                continue;
            }
        };
        let (w, h) = (camera.sensor.width, camera.sensor.height);
        for index in 0..recording.len() {
            let (meta, fw, fh) = recording.meta(index);
            if frames.is_some_and(|f| !f.contains(meta.seq)) {
                continue;
            }
            let frame_name = format!("{name}#{}", meta.seq);
            let frame = if (fw, fh) != (w, h) {
                Err(format!(
                    "{frame_name}: the frame is {fw}×{fh}, the camera is {w}×{h}"
                ))
            } else {
                recording
                    .frame(index)
                    .map(|(_, image)| image)
                    .map_err(|e| format!("{frame_name}: {e}"))
            };
            each(&frame_name, frame)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_selections_parse_and_refuse_with_the_part() {
        let s: FrameSelection = "0-2, 7,10-10".parse().unwrap();
        let picked: Vec<u64> = (0..12).filter(|&k| s.contains(k)).collect();
        assert_eq!(picked, [0, 1, 2, 7, 10]);
        let e = "3,x".parse::<FrameSelection>().unwrap_err();
        assert!(e.contains("`x`"), "{e}");
        let e = "5-2".parse::<FrameSelection>().unwrap_err();
        assert!(e.contains("backwards"), "{e}");
    }

    #[test]
    fn hashed_walk_reads_each_image_once_with_the_same_hashes_and_frames() {
        use photopose_formats::provenance::hash_file;
        use photopose_geometry::{Distortion, Interior, Sensor};
        let camera = Camera::new(
            Sensor {
                width: 4,
                height: 2,
                pixel_size: 0.0067,
            },
            Interior {
                c: 12.0,
                x0: 0.0,
                y0: 0.0,
            },
            Distortion::default(),
        )
        .unwrap();
        let dir = std::env::temp_dir().join(format!("photopose-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.pgm");
        std::fs::write(&good, b"P5\n4 2\n255\n\x01\x02\x03\x04\x05\x06\x07\x08").unwrap();
        let small = dir.join("small.pgm");
        std::fs::write(&small, b"P5\n2 2\n255\n\x01\x02\x03\x04").unwrap();
        let huge = dir.join("huge.pgm");
        std::fs::write(&huge, vec![b'P'; 4096]).unwrap();
        let missing = dir.join("missing.pgm");
        let paths = vec![good, small, huge, missing];

        let mut hashes = Vec::new();
        let mut seen = Vec::new();
        for_each_frame_hashed(&paths, &camera, None, &mut hashes, |name, frame| {
            seen.push((name.to_string(), frame));
            Ok::<(), ()>(())
        })
        .unwrap();
        // The same as hashing every readable file and loading each frame.
        let want_hashes: Vec<InputFile> = paths
            .iter()
            .filter_map(|p| hash_file(p, FileKind::Image).ok())
            .collect();
        assert_eq!(hashes, want_hashes);
        assert_eq!(hashes.len(), 3);
        let want: Vec<(String, Result<Image, String>)> = paths
            .iter()
            .map(|p| {
                let frame =
                    photopose_formats::load_image_for(p, &camera).map_err(|e| e.to_string());
                (p.display().to_string(), frame)
            })
            .collect();
        assert_eq!(seen, want);
        assert!(seen[0].1.is_ok() && seen[1..].iter().all(|(_, f)| f.is_err()));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
