//! The threshold: the [`Threshold`] type every stage asks whether a grey
//! value is a target's (the one place of that comparison), the grey-value
//! histogram and the global level: Otsu's method, bounded below by a noise
//! floor estimated from the same histogram, with explicit outcomes for
//! degenerate frames (all dark, saturated, nearly uniform).
//!
//! The histogram is taken on a sub-sampled grid (every `step`-th row and
//! column, rows and columns `≡ 1 (mod step)`, fixed in full-frame
//! coordinates so that a window samples the same pixels as its frame): the
//! threshold is a property of the grey-value distribution, and a sixteenth
//! of the pixels (the default step 4) estimate it as well as all of them
//! (Otsu's level within one 8-bit grey value of the level on every second
//! row and column). Reading a quarter of the rows also spares the memory
//! traffic of a frame not yet in the cache. 16-bit values are binned down
//! to at most [`MAX_BINS`] bins.
//!
//! The local levels ([`LocalLevels`]): one level per tile of
//! [`TILE`] × [`TILE`] pixels (aligned to the full frame), never above the
//! global level and never below the noise floor, so that dim targets (far
//! from the ring light) are found next to bright ones: where the brightest
//! pixel near a tile (its own and its eight neighbours', sampled on every
//! [`PEAK_STEP`]-th row, every column) rises less than half as high above
//! the background as the frame's brightest, the tile's level drops to a
//! share of that local peak's height above the background. Tiles with
//! nothing above the (local) floor, or with bright surroundings, keep the
//! global level. With the histogram on the same rows, one pass over them
//! gives both ([`LocalLevels::histogram_and_peaks`]).

use crate::pixel::{max_of_rows, Pixel, Plane};

/// What separates a target's pixels from the background: a pixel is
/// foreground when its grey value lies strictly above the level. One
/// global level per frame today; the stages only ever ask this type (per
/// value, or per block of a row), so a local (per-tile) level can replace
/// the global one here without touching them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Threshold {
    level: u32,
}

impl Threshold {
    /// One level for the whole frame.
    pub const fn global(level: u32) -> Self {
        Threshold { level }
    }

    /// The level: values strictly above it are foreground.
    #[inline(always)]
    pub const fn level(self) -> u32 {
        self.level
    }

    /// Whether a grey value belongs to a target.
    #[inline(always)]
    pub fn is_foreground(self, value: u32) -> bool {
        value > self.level
    }

    /// Bit `i` set where `block[i]` is foreground, for a block of a row of
    /// at most 64 pixels (vectorised per pixel type).
    #[inline(always)]
    pub fn foreground_mask<P: Pixel>(self, block: &[P]) -> u64 {
        P::above_mask(block, self)
    }

    /// Whether no pixel of a block of a row is foreground.
    #[inline(always)]
    pub fn all_background<P: Pixel>(self, block: &[P]) -> bool {
        !self.is_foreground(P::max_of(block))
    }
}

/// Side of a tile of the local levels, px (the labeller's block of 64
/// pixels of a row lies in one tile).
pub const TILE: usize = 64;
const TILE_SHIFT: u32 = 6;

/// The tile peaks are sampled on every `PEAK_STEP`-th row (full-frame rows
/// `≡ 1 (mod PEAK_STEP)`, every column): a dot's bright core spans more
/// rows than that, and the peak is taken over a tile and its neighbours.
/// The default histogram step, so that one pass reads those rows once.
pub const PEAK_STEP: usize = 4;

/// One level per tile of a window: its buffers, sized once for the
/// largest window.
#[derive(Debug, Clone)]
pub struct LocalLevels {
    /// Levels, row-major over the window's tiles.
    levels: Vec<u32>,
    /// Sampled peak per tile.
    peaks: Vec<u32>,
    /// Per tile, the largest peak of it and its left and right neighbours.
    across: Vec<u32>,
    /// Full-frame tile index of the window's first tile column and row.
    tile_col0: usize,
    tile_row0: usize,
    /// Tiles per row and rows of tiles of the window.
    cols: usize,
    rows: usize,
    /// Whether any tile's level is below the global one.
    any_local: bool,
    /// Per row of tiles, the level of all its tiles when they share one,
    /// else [`MIXED`].
    uniform: Vec<u32>,
}

/// [`LocalLevels::uniform`]'s mark of a row of tiles at different levels
/// (above every level: levels are grey values, at most 16 bits).
const MIXED: u32 = u32::MAX;

/// Sampled rows per row of tiles.
const TILE_SAMPLES: usize = TILE / PEAK_STEP;

/// The sampled rows of one row of tiles not yet taken into the tile peaks
/// (every sampled row of a row of tiles is read by the histogram's pass
/// before its peaks are taken, from the cache): a tile's peak over all of
/// them in one go, 16 pixels at a time for 8-bit frames, instead of one
/// maximum per tile and row (find_threshold 5.59 M -> 3.59 M instructions per
/// 8 frames).
struct TileRowSamples<'a, P> {
    rows: [&'a [P]; TILE_SAMPLES],
    /// How many of `rows` are held.
    n: usize,
    /// Full-frame tile row of the rows held.
    tile_row: usize,
}

impl<P> TileRowSamples<'_, P> {
    fn new() -> Self {
        TileRowSamples {
            rows: [&[]; TILE_SAMPLES],
            n: 0,
            tile_row: 0,
        }
    }
}

/// The levels of the tiles that one row of a window crosses: tile `k`
/// holds the window offsets `64 k − lead .. 64 (k + 1) − lead` of the row.
#[derive(Debug, Clone, Copy)]
pub struct TileRow<'a> {
    levels: &'a [u32],
    /// Pixels of the first tile left of the window (`< TILE`).
    lead: usize,
    /// The level of all the row's tiles, if they share one, else
    /// [`MIXED`].
    uniform: u32,
}

impl TileRow<'_> {
    /// The threshold of the tile holding window offset `i` of the row.
    #[inline(always)]
    pub fn at(&self, i: usize) -> Threshold {
        self.tile((i + self.lead) >> TILE_SHIFT)
    }

    /// The threshold of the row's tile `k`.
    #[inline(always)]
    pub fn tile(&self, k: usize) -> Threshold {
        Threshold::global(self.levels[k])
    }

    /// The lowest level of the tiles `k..k + 4`.
    #[inline(always)]
    pub fn lowest4(&self, k: usize) -> Threshold {
        let Some(&[l0, l1, l2, l3]) = self.levels.get(k..k + 4) else {
            panic!("four tiles from {k}")
        };
        Threshold::global(l0.min(l1).min(l2.min(l3)))
    }

    /// The threshold of every tile of the row, if they share one (most
    /// rows of a frame: only tiles in dim surroundings are lowered).
    #[inline(always)]
    pub fn uniform(&self) -> Option<Threshold> {
        (self.uniform != MIXED).then_some(Threshold::global(self.uniform))
    }

    /// How many pixels of the row's first tile lie left of the window.
    #[inline(always)]
    pub fn lead(&self) -> usize {
        self.lead
    }
}

impl LocalLevels {
    /// Levels for windows of up to `max_width × max_height` pixels.
    pub fn new(max_width: usize, max_height: usize) -> Self {
        // A window not aligned to the tiles crosses one more of them.
        let n = (max_width.div_ceil(TILE) + 1) * (max_height.div_ceil(TILE) + 1);
        LocalLevels {
            levels: Vec::with_capacity(n),
            peaks: Vec::with_capacity(n),
            across: Vec::with_capacity(n),
            tile_col0: 0,
            tile_row0: 0,
            cols: 0,
            rows: 0,
            any_local: false,
            uniform: Vec::with_capacity(max_height.div_ceil(TILE) + 1),
        }
    }

    /// Marks the rows of tiles whose tiles share one level
    /// ([`TileRow::uniform`]).
    fn mark_uniform_rows(&mut self) {
        self.uniform.clear();
        for tiles in self.levels.chunks_exact(self.cols) {
            let first = tiles[0];
            let same = tiles.iter().all(|&l| l == first);
            self.uniform.push(if same { first } else { MIXED });
        }
    }

    /// Lays out the tiles of the window `plane`.
    fn layout<P>(&mut self, plane: &Plane<'_, P>) {
        self.tile_col0 = plane.col0 >> TILE_SHIFT;
        self.tile_row0 = plane.row0 >> TILE_SHIFT;
        self.cols = ((plane.col0 + plane.width.max(1) - 1) >> TILE_SHIFT) - self.tile_col0 + 1;
        self.rows = ((plane.row0 + plane.height.max(1) - 1) >> TILE_SHIFT) - self.tile_row0 + 1;
        self.any_local = false;
    }

    /// Every tile of the window at the global level of `t`.
    pub fn set_global<P>(&mut self, plane: &Plane<'_, P>, t: Threshold) {
        self.layout(plane);
        self.levels.clear();
        self.levels.resize(self.cols * self.rows, t.level());
        self.uniform.clear();
        self.uniform.resize(self.rows, t.level());
    }

    /// Tests: the window's tiles at the levels `level(tile_col, tile_row)`
    /// (full-frame tile indices).
    #[cfg(test)]
    pub(crate) fn set_each<P>(
        &mut self,
        plane: &Plane<'_, P>,
        level: impl Fn(usize, usize) -> u32,
    ) {
        self.layout(plane);
        self.levels.clear();
        for r in 0..self.rows {
            for c in 0..self.cols {
                self.levels
                    .push(level(self.tile_col0 + c, self.tile_row0 + r));
            }
        }
        self.any_local = true;
        self.mark_uniform_rows();
    }

    /// The local levels of the window `plane`: per tile, the largest value
    /// on every [`PEAK_STEP`]-th row (full-frame rows `≡ 1 mod PEAK_STEP`)
    /// of the tile and its eight neighbours is the local peak; where it
    /// rises less than half as high above the background as the frame's
    /// brightest sampled pixel, the level is `share` of the peak's height
    /// above the background, between the local floor (`floor` above the
    /// background: a lower noise multiple than the global floor's, as only
    /// tiles with a peak above it are lowered) and the global level; tiles
    /// whose peak does not rise above the local floor keep the global level.
    pub fn compute<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        t: &ThresholdResult,
        share: f64,
        floor: f64,
    ) {
        self.sample_peaks(plane);
        self.from_peaks(plane, t, share, floor);
    }

    /// The tile peaks of the window `plane` alone (a pass of its own over
    /// the sampled rows).
    pub fn sample_peaks<P: Pixel>(&mut self, plane: &Plane<'_, P>) {
        self.layout(plane);
        self.clear_peaks();
        let mut pending = TileRowSamples::new();
        for_sampled_rows(plane, PEAK_STEP, |row, line| {
            self.add_row_peaks(plane, &mut pending, row, line)
        });
        self.raise_peaks(plane, &mut pending);
    }

    /// The sub-sampled histogram of the window `plane` ([`histogram`], same
    /// arguments and result) and its tile peaks ([`LocalLevels::sample_peaks`]);
    /// when `step` is [`PEAK_STEP`] both come from one pass over the rows.
    pub fn histogram_and_peaks<P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        step: usize,
        shift: u32,
        max_value: u32,
        hist: &mut [u32],
    ) -> u32 {
        if step != PEAK_STEP {
            self.sample_peaks(plane);
            return histogram(plane, step, shift, max_value, hist);
        }
        self.layout(plane);
        self.clear_peaks();
        let mut pending = TileRowSamples::new();
        let n = histogram_rows(plane, step, shift, max_value, hist, |row, line| {
            self.add_row_peaks(plane, &mut pending, row, line)
        });
        self.raise_peaks(plane, &mut pending);
        n
    }

    fn clear_peaks(&mut self) {
        self.peaks.clear();
        self.peaks.resize(self.cols * self.rows, 0);
    }

    /// Takes the sampled full-frame row `row` (`line`, the window's pixels
    /// of it) into the peaks: held with the other sampled rows of its row
    /// of tiles, whose peaks are raised once the row of tiles is complete.
    #[inline(always)]
    fn add_row_peaks<'a, P: Pixel>(
        &mut self,
        plane: &Plane<'_, P>,
        pending: &mut TileRowSamples<'a, P>,
        row: usize,
        line: &'a [P],
    ) {
        let tile_row = row >> TILE_SHIFT;
        if pending.n == TILE_SAMPLES || (pending.n > 0 && pending.tile_row != tile_row) {
            self.raise_peaks(plane, pending);
        }
        pending.tile_row = tile_row;
        pending.rows[pending.n] = line;
        pending.n += 1;
    }

    /// Raises the peaks of the tiles that the rows held by `pending` (of
    /// one row of tiles) cross, each tile's over all those rows at once,
    /// and empties `pending`.
    fn raise_peaks<P: Pixel>(&mut self, plane: &Plane<'_, P>, pending: &mut TileRowSamples<'_, P>) {
        let rows = &pending.rows[..pending.n];
        pending.n = 0;
        let Some(width) = rows.first().map(|r| r.len()) else {
            return;
        };
        let tr = (pending.tile_row - self.tile_row0) * self.cols;
        let mut peaks = self.peaks[tr..tr + self.cols].iter_mut();
        let mut raise = |m: u32| {
            if let Some(p) = peaks.next() {
                *p = (*p).max(m);
            }
        };
        // The first tile (short when the window starts inside it), whole
        // tiles four at a time, then one at a time, then a short last one.
        let mut i = 0;
        if !plane.col0.is_multiple_of(TILE) {
            i = (TILE - plane.col0 % TILE).min(width);
            raise(max_of_rows(rows, 0, i));
        }
        while i + 4 * TILE <= width {
            P::tile_peaks::<4>(rows, i).into_iter().for_each(&mut raise);
            i += 4 * TILE;
        }
        while i + TILE <= width {
            P::tile_peaks::<1>(rows, i).into_iter().for_each(&mut raise);
            i += TILE;
        }
        if i < width {
            raise(max_of_rows(rows, i, width));
        }
    }

    /// The levels from the peaks sampled last (on the same window `plane`,
    /// by [`LocalLevels::sample_peaks`] or
    /// [`LocalLevels::histogram_and_peaks`]); see [`LocalLevels::compute`].
    pub fn from_peaks<P>(
        &mut self,
        plane: &Plane<'_, P>,
        t: &ThresholdResult,
        share: f64,
        floor: f64,
    ) {
        let global = t.threshold.level();
        self.set_global(plane, t.threshold);
        let bg = t.background;
        let floor = ((bg + floor).ceil().max(0.0) as u32).min(global);
        // Nothing can be lowered when the global level is the local floor
        // already.
        if t.status != FrameStatus::Normal
            || share <= 0.0
            || floor >= global
            || self.peaks.len() != self.levels.len()
        {
            return;
        }
        // The peak of a tile's surroundings (its own and its eight
        // neighbours'): the largest along each row of tiles first, then of
        // those along the columns.
        let (rows, cols) = (self.rows, self.cols);
        self.across.clear();
        for p in self.peaks.chunks_exact(cols) {
            for c in 0..cols {
                let left = p[c.saturating_sub(1)];
                let right = p[(c + 1).min(cols - 1)];
                self.across.push(p[c].max(left).max(right));
            }
        }
        for r in 0..rows {
            let (up, down) = (r.saturating_sub(1) * cols, (r + 1).min(rows - 1) * cols);
            for c in 0..cols {
                let a = &self.across;
                let peak = a[r * cols + c].max(a[up + c]).max(a[down + c]);
                // Only surroundings that peak at less than half the height
                // of the frame's brightest sampled pixel: elsewhere the
                // global level serves (and the frame is labelled exactly
                // as with one level).
                if peak <= floor || peak as f64 - bg >= 0.5 * (t.max_sampled as f64 - bg) {
                    continue;
                }
                let level = (bg + share * (peak as f64 - bg)).ceil();
                let level = (level.max(floor as f64) as u32).min(global);
                if level < global {
                    self.levels[r * self.cols + c] = level;
                    self.any_local = true;
                }
            }
        }
        self.mark_uniform_rows();
    }

    /// Whether any tile's level lies below the global level.
    pub fn any_local(&self) -> bool {
        self.any_local
    }

    /// The tiles of full-frame row `row` of the window `plane` the levels
    /// were laid out for.
    #[inline(always)]
    pub fn row<P>(&self, plane: &Plane<'_, P>, row: usize) -> TileRow<'_> {
        let tr = (row >> TILE_SHIFT) - self.tile_row0;
        TileRow {
            levels: &self.levels[tr * self.cols..(tr + 1) * self.cols],
            lead: plane.col0 - (self.tile_col0 << TILE_SHIFT),
            uniform: self.uniform[tr],
        }
    }

    /// The threshold at full-frame position `(col, row)` inside the window.
    pub fn at(&self, col: usize, row: usize) -> Threshold {
        let tc = (col >> TILE_SHIFT)
            .saturating_sub(self.tile_col0)
            .min(self.cols - 1);
        let tr = (row >> TILE_SHIFT)
            .saturating_sub(self.tile_row0)
            .min(self.rows - 1);
        Threshold::global(self.levels[tr * self.cols + tc])
    }
}

/// Most bins of the histogram (12 bits).
pub const MAX_BINS: usize = 4096;

/// What the threshold stage concluded about a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameStatus {
    /// A usable threshold was found; targets (if any) were searched.
    Normal,
    /// Nothing rises above the noise floor: no targets (all dark or nearly uniform).
    Empty,
    /// Most of the frame is saturated: no targets are searched.
    Saturated,
    /// More runs or blobs than the detector's capacity (a cluttered or
    /// noisy frame): no targets are reported.
    Cluttered,
}

impl FrameStatus {
    /// The status's name in outputs: `normal`, `empty`, `saturated`,
    /// `cluttered`.
    pub fn name(&self) -> &'static str {
        match self {
            FrameStatus::Normal => "normal",
            FrameStatus::Empty => "empty",
            FrameStatus::Saturated => "saturated",
            FrameStatus::Cluttered => "cluttered",
        }
    }
}

/// Result of the threshold stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThresholdResult {
    /// The threshold found (meaningful when `status` is normal).
    pub threshold: Threshold,
    /// Otsu's threshold before the floor was applied (grey value).
    pub otsu: u32,
    /// The noise floor (grey value).
    pub floor: u32,
    /// Background level (median of the sampled pixels), grey value.
    pub background: f64,
    /// Noise estimate (robust σ of the dark half), grey values.
    pub noise: f64,
    /// Largest sampled grey value.
    pub max_sampled: u32,
    /// Outcome.
    pub status: FrameStatus,
}

/// Parameters of the threshold stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThresholdParams {
    /// Sub-sampling step of the histogram (rows and columns).
    pub step: usize,
    /// The floor lies at least this many noise σ above the background.
    pub noise_factor: f64,
    /// ... and at least this fraction of the saturation level above it.
    pub min_contrast: f64,
    /// A frame whose median is at or above this fraction of the saturation
    /// level counts as saturated.
    pub saturated_median: f64,
}

/// Bin shift for a saturation level: values are binned by `v >> shift`.
pub fn bin_shift(max_value: u32) -> u32 {
    let bits = 32 - max_value.max(1).leading_zeros();
    bits.saturating_sub(12)
}

/// The first offset from `origin` of the sampling grid: full-frame rows
/// (columns) `≡ 1 (mod step)` (every one for step 1).
fn grid_start(origin: usize, step: usize) -> usize {
    let phase = (step > 1) as usize;
    (phase + step - origin % step) % step
}

/// Fills `hist[..=max_value >> shift]` (`hist` holds at least that many
/// bins; those above are left as they are) with the sub-sampled histogram
/// of the window `plane` and returns the number of samples.
pub fn histogram<P: Pixel>(
    plane: &Plane<'_, P>,
    step: usize,
    shift: u32,
    max_value: u32,
    hist: &mut [u32],
) -> u32 {
    histogram_rows(plane, step, shift, max_value, hist, |_, _| {})
}

/// [`histogram`], calling `row_seen(row, pixels)` with every sampled
/// full-frame row (all its pixels in the window) as it goes.
#[inline(always)]
fn histogram_rows<'a, P: Pixel>(
    plane: &Plane<'a, P>,
    step: usize,
    shift: u32,
    max_value: u32,
    hist: &mut [u32],
    row_seen: impl FnMut(usize, &'a [P]),
) -> u32 {
    let step = step.max(1);
    let top = (max_value >> shift) as usize;
    // Only the bins up to the top are cleared (not all of `MAX_BINS` for
    // 8-bit frames: the 8-bit pass writes its 256 bins whole).
    let hist = &mut hist[..=top];
    if shift == 0 && P::MAX <= 255 && top >= 255 && matches!(step, 2 | 4) {
        hist[256..].fill(0);
        return if step == 2 {
            histogram_8bit::<P, 2>(plane, hist, row_seen)
        } else {
            histogram_8bit::<P, 4>(plane, hist, row_seen)
        };
    }
    hist.fill(0);
    histogram_any(plane, step, shift, max_value, hist, row_seen)
}

/// Sampled rows ahead of the one read whose lines the histogram asks for.
/// The histogram's pass is the first to read a frame, which is mostly not
/// in the cache: reading only every `step`-th row, it waits for each row
/// from memory unless the row was asked for before (`photopose bench`:
/// the threshold stage 88–117 µs → 52–58 µs with 2 to 4 rows ahead).
const SAMPLED_ROWS_AHEAD: usize = 3;

/// Calls `f(row, pixels)` with every sampled full-frame row of `plane`
/// (every `step`-th row of the frame's grid, [`grid_start`]), having asked
/// for the lines of the row `SAMPLED_ROWS_AHEAD` samples on.
#[inline(always)]
fn for_sampled_rows<'a, P: Pixel>(
    plane: &Plane<'a, P>,
    step: usize,
    mut f: impl FnMut(usize, &'a [P]),
) {
    let mut row = plane.row0 + grid_start(plane.row0, step);
    while row <= plane.last_row() {
        let ahead = row + SAMPLED_ROWS_AHEAD * step;
        if ahead <= plane.last_row() {
            prefetch_row(plane.row(ahead));
        }
        f(row, plane.row(row));
        row += step;
    }
}

/// Asks for every cache line of a row's pixels (a prefetch hint, as
/// [`Plane::prefetch`] gives for a box): the first pixel of each 64 bytes
/// of the row, and its last pixel (a row not aligned to the lines ends in
/// one more). A row is one stretch of memory: whole 64-byte parts, no
/// bounds per line (find_threshold 3.10 M -> 2.76 M instructions per 8
/// frames).
#[inline(always)]
fn prefetch_row<P>(line: &[P]) {
    let step = (64 / std::mem::size_of::<P>()).max(1);
    let mut parts = line.chunks_exact(step);
    for part in &mut parts {
        crate::prefetch::line(part);
    }
    crate::prefetch::line(parts.remainder());
    crate::prefetch::line(&line[line.len().saturating_sub(1)..]);
}

/// [`histogram_rows`] for any pixel type, step and binning.
#[inline(always)]
fn histogram_any<'a, P: Pixel>(
    plane: &Plane<'a, P>,
    step: usize,
    shift: u32,
    max_value: u32,
    hist: &mut [u32],
    mut row_seen: impl FnMut(usize, &'a [P]),
) -> u32 {
    let top = (max_value >> shift) as usize;
    let mut n = 0u32;
    let col_start = grid_start(plane.col0, step);
    for_sampled_rows(plane, step, |row, line| {
        row_seen(row, line);
        let mut col = col_start;
        while col < line.len() {
            let b = ((line[col].value().min(max_value)) >> shift) as usize;
            hist[b.min(top)] += 1;
            n += 1;
            col += step;
        }
    });
    n
}

/// [`histogram_rows`] of 8-bit values (no binning, no clamping) on every
/// `STEP`-th row and column: four interleaved partial histograms, so that
/// runs of equal grey values (the background) do not wait on each other's
/// increments.
#[inline(always)]
fn histogram_8bit<'a, P: Pixel, const STEP: usize>(
    plane: &Plane<'a, P>,
    hist: &mut [u32],
    mut row_seen: impl FnMut(usize, &'a [P]),
) -> u32 {
    let mut part = [[0u32; 256]; 4];
    let mut n = 0u32;
    let bin = |p: P| p.value() as u8 as usize;
    let col_start = grid_start(plane.col0, STEP);
    for_sampled_rows(plane, STEP, |row, whole| {
        row_seen(row, whole);
        let line = &whole[col_start.min(plane.width)..];
        // Sixteen samples per step of the loop (its counting spread over
        // more samples: find_threshold 3.59 M -> 3.23 M instructions per 8
        // frames), then four, then one.
        let mut chunks = line.chunks_exact(16 * STEP);
        for c in &mut chunks {
            for q in 0..4 {
                for (k, part) in part.iter_mut().enumerate() {
                    part[bin(c[(4 * q + k) * STEP])] += 1;
                }
            }
        }
        let mut quads = chunks.remainder().chunks_exact(4 * STEP);
        for c in &mut quads {
            for (k, part) in part.iter_mut().enumerate() {
                part[bin(c[k * STEP])] += 1;
            }
        }
        for p in quads.remainder().iter().step_by(STEP) {
            part[0][bin(*p)] += 1;
        }
        n += line.len().div_ceil(STEP) as u32;
    });
    for (i, h) in hist.iter_mut().take(256).enumerate() {
        *h = part[0][i] + part[1][i] + part[2][i] + part[3][i];
    }
    n
}

/// The value below which a fraction `q` of the histogram lies (bin index).
fn quantile(hist: &[u32], total: u32, q: f64) -> usize {
    let target = (q * total as f64).ceil().max(1.0) as u64;
    let mut acc = 0u64;
    for (i, &h) in hist.iter().enumerate() {
        acc += h as u64;
        if acc >= target {
            return i;
        }
    }
    hist.len().saturating_sub(1)
}

/// Otsu's threshold (bin index: foreground is `bin > t`) over `hist`; `None`
/// if the histogram has a single occupied bin.
pub fn otsu(hist: &[u32]) -> Option<usize> {
    let total: f64 = hist.iter().map(|&h| h as f64).sum();
    if total == 0.0 {
        return None;
    }
    let sum_all: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &h)| i as f64 * h as f64)
        .sum();
    let mut w0 = 0.0;
    let mut sum0 = 0.0;
    let mut best = None;
    let mut best_var = 0.0;
    for (t, &h) in hist.iter().enumerate() {
        w0 += h as f64;
        sum0 += t as f64 * h as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let m0 = sum0 / w0;
        let m1 = (sum_all - sum0) / w1;
        let var = w0 * w1 * (m1 - m0) * (m1 - m0);
        if var > best_var {
            best_var = var;
            best = Some(t);
        }
    }
    best
}

/// The threshold of a frame from its histogram (binned with `shift`).
pub fn threshold(
    hist: &[u32],
    total: u32,
    shift: u32,
    max_value: u32,
    p: &ThresholdParams,
) -> ThresholdResult {
    let top = (max_value >> shift) as usize;
    let hist = &hist[..=top];
    let scale = (1u32 << shift) as f64;
    let centre = |bin: usize| (bin as f64 + 0.5) * scale - 0.5;
    let mut r = ThresholdResult {
        threshold: Threshold::global(max_value),
        otsu: max_value,
        floor: max_value,
        background: 0.0,
        noise: 0.0,
        max_sampled: 0,
        status: FrameStatus::Empty,
    };
    if total == 0 {
        return r;
    }
    let median = quantile(hist, total, 0.5);
    let q25 = quantile(hist, total, 0.25);
    let max_bin = hist.iter().rposition(|&h| h > 0).unwrap_or(0);
    r.background = if shift == 0 {
        median as f64
    } else {
        centre(median)
    };
    // Robust σ from the dark half (the targets are in the bright tail);
    // at least the quantisation step.
    r.noise = ((median - q25) as f64 * scale / 0.6745).max(scale * 0.5);
    r.max_sampled = ((max_bin as u32) << shift).min(max_value);
    if median as f64 >= p.saturated_median * top as f64 {
        r.status = FrameStatus::Saturated;
        return r;
    }
    let floor_above = (p.noise_factor * r.noise).max(p.min_contrast * max_value as f64);
    let floor = (r.background + floor_above).ceil().min(max_value as f64) as u32;
    r.floor = floor;
    let otsu_value = otsu(hist)
        .map(|t| (((t as u32 + 1) << shift) - 1).min(max_value))
        .unwrap_or(max_value);
    r.otsu = otsu_value;
    // A saturated target pixel is foreground even if the floor is at the top.
    r.threshold = Threshold::global(otsu_value.max(floor).min(max_value.saturating_sub(1)));
    r.status = FrameStatus::Normal;
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::window;

    const P: ThresholdParams = ThresholdParams {
        step: 1,
        noise_factor: 8.0,
        min_contrast: 0.04,
        saturated_median: 0.9,
    };

    fn hist_of(values: &[u8]) -> (Vec<u32>, u32) {
        let mut h = vec![0u32; 256];
        let n = histogram(&Plane::whole(values, values.len(), 1), 1, 0, 255, &mut h);
        (h, n)
    }

    #[test]
    fn otsu_splits_two_modes() {
        let mut v = vec![20u8; 900];
        v.extend(std::iter::repeat_n(200u8, 100));
        let (h, n) = hist_of(&v);
        let t = threshold(&h, n, 0, 255, &P);
        assert_eq!(t.status, FrameStatus::Normal);
        assert!(
            t.threshold.level() >= 20 && t.threshold.level() < 200,
            "{t:?}"
        );
        assert_eq!(t.background, 20.0);
    }

    #[test]
    fn floor_keeps_noise_out() {
        // Background 30 ± a few DN, a handful of pixels 8 DN up.
        let mut v: Vec<u8> = (0..1000).map(|i| 28 + (i % 5) as u8).collect();
        v.extend([40u8; 5]);
        let (h, n) = hist_of(&v);
        let t = threshold(&h, n, 0, 255, &P);
        assert!(t.threshold.level() > 40, "{t:?}");
    }

    #[test]
    fn degenerate_histograms() {
        let (h, n) = hist_of(&[0u8; 500]);
        let t = threshold(&h, n, 0, 255, &P);
        assert!(t.threshold.level() >= 10, "all dark: {t:?}");
        let (h, n) = hist_of(&[255u8; 500]);
        assert_eq!(threshold(&h, n, 0, 255, &P).status, FrameStatus::Saturated);
        let (h, n) = hist_of(&[120u8; 500]);
        let t = threshold(&h, n, 0, 255, &P);
        assert!(t.threshold.level() > 120, "uniform: {t:?}");
    }

    #[test]
    fn a_window_samples_the_grid_of_its_frame() {
        // 9 × 7 frame of distinct values; windows at even and odd origins.
        let w = 9;
        let data: Vec<u16> = (0..63u16).map(|v| 1000 + 37 * v).collect();
        for step in [2usize, 3] {
            for (c0, r0, ww, hh) in [(0, 0, 9, 7), (1, 2, 5, 4), (2, 1, 6, 5), (3, 3, 1, 1)] {
                let plane = window(&data, w, (c0, r0, ww, hh));
                let mut h = vec![0u32; MAX_BINS];
                let n = histogram(&plane, step, 4, 65535, &mut h);
                // The frame's grid: rows and columns ≡ step / 2 (mod step).
                let mut want = vec![0u32; MAX_BINS];
                let mut m = 0;
                for r in (r0..r0 + hh).filter(|r| r % step == step / 2) {
                    for c in (c0..c0 + ww).filter(|c| c % step == step / 2) {
                        want[(data[r * w + c] >> 4) as usize] += 1;
                        m += 1;
                    }
                }
                assert_eq!((n, &h), (m, &want), "step {step}, window at ({c0}, {r0})");
            }
        }
        // The 8-bit path (step 2, no binning) likewise.
        let data8: Vec<u8> = (0..63u8).map(|v| 3 * v).collect();
        let plane = window(&data8, w, (2, 1, 6, 5));
        let mut h = vec![0u32; MAX_BINS];
        let n = histogram(&plane, 2, 0, 255, &mut h);
        let odd: Vec<usize> = (1..6)
            .step_by(2)
            .flat_map(|r| (3..8).step_by(2).map(move |c| r * w + c))
            .collect();
        assert_eq!(n as usize, odd.len());
        assert!(odd.iter().all(|&i| h[data8[i] as usize] == 1));
    }

    #[test]
    fn local_levels_drop_only_in_dim_surroundings() {
        // 320 × 192 px (5 × 3 tiles), background 20, a bright patch (220)
        // in tile (0, 0) and a dim one (60) in tile (4, 2).
        let (w, h) = (320usize, 192usize);
        let mut v = vec![20u8; w * h];
        for (c0, r0, val) in [(20usize, 20usize, 220u8), (280, 150, 60)] {
            for r in r0..r0 + 6 {
                for c in c0..c0 + 6 {
                    v[r * w + c] = val;
                }
            }
        }
        let plane = Plane::whole(&v, w, h);
        let t = ThresholdResult {
            threshold: Threshold::global(100),
            otsu: 100,
            floor: 40,
            background: 20.0,
            noise: 2.0,
            max_sampled: 220,
            status: FrameStatus::Normal,
        };
        let mut l = LocalLevels::new(w, h);
        l.compute(&plane, &t, 0.3, 10.0);
        assert!(l.any_local());
        // Around the dim patch: 20 + 0.3 × 40 = 32, above the local floor 30.
        for (c, r) in [(290, 160), (230, 160), (290, 100), (230, 100)] {
            assert_eq!(l.at(c, r).level(), 32, "({c}, {r})");
        }
        // Near the bright patch, and where nothing rises: the global level.
        for (c, r) in [(25, 25), (100, 100), (160, 20), (10, 180)] {
            assert_eq!(l.at(c, r).level(), 100, "({c}, {r})");
        }
        // The row view: offsets map to their tiles.
        let row = l.row(&plane, 160);
        assert_eq!(row.at(0).level(), 100);
        assert_eq!(row.at(300).level(), 32);
        assert_eq!((row.tile(2).level(), row.tile(3).level()), (100, 32));
        assert_eq!((row.tile(4).level(), row.lead()), (32, 0));
        assert_eq!(row.lowest4(0).level(), 32);
        let top = l.row(&plane, 20);
        assert_eq!((top.lowest4(0).level(), top.lowest4(1).level()), (100, 100));
        // A row of tiles at one level says so; one with a lowered tile not.
        assert_eq!(top.uniform(), Some(Threshold::global(100)));
        assert_eq!(row.uniform(), None);
        // A local floor above the dim peak, or no share: one level.
        l.compute(&plane, &t, 0.3, 45.0);
        assert!(!l.any_local());
        l.compute(&plane, &t, 0.0, 10.0);
        assert!(!l.any_local());
        // A window not aligned to the tiles: the same levels in full-frame
        // coordinates.
        let win = window(&v, w, (200, 100, 110, 80));
        l.compute(&win, &t, 0.3, 10.0);
        assert_eq!(l.at(290, 160).level(), 32);
        assert_eq!(l.row(&win, 160).at(90).level(), 32);
        assert_eq!(l.row(&win, 160).lead(), 200 - 192);
        assert_eq!(l.row(&win, 160).tile(1).level(), 32);
    }

    #[test]
    fn the_grid_of_every_fourth_row_and_column_is_fixed_in_the_frame() {
        // 8-bit (the unrolled path) and 16-bit: rows and columns ≡ 1 (mod 4).
        let (w, h) = (37usize, 23usize);
        let data: Vec<u16> = (0..(w * h) as u16).map(|v| v % 251).collect();
        let data8: Vec<u8> = data.iter().map(|&v| v as u8).collect();
        for (c0, r0, ww, hh) in [(0, 0, w, h), (1, 2, 30, 20), (2, 1, 33, 17), (5, 5, 1, 1)] {
            let mut want = vec![0u32; MAX_BINS];
            let mut m = 0;
            for r in (r0..r0 + hh).filter(|r| r % 4 == 1) {
                for c in (c0..c0 + ww).filter(|c| c % 4 == 1) {
                    want[data[r * w + c] as usize] += 1;
                    m += 1;
                }
            }
            let mut got = vec![0u32; MAX_BINS];
            let n = histogram(&window(&data8, w, (c0, r0, ww, hh)), 4, 0, 255, &mut got);
            assert_eq!((n, &got), (m, &want), "8-bit window at ({c0}, {r0})");
            let n = histogram(&window(&data, w, (c0, r0, ww, hh)), 4, 0, 4095, &mut got);
            assert_eq!((n, &got), (m, &want), "16-bit window at ({c0}, {r0})");
        }
    }

    /// The one pass over the rows (histogram and tile peaks) gives what
    /// the two plain passes give, for 8- and 16-bit windows at any origin.
    #[test]
    fn histogram_and_peaks_in_one_pass_equal_the_plain_passes() {
        let (w, h) = (300usize, 200usize);
        // Pseudo-random grey values with bright patches.
        let mut x = 12345u32;
        let mut v16: Vec<u16> = (0..w * h)
            .map(|_| {
                x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (x >> 20) as u16
            })
            .collect();
        for (c0, r0) in [(30usize, 40usize), (170, 130), (250, 10)] {
            for r in r0..r0 + 7 {
                for c in c0..c0 + 9 {
                    v16[r * w + c] = 4000 - (r + c) as u16;
                }
            }
        }
        let v8: Vec<u8> = v16.iter().map(|&v| (v >> 4) as u8).collect();
        fn check<P: Pixel>(data: &[P], w: usize, h: usize, max: u32, what: &str) {
            let shift = bin_shift(max);
            for step in [1usize, 2, 3, 4, 5] {
                for (c0, r0, ww, hh) in [(0, 0, w, h), (3, 5, 200, 150), (64, 63, 130, 70)] {
                    let plane = window(data, w, (c0, r0, ww, hh));
                    let mut plain = LocalLevels::new(w, h);
                    let mut fused = LocalLevels::new(w, h);
                    let (mut h1, mut h2) = (vec![7u32; MAX_BINS], vec![9u32; MAX_BINS]);
                    let n1 = histogram(&plane, step, shift, max, &mut h1);
                    plain.sample_peaks(&plane);
                    let n2 = fused.histogram_and_peaks(&plane, step, shift, max, &mut h2);
                    let at = format!("{what}, step {step}, window at ({c0}, {r0})");
                    // The bins up to the top; those above left as they were.
                    let top = (max >> shift) as usize;
                    assert_eq!((n1, &h1[..=top]), (n2, &h2[..=top]), "{at}");
                    assert!(h1[top + 1..].iter().all(|&b| b == 7), "{at}");
                    assert_eq!(plain.peaks, fused.peaks, "{at}");
                    assert!(plain.peaks.iter().any(|&p| p > 0), "{at}");
                    let t = threshold(&h1, n1, shift, max, &P);
                    plain.from_peaks(&plane, &t, 0.3, 2.0);
                    fused.compute(&plane, &t, 0.3, 2.0);
                    assert_eq!(plain.levels, fused.levels, "{at}");
                }
            }
        }
        check(&v8, w, h, 255, "8-bit");
        check(&v16, w, h, 4095, "12-bit");
        check(&v16, w, h, 65535, "16-bit");
    }

    /// The histogram's samples and the tile peaks, taken pixel by pixel
    /// from the frame's grid (rows and columns `≡ 1 mod step`, every
    /// column for the peaks), equal the fast passes' (sixteen samples per
    /// step of the 8-bit histogram's loop, then four, then one; a tile's
    /// peak over all its sampled rows at once): 8 and 16 bits, windows at
    /// odd origins and of odd sizes, single bright pixels in every lane
    /// of a tile and at its edges.
    #[test]
    fn histogram_and_tile_peaks_equal_the_pixels() {
        use crate::testutil::Rng;
        let (w, h) = (333usize, 150usize);
        let mut rng = Rng::new(23);
        for round in 0..6 {
            let mut v: Vec<u16> = (0..w * h).map(|_| (rng.next_u64() % 40) as u16).collect();
            for _ in 0..[0, 3, 30, 300, 3000, 30][round] {
                let i = (rng.next_u64() % (w * h) as u64) as usize;
                v[i] = 40 + (rng.next_u64() % 200) as u16;
            }
            for c in [0usize, 63, 64, 127, 191, 192, 255, 256, 332] {
                let r = (rng.next_u64() % h as u64) as usize;
                v[r * w + c] = 250;
            }
            let v8: Vec<u8> = v.iter().map(|&x| x as u8).collect();
            let v16: Vec<u16> = v.iter().map(|&x| x * 257).collect();
            for (c0, r0, ww, hh) in [
                (0, 0, w, h),
                (1, 2, 331, 147),
                (3, 5, 200, 129),
                (64, 63, 130, 70),
                (70, 1, 63, 64),
                (5, 9, 17, 3),
            ] {
                let at = format!("round {round}, window ({c0}, {r0}, {ww}, {hh})");
                let samples = |step: usize| {
                    let on = move |k: usize| step == 1 || k % step == 1;
                    (r0..r0 + hh).filter(move |&r| on(r)).flat_map(move |r| {
                        (c0..c0 + ww).filter(move |&c| on(c)).map(move |c| (c, r))
                    })
                };
                for step in [2usize, 3, 4] {
                    let mut want = vec![0u32; MAX_BINS];
                    let mut n = 0;
                    for (c, r) in samples(step) {
                        want[v8[r * w + c] as usize] += 1;
                        n += 1;
                    }
                    let mut got = vec![5u32; MAX_BINS];
                    let plane = window(&v8, w, (c0, r0, ww, hh));
                    assert_eq!(histogram(&plane, step, 0, 255, &mut got), n, "{at}");
                    assert_eq!(got[..256], want[..256], "{at}, step {step}");
                    assert!(got[256..].iter().all(|&b| b == 5), "{at}");
                    // An 8-bit frame binned up to 12 bits: the bins above
                    // 255 cleared.
                    assert_eq!(histogram(&plane, step, 0, 4095, &mut got), n, "{at}");
                    assert_eq!(got, want, "{at}, step {step}, 12 bits");
                }
                // The peaks: per tile of the window's layout, over the
                // rows of the peaks' grid and every column.
                let mut levels = LocalLevels::new(w, h);
                let plane8 = window(&v8, w, (c0, r0, ww, hh));
                levels.layout(&plane8);
                let mut want = vec![0u32; levels.cols * levels.rows];
                for r in (r0..r0 + hh).filter(|r| r % PEAK_STEP == 1) {
                    for c in c0..c0 + ww {
                        let t = ((r >> TILE_SHIFT) - levels.tile_row0) * levels.cols
                            + (c >> TILE_SHIFT)
                            - levels.tile_col0;
                        want[t] = want[t].max(v[r * w + c] as u32);
                    }
                }
                assert!(want.iter().any(|&p| p > 0) || hh < 2, "{at}");
                levels.sample_peaks(&plane8);
                assert_eq!(levels.peaks, want, "{at}, 8-bit");
                let plane16 = window(&v16, w, (c0, r0, ww, hh));
                levels.sample_peaks(&plane16);
                let want16: Vec<u32> = want.iter().map(|&p| p * 257).collect();
                assert_eq!(levels.peaks, want16, "{at}, 16-bit");
                let mut hist = vec![0u32; MAX_BINS];
                levels.histogram_and_peaks(&plane8, 4, 0, 255, &mut hist);
                assert_eq!(levels.peaks, want, "{at}, 8-bit in one pass");
            }
        }
    }

    #[test]
    fn sixteen_bit_is_binned() {
        assert_eq!(bin_shift(255), 0);
        assert_eq!(bin_shift(4095), 0);
        assert_eq!(bin_shift(65535), 4);
        let mut v = vec![1000u16; 900];
        v.extend(std::iter::repeat_n(50_000u16, 100));
        let mut h = vec![0u32; MAX_BINS];
        let n = histogram(&Plane::whole(&v, v.len(), 1), 1, 4, 65535, &mut h);
        let t = threshold(&h, n, 4, 65535, &P);
        assert!(
            t.threshold.level() > 1000 && t.threshold.level() < 50_000,
            "{t:?}"
        );
    }
}
