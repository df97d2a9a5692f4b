//! The running daemon records (`run --record`): a recording of 50
//! synthetic frames holds, read with the `mcap` crate and only the schemas
//! inside the file, 50 Foxglove images, 50 poses, the attachments and the
//! metadata; replayed twice at speed `max` it gives the same poses with
//! nothing dropped; `export` writes its frames as PGM. The run prints the
//! bytes per frame and the compression ratio.

mod common;

use common::{bin, scratch};
use std::collections::BTreeMap;
use std::net::UdpSocket;
use std::path::Path;
use std::time::Duration;

fn run(args: &[&str], config: Option<&Path>) -> String {
    let mut cmd = bin();
    cmd.arg("run").args(args);
    if let Some(c) = config {
        cmd.arg("--config").arg(c);
    }
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn poses(config: &Path, rx: &UdpSocket) -> (Vec<String>, String) {
    // Read while the daemon runs: 50 messages of about 2 kB each would
    // overflow the socket's default receive buffer if left queued.
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reader = {
        let rx = rx.try_clone().unwrap();
        let done = std::sync::Arc::clone(&done);
        std::thread::spawn(move || {
            rx.set_read_timeout(Some(Duration::from_millis(300)))
                .unwrap();
            let mut buf = [0u8; 8192];
            let mut lines = Vec::new();
            loop {
                match rx.recv(&mut buf) {
                    Ok(n) => {
                        let v: serde_json::Value = serde_json::from_slice(&buf[..n]).unwrap();
                        common::check_pose_message(&v);
                        lines.push(common::without_run_times(v).to_string());
                    }
                    Err(_) if done.load(std::sync::atomic::Ordering::Acquire) => break,
                    Err(_) => {}
                }
            }
            lines
        })
    };
    let summary = run(&[], Some(config));
    done.store(true, std::sync::atomic::Ordering::Release);
    (reader.join().unwrap(), summary)
}

#[test]
fn a_daemon_recording_is_standard_mcap_and_replays_the_same_twice() {
    let dir = scratch("record-run");
    let recording = dir.join("daemon.mcap");
    let summary = run(
        &["--frames", "50", "--record", recording.to_str().unwrap()],
        None,
    );
    // The figures asked for in the report (bytes per frame, ratio).
    println!("{summary}");
    assert!(
        summary.contains("50 frames (0 dropped), 50 poses (0 dropped)"),
        "{summary}"
    );

    // Only the mcap crate and the schemas in the file.
    let bytes = std::fs::read(&recording).unwrap();
    let mut per_topic = BTreeMap::<String, (String, String, usize)>::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m
            .channel
            .schema
            .as_ref()
            .expect("every channel has a schema");
        assert!(
            !schema.data.is_empty(),
            "{} carries its schema",
            schema.name
        );
        let e = per_topic.entry(m.channel.topic.clone()).or_insert((
            schema.name.clone(),
            schema.encoding.clone(),
            0,
        ));
        e.2 += 1;
        if m.channel.topic == "/pose/message" {
            // The schema the file carries is the repository's, and every
            // recorded message validates against it.
            assert_eq!(
                schema.data.as_ref(),
                std::fs::read(common::root().join("docs/schema/pose-message.v2.json"))
                    .unwrap()
                    .as_slice()
            );
            common::check_pose_message(&serde_json::from_slice(&m.data).unwrap());
        }
    }
    assert_eq!(
        per_topic["/camera/image"],
        ("foxglove.RawImage".into(), "protobuf".into(), 50)
    );
    assert_eq!(
        per_topic["/pose"],
        ("foxglove.PoseInFrame".into(), "protobuf".into(), 50)
    );
    assert_eq!(
        per_topic["/pose/message"],
        ("photopose.PoseMessage".into(), "jsonschema".into(), 50)
    );
    let summary_section = mcap::Summary::read(&bytes).unwrap().unwrap();
    let mut attachments: Vec<String> = summary_section
        .attachment_indexes
        .iter()
        .map(|a| a.name.clone())
        .collect();
    attachments.sort();
    assert_eq!(attachments, ["camera.toml", "photopose.toml", "plate.csv"]);
    for a in &summary_section.attachment_indexes {
        let att = mcap::read::attachment(&bytes, a).unwrap();
        assert!(!att.data.is_empty(), "{} is stored", a.name);
    }
    assert_eq!(summary_section.metadata_indexes.len(), 1);
    let meta = mcap::read::metadata(&bytes, &summary_section.metadata_indexes[0]).unwrap();
    assert_eq!(meta.name, "photopose");
    for key in ["version", "host", "start_utc_ns"] {
        assert!(
            meta.metadata.contains_key(key),
            "{key}: {:?}",
            meta.metadata
        );
    }
    assert!(summary_section
        .chunk_indexes
        .iter()
        .all(|c| c.compression == "zstd"));

    // Replayed twice at full speed: the same poses, nothing dropped.
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let config = dir.join("replay.toml");
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"replay\"\n[source.replay]\npath = \"{}\"\nspeed = \"max\"\n\
             [output]\nudp = [\"{}\"]\n",
            recording.display(),
            rx.local_addr().unwrap()
        ),
    )
    .unwrap();
    let (first, summary) = poses(&config, &rx);
    assert!(summary.contains("50 frames in, 0 dropped"), "{summary}");
    assert_eq!(first.len(), 50);
    let (second, summary) = poses(&config, &rx);
    assert!(summary.contains("50 frames in, 0 dropped"), "{summary}");
    assert_eq!(first, second, "two replays, the same output");

    // Export: one PGM per frame.
    let pgm = dir.join("pgm");
    let out = bin()
        .arg("export")
        .arg(&recording)
        .arg("--out")
        .arg(&pgm)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let frames = std::fs::read_dir(&pgm).unwrap().count();
    assert_eq!(frames, 50);
    let first_pgm = std::fs::read(pgm.join("frame-000000.pgm")).unwrap();
    assert!(first_pgm.starts_with(b"P5"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn record_section_errors_name_the_key() {
    let dir = scratch("record-keys");
    let config = dir.join("bad.toml");
    std::fs::write(&config, "[record]\ncompression = \"gzip\"\n").unwrap();
    let out = bin().arg("check-config").arg(&config).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("record.compression"), "{err}");
    assert!(err.contains("gzip"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn record_section_keeps_every_nth_frame_and_rotates_by_size() {
    let dir = scratch("record-rotate");
    let recording = dir.join("rot.mcap");
    let config = dir.join("rec.toml");
    std::fs::write(
        &config,
        format!(
            "[source]\nkind = \"synthetic\"\n[source.synthetic]\nrate_hz = 50.0\n\
             [output]\nudp = []\n\
             [record]\npath = \"{}\"\nframes = 2\ncompression = \"lz4\"\nrotate_mb = 1\n",
            recording.display()
        ),
    )
    .unwrap();
    let summary = run(&["--frames", "12"], Some(&config));
    assert!(summary.contains("6 frames (0 dropped)"), "{summary}");
    // Six frames of about 0.7 MB each (lz4) over 1 MiB files: several
    // files, each a complete recording, the frames in order across them.
    let mut seqs = Vec::new();
    let mut files = 0;
    for n in 0.. {
        let path = if n == 0 {
            recording.clone()
        } else {
            dir.join(format!("rot-{n}.mcap"))
        };
        if !path.exists() {
            break;
        }
        files += 1;
        let bytes = std::fs::read(&path).unwrap();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            if m.channel.topic == "/camera/image" {
                seqs.push(m.sequence);
            }
        }
    }
    assert!(files >= 2, "{files} files: {summary}");
    assert_eq!(seqs, [0, 2, 4, 6, 8, 10]);
    std::fs::remove_dir_all(&dir).unwrap();
}
