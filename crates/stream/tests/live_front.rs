//! The live view's front door on loopback: a client offering only the
//! protocol's first name `foxglove.websocket.v1` is served (answered with
//! that name) and gets the server's channels, a client offering the SDK's
//! name `foxglove.sdk.v1` is served under it, a viewer beyond
//! `max_clients` is refused with `503`, a client that never finishes its
//! handshake is dropped, and a viewer's slot is given back when it leaves.

use photopose_stream::live::{CameraShape, LiveOptions, LiveServer};
use photopose_stream::Edge;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

fn start(edge: &Edge, max_clients: usize) -> LiveServer {
    LiveServer::start(
        edge.handle(),
        &LiveOptions {
            address: "127.0.0.1:0".parse().unwrap(),
            image_scale: 2,
            max_clients,
        },
        1,
        64,
        &[],
        CameraShape {
            width_px: 100,
            height_px: 80,
            pixel_mm: 0.01,
            c_mm: 5.0,
        },
    )
    .unwrap()
}

/// Connects offering `offer`; the protocol the server answered with.
fn connect(addr: SocketAddr, offer: &str) -> (WebSocket<TcpStream>, String) {
    let mut request = format!("ws://{addr}").into_client_request().unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", offer.parse().unwrap());
    let stream = TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let (ws, response) = tungstenite::client(request, stream).expect("the handshake succeeds");
    let protocol = response
        .headers()
        .get("Sec-WebSocket-Protocol")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_string();
    (ws, protocol)
}

/// Reads until the server advertises its channels; their topics.
fn advertised(ws: &mut WebSocket<TcpStream>) -> Vec<String> {
    let t0 = Instant::now();
    loop {
        assert!(t0.elapsed() < Duration::from_secs(10), "no advertise");
        if let Ok(Message::Text(text)) = ws.read() {
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            if v["op"] == "advertise" {
                return v["channels"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|c| c["topic"].as_str().unwrap().to_string())
                    .collect();
            }
        }
    }
}

/// Waits until `cond` holds (bounded).
fn eventually(what: &str, cond: impl Fn() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(t0.elapsed() < Duration::from_secs(10), "{what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn both_names_of_the_protocol_are_served() {
    let edge = Edge::start(1).unwrap();
    let server = start(&edge, 4);
    let addr = server.local_addr();

    let (mut legacy, protocol) = connect(addr, "foxglove.websocket.v1");
    assert_eq!(protocol, "foxglove.websocket.v1");
    let topics = advertised(&mut legacy);
    assert!(topics.iter().any(|t| t == "/camera/image"), "{topics:?}");
    assert!(topics.iter().any(|t| t == "/pose"), "{topics:?}");
    assert_eq!(server.front().renamed.load(Ordering::Relaxed), 1);

    let (mut current, protocol) = connect(addr, "foxglove.sdk.v1");
    assert_eq!(protocol, "foxglove.sdk.v1");
    assert!(!advertised(&mut current).is_empty());
    assert_eq!(server.front().renamed.load(Ordering::Relaxed), 1);
    eventually("both clients reach the server", || server.clients() == 2);

    drop(server);
    edge.stop();
}

#[test]
fn viewers_beyond_the_limit_are_refused_and_slots_come_back() {
    let edge = Edge::start(1).unwrap();
    let server = start(&edge, 1);
    let addr = server.local_addr();

    let (mut first, _) = connect(addr, "foxglove.websocket.v1");
    assert!(!advertised(&mut first).is_empty());

    // A second viewer is answered 503 before any WebSocket talk.
    let mut second = TcpStream::connect(addr).unwrap();
    second
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    second
        .write_all(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\r\n")
        .unwrap();
    let mut answer = String::new();
    second.read_to_string(&mut answer).unwrap();
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer:?}");
    assert_eq!(server.front().refused.load(Ordering::Relaxed), 1);

    // The first one leaves; its slot is given back.
    let _ = first.close(None);
    drop(first);
    eventually("the slot is given back", || {
        server.front().active.load(Ordering::Relaxed) == 0
    });
    let (mut again, protocol) = connect(addr, "foxglove.websocket.v1");
    assert_eq!(protocol, "foxglove.websocket.v1");
    assert!(!advertised(&mut again).is_empty());

    drop(server);
    edge.stop();
}

#[test]
fn an_unfinished_handshake_does_not_hold_a_slot_forever() {
    let edge = Edge::start(1).unwrap();
    let server = start(&edge, 1);
    let addr = server.local_addr();
    // Half a head, then silence: dropped after the handshake timeout (5 s).
    let mut idle = TcpStream::connect(addr).unwrap();
    idle.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n").unwrap();
    eventually("the idle client holds the slot", || {
        server.front().active.load(Ordering::Relaxed) == 1
    });
    eventually("the idle client is dropped", || {
        server.front().active.load(Ordering::Relaxed) == 0
    });
    let (mut ws, _) = connect(addr, "foxglove.sdk.v1");
    assert!(!advertised(&mut ws).is_empty());
    drop(server);
    edge.stop();
}
