//! The RSI server over real UDP on loopback, without rendering: direct
//! exchanges (KR C2's IPOC-only datagram, IPOC echoed verbatim, the
//! controller file's spelling, a large datagram), bad datagrams and an
//! unlisted sender dropped while the server keeps answering a simulated
//! controller, and camera frames that stop (the correction freezes within
//! the configured age) and resume (no jump).

mod common;

use common::{hand_eye, nominal_tcp, settings};
use photopose_rsi::codec::parse_sen;
use photopose_rsi::controller::{SimConfig, SimController};
use photopose_rsi::law::{CorrectionMode, LawStatus, StaleReason};
use photopose_rsi::server::{RsiClock, RsiServer};
use photopose_rsi::{latest_slot, Measurement, RsiConfig};
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn exchange(sock: &UdpSocket, to: SocketAddr, msg: &[u8]) -> String {
    sock.send_to(msg, to).unwrap();
    let mut buf = [0u8; 2048];
    let (n, _) = sock.recv_from(&mut buf).unwrap();
    String::from_utf8(buf[..n].to_vec()).unwrap()
}

/// Waits (bounded) until `f` holds.
fn eventually(mut f: impl FnMut() -> bool) -> bool {
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(10) {
        if f() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

const ETHERNET_XML: &str = r#"<ROOT>
  <CONFIG><IP_NUMBER>127.0.0.1</IP_NUMBER><PORT>49152</PORT><SENTYPE>PhotoPose</SENTYPE><ONLYSEND>FALSE</ONLYSEND></CONFIG>
  <SEND><ELEMENTS><ELEMENT TAG="DEF_RIst" TYPE="DOUBLE" INDX="INTERNAL"/><ELEMENT TAG="DEF_RSol" TYPE="DOUBLE" INDX="INTERNAL"/><ELEMENT TAG="DEF_Delay" TYPE="LONG" INDX="INTERNAL"/></ELEMENTS></SEND>
  <RECEIVE><ELEMENTS>
    <ELEMENT TAG="RKorr.X" TYPE="DOUBLE" INDX="1" HOLDON="0"/><ELEMENT TAG="RKorr.Y" TYPE="DOUBLE" INDX="2" HOLDON="0"/>
    <ELEMENT TAG="RKorr.Z" TYPE="DOUBLE" INDX="3" HOLDON="0"/><ELEMENT TAG="RKorr.A" TYPE="DOUBLE" INDX="4" HOLDON="0"/>
    <ELEMENT TAG="RKorr.B" TYPE="DOUBLE" INDX="5" HOLDON="0"/><ELEMENT TAG="RKorr.C" TYPE="DOUBLE" INDX="6" HOLDON="0"/>
    <ELEMENT TAG="DiO" TYPE="LONG" INDX="7" HOLDON="0"/>
  </ELEMENTS></RECEIVE>
</ROOT>"#;

#[test]
fn direct_exchanges_follow_the_controller_file() {
    let cfg = RsiConfig {
        enabled: true,
        bind: "127.0.0.1".into(),
        controllers: vec!["127.0.0.1".into()],
        ethernet_config: Some("RSI_EthernetConfig.xml".into()),
        ..RsiConfig::default()
    };
    let mut s = cfg.settings(Some(ETHERNET_XML)).unwrap();
    assert_eq!(s.bind.port(), 49152);
    s.bind.set_port(0);
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn(s, hand_eye(), reader, RsiClock::new()).unwrap();
    let to = server.local_addr();
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();

    // KR C2's first datagram, IPOC with leading zeros echoed verbatim.
    let r = exchange(&sock, to, b"<Rob TYPE=\"KUKA\"><IPOC>000123</IPOC></Rob>");
    assert_eq!(
        r,
        "<Sen Type=\"PhotoPose\"><RKorr X=\"0.0000\" Y=\"0.0000\" Z=\"0.0000\" A=\"0.0000\" B=\"0.0000\" C=\"0.0000\"/><DiO>0.0000</DiO><IPOC>000123</IPOC></Sen>"
    );
    // A datagram near the 64 KiB limit with extra elements is answered.
    let mut big = String::from("<Rob Type=\"KUKA\">");
    while big.len() < 60_000 {
        big.push_str("<Tech C11=\"0.0\" C12=\"1.5\"/>");
    }
    big.push_str(
        "<RSol X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>123645634563</IPOC></Rob>",
    );
    let r = exchange(&sock, to, big.as_bytes());
    let f = parse_sen(r.as_bytes(), "PhotoPose", "RKorr").unwrap();
    assert!(f.type_matches);
    assert_eq!(f.ipoc.as_str(), "123645634563");
    // No measurement yet: frozen, zero (relative).
    assert_eq!(f.correction, Some([0.0; 6]));
    assert!(eventually(
        || server.status() == Some(LawStatus::Stale(StaleReason::NoMeasurement))
    ));
    let st = server.stop();
    assert_eq!(st.replies, 2);
    assert_eq!(st.garbage, 0);
}

#[test]
fn queued_datagrams_are_drained_and_only_the_newest_is_answered() {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to = socket.local_addr().unwrap();
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    // Three cycles queue up before the server runs (a stall).
    for ipoc in [100, 104, 108] {
        sock.send_to(
            format!("<Rob Type=\"KUKA\"><IPOC>{ipoc}</IPOC></Rob>").as_bytes(),
            to,
        )
        .unwrap();
    }
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn_on(
        socket,
        settings(|_| {}),
        hand_eye(),
        reader,
        RsiClock::new(),
    )
    .unwrap();
    let mut buf = [0u8; 1024];
    let (n, _) = sock.recv_from(&mut buf).unwrap();
    let f = parse_sen(&buf[..n], "ImFree", "RKorr").unwrap();
    assert_eq!(f.ipoc.value(), 108);
    // Nothing else is answered.
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    assert!(sock.recv_from(&mut buf).is_err());
    let st = server.stop();
    assert_eq!((st.replies, st.drained), (1, 2));
}

#[test]
fn bad_datagrams_and_unlisted_senders_are_dropped_and_the_server_keeps_answering() {
    let clock = RsiClock::new();
    let s = settings(|c| c.realtime_priority = Some(50));
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn(s.clone(), hand_eye(), reader, clock).unwrap();
    let to = server.local_addr();
    let mut sim_cfg = SimConfig::new(to);
    sim_cfg.cycles = 500;
    sim_cfg.timeout = 100;
    sim_cfg.realtime_priority = Some(60);
    let sim = SimController::spawn(sim_cfg, clock).unwrap();

    let listed = UdpSocket::bind("127.0.0.1:0").unwrap();
    let unlisted = UdpSocket::bind("127.0.0.2:0").unwrap();
    let good = b"<Rob Type=\"KUKA\"><IPOC>5</IPOC></Rob>";
    let bad: Vec<Vec<u8>> = vec![
        b"garbage \x00\xff\xfe".to_vec(),
        good[..good.len() - 7].to_vec(),         // truncated
        vec![b'<'; 65_507],                      // the largest UDP datagram, not XML
        b"<Rob><IPOC>12x</IPOC></Rob>".to_vec(), // bad IPOC
        b"<Sen Type=\"ImFree\"><IPOC>1</IPOC></Sen>".to_vec(),
        Vec::new(), // empty
    ];
    std::thread::sleep(Duration::from_millis(200));
    for round in 0..3 {
        for b in &bad {
            listed.send_to(b, to).unwrap();
        }
        unlisted.send_to(good, to).unwrap();
        std::thread::sleep(Duration::from_millis(100 + 50 * round));
    }
    let want_garbage = 3 * bad.len() as u64;
    assert!(
        eventually(|| {
            let st = server.stats().snapshot();
            st.foreign_port == want_garbage && st.unlisted == 3
        }),
        "{:?}",
        server.stats().snapshot()
    );
    let report = sim.join().unwrap();
    // The unlisted sender was never answered.
    unlisted.set_nonblocking(true).unwrap();
    let mut buf = [0u8; 512];
    assert!(unlisted.recv_from(&mut buf).is_err());
    let st = server.stop();
    assert!(!report.stopped_by_timeout, "{report:?}");
    assert_eq!(report.cycles + report.skipped, 500);
    assert!(
        st.replies + report.late >= report.cycles,
        "{st:?} {report:?}"
    );
    // Bad datagrams from another port of the controller's address are
    // dropped unparsed while the simulated controller's session is live.
    assert_eq!(st.foreign_port, want_garbage);
    assert_eq!(st.unlisted, 3);
    eprintln!(
        "garbage test: {st:?}; controller late {} skipped {}",
        report.late, report.skipped
    );
}

#[test]
fn frames_stop_then_the_correction_freezes_and_resumes_without_a_jump() {
    let he = hand_eye();
    let clock = RsiClock::new();
    let s = settings(|c| {
        c.mode = CorrectionMode::Absolute;
        c.max_age_ms = 100.0;
        c.realtime_priority = Some(50);
    });
    let law = s.law;
    let (mut publisher, reader) = latest_slot();
    let server = RsiServer::spawn(s.clone(), he, reader, clock).unwrap();
    let mut sim_cfg = SimConfig::new(server.local_addr());
    sim_cfg.cycles = 1000; // 4 s
    sim_cfg.timeout = 100;
    sim_cfg.mode = CorrectionMode::Absolute;
    sim_cfg.nominal = nominal_tcp(&he);
    // A fast drift, so that a freeze shows as a growing error.
    sim_cfg.error_drift_per_s = [0.2, 0.0, 0.0, 0.0, 0.0, 0.0];
    sim_cfg.realtime_priority = Some(60);
    let sim = SimController::spawn(sim_cfg, clock).unwrap();
    let probe = sim.probe();
    // The camera at 25 Hz from exact poses; silent from 1.5 s to 2.5 s.
    let gap = (1.5, 2.5);
    let last_before_gap = Arc::new(std::sync::Mutex::new(0.0f64));
    let done = Arc::new(AtomicBool::new(false));
    let cam = {
        let (last, done) = (last_before_gap.clone(), done.clone());
        std::thread::spawn(move || {
            let t0 = clock.now_s();
            let mut seq = 0;
            while !done.load(Ordering::Relaxed) && !probe.is_finished() {
                let st = probe.state();
                let t = st.time_s - t0;
                if t < gap.0 || t > gap.1 {
                    seq += 1;
                    publisher.publish(&Measurement {
                        plate_from_camera: he.camera_in_plate(&st.actual),
                        std_mm: 0.01,
                        std_deg: 0.001,
                        n_targets: 100,
                        time_s: st.time_s,
                        seq,
                    });
                    if t < gap.0 {
                        *last.lock().unwrap() = st.time_s;
                    }
                }
                std::thread::sleep(Duration::from_millis(40));
            }
        })
    };
    let report = sim.join().unwrap();
    done.store(true, Ordering::Relaxed);
    cam.join().unwrap();
    let st = server.stop();
    let last = *last_before_gap.lock().unwrap();
    let t0 = report.times[0];
    assert!(st.stale_cycles > 0);
    // Frozen: from max_age (+ one cycle) after the last frame before the gap
    // until the gap ends, the absolute total does not change.
    let freeze_from = last + law.max_age_s + 0.004;
    let frozen: Vec<usize> = (1..report.times.len())
        .filter(|&k| report.times[k - 1] > freeze_from && report.times[k] < t0 + gap.1)
        .collect();
    assert!(frozen.len() > 100, "{} frozen cycles", frozen.len());
    for &k in &frozen {
        assert_eq!(
            report.totals[k],
            report.totals[k - 1],
            "moved while frozen at cycle {k}"
        );
    }
    // The freeze happened within the configured age: the first cycle after
    // `last + max_age` holds.
    // No jump on resume (nor anywhere): every step within the slew limit.
    for i in 0..6 {
        let lim = if i < 3 {
            law.max_step_mm
        } else {
            law.max_step_deg
        };
        assert!(
            report.max_step[i] <= lim + 5e-5,
            "step {i}: {}",
            report.max_step[i]
        );
    }
    // The drift accumulated during the freeze is corrected again afterwards.
    let n = report.errors.len();
    let at_gap_end = report.times.iter().position(|&t| t > t0 + gap.1).unwrap();
    assert!(
        report.errors[at_gap_end].0 > 0.1,
        "{:?}",
        report.errors[at_gap_end]
    );
    assert!(report.errors[n - 1].0 < 0.05, "{:?}", report.errors[n - 1]);
    // Timeliness is the closed-loop test's business (the one long test).
    assert!(!report.stopped_by_timeout, "{report:?} {st:?}");
}

#[test]
fn the_simulated_controller_stops_after_timeout_faults() {
    // Nobody answers: every cycle is late.
    let silent = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut cfg = SimConfig::new(silent.local_addr().unwrap());
    cfg.timeout = 10;
    let r = SimController::spawn(cfg, RsiClock::new())
        .unwrap()
        .join()
        .unwrap();
    assert!(r.stopped_by_timeout);
    assert_eq!((r.late, r.mismatched, r.delay), (11, 0, 11));
    assert_eq!(r.cycles, 11);

    // A server whose SENTYPE does not match the context: mismatched replies.
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn(
        settings(|c| c.sentype = Some("Other".into())),
        hand_eye(),
        reader,
        RsiClock::new(),
    )
    .unwrap();
    let cfg = SimConfig::new(server.local_addr());
    let r = SimController::spawn(cfg, RsiClock::new())
        .unwrap()
        .join()
        .unwrap();
    assert!(r.stopped_by_timeout);
    assert!(r.mismatched > 0 && r.delay > 10, "{r:?}");
    let st = server.stop();
    assert!(st.replies > 0);
}

#[test]
fn a_tapped_server_hands_over_every_answered_cycle() {
    let s = settings(|_| {});
    let (_p, reader) = latest_slot();
    let tap = photopose_rsi::tap::CycleTap::new(16);
    let before_utc = photopose_rsi::tap::utc_ns();
    let before_mono = photopose_rsi::tap::monotonic_ns();
    let server =
        RsiServer::spawn_tapped(s, hand_eye(), reader, RsiClock::new(), tap.clone()).unwrap();
    let to = server.local_addr();
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    for (k, ipoc) in [1000u64, 1004, 1008].into_iter().enumerate() {
        let msg = format!(
            "<Rob Type=\"KUKA\"><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"{k}\"/>\
             <RSol X=\"7\" Y=\"8\" Z=\"9\" A=\"10\" B=\"11\" C=\"12\"/><IPOC>{ipoc}</IPOC></Rob>"
        );
        exchange(&sock, to, msg.as_bytes());
    }
    server.stop();
    let cycles: Vec<_> = std::iter::from_fn(|| tap.pop()).collect();
    assert_eq!(
        cycles.iter().map(|c| c.ipoc).collect::<Vec<_>>(),
        [1000, 1004, 1008]
    );
    for (k, c) in cycles.iter().enumerate() {
        assert_eq!(c.rist, Some([1.0, 2.0, 3.0, 4.0, 5.0, k as f64]));
        assert_eq!(c.rsol, Some([7.0, 8.0, 9.0, 10.0, 11.0, 12.0]));
        // No measurement: frozen, nothing sent.
        assert_eq!(c.status, LawStatus::Stale(StaleReason::NoMeasurement));
        assert_eq!(c.sent, [0.0; 6]);
        assert!(c.arrival_utc_ns >= before_utc && c.arrival_mono_ns >= before_mono);
    }
    assert!(cycles
        .windows(2)
        .all(|w| w[0].arrival_mono_ns <= w[1].arrival_mono_ns));
    assert_eq!((tap.pushed(), tap.dropped()), (3, 0));
}
