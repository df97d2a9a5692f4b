//! Reading files with limits: the one place where photopose reads a file
//! from disk.
//!
//! Every input file has a [`FileKind`] that names it in errors and sets the
//! largest size read for it. [`read_bytes`] and [`read_text`] read only
//! regular files: a directory, FIFO, socket or device is refused from its
//! metadata *before* the file is opened (so a FIFO never blocks the reader),
//! and the file is then opened non-blocking and checked again through the
//! open handle. A file larger than its kind's limit is refused with path,
//! kind, size and limit; the read itself goes through `take(limit + 1)`, so
//! files that report a wrong size (`/proc`, files still growing) cannot
//! exceed the limit either.

use std::fmt;
use std::fs::{File, Metadata};
use std::io::Read;
use std::path::Path;
use thiserror::Error;

const KIB: u64 = 1024;
const MIB: u64 = 1024 * KIB;
const GIB: u64 = 1024 * MIB;

/// The kinds of file photopose reads, each with its name and size limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum FileKind {
    /// The daemon configuration (TOML).
    Config,
    /// A camera file (TOML).
    Camera,
    /// A test-field file (CSV).
    Field,
    /// A hand-eye file (TOML).
    HandEye,
    /// The robot controller's `RSI_EthernetConfig.xml`.
    ControllerFile,
    /// An observation file (CSV `id,col,row`).
    Observations,
    /// A hand-eye station file (CSV).
    Stations,
    /// A pose file (JSON lines) for the circular test.
    Poses,
    /// An image file (PGM or PNG).
    Image,
    /// A recording (MCAP).
    Recording,
}

impl FileKind {
    /// Every kind (for tests and documentation).
    pub const ALL: [FileKind; 10] = [
        FileKind::Config,
        FileKind::Camera,
        FileKind::Field,
        FileKind::HandEye,
        FileKind::ControllerFile,
        FileKind::Observations,
        FileKind::Stations,
        FileKind::Poses,
        FileKind::Image,
        FileKind::Recording,
    ];

    /// The name used in errors.
    pub fn name(self) -> &'static str {
        match self {
            FileKind::Config => "configuration file",
            FileKind::Camera => "camera file",
            FileKind::Field => "field file",
            FileKind::HandEye => "hand-eye file",
            FileKind::ControllerFile => "controller file (RSI_EthernetConfig.xml)",
            FileKind::Observations => "observation file",
            FileKind::Stations => "station file",
            FileKind::Poses => "pose file",
            FileKind::Image => "image file",
            FileKind::Recording => "recording",
        }
    }

    /// The largest file of this kind that is read, bytes.
    ///
    /// Text files are limited far above any real file of their kind (a
    /// camera file has a dozen lines, a controller file a few kilobytes (64 KiB
    /// refuses the 880 KB file that hung the old XML parser), a
    /// field of 100 000 targets about 5 MB). An image is limited to what the
    /// largest sensor of a camera file (65535 × 65535) cannot reach anyway in
    /// practice; [`crate::image::load_image_for`] reads at most what the
    /// camera's sensor needs. Recordings are held in memory whole by the
    /// replay; the daemon's `source.replay.max_bytes` can lower or raise
    /// their limit.
    pub fn limit(self) -> u64 {
        match self {
            FileKind::Config => MIB,
            FileKind::Camera => 64 * KIB,
            FileKind::Field => 16 * MIB,
            FileKind::HandEye => 64 * KIB,
            FileKind::ControllerFile => 64 * KIB,
            FileKind::Observations => 16 * MIB,
            FileKind::Stations => 16 * MIB,
            FileKind::Poses => 256 * MIB,
            FileKind::Image => GIB,
            FileKind::Recording => 4 * GIB,
        }
    }
}

impl fmt::Display for FileKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A file that could not be read, naming the path and the kind of file.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FileError {
    /// The file does not exist.
    #[error("{path}: cannot read the {kind}: no such file")]
    Missing {
        /// The path.
        path: String,
        /// What the file was to be.
        kind: FileKind,
    },
    /// The path is not a regular file (directory, FIFO, socket, device).
    #[error("{path}: cannot read the {kind}: it is {what}, not a regular file")]
    NotRegular {
        /// The path.
        path: String,
        /// What the file was to be.
        kind: FileKind,
        /// What the path is.
        what: &'static str,
    },
    /// The file is larger than its kind's limit.
    #[error(
        "{path}: too large for the {kind}: {size}{} bytes, the limit is {limit} bytes",
        if *at_least { " or more" } else { "" }
    )]
    TooLarge {
        /// The path.
        path: String,
        /// What the file was to be.
        kind: FileKind,
        /// Its size (or the bytes read before the limit was passed).
        size: u64,
        /// Whether `size` is only a lower bound (found while reading).
        at_least: bool,
        /// The limit for the kind.
        limit: u64,
    },
    /// A text file that is not UTF-8.
    #[error("{path}: the {kind} is not UTF-8 text (invalid bytes at offset {offset})")]
    NotText {
        /// The path.
        path: String,
        /// What the file was to be.
        kind: FileKind,
        /// Byte offset of the first invalid sequence.
        offset: usize,
    },
    /// Any other failure to open or read the file.
    #[error("{path}: cannot read the {kind}: {source}")]
    Io {
        /// The path.
        path: String,
        /// What the file was to be.
        kind: FileKind,
        /// The IO error.
        source: std::io::Error,
    },
}

impl FileError {
    /// The path of the file.
    pub fn path(&self) -> &str {
        match self {
            FileError::Missing { path, .. }
            | FileError::NotRegular { path, .. }
            | FileError::TooLarge { path, .. }
            | FileError::NotText { path, .. }
            | FileError::Io { path, .. } => path,
        }
    }
}

/// What a path that is not a regular file is, for the error.
fn describe(meta: &Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_socket() {
            return "a socket";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
    }
    "not a regular file"
}

/// Opens `path` for reading without blocking on a FIFO that replaced the
/// checked file in the meantime.
fn open(path: &Path) -> std::io::Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // No effect on a regular file; keeps a FIFO's open from waiting for
        // a writer (the handle is checked and refused right after).
        options.custom_flags(libc::O_NONBLOCK);
    }
    options.open(path)
}

/// Reads a whole regular file of `kind`, at most the kind's limit.
pub fn read_bytes(path: &Path, kind: FileKind) -> Result<Vec<u8>, FileError> {
    read_bytes_limited(path, kind, kind.limit())
}

/// Reads a whole regular file of `kind`, at most `limit` bytes (for callers
/// that know a tighter or configured limit).
pub fn read_bytes_limited(path: &Path, kind: FileKind, limit: u64) -> Result<Vec<u8>, FileError> {
    let mut bytes = Vec::new();
    read_bytes_into(path, kind, limit, &mut bytes)?;
    Ok(bytes)
}

/// [`read_bytes_limited`] into a caller's buffer (cleared first): a batch
/// that reads many files of one size reuses the buffer's memory instead of
/// faulting in fresh pages for every file.
pub fn read_bytes_into(
    path: &Path,
    kind: FileKind,
    limit: u64,
    bytes: &mut Vec<u8>,
) -> Result<(), FileError> {
    bytes.clear();
    let name = || path.display().to_string();
    let io = |source: std::io::Error| {
        if source.kind() == std::io::ErrorKind::NotFound {
            FileError::Missing { path: name(), kind }
        } else {
            FileError::Io {
                path: name(),
                kind,
                source,
            }
        }
    };
    let check = |meta: &Metadata| -> Result<u64, FileError> {
        if !meta.is_file() {
            return Err(FileError::NotRegular {
                path: name(),
                kind,
                what: describe(meta),
            });
        }
        if meta.len() > limit {
            return Err(FileError::TooLarge {
                path: name(),
                kind,
                size: meta.len(),
                at_least: false,
                limit,
            });
        }
        Ok(meta.len())
    };
    // Before opening: a FIFO or device is never opened.
    check(&std::fs::metadata(path).map_err(io)?)?;
    let file = open(path).map_err(io)?;
    // Through the handle: the file that is read is the one checked.
    let size = check(&file.metadata().map_err(io)?)?;
    bytes.try_reserve_exact(size as usize + 1).map_err(|_| {
        io(std::io::Error::new(
            std::io::ErrorKind::OutOfMemory,
            format!("no memory for {size} bytes"),
        ))
    })?;
    file.take(limit.saturating_add(1))
        .read_to_end(bytes)
        .map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(FileError::TooLarge {
            path: name(),
            kind,
            size: bytes.len() as u64,
            at_least: true,
            limit,
        });
    }
    Ok(())
}

/// Reads a whole regular text file (UTF-8) of `kind`, at most the kind's
/// limit.
pub fn read_text(path: &Path, kind: FileKind) -> Result<String, FileError> {
    let bytes = read_bytes(path, kind)?;
    String::from_utf8(bytes).map_err(|e| FileError::NotText {
        path: path.display().to_string(),
        kind,
        offset: e.utf8_error().valid_up_to(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("photopose-file-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn every_kind_has_a_name_and_a_limit() {
        for kind in FileKind::ALL {
            assert!(!kind.name().is_empty());
            assert!(kind.limit() >= 64 * KIB, "{kind}");
        }
        assert_eq!(FileKind::Recording.limit(), 4 * GIB);
    }

    #[test]
    fn reads_a_regular_file_within_its_limit() {
        let dir = scratch("ok");
        let p = dir.join("c.toml");
        std::fs::write(&p, "a = 1\n").unwrap();
        assert_eq!(read_text(&p, FileKind::Camera).unwrap(), "a = 1\n");
        assert_eq!(read_bytes(&p, FileKind::Camera).unwrap(), b"a = 1\n");
        // Exactly at the limit is fine; one byte over is not.
        assert_eq!(
            read_bytes_limited(&p, FileKind::Camera, 6).unwrap().len(),
            6
        );
        let e = read_bytes_limited(&p, FileKind::Camera, 5).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{}: too large for the camera file: 6 bytes, the limit is 5 bytes",
                p.display()
            )
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_large_file_is_refused_naming_path_kind_size_and_limit() {
        let dir = scratch("large");
        let p = dir.join("he.toml");
        let f = File::create(&p).unwrap();
        f.set_len(FileKind::HandEye.limit() + 10).unwrap();
        let e = read_text(&p, FileKind::HandEye).unwrap_err();
        let size = FileKind::HandEye.limit() + 10;
        assert!(
            matches!(e, FileError::TooLarge { size: s, at_least: false, .. } if s == size),
            "{e}"
        );
        let msg = e.to_string();
        assert!(msg.starts_with(&p.display().to_string()), "{msg}");
        assert!(
            msg.contains("hand-eye file") && msg.contains(&size.to_string()),
            "{msg}"
        );
        assert!(
            msg.contains(&FileKind::HandEye.limit().to_string()),
            "{msg}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_directory_and_a_missing_file_are_named() {
        let dir = scratch("dir");
        let e = read_text(&dir, FileKind::Field).unwrap_err().to_string();
        assert!(e.contains("it is a directory, not a regular file"), "{e}");
        assert!(e.contains("field file"), "{e}");
        let e = read_text(&dir.join("nope.csv"), FileKind::Field).unwrap_err();
        assert!(matches!(e, FileError::Missing { .. }), "{e}");
        assert!(e
            .to_string()
            .ends_with("nope.csv: cannot read the field file: no such file"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn invalid_utf8_is_named_with_its_offset() {
        let dir = scratch("utf8");
        let p = dir.join("obs.csv");
        std::fs::write(&p, b"id,col,row\n\xff\n").unwrap();
        let e = read_text(&p, FileKind::Observations)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("not UTF-8 text") && e.contains("offset 11"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn devices_and_proc_files_are_bounded() {
        // /dev/zero is endless: refused before it is opened.
        for kind in FileKind::ALL {
            let e = read_bytes(Path::new("/dev/zero"), kind).unwrap_err();
            assert!(
                matches!(
                    e,
                    FileError::NotRegular {
                        what: "a character device",
                        ..
                    }
                ),
                "{kind}: {e}"
            );
        }
        // A /proc file reports size 0 but has content: read, within the limit.
        if let Ok(text) = read_text(Path::new("/proc/self/status"), FileKind::Config) {
            assert!(text.contains("Name:"));
        }
    }
}
