//! The live view's server end to end on loopback: a client speaking the
//! Foxglove WebSocket protocol subscribes to the annotations, the scene
//! and the transform; the states handed over by the pipeline's side come
//! out as `foxglove.ImageAnnotations` (detected targets with ids, on the
//! downscaled image), `foxglove.SceneUpdate` (the plate; the camera) and
//! `foxglove.FrameTransforms` (field → camera, metres).

use foxglove::schemas::{FrameTransforms, ImageAnnotations, SceneUpdate};
use foxglove::Decode;
use photopose_stream::live::{
    CameraShape, DetectedTarget, LiveOptions, LivePose, LiveServer, SceneTarget,
};
use photopose_stream::Edge;
use std::net::TcpStream;
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::Message;

#[test]
fn states_become_annotations_scene_and_transforms() {
    let edge = Edge::start(1).unwrap();
    let plate = [
        SceneTarget {
            id: 3,
            position_mm: [10.0, 20.0, 0.0],
            radius_mm: 4.0,
            coded: true,
        },
        SceneTarget {
            id: 100,
            position_mm: [50.0, 20.0, 0.0],
            radius_mm: 2.0,
            coded: false,
        },
    ];
    let server = LiveServer::start(
        edge.handle(),
        &LiveOptions {
            address: "127.0.0.1:0".parse().unwrap(),
            image_scale: 2,
            max_clients: 4,
        },
        1,
        64,
        &plate,
        CameraShape {
            width_px: 100,
            height_px: 80,
            pixel_mm: 0.01,
            c_mm: 5.0,
        },
    )
    .unwrap();
    let addr = server.local_addr();
    let mut request = format!("ws://{addr}").into_client_request().unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1, foxglove.sdk.v1".parse().unwrap(),
    );
    let stream = TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let (mut ws, _) = tungstenite::client(request, stream).unwrap();
    let t0 = Instant::now();
    let topics = ["/camera/annotations", "/scene", "/tf"];
    let mut ids = Vec::new();
    while ids.is_empty() {
        assert!(t0.elapsed() < Duration::from_secs(10), "no advertise");
        if let Ok(Message::Text(text)) = ws.read() {
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            if v["op"] == "advertise" {
                for t in topics {
                    let c = v["channels"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .find(|c| c["topic"] == t)
                        .unwrap_or_else(|| panic!("{t} advertised"));
                    ids.push(c["id"].as_u64().unwrap());
                }
            }
        }
    }
    let subs: Vec<_> = ids
        .iter()
        .enumerate()
        .map(|(k, id)| serde_json::json!({"id": k, "channelId": id}))
        .collect();
    ws.send(Message::Text(
        serde_json::json!({"op": "subscribe", "subscriptions": subs})
            .to_string()
            .into(),
    ))
    .unwrap();

    let tx = server.sender();
    let time_ns = 1_700_000_000_000_000_000;
    let (mut annotations, mut plate_seen, mut camera_seen, mut tf) = (None, false, false, None);
    let t0 = Instant::now();
    let mut last_send = None::<Instant>;
    while annotations.is_none() || !plate_seen || !camera_seen || tf.is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "annotations {} plate {plate_seen} camera {camera_seen} tf {}",
            annotations.is_some(),
            tf.is_some()
        );
        if last_send.is_none_or(|t| t.elapsed() > Duration::from_millis(100)) {
            last_send = Some(Instant::now());
            tx.send_state(|s| {
                s.seq = 9;
                s.time_ns = time_ns;
                s.pose = Some(LivePose {
                    position_mm: [0.0, 0.0, 500.0],
                    orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
                    ..LivePose::default()
                });
                s.targets.clear();
                s.targets.push(DetectedTarget {
                    id: Some(3),
                    col: 19.5,
                    row: 9.5,
                    coded: true,
                });
                s.targets_time_ns = Some(time_ns);
            });
        }
        let Ok(Message::Binary(data)) = ws.read() else {
            continue;
        };
        let sub = u32::from_le_bytes(data[1..5].try_into().unwrap());
        let payload = &data[13..];
        match sub {
            0 => annotations = Some(ImageAnnotations::decode(payload).unwrap()),
            1 => {
                let update = SceneUpdate::decode(payload).unwrap();
                for e in update.entities {
                    match e.id.as_str() {
                        "plate" => {
                            assert_eq!(e.spheres.len(), 2);
                            assert_eq!(e.texts.len(), 1, "the coded target's id");
                            plate_seen = true;
                        }
                        "camera" => {
                            assert_eq!(e.lines.len(), 2, "axes and frustum");
                            camera_seen = true;
                        }
                        other => panic!("entity {other}?"),
                    }
                }
            }
            2 => tf = Some(FrameTransforms::decode(payload).unwrap()),
            other => panic!("subscription {other}?"),
        }
    }
    let a = annotations.unwrap();
    assert_eq!(a.circles.len(), 1);
    let at = a.circles[0].position.unwrap();
    // Pixel centre (19.5, 9.5) → corner-based (20, 10) → halved.
    assert_eq!((at.x, at.y), (10.0, 5.0));
    assert_eq!(a.texts[0].text, "3");
    let t = &tf.unwrap().transforms[0];
    assert_eq!(
        (t.parent_frame_id.as_str(), t.child_frame_id.as_str()),
        ("field", "camera")
    );
    assert_eq!(t.translation.unwrap().z, 0.5);
    let _ = ws.close(None);
    server.shutdown();
    edge.stop();
}
