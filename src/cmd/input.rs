//! Where the commands that read images get them: image files (PGM, PNG)
//! and MCAP recordings, one home for both. A path ending in `.mcap` (or a
//! file starting with the MCAP magic) is a recording: each of its frames
//! (or those `--frames` selects by sequence number) is one input, named
//! `FILE#SEQ`; any other path is one image file. Every frame is checked
//! against the camera's sensor size.

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
    mut each: impl FnMut(&str, Result<Image, String>) -> Result<(), E>,
) -> Result<(), E> {
    for path in paths {
        let name = path.display().to_string();
        if !is_recording(path) {
            let frame = photopose_formats::load_image_for(path, camera).map_err(|e| e.to_string());
            each(&name, frame)?;
            continue;
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
}
