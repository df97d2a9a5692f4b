//! Handing pose lines to the TCP stream on the edge runtime allocates
//! nothing once warm: the line is copied into a preallocated buffer, queued
//! lock-free and the edge task woken. Counted over the whole process with
//! no client connected (with clients the edge side copies each line into a
//! shared buffer for them, which is allowed there), so the count covers the
//! publishing thread, the wake-up and the edge task taking the lines.

mod common;
use common::pose;
use photopose_stream::{Edge, PoseMessage, PoseStatus, TcpLimits, TcpServer};
use std::time::Duration;

#[global_allocator]
static GLOBAL: photopose_testkit::CountingAllocator = photopose_testkit::CountingAllocator;

#[test]
fn publishing_to_the_tcp_stream_allocates_nothing_once_warm() {
    let edge = Edge::start(1).unwrap();
    let mut server = TcpServer::bind(
        edge.handle(),
        "127.0.0.1:0".parse().unwrap(),
        TcpLimits::default(),
    )
    .unwrap();
    let mut m = PoseMessage::new(&std::sync::Arc::from("camera"), 1, PoseStatus::Ok);
    m.pose = Some(pose(1.0));
    let mut line = Vec::with_capacity(2048);
    m.encode_line(&mut line);
    let publish = |server: &mut TcpServer, n: usize| {
        for k in 0..n {
            server.publish(&line);
            if k % 50 == 0 {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    publish(&mut server, 3_000);
    let before = photopose_testkit::allocations();
    publish(&mut server, 10_000);
    let allocated = photopose_testkit::allocations() - before;
    assert_eq!(allocated, 0, "allocations while handing over 10 000 lines");
    server.shutdown();
    edge.stop();
}
