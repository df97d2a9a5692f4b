//! The RSI server's safety over real UDP on loopback, one test per defect:
//! non-finite corrections (a huge hand-eye, a NaN measurement), the slew
//! limit per controller cycle (repeated IPOCs, other ports, a flood, the
//! session's restart), the rounding remainder of relative increments, a
//! dual-stack bind, a reply larger than 4 KiB, malformed numbers and IPOCs.
//! The test's own socket plays the controller in lock step (send a cycle,
//! wait for its reply), so nothing depends on timing except the flood test.

mod common;

use common::{hand_eye, nominal_tcp, settings};
use nalgebra::Isometry3;
use photopose_rsi::codec::Pose6;
use photopose_rsi::controller::{SimConfig, SimController};
use photopose_rsi::law::{pose_to_isometry, CorrectionMode, LawStatus};
use photopose_rsi::server::{RsiClock, RsiServer};
use photopose_rsi::{latest_slot, HandEye, Measurement, RsiConfig, RsiWarning, SlotPublisher};
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A `<Rob>` cycle with `RSol` at `rsol`.
fn rob(ipoc: u64, rsol: &Pose6) -> String {
    format!(
        "<Rob Type=\"KUKA\"><RIst X=\"{0}\" Y=\"{1}\" Z=\"{2}\" A=\"{3}\" B=\"{4}\" C=\"{5}\"/><RSol X=\"{0}\" Y=\"{1}\" Z=\"{2}\" A=\"{3}\" B=\"{4}\" C=\"{5}\"/><Delay D=\"0\"/><IPOC>{ipoc}</IPOC></Rob>",
        rsol[0], rsol[1], rsol[2], rsol[3], rsol[4], rsol[5]
    )
}

/// The six correction values of a reply as integers in units of the last
/// printed digit (exact: no floating point between the wire and the sum),
/// and the echoed IPOC.
fn korr_units(reply: &str) -> ([i64; 6], String) {
    let mut out = [0i64; 6];
    for (k, name) in ["X", "Y", "Z", "A", "B", "C"].iter().enumerate() {
        let key = format!(" {name}=\"");
        let at = reply.find(&key).unwrap_or_else(|| panic!("{reply}")) + key.len();
        let v = &reply[at..at + reply[at..].find('"').unwrap()];
        let (int, frac) = v
            .split_once('.')
            .unwrap_or_else(|| panic!("{v} in {reply}"));
        assert!(
            frac.len() == 4 && frac.bytes().all(|b| b.is_ascii_digit()),
            "{v}"
        );
        let digits: String = format!("{int}{frac}");
        out[k] = digits.parse().unwrap_or_else(|_| panic!("{v} in {reply}"));
    }
    let ipoc = reply
        .split_once("<IPOC>")
        .and_then(|(_, r)| r.split_once("</IPOC>"))
        .map(|(i, _)| i.to_string())
        .unwrap_or_else(|| panic!("{reply}"));
    (out, ipoc)
}

/// Sends a cycle and returns the reply that echoes its IPOC; replies with
/// other IPOCs that arrive first are handed to `other`.
fn cycle_on(
    sock: &UdpSocket,
    to: SocketAddr,
    ipoc: u64,
    rsol: &Pose6,
    mut other: impl FnMut(&str),
) -> String {
    sock.send_to(rob(ipoc, rsol).as_bytes(), to).unwrap();
    let mut buf = vec![0u8; 70_000];
    loop {
        let (n, _) = sock
            .recv_from(&mut buf)
            .unwrap_or_else(|e| panic!("no reply to IPOC {ipoc}: {e}"));
        let r = std::str::from_utf8(&buf[..n]).unwrap().to_string();
        if r.contains(&format!("<IPOC>{ipoc}</IPOC>")) {
            return r;
        }
        other(&r);
    }
}

fn controller_socket() -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    s
}

/// Nothing arrives on `sock` within `wait`.
fn silent(sock: &UdpSocket, wait: Duration) -> bool {
    sock.set_read_timeout(Some(wait)).unwrap();
    let mut buf = [0u8; 2048];
    let r = sock.recv_from(&mut buf).is_err();
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    r
}

/// Waits (bounded) until the server has read `n` datagrams.
fn settle(server: &RsiServer, n: u64) {
    let t = Instant::now();
    while server.stats().received.get() < n {
        assert!(t.elapsed() < Duration::from_secs(10), "server stalled");
        std::thread::sleep(Duration::from_micros(100));
    }
}

/// Publishes a measurement of the TCP at `tcp`, exposed now.
fn publish(p: &mut SlotPublisher, he: &HandEye, tcp: &Isometry3<f64>, clock: &RsiClock, seq: u64) {
    p.publish(&Measurement {
        plate_from_camera: he.camera_in_plate(tcp),
        std_mm: 0.01,
        std_deg: 0.001,
        n_targets: 100,
        time_s: clock.now_s(),
        seq,
    });
}

/// The nominal TCP moved by `d` (base frame translations, KUKA angles added).
fn moved(nominal: &Pose6, d: &Pose6) -> Isometry3<f64> {
    pose_to_isometry(&std::array::from_fn(|i| nominal[i] + d[i]))
}

#[test]
fn a_huge_hand_eye_never_reaches_the_wire_and_a_bad_measurement_never_enters_the_total() {
    // Translations of 1.7e308 mm: finite, accepted by a file check that
    // only asks for finite numbers, and NaN once composed.
    let huge = HandEye {
        tcp_from_camera: pose_to_isometry(&[1.7e308, -1.7e308, 1.7e308, 90.0, 10.0, 0.0]),
        base_from_plate: pose_to_isometry(&[-1.7e308, 1.7e308, 1.7e308, 30.0, 0.0, 0.0]),
    };
    let he = hand_eye();
    let nominal = nominal_tcp(&he);
    for mode in [CorrectionMode::Absolute, CorrectionMode::Relative] {
        let clock = RsiClock::new();
        let s = settings(|c| {
            c.mode = mode;
            c.max_age_ms = 60_000.0;
        });
        let (mut p, reader) = latest_slot();
        let server = RsiServer::spawn(s, huge, reader, clock).unwrap();
        let to = server.local_addr();
        let ctl = controller_socket();
        publish(&mut p, &he, &moved(&nominal, &[1.0; 6]), &clock, 1);
        for k in 0..20 {
            let r = cycle_on(&ctl, to, 1000 + 4 * k, &nominal, |_| {});
            assert!(!r.contains("NaN") && !r.contains("inf"), "{r}");
            let (units, _) = korr_units(&r);
            assert_eq!(units, [0; 6], "{mode:?} cycle {k}: {r}");
        }
        assert_eq!(server.status(), Some(LawStatus::FrozenInvalid));
        let st = server.stop();
        assert_eq!((st.replies, st.invalid_cycles), (20, 20), "{st:?}");
    }

    // A measurement whose pose is NaN, then a good one: the correction
    // freezes, then tracks with finite values (no NaN left in the total).
    let clock = RsiClock::new();
    let s = settings(|c| {
        c.mode = CorrectionMode::Absolute;
        c.max_age_ms = 60_000.0;
    });
    let (mut p, reader) = latest_slot();
    let server = RsiServer::spawn(s.clone(), he, reader, clock).unwrap();
    let to = server.local_addr();
    let ctl = controller_socket();
    let mut bad = moved(&nominal, &[0.0; 6]);
    bad.translation.vector.x = f64::NAN;
    p.publish(&Measurement {
        plate_from_camera: bad,
        std_mm: 0.01,
        std_deg: 0.001,
        n_targets: 100,
        time_s: clock.now_s(),
        seq: 1,
    });
    let mut ipoc = 5000;
    for _ in 0..5 {
        ipoc += 4;
        let (u, _) = korr_units(&cycle_on(&ctl, to, ipoc, &nominal, |_| {}));
        assert_eq!(u, [0; 6]);
    }
    assert_eq!(server.status(), Some(LawStatus::FrozenInvalid));
    publish(
        &mut p,
        &he,
        &moved(&nominal, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        &clock,
        2,
    );
    let mut last = [0i64; 6];
    for k in 0..30 {
        ipoc += 4;
        let (u, _) = korr_units(&cycle_on(&ctl, to, ipoc, &nominal, |_| {}));
        // Absolute: the total walks by one slew step (0.05 mm) per cycle.
        assert!(
            (u[0] - last[0]).abs() <= 500,
            "cycle {k}: {u:?} after {last:?}"
        );
        last = u;
    }
    // The target is gain × the 1 mm error: -0.5 mm, reached in 10 steps.
    assert_eq!(last[0], -5000, "{last:?}");
    assert_eq!(server.status(), Some(LawStatus::Tracking));
    server.stop();
}

#[test]
fn repeated_ipocs_and_other_ports_never_step_the_correction() {
    let he = hand_eye();
    let nominal = nominal_tcp(&he);
    let clock = RsiClock::new();
    let s = settings(|c| {
        c.mode = CorrectionMode::Absolute;
        c.max_age_ms = 60_000.0;
    });
    let step_units = (s.law.max_step_mm * 1e4).round() as i64;
    let (mut p, reader) = latest_slot();
    let server = RsiServer::spawn(s, he, reader, clock).unwrap();
    let to = server.local_addr();
    let ctl = controller_socket();
    let other = controller_socket();
    // The TCP 3 mm off: the target is -1.5 mm, reached in 30 steps.
    publish(
        &mut p,
        &he,
        &moved(&nominal, &[3.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        &clock,
        1,
    );
    let first = cycle_on(&ctl, to, 1000, &nominal, |_| {});
    let (x0, _) = korr_units(&first);
    assert_eq!(x0[0], -step_units, "{first}");
    // 200 repeats of the same IPOC from the controller's port, 200 newer
    // IPOCs from another port of its address, one older IPOC; in bursts the
    // server reads before the next (no socket buffer overflows).
    let mut sent = 1;
    for k in 0..200u64 {
        ctl.send_to(rob(1000, &nominal).as_bytes(), to).unwrap();
        other
            .send_to(rob(1004 + 4 * k, &nominal).as_bytes(), to)
            .unwrap();
        sent += 2;
        if k % 25 == 24 {
            settle(&server, sent);
        }
    }
    ctl.send_to(rob(996, &nominal).as_bytes(), to).unwrap();
    settle(&server, sent + 1);
    let mut repeats = 0;
    let second = cycle_on(&ctl, to, 1004, &nominal, |r| {
        // A repeat is answered with exactly the same reply.
        assert_eq!(r, first);
        repeats += 1;
    });
    let (x1, _) = korr_units(&second);
    assert_eq!(x1[0] - x0[0], -step_units, "{first} → {second}");
    assert!(
        silent(&other, Duration::from_millis(100)),
        "another port was answered"
    );
    let st = server.stop();
    assert_eq!(st.cycles, 2, "{st:?}");
    assert_eq!(st.repeated, 200, "{st:?}");
    assert_eq!(st.foreign_port, 200, "{st:?}");
    assert_eq!(st.stale_ipoc, 1, "{st:?}");
    assert!((1..=200).contains(&repeats), "{repeats}");
}

#[test]
fn the_session_restarts_from_a_new_port_after_silence_with_zero_correction() {
    let he = hand_eye();
    let nominal = nominal_tcp(&he);
    let clock = RsiClock::new();
    let s = settings(|c| {
        c.mode = CorrectionMode::Absolute;
        c.max_age_ms = 60_000.0;
        c.session_idle_ms = 50.0;
    });
    let (mut p, reader) = latest_slot();
    let server = RsiServer::spawn(s, he, reader, clock).unwrap();
    let to = server.local_addr();
    let (old, new) = (controller_socket(), controller_socket());
    publish(
        &mut p,
        &he,
        &moved(&nominal, &[3.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        &clock,
        1,
    );
    let mut x = [0; 6];
    for k in 0..10 {
        x = korr_units(&cycle_on(&old, to, 100 + 4 * k, &nominal, |_| {})).0;
    }
    assert_eq!(x[0], -5000);
    // The old session is live: another port is not answered. (Sent right
    // after a reply, far inside the 50 ms idle time.)
    new.send_to(rob(7, &nominal).as_bytes(), to).unwrap();
    assert!(silent(&new, Duration::from_millis(20)));
    // After the idle time the new port takes over, from zero correction:
    // the frame exposed before the new session cannot be compared with
    // its commanded poses (stale), a new one tracks from zero.
    std::thread::sleep(Duration::from_millis(120));
    let (y, _) = korr_units(&cycle_on(&new, to, 11, &nominal, |_| {}));
    assert_eq!(y[0], 0, "{y:?}");
    publish(
        &mut p,
        &he,
        &moved(&nominal, &[3.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
        &clock,
        2,
    );
    let (y, _) = korr_units(&cycle_on(&new, to, 13, &nominal, |_| {}));
    assert_eq!(y[0], -500, "{y:?}");
    // Now the old port is the foreign one.
    old.send_to(rob(200, &nominal).as_bytes(), to).unwrap();
    let (y, _) = korr_units(&cycle_on(&new, to, 15, &nominal, |_| {}));
    assert_eq!(y[0], -1000, "{y:?}");
    assert!(silent(&old, Duration::from_millis(50)));
    let st = server.stop();
    assert_eq!(st.session_restarts, 1, "{st:?}");
    assert_eq!(st.foreign_port, 2, "{st:?}");
}

#[test]
fn relative_increments_sum_to_the_total_and_never_pass_the_clamp() {
    let he = hand_eye();
    let nominal = nominal_tcp(&he);
    let clock = RsiClock::new();
    // A slew limit that is not a whole number of printed digits.
    let s = settings(|c| {
        c.mode = CorrectionMode::Relative;
        c.max_age_ms = 60_000.0;
        c.max_step_deg = 0.00337;
        c.clamp_deg = 2.0;
    });
    let (mut p, reader) = latest_slot();
    let server = RsiServer::spawn(s, he, reader, clock).unwrap();
    let to = server.local_addr();
    let ctl = controller_socket();
    // The TCP turned 10° about the base's z: the target is the clamp.
    publish(
        &mut p,
        &he,
        &moved(&nominal, &[0.0, 0.0, 0.0, 10.0, 0.0, 0.0]),
        &clock,
        1,
    );
    let (clamp, step) = (20_000i64, 33i64);
    let mut sum = [0i64; 6];
    let mut unchanged = 0;
    for k in 0..2000u64 {
        let (u, _) = korr_units(&cycle_on(&ctl, to, 40 + 4 * k, &nominal, |_| {}));
        for i in 3..6 {
            assert!(u[i].abs() <= step, "cycle {k}: increment {u:?}");
        }
        let before = sum;
        (0..6).for_each(|i| sum[i] += u[i]);
        for i in 3..6 {
            assert!(sum[i].abs() <= clamp, "cycle {k}: integrated {sum:?}");
        }
        unchanged = if sum == before { unchanged + 1 } else { 0 };
        if unchanged == 20 {
            break;
        }
    }
    // The controller's integral is exactly the clamped total, 2.0000°.
    assert_eq!(sum[3].abs(), clamp, "{sum:?}");
    server.stop();
}

#[test]
fn a_dual_stack_bind_answers_an_ipv4_controller() {
    let cfg = RsiConfig {
        enabled: true,
        bind: "::".into(),
        port: Some(1),
        controllers: vec!["127.0.0.1".into()],
        ..RsiConfig::default()
    };
    let mut s = cfg.settings(None).unwrap();
    assert!(
        s.warnings
            .iter()
            .any(|w| matches!(w, RsiWarning::DualStackBind { .. })),
        "{:?}",
        s.warnings
    );
    s.bind.set_port(0);
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn(s, hand_eye(), reader, RsiClock::new()).unwrap();
    let to = SocketAddr::from(([127, 0, 0, 1], server.local_addr().port()));
    let ctl = controller_socket();
    let r = cycle_on(&ctl, to, 77, &nominal_tcp(&hand_eye()), |_| {});
    assert!(r.starts_with("<Sen Type=\"ImFree\">"), "{r}");
    let st = server.stop();
    assert_eq!((st.replies, st.unlisted), (1, 0));
}

#[test]
fn a_controller_file_with_250_receive_elements_is_answered_in_full() {
    let mut xml = String::from(
        "<ROOT><CONFIG><PORT>49152</PORT><SENTYPE>ImFree</SENTYPE></CONFIG>\
         <SEND><ELEMENTS><ELEMENT TAG=\"DEF_RSol\"/></ELEMENTS></SEND><RECEIVE><ELEMENTS>\n",
    );
    for a in ["X", "Y", "Z", "A", "B", "C"] {
        xml.push_str(&format!(
            "<ELEMENT TAG=\"RKorr.{a}\" TYPE=\"DOUBLE\" INDX=\"1\" HOLDON=\"0\"/>\n"
        ));
    }
    for k in 0..244 {
        xml.push_str(&format!(
            "<ELEMENT TAG=\"Out{k}\" TYPE=\"LONG\" INDX=\"{}\" HOLDON=\"0\"/>\n",
            k + 7
        ));
    }
    xml.push_str("</ELEMENTS></RECEIVE></ROOT>\n");
    // A real file, read back as the daemon does.
    let dir = std::env::temp_dir().join(format!("photopose-rsi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("RSI_EthernetConfig.xml");
    std::fs::write(&path, &xml).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let cfg = RsiConfig {
        enabled: true,
        bind: "127.0.0.1".into(),
        controllers: vec!["127.0.0.1".into()],
        ethernet_config: Some(path),
        ..RsiConfig::default()
    };
    let mut s = cfg.settings(Some(&text)).unwrap();
    assert!(s.reply_capacity() > 4096, "{}", s.reply_capacity());
    s.bind.set_port(0);
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn(s, hand_eye(), reader, RsiClock::new()).unwrap();
    let ctl = controller_socket();
    let r = cycle_on(
        &ctl,
        server.local_addr(),
        9,
        &nominal_tcp(&hand_eye()),
        |_| {},
    );
    assert!(r.len() > 4096, "{}", r.len());
    assert!(
        r.contains("<Out243>0.0000</Out243><IPOC>9</IPOC></Sen>"),
        "{r}"
    );
    server.stop();
}

#[test]
fn malformed_ipocs_and_numbers_are_counted_not_answered() {
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn(settings(|_| {}), hand_eye(), reader, RsiClock::new()).unwrap();
    let to = server.local_addr();
    let ctl = controller_socket();
    let nominal = nominal_tcp(&hand_eye());
    // Open the session.
    cycle_on(&ctl, to, 10, &nominal, |_| {});
    let bad = [
        "<Rob Type=\"KUKA\"><IPOC>12<!---->99</IPOC></Rob>".to_string(),
        "<Rob Type=\"KUKA\"><IPOC><!-- -->99</IPOC></Rob>".to_string(),
        "<Rob Type=\"KUKA\"><IPOC>98</IPOC><IPOC>99</IPOC></Rob>".to_string(),
        "<Rob Type=\"KUKA\"><Delay D=\"1e300\"/><IPOC>99</IPOC></Rob>".to_string(),
        "<Rob Type=\"KUKA\"><Delay D=\"NaN\"/><IPOC>99</IPOC></Rob>".to_string(),
        rob(99, &[1e300, 0.0, 0.0, 0.0, 0.0, 0.0]),
        rob(99, &[0.0, 0.0, 0.0, f64::INFINITY, 0.0, 0.0]),
        "<Rob Type=\"KUKA\"><IPOC>99999999999999999999999</IPOC></Rob>".to_string(),
    ];
    for b in &bad {
        ctl.send_to(b.as_bytes(), to).unwrap();
        assert!(silent(&ctl, Duration::from_millis(100)), "answered {b}");
    }
    // The next valid cycle is answered; the Delay metric never saw 1e300.
    cycle_on(&ctl, to, 14, &nominal, |r| panic!("unexpected {r}"));
    let st = server.stop();
    assert_eq!((st.garbage, st.cycles), (bad.len() as u64, 2), "{st:?}");
    assert_eq!(st.delay_max, 0);
}

/// Sends stale datagrams from other ports of the controller's address
/// while the simulated controller runs; returns its report and the
/// server's counters.
fn flooded_controller(
    cycles: u64,
) -> (
    photopose_rsi::controller::SimReport,
    photopose_rsi::monitor::StatsSnapshot,
) {
    let clock = RsiClock::new();
    let s = settings(|c| {
        c.realtime_priority = Some(50);
        c.session_idle_ms = 5000.0;
    });
    let (_p, reader) = latest_slot();
    let server = RsiServer::spawn(s, hand_eye(), reader, clock).unwrap();
    let to = server.local_addr();
    let mut cfg = SimConfig::new(to);
    cfg.cycles = cycles;
    cfg.timeout = u64::MAX;
    cfg.realtime_priority = Some(60);
    let sim = SimController::spawn(cfg.clone(), clock).unwrap();
    let probe = sim.probe();
    // Wait for the controller's session to open before the flood starts.
    let t = Instant::now();
    while server.stats().snapshot().cycles == 0 && t.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(1));
    }
    let done = Arc::new(AtomicBool::new(false));
    let flooder = {
        let done = done.clone();
        std::thread::spawn(move || {
            let socks: Vec<UdpSocket> = (0..4).map(|_| controller_socket()).collect();
            let msgs: Vec<String> = (0..8u64)
                .map(|k| rob(cfg.ipoc_start + k * 1_000_000, &cfg.nominal))
                .collect();
            let mut sent = 0u64;
            // About 20 datagrams per millisecond, bounded in count.
            while !done.load(Ordering::Relaxed) && !probe.is_finished() && sent < 400_000 {
                for _ in 0..20 {
                    let i = (sent % 32) as usize;
                    let _ = socks[i % 4].send_to(msgs[i % 8].as_bytes(), to);
                    sent += 1;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            sent
        })
    };
    let report = sim.join().unwrap();
    done.store(true, Ordering::Relaxed);
    let sent = flooder.join().unwrap();
    let st = server.stop();
    eprintln!(
        "flood: {sent} datagrams; controller {} cycles, {} late, {} skipped; {st:?}",
        report.cycles, report.late, report.skipped
    );
    assert!(st.foreign_port > 0);
    (report, st)
}

#[test]
fn a_flood_from_the_controller_address_leaves_the_controller_answered() {
    let (report, st) = flooded_controller(500);
    // Nothing from the flood moved the cycle: one cycle per controller
    // datagram at most.
    assert!(st.cycles <= report.cycles, "{st:?} {report:?}");
    // Tests make no strict timing assertions on a shared machine: before the
    // session rule three quarters of the cycles went unanswered; now only a
    // stalled machine makes one late. The strict bound is the ignored test.
    assert!(
        report.late * 10 <= report.cycles,
        "{} of {} late",
        report.late,
        report.cycles
    );
}

#[test]
#[ignore = "strict timing: run by hand on a quiet machine"]
fn a_flood_from_the_controller_address_strict_99_percent_in_time() {
    let (report, _) = flooded_controller(5000);
    assert!(
        report.late * 100 <= report.cycles,
        "{} of {} late",
        report.late,
        report.cycles
    );
}
