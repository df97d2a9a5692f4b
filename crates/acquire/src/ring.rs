//! The frame ring: a pool of preallocated frame slots and a bounded
//! single-producer / multi-consumer hand-over between a grabber thread and
//! detection workers.
//!
//! # Design
//!
//! A slot ([`Slot`]: an [`Image`] and its [`FrameMeta`]) is boxed once, when
//! the ring is built, and from then on only the box moves: from the free
//! queue to the producer, from the producer through the filled queue to a
//! consumer, and back to the free queue when the consumer's [`FrameHandle`]
//! is dropped (RAII). Moving a box moves a pointer; nothing is allocated or
//! copied on the frame path.
//!
//! - free slots: a [`crossbeam_queue::ArrayQueue`] (lock-free, bounded);
//! - filled slots: a bounded [`crossbeam_channel`] in array flavour
//!   (lock-free send and receive; consumers may block with a timeout, which
//!   parks them; the producer only ever uses `try_send`/`try_recv`).
//!
//! The producer always holds one slot "in hand" that the source fills; a
//! ring of capacity `n` therefore owns `n + 1` slots, and the filled channel
//! has room for all of them, so the producer's `try_send` never finds it
//! full.
//!
//! # Overflow
//!
//! When [`Producer::publish`] finds no free slot (all are queued or held by
//! consumers) it never waits under the dropping policies: with
//! [`Overflow::DropNewest`] the frame just filled is discarded (the producer
//! keeps its slot and overwrites it next time); with [`Overflow::DropOldest`]
//! the producer takes the oldest queued frame back, discards it, and queues
//! the new one (if consumers hold every slot, nothing is queued and the
//! newest is dropped instead). [`Overflow::Block`] is for sources that can
//! wait (replays, renderers): the producer waits for a consumer to free a
//! slot and never drops while a consumer exists. Every frame is counted
//! once: `frames_in == delivered + dropped + queued`.
//!
//! # Admission order
//!
//! Each queued frame gets the next admission number in [`Slot::order`]
//! (0, 1, 2, … without gaps over the frames queued); a frame dropped by
//! `drop-oldest` after it was queued is reported by
//! [`Published::QueuedDroppedOldest`] with its number, so a stage that
//! restores order downstream knows not to wait for it.
//!
//! Consumers each see strictly increasing sequence numbers, since the filled
//! queue is FIFO and the producer publishes in order.

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError};
use crossbeam_queue::ArrayQueue;
use photopose_frame::{FrameMeta, Image};
use photopose_telemetry::{Collect, Scrape};
use std::ops::{Deref, DerefMut};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// One frame buffer: the pixels and what the source knows about them.
///
/// A source either writes the frame into the slot's own buffer
/// ([`Slot::image_mut`], allocated when the ring is built) or, when it
/// already holds the frame whole and unchanging (a replayed recording),
/// lends it ([`Slot::share`]): the slot then holds a counted reference and
/// nothing is copied. Readers see either through [`Slot::image`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Slot {
    /// The slot's own pixels (allocated when the ring is built).
    image: Image,
    /// A frame lent by the source instead (shown while set).
    shared: Option<Arc<Image>>,
    /// Sequence number, camera timestamp, host time.
    pub meta: FrameMeta,
    /// Admission number, set by [`Producer::publish`] when the frame is
    /// queued (see the module documentation).
    pub order: u64,
    /// Monotonic instant the source handed the frame over (set by the
    /// grabber just before publishing; the start of latency measurements).
    pub received: Instant,
}

impl Slot {
    /// A slot holding `image`, with zeroed metadata.
    pub fn new(image: Image) -> Self {
        Slot {
            image,
            shared: None,
            meta: FrameMeta::default(),
            order: 0,
            received: Instant::now(),
        }
    }

    /// The frame: the one lent by [`Slot::share`] if any, else the slot's
    /// own pixels.
    pub fn image(&self) -> &Image {
        self.shared.as_deref().unwrap_or(&self.image)
    }

    /// The slot's own pixels, to be written (ends any lent frame; a source
    /// may also replace the image, e.g. to change its size).
    pub fn image_mut(&mut self) -> &mut Image {
        self.shared = None;
        &mut self.image
    }

    /// Lends `frame` to the slot instead of copying it into its own pixels
    /// (a counted reference: no allocation, no copy). It is dropped when a
    /// source next writes the slot or lends another frame.
    pub fn share(&mut self, frame: Arc<Image>) {
        self.shared = Some(frame);
    }

    /// Whether the frame is lent ([`Slot::share`]) rather than the slot's own.
    pub fn is_shared(&self) -> bool {
        self.shared.is_some()
    }
}

/// What the producer does when no slot is free.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overflow {
    /// Discard the frame just filled.
    DropNewest,
    /// Discard the oldest frame still queued and queue the new one.
    DropOldest,
    /// Wait for a free slot (for sources that can wait: replays, renderers);
    /// drops only when no consumer is left.
    Block,
}

impl Overflow {
    /// The policy's name as configured (`drop-newest`, `drop-oldest`, `block`).
    pub fn name(&self) -> &'static str {
        match self {
            Overflow::DropNewest => "drop-newest",
            Overflow::DropOldest => "drop-oldest",
            Overflow::Block => "block",
        }
    }
}

/// Counters of a ring (all monotonic, relaxed: read them for metrics).
#[derive(Debug, Default)]
pub struct RingCounters {
    frames_in: AtomicU64,
    dropped: AtomicU64,
    delivered: AtomicU64,
}

/// A snapshot of [`RingCounters`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RingStats {
    /// Frames published by the producer.
    pub frames_in: u64,
    /// Frames discarded by the overflow policy.
    pub dropped: u64,
    /// Frames handed to a consumer.
    pub delivered: u64,
}

impl RingStats {
    /// Frames published but neither delivered nor dropped (still queued).
    pub fn queued(&self) -> u64 {
        self.frames_in - self.dropped - self.delivered
    }
}

impl RingCounters {
    /// A consistent-enough snapshot (each counter read once, relaxed).
    ///
    /// Read `delivered` and `dropped` before `frames_in`, so that a
    /// concurrent snapshot never shows more frames out than in.
    pub fn snapshot(&self) -> RingStats {
        let delivered = self.delivered.load(Ordering::Acquire);
        let dropped = self.dropped.load(Ordering::Acquire);
        let frames_in = self.frames_in.load(Ordering::Acquire);
        RingStats {
            frames_in,
            dropped,
            delivered,
        }
    }
}

impl Collect for RingCounters {
    fn collect(&self, out: &mut Scrape<'_>) -> std::fmt::Result {
        let st = self.snapshot();
        out.counter(
            "photopose_ring_frames_in_total",
            "Frames published into the ring by the grabber.",
            st.frames_in,
        )?;
        out.counter(
            "photopose_ring_frames_dropped_total",
            "Frames the ring discarded by its overflow policy.",
            st.dropped,
        )?;
        out.counter(
            "photopose_ring_frames_delivered_total",
            "Frames the ring handed to a detection worker.",
            st.delivered,
        )?;
        out.gauge(
            "photopose_ring_frames_queued",
            "Frames waiting in the ring for a detection worker.",
            st.queued() as f64,
        )
    }
}

struct Shared {
    free: ArrayQueue<Box<Slot>>,
    counters: Arc<RingCounters>,
    slots: usize,
}

/// Builds a ring of `capacity` frames (plus the producer's slot in hand),
/// each slot's image made by `make_image` now, and never again.
pub struct Ring;

impl Ring {
    /// A ring of `capacity` (≥ 1) slots, overflow handled by `policy`.
    ///
    /// Allocates `capacity + 1` images with `make_image`; returns the single
    /// producer and a consumer (clone it for each worker).
    ///
    /// # Panics
    /// If `capacity` is 0.
    pub fn build(
        capacity: usize,
        policy: Overflow,
        mut make_image: impl FnMut() -> Image,
    ) -> (Producer, Consumer) {
        assert!(capacity > 0, "a frame ring needs at least one slot");
        let slots = capacity + 1;
        let free = ArrayQueue::new(slots);
        for _ in 0..capacity {
            let pushed = free.push(Box::new(Slot::new(make_image())));
            debug_assert!(pushed.is_ok());
        }
        let shared = Arc::new(Shared {
            free,
            counters: Arc::default(),
            slots,
        });
        let (tx, rx) = crossbeam_channel::bounded(slots);
        let producer = Producer {
            next_order: 0,
            hand: Box::new(Slot::new(make_image())),
            tx,
            steal: rx.clone(),
            policy,
            shared: Arc::clone(&shared),
        };
        (producer, Consumer { rx, shared })
    }
}

/// The single producer (the grabber): fills its slot in hand, then
/// publishes it. Never blocks unless the policy is [`Overflow::Block`].
pub struct Producer {
    next_order: u64,
    hand: Box<Slot>,
    tx: Sender<Box<Slot>>,
    steal: Receiver<Box<Slot>>,
    policy: Overflow,
    shared: Arc<Shared>,
}

/// What [`Producer::publish`] did with the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Published {
    /// Queued for the consumers.
    Queued,
    /// Queued, and the oldest queued frame was dropped to make room.
    QueuedDroppedOldest {
        /// The dropped frame's admission number ([`Slot::order`]).
        dropped_order: u64,
    },
    /// No room: this frame was dropped.
    DroppedNewest,
}

impl Producer {
    /// The slot to fill next.
    pub fn slot_mut(&mut self) -> &mut Slot {
        &mut self.hand
    }

    /// The slot in hand, read-only.
    pub fn slot(&self) -> &Slot {
        &self.hand
    }

    /// Hands the filled slot to the consumers and takes a fresh one, or
    /// applies the overflow policy when none is free. Never allocates; never
    /// blocks unless the policy is [`Overflow::Block`].
    pub fn publish(&mut self) -> Published {
        let c = &self.shared.counters;
        c.frames_in.fetch_add(1, Ordering::AcqRel);
        let next = match self.shared.free.pop() {
            Some(slot) => Some((slot, Published::Queued)),
            None => match self.policy {
                Overflow::DropNewest => None,
                Overflow::DropOldest => self
                    .steal
                    .try_recv()
                    .ok()
                    .map(|old| {
                        c.dropped.fetch_add(1, Ordering::AcqRel);
                        let dropped_order = old.order;
                        (old, Published::QueuedDroppedOldest { dropped_order })
                    })
                    // A consumer may have freed a slot meanwhile.
                    .or_else(|| self.shared.free.pop().map(|s| (s, Published::Queued))),
                Overflow::Block => self.wait_for_free().map(|s| (s, Published::Queued)),
            },
        };
        match next {
            Some((slot, outcome)) => {
                self.hand.order = self.next_order;
                let full = std::mem::replace(&mut self.hand, slot);
                match self.tx.try_send(full) {
                    Ok(()) => {
                        self.next_order += 1;
                        outcome
                    }
                    // Cannot happen: the channel holds every slot there is.
                    // Keep the frame's slot rather than lose it.
                    Err(TrySendError::Full(s)) | Err(TrySendError::Disconnected(s)) => {
                        let spare = std::mem::replace(&mut self.hand, s);
                        let _ = self.shared.free.push(spare);
                        c.dropped.fetch_add(1, Ordering::AcqRel);
                        Published::DroppedNewest
                    }
                }
            }
            None => {
                c.dropped.fetch_add(1, Ordering::AcqRel);
                Published::DroppedNewest
            }
        }
    }

    /// Waits for a consumer to free a slot: spins briefly, then yields,
    /// then sleeps in short steps. `None` once no consumer or frame handle
    /// is left (nobody could ever free one).
    fn wait_for_free(&self) -> Option<Box<Slot>> {
        let mut round = 0u32;
        loop {
            if let Some(s) = self.shared.free.pop() {
                return Some(s);
            }
            // The producer's own reference is the only one left.
            if Arc::strong_count(&self.shared) == 1 {
                return None;
            }
            match round {
                0..=63 => std::hint::spin_loop(),
                64..=127 => std::thread::yield_now(),
                _ => std::thread::sleep(Duration::from_micros(50)),
            }
            round = round.saturating_add(1);
        }
    }

    /// The ring's counters.
    pub fn counters(&self) -> &RingCounters {
        &self.shared.counters
    }

    /// The ring's counters, to keep (metrics) without keeping the slots.
    pub fn shared_counters(&self) -> Arc<RingCounters> {
        Arc::clone(&self.shared.counters)
    }

    /// The overflow policy.
    pub fn policy(&self) -> Overflow {
        self.policy
    }
}

impl std::fmt::Debug for Producer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Producer")
            .field("policy", &self.policy)
            .field("slots", &self.shared.slots)
            .finish()
    }
}

/// A consumer (a detection worker); clone one per worker.
#[derive(Clone)]
pub struct Consumer {
    rx: Receiver<Box<Slot>>,
    shared: Arc<Shared>,
}

/// Why [`Consumer::recv_timeout`] returned no frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecvError {
    /// Nothing arrived within the timeout.
    Timeout,
    /// The producer is gone and nothing is queued.
    Disconnected,
}

impl Consumer {
    fn handle(&self, slot: Box<Slot>) -> FrameHandle {
        self.shared
            .counters
            .delivered
            .fetch_add(1, Ordering::AcqRel);
        FrameHandle {
            slot: Some(slot),
            shared: Arc::clone(&self.shared),
        }
    }

    /// The oldest queued frame, if any, without waiting.
    pub fn try_recv(&self) -> Option<FrameHandle> {
        self.rx.try_recv().ok().map(|s| self.handle(s))
    }

    /// The oldest queued frame, waiting at most `timeout`.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<FrameHandle, RecvError> {
        match self.rx.recv_timeout(timeout) {
            Ok(s) => Ok(self.handle(s)),
            Err(RecvTimeoutError::Timeout) => Err(RecvError::Timeout),
            Err(RecvTimeoutError::Disconnected) => Err(RecvError::Disconnected),
        }
    }

    /// The ring's counters.
    pub fn counters(&self) -> &RingCounters {
        &self.shared.counters
    }

    /// The ring's counters, to keep (metrics) without keeping the slots.
    pub fn shared_counters(&self) -> Arc<RingCounters> {
        Arc::clone(&self.shared.counters)
    }

    /// Slots in the free pool now (neither queued, held nor in hand).
    pub fn free_slots(&self) -> usize {
        self.shared.free.len()
    }

    /// Frames queued now.
    pub fn queued(&self) -> usize {
        self.rx.len()
    }

    /// Slots the ring owns in all (capacity + the producer's one).
    pub fn total_slots(&self) -> usize {
        self.shared.slots
    }
}

impl std::fmt::Debug for Consumer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Consumer")
            .field("slots", &self.shared.slots)
            .field("queued", &self.rx.len())
            .finish()
    }
}

/// A frame held by a consumer; its slot returns to the pool when dropped.
pub struct FrameHandle {
    slot: Option<Box<Slot>>,
    shared: Arc<Shared>,
}

impl Deref for FrameHandle {
    type Target = Slot;
    fn deref(&self) -> &Slot {
        // Only `drop` takes the slot out.
        self.slot.as_deref().expect("slot present until drop")
    }
}

impl DerefMut for FrameHandle {
    fn deref_mut(&mut self) -> &mut Slot {
        self.slot.as_deref_mut().expect("slot present until drop")
    }
}

impl Drop for FrameHandle {
    fn drop(&mut self) {
        if let Some(slot) = self.slot.take() {
            // The free queue has room for every slot the ring owns.
            let pushed = self.shared.free.push(slot);
            debug_assert!(pushed.is_ok(), "free queue overflow");
        }
    }
}

impl std::fmt::Debug for FrameHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameHandle")
            .field("meta", &self.meta)
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(n: usize, policy: Overflow) -> (Producer, Consumer) {
        Ring::build(n, policy, || Image::new_mono8(4, 3))
    }

    #[test]
    fn a_slot_shows_a_lent_frame_until_it_is_written() {
        let mut slot = Slot::new(Image::new_mono8(4, 3));
        let mut lent = Image::new_mono8(4, 3);
        if let photopose_frame::Pixels::Mono8(v) = lent.pixels_mut() {
            v[5] = 200;
        }
        let lent = Arc::new(lent);
        slot.share(Arc::clone(&lent));
        assert!(slot.is_shared());
        assert_eq!(slot.image(), &*lent);
        assert_eq!(Arc::strong_count(&lent), 2);
        // Writing the slot ends the loan: the slot's own (black) pixels.
        slot.image_mut();
        assert!(!slot.is_shared());
        assert_eq!(Arc::strong_count(&lent), 1);
        assert_eq!(slot.image(), &Image::new_mono8(4, 3));
    }

    fn publish_seq(p: &mut Producer, seq: u64) -> Published {
        p.slot_mut().meta.seq = seq;
        p.publish()
    }

    #[test]
    fn delivers_in_order_and_returns_slots() {
        let (mut p, c) = ring(3, Overflow::DropNewest);
        assert_eq!(c.total_slots(), 4);
        assert_eq!(c.free_slots(), 3);
        for s in 0..3 {
            assert_eq!(publish_seq(&mut p, s), Published::Queued);
        }
        assert_eq!(c.free_slots(), 0);
        let a = c.try_recv().unwrap();
        let b = c.try_recv().unwrap();
        assert_eq!((a.meta.seq, b.meta.seq), (0, 1));
        drop(a);
        assert_eq!(c.free_slots(), 1);
        drop(b);
        let d = c.try_recv().unwrap();
        assert_eq!(d.meta.seq, 2);
        drop(d);
        assert!(c.try_recv().is_none());
        assert_eq!(c.free_slots(), 3);
        let st = c.counters().snapshot();
        assert_eq!((st.frames_in, st.delivered, st.dropped), (3, 3, 0));
    }

    #[test]
    fn the_ring_counters_are_exported() {
        let (mut p, c) = ring(1, Overflow::DropNewest);
        publish_seq(&mut p, 0);
        publish_seq(&mut p, 1);
        let mut e = photopose_telemetry::Exposition::new();
        e.register(c.shared_counters());
        let text = e.render();
        for line in [
            "photopose_ring_frames_in_total 2",
            "photopose_ring_frames_dropped_total 1",
            "photopose_ring_frames_delivered_total 0",
            "photopose_ring_frames_queued 1.0",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing:\n{text}");
        }
        assert_eq!(text.matches("# HELP ").count(), 4, "{text}");
    }

    #[test]
    fn drop_newest_keeps_the_queue() {
        let (mut p, c) = ring(2, Overflow::DropNewest);
        assert_eq!(publish_seq(&mut p, 0), Published::Queued);
        assert_eq!(publish_seq(&mut p, 1), Published::Queued);
        assert_eq!(publish_seq(&mut p, 2), Published::DroppedNewest);
        assert_eq!(publish_seq(&mut p, 3), Published::DroppedNewest);
        let seqs: Vec<u64> = std::iter::from_fn(|| c.try_recv().map(|h| h.meta.seq)).collect();
        assert_eq!(seqs, vec![0, 1]);
        let st = c.counters().snapshot();
        assert_eq!((st.frames_in, st.delivered, st.dropped), (4, 2, 2));
        assert_eq!(c.free_slots(), 2);
    }

    #[test]
    fn drop_oldest_keeps_the_newest() {
        let (mut p, c) = ring(2, Overflow::DropOldest);
        for s in 0..5 {
            publish_seq(&mut p, s);
        }
        let seqs: Vec<u64> = std::iter::from_fn(|| c.try_recv().map(|h| h.meta.seq)).collect();
        assert_eq!(seqs, vec![3, 4]);
        let st = c.counters().snapshot();
        assert_eq!((st.frames_in, st.delivered, st.dropped), (5, 2, 3));
    }

    #[test]
    fn drop_oldest_with_every_slot_held_drops_newest() {
        let (mut p, c) = ring(2, Overflow::DropOldest);
        publish_seq(&mut p, 0);
        publish_seq(&mut p, 1);
        let a = c.try_recv().unwrap();
        let b = c.try_recv().unwrap();
        assert_eq!(publish_seq(&mut p, 2), Published::DroppedNewest);
        drop(a);
        assert_eq!(publish_seq(&mut p, 3), Published::Queued);
        drop(b);
        assert_eq!(c.try_recv().unwrap().meta.seq, 3);
        let st = c.counters().snapshot();
        assert_eq!((st.frames_in, st.delivered, st.dropped), (4, 3, 1));
    }

    #[test]
    fn admission_numbers_have_no_gaps_and_evictions_name_theirs() {
        let (mut p, c) = ring(2, Overflow::DropOldest);
        assert_eq!(publish_seq(&mut p, 10), Published::Queued);
        assert_eq!(publish_seq(&mut p, 11), Published::Queued);
        assert_eq!(
            publish_seq(&mut p, 12),
            Published::QueuedDroppedOldest { dropped_order: 0 }
        );
        let (a, b) = (c.try_recv().unwrap(), c.try_recv().unwrap());
        assert_eq!((a.meta.seq, a.order), (11, 1));
        assert_eq!((b.meta.seq, b.order), (12, 2));
        // Dropped newest frames take no number.
        assert_eq!(publish_seq(&mut p, 13), Published::DroppedNewest);
        drop(a);
        assert_eq!(publish_seq(&mut p, 14), Published::Queued);
        assert_eq!(c.try_recv().unwrap().order, 3);
    }

    #[test]
    fn block_waits_for_a_consumer_and_never_drops() {
        let (mut p, c) = ring(2, Overflow::Block);
        let worker = std::thread::spawn(move || {
            let mut seqs = Vec::new();
            while let Ok(h) = c.recv_timeout(Duration::from_secs(5)) {
                std::thread::sleep(Duration::from_micros(200));
                seqs.push((h.meta.seq, h.order));
            }
            (seqs, c.counters().snapshot())
        });
        for s in 0..200 {
            assert_eq!(publish_seq(&mut p, s), Published::Queued);
        }
        drop(p);
        let (seqs, st) = worker.join().unwrap();
        assert_eq!(seqs, (0..200).map(|s| (s, s)).collect::<Vec<_>>());
        assert_eq!((st.frames_in, st.delivered, st.dropped), (200, 200, 0));
    }

    #[test]
    fn block_without_consumers_drops_instead_of_hanging() {
        let (mut p, c) = ring(1, Overflow::Block);
        assert_eq!(publish_seq(&mut p, 0), Published::Queued);
        drop(c);
        // The queued frame still holds no reference: nobody can free a slot.
        assert_eq!(publish_seq(&mut p, 1), Published::DroppedNewest);
    }

    #[test]
    fn consumer_sees_disconnect_after_draining() {
        let (mut p, c) = ring(2, Overflow::DropNewest);
        publish_seq(&mut p, 7);
        drop(p);
        assert_eq!(
            c.recv_timeout(Duration::from_millis(10)).unwrap().meta.seq,
            7
        );
        assert_eq!(
            c.recv_timeout(Duration::from_millis(10)).unwrap_err(),
            RecvError::Disconnected
        );
    }

    #[test]
    fn slots_keep_their_buffers() {
        let (mut p, c) = ring(2, Overflow::DropNewest);
        let mut ptrs = std::collections::HashSet::new();
        for s in 0..50 {
            publish_seq(&mut p, s);
            let h = c.try_recv().unwrap();
            if let photopose_frame::Pixels::Mono8(v) = h.image().pixels() {
                ptrs.insert(v.as_ptr() as usize);
            }
        }
        assert!(ptrs.len() <= 3, "only the ring's own buffers circulate");
    }
}
