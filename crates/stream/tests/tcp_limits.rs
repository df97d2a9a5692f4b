//! The TCP pose stream's bounds over real sockets on loopback: a client
//! limit (the connections beyond it are closed at once and counted), and a
//! client that never reads is dropped when its queue fills and leaves
//! nothing behind.

mod common;
use common::line;
use photopose_stream::{Edge, TcpLimits, TcpServer};
use std::io::{BufRead, BufReader, ErrorKind, Read};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

fn wait_for(what: &str, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < Duration::from_secs(10), "timed out: {what}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Reads until the server closes the connection; the bytes read.
fn read_to_close(s: &mut TcpStream) -> usize {
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut total = 0;
    let mut buf = [0u8; 65536];
    loop {
        match s.read(&mut buf) {
            Ok(0) => return total,
            Ok(n) => total += n,
            Err(e) if e.kind() == ErrorKind::ConnectionReset => return total,
            Err(e) => panic!("the server did not close the connection: {e}"),
        }
    }
}

#[test]
fn only_the_client_limit_is_served_the_rest_are_closed_and_counted() {
    let edge = Edge::start(1).unwrap();
    let limit = 3;
    let mut server = TcpServer::bind(
        edge.handle(),
        "127.0.0.1:0".parse().unwrap(),
        TcpLimits {
            max_clients: limit,
            client_queue: 64,
        },
    )
    .unwrap();
    let addr = server.local_addr();
    let stats = server.shared_stats();
    let handled = || stats.accepted.get() + stats.refused.get();
    // One at a time, so which ones are refused is known.
    let mut clients = Vec::new();
    for k in 0..limit + 5 {
        clients.push(TcpStream::connect(addr).unwrap());
        wait_for("the connection handled", || handled() == k as u64 + 1);
    }
    assert_eq!(stats.accepted.get(), limit as u64);
    assert_eq!(stats.refused.get(), 5);
    assert_eq!(stats.connected.load(Ordering::Relaxed), limit as u64);
    let mut buf = Vec::new();
    for seq in 0..5 {
        line(seq, &mut buf);
        server.publish(&buf);
    }
    let mut refused = clients.split_off(limit);
    for c in clients.iter_mut() {
        c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut r = BufReader::new(c.try_clone().unwrap());
        for seq in 0..5 {
            let mut l = String::new();
            r.read_line(&mut l).unwrap();
            let v: serde_json::Value = serde_json::from_str(&l).unwrap();
            assert_eq!(v["seq"], seq, "a served client gets every line");
        }
    }
    for c in refused.iter_mut() {
        assert_eq!(read_to_close(c), 0, "a refused client gets nothing");
    }
    // When the served clients leave, their places are free again.
    drop(clients);
    wait_for("the served clients gone", || {
        stats.connected.load(Ordering::Relaxed) == 0
    });
    let again: Vec<_> = (0..limit)
        .map(|_| TcpStream::connect(addr).unwrap())
        .collect();
    wait_for("new clients served", || {
        stats.accepted.get() == 2 * limit as u64
    });
    assert_eq!(stats.refused.get(), 5);
    assert_eq!(stats.disconnected.get(), limit as u64);
    assert_eq!(stats.dropped.get(), 0);
    drop(again);
    server.shutdown();
    edge.stop();
}

/// A client socket with a tiny receive buffer (so a tiny TCP window).
fn tiny_window_client(addr: SocketAddr) -> TcpStream {
    let s = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
    s.set_recv_buffer_size(1024).unwrap();
    s.connect(&addr.into()).unwrap();
    s.into()
}

#[test]
fn a_client_that_never_reads_is_dropped_when_its_queue_fills_and_freed() {
    let edge = Edge::start(1).unwrap();
    let queue = 64;
    let mut server = TcpServer::bind(
        edge.handle(),
        "127.0.0.1:0".parse().unwrap(),
        TcpLimits {
            max_clients: 4,
            client_queue: queue,
        },
    )
    .unwrap();
    let addr = server.local_addr();
    let stats = server.shared_stats();
    let healthy = TcpStream::connect(addr).unwrap();
    let reader = std::thread::spawn(move || {
        // Only counts lines: this reader must keep up.
        let mut n = 0u64;
        let mut r = BufReader::with_capacity(1 << 16, healthy);
        loop {
            let buf = r.fill_buf().unwrap();
            if buf.is_empty() {
                return n;
            }
            n += buf.iter().filter(|&&b| b == b'\n').count() as u64;
            let k = buf.len();
            r.consume(k);
        }
    });
    let mut slow = tiny_window_client(addr);
    wait_for("both connected", || {
        stats.connected.load(Ordering::Relaxed) == 2
    });
    let mut buf = Vec::new();
    let mut seq = 0u64;
    let t0 = Instant::now();
    while stats.dropped.get() == 0 {
        assert!(
            seq < 200_000 && t0.elapsed() < Duration::from_secs(30),
            "the slow client was never dropped ({seq} lines)"
        );
        line(seq, &mut buf);
        server.publish(&buf);
        seq += 1;
        std::thread::sleep(Duration::from_micros(50));
    }
    eprintln!("the slow client was dropped after {seq} lines");
    // Its task has ended and its socket is closed: what the kernel buffered
    // is all it gets, nothing is kept for it on the server.
    wait_for("the slow client's task ended", || {
        stats.connected.load(Ordering::Relaxed) == 1
    });
    let got = read_to_close(&mut slow);
    assert!(
        got < seq as usize * buf.len(),
        "the slow client did not get everything: {got} bytes"
    );
    assert_eq!(stats.dropped.get(), 1);
    assert_eq!(stats.disconnected.get(), 0);
    // The healthy client is still served, and gets the rest at shutdown.
    for _ in 0..10 {
        line(seq, &mut buf);
        server.publish(&buf);
        seq += 1;
    }
    server.shutdown();
    let n = reader.join().unwrap();
    let lost = stats.lines_dropped.get();
    assert_eq!(
        n + lost,
        seq,
        "the healthy client got every line handed over"
    );
    edge.stop();
}
