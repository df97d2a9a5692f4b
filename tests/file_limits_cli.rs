//! The binary reads every file with limits: a device, FIFO or oversized
//! file given as camera, field, hand-eye, station, pose, configuration or
//! image file is refused at once with the file named; an image whose header
//! declares a huge size is refused from its header, even under a 3 GiB
//! address-space limit (it used to allocate 10 GB first and abort).
//!
//! Every command runs under `ulimit -v` (3 GiB) and a time bound, so a
//! regression fails the test instead of exhausting the machine.

mod common;

use common::{bin, fixture, scratch};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Runs `photopose ARGS` under a 3 GiB address-space limit; kills it after
/// 60 s (a blocked or endless read) and fails.
fn run_limited(args: &[&dyn AsRef<std::ffi::OsStr>]) -> Output {
    let mut cmd = Command::new("sh");
    cmd.arg("-c")
        .arg("ulimit -v 3145728 && exec \"$0\" \"$@\"")
        .arg(bin().get_program());
    for a in args {
        cmd.arg(a);
    }
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("photopose did not return within 60 s (blocked or endless read)");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn first_line(out: &Output) -> Value {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().next().unwrap_or_else(|| {
        panic!(
            "no output line; status {:?}, stderr {}",
            out.status,
            stderr(out)
        )
    });
    serde_json::from_str(line).unwrap()
}

/// A 62-byte greyscale PNG declaring 100000 × 100000 8-bit pixels.
fn huge_png() -> Vec<u8> {
    fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let start = out.len();
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
        let crc = crc32(&out[start..]);
        out.extend_from_slice(&crc.to_be_bytes());
    }
    // Bitwise CRC-32 (the root crate has no CRC dependency; test only).
    fn crc32(data: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in data {
            crc ^= b as u32;
            for _ in 0..8 {
                crc = (crc >> 1) ^ (0xedb8_8320 & (crc & 1).wrapping_neg());
            }
        }
        !crc
    }
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = 100_000u32.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    chunk(&mut out, b"IDAT", &[0x78, 0x9c, 0x63, 0x60, 0]);
    chunk(&mut out, b"IEND", &[]);
    out
}

#[test]
fn a_62_byte_png_declaring_100000_squared_pixels_is_refused_from_its_header() {
    let dir = scratch("hugepng");
    let png = dir.join("huge.png");
    let bytes = huge_png();
    assert_eq!(bytes.len(), 62);
    std::fs::write(&png, bytes).unwrap();
    let pgm = dir.join("huge.pgm");
    std::fs::write(&pgm, b"P5\n100000 100000\n255\n\0\0\0\0").unwrap();
    for p in [&png, &pgm] {
        let out = run_limited(&[&"resect", p]);
        // An error line and exit status 1, not an abort.
        assert_eq!(out.status.code(), Some(1), "stderr: {}", stderr(&out));
        let v = first_line(&out);
        assert_eq!(v["ok"], false);
        assert_eq!(
            v["error"],
            format!(
                "{}: image is 100000×100000, camera file says 1300×1030",
                p.display()
            )
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[cfg(target_os = "linux")]
#[test]
fn dev_zero_is_refused_as_any_input_file() {
    let zero = Path::new("/dev/zero");
    let obs = fixture("observations/oblique-0.1px.csv");
    let out_dir = scratch("zero");
    let he_out = out_dir.join("he.toml");
    let poses = out_dir.join("poses.jsonl");
    std::fs::write(
        &poses,
        "{\"status\":\"ok\",\"pose\":{\"position_mm\":[0,0,1000],\"rotation_field_to_camera\":[[1,0,0],[0,1,0],[0,0,1]]}}\n",
    )
    .unwrap();
    // (arguments, what the error must say)
    let cases: Vec<(Vec<&dyn AsRef<std::ffi::OsStr>>, &str)> = vec![
        (
            vec![&"resect", &"--camera", &zero, &"--observations", &obs],
            "camera file",
        ),
        (
            vec![&"resect", &"--field", &zero, &"--observations", &obs],
            "field file",
        ),
        (
            vec![&"resect", &"--observations", &zero],
            "observation file",
        ),
        (vec![&"resect", &zero], "image file"),
        (vec![&"circle-test", &zero], "pose file"),
        (
            vec![&"circle-test", &poses, &"--hand-eye", &zero],
            "hand-eye file",
        ),
        (
            vec![
                &"calibrate",
                &"hand-eye",
                &"--stations",
                &zero,
                &"--out",
                &he_out,
            ],
            "station file",
        ),
        (vec![&"check-config", &zero], "configuration file"),
    ];
    for (args, kind) in cases {
        let out = run_limited(&args);
        assert!(!out.status.success(), "{kind}: accepted /dev/zero");
        // Batch commands report on stdout, the others on stderr.
        let all = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
        assert!(
            all.contains(&format!(
                "/dev/zero: cannot read the {kind}: it is a character device, not a regular file"
            )),
            "{kind}: status {:?}: {all}",
            out.status
        );
    }
    std::fs::remove_dir_all(&out_dir).unwrap();
}

#[cfg(unix)]
#[test]
fn a_fifo_is_refused_without_waiting_for_a_writer() {
    let dir = scratch("fifo");
    let fifo = dir.join("poses.jsonl");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let started = Instant::now();
    let out = run_limited(&[&"circle-test", &fifo]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("it is a FIFO (named pipe), not a regular file"),
        "{}",
        stderr(&out)
    );
    assert!(started.elapsed() < Duration::from_secs(30));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_config_refuses_a_hand_eye_file_with_huge_translations() {
    let dir = scratch("hugehe");
    let he = dir.join("he.toml");
    std::fs::write(
        &he,
        "[camera_in_tcp]\nxyzabc = [1.7e308, 0.0, -80.0, 0.0, 0.0, 180.0]\n\
         std_xyzabc = [0.01, 0.01, 0.01, 0.001, 0.001, 0.001]\n\
         [plate_in_base]\nxyzabc = [400.0, 0.0, -200.0, 0.0, 0.0, 0.0]\n\
         std_xyzabc = [0.01, 0.01, 0.01, 0.001, 0.001, 0.001]\n",
    )
    .unwrap();
    let cfg = dir.join("photopose.toml");
    std::fs::write(
        &cfg,
        format!(
            "[source]\nkind = \"synthetic\"\n[rsi]\nenabled = true\nbind = \"127.0.0.1\"\n\
             port = 59152\ncontrollers = [\"127.0.0.1\"]\nhand_eye = \"{}\"\n",
            he.display()
        ),
    )
    .unwrap();
    let out = run_limited(&[&"check-config", &cfg]);
    assert!(!out.status.success(), "accepted: {}", stderr(&out));
    let e = stderr(&out);
    assert!(
        e.contains(&format!("{}: camera_in_tcp.xyzabc[0] (X) = ", he.display()))
            && e.contains("is outside ±100000 mm"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
