//! Loopback fuzz of the RSI server: more than 50,000 hostile datagrams
//! (random bytes, truncated and 64 KiB documents, deep nesting, entities,
//! NaN/inf/huge numbers, IPOC overflow, duplicated elements, wrong roots,
//! old and repeated IPOCs, newer IPOCs from other ports) from unlisted
//! addresses, from other ports of the controller's address and from the
//! controller's own port, interleaved with the cycles of a controller played
//! in lock step by the test. Every cycle must be answered with its IPOC,
//! finite values inside the clamp and the slew limit; repeats are answered
//! with the very same reply; nothing else is answered. Seeded, deterministic
//! content; bounded in count and time.

mod common;

use common::{hand_eye, nominal_tcp, settings};
use photopose_rsi::codec::Pose6;
use photopose_rsi::law::{pose_to_isometry, CorrectionMode};
use photopose_rsi::server::{RsiClock, RsiServer};
use photopose_rsi::{latest_slot, Measurement};
use std::collections::HashMap;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

/// SplitMix64: a tiny seeded generator, enough for test content.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn pose_el(name: &str, p: &[String; 6]) -> String {
    format!(
        "<{name} X=\"{}\" Y=\"{}\" Z=\"{}\" A=\"{}\" B=\"{}\" C=\"{}\"/>",
        p[0], p[1], p[2], p[3], p[4], p[5]
    )
}

fn rob(ipoc: &str, rsol: &Pose6) -> String {
    let p = rsol.map(|v| format!("{v:.4}"));
    format!(
        "<Rob Type=\"KUKA\">{}{}<Delay D=\"0\"/><IPOC>{ipoc}</IPOC></Rob>",
        pose_el("RIst", &p),
        pose_el("RSol", &p)
    )
}

/// Where a hostile datagram comes from.
#[derive(Clone, Copy, PartialEq)]
enum From {
    Unlisted,
    OtherPort,
    /// The controller's own port: only datagrams that must not advance.
    Session,
}

/// One hostile datagram. `last` is the last IPOC the controller sent.
fn hostile(rng: &mut Rng, from: From, last: u64, nominal: &Pose6) -> Vec<u8> {
    let old = last.saturating_sub(4 * (1 + rng.below(50)));
    // An IPOC a session datagram may carry: the last one again or older
    // (a newer one from the controller's own port is a cycle by definition;
    // some "broken" documents below are valid, e.g. a value of 1e-400).
    let safe_ipoc = if rng.below(2) == 0 { last } else { old };
    let newer = if from == From::Session {
        safe_ipoc
    } else {
        last + 4 * (1 + rng.below(1000))
    };
    let any_ipoc = if from == From::Session {
        safe_ipoc
    } else if rng.below(4) == 0 {
        u64::MAX
    } else {
        newer
    };
    let weird = [
        "NaN", "inf", "-inf", "1e300", "-1.7e308", "1e-400", "0x10", "", " ", "1,5", "+-1",
    ];
    match rng.below(12) {
        0 => (0..rng.below(1500)).map(|_| rng.next() as u8).collect(),
        1 => {
            let d = rob(&newer.to_string(), nominal).into_bytes();
            let cut = rng.below(d.len() as u64 - 1) as usize;
            d[..cut].to_vec()
        }
        2 => {
            // About 64 KiB of well-formed XML.
            let mut d = String::from("<Rob Type=\"KUKA\">");
            let target = 60_000 + rng.below(5_000) as usize;
            while d.len() < target {
                d.push_str("<Tech C11=\"0.5\" C12=\"-1.25\" C13=\"3\"/><DiL>7</DiL>");
            }
            d.push_str(&format!("<IPOC>{any_ipoc}</IPOC></Rob>"));
            d.into_bytes()
        }
        3 => {
            let depth = 100 + rng.below(3000) as usize;
            let mut d = String::from("<Rob>");
            d.push_str(&"<a>".repeat(depth));
            d.push_str(&format!("<IPOC>{any_ipoc}</IPOC>"));
            if rng.below(2) == 0 {
                d.push_str(&"</a>".repeat(depth));
                d.push_str("</Rob>");
            }
            d.into_bytes()
        }
        4 => {
            let entity = ["&amp;", "&#49;", "&lt;", "&#x31;", "&bogus;"][rng.below(5) as usize];
            let mut p = nominal.map(|v| format!("{v:.4}"));
            p[rng.below(6) as usize] = format!("{entity}1");
            let ipoc = if rng.below(2) == 0 {
                format!("{entity}{newer}")
            } else {
                newer.to_string()
            };
            format!("<Rob>{}<IPOC>{ipoc}</IPOC></Rob>", pose_el("RSol", &p)).into_bytes()
        }
        5 => {
            let mut p = nominal.map(|v| format!("{v:.4}"));
            p[rng.below(6) as usize] = weird[rng.below(weird.len() as u64) as usize].to_string();
            let el = if rng.below(2) == 0 { "RSol" } else { "RIst" };
            format!("<Rob>{}<IPOC>{newer}</IPOC></Rob>", pose_el(el, &p)).into_bytes()
        }
        6 => {
            let d = weird[rng.below(weird.len() as u64) as usize];
            format!("<Rob><Delay D=\"{d}\"/><IPOC>{newer}</IPOC></Rob>").into_bytes()
        }
        7 => {
            let ipoc = [
                "18446744073709551616",
                "99999999999999999999999999",
                "-4",
                "12 34",
                "4.0",
                "1e5",
            ][rng.below(6) as usize];
            format!("<Rob><IPOC>{ipoc}</IPOC></Rob>").into_bytes()
        }
        8 => {
            let p = nominal.map(|v| format!("{v:.4}"));
            match rng.below(4) {
                0 => format!(
                    "<Rob>{}{}<IPOC>{newer}</IPOC></Rob>",
                    pose_el("RSol", &p),
                    pose_el("RSol", &p)
                ),
                1 => format!("<Rob><IPOC>{newer}</IPOC><IPOC>{newer}</IPOC></Rob>"),
                2 => format!("<Rob><IPOC>{last}<!-- -->{newer}</IPOC></Rob>"),
                _ => format!(
                    "<Rob><RSol X=\"1\" X=\"2\" Y=\"0\" Z=\"0\" A=\"0\" B=\"0\" C=\"0\"/><IPOC>{newer}</IPOC></Rob>"
                ),
            }
            .into_bytes()
        }
        9 => match rng.below(3) {
            0 => format!("<Sen Type=\"ImFree\"><IPOC>{newer}</IPOC></Sen>").into_bytes(),
            1 => format!("<?xml version=\"1.0\"?><Rob Type=\"Evil\"><IPOC>{any_ipoc}</IPOC></Rob>")
                .into_bytes(),
            _ => format!("<Rob><IPOC>{newer}</IPOC></Rob><Rob>").into_bytes(),
        },
        // Valid documents: newer IPOCs from elsewhere, old or repeated ones
        // from the controller's port; with a wild but valid RSol.
        10 => {
            let mut p = *nominal;
            p[rng.below(3) as usize] += (rng.unit() - 0.5) * 1e4;
            rob(&any_ipoc.to_string(), &p).into_bytes()
        }
        _ => rob(&safe_ipoc.to_string(), nominal).into_bytes(),
    }
}

struct Rig {
    server: RsiServer,
    to: SocketAddr,
    ctl: UdpSocket,
    others: Vec<UdpSocket>,
    unlisted: Vec<UdpSocket>,
    sent: u64,
}

impl Rig {
    fn send(&mut self, from: From, k: usize, d: &[u8]) {
        let s = match from {
            From::Unlisted => &self.unlisted[k % self.unlisted.len()],
            From::OtherPort => &self.others[k % self.others.len()],
            From::Session => &self.ctl,
        };
        s.send_to(d, self.to).unwrap();
        self.sent += 1;
    }

    /// Waits until the server has read everything sent (bounded).
    fn settle(&self) {
        let t = Instant::now();
        while self.server.stats().received.get() < self.sent {
            assert!(
                t.elapsed() < Duration::from_secs(10),
                "server read {} of {}",
                self.server.stats().received.get(),
                self.sent
            );
            std::thread::sleep(Duration::from_micros(50));
        }
    }
}

fn korr(reply: &str) -> Pose6 {
    let f = photopose_rsi::codec::parse_sen(reply.as_bytes(), "ImFree", "RKorr")
        .unwrap_or_else(|e| panic!("{e}: {reply}"));
    assert!(f.type_matches, "{reply}");
    f.correction.unwrap_or_else(|| panic!("{reply}"))
}

/// One run of `cycles` controller cycles with about `per_cycle` hostile
/// datagrams each; returns the number of hostile datagrams sent.
fn run(mode: CorrectionMode, seed: u64, cycles: u64, per_cycle: u64) -> u64 {
    let he = hand_eye();
    let nominal = nominal_tcp(&he);
    let clock = RsiClock::new();
    let s = settings(|c| {
        c.mode = mode;
        c.max_age_ms = 60_000.0;
        c.session_idle_ms = 60_000.0;
        c.clamp_mm = 1.0;
        c.clamp_deg = 0.5;
    });
    let law = s.law;
    let (mut publisher, reader) = latest_slot();
    let server = RsiServer::spawn(s, he, reader, clock).unwrap();
    let to = server.local_addr();
    let bind = |ip: &str| {
        let s = UdpSocket::bind(format!("{ip}:0")).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        s
    };
    let mut rig = Rig {
        server,
        to,
        ctl: bind("127.0.0.1"),
        others: (0..3).map(|_| bind("127.0.0.1")).collect(),
        unlisted: vec![bind("127.0.0.2"), bind("127.0.0.3")],
        sent: 0,
    };
    let mut rng = Rng(seed);
    let step = [
        law.max_step_mm,
        law.max_step_mm,
        law.max_step_mm,
        law.max_step_deg,
        law.max_step_deg,
        law.max_step_deg,
    ];
    let clamp = [
        law.clamp_mm,
        law.clamp_mm,
        law.clamp_mm,
        law.clamp_deg,
        law.clamp_deg,
        law.clamp_deg,
    ];
    let tol = 1e-9;
    let mut replies: HashMap<u64, String> = HashMap::new();
    let mut integrated = [0.0; 6];
    let mut prev_total = [0.0; 6];
    let mut hostile_sent = 0u64;
    let mut buf = vec![0u8; 70_000];
    let ipoc0 = 123_645_634_563u64;
    for k in 0..cycles {
        let ipoc = ipoc0 + 4 * k;
        let last = if k == 0 { ipoc0 } else { ipoc - 4 };
        if k % 40 == 0 {
            // A new measurement somewhere beyond the clamp, now.
            let d: Pose6 = std::array::from_fn(|i| {
                let r = if i < 3 { 3.0 } else { 2.0 };
                (rng.unit() - 0.5) * 2.0 * r
            });
            let tcp = pose_to_isometry(&std::array::from_fn(|i| nominal[i] + d[i]));
            publisher.publish(&Measurement {
                plate_from_camera: he.camera_in_plate(&tcp),
                std_mm: 0.01,
                std_deg: 0.001,
                n_targets: 100,
                time_s: clock.now_s(),
                seq: k + 1,
            });
        }
        // The session opens with the first valid cycle: before it, the
        // controller's port sends nothing that could open it.
        let n = if k == 0 { 0 } else { per_cycle };
        // Part 1: most of the hostile datagrams, read by the server before
        // the cycle (at most 16 KiB queued at once, so no socket buffer
        // fills and the kernel drops nothing).
        let before = n - n.min(20);
        let mut queued = 0;
        for i in 0..before {
            let from = match rng.below(10) {
                0..=3 => From::Unlisted,
                4..=7 => From::OtherPort,
                _ => From::Session,
            };
            let d = hostile(&mut rng, from, last, &nominal);
            rig.send(from, i as usize, &d);
            queued += d.len();
            if queued > 16_384 {
                rig.settle();
                queued = 0;
            }
        }
        hostile_sent += before;
        rig.settle();
        // Part 2: small hostile datagrams queued with the cycle, before and
        // after it (the server drains them together).
        let small = |rig: &mut Rig, rng: &mut Rng, count: u64| {
            let mut i = 0;
            while i < count {
                let from = match rng.below(3) {
                    0 => From::Unlisted,
                    1 => From::OtherPort,
                    _ => From::Session,
                };
                let d = hostile(rng, from, last, &nominal);
                if d.len() <= 2048 {
                    rig.send(from, i as usize, &d);
                    i += 1;
                }
            }
        };
        let around = n.min(20);
        small(&mut rig, &mut rng, around / 2);
        rig.send(
            From::Session,
            0,
            rob(&ipoc.to_string(), &nominal).as_bytes(),
        );
        small(&mut rig, &mut rng, around - around / 2);
        hostile_sent += around;
        // The cycle's reply; earlier ones may only be repeats.
        let reply = loop {
            let (m, _) = rig
                .ctl
                .recv_from(&mut buf)
                .unwrap_or_else(|e| panic!("cycle {k} (IPOC {ipoc}) not answered: {e}"));
            let r = std::str::from_utf8(&buf[..m]).unwrap().to_string();
            let echoed = photopose_rsi::codec::parse_sen(r.as_bytes(), "ImFree", "RKorr")
                .unwrap_or_else(|e| panic!("{e}: {r}"))
                .ipoc
                .value();
            if echoed == ipoc {
                break r;
            }
            assert_eq!(
                replies.get(&echoed),
                Some(&r),
                "cycle {k}: a reply for IPOC {echoed} that is not a repeat"
            );
        };
        let v = korr(&reply);
        for i in 0..6 {
            assert!(v[i].is_finite(), "{reply}");
            let total = match mode {
                CorrectionMode::Absolute => v[i],
                CorrectionMode::Relative => {
                    assert!(v[i].abs() <= step[i] + tol, "cycle {k}: increment {reply}");
                    integrated[i] += v[i];
                    integrated[i]
                }
            };
            assert!(
                total.abs() <= clamp[i] + tol,
                "cycle {k}: total {total} {reply}"
            );
            assert!(
                (total - prev_total[i]).abs() <= step[i] + tol,
                "cycle {k}: change {} of component {i}",
                total - prev_total[i]
            );
            prev_total[i] = total;
        }
        replies.insert(ipoc, reply);
        replies.remove(&(ipoc.saturating_sub(8)));
    }
    rig.settle();
    // Late repeats may still arrive for the controller; nobody else got
    // anything.
    for s in rig.others.iter().chain(&rig.unlisted) {
        s.set_nonblocking(true).unwrap();
        assert!(
            s.recv_from(&mut buf).is_err(),
            "a hostile sender was answered"
        );
    }
    let st = rig.server.stop();
    eprintln!("{mode:?}: {hostile_sent} hostile datagrams, {st:?}");
    assert_eq!(st.cycles, cycles, "{st:?}");
    assert_eq!(st.received, rig.sent);
    assert!(
        st.unlisted > 0
            && st.foreign_port > 0
            && st.garbage > 0
            && st.stale_ipoc > 0
            && st.repeated > 0
    );
    // The clamp and the slew limit were reached: the limits were exercised.
    assert!(st.slew_hits > 0 && st.clamp_hits > 0, "{st:?}");
    hostile_sent
}

#[test]
fn fifty_thousand_hostile_datagrams_never_move_the_correction_beyond_its_limits() {
    let a = run(CorrectionMode::Absolute, 0x5EED_0001, 501, 52);
    let r = run(CorrectionMode::Relative, 0x5EED_0002, 501, 52);
    assert!(a + r >= 50_000, "{}", a + r);
}
