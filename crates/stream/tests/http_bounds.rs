//! The edge's HTTP text endpoint keeps its bounds over real sockets on
//! loopback: connections beyond the limit are closed at once and counted,
//! an oversized request head is refused, an unfinished head is closed after
//! the header timeout, and other paths and methods are answered, not served.

use photopose_stream::{Edge, HttpLimits, TextEndpoint};
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn ask(addr: SocketAddr, request: &[u8]) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request).unwrap();
    let mut answer = Vec::new();
    if let Err(e) = s.read_to_end(&mut answer) {
        assert_eq!(e.kind(), ErrorKind::ConnectionReset, "{e}");
    }
    String::from_utf8_lossy(&answer).into_owned()
}

fn get(path: &str) -> Vec<u8> {
    format!("GET {path} HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n").into_bytes()
}

#[test]
fn the_endpoint_keeps_its_limits() {
    let edge = Edge::start(1).unwrap();
    let limits = HttpLimits {
        max_connections: 4,
        max_head_bytes: 8192,
        header_timeout: Duration::from_millis(300),
        max_connection_life: Duration::from_secs(30),
    };
    let endpoint = TextEndpoint::start(
        edge.handle(),
        "127.0.0.1:0".parse().unwrap(),
        "/metrics",
        Arc::new(|| "answer 1\n".to_string()),
        limits,
    )
    .unwrap();
    let addr = endpoint.local_addr();
    let ok = ask(addr, &get("/metrics"));
    assert!(
        ok.starts_with("HTTP/1.1 200 OK") && ok.ends_with("answer 1\n"),
        "{ok}"
    );
    assert!(ask(addr, &get("/")).starts_with("HTTP/1.1 404"));
    let post = ask(
        addr,
        b"POST /metrics HTTP/1.1\r\nHost: t\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
    );
    assert!(post.starts_with("HTTP/1.1 405"), "{post}");
    // A head above the limit.
    let mut big = b"GET /metrics HTTP/1.1\r\nHost: t\r\nX-Pad: ".to_vec();
    big.extend(std::iter::repeat_n(b'a', 20_000));
    big.extend_from_slice(b"\r\n\r\n");
    let refused = ask(addr, &big);
    assert!(
        refused.is_empty() || refused.starts_with("HTTP/1.1 431"),
        "{refused}"
    );
    // Four idle clients hold every place; the fifth is closed at once.
    let idle: Vec<TcpStream> = (0..4).map(|_| TcpStream::connect(addr).unwrap()).collect();
    let t0 = Instant::now();
    while endpoint.stats().accepted.get() < 8 {
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "the idle clients were not accepted"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let extra = ask(addr, &get("/metrics"));
    assert_eq!(extra, "", "a connection beyond the limit gets nothing");
    assert_eq!(endpoint.stats().refused.get(), 1);
    // The header timeout closes the idle ones and frees their places.
    let t0 = Instant::now();
    for mut s in idle {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut rest = Vec::new();
        if let Err(e) = s.read_to_end(&mut rest) {
            assert_eq!(e.kind(), ErrorKind::ConnectionReset, "{e}");
        }
    }
    assert!(t0.elapsed() < Duration::from_secs(4), "{:?}", t0.elapsed());
    std::thread::sleep(Duration::from_millis(50));
    assert!(ask(addr, &get("/metrics")).starts_with("HTTP/1.1 200 OK"));
    endpoint.stop();
    edge.stop();
}
