//! Hostile datagrams do not amplify into log lines: at most one warning per
//! reason per interval, the counters carry the rest. Its own test binary:
//! it installs a global subscriber that counts the RSI thread's warnings.

mod common;

use common::{hand_eye, settings};
use photopose_rsi::latest_slot;
use photopose_rsi::server::{RsiClock, RsiServer};
use std::net::UdpSocket;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::layer::{Context, Layer, SubscriberExt};

static WARNINGS: AtomicU64 = AtomicU64::new(0);

struct CountWarnings;

impl<S: Subscriber> Layer<S> for CountWarnings {
    fn on_event(&self, event: &Event<'_>, _ctx: Context<'_, S>) {
        let m = event.metadata();
        if *m.level() <= Level::WARN && m.target() == "photopose::rsi" {
            WARNINGS.fetch_add(1, Ordering::Relaxed);
        }
    }
}

#[test]
fn twenty_thousand_hostile_datagrams_give_a_handful_of_warnings() {
    tracing::subscriber::set_global_default(tracing_subscriber::registry().with(CountWarnings))
        .unwrap();
    let (_p, reader) = latest_slot();
    // The controller stays silent after its first cycle: a long idle time
    // keeps its session (another port could take over after it).
    let s = settings(|c| c.session_idle_ms = 60_000.0);
    let server = RsiServer::spawn(s, hand_eye(), reader, RsiClock::new()).unwrap();
    let to = server.local_addr();
    let ctl = UdpSocket::bind("127.0.0.1:0").unwrap();
    ctl.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let other = UdpSocket::bind("127.0.0.1:0").unwrap();
    let unlisted = UdpSocket::bind("127.0.0.2:0").unwrap();
    // The session opens (and the law logs its frozen state once).
    ctl.send_to(b"<Rob><IPOC>1000</IPOC></Rob>", to).unwrap();
    let mut buf = [0u8; 1024];
    ctl.recv_from(&mut buf).unwrap();
    let before = WARNINGS.load(Ordering::Relaxed);
    // Reasons alternate on every datagram (the old log wrote a line on
    // every change of reason).
    let hostile: [(&UdpSocket, &[u8]); 6] = [
        (&unlisted, b"<Rob><IPOC>2000</IPOC></Rob>"),
        (&other, b"<Rob><IPOC>2000</IPOC></Rob>"),
        (&ctl, b"garbage"),
        (&ctl, b"<Rob><IPOC>12<!---->99</IPOC></Rob>"),
        (&ctl, b"<Rob><IPOC>996</IPOC></Rob>"),
        (&ctl, b"<Rob><Delay D=\"1e300\"/><IPOC>2000</IPOC></Rob>"),
    ];
    let n = 20_000u64;
    for k in 0..n {
        let (s, d) = hostile[(k % 6) as usize];
        s.send_to(d, to).unwrap();
        if k % 100 == 99 {
            // Let the server keep up (no socket buffer overflows).
            let t = Instant::now();
            while server.stats().received.get() < k + 2 && t.elapsed() < Duration::from_secs(10) {
                std::thread::sleep(Duration::from_micros(50));
            }
        }
    }
    let t = Instant::now();
    while server.stats().received.get() < n + 1 && t.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(1));
    }
    let st = server.stop();
    let lines = WARNINGS.load(Ordering::Relaxed) - before;
    assert_eq!(st.received, n + 1, "{st:?}");
    assert_eq!(
        st.unlisted + st.foreign_port + st.garbage + st.stale_ipoc,
        n,
        "{st:?}"
    );
    // One line per reason (unlisted, foreign port, syntax, bad IPOC, old
    // IPOC, out of range) in this run of well under 10 s, plus perhaps the
    // law's "correction frozen" line of the first cycle (logged after its
    // reply, so it may be counted here).
    assert!(lines <= 7, "{lines} warnings for {n} datagrams: {st:?}");
    assert!(lines >= 1);
}
