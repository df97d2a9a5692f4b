//! The daemon on GenTL sources (`source.kind = "gentl"`):
//!
//! - the workspace's test producer (`photopose-gentl-producer`, the `.cti`
//!   cargo builds for this test) serves the default plate rendered at a
//!   known pose per frame: `photopose run --frames 20` ends with 20 frames
//!   in, and every pose is within 0.1 mm of the render's truth (the frame
//!   is found from its camera timestamp);
//! - a pixel format photopose does not convert is refused, naming its PFNC
//!   value; a missing or invalid `.cti` is a clear error naming the file;
//! - `viky.cti` (third-party, installed by `.ci/deps.sh`; skipped with a
//!   printed reason when absent), found through `GENICAM_GENTL64_PATH`:
//!   `run --frames 20` ends with 20 frames in (RGBa8 → grey; viky's
//!   pattern holds no plate, so no poses are expected); `camera list`
//!   lists its three devices (from `GENICAM_GENTL64_PATH` and from
//!   `--config`'s `[source.gentl] producer`).

mod common;

use common::{bin, scratch, UdpMessages};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Output, Stdio};
use std::time::{Duration, Instant};

const VIKY_DIR: &str = "/opt/photopose-test/gentl";

/// The test producer cargo built for this test (a dev-dependency).
fn test_producer() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap();
    let name = "libphotopose_gentl_producer.so";
    [deps.join(name), deps.join("..").join(name)]
        .into_iter()
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("{name} not built next to {}", exe.display()))
}

/// Waits for `child` (killed after `limit`) and returns its output.
fn finish(mut child: Child, limit: Duration) -> Output {
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "the daemon did not end within {limit:?}:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

fn write_config(dir: &Path, gentl: &str, udp: &UdpSocket) -> PathBuf {
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"gentl\"\n[source.gentl]\n{gentl}\
             [pipeline]\nworkers = 2\nslots = 6\noverflow = \"block\"\n\
             [output]\nudp = [\"{}\"]\n",
            udp.local_addr().unwrap()
        ),
    )
    .unwrap();
    config
}

/// Runs `photopose run --frames <frames>` on `config` with `env` set,
/// killed after `limit`; its output.
fn run_frames(config: &Path, frames: u32, env: &[(&str, &str)], limit: Duration) -> Output {
    let child = bin()
        .args(["run", "--frames", &frames.to_string(), "--config"])
        .arg(config)
        .envs(env.iter().copied())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    finish(child, limit)
}

#[test]
fn poses_from_the_test_producer_agree_with_the_render_truth() {
    let dir = scratch("gentl-render");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = write_config(
        &dir,
        &format!(
            "producer = \"{}\"\ndevice = \"{}\"\nbuffers = 4\n",
            test_producer().display(),
            photopose_gentl_producer::SERIAL
        ),
        &rx,
    );
    let collected = UdpMessages::collect(&rx);
    let out = run_frames(&config, 20, &[], Duration::from_secs(300));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("20 frames in, 0 dropped"),
        "{stdout}\n{stderr}"
    );
    let msgs = collected.finish();
    let frames: Vec<_> = msgs.iter().filter(|v| v["status"] != "stale").collect();
    assert_eq!(frames.len(), 20, "{msgs:?}");
    let mut ok = 0;
    for v in frames {
        assert_eq!(v["status"], "ok", "{v}");
        let ts = v["time"]["camera_clock_ns"].as_u64().unwrap();
        let id = photopose_gentl_producer::frame_of_timestamp(ts)
            .unwrap_or_else(|| panic!("camera timestamp {ts} is the producer's"));
        let pose = photopose_gentl_producer::truth_pose(id);
        let truth = photopose_geometry::Exterior::from_kuka_pose(pose).center;
        let c: Vec<f64> = v["pose"]["position_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let err = (0..3)
            .map(|i| (c[i] - truth[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            err < 0.1,
            "frame {id}: centre {c:?} is {err} mm from {truth:?} (pose {pose:?})"
        );
        ok += 1;
    }
    assert_eq!(ok, 20);
}

#[test]
fn an_unsupported_pixel_format_is_refused_naming_its_value() {
    let dir = scratch("gentl-bayer");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = write_config(
        &dir,
        &format!("producer = \"{}\"\n", test_producer().display()),
        &rx,
    );
    // BayerRG8: the device now says it sends that.
    let bayer = [(photopose_gentl_producer::PFNC_VAR, "0x01080009")];
    let out = run_frames(&config, 5, &bayer, Duration::from_secs(120));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("0x01080009") && stderr.contains("not supported"),
        "{stderr}"
    );
}

#[test]
fn a_missing_or_invalid_producer_is_named() {
    let dir = scratch("gentl-bad");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    // Missing: refused by the validation, naming the key and the file.
    let missing = dir.join("absent.cti");
    let config = write_config(
        &dir,
        &format!("producer = \"{}\"\n", missing.display()),
        &rx,
    );
    let out = bin().args(["check-config"]).arg(&config).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("source.gentl.producer") && stderr.contains("absent.cti"),
        "{stderr}"
    );
    // Invalid: a file that is no shared library; `run` fails at once,
    // naming it.
    let text = dir.join("text.cti");
    std::fs::write(&text, "no producer\n").unwrap();
    let config = write_config(&dir, &format!("producer = \"{}\"\n", text.display()), &rx);
    let out = run_frames(&config, 5, &[], Duration::from_secs(60));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("text.cti") && stderr.contains("not usable"),
        "{stderr}"
    );
}

#[test]
fn run_on_viky_ends_with_its_twenty_frames() {
    if !Path::new(VIKY_DIR).join("viky.cti").is_file() {
        eprintln!("skipped: {VIKY_DIR}/viky.cti is absent (installed by .ci/deps.sh)");
        return;
    }
    let dir = scratch("gentl-viky");
    // viky's 400×400 sensor.
    let camera = dir.join("camera.toml");
    std::fs::write(
        &camera,
        "[sensor]\nwidth = 400\nheight = 400\npixel_size = 0.0067\n[interior]\nc = 12.0\nx0 = 0.0\ny0 = 0.0\n",
    )
    .unwrap();
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = write_config(&dir, "buffers = 4\n", &rx);
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(
        &config,
        format!("[camera]\ncamera_file = \"{}\"\n{text}", camera.display()),
    )
    .unwrap();
    // No `producer` key: the one .cti of this directory.
    let search = [("GENICAM_GENTL64_PATH", VIKY_DIR)];
    let out = run_frames(&config, 20, &search, Duration::from_secs(120));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("20 frames in, 0 dropped"),
        "{stdout}\n{stderr}"
    );
}

#[test]
fn camera_list_lists_the_devices_of_the_gentl_producer() {
    if !Path::new(VIKY_DIR).join("viky.cti").is_file() {
        eprintln!("skipped: {VIKY_DIR}/viky.cti is absent (installed by .ci/deps.sh)");
        return;
    }
    let viky_lines = |out: &Output| {
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(stdout.starts_with("transport\tid\tvendor\tmodel\tserial\taddress\n"));
        stdout
            .lines()
            .filter(|l| {
                l.split('\t')
                    .nth(5)
                    .is_some_and(|a| a.starts_with("viky.cti:"))
            })
            .map(str::to_string)
            .collect::<Vec<String>>()
    };
    // Through GENICAM_GENTL64_PATH.
    let out = bin()
        .args(["camera", "list"])
        .env("GENICAM_GENTL64_PATH", VIKY_DIR)
        .output()
        .unwrap();
    let lines = viky_lines(&out);
    assert_eq!(lines.len(), 3, "viky's three devices: {lines:?}");
    let ids: std::collections::BTreeSet<&str> =
        lines.iter().filter_map(|l| l.split('\t').nth(1)).collect();
    assert_eq!(ids.len(), 3, "distinct ids: {lines:?}");
    // Through the daemon's configuration.
    let dir = scratch("gentl-list");
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        format!("[source]\nkind = \"gentl\"\n[source.gentl]\nproducer = \"{VIKY_DIR}/viky.cti\"\n"),
    )
    .unwrap();
    let out = bin()
        .args(["camera", "list", "--config"])
        .arg(&config)
        .env_remove("GENICAM_GENTL64_PATH")
        .output()
        .unwrap();
    assert_eq!(viky_lines(&out), lines);
}
