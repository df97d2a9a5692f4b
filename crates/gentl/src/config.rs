//! The GenTL source's settings ([`GentlConfig`], with its one set of
//! defaults) and the producer search: a file named in the configuration, or
//! the one `.cti` found through `GENICAM_GENTL64_PATH` (the standard's
//! variable: a `:`-separated list of directories).

use crate::error::GentlError;
use crate::system::check_producer_file;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The environment variable GenTL consumers search producers with.
pub const PRODUCER_PATH_VAR: &str = "GENICAM_GENTL64_PATH";

/// How to open and run a GenTL device.
#[derive(Debug, Clone, PartialEq)]
pub struct GentlConfig {
    /// The producer file (`.cti`).
    pub producer: PathBuf,
    /// Device id or serial number; `None` takes the first device found.
    pub device: Option<String>,
    /// Buffers of ours announced to the data stream (≥ 2; more if the
    /// producer asks for more), allocated at each opening.
    pub buffers: usize,
    /// Bytes of one buffer when the producer's data stream does not define
    /// the payload size (it then comes from the remote device's
    /// `PayloadSize` feature, which photopose does not read): e.g.
    /// width × height × bytes per pixel. Ignored when the stream says it.
    pub payload_size: Option<usize>,
    /// No buffer at all for this long means the device is lost (also the
    /// timeout of device discovery).
    pub timeout: Duration,
    /// First wait before reopening a lost device; doubles per failure.
    pub backoff_initial: Duration,
    /// Longest wait between reopening attempts.
    pub backoff_max: Duration,
}

impl GentlConfig {
    /// The defaults for the producer at `producer`.
    pub fn new(producer: PathBuf) -> GentlConfig {
        GentlConfig {
            producer,
            device: None,
            buffers: 8,
            payload_size: None,
            timeout: Duration::from_secs(2),
            backoff_initial: Duration::from_millis(100),
            backoff_max: Duration::from_secs(5),
        }
    }
}

/// The producer to use: `explicit` if given (it must be a regular file),
/// else the one `.cti` file in the directories (or files) listed in
/// `search` (the value of [`PRODUCER_PATH_VAR`]). `key` names the
/// configuration key in errors.
pub fn find_producer(
    explicit: Option<&Path>,
    search: Option<&OsStr>,
    key: &str,
) -> Result<PathBuf, GentlError> {
    if let Some(p) = explicit {
        check_producer_file(p)?;
        return Ok(p.to_path_buf());
    }
    let Some(search) = search.filter(|s| !s.is_empty()) else {
        return Err(GentlError::NoProducer {
            key: key.into(),
            searched: format!("{PRODUCER_PATH_VAR} is not set"),
        });
    };
    let mut found = Vec::new();
    for entry in std::env::split_paths(search) {
        if entry.is_file() {
            found.push(entry);
        } else if let Ok(dir) = std::fs::read_dir(&entry) {
            let mut here: Vec<PathBuf> = dir
                .flatten()
                .map(|e| e.path())
                .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "cti"))
                .collect();
            here.sort();
            found.extend(here);
        }
    }
    match found.len() {
        0 => Err(GentlError::NoProducer {
            key: key.into(),
            searched: format!(
                "no .cti file in {PRODUCER_PATH_VAR}={}",
                search.to_string_lossy()
            ),
        }),
        1 => Ok(found.remove(0)),
        _ => Err(GentlError::AmbiguousProducer {
            key: key.into(),
            found: found
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("photopose-gentl-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn the_producer_is_found_named_or_through_the_variable() {
        let d = scratch("find");
        let a = d.join("a.cti");
        std::fs::write(&a, b"x").unwrap();
        assert_eq!(find_producer(Some(&a), None, "k").unwrap(), a);
        let missing = d.join("missing.cti");
        let e = find_producer(Some(&missing), None, "k").unwrap_err();
        assert!(e.to_string().contains("missing.cti"), "{e}");
        assert!(matches!(e, GentlError::MissingProducer { .. }));
        // A directory is not a producer file.
        let e = find_producer(Some(&d), None, "k").unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        // Through the variable: one .cti in the listed directories.
        let var = std::env::join_paths([d.join("nowhere"), d.clone()]).unwrap();
        assert_eq!(find_producer(None, Some(&var), "k").unwrap(), a);
        std::fs::write(d.join("b.cti"), b"x").unwrap();
        let e = find_producer(None, Some(&var), "source.gentl.producer").unwrap_err();
        assert!(
            matches!(e, GentlError::AmbiguousProducer { .. })
                && e.to_string().contains("source.gentl.producer"),
            "{e}"
        );
        let e = find_producer(None, None, "source.gentl.producer").unwrap_err();
        assert!(
            e.to_string().contains("GENICAM_GENTL64_PATH is not set"),
            "{e}"
        );
        let empty = scratch("find-empty");
        let e = find_producer(None, Some(empty.as_os_str()), "k").unwrap_err();
        assert!(e.to_string().contains("no .cti file"), "{e}");
    }
}
