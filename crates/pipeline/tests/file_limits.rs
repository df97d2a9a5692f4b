//! The daemon reads its files with limits: the configuration and the
//! controller file it names are regular files of bounded size (a device or
//! FIFO is refused at once, naming the file and the key), and a replay
//! refuses a recording that is larger than `source.replay.max_bytes` or
//! whose checksums fail, naming the file.

use photopose_frame::{Image, Pixels};
use photopose_pipeline::config::Source;
use photopose_pipeline::source::ReplaySource;
use photopose_pipeline::Config;
use photopose_record::{FrameMeta, Recorder};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "photopose-pipeline-limits-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs `f` on its own thread; a read that blocks fails the test.
fn within<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(10))
        .expect("the read did not return in time (blocked)")
}

fn load_err(path: &Path) -> String {
    let p = path.to_path_buf();
    within(move || Config::load(&p).err().map(|e| e.to_string())).expect("refused")
}

#[cfg(target_os = "linux")]
#[test]
fn dev_zero_as_configuration_or_controller_file_is_refused() {
    let e = load_err(Path::new("/dev/zero"));
    assert_eq!(
        e,
        "/dev/zero: cannot read the configuration file: it is a character device, not a regular file"
    );
    let dir = scratch("zero");
    let cfg = dir.join("photopose.toml");
    std::fs::write(
        &cfg,
        "[source]\nkind = \"synthetic\"\n[rsi]\nenabled = true\nethernet_config = \"/dev/zero\"\n\
         hand_eye = \"he.toml\"\n",
    )
    .unwrap();
    let e = load_err(&cfg);
    assert!(
        e.starts_with("/dev/zero: cannot read the controller file (RSI_EthernetConfig.xml)")
            && e.ends_with("(named by `rsi.ethernet_config`)"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[cfg(unix)]
#[test]
fn a_fifo_as_configuration_is_refused_without_blocking() {
    let dir = scratch("fifo");
    let fifo = dir.join("photopose.toml");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let e = load_err(&fifo);
    assert!(
        e.contains("it is a FIFO (named pipe), not a regular file"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_oversized_configuration_or_controller_file_is_refused_by_size() {
    let dir = scratch("big");
    let cfg = dir.join("photopose.toml");
    let f = std::fs::File::create(&cfg).unwrap();
    f.set_len(10 << 20).unwrap();
    drop(f);
    let e = load_err(&cfg);
    assert!(
        e.contains("too large for the configuration file: 10485760 bytes, the limit is"),
        "{e}"
    );
    // Controller files of 880 KB (hung the old XML parser) and 10 MB are
    // refused by size before they are parsed.
    let xml = dir.join("RSI_EthernetConfig.xml");
    for size in [880_000, 10 << 20] {
        let mut text = String::from("<ROOT><CONFIG><IP_NUMBER>127.0.0.1</IP_NUMBER>");
        while text.len() < size {
            text.push_str("<ELEMENT TAG=\"DEF_RIst.X\" TYPE=\"DOUBLE\" INDX=\"1\" />\n");
        }
        text.push_str("</CONFIG></ROOT>\n");
        std::fs::write(&xml, &text).unwrap();
        std::fs::write(
            &cfg,
            format!(
                "[source]\nkind = \"synthetic\"\n[rsi]\nenabled = true\nethernet_config = \"{}\"\n\
                 hand_eye = \"he.toml\"\n",
                xml.display()
            ),
        )
        .unwrap();
        let e = load_err(&cfg);
        assert!(
            e.contains(&format!(
                "too large for the controller file (RSI_EthernetConfig.xml): {} bytes, \
                 the limit is 65536 bytes",
                text.len()
            )) && e.ends_with("(named by `rsi.ethernet_config`)"),
            "{e}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn replay_config(path: &Path, extra: &str) -> Result<Config, String> {
    Config::parse(
        &format!(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"{}\"\nspeed = \"max\"\n{extra}",
            path.display()
        ),
        "test.toml",
    )
    .map_err(|e| e.to_string())
}

fn replay_err(cfg: &Config) -> String {
    let Source::Replay(r) = &cfg.source else {
        panic!("replay expected")
    };
    ReplaySource::open(&photopose_formats::default_camera(), r)
        .expect_err("refused")
        .to_string()
}

#[test]
fn a_replay_refuses_a_large_or_corrupt_recording_naming_the_file() {
    let dir = scratch("replay");
    let path = dir.join("run.mcap");
    let cam = photopose_formats::default_camera();
    let (w, h) = (cam.sensor.width, cam.sensor.height);
    // Uncompressed: the file is larger than the small limit below.
    let options = photopose_record::RecordOptions {
        compression: photopose_record::Compression::None,
        ..Default::default()
    };
    let mut rec = Recorder::create_with(&path, &options).unwrap();
    for k in 0..2u8 {
        let px = vec![k.wrapping_mul(40).wrapping_add(3); (w * h) as usize];
        let img = Image::from_pixels(w, h, 255, Pixels::Mono8(px)).unwrap();
        let meta = FrameMeta {
            seq: k as u64,
            camera_time_ns: k as u64 * 10_000_000,
            host_time_ns: 0,
            ..FrameMeta::default()
        };
        rec.write(meta, &img).unwrap();
    }
    rec.finish().unwrap();
    let size = std::fs::metadata(&path).unwrap().len();

    // The default limit takes it; a smaller configured one does not.
    let cfg = replay_config(&path, "").unwrap();
    let Source::Replay(r) = &cfg.source else {
        panic!()
    };
    assert_eq!(r.max_bytes, 4 << 30);
    assert_eq!(ReplaySource::open(&cam, r).unwrap().len(), 2);
    let small = replay_config(&path, "max_bytes = 1000000\n").unwrap();
    assert_eq!(
        replay_err(&small),
        format!(
            "{}: too large for the recording: {size} bytes, the limit is 1000000 bytes",
            path.display()
        )
    );
    let e = replay_config(&path, "max_bytes = 0\n").unwrap_err();
    assert!(
        e.starts_with("test.toml: `source.replay.max_bytes` = 0"),
        "{e}"
    );

    // One flipped bit in the second frame's pixels.
    let mut bytes = std::fs::read(&path).unwrap();
    let pattern = vec![43u8; 64];
    let at = bytes
        .windows(64)
        .position(|win| win == pattern.as_slice())
        .unwrap();
    bytes[at + 1000] ^= 0x10;
    let bad = dir.join("flipped.mcap");
    std::fs::write(&bad, &bytes).unwrap();
    let e = replay_err(&replay_config(&bad, "").unwrap());
    assert!(
        e.starts_with(&format!(
            "{}: corrupt recording: a chunk's CRC",
            bad.display()
        )),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
