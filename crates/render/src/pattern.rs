//! The target pattern on the plate and how much of a pixel it covers: a
//! target in the plate's own 2-D frame, its reflectance (dot, code ring by
//! sector), the exact area coverage of a pixel crossed by one edge of the
//! pattern (straight sector boundary or circle, the circle followed in
//! strips), and the test whether a pixel may straddle an edge.

use nalgebra::{Matrix2, Vector2};
use photopose_field::{codes, TargetKind};

/// A target in the plate's own 2-D frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Flat {
    pub(crate) id: u64,
    pub(crate) kind: TargetKind,
    /// Centre in plate coordinates, mm.
    pub(crate) at: Vector2<f64>,
    pub(crate) radius: f64,
    pub(crate) code: u16,
    /// Bit `k` set: the sector boundary at `k·30°` separates a bright from
    /// a dark sector.
    pub(crate) edges: u16,
}

/// Reflectance of the pattern at `local` (plate coordinates relative to the
/// target centre, in dot radii): 1 bright, 0 dark.
#[inline]
pub(crate) fn reflectance(t: &Flat, local: Vector2<f64>) -> f64 {
    let rho2 = local.norm_squared();
    if rho2 <= 1.0 {
        return 1.0;
    }
    if t.kind == TargetKind::Uncoded || !(4.0..9.0).contains(&rho2) {
        return 0.0;
    }
    let a = local.y.atan2(local.x).rem_euclid(std::f64::consts::TAU);
    let k = ((a / (std::f64::consts::PI / 6.0)) as u32).min(11);
    codes::sector_bit(t.code, k) as u8 as f64
}

/// Share of `[-½, ½]²` where `g·δ < t` (the CDF of the sum of two
/// uniform variables of widths `|g.x|`, `|g.y|`).
#[inline]
pub(crate) fn square_share_below(g: Vector2<f64>, t: f64) -> f64 {
    let (a, b) = (g.x.abs().max(g.y.abs()), g.x.abs().min(g.y.abs()));
    let s = t + 0.5 * (a + b);
    if s <= 0.0 {
        0.0
    } else if s >= a + b {
        1.0
    } else if s < b {
        s * s / (2.0 * a * b)
    } else if s <= a {
        (s - 0.5 * b) / a
    } else {
        1.0 - (a + b - s) * (a + b - s) / (2.0 * a * b)
    }
}

/// Share of the pixel inside the circle `ρ < a` (local units): the pixel
/// is cut into strips across the edge, each with the circle linearised at
/// its own centre, which follows the edge's curvature (the error of one
/// straight line, about 1/(24 R) of a pixel for an image radius of R px,
/// drops by the square of the strip count).
fn circle_share(local: Vector2<f64>, jac: &Matrix2<f64>, a: f64, g: Vector2<f64>) -> f64 {
    const STRIPS: usize = 8;
    let m = STRIPS as f64;
    // Strips narrow along the axis the edge runs along.
    let split_col = g.x.abs() <= g.y.abs();
    // Pixel offsets: `along` across the strips, `across` along each strip.
    let (along, across) = if split_col {
        (Vector2::x(), Vector2::y())
    } else {
        (Vector2::y(), Vector2::x())
    };
    let (ja, jc) = (jac * along, jac * across);
    let mut sum = 0.0;
    for i in 0..STRIPS {
        let off = (i as f64 + 0.5) / m - 0.5;
        // Where the edge crosses the strip's centre line (Newton from the
        // middle), kept inside the pixel.
        let mut y = 0.0;
        for _ in 0..2 {
            let l = local + ja * off + jc * y;
            let rho = l.norm();
            let slope = jc.dot(&l) / rho.max(1e-12);
            if slope.abs() < 1e-12 {
                break;
            }
            y = (y - (rho - a) / slope).clamp(-0.5, 0.5);
        }
        let l = local + ja * off + jc * y;
        let rho = l.norm();
        if rho < 1e-12 {
            return square_share_below(g, a - local.norm());
        }
        let n = l / rho;
        // ρ − a ≈ (rho − a) + ga·(x − off) + gc·(y' − y) in the strip, with
        // x − off ∈ [−1/2m, 1/2m] and y' ∈ [−½, ½].
        let (ga, gc) = (ja.dot(&n), jc.dot(&n));
        let gs = if split_col {
            Vector2::new(ga / m, gc)
        } else {
            Vector2::new(gc, ga / m)
        };
        sum += square_share_below(gs, a - rho + gc * y);
    }
    sum / m
}

/// Exact share of the pattern's brightness in a pixel crossed by a single
/// edge, with the pixel → plate mapping linearised over the pixel:
/// `local(δ) = local + jac·δ`, `δ ∈ [-½, ½]²`. `None` if more than one
/// edge crosses the pixel (or the linearisation is unusable).
pub(crate) fn analytic_coverage(t: &Flat, local: Vector2<f64>, jac: &Matrix2<f64>) -> Option<f64> {
    let rho = local.norm();
    if rho < 0.25 {
        return None;
    }
    let sector = std::f64::consts::PI / 6.0;
    let a = local.y.atan2(local.x).rem_euclid(std::f64::consts::TAU);
    let j = ((a / sector) as u32).min(11);
    let bit = |k: u32| f64::from(u8::from(codes::sector_bit(t.code, k % 12)));
    let coded = t.kind == TargetKind::Coded;
    // Edges as (circle radius or 0 for a straight boundary, d0, g, value
    // where d0 + g·δ < 0, value where > 0).
    let radial = jac.transpose() * (local / rho);
    let mut edge: Option<(f64, f64, Vector2<f64>, f64, f64)> = None;
    let mut crossing = 0;
    // How far a circle bends away from its linearisation within the pixel
    // (tangential reach² / 2ρ): a curved edge may cut a corner the straight
    // one misses.
    let tangential = jac.transpose() * Vector2::new(-local.y, local.x) / rho;
    let bend = (0.5 * (tangential.x.abs() + tangential.y.abs())).powi(2) / (2.0 * rho);
    let mut consider = |circle: f64, d0: f64, g: Vector2<f64>, below: f64, above: f64| {
        let slack = if circle > 0.0 { bend } else { 0.0 };
        if below != above && d0.abs() < 0.5 * (g.x.abs() + g.y.abs()) + slack {
            crossing += 1;
            edge = Some((circle, d0, g, below, above));
        }
    };
    consider(1.0, rho - 1.0, radial, 1.0, 0.0);
    if coded {
        consider(2.0, rho - 2.0, radial, 0.0, bit(j));
        consider(3.0, rho - 3.0, radial, bit(j), 0.0);
        // Sector boundaries either side, where the ring is.
        for k in [j, j + 1] {
            let phi = k as f64 * sector;
            let (dir, normal) = (
                Vector2::new(phi.cos(), phi.sin()),
                Vector2::new(-phi.sin(), phi.cos()),
            );
            let d0 = normal.dot(&local);
            let g = jac.transpose() * normal;
            let along = dir.dot(&local);
            let reach = 0.5 * (jac.column(0).norm() + jac.column(1).norm());
            if along > 0.0 && along > 2.0 - reach && along < 3.0 + reach {
                if along < 2.0 + reach || along > 3.0 - reach {
                    // The boundary ends inside the pixel: a corner.
                    if d0.abs() < 0.5 * (g.x.abs() + g.y.abs()) && bit(k + 11) != bit(k) {
                        return None;
                    }
                }
                consider(0.0, d0, g, bit(k + 11), bit(k));
            }
        }
    }
    match (crossing, edge) {
        (0, _) => Some(reflectance(t, local)),
        (1, Some((circle, d0, g, below, above))) => {
            if g.norm() < 1e-12 {
                return None;
            }
            let share = if circle > 0.0 {
                circle_share(local, jac, circle, g)
            } else {
                square_share_below(g, -d0)
            };
            Some(below * share + above * (1.0 - share))
        }
        _ => None,
    }
}

/// Whether a pixel whose centre maps to `local` (radius `rho`, in dot radii)
/// with a footprint of `foot` dot radii may straddle an edge of the pattern.
#[inline]
pub(crate) fn near_edge(t: &Flat, local: Vector2<f64>, rho: f64, foot: f64) -> bool {
    let radii: &[f64] = match t.kind {
        TargetKind::Coded => &[1.0, 2.0, 3.0],
        TargetKind::Uncoded => &[1.0],
    };
    if radii.iter().any(|r| (rho - r).abs() <= foot) {
        return true;
    }
    if t.kind == TargetKind::Coded && t.edges != 0 && rho > 2.0 - foot && rho < 3.0 + foot {
        // Distance to the two sector boundaries either side, where they
        // separate sectors of different bits.
        let sector = std::f64::consts::PI / 6.0;
        let a = local.y.atan2(local.x).rem_euclid(std::f64::consts::TAU);
        let j = ((a / sector) as u32).min(11);
        let da = a - j as f64 * sector;
        let near = |boundary: u32, angle: f64| {
            t.edges & (1 << (boundary % 12)) != 0 && rho * angle.min(sector).sin() <= foot
        };
        return near(j, da) || near(j + 1, sector - da);
    }
    false
}
