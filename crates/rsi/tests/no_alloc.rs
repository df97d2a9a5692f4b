//! The per-cycle path of the RSI thread — parse `<Rob>` (and reject hostile
//! ones), classify it against the controller session, read the slot, run
//! the correction law with its checks (including a frozen-invalid cycle),
//! check the values once more, write `<Sen>`, decide whether a drop is
//! logged, count the cycle and record its latencies, hand the cycle to the
//! recording's tap — allocates nothing: a
//! counting global allocator watches (the socket calls around it are system
//! calls).

use photopose_rsi::codec::{parse_rob, SenFormat};
use photopose_rsi::law::{pose_to_isometry, LawConfig, LawStatus};
use photopose_rsi::monitor::Stats;
use photopose_rsi::server::RateLog;
use photopose_rsi::session::Session;
use photopose_rsi::tap::{monotonic_ns, utc_ns, CycleRecord, CycleTap};
use photopose_rsi::{latest_slot, CorrectionLaw, HandEye, Measurement};
use photopose_testkit::{allocations, CountingAllocator};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn a_cycle_allocates_nothing() {
    let he = HandEye {
        tcp_from_camera: pose_to_isometry(&[0.0, 50.0, 100.0, 90.0, 0.0, 0.0]),
        base_from_plate: pose_to_isometry(&[1200.0, 0.0, -300.0, 0.0, 0.0, 180.0]),
    };
    let mut law = CorrectionLaw::new(LawConfig::default(), he);
    let (mut publisher, reader) = latest_slot();
    let fmt = SenFormat::default();
    let mut out = vec![0u8; 4096];
    let datagrams: Vec<String> = (0..50u64)
        .map(|k| {
            format!(
                "<Rob Type=\"KUKA\"><RIst X=\"445.0\" Y=\"0.0\" Z=\"790.0\" A=\"180.0\" B=\"0.0\" C=\"180.0\"/>\
                 <RSol X=\"445.{k}\" Y=\"0.0\" Z=\"790.0\" A=\"180.0\" B=\"0.0\" C=\"180.0\"/><Delay D=\"0\"/><IPOC>{}</IPOC></Rob>",
                123_645_634_563 + 4 * k
            )
        })
        .collect();
    let tcp = pose_to_isometry(&[446.0, 0.2, 790.0, 180.0, 0.01, 180.0]);
    let m = |k: u64| Measurement {
        plate_from_camera: he.camera_in_plate(&tcp),
        std_mm: 0.01,
        std_deg: 0.001,
        n_targets: 100,
        time_s: k as f64 * 0.004,
        seq: k,
    };
    let hostile: Vec<Vec<u8>> = vec![
        b"<Rob><IPOC>12<!---->99</IPOC></Rob>".to_vec(),
        b"<Rob><Delay D=\"1e300\"/><IPOC>1</IPOC></Rob>".to_vec(),
        b"<Rob><RSol X=\"NaN\" Y=\"0\" Z=\"0\" A=\"0\" B=\"0\" C=\"0\"/><IPOC>1</IPOC></Rob>"
            .to_vec(),
        b"<Rob><IPOC>1</IPOC><IPOC>2</IPOC></Rob>".to_vec(),
        vec![b'<'; 3000],
    ];
    let ctl: SocketAddr = "127.0.0.1:6000".parse().unwrap();
    let other: SocketAddr = "[::ffff:127.0.0.1]:6001".parse().unwrap();
    let mut session = Session::new(0.1);
    let mut log = RateLog::new(Duration::from_secs(10));
    let stats = Stats::new();
    let tap = CycleTap::new(8);
    let t0 = Instant::now();
    let mut bad = m(0);
    bad.plate_from_camera.translation.vector.x = f64::NAN;
    let mut run = |from: u64| {
        for (k, d) in datagrams.iter().enumerate() {
            let k = from + k as u64;
            let now = k as f64 * 0.004;
            if k.is_multiple_of(10) {
                // Every fifth publication is broken: a frozen-invalid cycle.
                if k.is_multiple_of(50) {
                    publisher.publish(&Measurement {
                        seq: k,
                        time_s: now,
                        ..bad
                    });
                } else {
                    publisher.publish(&m(k));
                }
            }
            for h in &hostile {
                assert!(parse_rob(h).is_err());
                let _ = log.due("hostile", t0 + Duration::from_millis(k));
            }
            assert!(session.is_foreign(other, now) || k == from);
            let f = parse_rob(d.as_bytes()).unwrap();
            let verdict = session.classify(ctl, f.ipoc.value() + k * 4, now);
            assert!(verdict.advances());
            session.commit(ctl, f.ipoc.value() + k * 4, now);
            let latest = reader.read();
            let o = law.cycle(now, f.rsol, latest.as_ref());
            if k.is_multiple_of(50) {
                assert_eq!(o.status, LawStatus::FrozenInvalid);
            }
            let send = if law.admissible(&o.send) {
                o.send
            } else {
                law.hold()
            };
            let n = fmt.write(&send, &f.ipoc, &mut out).unwrap();
            assert!(n > 0);
            // The cycle's bookkeeping: counters and histograms.
            stats.received.inc();
            stats.cycles.inc();
            stats.replies.inc();
            stats.latency.record_ns(20_000 + k * 37);
            stats.interarrival.record_ns(4_000_000 + k);
            // The recording's tap: both clocks read, the record handed
            // over (dropped and counted when full), the reader drains.
            tap.push(CycleRecord {
                ipoc: f.ipoc.value(),
                arrival_utc_ns: utc_ns(),
                arrival_mono_ns: monotonic_ns(),
                rist: f.rist,
                rsol: f.rsol,
                delay: f.delay,
                sent: send,
                total: o.total,
                status: o.status,
                error: o.error,
                slew_limited: o.slew_limited,
                clamped: o.clamped,
            });
            if k.is_multiple_of(3) {
                let _ = tap.pop();
            }
        }
    };
    run(0);
    let before = allocations();
    run(1000);
    assert_eq!(
        allocations() - before,
        0,
        "allocations in 50 cycles once warm"
    );
}
