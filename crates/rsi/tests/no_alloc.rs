//! The per-cycle path of the RSI thread — parse `<Rob>`, read the slot, run
//! the correction law, write `<Sen>` — allocates nothing: a counting global
//! allocator watches (the socket calls around it are system calls).

use photopose_rsi::codec::{parse_rob, SenFormat};
use photopose_rsi::law::{pose_to_isometry, LawConfig};
use photopose_rsi::{latest_slot, CorrectionLaw, HandEye, Measurement};
use photopose_testkit::{allocations, CountingAllocator};

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
    let mut run = |from: u64| {
        for (k, d) in datagrams.iter().enumerate() {
            let k = from + k as u64;
            if k % 10 == 0 {
                publisher.publish(&m(k));
            }
            let f = parse_rob(d.as_bytes()).unwrap();
            let latest = reader.read();
            let o = law.cycle(k as f64 * 0.004, f.rsol, latest.as_ref());
            let n = fmt.write(&o.send, &f.ipoc, &mut out).unwrap();
            assert!(n > 0);
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
