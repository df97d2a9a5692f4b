//! The ring under concurrent load: one producer hammering, several
//! consumers holding frames for random short times, both overflow policies.
//! Every frame is accounted for (delivered + dropped = produced), no slot is
//! lost, each consumer sees strictly increasing sequence numbers, and each
//! slot's pixels match its metadata (no two parties share a slot).

use photopose_acquire::ring::{Overflow, RecvError, Ring};
use photopose_frame::{Image, Pixels};
use std::collections::HashSet;
use std::time::Duration;

/// A small xorshift generator (seeded, so failures reproduce).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

fn stamp(image: &mut Image, seq: u64) {
    if let Pixels::Mono8(v) = image.pixels_mut() {
        v[..8].copy_from_slice(&seq.to_le_bytes());
        let last = v.len() - 1;
        v[last] = seq as u8;
    }
}

fn stamped(image: &Image) -> u64 {
    match image.pixels() {
        Pixels::Mono8(v) => {
            assert_eq!(v[v.len() - 1], v[0], "slot written while held");
            u64::from_le_bytes(v[..8].try_into().unwrap())
        }
        Pixels::Mono16(_) => unreachable!(),
    }
}

fn hammer(policy: Overflow, capacity: usize, consumers: usize, frames: u64, slow: bool) {
    let (mut producer, consumer) = Ring::build(capacity, policy, || Image::new_mono8(32, 8));
    let start = std::sync::Arc::new(std::sync::Barrier::new(consumers + 1));
    let workers: Vec<_> = (0..consumers)
        .map(|k| {
            let c = consumer.clone();
            let start = std::sync::Arc::clone(&start);
            std::thread::Builder::new()
                .name(format!("consumer-{k}"))
                .spawn(move || {
                    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ (k as u64 + 1));
                    let mut seen = Vec::new();
                    let mut held = Vec::new();
                    start.wait();
                    loop {
                        // Nothing queued: finish with the held frames first
                        // (holding them while waiting could hold every slot).
                        let next = match c.try_recv() {
                            Some(f) => Ok(f),
                            None => {
                                held.clear();
                                c.recv_timeout(Duration::from_millis(20))
                            }
                        };
                        match next {
                            Ok(f) => {
                                assert_eq!(stamped(f.image()), f.meta.seq, "pixels match metadata");
                                if let Some(&last) = seen.last() {
                                    assert!(
                                        f.meta.seq > last,
                                        "consumer {k}: {} after {last}",
                                        f.meta.seq
                                    );
                                }
                                seen.push(f.meta.seq);
                                let r = rng.next();
                                if slow && r.is_multiple_of(4) {
                                    std::thread::sleep(Duration::from_micros(r % 200));
                                }
                                // Sometimes keep a frame (or two) a while longer.
                                if r.is_multiple_of(5) && held.len() < 2 {
                                    held.push(f);
                                } else if r.is_multiple_of(3) {
                                    held.clear();
                                }
                            }
                            Err(RecvError::Timeout) => held.clear(),
                            Err(RecvError::Disconnected) => break,
                        }
                    }
                    seen
                })
                .unwrap()
        })
        .collect();

    let mut rng = Rng(42);
    start.wait();
    for seq in 0..frames {
        let slot = producer.slot_mut();
        slot.meta.seq = seq;
        stamp(slot.image_mut(), seq);
        producer.publish();
        // A camera's pace, roughly: let the consumers interleave.
        let until = std::time::Instant::now() + Duration::from_nanos(rng.next() % 4_000);
        while std::time::Instant::now() < until {
            std::hint::spin_loop();
        }
        if seq % 32 == 0 {
            std::thread::sleep(Duration::from_micros(100));
        } else {
            std::thread::yield_now();
        }
    }
    drop(producer);

    let mut all = HashSet::new();
    let mut delivered = 0u64;
    for w in workers {
        let seen = w.join().unwrap();
        delivered += seen.len() as u64;
        for s in seen {
            assert!(all.insert(s), "frame {s} delivered twice");
        }
    }
    let st = consumer.counters().snapshot();
    eprintln!("{policy:?} capacity {capacity} consumers {consumers} slow {slow}: {st:?}");
    assert_eq!(st.frames_in, frames);
    assert_eq!(st.delivered, delivered);
    assert_eq!(
        st.delivered + st.dropped,
        frames,
        "every frame accounted for"
    );
    assert_eq!(consumer.queued(), 0);
    assert_eq!(consumer.free_slots(), capacity, "no slot lost");
    assert!(
        st.delivered >= frames / 1000,
        "consumers hardly ran: the test did not exercise the hand-over"
    );
    if slow {
        assert!(st.dropped > 0, "slow consumers must cause drops");
    }
}

/// The configurations run one after the other: on a small machine,
/// parallel tests with spinning producers would starve the consumers.
#[test]
fn hammer_both_policies() {
    hammer(Overflow::DropNewest, 4, 3, 40_000, false);
    hammer(Overflow::DropOldest, 4, 3, 40_000, false);
    hammer(Overflow::DropNewest, 1, 2, 20_000, true);
    hammer(Overflow::DropOldest, 3, 2, 20_000, true);
    hammer(Overflow::DropOldest, 2, 4, 30_000, false);
}

#[test]
fn drop_oldest_delivers_the_newest_when_consumers_idle() {
    // Consumers start only after the burst: the ring keeps the last frames.
    let (mut p, c) = Ring::build(3, Overflow::DropOldest, || Image::new_mono8(8, 1));
    for seq in 0..1000 {
        p.slot_mut().meta.seq = seq;
        p.publish();
    }
    let seqs: Vec<u64> = std::iter::from_fn(|| c.try_recv().map(|f| f.meta.seq)).collect();
    assert_eq!(seqs, vec![997, 998, 999]);
}
