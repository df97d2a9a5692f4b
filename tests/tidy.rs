//! The workspace's invariants as a test, not prose:
//!
//! - the pure crates (frame, geometry, field, render, vision, locate,
//!   circle, handeye, calibrate) use no files, sockets, threads or clocks in
//!   their sources, carry the `clippy.toml` that makes clippy refuse them,
//!   and have neither tokio nor aravis (nor glib) in their dependency tree;
//! - the GenTL loader (`libloading`) is reachable only through the `gentl`
//!   feature: named in one module's code (`photopose-gentl`'s `ffi`), absent
//!   from the binary's and the pipeline's trees without their features;
//!   Zenoh likewise is in the binary's tree only with its `zenoh` feature;
//! - `unsafe` is allowed in the quarantined modules only;
//! - every module opens with a `//!` comment saying what it owns;
//! - no document of the repository points outside it (`../shared`);
//! - no Rust Debug text reaches a user: the sources of the binary and of
//!   every library (their code before `#[cfg(test)]`) format no value with
//!   `{:?}` and log no tracing field with `?` (Debug); values are named
//!   and printed with their units.

mod common;

use common::root;
use std::path::{Path, PathBuf};
use std::process::Command;

const PURE: [&str; 9] = [
    "frame",
    "geometry",
    "field",
    "render",
    "vision",
    "locate",
    "circle",
    "handeye",
    "calibrate",
];

/// What a pure crate's sources must not name.
const FORBIDDEN: [&str; 5] = [
    "std::fs",
    "std::net",
    "std::thread",
    "Instant",
    "SystemTime",
];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The code of a line, without a trailing `//` comment (good enough for
/// the names looked for: none of them appears in a string literal here).
fn code(line: &str) -> &str {
    let t = line.trim_start();
    if t.starts_with("//") {
        return "";
    }
    line.split("//").next().unwrap_or("")
}

#[test]
fn pure_crates_do_no_io_threads_or_clocks() {
    let mut found = Vec::new();
    for c in PURE {
        let mut files = Vec::new();
        rust_files(&root().join("crates").join(c).join("src"), &mut files);
        assert!(!files.is_empty(), "crates/{c}/src has no sources");
        for f in files {
            let text = std::fs::read_to_string(&f).unwrap();
            for (n, line) in text.lines().enumerate() {
                let code = code(line);
                for word in FORBIDDEN {
                    if code.contains(word) {
                        found.push(format!("{}:{}: {word}", f.display(), n + 1));
                    }
                }
            }
        }
        assert!(
            root().join("crates").join(c).join("clippy.toml").exists(),
            "crates/{c}/clippy.toml (disallowed IO, threads and clocks) is missing"
        );
    }
    assert!(
        found.is_empty(),
        "pure crates doing IO:\n{}",
        found.join("\n")
    );
}

/// `cargo tree` of a package's normal dependencies, one crate a line.
fn tree(package: &str, extra: &[&str]) -> String {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(&cargo)
        .current_dir(root())
        .args([
            "tree",
            "--offline",
            "-e",
            "normal",
            "--prefix",
            "none",
            "-p",
            package,
        ])
        .args(extra)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cargo tree -p {package}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn has(tree: &str, krate: &str) -> bool {
    tree.lines()
        .any(|l| l.split_whitespace().next() == Some(krate))
}

#[test]
fn pure_crates_depend_on_neither_tokio_nor_aravis() {
    for c in PURE {
        let t = tree(&format!("photopose-{c}"), &[]);
        for bad in ["tokio", "aravis", "glib", "zenoh"] {
            assert!(!has(&t, bad), "photopose-{c} depends on {bad}:\n{t}");
        }
    }
}

#[test]
fn the_binary_without_default_features_links_no_aravis_and_has_tokio() {
    let lean = tree("photopose", &["--no-default-features"]);
    for bad in [
        "aravis",
        "aravis-sys",
        "glib",
        "libloading",
        "photopose-gentl",
        "zenoh",
    ] {
        assert!(!has(&lean, bad), "--no-default-features still has {bad}");
    }
    let full = tree("photopose", &[]);
    assert!(has(&full, "tokio"), "tokio in the binary's tree");
    assert!(has(&full, "aravis"), "the default build has GigE");
    assert!(has(&full, "libloading"), "the default build has GenTL");
    assert!(has(&full, "zenoh"), "the default build has Zenoh");
}

#[test]
fn the_gentl_loader_is_only_reachable_with_its_feature() {
    let pipeline = tree("photopose-pipeline", &["--no-default-features"]);
    for bad in ["libloading", "photopose-gentl"] {
        assert!(
            !has(&pipeline, bad),
            "photopose-pipeline without features has {bad}"
        );
    }
    let with = tree(
        "photopose-pipeline",
        &["--no-default-features", "--features", "gentl"],
    );
    assert!(
        has(&with, "libloading"),
        "the gentl feature brings the loader"
    );
    // In code, the loader is named by the quarantined module only.
    let mut files = Vec::new();
    rust_files(&root().join("crates"), &mut files);
    rust_files(&root().join("src"), &mut files);
    let ffi = root().join("crates/gentl/src/ffi.rs");
    let found: Vec<String> = files
        .iter()
        .filter(|f| **f != ffi && !f.to_string_lossy().contains("/target/"))
        .filter(|f| {
            std::fs::read_to_string(f)
                .unwrap()
                .lines()
                .any(|l| code(l).contains("libloading"))
        })
        .map(|f| f.display().to_string())
        .collect();
    assert!(
        found.is_empty(),
        "libloading named outside the GenTL ffi: {found:?}"
    );
}

#[test]
fn unsafe_code_is_allowed_in_the_quarantined_modules_only() {
    // The crate roots that allow `unsafe` for one private module (or, for
    // the test kit, the whole crate).
    let allowed = [
        "crates/acquire/src/lib.rs",
        "crates/gentl/src/lib.rs",
        "crates/gentl-producer/src/lib.rs",
        "crates/testkit/src/lib.rs",
        "crates/vision/src/lib.rs",
    ];
    let mut files = Vec::new();
    rust_files(&root().join("crates"), &mut files);
    rust_files(&root().join("src"), &mut files);
    rust_files(&root().join("tests"), &mut files);
    let needle = concat!("allow(", "unsafe_code)");
    let mut found = Vec::new();
    for f in files
        .iter()
        .filter(|f| !f.to_string_lossy().contains("/target/"))
    {
        let rel = f
            .strip_prefix(root())
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let text = std::fs::read_to_string(f).unwrap();
        if text.lines().any(|l| code(l).contains(needle)) && !allowed.contains(&rel.as_str()) {
            found.push(rel);
        }
    }
    assert!(
        found.is_empty(),
        "unsafe allowed outside the quarantine: {found:?}"
    );
}

#[test]
fn every_module_says_what_it_owns() {
    let mut files = Vec::new();
    rust_files(&root().join("crates"), &mut files);
    rust_files(&root().join("src"), &mut files);
    let missing: Vec<String> = files
        .iter()
        .filter(|f| {
            let s = f.to_string_lossy();
            s.contains("/src/") && !s.contains("/target/")
        })
        .filter(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            !text.trim_start().starts_with("//!")
        })
        .map(|f| f.display().to_string())
        .collect();
    assert!(
        missing.is_empty(),
        "modules without a //! comment:\n{}",
        missing.join("\n")
    );
}

#[test]
fn no_document_points_outside_the_repository() {
    let mut docs: Vec<PathBuf> = vec![root().join("README.md"), root().join("ARCHITECTURE.md")];
    for dir in ["docs", "config", "systemd", "fixtures"] {
        let mut stack = vec![root().join(dir)];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    docs.push(p);
                }
            }
        }
    }
    let mut found = Vec::new();
    for d in docs {
        let Ok(text) = std::fs::read_to_string(&d) else {
            continue; // binary data (recordings, images)
        };
        for (n, line) in text.lines().enumerate() {
            if line.contains("shared/spec") || line.contains("../shared") {
                found.push(format!("{}:{}", d.display(), n + 1));
            }
        }
    }
    assert!(
        found.is_empty(),
        "pointers outside the repository:\n{}",
        found.join("\n")
    );
}

/// Where a line of code formats a value as Rust Debug text: `{:?}`,
/// `{x:?}`, `{:#?}` or a tracing field recorded with `?`.
fn debug_formatting(code: &str) -> bool {
    let b = code.as_bytes();
    let format_spec = b.windows(3).any(|w| w == b":?}") || b.windows(4).any(|w| w == b":#?}");
    // `?field` or `name = ?value` in a tracing macro's field list.
    let tracing_field = code.trim_start().starts_with('?')
        || ["(?", ", ?", "= ?"].iter().any(|p| {
            code.match_indices(p).any(|(i, _)| {
                code[i + p.len()..]
                    .chars()
                    .next()
                    .is_some_and(|c| c.is_ascii_lowercase() || c == '_')
            })
        });
    format_spec || tracing_field
}

#[test]
fn no_rust_debug_text_reaches_users() {
    assert!(debug_formatting(r#"format!("{x:?}")"#));
    assert!(debug_formatting(r#"tracing::debug!(?exit, "joined")"#));
    assert!(debug_formatting(
        r#"tracing::info!(threads = ?threads, "x")"#
    ));
    assert!(!debug_formatting(r#"let v = f(x)?; let w = g()?;"#));
    assert!(!debug_formatting(r#"tracing::info!(error = %e, "x")"#));
    let mut files = Vec::new();
    rust_files(&root().join("src"), &mut files);
    if let Ok(crates) = std::fs::read_dir(root().join("crates")) {
        for c in crates.flatten() {
            rust_files(&c.path().join("src"), &mut files);
        }
    }
    let mut found = Vec::new();
    for f in &files {
        if f.file_name().is_some_and(|n| n == "tests.rs") {
            continue; // a test module of its own
        }
        let text = std::fs::read_to_string(f).unwrap();
        for (k, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("#[cfg(test)]") {
                break;
            }
            if debug_formatting(code(line)) {
                found.push(format!("{}:{}: {}", f.display(), k + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "Rust Debug text in what users see (name the value and its unit instead):\n{}",
        found.join("\n")
    );
}
