//! The camera-clock → host-clock mapping: an online estimate of the offset
//! and drift between a camera's timestamp clock and the host's monotonic
//! clock from (camera timestamp, host arrival) pairs, with its uncertainty.
//!
//! Pure: no clock is read here, the caller passes every pair in.
//!
//! # Model
//! A frame stamped `c` by the camera arrives on the host at
//! `a = h(c) + d_min + j`, where `h` is the camera instant on the host
//! clock (`h(c) = offset + (1 + drift) · c`), `d_min` the smallest delay
//! between the stamped event and the arrival (exposure, read-out and
//! transfer of the frame's bytes: the caller knows it, this module does
//! not) and `j ≥ 0` the jitter of the transfer and of the host. The jitter
//! is one-sided, so the pairs lie on or above the line `h(c) + d_min`: the
//! estimate is the *lower envelope* of the pairs of a sliding window. Of
//! the lines that pass below every pair, the one closest to the pairs on
//! average (the linear programme of Moon, Skelly and Towsley) is the edge
//! of the window's lower convex hull that spans the window's mean camera
//! time. [`ClockMap::floor`] is that line: the earliest arrival a frame
//! stamped `c` can have; the caller subtracts `d_min`.
//!
//! # Clock jumps
//! A camera clock that goes back (a reconnect, a reset timestamp), a pair
//! that lies below the envelope by more than the jump tolerance (the camera
//! clock leapt forward), or pairs that stay above it by more than the
//! tolerance for several frames in a row (it leapt back by less than a
//! frame period) start a new epoch: the window is emptied and the estimate
//! starts again from the pair at hand. The owner calls [`ClockMap::reset`]
//! when it knows the camera was reopened.
//!
//! # Allocation
//! The window and the hull's scratch space are allocated once, in
//! [`ClockMap::new`]; [`ClockMap::update`] never allocates.

/// The time `bytes` take on a 1 Gbit/s link, ns (8 ns a byte): the default
/// transfer of a frame (1300×1030 Mono8: 10.7 ms).
pub fn bytes_at_gigabit_ns(bytes: usize) -> u64 {
    (bytes as u64).saturating_mul(8)
}

/// The settings of a [`ClockMap`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockMapConfig {
    /// Pairs in the sliding window (≥ 2). At 25 frames/s, 128 pairs span
    /// about 5 s.
    pub window: usize,
    /// Pairs before the estimate counts as warm (≥ 2, ≤ `window`).
    pub warm_after: usize,
    /// Largest drift believed, parts per million; a steeper (or flatter)
    /// envelope is cut to it.
    pub max_drift_ppm: f64,
    /// A pair this far below the envelope, or this far above it
    /// `jump_confirm` times in a row, is a jump of the camera clock, ns.
    pub jump_ns: u64,
    /// Consecutive pairs above the envelope by more than `jump_ns` that
    /// make a backward jump.
    pub jump_confirm: u32,
}

impl Default for ClockMapConfig {
    fn default() -> Self {
        ClockMapConfig {
            window: 128,
            warm_after: 16,
            max_drift_ppm: 1000.0,
            jump_ns: 50_000_000,
            jump_confirm: 8,
        }
    }
}

/// The mapping of one frame's camera timestamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mapped {
    /// The earliest host arrival of a frame with this camera timestamp
    /// (host monotonic ns): the camera instant on the host clock plus the
    /// smallest delay, which the caller subtracts.
    pub floor_ns: u64,
    /// The standard uncertainty of `floor_ns`, ns.
    pub sigma_ns: u64,
    /// The estimate had `warm_after` pairs when it mapped this one.
    pub warm: bool,
    /// This pair started a new epoch (a jump or the first pair).
    pub reset: bool,
}

/// Why a new epoch started (see [`ClockMap::last_reset`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetReason {
    /// The first pair, or [`ClockMap::reset`] by the owner.
    Start,
    /// The camera timestamp did not increase.
    Backwards,
    /// The pair lay below the envelope by more than the tolerance.
    JumpForward,
    /// Pairs stayed above the envelope by more than the tolerance.
    JumpBack,
}

/// The line `floor(c) = a0 + slope · (c − c0)` through a hull vertex.
#[derive(Debug, Clone, Copy)]
struct Line {
    c0: u64,
    a0: u64,
    slope: f64,
}

impl Line {
    fn at(&self, c: u64) -> f64 {
        let dc = c as i128 - self.c0 as i128;
        self.a0 as f64 + self.slope * dc as f64
    }
}

/// The online camera → host clock estimate (see the module docs).
#[derive(Debug, Clone)]
pub struct ClockMap {
    cfg: ClockMapConfig,
    /// Window of pairs (camera ns, arrival ns), a ring; oldest at `head`.
    pairs: Box<[(u64, u64)]>,
    head: usize,
    len: usize,
    /// Indices (in window order) of the lower hull, scratch.
    hull: Box<[usize]>,
    line: Option<Line>,
    /// Mean positive distance of the window's pairs above the line, ns.
    spread_ns: f64,
    /// Mean camera time of the window (relative to the line's `c0`) and
    /// the window's camera span, for the extrapolation uncertainty.
    mean_dc: f64,
    span: f64,
    above: u32,
    last_out: Option<u64>,
    resets: u64,
    last_reset: Option<ResetReason>,
}

impl ClockMap {
    /// An empty estimate (allocates its window once). Settings out of range
    /// are brought into range (window ≥ 2, `warm_after` in 2..=window,
    /// drift finite and ≥ 1 ppm, `jump_confirm` ≥ 1).
    pub fn new(cfg: ClockMapConfig) -> ClockMap {
        let window = cfg.window.max(2);
        let cfg = ClockMapConfig {
            window,
            warm_after: cfg.warm_after.clamp(2, window),
            max_drift_ppm: if cfg.max_drift_ppm.is_finite() {
                cfg.max_drift_ppm.max(1.0)
            } else {
                1000.0
            },
            jump_ns: cfg.jump_ns.max(1),
            jump_confirm: cfg.jump_confirm.max(1),
        };
        ClockMap {
            cfg,
            pairs: vec![(0, 0); window].into_boxed_slice(),
            head: 0,
            len: 0,
            hull: vec![0; window].into_boxed_slice(),
            line: None,
            spread_ns: 0.0,
            mean_dc: 0.0,
            span: 0.0,
            above: 0,
            last_out: None,
            resets: 0,
            last_reset: None,
        }
    }

    /// The settings in use.
    pub fn config(&self) -> &ClockMapConfig {
        &self.cfg
    }

    /// Forgets every pair: the next one starts a new epoch (the camera was
    /// reopened; its clock may have restarted).
    pub fn reset(&mut self) {
        self.len = 0;
        self.head = 0;
        self.line = None;
        self.above = 0;
        self.last_out = None;
    }

    /// Epochs started so far (the first pair's included).
    pub fn resets(&self) -> u64 {
        self.resets
    }

    /// Why the current epoch started.
    pub fn last_reset(&self) -> Option<ResetReason> {
        self.last_reset
    }

    /// Pairs in the window.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the window is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The estimated drift of the camera clock against the host's, parts
    /// per million (`None` before the first pair).
    pub fn drift_ppm(&self) -> Option<f64> {
        self.line.map(|l| (l.slope - 1.0) * 1e6)
    }

    fn pair(&self, k: usize) -> (u64, u64) {
        self.pairs[(self.head + k) % self.cfg.window]
    }

    /// The earliest arrival of a frame stamped `camera_ns` under the
    /// current estimate (host ns), with its standard uncertainty; `None`
    /// before the first pair. For a fixed estimate it increases with
    /// `camera_ns` (the slope is positive).
    pub fn floor(&self, camera_ns: u64) -> Option<(u64, u64)> {
        let line = self.line?;
        let v = line.at(camera_ns);
        let floor = if v <= 0.0 {
            0
        } else if v >= u64::MAX as f64 {
            u64::MAX
        } else {
            v.round() as u64
        };
        Some((floor, self.sigma_at(camera_ns, &line)))
    }

    /// The uncertainty of the envelope at `c`: each hull vertex sits above
    /// the true floor by about the jitter's mean over the pairs (the
    /// expected least of `n` exponential delays); twice that for the two
    /// vertices of the edge, growing with the distance from the window's
    /// mean (the slope's error, extrapolated); before warm-up the whole
    /// mean jitter. Calibrated on the unit tests' exponential jitter (about
    /// 95 % of the errors within 3σ).
    fn sigma_at(&self, c: u64, line: &Line) -> u64 {
        let n = self.len.max(1) as f64;
        let base = if self.len >= self.cfg.warm_after {
            2.0 * self.spread_ns / n
        } else {
            self.spread_ns
        };
        let dc = (c as i128 - line.c0 as i128) as f64 - self.mean_dc;
        let reach = if self.span > 0.0 {
            1.0 + 4.0 * dc.abs() / self.span
        } else {
            1.0
        };
        let s = (base * reach).max(1.0);
        if s.is_finite() && s < u64::MAX as f64 {
            s.ceil() as u64
        } else {
            u64::MAX
        }
    }

    /// Adds the pair of one frame (its camera timestamp, its host arrival)
    /// and maps that frame. Over an epoch the `floor_ns` it returns never
    /// lies after the arrival and, for frames arriving in the order they
    /// were taken (as a camera link delivers them), never decreases.
    pub fn update(&mut self, camera_ns: u64, arrival_ns: u64) -> Mapped {
        let jump = match (self.line, self.len) {
            (_, 0) => Some(ResetReason::Start),
            (Some(line), _) => {
                let (last_c, _) = self.pair(self.len - 1);
                if camera_ns <= last_c {
                    Some(ResetReason::Backwards)
                } else {
                    let r = arrival_ns as f64 - line.at(camera_ns);
                    let tol = self.cfg.jump_ns as f64;
                    if r < -tol {
                        Some(ResetReason::JumpForward)
                    } else if r > tol {
                        self.above += 1;
                        (self.above >= self.cfg.jump_confirm).then_some(ResetReason::JumpBack)
                    } else {
                        self.above = 0;
                        None
                    }
                }
            }
            (None, _) => Some(ResetReason::Start),
        };
        let reset = jump.is_some();
        if let Some(why) = jump {
            self.reset();
            self.resets += 1;
            self.last_reset = Some(why);
        }
        if self.len == self.cfg.window {
            self.head = (self.head + 1) % self.cfg.window;
            self.len -= 1;
        }
        let at = (self.head + self.len) % self.cfg.window;
        self.pairs[at] = (camera_ns, arrival_ns);
        self.len += 1;
        self.fit();
        let (mut floor, sigma) = self
            .floor(camera_ns)
            .unwrap_or((arrival_ns, self.cfg.jump_ns));
        // Never after the arrival (the envelope passes below every pair up
        // to rounding and the drift cut), never before the last frame's.
        floor = floor.min(arrival_ns);
        if let Some(last) = self.last_out {
            floor = floor.max(last.min(arrival_ns));
        }
        self.last_out = Some(floor);
        Mapped {
            floor_ns: floor,
            sigma_ns: sigma,
            warm: self.len >= self.cfg.warm_after,
            reset,
        }
    }

    /// The lower hull of the window (Andrew's monotone chain; the camera
    /// times increase along the window) and its edge over the mean.
    fn fit(&mut self) {
        let n = self.len;
        let (c0, a0) = self.pair(0);
        // Coordinates relative to the oldest pair: exact in i128.
        let rel = |p: (u64, u64)| (p.0 as i128 - c0 as i128, p.1 as i128 - a0 as i128);
        let mut h = 0usize;
        for k in 0..n {
            let p = rel(self.pair(k));
            while h >= 2 {
                let o = rel(self.pair(self.hull[h - 2]));
                let q = rel(self.pair(self.hull[h - 1]));
                // Keep q only if o → q → p turns left (counter-clockwise).
                let cross = (q.0 - o.0) * (p.1 - o.1) - (q.1 - o.1) * (p.0 - o.0);
                if cross <= 0 {
                    h -= 1;
                } else {
                    break;
                }
            }
            self.hull[h] = k;
            h += 1;
        }
        let mut sum_dc = 0.0;
        for k in 0..n {
            sum_dc += rel(self.pair(k)).0 as f64;
        }
        let mean = sum_dc / n as f64;
        let lo = 1.0 - self.cfg.max_drift_ppm * 1e-6;
        let hi = 1.0 + self.cfg.max_drift_ppm * 1e-6;
        let mut line = if h == 1 {
            let (c, a) = self.pair(self.hull[0]);
            Line {
                c0: c,
                a0: a,
                slope: 1.0,
            }
        } else {
            let mut e = 0;
            while e + 2 < h && (rel(self.pair(self.hull[e + 1])).0 as f64) < mean {
                e += 1;
            }
            let (p, q) = (self.pair(self.hull[e]), self.pair(self.hull[e + 1]));
            let (rp, rq) = (rel(p), rel(q));
            let slope = (rq.1 - rp.1) as f64 / (rq.0 - rp.0) as f64;
            Line {
                c0: p.0,
                a0: p.1,
                slope,
            }
        };
        if !(lo..=hi).contains(&line.slope) || !line.slope.is_finite() {
            // Cut to the believed drift and lowered onto the lowest pair.
            let slope = if line.slope.is_finite() {
                line.slope.clamp(lo, hi)
            } else {
                1.0
            };
            let mut best = self.pair(0);
            let mut best_v = f64::INFINITY;
            for k in 0..n {
                let (c, a) = self.pair(k);
                let r = rel((c, a));
                let v = r.1 as f64 - slope * r.0 as f64;
                if v < best_v {
                    best_v = v;
                    best = (c, a);
                }
            }
            line = Line {
                c0: best.0,
                a0: best.1,
                slope,
            };
        }
        let mut spread = 0.0;
        for k in 0..n {
            let (c, a) = self.pair(k);
            spread += (a as f64 - line.at(c)).max(0.0);
        }
        let last = rel(self.pair(n - 1)).0 as f64;
        self.spread_ns = spread / n as f64;
        self.mean_dc = mean - (line.c0 as i128 - c0 as i128) as f64;
        self.span = last;
        self.line = Some(line);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64: a small deterministic generator for the tests.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn uniform(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
        fn exponential(&mut self, mean: f64) -> f64 {
            -mean * (1.0 - self.uniform()).ln()
        }
    }

    /// A camera at 25 frames/s whose clock runs `drift_ppm` fast against
    /// the host's, started at camera time `c_start`; the host sees the
    /// exposure at `h` and the arrival after `transfer` + jitter.
    struct Cell {
        drift_ppm: f64,
        offset_ns: f64,
        transfer_ns: f64,
        c_start: u64,
    }

    impl Cell {
        /// Host instant of camera time `c`.
        fn host(&self, c: u64) -> f64 {
            self.offset_ns + (c - self.c_start) as f64 / (1.0 + self.drift_ppm * 1e-6)
        }
    }

    fn percentile(mut v: Vec<f64>, p: f64) -> f64 {
        v.sort_by(|a, b| a.total_cmp(b));
        v[((v.len() - 1) as f64 * p).round() as usize]
    }

    /// Runs `frames` frames with a given jitter; returns the errors of the
    /// mapped exposure instants after warm-up (ns) and the map.
    fn run(
        cell: &Cell,
        frames: u64,
        jitter: &mut dyn FnMut() -> f64,
        warm_up: u64,
    ) -> (Vec<f64>, ClockMap) {
        let mut map = ClockMap::new(ClockMapConfig::default());
        let mut errors = Vec::new();
        for k in 0..frames {
            let c = cell.c_start + k * 40_000_000;
            let h = cell.host(c);
            let arrival = (h + cell.transfer_ns + jitter()).round() as u64;
            let m = map.update(c, arrival);
            let exposure = m.floor_ns as f64 - cell.transfer_ns;
            if k >= warm_up {
                errors.push(exposure - h);
            }
        }
        (errors, map)
    }

    #[test]
    fn fifty_ppm_and_exponential_jitter_map_within_100_us_at_p99() {
        for (drift, seed) in [(50.0, 1u64), (-50.0, 2), (50.0, 3)] {
            let cell = Cell {
                drift_ppm: drift,
                offset_ns: 7.5e11,
                transfer_ns: 11.0e6,
                c_start: 3_000_000_000_000,
            };
            let mut rng = Rng(seed);
            let (errors, map) = run(&cell, 3000, &mut || rng.exponential(0.5e6), 64);
            let abs: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
            let p99 = percentile(abs, 0.99);
            assert!(p99 < 100e3, "drift {drift} ppm: p99 {p99} ns");
            let est = map.drift_ppm().unwrap();
            // A camera running fast: host = camera / (1 + d), slope ≈ 1 − d.
            assert!((est + drift).abs() < 5.0, "drift estimate {est} ppm");
            assert_eq!(map.resets(), 1);
        }
    }

    #[test]
    fn uniform_jitter_maps_within_100_us_at_p99() {
        let cell = Cell {
            drift_ppm: 50.0,
            offset_ns: 1.0e9,
            transfer_ns: 11.0e6,
            c_start: 0,
        };
        let mut rng = Rng(9);
        let (errors, _) = run(&cell, 2000, &mut || 0.5e6 * rng.uniform(), 64);
        let p99 = percentile(errors.iter().map(|e| e.abs()).collect(), 0.99);
        assert!(p99 < 100e3, "p99 {p99} ns");
    }

    #[test]
    fn without_the_envelope_the_jitter_would_show() {
        // The contrast: arrival minus the transfer is off by the jitter's
        // mean (0.5 ms), five times the bound.
        let mut rng = Rng(4);
        let errs: Vec<f64> = (0..2000).map(|_| rng.exponential(0.5e6)).collect();
        assert!(percentile(errs, 0.99) > 100e3);
    }

    #[test]
    fn the_uncertainty_shrinks_after_warm_up_and_covers_the_error() {
        let cell = Cell {
            drift_ppm: 50.0,
            offset_ns: 5.0e9,
            transfer_ns: 11.0e6,
            c_start: 10,
        };
        let mut rng = Rng(5);
        let mut map = ClockMap::new(ClockMapConfig::default());
        let mut first = None;
        let mut covered = 0;
        let mut n = 0;
        for k in 0..2000u64 {
            let c = cell.c_start + k * 40_000_000;
            let h = cell.host(c);
            let m = map.update(c, (h + 11.0e6 + rng.exponential(0.5e6)) as u64);
            if k == 2 {
                first = Some(m.sigma_ns);
                assert!(!m.warm);
            }
            if k >= 200 {
                assert!(m.warm);
                n += 1;
                let err = (m.floor_ns as f64 - 11.0e6 - h).abs();
                if err <= 3.0 * m.sigma_ns as f64 + 1e3 {
                    covered += 1;
                }
                assert!(m.sigma_ns < first.unwrap(), "{} vs {:?}", m.sigma_ns, first);
            }
        }
        assert!(covered * 100 >= n * 95, "{covered} of {n} within 3σ");
    }

    #[test]
    fn a_reconnect_with_a_restarted_camera_clock_starts_a_new_epoch() {
        let mut rng = Rng(6);
        let mut map = ClockMap::new(ClockMapConfig::default());
        let transfer = 11.0e6;
        // Before: camera clock at 9e12, host at 1e12.
        for k in 0..300u64 {
            let c = 9_000_000_000_000 + k * 40_000_000;
            let h = 1.0e12 + (k * 40_000_000) as f64;
            map.update(c, (h + transfer + rng.exponential(0.5e6)) as u64);
        }
        // The camera restarts: its clock begins at 0, two seconds later.
        let mut errs = Vec::new();
        for k in 0..300u64 {
            let c = k * 40_000_000;
            let h = 1.0e12 + 14.0e9 + (k * 40_000_000) as f64;
            let m = map.update(c, (h + transfer + rng.exponential(0.5e6)) as u64);
            if k == 0 {
                assert!(m.reset);
                assert_eq!(map.last_reset(), Some(ResetReason::Backwards));
            }
            if k >= 64 {
                errs.push((m.floor_ns as f64 - transfer - h).abs());
            }
        }
        assert!(percentile(errs, 0.99) < 100e3);
        assert_eq!(map.resets(), 2);
    }

    #[test]
    fn a_forward_leap_of_the_camera_clock_starts_a_new_epoch() {
        let mut map = ClockMap::new(ClockMapConfig::default());
        for k in 0..100u64 {
            map.update(k * 40_000_000, 5_000_000_000 + k * 40_000_000);
        }
        // The camera clock leaps 1 s ahead (e.g. a PTP correction).
        let m = map.update(
            100 * 40_000_000 + 1_000_000_000,
            5_000_000_000 + 100 * 40_000_000,
        );
        assert!(m.reset);
        assert_eq!(map.last_reset(), Some(ResetReason::JumpForward));
    }

    #[test]
    fn a_small_backward_leap_is_confirmed_then_followed() {
        let cfg = ClockMapConfig {
            jump_ns: 10_000_000,
            ..ClockMapConfig::default()
        };
        let mut map = ClockMap::new(cfg);
        for k in 0..100u64 {
            map.update(k * 40_000_000, 5_000_000_000 + k * 40_000_000);
        }
        // The camera clock falls back 25 ms, less than a frame period: its
        // times still increase, the pairs now lie 25 ms above the envelope.
        let mut resets = 0;
        for k in 100..120u64 {
            let c = k * 40_000_000 - 25_000_000;
            let m = map.update(c, 5_000_000_000 + k * 40_000_000);
            resets += u32::from(m.reset);
            if k >= 100 + u64::from(cfg.jump_confirm) {
                // Mapped onto the arrival again after the confirmation.
                assert_eq!(m.floor_ns, 5_000_000_000 + k * 40_000_000, "frame {k}");
            }
        }
        assert_eq!(resets, 1);
        assert_eq!(map.last_reset(), Some(ResetReason::JumpBack));
    }
}

#[cfg(test)]
mod props {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// For any estimate, the mapping never decreases with the camera
        /// time; over an epoch the mapped frames (arriving in order) never
        /// go back and never lie after their arrival.
        #[test]
        fn the_mapping_is_monotonic(
            steps in proptest::collection::vec((1u64..100_000_000, 0u64..2_000_000, 0u64..100_000_000), 1..300),
            drift_ppb in -200_000i64..200_000,
            probes in proptest::collection::vec(0u64..10_000_000_000, 2..20),
        ) {
            let mut map = ClockMap::new(ClockMapConfig { window: 32, warm_after: 8, ..ClockMapConfig::default() });
            let (mut c, mut a) = (1_000_000_000u64, 50_000_000_000u64);
            let mut last: Option<u64> = None;
            let mut last_arrival = 0u64;
            for (dc, jitter, _) in &steps {
                c += dc;
                let host_step = (*dc as i128 + *dc as i128 * drift_ppb as i128 / 1_000_000_000) as u64;
                a += host_step;
                // Frames arrive in the order they were taken.
                let arrival = (a + jitter).max(last_arrival);
                last_arrival = arrival;
                let m = map.update(c, arrival);
                prop_assert!(m.floor_ns <= arrival);
                if m.reset {
                    last = None;
                }
                if let Some(l) = last {
                    prop_assert!(m.floor_ns >= l, "went back: {} < {}", m.floor_ns, l);
                }
                last = Some(m.floor_ns);
            }
            let mut ps = probes.clone();
            ps.sort_unstable();
            ps.dedup();
            let mut prev: Option<u64> = None;
            for p in ps {
                let (f, s) = map.floor(c - c.min(5_000_000_000) + p).unwrap();
                prop_assert!(s >= 1);
                if let Some(q) = prev {
                    prop_assert!(f >= q, "not monotonic: {} after {}", f, q);
                }
                prev = Some(f);
            }
        }
    }
}
