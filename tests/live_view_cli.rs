//! The live view in Foxglove (`[live]`): the daemon, running the synthetic
//! source as fast as it goes, serves a Foxglove WebSocket; a client that
//! speaks the protocol under its first name (offering only the subprotocol
//! `foxglove.websocket.v1`, as Lichtblick and older Foxglove Studio
//! releases do; answered with that name) reads the advertised channels,
//! subscribes to the image and the pose, and receives both as binary
//! message data: a downscaled mono8 `foxglove.RawImage` and a
//! `foxglove.PoseInFrame` about 1 m above the plate. The daemon then stops
//! on SIGTERM with exit 0.

mod common;

use common::{bin, scratch, Killed};
use foxglove::schemas::{ImageAnnotations, PoseInFrame, RawImage};
use foxglove::Decode;
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

const CONFIG: &str = r#"
[source]
kind = "synthetic"
[source.synthetic]
rate_hz = 10000.0
[pipeline]
overflow = "drop-newest"
[live]
enabled = true
address = "127.0.0.1:0"
image_hz = 10.0
image_scale = 4
pose_hz = 20.0
"#;

/// Waits for the log line that names the view's address.
fn address(lines: &mpsc::Receiver<String>, log: &mut String) -> String {
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(60) {
        let Ok(line) = lines.recv_timeout(Duration::from_millis(200)) else {
            continue;
        };
        log.push_str(&line);
        log.push('\n');
        if let Some(at) = line.find("ws://") {
            let rest = &line[at + 5..];
            let end = rest
                .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == ':'))
                .unwrap_or(rest.len());
            return rest[..end].to_string();
        }
    }
    panic!("the daemon never named the live view's address:\n{log}");
}

fn connect(addr: &str) -> WebSocket<TcpStream> {
    let mut request = format!("ws://{addr}").into_client_request().unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    let stream = TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let (ws, response) = tungstenite::client(request, stream).expect("the handshake succeeds");
    let protocol = response
        .headers()
        .get("Sec-WebSocket-Protocol")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_string();
    assert_eq!(protocol, "foxglove.websocket.v1");
    ws
}

#[test]
fn a_foxglove_client_receives_image_and_pose_while_the_pipeline_runs() {
    let dir = scratch("live-view");
    let path = dir.join("live.toml");
    std::fs::write(&path, CONFIG).unwrap();
    let mut child = Killed(
        bin()
            .args(["run", "--config"])
            .arg(&path)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let stderr = child.0.stderr.take().unwrap();
    let (tx, lines) = mpsc::channel();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut log = String::new();
    let addr = address(&lines, &mut log);
    let mut ws = connect(&addr);

    // serverInfo, then the advertisement of the channels.
    let t0 = Instant::now();
    let mut channels = serde_json::Map::new();
    while channels.is_empty() {
        assert!(t0.elapsed() < Duration::from_secs(30), "no advertise");
        if let Message::Text(text) = ws.read().expect("the server speaks") {
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            if v["op"] == "advertise" {
                for c in v["channels"].as_array().unwrap() {
                    channels.insert(c["topic"].as_str().unwrap().to_string(), c.clone());
                }
            }
        }
    }
    for (topic, schema) in [
        ("/camera/image", "foxglove.RawImage"),
        ("/camera/annotations", "foxglove.ImageAnnotations"),
        ("/pose", "foxglove.PoseInFrame"),
        ("/tf", "foxglove.FrameTransforms"),
        ("/scene", "foxglove.SceneUpdate"),
        ("/pose/message", "photopose.PoseMessage"),
        ("/status", "photopose.LiveStatus"),
    ] {
        let c = channels
            .get(topic)
            .unwrap_or_else(|| panic!("{topic} advertised: {channels:?}"));
        assert_eq!(c["schemaName"], schema, "{topic}");
    }
    let id = |topic: &str| channels[topic]["id"].as_u64().unwrap();
    let subscribe = serde_json::json!({
        "op": "subscribe",
        "subscriptions": [
            {"id": 1, "channelId": id("/camera/image")},
            {"id": 2, "channelId": id("/pose")},
            {"id": 3, "channelId": id("/status")},
            {"id": 4, "channelId": id("/camera/annotations")},
        ]
    });
    ws.send(Message::Text(subscribe.to_string().into()))
        .unwrap();

    // Binary message data: op 1, subscription id (u32), time (u64), payload.
    let (mut image, mut pose, mut status, mut marks) = (None, None, None, None);
    let t0 = Instant::now();
    while image.is_none() || pose.is_none() || status.is_none() || marks.is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "image {} pose {} status {} annotations {}",
            image.is_some(),
            pose.is_some(),
            status.is_some(),
            marks.is_some()
        );
        let Message::Binary(data) = ws.read().expect("the server keeps sending") else {
            continue;
        };
        assert_eq!(data[0], 1, "message data");
        let sub = u32::from_le_bytes(data[1..5].try_into().unwrap());
        let time_ns = u64::from_le_bytes(data[5..13].try_into().unwrap());
        assert!(time_ns > 0);
        let payload = &data[13..];
        match sub {
            1 => image = Some(RawImage::decode(payload).unwrap()),
            2 => pose = Some(PoseInFrame::decode(payload).unwrap()),
            3 => status = Some(serde_json::from_slice::<serde_json::Value>(payload).unwrap()),
            4 => {
                let a = ImageAnnotations::decode(payload).unwrap();
                // The identified targets of the frame shown, with their ids.
                if !a.texts.is_empty() {
                    marks = Some(a);
                }
            }
            other => panic!("subscription {other}?"),
        }
    }
    let image = image.unwrap();
    // The built-in camera, 1300 × 1030, downscaled by 4.
    assert_eq!((image.width, image.height), (325, 257));
    assert_eq!((image.encoding.as_str(), image.step), ("mono8", 325));
    assert_eq!(image.data.len(), 325 * 257);
    assert_eq!(image.frame_id, "camera");
    assert!(
        image.data.iter().any(|&v| v > 128),
        "the targets are bright"
    );
    let pose = pose.unwrap();
    assert_eq!(pose.frame_id, "field");
    let p = pose.pose.unwrap().position.unwrap();
    // The synthetic camera circles 1000 mm above the plate (metres here).
    assert!((p.z - 1.0).abs() < 0.01 && p.x.hypot(p.y) < 0.06, "{p:?}");
    let status = status.unwrap();
    assert_eq!(status["status"], "ok", "{status}");
    assert!(status["n_targets"].as_u64().unwrap() >= 4, "{status}");
    assert_eq!(status["std_position_mm"].as_array().unwrap().len(), 3);
    let marks = marks.unwrap();
    assert!(
        marks.texts.len() >= 4,
        "{} target labels",
        marks.texts.len()
    );
    assert!(marks.texts.iter().all(|t| !t.text.is_empty()));
    let _ = ws.close(None);

    let kill = Command::new("kill")
        .args(["-TERM", &child.0.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let t0 = Instant::now();
    let exit = loop {
        if let Some(s) = child.0.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "no stop on SIGTERM");
        std::thread::sleep(Duration::from_millis(50));
    };
    let _ = reader.join();
    while let Ok(line) = lines.try_recv() {
        log.push_str(&line);
        log.push('\n');
    }
    assert!(exit.success(), "exit {exit:?}\n{log}");
    assert!(log.contains("live view stopped"), "{log}");
}
