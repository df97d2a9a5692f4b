//! Reading the 12-sector code ring of a coded target (`docs/coded-targets.md`).
//!
//! The centre dot's second moments give the ellipse `E` onto which the
//! plate's circle of radius `r` projects (a uniform disc of radius `r` has
//! second moment `r²/4` along each axis, so `E = 2·C^{1/2}`). Under the
//! affine approximation of the projection, the plate's circle of radius
//! `k·r` at plate angle `t` (counter-clockwise seen from +Z, i.e. in image
//! coordinates with `y'` up) lies at pixel offset `k·E·(cos t, −sin t)` up to
//! a constant angle, the ring's unknown phase. The minus sign is the row
//! axis pointing down: reading counter-clockwise in the image (`y'` up) is
//! reading clockwise in pixel coordinates.
//!
//! The reader
//! 1. takes the dark level from the gap (1.5 r) and the bright level from
//!    the dot, and puts the threshold half-way;
//! 2. samples the ring's middle (2.5 r) every 5° (six samples per sector) and
//!    finds the sector phase as the 12th harmonic of the grey-value
//!    transitions (the sector boundaries are 30° apart);
//! 3. classifies each sector from six samples over its central 20° at 2.5 r:
//!    every sample must lie on the same side of the threshold as its
//!    sector's mean, the mean must be clear of the threshold; the same at
//!    2.35 r and 2.65 r with smaller margins must give the same bits,
//!    otherwise the reading is uncertain and the target unidentified;
//! 4. checks that the gap and the quiet zone (3.5 r) are dark all round;
//! 5. reads bits in that order, first bit most significant, and takes the id
//!    of the canonical value; ids that the field does not carry as coded
//!    targets are not accepted.

use crate::num::{ceil_i64, floor_i64};
use crate::pixel::{Cells, Pixel, Plane};
use photopose_field::{codes, Field, TargetKind};
use wide::{f64x2, CmpGe, CmpGt, CmpLe, CmpLt};

/// The set of code ids a detector accepts (those of the field's coded targets).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CodeSet {
    bits: [u64; 6],
}

impl CodeSet {
    /// No ids: every ring reads as unidentified.
    pub const fn empty() -> Self {
        CodeSet { bits: [0; 6] }
    }

    /// All 350 ids (for tests and tools; a real field should be used on plates).
    pub fn all() -> Self {
        let mut s = Self::empty();
        for id in 1..=codes::COUNT as u64 {
            s.insert(id);
        }
        s
    }

    /// The ids of the coded targets of `field`.
    pub fn from_field(field: &Field) -> Self {
        Self::from_ids(
            field
                .targets()
                .iter()
                .filter(|t| t.kind == TargetKind::Coded)
                .map(|t| t.id),
        )
    }

    /// From a list of ids (ids outside 1..=350 are ignored).
    pub fn from_ids(ids: impl IntoIterator<Item = u64>) -> Self {
        let mut s = Self::empty();
        for id in ids {
            s.insert(id);
        }
        s
    }

    /// Adds an id (ignored outside 1..=350).
    pub fn insert(&mut self, id: u64) {
        if (1..=codes::COUNT as u64).contains(&id) {
            self.bits[(id / 64) as usize] |= 1 << (id % 64);
        }
    }

    /// Whether the set holds `id`.
    pub fn contains(&self, id: u64) -> bool {
        (1..=codes::COUNT as u64).contains(&id)
            && self.bits[(id / 64) as usize] >> (id % 64) & 1 == 1
    }

    /// Number of ids.
    pub fn len(&self) -> usize {
        self.bits.iter().map(|b| b.count_ones() as usize).sum()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Why a ring could not be read with certainty.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Uncertainty {
    /// Part of the ring or its surroundings lies outside the image.
    OutsideImage,
    /// Too little contrast between the dot and the gap.
    LowContrast,
    /// Something bright in the gap between dot and ring.
    GapNotDark,
    /// Something bright in the quiet zone outside the ring.
    QuietZoneNotDark,
    /// No sector boundaries found (no transitions around the ring).
    NoPhase,
    /// A sector's mean lies too close to the threshold.
    MarginalSector,
    /// The samples within a sector disagree.
    SectorDisagrees,
    /// Inner, middle and outer readings of the ring differ.
    RadiiDisagree,
}

/// The outcome of reading a target's ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CodeStatus {
    /// Nothing bright in the ring zone: an uncoded target.
    NoRing,
    /// A certain reading of a code that the field carries.
    Read {
        /// The code id.
        id: u64,
        /// Its canonical value.
        value: u16,
    },
    /// A certain reading whose code is not in the field (or is no code at
    /// all: `value` 4095, a full ring); the target is unidentified.
    NotInField {
        /// The canonical value read.
        value: u16,
    },
    /// The bits could not be read with certainty; the target is unidentified.
    Uncertain(Uncertainty),
}

impl CodeStatus {
    /// The outcome's name in outputs: `read`, `no_ring`, `not_in_field`,
    /// or the reason a reading was uncertain (`uncertain_low_contrast` …).
    pub fn name(&self) -> &'static str {
        match self {
            CodeStatus::NoRing => "no_ring",
            CodeStatus::Read { .. } => "read",
            CodeStatus::NotInField { .. } => "not_in_field",
            CodeStatus::Uncertain(u) => match u {
                Uncertainty::OutsideImage => "uncertain_outside_image",
                Uncertainty::LowContrast => "uncertain_low_contrast",
                Uncertainty::GapNotDark => "uncertain_gap_not_dark",
                Uncertainty::QuietZoneNotDark => "uncertain_quiet_zone_not_dark",
                Uncertainty::NoPhase => "uncertain_no_phase",
                Uncertainty::MarginalSector => "uncertain_marginal_sector",
                Uncertainty::SectorDisagrees => "uncertain_sector_disagrees",
                Uncertainty::RadiiDisagree => "uncertain_radii_disagree",
            },
        }
    }

    /// The canonical 12-bit value read, if the reading was certain.
    pub fn value(&self) -> Option<u16> {
        match self {
            CodeStatus::Read { value, .. } | CodeStatus::NotInField { value } => Some(*value),
            _ => None,
        }
    }

    /// The id, if one was read.
    pub fn id(&self) -> Option<u64> {
        match self {
            CodeStatus::Read { id, .. } => Some(*id),
            _ => None,
        }
    }
}

/// Parameters of the reader.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CodeParams {
    /// Least dot-to-gap contrast to read a code, grey values.
    pub min_contrast: f64,
    /// Least dot-to-gap contrast to judge the dot's isolation (gap dark,
    /// ring present) at all, grey values; at most `min_contrast`. Between
    /// the two a dot is judged but its ring never read (dim targets found
    /// with a local threshold).
    pub min_isolation_contrast: f64,
    /// A sector's mean must be this fraction of the contrast away from the threshold.
    pub sector_margin: f64,
    /// Each sample must lie on its sector's side, at least this fraction of
    /// the contrast away from the threshold.
    pub sample_margin: f64,
    /// Gap and quiet-zone samples must stay below dark + this fraction of the contrast.
    pub dark_tolerance: f64,
}

/// Whether the dark zone between the dot and its ring (1 r to 2 r, the
/// quiet zone of an uncoded target) is dark all round.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gap {
    /// Dark all round: the dot is isolated, as every target's is.
    Dark,
    /// Something bright in it: not a target's dot (a ring part, a merged
    /// reflection).
    NotDark,
    /// Part of it lies outside the image.
    Outside,
}

/// Result of reading a ring.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// The gap around the dot.
    pub gap: Gap,
    /// Outcome.
    pub status: CodeStatus,
    /// Whether bright marks were found in the ring zone (a coded target).
    pub ring_present: bool,
    /// Raw bits in reading order (first read most significant) when read.
    pub raw: u16,
    /// Bright (dot) level.
    pub bright: f64,
    /// Dark (gap) level.
    pub dark: f64,
}

/// Sampling geometry: centre and the matrix `E` that maps the plate's unit
/// circle (in units of the dot radius) into pixel offsets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RingFrame {
    /// Centre column.
    pub col: f64,
    /// Centre row.
    pub row: f64,
    /// `E` (symmetric): `[exx, exy, eyy]`.
    pub e: [f64; 3],
}

impl RingFrame {
    /// The frame of a dot whose central second moments are `(cxx, cyy, cxy)`.
    pub fn from_moments(col: f64, row: f64, cxx: f64, cyy: f64, cxy: f64) -> Option<Self> {
        // Symmetric square root of 4C: sqrt(M) = (M + sqrt(det) I) / sqrt(tr + 2 sqrt(det)).
        let (a, b, c) = (4.0 * cxx, 4.0 * cxy, 4.0 * cyy);
        let det = a * c - b * b;
        if !(det > 0.0 && a > 0.0 && c > 0.0) {
            return None;
        }
        let sd = det.sqrt();
        let t = (a + c + 2.0 * sd).sqrt();
        Some(RingFrame {
            col,
            row,
            e: [(a + sd) / t, b / t, (c + sd) / t],
        })
    }

    /// Pixel position at radius `k` (units of the dot radius) and plate angle
    /// `t` (counter-clockwise in the image, `y'` up).
    #[inline]
    pub fn point(&self, k: f64, t: f64) -> (f64, f64) {
        let (s, c) = t.sin_cos();
        let (x, y) = (k * c, -k * s);
        (
            self.col + self.e[0] * x + self.e[1] * y,
            self.row + self.e[1] * x + self.e[2] * y,
        )
    }

    /// Like [`RingFrame::point`] with `(cos t, sin t)` given.
    #[inline(always)]
    pub fn point_cs(&self, k: f64, (c, s): (f64, f64)) -> (f64, f64) {
        let (x, y) = (k * c, -k * s);
        (
            self.col + self.e[0] * x + self.e[1] * y,
            self.row + self.e[1] * x + self.e[2] * y,
        )
    }

    /// Radius (units of the dot radius) of a pixel position in this frame.
    pub fn radius_of(&self, col: f64, row: f64) -> f64 {
        let (dx, dy) = (col - self.col, row - self.row);
        let [a, b, c] = self.e;
        let det = a * c - b * b;
        let x = (c * dx - b * dy) / det;
        let y = (-b * dx + a * dy) / det;
        (x * x + y * y).sqrt()
    }
}

const DEG: f64 = std::f64::consts::PI / 180.0;
/// Phase samples around the ring (every 5°: six per sector).
const PHASE_SAMPLES: usize = 72;
/// Radii of the gap and the quiet zone samples.
const ZONE_RADII: [f64; 2] = [1.5, 3.5];
/// Samples of the gap and the quiet zone.
const ZONE_SAMPLES: usize = 24;
/// Offsets of the classification samples from a sector's centre, degrees.
const SECTOR_OFFSETS: [f64; 6] = [-10.0, -6.0, -2.0, 2.0, 6.0, 10.0];
/// Phase samples closer than this to a sector boundary (degrees) are not
/// checked against their sector.
const EDGE_CLEARANCE: f64 = 3.0;
/// Radii at which sectors are classified (middle first).
const RING_RADII: [f64; 3] = [2.5, 2.35, 2.65];
/// At the inner and outer radii (cross-checks), margins are this fraction
/// of those at the middle.
const CROSS_MARGIN: f64 = 0.4;

/// `(cos, sin)` of `(j + 0.5) × 60°`, `j = 0..6`.
const HARMONIC: [(f64, f64); 6] = [
    (0.866_025_403_784_438_6, 0.5),
    (0.0, 1.0),
    (-0.866_025_403_784_438_6, 0.5),
    (-0.866_025_403_784_438_6, -0.5),
    (0.0, -1.0),
    (0.866_025_403_784_438_6, -0.5),
];

/// Cosines and sines of two sampling angles, one to a lane: `(cos, sin)`.
type CsPair = (f64x2, f64x2);

/// The plate offsets `(k cos t, −k sin t)` of two sampling angles on the
/// circle of radius `k`, one to a lane: what [`RingFrame::point_cs`] maps
/// (the same products).
type XyPair = (f64x2, f64x2);

/// The classification samples of all sectors, two to a lane pair.
const SECTOR_PAIRS: usize = 12 * SECTOR_OFFSETS.len() / 2;

/// Half the phase samples: the ring's middle is kept two to a lane pair,
/// samples `i` and `i + 36` (half a turn on) in element `i`.
const HALF: usize = PHASE_SAMPLES / 2;

/// The angles of `cs` two to a [`CsPair`], in order.
fn pairs<const N: usize>(cs: &[(f64, f64)]) -> [CsPair; N] {
    debug_assert_eq!(cs.len(), 2 * N);
    std::array::from_fn(|i| {
        let ((c0, s0), (c1, s1)) = (cs[2 * i], cs[2 * i + 1]);
        (f64x2::new([c0, c1]), f64x2::new([s0, s1]))
    })
}

/// The plate offsets of `cs` at radius `k` (see [`XyPair`]).
#[inline(always)]
fn offsets(k: f64, (c, s): CsPair) -> XyPair {
    (f64x2::splat(k) * c, f64x2::splat(-k) * s)
}

/// Cosines and sines of the fixed sampling angles, computed once; also
/// the plate offsets of the fixed circles, two angles to a lane pair (for
/// sampling two at a time).
#[derive(Debug, Clone)]
pub struct RingTables {
    phase: [(f64, f64); PHASE_SAMPLES],
    zone: [(f64, f64); ZONE_SAMPLES],
    bright: [(f64, f64); 8],
    /// Sector `k`, sample `i`: angle `15° + 30° k + offset_i` from the boundary.
    sector: [[(f64, f64); SECTOR_OFFSETS.len()]; 12],
    /// The ring's middle at the phase angles `(i, i + 36)` for `i = 3c`
    /// (the first pass, element `c`).
    phase_first: [XyPair; HALF / 3],
    /// The same for `i = 3c + 1, 3c + 2` (the second pass, elements `2c`,
    /// `2c + 1`).
    phase_rest: [XyPair; 2 * HALF / 3],
    /// The phase angles `(i, i + 36)` in degrees.
    phase_deg: [f64x2; HALF],
    bright_x2: [XyPair; 4],
    gap_x2: [XyPair; ZONE_SAMPLES / 2],
    quiet_x2: [XyPair; ZONE_SAMPLES / 2],
    /// The sector angles two to a lane pair: element `6k + i` holds
    /// sample `i` of sectors `k` and `k + 6` (see [`classify`]).
    sector_x2: [CsPair; SECTOR_PAIRS],
}

impl Default for RingTables {
    fn default() -> Self {
        let cs = |deg: f64| {
            let (s, c) = (deg * DEG).sin_cos();
            (c, s)
        };
        let zero = (f64x2::ZERO, f64x2::ZERO);
        let mut t = RingTables {
            phase: [(0.0, 0.0); PHASE_SAMPLES],
            zone: [(0.0, 0.0); ZONE_SAMPLES],
            bright: [(0.0, 0.0); 8],
            sector: [[(0.0, 0.0); SECTOR_OFFSETS.len()]; 12],
            phase_first: [zero; HALF / 3],
            phase_rest: [zero; 2 * HALF / 3],
            phase_deg: [f64x2::ZERO; HALF],
            bright_x2: [zero; 4],
            gap_x2: [zero; ZONE_SAMPLES / 2],
            quiet_x2: [zero; ZONE_SAMPLES / 2],
            sector_x2: [zero; SECTOR_PAIRS],
        };
        for (j, v) in t.phase.iter_mut().enumerate() {
            *v = cs(j as f64 * (360.0 / PHASE_SAMPLES as f64));
        }
        for (j, v) in t.zone.iter_mut().enumerate() {
            *v = cs((j as f64 + 0.5) * (360.0 / ZONE_SAMPLES as f64));
        }
        for (j, v) in t.bright.iter_mut().enumerate() {
            *v = cs(j as f64 * 45.0);
        }
        for (k, row) in t.sector.iter_mut().enumerate() {
            for (v, d) in row.iter_mut().zip(SECTOR_OFFSETS) {
                *v = cs(15.0 + 30.0 * k as f64 + d);
            }
        }
        let [middle, gap, quiet] = [RING_RADII[0], ZONE_RADII[0], ZONE_RADII[1]];
        let half_turn = |i: usize| {
            let ((c0, s0), (c1, s1)) = (t.phase[i], t.phase[i + HALF]);
            offsets(middle, (f64x2::new([c0, c1]), f64x2::new([s0, s1])))
        };
        for c in 0..HALF / 3 {
            t.phase_first[c] = half_turn(3 * c);
            t.phase_rest[2 * c] = half_turn(3 * c + 1);
            t.phase_rest[2 * c + 1] = half_turn(3 * c + 2);
        }
        for (i, v) in t.phase_deg.iter_mut().enumerate() {
            let deg = |j: usize| j as f64 * (360.0 / PHASE_SAMPLES as f64);
            *v = f64x2::new([deg(i), deg(i + HALF)]);
        }
        t.bright_x2 = pairs::<4>(&t.bright).map(|cs| offsets(0.3, cs));
        t.gap_x2 = pairs::<{ ZONE_SAMPLES / 2 }>(&t.zone).map(|cs| offsets(gap, cs));
        t.quiet_x2 = pairs::<{ ZONE_SAMPLES / 2 }>(&t.zone).map(|cs| offsets(quiet, cs));
        for (k, x2) in t.sector_x2.chunks_exact_mut(6).enumerate() {
            for (i, x2) in x2.iter_mut().enumerate() {
                let ((c0, s0), (c1, s1)) = (t.sector[k][i], t.sector[k + 6][i]);
                *x2 = (f64x2::new([c0, c1]), f64x2::new([s0, s1]));
            }
        }
        t
    }
}

/// Rotates `(cos a, sin a)` by `(cos b, sin b)` (`f64` or two lanes).
#[inline(always)]
fn rotate_cs<T>((ca, sa): (T, T), (cb, sb): (T, T)) -> (T, T)
where
    T: Copy + std::ops::Mul<Output = T> + std::ops::Add<Output = T> + std::ops::Sub<Output = T>,
{
    (ca * cb - sa * sb, sa * cb + ca * sb)
}

/// The values at the plate offsets `xy` (two at a time, lane `l` of
/// element `i` into lane `l` of `out(i, _)`) for a ring clear of the
/// window's edges ([`Sampler`]'s `cells`). Each lane does the scalar
/// [`RingFrame::point_cs`] and [`Plane::bilinear_inside`] operations in
/// the same order: the values are theirs bit for bit, in fewer
/// instructions (the arithmetic of two samples in one vector operation,
/// no clamping of the cells, no range checks).
#[inline(always)]
fn circle<P: Pixel>(
    cells: &Cells<'_, P>,
    f: &RingFrame,
    xy: impl IntoIterator<Item = XyPair>,
    mut out: impl FnMut(usize, f64x2),
) {
    for (i, (col, row)) in positions(f, xy).enumerate() {
        out(i, cells.bilinear_x2(col, row));
    }
}

/// Whether a bound of the pixels of the cells of the plate offsets `xy`
/// lies below `limit` (and so every value there at most `limit`, see
/// [`Cells::corners_bound`]): four pairs of offsets at a time, done at the
/// first whose bound is not (a coded target's ring).
#[inline(always)]
fn below<P: Pixel>(cells: &Cells<'_, P>, f: &RingFrame, xy: &[XyPair], limit: f64) -> bool {
    xy.chunks(4)
        .all(|xy| (cells.corners_bound(positions(f, xy.iter().copied())) as f64) < limit)
}

/// The pixel positions of the plate offsets `xy` (two at a time, as
/// [`RingFrame::point_cs`] forms them).
#[inline(always)]
fn positions(
    f: &RingFrame,
    xy: impl IntoIterator<Item = XyPair>,
) -> impl Iterator<Item = (f64x2, f64x2)> {
    let (col, row) = (f64x2::splat(f.col), f64x2::splat(f.row));
    let [e0, e1, e2] = f.e.map(f64x2::splat);
    xy.into_iter()
        .map(move |(x, y)| (col + e0 * x + e1 * y, row + e1 * x + e2 * y))
}

/// The values at the plate offsets `xy` into `out` (whole circles two at a
/// time, [`circle`]). Not inlined: the loop keeps its registers to itself.
#[inline(never)]
fn samples_at<P: Pixel, const N: usize>(
    cells: &Cells<'_, P>,
    f: &RingFrame,
    xy: &[XyPair; N],
    out: &mut [f64x2; N],
) {
    circle(cells, f, xy.iter().copied(), |i, v| out[i] = v);
}

/// The sector samples at radius `k` (the angles `turned`, two to a lane
/// pair) into `s`, a whole circle two at a time ([`circle`]); at the first
/// radius the angles are turned here (`turn`: the table's angles and the
/// ring's phase). Not inlined: the loop keeps its registers to itself.
#[inline(never)]
fn sectors_at<P: Pixel>(
    cells: &Cells<'_, P>,
    f: &RingFrame,
    k: f64,
    turn: Option<(&[CsPair; SECTOR_PAIRS], CsPair)>,
    turned: &mut [CsPair; SECTOR_PAIRS],
    s: &mut [f64x2; SECTOR_PAIRS],
) {
    let into = |i: usize, v: f64x2| s[i] = v;
    match turn {
        Some((table, phase)) => {
            let xy = turned.iter_mut().zip(table).map(|(t, &a)| {
                *t = rotate_cs(a, phase);
                offsets(k, *t)
            });
            circle(cells, f, xy, into);
        }
        None => circle(cells, f, turned.iter().map(|&cs| offsets(k, cs)), into),
    }
}

/// Bilinear sampling for one ring: when the whole target (out to its
/// quiet zone) lies inside the image, every sample skips the range checks;
/// when it lies half a pixel clear of the image's edges, whole circles of
/// samples go two at a time ([`circle`]) from the cells of its box
/// ([`Plane::cells`]). `FAST` off: one sample at a time even then (the
/// reference for tests).
struct Sampler<'p, 'a, P, const FAST: bool> {
    plane: &'p Plane<'a, P>,
    inside: bool,
    cells: Option<Cells<'a, P>>,
}

impl<'p, 'a, P: Pixel, const FAST: bool> Sampler<'p, 'a, P, FAST> {
    fn new(plane: &'p Plane<'a, P>, f: &RingFrame) -> Self {
        // Farthest reach of the samples (the quiet zone), with a margin for
        // rounding: |E·(cos t, −sin t)| ≤ the norm of E's rows.
        let k = ZONE_RADII[1] * (1.0 + 1e-9) + 1e-9;
        let hx = k * (f.e[0] * f.e[0] + f.e[1] * f.e[1]).sqrt();
        let hy = k * (f.e[1] * f.e[1] + f.e[2] * f.e[2]).sqrt();
        // (Full-frame coordinates: the window's first and last centres.)
        let (c0, r0) = (plane.col0 as f64, plane.row0 as f64);
        let (c1, r1) = (plane.last_col() as f64, plane.last_row() as f64);
        let within = |margin: f64| {
            plane.width >= 2
                && plane.height >= 2
                && f.col - hx >= c0 + margin
                && f.row - hy >= r0 + margin
                && f.col + hx <= c1 - margin
                && f.row + hy <= r1 - margin
        };
        // Half a pixel clear of the edges, the cells' corners (`v − 0.5`
        // rounded: `⌊v⌋ − 1` or `⌊v⌋`) lie in the box from one before
        // the farthest reach's to its own, inside the window short of its
        // last column and row (`⌊v⌋` by truncation: `v` is positive, and
        // below 2³² as every position).
        let floor = |v: f64| v as u32 as usize;
        let cells = (FAST && within(0.5))
            .then(|| {
                plane.cells(
                    (
                        floor(f.col - hx).saturating_sub(1).max(plane.col0),
                        floor(f.row - hy).saturating_sub(1).max(plane.row0),
                    ),
                    (floor(f.col + hx), floor(f.row + hy)),
                )
            })
            .flatten();
        Sampler {
            plane,
            // (Cells lie half a pixel inside.)
            inside: cells.is_some() || within(0.0),
            cells,
        }
    }

    #[inline(always)]
    fn at(&self, col: f64, row: f64) -> Option<f64> {
        if self.inside {
            Some(self.plane.bilinear_inside(col, row))
        } else {
            self.plane.bilinear(col, row)
        }
    }
}

/// The ring's middle at phase angle `j`, `None` outside the image.
#[inline(always)]
fn phase_sample<P: Pixel, const FAST: bool>(
    plane: &Sampler<'_, '_, P, FAST>,
    f: &RingFrame,
    tables: &RingTables,
    j: usize,
) -> Option<f64> {
    let (x, y) = f.point_cs(RING_RADII[0], tables.phase[j]);
    plane.at(x, y)
}

/// The mean and the largest of the samples of a dark zone at radius `k`
/// (`xy`: its plate offsets for [`circle`]); `None` if one is outside.
fn zone<P: Pixel, const FAST: bool>(
    plane: &Sampler<'_, '_, P, FAST>,
    f: &RingFrame,
    k: f64,
    xy: &[XyPair; ZONE_SAMPLES / 2],
    tables: &RingTables,
) -> Option<(f64, f64)> {
    let mut sum = 0.0;
    let mut max = f64::MIN;
    if let Some(cells) = &plane.cells {
        // The sum in the samples' order, as below; the largest lane by
        // lane (no sample is NaN or −0: the same value).
        let mut max2 = f64x2::splat(f64::MIN);
        circle(cells, f, xy.iter().copied(), |_, v| {
            let [a, b] = v.to_array();
            sum += a;
            sum += b;
            max2 = v.fast_max(max2);
        });
        let [a, b] = max2.to_array();
        return Some((sum / ZONE_SAMPLES as f64, a.max(b)));
    }
    for &cs in &tables.zone {
        let (x, y) = f.point_cs(k, cs);
        let v = plane.at(x, y)?;
        sum += v;
        if v > max {
            max = v;
        }
    }
    Some((sum / ZONE_SAMPLES as f64, max))
}

/// The ring's middle as the two passes sample it: element `c` of `first`
/// holds samples `3c` and `3c + 36` (see [`HALF`]), elements `2c` and `2c
/// + 1` of `rest` those from `3c + 1` and `3c + 2`.
struct Middle<'r> {
    first: &'r [f64x2; HALF / 3],
    rest: &'r [f64x2; 2 * HALF / 3],
}

impl Middle<'_> {
    /// Elements `3c` to `3c + 2` of the layout of [`HALF`].
    #[inline(always)]
    fn chunk(&self, c: usize) -> [f64x2; 3] {
        [self.first[c], self.rest[2 * c], self.rest[2 * c + 1]]
    }
}

/// The 12th harmonic of the transitions' strength around the ring: `(re, im, total)` of `g_j = |ring[j + 1] −
/// ring[j]|` weighted by `(cos, sin)` of `(j + 0.5) × 60°`, summed in the
/// order `j = 0 … 71` (the differences two at a time, `re` and `im` in one
/// lane pair: the same operations as one at a time).
fn harmonic(ring: &Middle) -> (f64, f64, f64) {
    // 12 × (j + 0.5) × 5° = (j + 0.5) × 60°: six distinct angles (36 is a
    // multiple of 6, so lane 1 repeats lane 0's).
    const H: [f64x2; 6] = {
        let mut h = [f64x2::ZERO; 6];
        let mut k = 0;
        while k < 6 {
            h[k] = f64x2::new([HARMONIC[k].0, HARMONIC[k].1]);
            k += 1;
        }
        h
    };
    let mut g = [f64x2::ZERO; HALF];
    for (c, g) in g.as_chunks_mut::<3>().0.iter_mut().enumerate() {
        let [a, b, d] = ring.chunk(c);
        // After sample 35 comes 36, after 71 comes 0: lanes crossed.
        let next = match ring.first.get(c + 1) {
            Some(&next) => next,
            None => {
                let [first, opposite] = ring.first[0].to_array();
                f64x2::new([opposite, first])
            }
        };
        *g = [(b - a).abs(), (d - b).abs(), (next - d).abs()];
    }
    let (mut re_im, mut total) = (f64x2::ZERO, 0.0);
    for lane in 0..2 {
        for g in g.as_chunks::<6>().0 {
            for (g, &h) in g.iter().zip(&H) {
                let g = g.as_array_ref()[lane];
                re_im += f64x2::splat(g) * h;
                total += g;
            }
        }
    }
    let [re, im] = re_im.to_array();
    (re, im, total)
}

/// Whether every phase sample of `ring` clear of a
/// sector boundary agrees with its sector's bit in `raw`, the boundary at
/// `boundary_deg` (within ±15°). Two samples at a time, each lane with the
/// scalar's operations: the angle from the boundary `rel = (t − boundary)
/// mod 360` (the offset lies within (−30°, 390°); the samples 20° and more
/// from 0° need no turn), its sector `q = ⌊rel / 30⌋` and the remainder
/// `rel − 30 q`, all exact as one at a time. `q` is `rel / 30 − 1/2`
/// rounded (by adding 1.5 · 2⁵²): `⌊rel / 30⌋` but at an integer `n`,
/// where it may be `n − 1`, the remainder 30 instead of 0: a sample on a
/// boundary, not checked either way.
fn phase_agrees(
    ring: &Middle,
    phase_deg: &[f64x2; HALF],
    boundary_deg: f64,
    raw: u16,
    thr: f64,
) -> bool {
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let splat = f64x2::splat;
    let (b, thr) = (splat(boundary_deg), splat(thr));
    let (full, thirty, half, round) = (splat(360.0), splat(30.0), splat(0.5), splat(ROUND));
    let (lo, hi) = (splat(EDGE_CLEARANCE), splat(30.0 - EDGE_CLEARANCE));
    // The bit of sector `q % 12` as a lane mask, for `q` up to 12 (and 15).
    let bits: [f64; 16] = std::array::from_fn(|q| {
        f64::from_bits(0u64.wrapping_sub(((raw >> (11 - q % 12)) & 1) as u64))
    });
    // Whether the samples of element `i` (`v`) disagree (lane masks).
    let disagree = |i: usize, v: f64x2, may_turn: bool| {
        let d = phase_deg[i] - b;
        let rel = if may_turn {
            // `d + 360`, `d − 360` or `d + 0` (which is `d`: never −0).
            d + ((d.cmp_lt(f64x2::ZERO) & full) | (d.cmp_ge(full) & -full))
        } else {
            d
        };
        let r = (rel / thirty - half) + round;
        let within = rel - thirty * (r - round);
        let clear = within.cmp_ge(lo) & within.cmp_le(hi);
        let [qa, qb] = r.to_array().map(|v| v.to_bits() as usize & 15);
        let bit = f64x2::new([bits[qa], bits[qb]]);
        clear & (bit ^ v.cmp_gt(thr))
    };
    let mut bad = f64x2::ZERO;
    let mut chunk = |c: usize, may_turn: bool| {
        for (k, v) in ring.chunk(c).into_iter().enumerate() {
            bad |= disagree(3 * c + k, v, may_turn);
        }
    };
    // Elements 6 to 32: samples 6 … 32 and 42 … 68, 20° and more from 0°.
    for c in [0, 1, 11] {
        chunk(c, true);
    }
    for c in 2..11 {
        chunk(c, false);
    }
    bad.move_mask() == 0
}

/// The bits of the 12 sectors from their samples, two sectors to a lane
/// pair (element `6k + i` holds sample `i` of sectors `k` and `k + 6`), in
/// reading order (sector 0 most significant); or the first sector (in
/// order) that is uncertain, and why. A sector's mean must be `margins.0`
/// clear of the threshold, each sample `margins.1` clear of it on the
/// mean's side (its smallest or largest sample against one bound: the same
/// comparisons as each sample, as no sample is NaN). Each lane does the
/// operations of one sector at a time (the mean summed in the samples'
/// order).
#[inline(always)]
fn classify(
    s: &[f64x2; SECTOR_PAIRS],
    thr: f64,
    (margin, sample_margin): (f64, f64),
) -> Result<u16, (usize, Uncertainty)> {
    let splat = f64x2::splat;
    let (thr2, margin) = (splat(thr), splat(margin));
    let (low, high) = (splat(thr + sample_margin), splat(thr - sample_margin));
    // The bits of lane 0 (sectors 0 to 5) and of lane 1 (6 to 11) apart,
    // first sector most significant; the first uncertain sector of lane
    // 1 (any of lane 0 comes before it, and is returned as found).
    let (mut bits, mut later) = ([0u16; 2], None);
    for (k, v) in s.as_chunks::<6>().0.iter().enumerate() {
        let mean = (v[0] + v[1] + v[2] + v[3] + v[4] + v[5]) / splat(v.len() as f64);
        let close = (mean - thr2).abs().cmp_lt(margin);
        let bit = mean.cmp_gt(thr2);
        let least = v[0].fast_min(v[1]).fast_min(v[2]).fast_min(v[3]);
        let most = v[0].fast_max(v[1]).fast_max(v[2]).fast_max(v[3]);
        let least = least.fast_min(v[4]).fast_min(v[5]);
        let most = most.fast_max(v[4]).fast_max(v[5]);
        let off_side = (bit & least.cmp_lt(low)) | (!bit & most.cmp_gt(high));
        let uncertain = (close | off_side).move_mask();
        if uncertain != 0 {
            let why = |lane: i32| match close.move_mask() >> lane & 1 {
                1 => Uncertainty::MarginalSector,
                _ => Uncertainty::SectorDisagrees,
            };
            if uncertain & 1 == 1 {
                return Err((k, why(0)));
            }
            later = later.or(Some((k + 6, why(1))));
        }
        let bit = bit.move_mask() as u16;
        bits = [bits[0] << 1 | (bit & 1), bits[1] << 1 | bit >> 1];
    }
    match later {
        Some(first) => Err(first),
        None => Ok(bits[0] << 6 | bits[1]),
    }
}

/// The grey levels a reading starts from (see [`levels`]).
struct Levels {
    /// The dot's level: the mean of its centre and eight points at 0.3 r.
    bright: f64,
    /// The gap's level: the mean of its samples at 1.5 r.
    dark: f64,
    /// The gap's largest sample.
    gap_max: f64,
}

/// The dot's and the gap's levels of the ring in `f` (the value at the
/// dot's centre given where it is known); `None` if a sample lies outside
/// the image.
#[inline(always)]
fn levels<P: Pixel, const FAST: bool>(
    plane: &Sampler<'_, '_, P, FAST>,
    f: &RingFrame,
    centre: Option<f64>,
    tables: &RingTables,
) -> Option<Levels> {
    let mut bright = centre.or_else(|| plane.at(f.col, f.row))?;
    if let Some(cells) = &plane.cells {
        circle(cells, f, tables.bright_x2.iter().copied(), |_, v| {
            let [a, b] = v.to_array();
            bright += a;
            bright += b;
        });
    } else {
        for &cs in &tables.bright {
            let (x, y) = f.point_cs(0.3, cs);
            bright += plane.at(x, y)?;
        }
    }
    bright /= 9.0;
    let (dark, gap_max) = zone(plane, f, ZONE_RADII[0], &tables.gap_x2, tables)?;
    Some(Levels {
        bright,
        dark,
        gap_max,
    })
}

/// The sector boundary nearest plate angle 0 (within ±15°, radians) from
/// the 12th harmonic of the transitions' strength around the ring's
/// middle; `None` where the transitions are too weak (`total` below
/// `min_contrast`) or show no 30° pattern.
#[inline(always)]
fn phase_of(ring: &Middle, min_contrast: f64) -> Option<f64> {
    let (re, im, total) = harmonic(ring);
    if total < min_contrast || (re * re + im * im).sqrt() < 0.2 * total {
        return None;
    }
    Some(im.atan2(re) / 12.0)
}

/// The bits of the 12 sectors from the ring's middle alone, the boundary
/// at `boundary_deg` (within ±15°), in reading order (sector 0 most
/// significant, as [`classify`] gives them): every sample `EDGE_CLEARANCE`
/// or more from its sector's boundaries (four or five at 5° steps) must
/// lie `margin` clear of the threshold `thr`, all of a sector's on one
/// side; `None` otherwise.
///
/// Sector `q` holds the samples `j` from `⌈(b + 3°) / 5°⌉ + 6q` to
/// `⌊(b + 27°) / 5°⌋ + 6q`; sector `q + 6` those 36 on, the other lane of
/// the same elements ([`HALF`]): two sectors to a lane pair, their least
/// and largest samples against the two bounds. (Element `j` lies in
/// −2 … 38: past either end of the half turn it is element `j ∓ 36` with
/// its lanes crossed.)
fn middle_bits(ring: &Middle, boundary_deg: f64, thr: f64, margin: f64) -> Option<u16> {
    let splat = f64x2::splat;
    let (above, below) = (splat(thr + margin), splat(thr - margin));
    let first = ceil_i64((boundary_deg + EDGE_CLEARANCE) / 5.0);
    let last = floor_i64((boundary_deg + 30.0 - EDGE_CLEARANCE) / 5.0);
    if !(-2..=4).contains(&first) || !(first + 3..=first + 4).contains(&last) {
        return None;
    }
    let element = |j: i64| {
        let (e, crossed) = match j {
            ..0 => (j + HALF as i64, true),
            0..36 => (j, false),
            _ => (j - HALF as i64, true),
        };
        let e = e as usize;
        let v = match e % 3 {
            0 => ring.first[e / 3],
            k => ring.rest[2 * (e / 3) + k - 1],
        };
        if crossed {
            let [a, b] = v.to_array();
            f64x2::new([b, a])
        } else {
            v
        }
    };
    let mut bits = [0u16; 2];
    for q in 0..6 {
        let (mut least, mut most) = (splat(f64::MAX), splat(f64::MIN));
        for j in first + 6 * q..=last + 6 * q {
            let v = element(j);
            least = least.fast_min(v);
            most = most.fast_max(v);
        }
        let (bright, dark) = (least.cmp_gt(above), most.cmp_lt(below));
        if (bright | dark).move_mask() != 3 {
            return None;
        }
        let bit = bright.move_mask() as u16;
        bits = [bits[0] << 1 | (bit & 1), bits[1] << 1 | bit >> 1];
    }
    Some(bits[0] << 6 | bits[1])
}

/// Whether the ring in `f` plainly carries the code of canonical value
/// `value`: tracking mode's check of an identity it predicted, with a
/// third of [`read`]'s samples ([`plain_value`]). `false` says nothing
/// about the ring: read it then.
pub(crate) fn confirms<P: Pixel>(
    plane: &Plane<P>,
    f: &RingFrame,
    centre: Option<f64>,
    params: &CodeParams,
    value: u16,
    tables: &RingTables,
) -> bool {
    plain_value(plane, f, centre, params, tables) == Some(value)
}

/// The canonical value a ring plainly carries, judged on its middle
/// alone: the dot's and the gap's levels and the gap's darkness judged as
/// [`read`] judges them, the phase found the same way on the ring's
/// middle, and every sample of the middle clear of a sector boundary on
/// its sector's side of the threshold, the sample margin clear of it
/// ([`middle_bits`]). `None` where any of that fails, or where the ring
/// is not clear of the window's edges (where [`read`] samples one at a
/// time): no inner and outer circles, no quiet zone were looked at, so
/// `None` is no verdict on the ring, and a value is only to be compared
/// with one expected.
fn plain_value<P: Pixel>(
    plane: &Plane<P>,
    f: &RingFrame,
    centre: Option<f64>,
    params: &CodeParams,
    tables: &RingTables,
) -> Option<u16> {
    let plane = &Sampler::<P, true>::new(plane, f);
    let cells = plane.cells.as_ref()?;
    let Levels {
        bright,
        dark,
        gap_max,
    } = levels(plane, f, centre, tables)?;
    let contrast = bright - dark;
    // (A NaN level leaves a NaN threshold: no sector is clear of it.)
    if contrast < params.min_contrast || gap_max > dark + params.dark_tolerance * contrast {
        return None;
    }
    let mut first = [f64x2::ZERO; HALF / 3];
    let mut rest = [f64x2::ZERO; 2 * HALF / 3];
    samples_at(cells, f, &tables.phase_first, &mut first);
    samples_at(cells, f, &tables.phase_rest, &mut rest);
    let ring = Middle {
        first: &first,
        rest: &rest,
    };
    let boundary = phase_of(&ring, params.min_contrast)?;
    let thr = dark + 0.5 * contrast;
    let margin = params.sample_margin * contrast;
    // (No ring, or a full one: no code.)
    middle_bits(&ring, boundary / DEG, thr, margin)
        .filter(|&raw| raw != 0 && raw != codes::MASK)
        .map(codes::canonical)
}

/// Reads the ring around a dot.
pub fn read<P: Pixel>(
    plane: &Plane<P>,
    f: &RingFrame,
    params: &CodeParams,
    accepted: &CodeSet,
    tables: &RingTables,
) -> Reading {
    read_centred(plane, f, None, params, accepted, tables)
}

/// [`read`] with the grey value at the dot's centre given where it is
/// known (`None`: sampled here; a value outside the image is never
/// given): the same reading.
pub(crate) fn read_centred<P: Pixel>(
    plane: &Plane<P>,
    f: &RingFrame,
    centre: Option<f64>,
    params: &CodeParams,
    accepted: &CodeSet,
    tables: &RingTables,
) -> Reading {
    read_with::<P, true>(plane, f, centre, params, accepted, tables)
}

/// [`read`], with whole circles of samples two at a time (`FAST`) or one
/// at a time (the reference: the same reading bit for bit).
fn read_with<P: Pixel, const FAST: bool>(
    plane: &Plane<P>,
    f: &RingFrame,
    centre: Option<f64>,
    params: &CodeParams,
    accepted: &CodeSet,
    tables: &RingTables,
) -> Reading {
    let mut out = Reading {
        gap: Gap::Outside,
        status: CodeStatus::Uncertain(Uncertainty::OutsideImage),
        ring_present: false,
        raw: 0,
        bright: 0.0,
        dark: 0.0,
    };
    let plane = &Sampler::<P, FAST>::new(plane, f);
    let Some(Levels {
        bright,
        dark,
        gap_max,
    }) = levels(plane, f, centre, tables)
    else {
        return out;
    };
    out.bright = bright;
    out.dark = dark;
    let contrast = bright - dark;
    if contrast < params.min_isolation_contrast.min(params.min_contrast) {
        out.gap = Gap::NotDark;
        out.status = CodeStatus::Uncertain(Uncertainty::LowContrast);
        return out;
    }
    let too_dim_to_read = contrast < params.min_contrast;
    let thr = dark + 0.5 * contrast;
    // Presence and phase: the ring's middle every 5°, first every 15° (at
    // least one sample in the middle half of every sector). Kept as the
    // passes take them: element `c` of `first` holds samples `3c` and `3c
    // + 36`, elements `2c` and `2c + 1` of `rest` those from `3c + 1` and
    // `3c + 2` (see [`HALF`]).
    let mut first = [f64x2::ZERO; HALF / 3];
    // The count of bright samples as a float (exact), two lanes at a time
    // on the fast path (1.0 per lane that is).
    let mut n_bright = 0.0;
    let mut outside = false;
    let thr2 = f64x2::splat(thr);
    let count = |v: &[f64x2]| {
        let one = f64x2::splat(1.0);
        let n = v
            .iter()
            .fold(f64x2::ZERO, |n, v| n + (v.cmp_gt(thr2) & one));
        let [a, b] = n.to_array();
        a + b
    };
    // One at a time: into its lane; whether it is bright (`None`: outside).
    let sample = |j: usize, into: &mut f64x2| {
        phase_sample(plane, f, tables, j).map(|v| {
            into.as_array_mut()[j / HALF] = v;
            v > thr
        })
    };
    // No sample is bright where no pixel of its cell reaches the
    // threshold ([`Cells::corners_bound`]): an uncoded target's, found
    // without interpolating.
    let none_bright = |cells: &Cells<'_, P>| below(cells, f, &tables.phase_first, thr);
    if let Some(cells) = plane.cells.as_ref().filter(|&c| !none_bright(c)) {
        samples_at(cells, f, &tables.phase_first, &mut first);
        n_bright = count(&first);
    } else if plane.cells.is_none() {
        for j in (0..PHASE_SAMPLES).step_by(3) {
            match sample(j, &mut first[j % HALF / 3]) {
                Some(b) => n_bright += b as u8 as f64,
                None => outside = true,
            }
        }
    }
    // The second pass once one sample is bright.
    let mut second = None;
    if n_bright > 0.0 {
        let rest = second.insert([f64x2::ZERO; 2 * HALF / 3]);
        if let Some(cells) = &plane.cells {
            samples_at(cells, f, &tables.phase_rest, rest);
            n_bright += count(rest);
        } else {
            for j in (0..PHASE_SAMPLES).filter(|j| j % 3 != 0) {
                let i = j % HALF;
                match sample(j, &mut rest[2 * (i / 3) + i % 3 - 1]) {
                    Some(b) => n_bright += b as u8 as f64,
                    None => outside = true,
                }
            }
        }
    }
    out.ring_present = n_bright >= 2.0;
    let dark_limit = dark + params.dark_tolerance * contrast;
    if gap_max > dark_limit {
        out.gap = Gap::NotDark;
        out.status = CodeStatus::Uncertain(Uncertainty::GapNotDark);
        return out;
    }
    out.gap = Gap::Dark;
    // (A ring is present only where one sample was bright.)
    let ring = match &second {
        Some(rest) if out.ring_present => Middle {
            first: &first,
            rest,
        },
        _ => {
            out.status = if outside {
                CodeStatus::Uncertain(Uncertainty::OutsideImage)
            } else {
                CodeStatus::NoRing
            };
            return out;
        }
    };
    if outside {
        return out;
    }
    if too_dim_to_read {
        out.status = CodeStatus::Uncertain(Uncertainty::LowContrast);
        return out;
    }
    // Dark where no pixel of its cells reaches the limit (see
    // [`Cells::corners_bound`]); else each sample against it.
    let quiet = |cells: &Cells<'_, P>| below(cells, f, &tables.quiet_x2, dark_limit);
    match plane.cells.as_ref().filter(|&c| quiet(c)).map_or_else(
        || zone(plane, f, ZONE_RADII[1], &tables.quiet_x2, tables),
        |_| Some((0.0, f64::MIN)),
    ) {
        None => return out,
        Some((_, quiet_max)) if quiet_max > dark_limit => {
            out.status = CodeStatus::Uncertain(Uncertainty::QuietZoneNotDark);
            return out;
        }
        Some(_) => {}
    }
    let Some(boundary) = phase_of(&ring, params.min_contrast) else {
        // A full ring (4095) has no transitions; anything else without a
        // 30° pattern is not a code.
        out.status = if n_bright == PHASE_SAMPLES as f64 {
            CodeStatus::NotInField { value: codes::MASK }
        } else {
            CodeStatus::Uncertain(Uncertainty::NoPhase)
        };
        return out;
    };
    let boundary_cs = (boundary.cos(), boundary.sin());
    // Classify: sector k is centred at boundary + 15° + 30°k.
    let base_margin = params.sector_margin * contrast;
    let base_sample_margin = params.sample_margin * contrast;
    let mut raw = 0u16;
    // The sample angles turned to the ring's phase: at the middle radius,
    // then reused at the inner and outer ones.
    let mut turned = [[(0.0f64, 0.0f64); SECTOR_OFFSETS.len()]; 12];
    // The same two to a lane pair as [`classify`] takes them (whole
    // circles two at a time: every sample of a radius, then its sectors).
    let mut turned_x2 = [(f64x2::ZERO, f64x2::ZERO); SECTOR_PAIRS];
    let boundary_x2 = (f64x2::splat(boundary_cs.0), f64x2::splat(boundary_cs.1));
    for (ri, &k) in RING_RADII.iter().enumerate() {
        let relax = if ri == 0 { 1.0 } else { CROSS_MARGIN };
        let margins = (base_margin * relax, base_sample_margin * relax);
        let mut s = [f64x2::ZERO; SECTOR_PAIRS];
        // One sample at a time, sector by sector: the first sector with a
        // sample outside the image (12: none).
        let mut cut = 12;
        if let Some(cells) = &plane.cells {
            let turn = (ri == 0).then_some((&tables.sector_x2, boundary_x2));
            sectors_at(cells, f, k, turn, &mut turned_x2, &mut s);
        } else {
            'sectors: for (sector, turned) in turned.iter_mut().enumerate() {
                if ri == 0 {
                    for (t, &a) in turned.iter_mut().zip(&tables.sector[sector]) {
                        *t = rotate_cs(a, boundary_cs);
                    }
                }
                for (i, &cs) in turned.iter().enumerate() {
                    let (x, y) = f.point_cs(k, cs);
                    match plane.at(x, y) {
                        Some(g) => s[6 * (sector % 6) + i].as_array_mut()[sector / 6] = g,
                        None => {
                            cut = sector;
                            break 'sectors;
                        }
                    }
                }
            }
        }
        // The sectors before the cut are classified as if read in order.
        let word = match classify(&s, thr, margins) {
            Err((sector, why)) if sector < cut => {
                out.status = CodeStatus::Uncertain(why);
                return out;
            }
            Ok(word) if cut == 12 => word,
            // A sample outside the image before any uncertain sector.
            _ => return out,
        };
        if ri == 0 {
            raw = word;
        } else if word != raw {
            out.status = CodeStatus::Uncertain(Uncertainty::RadiiDisagree);
            return out;
        }
    }
    // Every phase sample clear of a sector boundary must agree with its
    // sector: catches marks (a bar's shadow) that hide a sector's middle
    // but not its edges.
    debug_assert!(!outside);
    if !phase_agrees(&ring, &tables.phase_deg, boundary / DEG, raw, thr) {
        out.status = CodeStatus::Uncertain(Uncertainty::SectorDisagrees);
        return out;
    }
    out.raw = raw;
    let value = codes::canonical(raw);
    out.status = match codes::id_of(raw) {
        Some(id) if accepted.contains(id) => CodeStatus::Read { id, value },
        _ => CodeStatus::NotInField { value },
    };
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn code_set_membership() {
        let s = CodeSet::from_ids([2, 17, 350, 0, 351]);
        assert!(s.contains(2) && s.contains(17) && s.contains(350));
        assert!(!s.contains(3) && !s.contains(0) && !s.contains(351));
        assert_eq!(s.len(), 3);
        assert_eq!(CodeSet::all().len(), 350);
        let f = photopose_field::design::default_plate();
        let s = CodeSet::from_field(&f);
        assert_eq!(s.len(), 30);
        assert!(f.coded().all(|t| s.contains(t.id)));
    }

    /// Reads the ring in `f` both ways and checks the readings agree bit
    /// for bit; the reading, whether whole circles went two at a time, and
    /// whether the ring was inside the window but not clear of its edges.
    fn read_both<P: Pixel>(
        plane: &Plane<P>,
        f: &RingFrame,
        params: &CodeParams,
        tables: &RingTables,
    ) -> (Reading, bool, bool) {
        let accepted = CodeSet::all();
        let fast = read_with::<P, true>(plane, f, None, params, &accepted, tables);
        let one = read_with::<P, false>(plane, f, None, params, &accepted, tables);
        // The centre's value given (as the detector gives it): the same.
        let centre = plane.bilinear(f.col, f.row);
        let given = read_with::<P, true>(plane, f, centre, params, &accepted, tables);
        assert_eq!(given, fast, "{f:?}");
        assert_eq!(fast.status, one.status, "{f:?}");
        assert_eq!(
            (fast.gap, fast.ring_present, fast.raw),
            (one.gap, one.ring_present, one.raw)
        );
        assert_eq!(fast.bright.to_bits(), one.bright.to_bits(), "{f:?}");
        assert_eq!(fast.dark.to_bits(), one.dark.to_bits(), "{f:?}");
        let s = Sampler::<P, true>::new(plane, f);
        (fast, s.cells.is_some(), s.inside && s.cells.is_none())
    }

    /// Whole circles of samples two at a time read every ring exactly as
    /// one sample at a time: coded targets and dots under tilted views,
    /// frames off their centres and of other sizes, and frames anywhere
    /// (wholly inside, near and across the window's edges, within half a
    /// pixel of them); 8 and 16 bits, the whole frame and a window.
    /// A frame of 15 drawn targets (a few uncoded, the others carrying
    /// codes), tilted and turned, blurred and noisy, as 8 and 16 bits; and
    /// ring frames to read in it: each target's own and six near it (off
    /// centre, scaled) with its drawn code, then frames anywhere (some half
    /// outside) and frames whose quiet zone ends just inside (or just
    /// outside) the margin of the fast path, with none; and the reader's
    /// parameters.
    struct RingScene {
        w: usize,
        h: usize,
        px8: Vec<u8>,
        px16: Vec<u16>,
        frames: Vec<(RingFrame, Option<u16>)>,
        /// The reader's parameters for the scene's contrast.
        params: CodeParams,
    }

    fn ring_scene() -> RingScene {
        use crate::testutil::{Drawn, Rng, Scene, View};
        // (Large enough for the cells of a ring: more than 2¹⁶ pixels.)
        let (w, h) = (330usize, 210usize);
        let mut scene = Scene::new(w, h, 15.0);
        let mut rng = Rng::new(5);
        let ids: Vec<u64> = codes::even_ids().step_by(11).collect();
        let mut targets = Vec::new();
        for k in 0..15 {
            let (col, row) = (16.0 + 40.0 * (k % 5) as f64, 30.0 + 45.0 * (k / 5) as f64);
            let radius = rng.range(3.0, 4.5);
            let m = View::tilted(1.0, rng.range(0.0, 0.9), rng.range(0.0, 6.3), 0.0).m;
            let code = (k % 4 != 3).then(|| codes::value_of(ids[k % ids.len()]).unwrap());
            let view = View { m };
            let phase = rng.range(0.0, 6.3);
            scene.draw(
                &Drawn {
                    col,
                    row,
                    radius,
                    view,
                    code,
                    phase,
                },
                190.0,
            );
            // The second moments of the dot: (r²/4) M Mᵀ.
            let q = radius * radius / 4.0;
            let (cxx, cyy) = (
                q * (m[0] * m[0] + m[1] * m[1]),
                q * (m[2] * m[2] + m[3] * m[3]),
            );
            targets.push((col, row, cxx, cyy, q * (m[0] * m[2] + m[1] * m[3]), code));
        }
        scene.blur(0.7);
        scene.noise(2.0, &mut rng);
        let px8: Vec<u8> = scene
            .v
            .iter()
            .map(|v| v.round().clamp(0.0, 255.0) as u8)
            .collect();
        let px16: Vec<u16> = scene
            .v
            .iter()
            .map(|v| (v * 13.0).round().clamp(0.0, 4095.0) as u16)
            .collect();
        let mut frames = Vec::new();
        for &(col, row, cxx, cyy, cxy, code) in &targets {
            frames.push((
                RingFrame::from_moments(col, row, cxx, cyy, cxy).unwrap(),
                code,
            ));
            for _ in 0..6 {
                let s = rng.range(0.9, 1.1);
                let (dc, dr) = (rng.range(-0.4, 0.4), rng.range(-0.4, 0.4));
                let f = RingFrame::from_moments(col + dc, row + dr, s * cxx, s * cyy, s * cxy);
                frames.push((f.unwrap(), code));
            }
        }
        for _ in 0..300 {
            let (col, row) = (
                rng.range(-5.0, w as f64 + 5.0),
                rng.range(-5.0, h as f64 + 5.0),
            );
            let (a, c) = (rng.range(1.0, 6.0), rng.range(1.0, 6.0));
            let b = rng.range(-0.9, 0.9) * (a * c).sqrt();
            frames.push((RingFrame::from_moments(col, row, a, c, b).unwrap(), None));
        }
        // Frames whose quiet zone ends just inside (or just outside) the
        // margin of the fast path, half a pixel from the window's edges.
        for k in 0..40 {
            let (cxx, cyy) = (rng.range(2.0, 5.0), rng.range(2.0, 5.0));
            let cxy = rng.range(-0.5, 0.5) * (cxx * cyy).sqrt();
            let probe = RingFrame::from_moments(0.0, 0.0, cxx, cyy, cxy).unwrap();
            let k3 = ZONE_RADII[1];
            let [a, b, c] = probe.e;
            let (hx, hy) = (k3 * (a * a + b * b).sqrt(), k3 * (b * b + c * c).sqrt());
            let d = [0.0, 0.25, 0.5, 0.5 + 1e-9, 0.75][k % 5] + rng.range(-1e-6, 1e-6);
            let (col, row) = match k / 5 % 4 {
                0 => (d + hx, rng.range(hy + 1.0, h as f64 - hy - 1.0)),
                1 => (
                    w as f64 - 1.0 - d - hx,
                    rng.range(hy + 1.0, h as f64 - hy - 1.0),
                ),
                2 => (rng.range(hx + 1.0, w as f64 - hx - 1.0), d + hy),
                _ => (
                    rng.range(hx + 1.0, w as f64 - hx - 1.0),
                    h as f64 - 1.0 - d - hy,
                ),
            };
            frames.push((
                RingFrame::from_moments(col, row, cxx, cyy, cxy).unwrap(),
                None,
            ));
        }
        let params = CodeParams {
            min_contrast: 20.0,
            min_isolation_contrast: 10.0,
            sector_margin: 0.15,
            sample_margin: 0.05,
            dark_tolerance: 0.25,
        };
        RingScene {
            w,
            h,
            px8,
            px16,
            frames,
            params,
        }
    }

    /// The value a ring plainly carries on its middle is only ever the
    /// code drawn there, and where the full reading gives a value, that
    /// one: frames on and near every drawn target (coded, uncoded) and
    /// anywhere else, in 8 and 16 bits, whole frames and windows. Most
    /// coded targets read in full are confirmed this way.
    #[test]
    fn a_ring_plainly_carries_only_its_own_code() {
        use crate::testutil::window;
        let RingScene {
            w,
            h,
            px8,
            px16,
            frames,
            params,
        } = ring_scene();
        let tables = RingTables::default();
        let accepted = CodeSet::all();
        let (mut full, mut confirmed, mut plain) = (0, 0, 0);
        let check = |reading: Reading, value: Option<u16>, drawn: Option<u16>| {
            if let Some(value) = value {
                assert_eq!(Some(value), drawn);
                if let Some(v) = reading.status.value() {
                    assert_eq!(v, value);
                }
            }
            match reading.status {
                CodeStatus::Read { value: v, .. } => (1, (value == Some(v)) as usize),
                _ => (0, 0),
            }
        };
        for (f, drawn) in &frames {
            let (wide8, wide16) = (Plane::whole(&px8, w, h), Plane::whole(&px16, w, h));
            let (part8, part16) = (
                window(&px8, w, (13, 7, 300, 190)),
                window(&px16, w, (2, 3, 320, 200)),
            );
            let outcomes = [
                check(
                    read(&wide8, f, &params, &accepted, &tables),
                    plain_value(&wide8, f, None, &params, &tables),
                    *drawn,
                ),
                check(
                    read(&part8, f, &params, &accepted, &tables),
                    plain_value(&part8, f, None, &params, &tables),
                    *drawn,
                ),
                check(
                    read(&wide16, f, &params, &accepted, &tables),
                    plain_value(&wide16, f, None, &params, &tables),
                    *drawn,
                ),
                check(
                    read(&part16, f, &params, &accepted, &tables),
                    plain_value(&part16, f, None, &params, &tables),
                    *drawn,
                ),
            ];
            for (r, c) in outcomes {
                full += r;
                confirmed += c;
            }
            plain += [&wide8, &part8]
                .iter()
                .filter(|p| plain_value(p, f, None, &params, &tables).is_some())
                .count();
        }
        // (The values each frame gives were checked above.)
        assert!(
            plain > 100 && full > 200 && 10 * confirmed >= 9 * full,
            "{plain} {full} {confirmed}"
        );
    }

    #[test]
    fn circles_two_at_a_time_read_as_one_at_a_time() {
        use crate::testutil::window;
        let RingScene {
            w,
            h,
            px8,
            px16,
            frames,
            params,
        } = ring_scene();
        let tables = RingTables::default();
        let (mut read, mut fast, mut slow, mut near) = (0, 0, 0, 0);
        for (f, _) in &frames {
            for (reading, inside, edge) in [
                read_both(&Plane::whole(&px8, w, h), f, &params, &tables),
                read_both(&window(&px8, w, (13, 7, 300, 190)), f, &params, &tables),
                read_both(&Plane::whole(&px16, w, h), f, &params, &tables),
                read_both(&window(&px16, w, (2, 3, 320, 200)), f, &params, &tables),
            ] {
                read += matches!(reading.status, CodeStatus::Read { .. }) as usize;
                fast += inside as usize;
                slow += !inside as usize;
                near += edge as usize;
            }
        }
        assert!(
            read > 40 && fast > 200 && slow > 200 && near > 30,
            "{read} {fast} {slow} {near}"
        );
    }

    /// The ring's middle as the passes take it ([`Middle`]): its first
    /// pass and its second.
    fn passes(ring: &[f64; PHASE_SAMPLES]) -> ([f64x2; HALF / 3], [f64x2; 2 * HALF / 3]) {
        let half = |i: usize| f64x2::new([ring[i], ring[i + HALF]]);
        let first = std::array::from_fn(|c| half(3 * c));
        let rest = std::array::from_fn(|e| half(3 * (e / 2) + 1 + e % 2));
        (first, rest)
    }

    /// [`harmonic`] one sample at a time (the reference).
    fn harmonic_plain(ring: &[f64; PHASE_SAMPLES]) -> (f64, f64, f64) {
        let (mut re, mut im, mut total) = (0.0, 0.0, 0.0);
        for j in 0..PHASE_SAMPLES {
            let g = (ring[(j + 1) % PHASE_SAMPLES] - ring[j]).abs();
            let (c, sn) = HARMONIC[j % 6];
            re += g * c;
            im += g * sn;
            total += g;
        }
        (re, im, total)
    }

    /// [`phase_agrees`] one sample at a time (the reference).
    fn phase_agrees_plain(
        ring: &[f64; PHASE_SAMPLES],
        boundary_deg: f64,
        raw: u16,
        thr: f64,
    ) -> bool {
        for (j, &v) in ring.iter().enumerate() {
            let t = j as f64 * (360.0 / PHASE_SAMPLES as f64);
            let d = t - boundary_deg;
            let rel = if d < 0.0 {
                d + 360.0
            } else if d >= 360.0 {
                d - 360.0
            } else {
                d
            };
            let q = (rel / 30.0) as u32;
            let within = rel - 30.0 * q as f64;
            if !(EDGE_CLEARANCE..=30.0 - EDGE_CLEARANCE).contains(&within) {
                continue;
            }
            let sector = q % 12;
            let bit = (raw >> (11 - sector)) & 1 == 1;
            if bit != (v > thr) {
                return false;
            }
        }
        true
    }

    /// [`classify`] one sector at a time (the reference): sector `k`'s
    /// samples in `sectors[k]`.
    fn classify_plain(
        sectors: &[[f64; 6]; 12],
        thr: f64,
        (margin, sample_margin): (f64, f64),
    ) -> Result<u16, (usize, Uncertainty)> {
        let mut word = 0u16;
        for (k, s) in sectors.iter().enumerate() {
            let mean = s.iter().sum::<f64>() / s.len() as f64;
            if (mean - thr).abs() < margin {
                return Err((k, Uncertainty::MarginalSector));
            }
            let bit = mean > thr;
            let off_side = if bit {
                let low = thr + sample_margin;
                s.iter().any(|&v| v < low)
            } else {
                let high = thr - sample_margin;
                s.iter().any(|&v| v > high)
            };
            if off_side {
                return Err((k, Uncertainty::SectorDisagrees));
            }
            word = (word << 1) | bit as u16;
        }
        Ok(word)
    }

    /// Two sectors at a time classify as one at a time: clear and noisy
    /// sectors, means and samples on the margins' edges, every sector
    /// the first uncertain one now and then.
    #[test]
    fn sectors_two_at_a_time_classify_as_one_at_a_time() {
        use crate::testutil::Rng;
        let mut rng = Rng::new(23);
        let (mut read, mut marginal, mut disagree) = (0, 0, 0);
        for round in 0..20000 {
            let (thr, margins) = (100.0, (12.0, 4.0));
            let word = rng.range(0.0, 4096.0) as u16;
            let mut sectors = [[0.0f64; 6]; 12];
            for (k, s) in sectors.iter_mut().enumerate() {
                let lit = word >> (11 - k) & 1 == 1;
                let level = if lit { 160.0 } else { 40.0 };
                let noise = [0.0, 5.0, 50.0, 70.0][round % 4];
                for v in s.iter_mut() {
                    *v = (level + rng.range(-noise, noise)).max(0.0);
                }
                // Now and then a sample on its bound, or a mean on the
                // sector margin's edge.
                match (round / 4 + k) % 23 {
                    0 => s[k % 6] = if lit { 104.0 } else { 96.0 },
                    1 => *s = [112.0, 112.0, 112.0, 112.0, 112.0, 112.0],
                    2 => *s = [88.0, 88.0, 88.0, 88.0, 88.0, 88.0],
                    3 => *s = [111.0, 113.0, 111.0, 113.0, 111.0, 113.0],
                    4 => *s = [111.9, 100.0, 120.0, 111.0, 113.0, 98.0],
                    5 => *s = [88.1, 88.1, 88.1, 88.1, 88.1, 88.1],
                    _ => {}
                }
            }
            let mut x2 = [f64x2::ZERO; SECTOR_PAIRS];
            for (k, s) in sectors.iter().enumerate() {
                for (i, &v) in s.iter().enumerate() {
                    x2[6 * (k % 6) + i].as_array_mut()[k / 6] = v;
                }
            }
            let want = classify_plain(&sectors, thr, margins);
            assert_eq!(classify(&x2, thr, margins), want, "{round}");
            match want {
                Ok(_) => read += 1,
                Err((_, Uncertainty::MarginalSector)) => marginal += 1,
                Err(_) => disagree += 1,
            }
        }
        assert!(
            read > 2000 && marginal > 2000 && disagree > 2000,
            "{read} {marginal} {disagree}"
        );
    }

    /// The harmonic and the check of the phase samples against their
    /// sectors two at a time equal one at a time: rings drawn from codes
    /// with blurred and noisy edges (and some flat or random ones), the
    /// code read and others, boundaries anywhere in ±15° and on the edges
    /// of the clearance and of the turn (±0, tiny, whole degrees).
    /// A sector boundary (degrees) for round `round` of a test: anywhere
    /// in ±15°, at and next to the steps where a sample enters or leaves a
    /// sector, or near 0.
    fn test_boundary(round: usize, rng: &mut crate::testutil::Rng) -> f64 {
        match round % 4 {
            0 => rng.range(-15.0, 15.0),
            1 => [
                0.0, -0.0, 1e-300, -1e-300, 2.0, -2.0, 3.0, -3.0, 12.0, -12.0, 15.0, -15.0,
            ][round / 4 % 12],
            2 => (rng.range(-15.0, 15.0) as i32) as f64 + [0.0, 1e-13, -1e-13][round % 3],
            _ => rng.range(-1.0, 1.0),
        }
    }

    /// Whether phase sample `j` (at `5 j` degrees) of a ring carrying
    /// `raw`, its boundary at `boundary` degrees, lies in a lit sector.
    fn lit_at(raw: u16, boundary: f64, j: usize) -> bool {
        let t = j as f64 * 5.0 - boundary;
        let sector = (t.rem_euclid(360.0) / 30.0) as usize % 12;
        (raw >> (11 - sector)) & 1 == 1
    }

    /// [`middle_bits`] one sample at a time: each sample's sector from its
    /// angle to the boundary (as [`phase_agrees_plain`] finds it).
    fn middle_bits_plain(
        ring: &[f64; PHASE_SAMPLES],
        boundary_deg: f64,
        thr: f64,
        margin: f64,
    ) -> Option<u16> {
        let (mut bright, mut dark) = (0u16, 0u16);
        for (j, &v) in ring.iter().enumerate() {
            let t = j as f64 * (360.0 / PHASE_SAMPLES as f64);
            let rel = (t - boundary_deg).rem_euclid(360.0);
            let q = (rel / 30.0) as u32;
            let within = rel - 30.0 * q as f64;
            if !(EDGE_CLEARANCE..=30.0 - EDGE_CLEARANCE).contains(&within) {
                continue;
            }
            let bit = 1 << (11 - q % 12);
            if v > thr + margin {
                bright |= bit;
            } else if v < thr - margin {
                dark |= bit;
            } else {
                return None;
            }
        }
        (bright & dark == 0 && bright | dark == codes::MASK).then_some(bright)
    }

    /// The sectors' bits from the ring's middle two sectors at a time are
    /// those one sample at a time: rings of every code at every phase,
    /// clean, noisy (some samples inside the margin or across the
    /// threshold) and random, boundaries anywhere in ±15° and at and next
    /// to the steps where a sample enters or leaves a sector.
    #[test]
    fn middle_bits_two_sectors_at_a_time_equal_one_sample_at_a_time() {
        use crate::testutil::Rng;
        let mut rng = Rng::new(29);
        let (mut read, mut unread) = (0, 0);
        for round in 0..4000 {
            let raw = (rng.range(0.0, 4096.0) as u16).min(codes::MASK);
            let boundary = test_boundary(round, &mut rng);
            let ring: [f64; PHASE_SAMPLES] = std::array::from_fn(|j| {
                let lit = lit_at(raw, boundary, j);
                let level = if lit { 200.0 } else { 20.0 };
                match round % 5 {
                    0 => rng.range(0.0, 255.0),
                    1 | 2 => level,
                    _ => level + rng.range(-75.0, 75.0),
                }
            });
            let (thr, margin) = ([110.0, rng.range(0.0, 255.0)][round % 2], 9.0);
            let (first, rest) = passes(&ring);
            let middle = Middle {
                first: &first,
                rest: &rest,
            };
            let want = middle_bits_plain(&ring, boundary, thr, margin);
            assert_eq!(
                middle_bits(&middle, boundary, thr, margin),
                want,
                "{round} {raw} {boundary}"
            );
            read += want.is_some() as usize;
            unread += want.is_none() as usize;
        }
        assert!(read > 800 && unread > 1500, "{read} {unread}");
    }

    #[test]
    fn harmonic_and_phase_check_two_at_a_time_equal_one_at_a_time() {
        use crate::testutil::Rng;
        let mut rng = Rng::new(17);
        let tables = RingTables::default();
        let (mut agree, mut disagree) = (0, 0);
        for round in 0..3000 {
            let raw = (rng.range(0.0, 4096.0) as u16).min(codes::MASK);
            let boundary = test_boundary(round, &mut rng);
            let ring: [f64; PHASE_SAMPLES] = std::array::from_fn(|j| {
                let lit = lit_at(raw, boundary, j);
                match round % 7 {
                    0 => rng.range(0.0, 255.0),
                    1 => 40.0,
                    2 => {
                        if lit {
                            200.0
                        } else {
                            20.0
                        }
                    }
                    _ => (if lit { 200.0 } else { 20.0 }) + rng.range(-30.0, 30.0),
                }
            });
            let thr = [110.0, rng.range(0.0, 255.0), 40.0, 200.0][round % 4];
            let (first, rest) = passes(&ring);
            let middle = Middle {
                first: &first,
                rest: &rest,
            };
            let h = harmonic(&middle);
            let want = harmonic_plain(&ring);
            assert_eq!(
                [h.0, h.1, h.2].map(f64::to_bits),
                [want.0, want.1, want.2].map(f64::to_bits),
                "{round}"
            );
            for raw in [raw, raw ^ 1, raw ^ 0x800, !raw & codes::MASK] {
                let want = phase_agrees_plain(&ring, boundary, raw, thr);
                let got = phase_agrees(&middle, &tables.phase_deg, boundary, raw, thr);
                assert_eq!(got, want, "{round} {raw} {boundary}");
                agree += want as usize;
                disagree += !want as usize;
            }
        }
        assert!(agree > 500 && disagree > 1000, "{agree} {disagree}");
    }

    #[test]
    fn ring_frame_maps_the_unit_circle_onto_the_moment_ellipse() {
        // A circle of radius 4 px: second moments 4.
        let f = RingFrame::from_moments(10.0, 20.0, 4.0, 4.0, 0.0).unwrap();
        let (x, y) = f.point(1.0, 0.0);
        assert!((x - 14.0).abs() < 1e-12 && (y - 20.0).abs() < 1e-12);
        // Counter-clockwise in the image is up in the picture: row decreases.
        let (x, y) = f.point(1.0, 90.0 * DEG);
        assert!(
            (x - 10.0).abs() < 1e-12 && (y - 16.0).abs() < 1e-12,
            "{x} {y}"
        );
        assert!((f.radius_of(10.0, 28.0) - 2.0).abs() < 1e-12);
        // An ellipse with axes 6 (along col) and 3 (along row).
        let f = RingFrame::from_moments(0.0, 0.0, 9.0, 2.25, 0.0).unwrap();
        let (x, _) = f.point(1.0, 0.0);
        assert!((x - 6.0).abs() < 1e-12);
        assert!((f.radius_of(0.0, 3.0) - 1.0).abs() < 1e-12);
        assert!(RingFrame::from_moments(0.0, 0.0, 1.0, 1.0, 1.0).is_none());
    }
}
