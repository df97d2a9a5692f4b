//! Poses on Zenoh, end to end over loopback: two daemons (two simulated
//! cells, distinct `[camera] id`) publish to one subscriber — this test's
//! own Zenoh session, which listens; the daemons connect to it and wait for
//! it to subscribe before they take frames (`wait_for_subscriber_ms`), so
//! nothing is published before anyone listens. Each stream arrives
//! complete and in order under the documented keys; the queryable answers
//! the latest pose and the configuration; the ROS 2 messages decode with
//! an independent CDR implementation (the `rosbags` Python package) to the
//! JSON message's pose and covariance. `check-config` names the `zenoh.*`
//! key of a bad value.

mod common;

use common::{bin, check_pose_message, free_tcp_port, scratch, Killed};
use serde_json::Value;
use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use zenoh::Wait;

const FRAMES: usize = 200;
const TYPE: &str = "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_";
const HASH: &str = "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e";
/// Where `.ci/deps.sh` installs the `rosbags` package.
const PYTHON_PATH: &str = "/opt/photopose-test/python";

fn daemon_config(dir: &std::path::Path, camera: &str, port: u16) -> std::path::PathBuf {
    let path = dir.join(format!("{camera}.toml"));
    std::fs::write(
        &path,
        format!(
            "[camera]\nid = \"{camera}\"\n\
             [source]\nkind = \"synthetic\"\n\
             [source.synthetic]\nrate_hz = 100.0\n\
             [pipeline]\noverflow = \"block\"\nmax_age_ms = 5000.0\n\
             [output]\nudp = []\n\
             [zenoh]\nenabled = true\nmode = \"peer\"\n\
             connect = [\"tcp/127.0.0.1:{port}\"]\n\
             scouting_multicast = false\nwait_for_subscriber_ms = 30000\n\
             status_period_ms = 200\n\
             ros2 = true\nros2_domain_id = 0\n"
        ),
    )
    .unwrap();
    path
}

/// What the subscriber saw.
enum Seen {
    Pose(String, Vec<u8>),
    Status(String, Vec<u8>),
    Ros(String, Vec<u8>, Vec<u8>),
}

fn camera_of(key: &str, index: usize) -> String {
    key.split('/').nth(index).unwrap_or("").to_string()
}

/// The ROS 2 messages decoded by rosbags (`deserialize_cdr`), one JSON
/// object per file, and rosbags' RIHS01 hash of the type.
fn decode_with_rosbags(files: &[std::path::PathBuf]) -> Option<(Vec<Value>, String)> {
    let script = r#"
import json, sys
from rosbags.typesys import Stores, get_typestore
store = get_typestore(Stores.ROS2_JAZZY)
name = "geometry_msgs/msg/PoseWithCovarianceStamped"
print(json.dumps({"hash": store.hash_rihs01(name)}))
for path in sys.argv[1:]:
    m = store.deserialize_cdr(open(path, "rb").read(), name)
    p, q = m.pose.pose.position, m.pose.pose.orientation
    print(json.dumps({
        "sec": m.header.stamp.sec, "nanosec": m.header.stamp.nanosec,
        "frame_id": m.header.frame_id,
        "position": [p.x, p.y, p.z], "orientation": [q.x, q.y, q.z, q.w],
        "covariance": [float(c) for c in m.pose.covariance],
    }))
"#;
    let probe = Command::new("python3")
        .args(["-c", "import rosbags"])
        .env("PYTHONPATH", PYTHON_PATH)
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        return None;
    }
    let out = Command::new("python3")
        .args(["-c", script])
        .args(files)
        .env("PYTHONPATH", PYTHON_PATH)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rosbags: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut lines = std::str::from_utf8(&out.stdout).unwrap().lines();
    let hash: Value = serde_json::from_str(lines.next().unwrap()).unwrap();
    let decoded = lines.map(|l| serde_json::from_str(l).unwrap()).collect();
    Some((decoded, hash["hash"].as_str().unwrap().to_string()))
}

#[test]
fn two_daemons_publish_complete_ordered_streams_to_one_subscriber() {
    let dir = scratch("zenoh-two");
    let port = free_tcp_port();
    let mut config = zenoh::Config::default();
    config.insert_json5("mode", "\"peer\"").unwrap();
    config
        .insert_json5("listen/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))
        .unwrap();
    config
        .insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    let session = zenoh::open(config).wait().unwrap();
    let (tx, rx) = mpsc::channel::<Seen>();
    let t = tx.clone();
    let _poses = session
        .declare_subscriber("photopose/*/pose")
        .callback(move |s| {
            let _ = t.send(Seen::Pose(
                s.key_expr().to_string(),
                s.payload().to_bytes().to_vec(),
            ));
        })
        .wait()
        .unwrap();
    let t = tx.clone();
    let _status = session
        .declare_subscriber("photopose/*/status")
        .callback(move |s| {
            let _ = t.send(Seen::Status(
                s.key_expr().to_string(),
                s.payload().to_bytes().to_vec(),
            ));
        })
        .wait()
        .unwrap();
    let t = tx;
    let _ros = session
        .declare_subscriber("0/photopose/**")
        .callback(move |s| {
            let _ = t.send(Seen::Ros(
                s.key_expr().to_string(),
                s.payload().to_bytes().to_vec(),
                s.attachment()
                    .map(|a| a.to_bytes().to_vec())
                    .unwrap_or_default(),
            ));
        })
        .wait()
        .unwrap();

    let cameras = ["cell_a", "cell_b"];
    let mut daemons: Vec<Killed> = cameras
        .iter()
        .map(|c| {
            let config = daemon_config(&dir, c, port);
            Killed(
                bin()
                    .args(["run", "--config"])
                    .arg(&config)
                    .args(["--frames", &FRAMES.to_string()])
                    .stdout(Stdio::null())
                    .stderr(std::fs::File::create(dir.join(format!("{c}.log"))).unwrap())
                    .spawn()
                    .unwrap(),
            )
        })
        .collect();

    let mut poses: BTreeMap<String, Vec<Value>> = BTreeMap::new();
    let mut statuses: BTreeMap<String, Vec<Value>> = BTreeMap::new();
    let mut ros: Vec<(String, Vec<u8>, Vec<u8>)> = Vec::new();
    let mut queried = false;
    let t0 = Instant::now();
    let fresh = |v: &Vec<Value>| v.iter().filter(|m| !m["seq"].is_null()).count();
    loop {
        let done = cameras
            .iter()
            .all(|c| poses.get(*c).is_some_and(|v| fresh(v) >= FRAMES));
        let mut exited = true;
        for (d, c) in daemons.iter_mut().zip(cameras) {
            match d.0.try_wait().unwrap() {
                Some(status) if !status.success() => {
                    let log = std::fs::read_to_string(dir.join(format!("{c}.log")));
                    panic!("daemon {c} failed: {}", log.unwrap_or_default());
                }
                Some(_) => {}
                None => exited = false,
            }
        }
        if done && exited {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(180),
            "incomplete after 180 s: {:?}",
            poses.iter().map(|(k, v)| (k, fresh(v))).collect::<Vec<_>>()
        );
        let Ok(seen) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        match seen {
            Seen::Pose(key, bytes) => {
                let camera = camera_of(&key, 1);
                assert_eq!(key, format!("photopose/{camera}/pose"));
                let v: Value = serde_json::from_slice(&bytes).unwrap();
                check_pose_message(&v);
                assert_eq!(v["camera"], camera.as_str(), "tagged with its camera");
                poses.entry(camera).or_default().push(v);
            }
            Seen::Status(key, bytes) => {
                let camera = camera_of(&key, 1);
                let v: Value = serde_json::from_slice(&bytes).unwrap();
                assert_eq!(v["camera"], camera.as_str());
                statuses.entry(camera).or_default().push(v);
            }
            Seen::Ros(key, payload, attachment) => ros.push((key, payload, attachment)),
        }
        // While cell_a streams: the query of its latest pose, and the ROS
        // graph's liveliness tokens.
        let seen_a = poses.get("cell_a").map_or(0, fresh);
        if !queried && (20..FRAMES).contains(&seen_a) {
            queried = true;
            let last_seq = poses["cell_a"]
                .iter()
                .rev()
                .find_map(|m| m["seq"].as_u64())
                .unwrap();
            let replies = session
                .get("photopose/cell_a/latest")
                .timeout(Duration::from_secs(10))
                .wait()
                .unwrap();
            let reply = replies
                .recv_timeout(Duration::from_secs(10))
                .unwrap()
                .expect("the queryable answers");
            let sample = reply.result().expect("an answer, not an error");
            assert_eq!(sample.key_expr().as_str(), "photopose/cell_a/latest");
            let v: Value = serde_json::from_slice(&sample.payload().to_bytes()).unwrap();
            check_pose_message(&v["pose"]);
            let seq = v["pose"]["seq"].as_u64().expect("the latest frame's pose");
            assert!(
                seq >= last_seq && seq < FRAMES as u64 + 1,
                "latest {seq}, seen {last_seq}"
            );
            let c = &v["config"];
            assert_eq!(c["camera"], "cell_a");
            assert_eq!(c["source"], "synthetic");
            assert_eq!(c["zenoh"]["pose_key"], "photopose/cell_a/pose");
            assert_eq!(c["zenoh"]["ros2"]["topic"], "/photopose/cell_a/pose");
            let tokens = session
                .liveliness()
                .get("@ros2_lv/0/**")
                .timeout(Duration::from_secs(10))
                .wait()
                .unwrap();
            let mut keys = Vec::new();
            while let Ok(Some(r)) = tokens.recv_timeout(Duration::from_secs(10)) {
                if let Ok(s) = r.result() {
                    keys.push(s.key_expr().to_string());
                }
            }
            let publisher = format!(
                "/MP/%/%/photopose_cell_a/%photopose%cell_a%pose/{TYPE}/{HASH}/::,10:,:,:,,"
            );
            assert!(
                keys.iter().any(|k| k.ends_with(&publisher)),
                "no publisher token in {keys:?}"
            );
            assert!(
                keys.iter().any(|k| k.ends_with("/NN/%/%/photopose_cell_a")),
                "no node token in {keys:?}"
            );
        }
    }
    assert!(queried, "the query ran while cell_a streamed");
    for (d, c) in daemons.iter_mut().zip(cameras) {
        let status = d.0.wait().unwrap();
        let log = std::fs::read_to_string(dir.join(format!("{c}.log"))).unwrap_or_default();
        assert!(status.success(), "daemon {c} failed: {log}");
    }
    // Samples in flight when the daemons ended are in the channel.
    while let Ok(seen) = rx.recv_timeout(Duration::from_millis(300)) {
        if let Seen::Ros(key, payload, attachment) = seen {
            ros.push((key, payload, attachment));
        }
    }

    // Complete and in order, per camera.
    for camera in cameras {
        let seqs: Vec<u64> = poses[camera]
            .iter()
            .filter_map(|m| m["seq"].as_u64())
            .collect();
        assert_eq!(seqs.len(), FRAMES, "{camera}: {} poses", seqs.len());
        assert!(
            seqs.windows(2).all(|w| w[1] == w[0] + 1),
            "{camera}: not consecutive: {seqs:?}"
        );
        let st = statuses.get(camera).expect("a status");
        assert!(st
            .iter()
            .all(|s| s["state"].is_string() && s["rsi"] == "off"));
        assert!(st.iter().any(|s| s["poses_ok"].as_u64() > Some(0)));
    }

    // ROS 2: the key, the attachment, and the CDR decoded independently.
    let key = |c: &str| format!("0/photopose/{c}/pose/{TYPE}/{HASH}");
    let mut files = Vec::new();
    let mut expected = Vec::new();
    for camera in cameras {
        let mine: Vec<_> = ros.iter().filter(|(k, ..)| *k == key(camera)).collect();
        let ok: Vec<&Value> = poses[camera]
            .iter()
            .filter(|m| m["status"] == "ok")
            .collect();
        assert_eq!(
            mine.len(),
            ok.len(),
            "{camera}: one ROS message per ok pose"
        );
        let mut last = 0i64;
        for (k, (_, payload, attachment)) in mine.iter().enumerate() {
            assert_eq!(attachment.len(), 33, "sequence, timestamp, GID");
            let seq = i64::from_le_bytes(attachment[..8].try_into().unwrap());
            assert!(seq > last, "sequence numbers increase");
            last = seq;
            assert_eq!(attachment[16], 16, "the GID's length");
            if k < 20 {
                let f = dir.join(format!("{camera}-{k}.cdr"));
                std::fs::write(&f, payload).unwrap();
                files.push(f);
                expected.push(ok[k].clone());
            }
        }
    }
    assert!(ros
        .iter()
        .all(|(k, ..)| cameras.iter().any(|c| *k == key(c))));
    let Some((decoded, hash)) = decode_with_rosbags(&files) else {
        println!("skipped the CDR check: python3 with rosbags is missing (run .ci/deps.sh)");
        return;
    };
    assert_eq!(hash, HASH, "rosbags' RIHS01 hash of the type");
    assert_eq!(decoded.len(), expected.len());
    for (d, m) in decoded.iter().zip(&expected) {
        let ns = m["time"]["exposure_utc_ns"].as_u64().unwrap();
        assert_eq!(d["sec"].as_u64(), Some(ns / 1_000_000_000));
        assert_eq!(d["nanosec"].as_u64(), Some(ns % 1_000_000_000));
        assert_eq!(d["frame_id"], m["frame_id"]);
        let p = &m["pose"];
        let f = |v: &Value| v.as_f64().unwrap();
        for i in 0..3 {
            let want = f(&p["position_mm"][i]) / 1000.0;
            assert!((f(&d["position"][i]) - want).abs() < 1e-9);
        }
        let q: Vec<f64> = (0..4).map(|i| f(&p["quaternion_xyzw"][i])).collect();
        let (x, y, z, w) = (q[0], q[1], q[2], q[3]);
        let optical = [w, z, -y, -x];
        for i in 0..4 {
            assert!((f(&d["orientation"][i]) - optical[i]).abs() < 1e-9);
        }
        let scale = [1e-3, 1e-3, 1e-3, -1.0, -1.0, -1.0];
        for k in 0..36 {
            let want = scale[k / 6] * f(&p["covariance"][k]) * scale[k % 6];
            let got = f(&d["covariance"][k]);
            assert!(
                (got - want).abs() <= 1e-9 * want.abs().max(1e-12),
                "covariance {k}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn check_config_names_the_zenoh_key_of_a_bad_value() {
    let dir = scratch("zenoh-check");
    let cases = [
        ("connect = [\"udp/127.0.0.1:7447\"]", "zenoh.connect"),
        ("connect = [\"tcp/127.0.0.1\"]", "zenoh.connect"),
        ("listen = [\"tcp/:7447\"]", "zenoh.listen"),
        ("mode = \"router\"", "zenoh.mode"),
        ("pose_key = \"photopose/*/pose\"", "zenoh.pose_key"),
        ("status_key = \"photopose//status\"", "zenoh.status_key"),
        ("query_key = \"photopose/{camera}/pose\"", "zenoh.query_key"),
        (
            "ros2 = true\nros2_topic = \"no/leading/slash\"",
            "zenoh.ros2_topic",
        ),
        ("ros2_domain_id = 300", "zenoh.ros2_domain_id"),
        ("status_period_ms = 5", "zenoh.status_period_ms"),
        ("colour = \"red\"", "colour"),
    ];
    for (k, (line, want)) in cases.iter().enumerate() {
        let path = dir.join(format!("bad-{k}.toml"));
        std::fs::write(
            &path,
            format!("[source]\nkind = \"synthetic\"\n[zenoh]\nenabled = true\n{line}\n"),
        )
        .unwrap();
        let out = bin().arg("check-config").arg(&path).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{line}: accepted");
        assert!(
            err.contains(&format!("bad-{k}.toml")) && err.contains(want),
            "{line}: {err}"
        );
    }
    let good = dir.join("good.toml");
    std::fs::write(
        &good,
        "[source]\nkind = \"synthetic\"\n[zenoh]\nenabled = true\nmode = \"client\"\n\
         connect = [\"tcp/localhost:7447\", \"tcp/[::1]:7447\"]\nros2 = true\n",
    )
    .unwrap();
    let out = bin().arg("check-config").arg(&good).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
