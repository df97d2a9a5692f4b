//! Seeded labelling: the connected components (8-connectivity) that hold
//! given foreground pixels, grown run by run from those pixels, without
//! visiting the rest of the window. Tracking mode knows where each target
//! lies to a pixel or two: growing its blob from there reads the blob and
//! the pixels around its edge, where [`Labeller`](crate::label::Labeller)
//! reads every pixel of the window.
//!
//! A grown blob is the labeller's blob exactly: its runs are the maximal
//! runs of the window, its statistics are added in the labeller's
//! (row-major) order or summed exactly, so that its centre and moments are
//! bit for bit the ones the whole-window labeller gives it.
//!
//! A window at most 64 pixels wide and high (tracking's windows) is grown
//! on bit masks, one 64-bit word per row: a row's foreground pixels are
//! found sixteen at a time ([`ShortRow`]), each row read once per blob
//! (again only for a branch turning back) with the largest of its pixels
//! (the blob's peak when the blob is alone in its rows), a blob spreads
//! from row to row by shifts and ands, its runs are read off its rows'
//! words and its moments summed a row at a time in exact sums of integers
//! (`label::SmallMoments`). Wider windows are grown run by run, with a
//! list of the runs found per row.

use crate::label::{Blob, RowSums, Run, SmallMoments, SMALL_SIDE};
use crate::pixel::{Pixel, Plane, ShortRow};
use crate::threshold::Threshold;
use wide::f64x2;

/// No run (end of a row's list).
const NONE: u32 = u32::MAX;

/// Largest width and height of a window grown on row masks.
const MASK_SIDE: usize = 64;
// (Its blobs' moments are summed exactly: `SmallMoments`.)
/// Rows of all the blobs of a window grown on row masks, at most.
const ROWS: usize = MASK_SIDE * MASK_SIDE;
const _: () = assert!(MASK_SIDE <= SMALL_SIDE);

/// Why growing stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeedOverflow {
    /// More runs than the capacity.
    Runs,
    /// More blobs than the capacity.
    Blobs,
}

/// The seeded labeller with its buffers (allocated once).
#[derive(Debug)]
pub struct SeedLabeller {
    /// The runs found in the current window.
    runs: Vec<Run>,
    /// Per run: the next run of its row (in column order), or [`NONE`].
    next: Vec<u32>,
    /// Per run: its blob.
    owner: Vec<u32>,
    /// Per window row: its first run, or [`NONE`].
    head: Vec<u32>,
    /// Runs whose neighbour rows are still to be searched.
    stack: Vec<u32>,
    blobs: Vec<Blob>,
    max_runs: usize,
    max_blobs: usize,
    /// The window: full-frame first row and column, last column.
    row0: usize,
    col0: usize,
    /// The window is grown on row masks ([`MASK_SIDE`]).
    masked: bool,
    /// Mask path: per window row, the pixels of the blobs grown so far,
    /// for the rows set in `valid` (the others hold none: a window of one
    /// blob clears no rows).
    taken: [u64; MASK_SIDE],
    valid: u64,
    /// Mask path: the window's height.
    height: usize,
    /// Mask path: the blob being grown, per window row (its rows only).
    grown: [u64; MASK_SIDE],
    /// Mask path: the grown blobs' rows: blob `k` holds window rows
    /// `spans[k].0 ..` with masks `rows[spans[k].1 .. spans[k].2]` (a
    /// window's first blob is `taken` until a second one is grown: then
    /// its rows are copied there and its span noted).
    spans: Vec<(u32, u32, u32)>,
    rows: Box<[u64; ROWS]>,
    /// Mask path: rows of `rows` in use (from the second blob on).
    n_rows: usize,
    /// Mask path: runs counted against the capacity.
    n_runs: usize,
}

impl SeedLabeller {
    /// A labeller for at most `max_runs` runs, `max_blobs` blobs and
    /// `max_rows` rows per window.
    pub fn new(max_runs: usize, max_blobs: usize, max_rows: usize) -> Self {
        SeedLabeller {
            runs: Vec::with_capacity(max_runs),
            next: Vec::with_capacity(max_runs),
            owner: Vec::with_capacity(max_runs),
            head: Vec::with_capacity(max_rows),
            stack: Vec::with_capacity(max_runs),
            blobs: Vec::with_capacity(max_blobs),
            max_runs,
            max_blobs,
            row0: 0,
            col0: 0,
            masked: false,
            taken: [0; MASK_SIDE],
            valid: 0,
            height: 0,
            grown: [0; MASK_SIDE],
            spans: Vec::with_capacity(max_blobs),
            // (Every row of a blob holds a pixel no other blob holds.)
            rows: Box::new([0; ROWS]),
            n_rows: 0,
            n_runs: 0,
        }
    }

    /// Starts a window: forgets the blobs of the last one. A window with
    /// more rows than the capacity (given at [`SeedLabeller::new`]) makes
    /// the row table grow once.
    pub fn start<P>(&mut self, plane: &Plane<'_, P>) {
        self.blobs.clear();
        self.row0 = plane.row0;
        self.col0 = plane.col0;
        self.masked =
            (1..=MASK_SIDE).contains(&plane.width) && (1..=MASK_SIDE).contains(&plane.height);
        if self.masked {
            self.valid = 0;
            self.height = plane.height;
            self.spans.clear();
            self.n_rows = 0;
            self.n_runs = 0;
        } else {
            // (The run path's lists: the mask path uses none of them.)
            self.runs.clear();
            self.next.clear();
            self.owner.clear();
            self.stack.clear();
            self.head.clear();
            self.head.resize(plane.height, NONE);
        }
    }

    /// The blobs grown in this window, in the order they were grown.
    pub fn blobs(&self) -> &[Blob] {
        &self.blobs
    }

    /// The blob holding full-frame pixel `(col, row)` of the window, if one
    /// was grown.
    pub fn blob_at(&self, col: usize, row: usize) -> Option<usize> {
        if self.masked {
            let r = row.checked_sub(self.row0)?;
            let bit = 1u64 << col.checked_sub(self.col0).filter(|&c| c < MASK_SIDE)?;
            if r >= self.height || self.taken(r) & bit == 0 {
                return None;
            }
            if self.blobs.len() == 1 {
                return Some(0);
            }
            return self.spans.iter().position(|&(first, a, b)| {
                let k = r.wrapping_sub(first as usize);
                k < (b - a) as usize && self.rows[a as usize + k] & bit != 0
            });
        }
        self.run_at(col, row).map(|k| self.owner[k] as usize)
    }

    /// Whether every full-frame pixel of the box `col_lo..=col_hi ×
    /// row_lo..=row_hi` lies in a blob grown so far: then no other blob
    /// has a pixel there. Answered on the row masks (a mask and a compare
    /// per row); `false` for a window grown run by run.
    #[inline]
    pub fn covers(&self, col_lo: usize, col_hi: usize, row_lo: usize, row_hi: usize) -> bool {
        if !self.masked || col_lo > col_hi || row_lo > row_hi {
            return false;
        }
        let (Some(a), Some(b)) = (col_lo.checked_sub(self.col0), col_hi.checked_sub(self.col0))
        else {
            return false;
        };
        let Some(r0) = row_lo.checked_sub(self.row0) else {
            return false;
        };
        let r1 = row_hi - self.row0;
        if b >= MASK_SIDE || r1 >= self.height {
            return false;
        }
        let cols = span(a, b);
        let rows = span(r0, r1);
        if self.valid & rows != rows {
            return false;
        }
        // (`r0..r1 + 1`, not `r0..=r1`: an inclusive range's index is a
        // call of its own, not inlined.)
        self.taken[r0..r1 + 1].iter().all(|&t| t & cols == cols)
    }

    /// Mask path: the pixels of window row `r` (below the window's
    /// height) in the blobs grown so far.
    #[inline(always)]
    fn taken(&self, r: usize) -> u64 {
        if self.valid >> r & 1 != 0 {
            self.taken[r]
        } else {
            0
        }
    }

    /// The run found so far that holds full-frame pixel `(col, row)`.
    fn run_at(&self, col: usize, row: usize) -> Option<usize> {
        let r = row.checked_sub(self.row0)?;
        let mut k = *self.head.get(r)?;
        let col = col as u32;
        while k != NONE {
            let run = &self.runs[k as usize];
            if run.start > col {
                return None;
            }
            if col < run.end {
                return Some(k as usize);
            }
            k = self.next[k as usize];
        }
        None
    }

    /// Grows the blob holding full-frame pixel `(col, row)` of `plane` (the
    /// window given to [`SeedLabeller::start`]): `Ok(Some(index))` of the
    /// blob in [`SeedLabeller::blobs`] (an earlier one if it holds the
    /// pixel already), `Ok(None)` if the pixel is background or outside
    /// the window. Pixels at or above `saturation` count as saturated.
    /// (Inlined: a window's one grow goes straight to its path, the
    /// masks' or the runs', each out of line.)
    #[inline(always)]
    pub fn grow<P: ShortRow>(
        &mut self,
        plane: &Plane<'_, P>,
        threshold: Threshold,
        saturation: u32,
        col: usize,
        row: usize,
    ) -> Result<Option<usize>, SeedOverflow> {
        if col < plane.col0 || col > plane.last_col() || row < plane.row0 || row > plane.last_row()
        {
            return Ok(None);
        }
        if self.masked {
            self.grow_masked(plane, threshold, saturation, col, row)
        } else {
            self.grow_runs(plane, threshold, saturation, col, row)
        }
    }

    /// [`SeedLabeller::grow`] run by run (a window wider or taller than
    /// [`MASK_SIDE`], position inside it).
    #[inline(never)]
    fn grow_runs<P: ShortRow>(
        &mut self,
        plane: &Plane<'_, P>,
        threshold: Threshold,
        saturation: u32,
        col: usize,
        row: usize,
    ) -> Result<Option<usize>, SeedOverflow> {
        if !threshold.is_foreground(plane.row(row)[col - plane.col0].value()) {
            return Ok(None);
        }
        if let Some(b) = self.blob_at(col, row) {
            return Ok(Some(b));
        }
        if self.blobs.len() >= self.max_blobs {
            return Err(SeedOverflow::Blobs);
        }
        let blob = self.blobs.len() as u32;
        let first = self.runs.len();
        self.add_run_at(plane, threshold, saturation, col - plane.col0, row, blob)?;
        let mut rows = (row as u32, row as u32);
        while let Some(k) = self.stack.pop() {
            let run = self.runs[k as usize];
            let r = run.row as usize;
            for nr in [r.wrapping_sub(1), r + 1] {
                if nr < plane.row0 || nr > plane.last_row() {
                    continue;
                }
                // Runs of row `nr` touching `run` (8-connectivity) have a
                // pixel in columns `start − 1 ..= end`.
                let line = plane.row(nr);
                let lo = (run.start as usize).saturating_sub(1).max(plane.col0) - plane.col0;
                let hi = (run.end as usize).min(plane.last_col()) - plane.col0;
                let mut x = lo;
                while x <= hi {
                    if !threshold.is_foreground(line[x].value()) {
                        x += 1;
                        continue;
                    }
                    x = match self.run_end_at(x + plane.col0, nr) {
                        Some(end) => end - plane.col0,
                        None => {
                            let end = self.add_run_at(plane, threshold, saturation, x, nr, blob)?;
                            rows = (rows.0.min(nr as u32), rows.1.max(nr as u32));
                            end
                        }
                    };
                }
            }
        }
        // The statistics in the labeller's order: row by row, each row's
        // runs by column.
        let mut b = Blob::empty();
        for r in rows.0..=rows.1 {
            let mut k = self.head[r as usize - self.row0];
            while k != NONE {
                if self.owner[k as usize] == blob {
                    b.add_run(&self.runs[k as usize]);
                }
                k = self.next[k as usize];
            }
        }
        debug_assert!(self.runs.len() > first);
        self.blobs.push(b);
        Ok(Some(blob as usize))
    }

    /// Grows the blobs of every foreground pixel of full-frame row `row`,
    /// columns `col_lo..=col_hi` (clipped to the window) not yet in a
    /// blob: [`SeedLabeller::grow`] for a stretch of a row, skipping the
    /// runs found before in one step.
    pub fn grow_span<P: ShortRow>(
        &mut self,
        plane: &Plane<'_, P>,
        threshold: Threshold,
        saturation: u32,
        row: usize,
        col_lo: usize,
        col_hi: usize,
    ) -> Result<(), SeedOverflow> {
        if row < plane.row0 || row > plane.last_row() {
            return Ok(());
        }
        let lo = col_lo.max(plane.col0);
        let hi = col_hi.min(plane.last_col());
        if self.masked {
            if lo > hi {
                return Ok(());
            }
            let r = row - self.row0;
            let cols = span(lo - self.col0, hi - self.col0);
            let reading = P::reading(plane, threshold);
            let mut open = P::read_row(plane, &reading, r).0 & cols & !self.taken(r);
            while open != 0 {
                let col = self.col0 + open.trailing_zeros() as usize;
                self.grow_masked(plane, threshold, saturation, col, row)?;
                open &= !self.taken(r);
            }
            return Ok(());
        }
        let line = plane.row(row);
        let mut col = lo;
        while col <= hi {
            if !threshold.is_foreground(line[col - plane.col0].value()) {
                col += 1;
                continue;
            }
            col = match self.run_end_at(col, row) {
                Some(end) => end,
                None => {
                    let b = self.grow(plane, threshold, saturation, col, row)?;
                    debug_assert!(b.is_some());
                    self.run_end_at(col, row).unwrap_or(col + 1)
                }
            };
        }
        Ok(())
    }

    /// [`SeedLabeller::grow`] on row masks (a window of at most
    /// [`MASK_SIDE`] pixels each way, position inside it).
    #[inline(never)]
    fn grow_masked<P: ShortRow>(
        &mut self,
        plane: &Plane<'_, P>,
        threshold: Threshold,
        saturation: u32,
        col: usize,
        row: usize,
    ) -> Result<Option<usize>, SeedOverflow> {
        let reading = &P::reading(plane, threshold);
        let (r, bit) = (row - self.row0, 1u64 << (col - self.col0));
        let (f, p) = P::read_row(plane, reading, r);
        if f & bit == 0 {
            return Ok(None);
        }
        if self.taken(r) & bit != 0 {
            return Ok(self.blob_at(col, row));
        }
        if self.blobs.len() >= self.max_blobs {
            return Err(SeedOverflow::Blobs);
        }
        // The runs of each row that touch the blob's pixels of the row
        // above or below (8-connectivity: within one column). A blob of one
        // run per row (the rule) is found in one pass down from the seed's
        // row and one up, each row from the one before it; the pixels of a
        // row next to the following row's runs that the pass did not take
        // (a branch turning back) are noted, and only then are the rows
        // searched again until none gains a pixel (`flood`). (No list of
        // pending rows per step: SeedLabeller::grow 26.03 M -> 23.67 M in
        // tracking.) Each row is read once, its mask and peak together
        // (no row kept for later: a window's rows are read again only for
        // a second blob or a branch turning back).
        // (`grown` holds the blob's rows `lo..=hi` as they are found.)
        let seed = if single_run(f) {
            f
        } else {
            run_holding(f, bit)
        };
        self.grown[r] = seed;
        // The rows' peak, and `others`: the foreground pixels of other
        // blobs in the rows (then the peak is not the blob's).
        let mut pass = Pass {
            peak: p,
            others: f ^ seed,
            missed: 0,
        };
        let hi = self.pass(plane, reading, (r, seed, f), 1, &mut pass);
        let lo = self.pass(plane, reading, (r, seed, f), usize::MAX, &mut pass);
        let Pass {
            peak,
            mut others,
            missed,
        } = pass;
        let (mut lo, mut hi) = (lo, hi);
        if missed != 0 {
            (lo, hi) = self.flood(plane, reading, lo, hi);
            // (The rows' peak is not the blob's when it grew.)
            others = u64::MAX;
        }
        // The grey-value statistics: a blob alone in its rows has their
        // peak (its other pixels are background, below every pixel of the
        // blob), and no saturated pixel unless the peak is one; else they
        // are read over its pixels.
        let (max, saturated) = match P::peak(peak) {
            max if others == 0 && max < saturation => (max, 0),
            _ => masked_stats(plane, self.row0 + lo, &self.grown[lo..=hi], saturation),
        };
        // The moments summed exactly a row at a time (`SmallMoments`: the
        // values `Blob::add_run` gives, bit for bit).
        let origin = self.grown[lo].trailing_zeros() as usize;
        let (sums, cols, runs) = if self.blobs.is_empty() {
            self.take_rows::<true>(lo, hi, origin)
        } else {
            if self.blobs.len() == 1 {
                // The first blob's masks into `rows` (`taken` holds it alone).
                let (a, b) = (self.blobs[0].row0, self.blobs[0].row1);
                let (a, n) = (a as usize - self.row0, (b - a) as usize + 1);
                self.rows[..n].copy_from_slice(&self.taken[a..a + n]);
                self.spans.push((a as u32, 0, n as u32));
                self.n_rows = n;
            }
            // Rows of `taken` not yet in use cleared.
            let mut fresh = span(lo, hi) & !self.valid;
            while fresh != 0 {
                self.taken[fresh.trailing_zeros() as usize] = 0;
                fresh &= fresh - 1;
            }
            let first = self.n_rows;
            debug_assert!(first + hi - lo < ROWS);
            let taken = self.take_rows::<false>(lo, hi, origin);
            self.n_rows = first + hi - lo + 1;
            self.spans
                .push((lo as u32, first as u32, self.n_rows as u32));
            taken
        };
        self.valid |= span(lo, hi);
        // (The capacity counted per blob: the same error, the window's
        // state after it is not used.)
        if self.n_runs + runs > self.max_runs {
            return Err(SeedOverflow::Runs);
        }
        self.n_runs += runs;
        let (m, m4) = sums.to_blob_moments();
        let b = Blob {
            area: sums.area(),
            col0: (self.col0 + cols.trailing_zeros() as usize) as u32,
            row0: (self.row0 + lo) as u32,
            col1: (self.col0 + 63 - cols.leading_zeros() as usize) as u32,
            row1: (self.row0 + hi) as u32,
            max,
            saturated,
            m,
            m4,
            origin_col: (self.col0 + origin) as u32,
        };
        self.blobs.push(b);
        Ok(Some(self.blobs.len() - 1))
    }

    /// One pass of [`SeedLabeller::grow_masked`] from window row `r` (the
    /// blob's pixels `g` there, of the row's foreground `f`) one row at a
    /// time along `step` (1 down, `usize::MAX` up): each row's runs that
    /// touch the blob's pixels of the row before, into `grown`, until a row
    /// adds none. The last row reached.
    #[inline(always)]
    fn pass<P: ShortRow>(
        &mut self,
        plane: &Plane<'_, P>,
        reading: &P::Reading,
        (r, g, f): (usize, u64, u64),
        step: usize,
        pass: &mut Pass<P>,
    ) -> usize {
        // (`rg`: the pixels the blob's pixels of row `k` reach, formed once
        // for both rows next to it; `stray`: the row's foreground pixels
        // outside the blob.)
        let (mut k, mut rg, mut stray) = (r, reach(g), f ^ g);
        // (The height is at most `MASK_SIDE`: said once, no bounds check
        // of `grown` per row.)
        let height = plane.height.min(MASK_SIDE);
        loop {
            // (Past either end of the window: at least `height`.)
            let n = k.wrapping_add(step);
            if n >= height {
                return k;
            }
            let (f, p) = P::read_row(plane, reading, n);
            let touch = rg & f;
            if touch == 0 {
                return k;
            }
            // A row of one run (the rule) is the blob's whole, no filling.
            // (Its other pixels noted only then: none in a row of one run.)
            let add = if single_run(f) {
                f
            } else {
                let add = fill_runs(f, touch);
                pass.others |= f ^ add;
                add
            };
            pass.peak = P::fold(pass.peak, p);
            let ra = reach(add);
            pass.missed |= ra & stray;
            self.grown[n] = add;
            (k, rg, stray) = (n, ra, f ^ add);
        }
    }

    /// The blob being grown (`grown`, rows `lo..=hi`) added
    /// to `taken` (and its masks to `rows` unless it is the window's first
    /// blob, `FIRST`: `taken` holds it alone): its moments about column
    /// `origin` (from the last row up: `SmallMoments::add_row_up`), the
    /// columns it holds, its runs.
    #[inline(always)]
    fn take_rows<const FIRST: bool>(
        &mut self,
        lo: usize,
        hi: usize,
        origin: usize,
    ) -> (SmallMoments, u64, usize) {
        let mut sums = SmallMoments::ZERO;
        let ends = SmallMoments::ends(origin);
        let (mut cols, mut runs) = (0u64, hi - lo + 1);
        let first = self.n_rows;
        let rows = self.grown[lo..=hi].iter().zip(&mut self.taken[lo..=hi]);
        for (i, (&g, taken)) in rows.enumerate().rev() {
            // (`past`: the bit after the lowest run, 0 past the last column;
            // `single_run` without it.)
            let past = g.wrapping_add(g & g.wrapping_neg());
            if g & past == 0 {
                // One run (the rule): its ends straight from the mask.
                let (start, end) = (g.trailing_zeros() as usize, past.trailing_zeros() as usize);
                sums.add_row_up(&SmallMoments::run(ends, start, end));
            } else {
                let mut row: RowSums = [f64x2::ZERO; 3];
                let mut m = g;
                runs -= 1;
                while m != 0 {
                    let start = m.trailing_zeros() as usize;
                    let end = start + (!(m >> start)).trailing_zeros() as usize;
                    runs += 1;
                    SmallMoments::add_run(&mut row, ends, start, end);
                    m &= !(u64::MAX >> (MASK_SIDE - end));
                }
                sums.add_row_up(&row);
            }
            cols |= g;
            if FIRST {
                *taken = g;
            } else {
                *taken |= g;
                // (Below `ROWS` rows in all: every row of a blob holds a
                // pixel of the window no other blob holds.)
                self.rows[(first + i) % ROWS] = g;
            }
        }
        (sums, cols, runs)
    }

    /// The blob being grown (`grown`, rows `lo..=hi`, connected) made
    /// whole: the rows whose neighbours are still to be searched kept as a
    /// mask (a row that gains pixels again is still pending), every row
    /// searched once at first. The rows the blob then holds.
    fn flood<P: ShortRow>(
        &mut self,
        plane: &Plane<'_, P>,
        reading: &P::Reading,
        lo: usize,
        hi: usize,
    ) -> (usize, usize) {
        let last = plane.height - 1;
        // (`grown` holds the blob's rows alone.)
        for (k, g) in self.grown[..plane.height].iter_mut().enumerate() {
            if k < lo || k > hi {
                *g = 0;
            }
        }
        let mut todo = span(lo, hi);
        let mut held = todo;
        while todo != 0 {
            let k = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            let reach = reach(self.grown[k]);
            if k > 0 {
                todo |= self.spread(plane, reading, reach, k - 1);
            }
            if k < last {
                todo |= self.spread(plane, reading, reach, k + 1);
            }
            held |= todo;
        }
        (
            held.trailing_zeros() as usize,
            MASK_SIDE - 1 - held.leading_zeros() as usize,
        )
    }

    /// Adds to the blob being grown (`grown`) the runs
    /// of window row `n` that touch `reach` (the pixels of a neighbour row
    /// and their left and right neighbours); the row's bit if it gained
    /// pixels (its own neighbours are then to be searched).
    #[inline(always)]
    fn spread<P: ShortRow>(
        &mut self,
        plane: &Plane<'_, P>,
        reading: &P::Reading,
        reach: u64,
        n: usize,
    ) -> u64 {
        let before = self.grown[n];
        let f = P::read_row(plane, reading, n).0;
        let add = fill_runs(f, reach & f) & !before;
        if add == 0 {
            return 0;
        }
        self.grown[n] = before | add;
        1 << n
    }

    /// One past the last column of the run of row `row` holding column
    /// `col`, if one was found.
    fn run_end_at(&self, col: usize, row: usize) -> Option<usize> {
        self.run_at(col, row).map(|k| self.runs[k].end as usize)
    }

    /// Adds the maximal run of window row `row` (full frame) through window
    /// column offset `x` to blob `blob` and to the search; returns the
    /// window column offset one past its end.
    fn add_run_at<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        threshold: Threshold,
        saturation: u32,
        x: usize,
        row: usize,
        blob: u32,
    ) -> Result<usize, SeedOverflow> {
        if self.runs.len() >= self.max_runs {
            return Err(SeedOverflow::Runs);
        }
        let line = plane.row(row);
        let mut start = x;
        while start > 0 && threshold.is_foreground(line[start - 1].value()) {
            start -= 1;
        }
        let mut end = x + 1;
        while end < line.len() && threshold.is_foreground(line[end].value()) {
            end += 1;
        }
        let run = Run::of(line, row as u32, plane.col0 as u32, start, end, saturation);
        let k = self.runs.len() as u32;
        self.runs.push(run);
        self.owner.push(blob);
        // Into the row's list, in column order.
        let slot = row - self.row0;
        let mut prev = NONE;
        let mut cur = self.head[slot];
        while cur != NONE && self.runs[cur as usize].start < run.start {
            prev = cur;
            cur = self.next[cur as usize];
        }
        self.next.push(cur);
        if prev == NONE {
            self.head[slot] = k;
        } else {
            self.next[prev as usize] = k;
        }
        self.stack.push(k);
        Ok(end)
    }
}

/// [`ShortRow::masked_stats`] out of line: the rare path of
/// [`SeedLabeller::grow_masked`] (a blob sharing its rows or saturated),
/// whose set-up would otherwise be done for every blob.
#[inline(never)]
fn masked_stats<P: ShortRow>(
    plane: &Plane<'_, P>,
    row0: usize,
    masks: &[u64],
    saturation: u32,
) -> (u32, u32) {
    P::masked_stats(plane, row0, masks, saturation)
}

/// What the passes of [`SeedLabeller::grow_masked`] gather besides the
/// blob's rows.
struct Pass<P: ShortRow> {
    /// The peak of the rows.
    peak: P::Peak,
    /// Foreground pixels of the rows outside the blob (of other blobs:
    /// then the peak need not be the blob's).
    others: u64,
    /// Pixels of a row next to the blob's pixels of the row after it that
    /// the pass did not take (a branch turning back).
    missed: u64,
}

/// Bits `a..=b` (`a ≤ b < 64`): columns or rows of a window grown on row
/// masks.
#[inline(always)]
fn span(a: usize, b: usize) -> u64 {
    debug_assert!(a <= b && b < MASK_SIDE);
    (u64::MAX >> (MASK_SIDE - 1 - (b - a))) << a
}

/// The pixels of a row touching those of `g` (of the row above or below,
/// 8-connectivity): `g` and its left and right neighbours.
#[inline(always)]
fn reach(g: u64) -> u64 {
    g | g << 1 | g >> 1
}

/// The run of `f` (a row's foreground bits) that holds `bit` (a single
/// bit of `f`): [`fill_runs`] of one seed, without spreading it a bit at a
/// time (the seed mostly lies inside a run of several pixels). Upward the
/// carry of `f + bit` runs through the run's bits; downward the run starts
/// above the highest background bit below `bit`.
#[inline(always)]
fn run_holding(f: u64, bit: u64) -> u64 {
    debug_assert!(bit.is_power_of_two() && f & bit != 0);
    let up = f & !f.wrapping_add(bit);
    let below = bit - 1;
    let gaps = !f & below;
    let down = if gaps == 0 {
        below
    } else {
        below & (u64::MAX << (64 - gaps.leading_zeros()))
    };
    up | down
}

/// Whether the bits of `f` (not 0) are one run: adding its lowest bit
/// carries through the lowest run and leaves none of its bits.
#[inline(always)]
fn single_run(f: u64) -> bool {
    f & f.wrapping_add(f & f.wrapping_neg()) == 0
}

/// The runs of `f` (a row's foreground bits) that hold a bit of `seeds`:
/// the seeds spread one bit either way within `f` until nothing changes.
#[inline(always)]
fn fill_runs(f: u64, seeds: u64) -> u64 {
    let mut x = seeds & f;
    loop {
        let y = (x | x << 1 | x >> 1) & f;
        if y == x {
            return x;
        }
        x = y;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::label::{LabelOutcome, Labeller};
    use crate::testutil::window;
    use proptest::prelude::*;

    /// An 8-bit frame drawn in text: `#` foreground (200), anything else
    /// background (10); with its width and height.
    fn drawn(img: &[&str]) -> (Vec<u8>, usize, usize) {
        let data = img
            .iter()
            .flat_map(|r| r.bytes().map(|b| if b == b'#' { 200 } else { 10 }))
            .collect();
        (data, img[0].len(), img.len())
    }

    /// Every blob the labeller finds in a window, grown from each of its
    /// pixels, is the labeller's blob, bit for bit; in 8-bit and 16-bit
    /// frames.
    fn check(data: &[u8], width: usize, area: (usize, usize, usize, usize)) {
        check_pixels(data, width, area);
        let wide: Vec<u16> = data.iter().map(|&v| v as u16).collect();
        check_pixels(&wide, width, area);
    }

    fn check_pixels<P: ShortRow>(data: &[P], width: usize, area: (usize, usize, usize, usize)) {
        let (c0, r0, w, h) = area;
        let plane = window(data, width, area);
        let t = Threshold::global(100);
        let mut labeller = Labeller::new(10_000, 10_000);
        assert_eq!(labeller.label(&plane, t, 250), LabelOutcome::Complete);
        let mut seeds = SeedLabeller::new(10_000, 10_000, 4);
        seeds.start(&plane);
        for row in r0..r0 + h {
            for col in c0..c0 + w {
                let v = data[row * width + col].value();
                let got = seeds.grow(&plane, t, 250, col, row).expect("capacity");
                assert_eq!(got.is_some(), v > 100, "({col}, {row})");
            }
        }
        // Each pixel's blob found again (the first blob's rows kept apart
        // once a second one is grown), its box around the pixel.
        for row in r0..r0 + h {
            for col in c0..c0 + w {
                let at = seeds.blob_at(col, row);
                assert_eq!(at.is_some(), data[row * width + col].value() > 100);
                if let Some(b) = at.map(|i| seeds.blobs()[i]) {
                    let (col, row) = (col as u32, row as u32);
                    assert!((b.col0..=b.col1).contains(&col) && (b.row0..=b.row1).contains(&row));
                    assert_eq!(
                        seeds.grow(&plane, t, 250, col as usize, row as usize),
                        Ok(at)
                    );
                }
            }
        }
        // The same, a row at a time (the span reaching past the window).
        let mut spans = SeedLabeller::new(10_000, 10_000, 4);
        spans.start(&plane);
        for row in 0..r0 + h + 1 {
            spans
                .grow_span(&plane, t, 250, row, 0, width + 3)
                .expect("capacity");
        }
        let mut want: Vec<Blob> = labeller.blobs().to_vec();
        let mut got: Vec<Blob> = seeds.blobs().to_vec();
        let mut by_span: Vec<Blob> = spans.blobs().to_vec();
        let key = |b: &Blob| (b.row0, b.origin_col);
        want.sort_by_key(key);
        got.sort_by_key(key);
        by_span.sort_by_key(key);
        assert_eq!(got, want);
        assert_eq!(by_span, want);
    }

    #[test]
    fn shapes_with_arms_and_holes_grow_as_the_labeller_finds_them() {
        let img = [
            "#...#.....##", //
            "#...#....#..", //
            "#####...#..#", //
            "..#....#...#", //
            ".#.#...#####", //
            "#...#.......", //
        ];
        let (data, w, h) = drawn(&img);
        check(&data, w, (0, 0, w, h));
        check(&data, w, (1, 1, w - 2, h - 2));
    }

    /// The largest blob of the mask path (a whole 64 × 64 window, its
    /// moments' largest sums, with the origin at either side) and a
    /// diamond whose rows start left of its origin: the integer moments
    /// equal the labeller's `f64` ones.
    #[test]
    fn the_largest_masked_blobs_have_the_labellers_moments() {
        let (w, h) = (66usize, 66usize);
        let mut data = vec![10u8; w * h];
        for (i, v) in data.iter_mut().enumerate() {
            let (c, r) = ((i % w) as i64, (i / w) as i64);
            if (1..65).contains(&c) && (1..65).contains(&r) {
                *v = if (c + r) % 7 == 0 { 255 } else { 200 };
            }
        }
        check(&data, w, (1, 1, 64, 64));
        check(&data, w, (0, 0, 64, 64));
        let mut diamond = vec![10u8; w * h];
        for (i, v) in diamond.iter_mut().enumerate() {
            let (c, r) = ((i % w) as i64, (i / w) as i64);
            if (c - 32).abs() + (r - 31).abs() <= 31 {
                *v = 220;
            }
        }
        check(&diamond, w, (0, 0, 64, 64));
    }

    /// `covers` is "every pixel of the box is in a grown blob", asked
    /// pixel by pixel with `blob_at`, for boxes inside, across and outside
    /// the window.
    #[test]
    fn a_box_is_covered_when_each_of_its_pixels_is_in_a_blob() {
        let img = [
            "..........", //
            ".######...", //
            ".######.#.", //
            ".#####..#.", //
            "..........", //
        ];
        let (data, w, h) = drawn(&img);
        let plane = window(&data, w, (1, 0, w - 1, h));
        let t = Threshold::global(100);
        let mut s = SeedLabeller::new(100, 10, h);
        s.start(&plane);
        s.grow(&plane, t, 250, 3, 2).expect("capacity");
        let (mut yes, mut no) = (0, 0);
        for (c0, c1, r0, r1) in (0..w + 1).flat_map(|c0| {
            (c0..w + 1).flat_map(move |c1| {
                (0..h + 1).flat_map(move |r0| (r0..h + 1).map(move |r1| (c0, c1, r0, r1)))
            })
        }) {
            let plain = (r0..=r1).all(|r| (c0..=c1).all(|c| s.blob_at(c, r).is_some()));
            assert_eq!(s.covers(c0, c1, r0, r1), plain, "{c0}..={c1} × {r0}..={r1}");
            if plain {
                yes += 1;
            } else {
                no += 1;
            }
        }
        assert!(yes > 20 && no > 20, "{yes} {no}");
        // The other blob not grown yet: its pixels are not covered.
        assert!(!s.covers(8, 8, 2, 3));
        s.grow(&plane, t, 250, 8, 2).expect("capacity");
        assert!(s.covers(8, 8, 2, 3));
    }

    /// The run holding a bit is the seed spread a bit at a time: every
    /// bit of random rows, dense and sparse, runs through both ends; a row
    /// is one run when the run through any of its bits is the whole row.
    #[test]
    fn the_run_holding_a_bit_is_the_seed_spread() {
        use crate::testutil::Rng;
        let mut rng = Rng::new(3);
        for round in 0..2000 {
            let f = match round % 4 {
                0 => rng.next_u64(),
                1 => rng.next_u64() | rng.next_u64(),
                2 => rng.next_u64() & rng.next_u64(),
                _ => [u64::MAX, 1, 1 << 63, u64::MAX >> 1, u64::MAX << 1][round / 4 % 5],
            };
            for i in (0..64).filter(|i| f >> i & 1 != 0) {
                assert_eq!(run_holding(f, 1 << i), fill_runs(f, 1 << i), "{f:#x} {i}");
                // One run: the run through any of its bits is all of them.
                let run = fill_runs(f, 1 << i);
                assert!(single_run(run), "{run:#x}");
                assert_eq!(single_run(f), run == f, "{f:#x}");
            }
        }
    }

    /// The passes down and up from the seed's row miss a branch that
    /// turns back (the far arm of a U grown from the other's top): it is
    /// found by searching the rows again, the blob whole.
    #[test]
    fn a_branch_turning_back_is_found() {
        let img = [
            "#.#.", //
            "#.#.", //
            "###.", //
        ];
        let (data, w, h) = drawn(&img);
        let plane = Plane::whole(&data, w, h);
        let t = Threshold::global(100);
        for (col, row) in [(0, 0), (2, 0), (1, 2)] {
            let mut s = SeedLabeller::new(100, 10, h);
            s.start(&plane);
            assert_eq!(s.grow(&plane, t, 250, col, row), Ok(Some(0)));
            assert_eq!(s.blobs()[0].area, 7, "{col} {row}");
            assert_eq!(s.blob_at(2, 0), Some(0));
            assert!(s.covers(0, 0, 0, 2) && s.covers(2, 2, 0, 2));
        }
        check(&data, w, (0, 0, w, h));
        // A branch turning back past the rows of the passes (row 0 from
        // row 1), into a row where the blob grown before had its pixels.
        let img = [
            "#...#", //
            "#.#..", //
            "#.#..", //
            "###..", //
        ];
        let (data, w, h) = drawn(&img);
        let plane = Plane::whole(&data, w, h);
        let mut s = SeedLabeller::new(100, 10, h);
        s.start(&plane);
        assert_eq!(s.grow(&plane, t, 250, 4, 0), Ok(Some(0)));
        s.start(&plane);
        assert_eq!(s.grow(&plane, t, 250, 2, 1), Ok(Some(0)));
        assert_eq!(s.blobs()[0].area, 8);
        check(&data, w, (0, 0, w, h));
    }

    #[test]
    fn a_background_seed_or_one_outside_the_window_grows_nothing() {
        let data = [10u8, 200, 10, 10];
        let plane = Plane::whole(&data, 4, 1);
        let mut s = SeedLabeller::new(8, 8, 1);
        s.start(&plane);
        let t = Threshold::global(100);
        assert_eq!(s.grow(&plane, t, 250, 0, 0), Ok(None));
        assert_eq!(s.grow(&plane, t, 250, 9, 0), Ok(None));
        assert_eq!(s.grow(&plane, t, 250, 1, 0), Ok(Some(0)));
        assert_eq!(s.grow(&plane, t, 250, 1, 0), Ok(Some(0)));
        assert_eq!(s.blobs().len(), 1);
    }

    #[test]
    fn capacity_is_reported() {
        let data = [200u8, 10, 200, 10, 200, 10, 200, 200, 200, 200];
        let plane = Plane::whole(&data, 5, 2);
        let t = Threshold::global(100);
        let mut s = SeedLabeller::new(2, 8, 2);
        s.start(&plane);
        assert_eq!(s.grow(&plane, t, 250, 0, 0), Err(SeedOverflow::Runs));
        let mut s = SeedLabeller::new(8, 1, 2);
        s.start(&plane);
        let data = [200u8, 10, 200];
        let plane = Plane::whole(&data, 3, 1);
        s.start(&plane);
        assert_eq!(s.grow(&plane, t, 250, 0, 0), Ok(Some(0)));
        assert_eq!(s.grow(&plane, t, 250, 2, 0), Err(SeedOverflow::Blobs));
    }

    /// A dot alone in its rows takes its peak from them: brighter pixels
    /// just past the window's right edge (in the vectors that read its
    /// rows: windows of 10, 20, 40 and 64 pixels) are not its own; nor in a
    /// window at the frame's end (read one pixel at a time).
    #[test]
    fn a_dot_alone_in_its_rows_has_its_own_peak() {
        let (w, h) = (100usize, 7usize);
        for width in [10, 20, 40, 64] {
            let mut data = vec![10u8; w * h];
            for row in 1..4 {
                data[row * w + 7..row * w + 10].fill(150);
                data[row * w + 5 + width] = 240;
                data[row * w + 5 + width + 9] = 245;
            }
            data[4 * w + 8] = 170;
            check(&data, w, (5, 0, width, 6));
            check(&data, w, (5, 1, width, 3));
        }
        let mut data = vec![10u8; w * h];
        for row in 4..7 {
            data[row * w + 90..row * w + 94].fill(150);
            data[row * w + 99] = 240;
        }
        check(&data, w, (88, 4, 11, 3));
        check(&data, w, (88, 3, 12, 4));
    }

    /// A frame of `w × h` pixels, mostly background, holding a few small
    /// blocks of one grey each (some saturated) and single pixels just
    /// below saturation: windows anywhere in it have rows read in one, two
    /// or four vectors or one pixel at a time (as far as the frame holds
    /// pixels past the window's last row), blobs alone in their rows (their
    /// peak read off the rows) beside brighter pixels just past the
    /// window's edge, and rows shared by blobs.
    fn sparse_frame(w: usize, h: usize, seed: u64) -> Vec<u8> {
        const GREY: [u8; 8] = [120, 150, 180, 200, 230, 249, 250, 255];
        let mut rng = crate::testutil::Rng::new(seed);
        let mut next = |n: usize| (rng.next_u64() % n as u64) as usize;
        let mut data = vec![10u8; w * h];
        for _ in 0..1 + next(4) {
            let (c, r, bw, bh, v) = (next(w), next(h), 1 + next(4), 1 + next(3), GREY[next(8)]);
            for row in r..(r + bh).min(h) {
                data[row * w + c..row * w + (c + bw).min(w)].fill(v);
            }
        }
        for _ in 0..next(8) {
            data[next(w * h)] = 249;
        }
        data
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        #[test]
        fn random_frames_grow_as_the_labeller_labels_them(
            bits in proptest::collection::vec(0u8..3, 12 * 10),
            c0 in 0usize..3, r0 in 0usize..3, dw in 0usize..3, dh in 0usize..3,
        ) {
            // About a third of the pixels bright, some saturated (windows
            // grown on row masks).
            let data: Vec<u8> = bits.iter().map(|&b| [10, 200, 255][b as usize]).collect();
            let (w, h) = (12 - c0 - dw, 10 - r0 - dh);
            check(&data, 12, (c0, r0, w, h));
        }

        #[test]
        fn windows_anywhere_in_a_frame_grow_as_the_labeller_labels_them(
            w in 17usize..72, h in 2usize..10, seed in any::<u64>(),
            area in (0usize..72, 0usize..10, 1usize..65, 1usize..10),
        ) {
            let data = sparse_frame(w, h, seed);
            let (c0, r0) = (area.0 % w, area.1 % h);
            let (cw, ch) = (area.2.min(w - c0), area.3.min(h - r0));
            check(&data, w, (c0, r0, cw, ch));
        }

        #[test]
        fn random_wide_or_tall_frames_grow_as_the_labeller_labels_them(
            bits in proptest::collection::vec(0u8..3, 70 * 8),
            c0 in 0usize..3, dw in 0usize..3, tall in any::<bool>(),
        ) {
            // Windows wider or taller than 64 pixels are grown run by run;
            // ones of 64 and of at most 32 in a wider frame on row masks
            // read in blocks past their width.
            let data: Vec<u8> = bits.iter().map(|&b| [10, 200, 255][b as usize]).collect();
            if tall {
                check(&data, 8, (0, c0, 8, 70 - c0 - dw));
            } else {
                check(&data, 70, (c0, 0, 70 - c0 - dw, 8));
                check(&data, 70, (3, 0, 64, 8));
                check(&data, 70, (c0 + 5, 0, 30 - dw, 8));
            }
        }
    }

    #[test]
    fn the_window_decides_the_path() {
        let data = [10u8; 70 * 70];
        let mut s = SeedLabeller::new(8, 8, 70);
        for (w, h, masked) in [
            (64, 64, true),
            (65, 10, false),
            (10, 65, false),
            (1, 1, true),
        ] {
            s.start(&Plane::whole(&data[..w * h], w, h));
            assert_eq!(s.masked, masked, "{w} × {h}");
        }
    }

    /// One labeller over windows of both paths in turn (a window grown on
    /// masks leaves the run path's lists as they were): each window's
    /// blobs are those a fresh labeller grows.
    #[test]
    fn windows_of_either_path_in_turn_grow_as_fresh_ones() {
        let (w, h) = (70usize, 8usize);
        let data: Vec<u8> = (0..w * h)
            .map(|i| if (i % w + i / w) % 5 < 2 { 200 } else { 10 })
            .collect();
        let t = Threshold::global(100);
        let mut s = SeedLabeller::new(10_000, 1_000, h);
        for area in [(0, 0, 70, 8), (3, 0, 20, 8), (0, 1, 66, 6), (5, 2, 64, 5)] {
            let plane = window(&data, w, area);
            let mut fresh = SeedLabeller::new(10_000, 1_000, h);
            s.start(&plane);
            fresh.start(&plane);
            for row in area.1..area.1 + area.3 {
                s.grow_span(&plane, t, 250, row, 0, w).expect("capacity");
                fresh
                    .grow_span(&plane, t, 250, row, 0, w)
                    .expect("capacity");
            }
            assert!(!s.blobs().is_empty());
            assert_eq!(s.blobs(), fresh.blobs(), "{area:?}");
        }
    }
}
