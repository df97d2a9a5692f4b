//! The latest-measurement slot: the vision side publishes each new camera
//! measurement, the RSI thread reads the newest one without ever waiting on
//! a lock. A sequence lock over atomics (no `unsafe`): the single publisher
//! makes the sequence odd, stores the fields, makes it even again; a reader
//! takes a copy and keeps it only if the sequence was even and unchanged
//! around the copy. A reader that keeps losing the race (it cannot, with
//! one publisher at camera rate, beyond a retry or two) returns `None`
//! for this cycle rather than spin: the law then uses its last copy.

use crate::law::Measurement;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::sync::atomic::{fence, AtomicU64, Ordering};
use std::sync::Arc;

const FIELDS: usize = 12;

/// Attempts of a read before it gives up for this cycle.
pub const READ_ATTEMPTS: usize = 64;

#[derive(Debug)]
struct Inner {
    seq: AtomicU64,
    fields: [AtomicU64; FIELDS],
}

/// The publishing end (one per slot: not `Clone`).
#[derive(Debug)]
pub struct SlotPublisher {
    inner: Arc<Inner>,
}

/// A reading end (any number, never blocks).
#[derive(Debug, Clone)]
pub struct SlotReader {
    inner: Arc<Inner>,
}

/// A new, empty slot.
pub fn latest_slot() -> (SlotPublisher, SlotReader) {
    let inner = Arc::new(Inner {
        seq: AtomicU64::new(0),
        fields: std::array::from_fn(|_| AtomicU64::new(0)),
    });
    (
        SlotPublisher {
            inner: inner.clone(),
        },
        SlotReader { inner },
    )
}

fn encode(m: &Measurement) -> [u64; FIELDS] {
    let t = m.plate_from_camera.translation.vector;
    let q = m.plate_from_camera.rotation.quaternion().coords; // i j k w
    [
        t.x.to_bits(),
        t.y.to_bits(),
        t.z.to_bits(),
        q.x.to_bits(),
        q.y.to_bits(),
        q.z.to_bits(),
        q.w.to_bits(),
        m.std_mm.to_bits(),
        m.std_deg.to_bits(),
        u64::from(m.n_targets),
        m.time_s.to_bits(),
        m.seq,
    ]
}

fn decode(f: &[u64; FIELDS]) -> Measurement {
    let v = |i: usize| f64::from_bits(f[i]);
    Measurement {
        plate_from_camera: Isometry3::from_parts(
            Translation3::new(v(0), v(1), v(2)),
            UnitQuaternion::new_unchecked(Quaternion::new(v(6), v(3), v(4), v(5))),
        ),
        std_mm: v(7),
        std_deg: v(8),
        n_targets: f[9] as u32,
        time_s: v(10),
        seq: f[11],
    }
}

impl SlotPublisher {
    /// Publishes `m` as the latest measurement (wait-free).
    pub fn publish(&mut self, m: &Measurement) {
        let s = self.inner.seq.load(Ordering::Relaxed);
        self.inner.seq.store(s.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (a, v) in self.inner.fields.iter().zip(encode(m)) {
            a.store(v, Ordering::Relaxed);
        }
        self.inner.seq.store(s.wrapping_add(2), Ordering::Release);
    }

    /// A reader of this slot.
    pub fn reader(&self) -> SlotReader {
        SlotReader {
            inner: self.inner.clone(),
        }
    }
}

impl SlotReader {
    /// The latest measurement: `None` if nothing was published yet or if
    /// the publisher kept overwriting it during [`READ_ATTEMPTS`] attempts.
    pub fn read(&self) -> Option<Measurement> {
        for _ in 0..READ_ATTEMPTS {
            let s1 = self.inner.seq.load(Ordering::Acquire);
            if s1 == 0 {
                return None;
            }
            if s1 % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let mut f = [0u64; FIELDS];
            for (v, a) in f.iter_mut().zip(&self.inner.fields) {
                *v = a.load(Ordering::Relaxed);
            }
            fence(Ordering::Acquire);
            let s2 = self.inner.seq.load(Ordering::Relaxed);
            if s1 == s2 {
                return Some(decode(&f));
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::pose_to_isometry;

    fn m(k: u64) -> Measurement {
        // Every field derived from k, so a torn read is detectable.
        let x = k as f64;
        Measurement {
            plate_from_camera: pose_to_isometry(&[x, 2.0 * x, 3.0 * x, (k % 360) as f64, 0.0, 0.0]),
            std_mm: x * 1e-3,
            std_deg: x * 1e-4,
            n_targets: (k % 1000) as u32,
            time_s: x * 0.04,
            seq: k,
        }
    }

    fn consistent(r: &Measurement) -> bool {
        let k = r.seq;
        let e = m(k);
        let t = r.plate_from_camera.translation.vector;
        t == e.plate_from_camera.translation.vector
            && r.plate_from_camera.rotation == e.plate_from_camera.rotation
            && r.std_mm == e.std_mm
            && r.std_deg == e.std_deg
            && r.n_targets == e.n_targets
            && r.time_s == e.time_s
    }

    #[test]
    fn empty_then_latest() {
        let (mut p, r) = latest_slot();
        assert_eq!(r.read(), None);
        p.publish(&m(1));
        p.publish(&m(2));
        assert_eq!(r.read(), Some(m(2)));
        assert_eq!(p.reader().read(), Some(m(2)));
    }

    #[test]
    fn never_torn_under_contention() {
        let (mut p, r) = latest_slot();
        let n = 200_000u64;
        let readers: Vec<_> = (0..2)
            .map(|_| {
                let r = r.clone();
                std::thread::spawn(move || {
                    let (mut ok, mut last) = (0u64, 0u64);
                    loop {
                        if let Some(v) = r.read() {
                            assert!(consistent(&v), "torn read {v:?}");
                            assert!(v.seq >= last, "went back {} < {last}", v.seq);
                            last = v.seq;
                            ok += 1;
                            if v.seq == n {
                                return ok;
                            }
                        }
                    }
                })
            })
            .collect();
        for k in 1..=n {
            p.publish(&m(k));
        }
        for h in readers {
            assert!(h.join().unwrap() > 0);
        }
    }
}
