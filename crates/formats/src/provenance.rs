//! Provenance of everything photopose writes for people to keep: which tool
//! and version made it, when (UTC, RFC 3339), and from which input files
//! (path and SHA-256 of the bytes read). The one home of these facts: camera
//! files, calibration and circle-test reports (text and JSON) and their SVG
//! plots all take them from a [`Provenance`].
//!
//! The date is the wall clock at the time of writing, or the instant of the
//! environment variable `SOURCE_DATE_EPOCH` (seconds since 1970, the
//! reproducible-builds convention) when it is set, so that two runs on the
//! same inputs can write byte-identical files.

use crate::{FileKind, FormatError};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::fmt::Write;
use std::path::Path;
use std::time::{Duration, SystemTime};

/// Name and version of the tool, as written into every report.
pub const TOOL: &str = concat!("photopose ", env!("CARGO_PKG_VERSION"));

/// One input file: its path as given and the SHA-256 of its bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputFile {
    /// The path as given on the command line (or in a station file).
    pub path: String,
    /// SHA-256 of the file's bytes, 64 lower-case hex digits.
    pub sha256: String,
}

/// Tool, date and inputs of one report or file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// Tool and version, e.g. `photopose 0.1.0`.
    pub tool: String,
    /// When the report was made: UTC, RFC 3339 (`2026-11-24T16:08:08Z`).
    pub date: String,
    /// The input files.
    pub inputs: Vec<InputFile>,
}

impl Provenance {
    /// Provenance dated `date` (whole seconds) with these inputs.
    pub fn at(date: SystemTime, inputs: Vec<InputFile>) -> Provenance {
        Provenance {
            tool: TOOL.into(),
            date: rfc3339(date),
            inputs,
        }
    }

    /// Provenance dated now (or at `SOURCE_DATE_EPOCH`).
    pub fn now(inputs: Vec<InputFile>) -> Provenance {
        Provenance::at(report_time(), inputs)
    }

    /// One line: tool and date.
    pub fn headline(&self) -> String {
        format!("{}, {}", self.tool, self.date)
    }

    /// The provenance as text lines for a report: the headline, then one
    /// line per input file with its SHA-256.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "made by {}", self.headline());
        for i in &self.inputs {
            let _ = writeln!(s, "input {}  sha256 {}", i.path, i.sha256);
        }
        s
    }

    /// An SVG `<metadata>` element holding the provenance as JSON (escaped
    /// for XML), for a plot to carry where it came from.
    pub fn svg_metadata(&self) -> String {
        let json = serde_json::to_string(self).unwrap_or_default();
        format!(
            "<metadata id=\"photopose-provenance\">{}</metadata>\n",
            xml_escape(&json)
        )
    }

    /// `svg` with [`Provenance::svg_metadata`] inserted right after its
    /// opening `<svg …>` tag (unchanged when it has none).
    pub fn insert_into_svg(&self, svg: &str) -> String {
        let Some(open) = svg.find("<svg") else {
            return svg.to_string();
        };
        let Some(end) = svg[open..].find('>').map(|k| open + k + 1) else {
            return svg.to_string();
        };
        let mut s = String::with_capacity(svg.len() + 512);
        s.push_str(&svg[..end]);
        s.push('\n');
        s.push_str(&self.svg_metadata());
        s.push_str(svg[end..].trim_start_matches('\n'));
        s
    }
}

/// SHA-256 of `bytes` as 64 lower-case hex digits.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in digest {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// Reads `path` (a file of `kind`, with that kind's size limit) and returns
/// its path and SHA-256.
pub fn hash_file(path: &Path, kind: FileKind) -> Result<InputFile, FormatError> {
    let bytes = crate::read_bytes(path, kind)?;
    Ok(InputFile {
        path: path.display().to_string(),
        sha256: sha256_hex(&bytes),
    })
}

/// The instant a report is dated: `SOURCE_DATE_EPOCH` when it holds a
/// whole number of seconds, otherwise the wall clock.
pub fn report_time() -> SystemTime {
    std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok())
        .map(|s| SystemTime::UNIX_EPOCH + Duration::from_secs(s))
        .unwrap_or_else(SystemTime::now)
}

/// `t` as UTC RFC 3339 with whole seconds.
pub fn rfc3339(t: SystemTime) -> String {
    humantime::format_rfc3339_seconds(t).to_string()
}

/// Checks a date as written by [`rfc3339`] (UTC, RFC 3339).
pub fn parse_rfc3339(text: &str) -> Result<SystemTime, String> {
    humantime::parse_rfc3339(text)
        .map_err(|e| format!("\"{text}\" is not a UTC RFC 3339 date: {e}"))
}

/// True when `text` is 64 hex digits (a SHA-256 as written here).
pub fn is_sha256_hex(text: &str) -> bool {
    text.len() == 64 && text.bytes().all(|b| b.is_ascii_hexdigit())
}

/// `text` with `&`, `<`, `>` and quotes escaped for XML text and attributes.
pub fn xml_escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&apos;"),
            c => s.push(c),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_known_text() {
        // FIPS 180-2 example "abc".
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert!(is_sha256_hex(&sha256_hex(b"")));
        assert!(!is_sha256_hex("abc"));
    }

    #[test]
    fn dates_are_utc_rfc3339_with_seconds() {
        let t = SystemTime::UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        let p = Provenance::at(t, vec![]);
        assert_eq!(p.date, "2023-11-14T22:13:20Z");
        assert_eq!(parse_rfc3339(&p.date).unwrap(), t);
        assert!(p.tool.starts_with("photopose "));
        assert!(parse_rfc3339("yesterday").is_err());
    }

    #[test]
    fn a_file_is_hashed_as_read_and_named_in_the_text() {
        let dir = std::env::temp_dir().join(format!("photopose-prov-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a&b.csv");
        std::fs::write(&path, "abc").unwrap();
        let input = hash_file(&path, FileKind::Field).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(input.sha256, sha256_hex(b"abc"));
        let p = Provenance::at(SystemTime::UNIX_EPOCH, vec![input]);
        let text = p.to_text();
        assert!(text.contains("1970-01-01T00:00:00Z") && text.contains("a&b.csv  sha256 ba78"));
        let meta = p.svg_metadata();
        assert!(meta.contains("a&amp;b.csv") && !meta.contains("a&b"));
        assert!(meta.contains("&quot;sha256&quot;"));
        let svg = p.insert_into_svg("<?xml version=\"1.0\"?>\n<svg a=\"1\">\n<g/></svg>\n");
        assert!(svg.starts_with("<?xml version=\"1.0\"?>\n<svg a=\"1\">\n<metadata"));
        assert!(svg.ends_with("</metadata>\n<g/></svg>\n"), "{svg}");
        assert_eq!(p.insert_into_svg("no svg"), "no svg");
    }
}
