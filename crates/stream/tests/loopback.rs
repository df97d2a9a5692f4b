//! The pose streams over real sockets on loopback: every pose reaches every
//! UDP destination and TCP client in order; a slow TCP client is dropped
//! without stalling the others; an unreachable destination is counted.

mod common;
use common::line;
use photopose_stream::{Edge, TcpLimits, TcpServer, UdpSender};
use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

#[test]
fn udp_datagrams_arrive_in_order() {
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let mut tx =
        UdpSender::new("127.0.0.1:0".parse().unwrap(), &[rx.local_addr().unwrap()]).unwrap();
    let mut buf = Vec::new();
    let mut got = [0u8; 2048];
    for seq in 0..200 {
        line(seq, &mut buf);
        tx.send(&buf);
        let n = rx.recv(&mut got).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&got[..n]).unwrap();
        assert_eq!(v["seq"], seq);
    }
    let (_, sent, errors) = tx.stats().next().unwrap();
    assert_eq!((sent, errors), (200, 0));
}

#[test]
fn unreachable_udp_destination_is_counted_not_fatal() {
    // A port nobody listens on: the kernel answers with ICMP port unreachable.
    let closed = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let mut tx = UdpSender::new(
        "127.0.0.1:0".parse().unwrap(),
        &[closed, rx.local_addr().unwrap()],
    )
    .unwrap();
    let mut buf = Vec::new();
    let mut got = [0u8; 2048];
    for seq in 0..50 {
        line(seq, &mut buf);
        tx.send(&buf);
        rx.recv(&mut got).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    let stats: Vec<(SocketAddr, u64, u64)> = tx.stats().collect();
    assert!(
        stats[0].2 > 0,
        "the closed port produced send errors: {stats:?}"
    );
    assert_eq!(stats[1].1, 50, "the live destination got everything");
}

fn wait_for(mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < Duration::from_secs(5), "timed out");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn tcp_clients_get_every_line_and_a_slow_one_is_dropped() {
    // 1024 lines of slack: 50 ms at this rate, whatever else the machine does.
    let edge = Edge::start(1).unwrap();
    let limits = TcpLimits {
        max_clients: 16,
        client_queue: 1024,
    };
    let mut server =
        TcpServer::bind(edge.handle(), "127.0.0.1:0".parse().unwrap(), limits).unwrap();
    let addr = server.local_addr();
    let readers: Vec<_> = (0..2)
        .map(|_| {
            let s = TcpStream::connect(addr).unwrap();
            std::thread::spawn(move || {
                let r = BufReader::new(s);
                let mut seqs = Vec::new();
                for l in r.lines() {
                    let v: serde_json::Value = serde_json::from_str(&l.unwrap()).unwrap();
                    seqs.push(v["seq"].as_u64().unwrap());
                }
                seqs
            })
        })
        .collect();
    // A client that never reads, with a tiny socket buffer.
    let slow = TcpStream::connect(addr).unwrap();
    wait_for(|| server.stats().connected.load(Ordering::Relaxed) == 3);
    // Publish at about 20 kHz (far above any camera) until the slow
    // client's socket buffer and queue are full and it is dropped.
    let mut buf = Vec::new();
    let mut n = 0u64;
    let t0 = Instant::now();
    while server.stats().dropped.get() == 0 {
        assert!(n < 500_000, "the slow client was never dropped");
        line(n, &mut buf);
        server.publish(&buf);
        n += 1;
        std::thread::sleep(Duration::from_micros(50));
    }
    // And some more after it is gone.
    for _ in 0..1000 {
        line(n, &mut buf);
        server.publish(&buf);
        n += 1;
        std::thread::sleep(Duration::from_micros(50));
    }
    let publish_time = t0.elapsed();
    server.shutdown();
    for r in readers {
        let seqs = r.join().unwrap();
        assert_eq!(seqs.len() as u64, n, "a healthy client got every line");
        assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "in order");
    }
    drop(slow);
    edge.stop();
    // Sleeping alone takes n × 50 µs; the rest is publishing, which never blocked.
    let sleeping = Duration::from_micros(50 * n);
    assert!(
        publish_time < sleeping * 4 + Duration::from_secs(2),
        "publishing blocked: {publish_time:?} for {n} lines"
    );
}
