//! Thousands of TCP clients connecting and leaving leave nothing behind:
//! after 10 000 connect/disconnect cycles against a running pose stream the
//! process's resident and virtual memory and its thread count are back
//! within 5 % of where they were (alone in its test binary so no other test
//! moves the figures).

mod common;
use common::pose;
use photopose_stream::{Edge, PoseMessage, PoseStatus, TcpLimits, TcpServer, TcpStats};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// (VmRSS kB, VmSize kB, threads) of this process.
fn footprint() -> (u64, u64, u64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let field = |name: &str| -> u64 {
        let l = status
            .lines()
            .find(|l| l.starts_with(name))
            .unwrap_or_else(|| panic!("{name} missing"));
        l[name.len()..]
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse()
            .unwrap()
    };
    (field("VmRSS:"), field("VmSize:"), field("Threads:"))
}

fn handled(s: &TcpStats) -> u64 {
    s.accepted.get() + s.refused.get()
}

/// `n` clients connect and leave at once; a line is published now and then.
fn churn(server: &mut TcpServer, addr: SocketAddr, n: u64, deadline: Instant) {
    let stats = server.shared_stats();
    let start = handled(&stats);
    let mut buf = Vec::new();
    for k in 0..n {
        drop(TcpStream::connect(addr).unwrap());
        if k % 10 == 0 {
            let mut m = PoseMessage::new(&std::sync::Arc::from("camera"), k, PoseStatus::Ok);
            m.pose = Some(pose(k as f64));
            m.encode_line(&mut buf);
            server.publish(&buf);
        }
        // Keep the listen backlog short.
        while handled(&stats) + 64 < start + k {
            assert!(Instant::now() < deadline, "the server stopped accepting");
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    while handled(&stats) < start + n || stats.connected.load(Ordering::Relaxed) > 0 {
        assert!(Instant::now() < deadline, "clients still held: {stats:?}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn ten_thousand_reconnects_leave_memory_and_threads_where_they_were() {
    let deadline = Instant::now() + Duration::from_secs(180);
    let edge = Edge::start(1).unwrap();
    // A limit far above the clients in flight: every one is served.
    let mut server = TcpServer::bind(
        edge.handle(),
        "127.0.0.1:0".parse().unwrap(),
        TcpLimits {
            max_clients: photopose_stream::tcp::MAX_CLIENTS,
            client_queue: 256,
        },
    )
    .unwrap();
    let addr = server.local_addr();
    // Warm the allocator and the runtime.
    churn(&mut server, addr, 3_000, deadline);
    std::thread::sleep(Duration::from_millis(200));
    let before = footprint();
    churn(&mut server, addr, 10_000, deadline);
    std::thread::sleep(Duration::from_millis(200));
    let after = footprint();
    let stats = server.shared_stats();
    eprintln!("(VmRSS kB, VmSize kB, threads): {before:?} → {after:?}; {stats:?}");
    assert_eq!(stats.accepted.get(), 13_000);
    assert_eq!(stats.disconnected.get(), 13_000);
    let within = |a: u64, b: u64| (b as f64) <= a as f64 * 1.05;
    assert!(
        within(before.0, after.0),
        "VmRSS grew: {} → {} kB",
        before.0,
        after.0
    );
    assert!(
        within(before.1, after.1),
        "VmSize grew: {} → {} kB",
        before.1,
        after.1
    );
    assert!(
        within(before.2, after.2),
        "threads grew: {} → {}",
        before.2,
        after.2
    );
    server.shutdown();
    edge.stop();
}
