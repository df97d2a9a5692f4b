//! With the live view on and a Foxglove client watching the image and the
//! pose, the frame path still allocates nothing once warm: the grabber's
//! tap box-filters a frame now and then into a preallocated buffer, the
//! sink copies the latest state into a preallocated slot. Only the edge
//! runtime's thread (`edge-0`: message encoding, the WebSocket server)
//! allocates, so this test's allocator counts every thread but that one;
//! the client drains its socket raw, into a fixed buffer.

mod common;
use common::{synthetic_source, Poses};
use photopose_pipeline::{Pipeline, Supervision};
use photopose_testkit::{allocations_outside, exclude_thread, CountingAllocator};
use std::io::Read;
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::Message;

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_frame_path_does_not_allocate_while_a_client_watches_the_live_view() {
    exclude_thread("edge-0");
    let mut udp = Poses::bind();
    let cfg = udp.config(
        20.0,
        r#"
[live]
enabled = true
address = "127.0.0.1:0"
image_hz = 10.0
pose_hz = 20.0
"#,
    );
    let (camera, field, source) = synthetic_source(&cfg);
    let pipeline =
        Pipeline::start_supervised(&cfg, camera, field, Box::new(source), Supervision::none())
            .unwrap();
    let addr = pipeline.live_addr().expect("the live view runs");

    // A client: advertise, subscribe to the image, pose and status.
    let mut request = format!("ws://{addr}").into_client_request().unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1, foxglove.sdk.v1".parse().unwrap(),
    );
    let stream = TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let (mut ws, _) = tungstenite::client(request, stream).unwrap();
    let t0 = Instant::now();
    let ids = loop {
        assert!(t0.elapsed() < Duration::from_secs(30), "no advertise");
        if let Message::Text(text) = ws.read().unwrap() {
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            if v["op"] == "advertise" {
                break v["channels"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .filter(|c| {
                        ["/camera/image", "/pose", "/status"]
                            .contains(&c["topic"].as_str().unwrap())
                    })
                    .map(|c| c["id"].as_u64().unwrap())
                    .collect::<Vec<_>>();
            }
        }
    };
    assert_eq!(ids.len(), 3);
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
    // From here on the client only drains its socket, into a fixed buffer.
    let mut raw = ws.get_ref().try_clone().unwrap();
    raw.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let (received, done) = (
        Arc::new(AtomicUsize::new(0)),
        Arc::new(AtomicBool::new(false)),
    );
    let drain = {
        let (received, done) = (received.clone(), done.clone());
        std::thread::spawn(move || {
            let mut buf = vec![0u8; 1 << 16];
            while !done.load(Ordering::Relaxed) {
                if let Ok(n) = raw.read(&mut buf) {
                    received.fetch_add(n, Ordering::Relaxed);
                }
            }
        })
    };

    // Warm: several images (325 × 257 bytes each) have reached the client.
    let t0 = Instant::now();
    while received.load(Ordering::Relaxed) < 4 * 325 * 257 {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no images reach the client"
        );
        udp.receive(1);
    }
    udp.receive(10);
    let (before, bytes_before) = (allocations_outside(), received.load(Ordering::Relaxed));
    udp.receive(40);
    let allocated = allocations_outside() - before;
    let bytes = received.load(Ordering::Relaxed) - bytes_before;
    done.store(true, Ordering::Relaxed);
    drain.join().unwrap();
    pipeline.stop();
    pipeline.join();
    assert!(bytes > 325 * 257, "images kept flowing ({bytes} bytes)");
    assert_eq!(
        allocated, 0,
        "allocations on the frame path while the live view is watched"
    );
}
