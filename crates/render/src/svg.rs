//! The test field as an SVG drawing at 1:1, for printing a plate.
//!
//! Lengths in the drawing are millimetres (`width`/`height` in `mm`, the
//! `viewBox` in mm), so a print at 100 % has the field's dimensions. The
//! plate is drawn as seen from `+Z` (the side the targets face) with the
//! plate frame's `u` axis to the right and `v` up; SVG's `y` runs down, so
//! a plate point `(u, v)` is drawn at `(u − u_min, v_max − v)`.
//!
//! Black plate, white (retro-reflective) centre dots and code-ring sectors
//! exactly as the renderer draws them: sector `k` spans `[k·30°, (k+1)·30°)`
//! counter-clockwise from `+u` seen from `+Z`, bright when
//! `codes::sector_bit(value, k)` is set. Adjacent bright sectors are drawn
//! as one annular path (no hairline seams). Each id is written in grey below
//! its target, outside every quiet zone; an id that would reach into one is
//! left out.

use crate::plate::Plate;
use crate::RenderError;
use nalgebra::Vector2;
use photopose_field::{codes, Field, TargetKind};
use std::fmt::Write;

/// Options of the drawing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SvgOptions {
    /// Dark border around the outermost quiet zones, mm.
    pub border_mm: f64,
    /// Height of the id labels, mm (0: no labels).
    pub label_mm: f64,
}

impl Default for SvgOptions {
    fn default() -> Self {
        SvgOptions {
            border_mm: 10.0,
            label_mm: 3.0,
        }
    }
}

/// A number for the drawing: 4 decimals (0.1 µm), trailing zeros dropped.
fn num(v: f64) -> String {
    let s = format!("{:.4}", v);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

/// Label box of a target (plate coordinates: min corner, max corner).
fn label_box(at: Vector2<f64>, quiet: f64, text: &str, h: f64) -> (Vector2<f64>, Vector2<f64>) {
    let half_w = 0.3 * h * text.len() as f64;
    let top = at.y - quiet - 0.3 * h;
    (
        Vector2::new(at.x - half_w, top - h),
        Vector2::new(at.x + half_w, top),
    )
}

/// Distance from a point to an axis-aligned box (0 inside).
fn box_distance(p: Vector2<f64>, lo: Vector2<f64>, hi: Vector2<f64>) -> f64 {
    let dx = (lo.x - p.x).max(0.0).max(p.x - hi.x);
    let dy = (lo.y - p.y).max(0.0).max(p.y - hi.y);
    dx.hypot(dy)
}

/// The SVG text of the plate.
pub fn plate_svg(field: &Field, options: &SvgOptions) -> Result<String, RenderError> {
    Ok(plate_drawing(field, options)?.to_svg())
}

/// A target as drawn: its centre in drawing coordinates (mm, `y` down)
/// and the radius of its bright figure (dot or code ring), mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawnTarget {
    /// Target id.
    pub id: u64,
    /// Centre, drawing mm from the left.
    pub x: f64,
    /// Centre, drawing mm from the top.
    pub y: f64,
    /// Radius of what is drawn of it, mm.
    pub radius: f64,
}

/// The plate drawn at 1:1: its size, the SVG elements (drawing
/// coordinates, mm) and where things are, for sheets and tiles.
#[derive(Debug, Clone, PartialEq)]
pub struct Drawing {
    /// Width, mm.
    pub width_mm: f64,
    /// Height, mm.
    pub height_mm: f64,
    /// An XML comment describing the drawing.
    pub comment: String,
    /// The SVG elements.
    pub content: String,
    /// Every target as drawn.
    pub targets: Vec<DrawnTarget>,
    /// The field's origin `(X, Y) = (0, 0)` in drawing coordinates.
    pub origin: (f64, f64),
    /// Unit directions of the field's `X` and `Y` axes in the drawing
    /// (`y` down).
    pub axes: [(f64, f64); 2],
}

impl Drawing {
    /// The drawing as a standalone SVG of its own size, 1:1 in mm.
    pub fn to_svg(&self) -> String {
        let (w, h) = (num(self.width_mm), num(self.height_mm));
        let mut s = String::new();
        let _ = writeln!(s, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" viewBox="0 0 {w} {h}">"#
        );
        s.push_str(&self.comment);
        s.push_str(&self.content);
        let _ = writeln!(s, "</svg>");
        s
    }
}

/// The plate drawn at 1:1 (see the module's description).
pub fn plate_drawing(field: &Field, options: &SvgOptions) -> Result<Drawing, RenderError> {
    let plate = Plate::fit(field)?;
    let flat: Vec<(Vector2<f64>, &photopose_field::Target)> = field
        .targets()
        .iter()
        .map(|t| (plate.to_plate(&t.position), t))
        .collect();
    // Labels that keep out of every quiet zone.
    let h = options.label_mm;
    let labels: Vec<Option<(Vector2<f64>, Vector2<f64>)>> = flat
        .iter()
        .map(|(at, t)| {
            if h <= 0.0 {
                return None;
            }
            let (lo, hi) = label_box(*at, t.quiet_radius(), &t.id.to_string(), h);
            flat.iter()
                .all(|(o, ot)| box_distance(*o, lo, hi) > ot.quiet_radius())
                .then_some((lo, hi))
        })
        .collect();
    // Extent: quiet zones, labels, border.
    let (mut lo, mut hi) = (
        Vector2::repeat(f64::INFINITY),
        Vector2::repeat(f64::NEG_INFINITY),
    );
    for ((at, t), label) in flat.iter().zip(&labels) {
        let q = Vector2::repeat(t.quiet_radius());
        lo = lo.inf(&(at - q));
        hi = hi.sup(&(at + q));
        if let Some((a, b)) = label {
            lo = lo.inf(a);
            hi = hi.sup(b);
        }
    }
    lo -= Vector2::repeat(options.border_mm);
    hi += Vector2::repeat(options.border_mm);
    let size = hi - lo;
    let to_svg = |p: Vector2<f64>| (num(p.x - lo.x), num(hi.y - p.y));

    let mut comment = String::new();
    let (w, hh) = (num(size.x), num(size.y));
    // Writing into a String cannot fail.
    let _ = writeln!(
        comment,
        "<!-- photopose test field: {} targets ({} coded), 1:1 in mm, seen from +Z \
         (the targets' side); plate axes u right, v up; plate origin (centroid of the \
         targets) at ({}, {}) in the drawing. Code sector k spans [k*30, (k+1)*30) degrees \
         counter-clockwise from +u. Print at 100 %. -->",
        field.len(),
        field.coded().count(),
        num(-lo.x),
        num(hi.y),
    );
    let mut s = String::new();
    let _ = writeln!(
        s,
        r##"<rect x="0" y="0" width="{w}" height="{hh}" fill="#000"/>"##
    );
    let _ = writeln!(s, r##"<g fill="#fff" stroke="none">"##);
    for (at, t) in &flat {
        let (cx, cy) = to_svg(*at);
        let _ = writeln!(
            s,
            r#"<circle id="t{}" cx="{cx}" cy="{cy}" r="{}"/>"#,
            t.id,
            num(t.radius)
        );
        if t.kind == TargetKind::Coded {
            let value = codes::value_of(t.id).unwrap_or(0);
            for (k0, len) in bright_runs(value) {
                let _ = writeln!(
                    s,
                    r#"<path d="{}"/>"#,
                    sector_path(*at, t.radius, k0, len, &to_svg)
                );
            }
        }
    }
    let _ = writeln!(s, "</g>");
    if labels.iter().any(Option::is_some) {
        let _ = writeln!(
            s,
            r##"<g fill="#808080" font-family="sans-serif" font-size="{}" text-anchor="middle">"##,
            num(h)
        );
        for ((_, t), label) in flat.iter().zip(&labels) {
            if let Some((a, b)) = label {
                let (x, y) = to_svg(Vector2::new(0.5 * (a.x + b.x), a.y + 0.15 * h));
                let _ = writeln!(s, r#"<text x="{x}" y="{y}">{}</text>"#, t.id);
            }
        }
        let _ = writeln!(s, "</g>");
    }
    let at = |p: Vector2<f64>| (p.x - lo.x, hi.y - p.y);
    let o = plate.to_plate(&nalgebra::Vector3::zeros());
    let direction = |axis: nalgebra::Vector3<f64>| {
        let d = plate.to_plate(&axis) - o;
        let n = d.norm().max(f64::MIN_POSITIVE);
        (d.x / n, -d.y / n)
    };
    Ok(Drawing {
        width_mm: size.x,
        height_mm: size.y,
        comment,
        content: s,
        targets: flat
            .iter()
            .map(|(p, t)| {
                let (x, y) = at(*p);
                DrawnTarget {
                    id: t.id,
                    x,
                    y,
                    radius: t.bright_radius(),
                }
            })
            .collect(),
        origin: at(o),
        axes: [
            direction(nalgebra::Vector3::x()),
            direction(nalgebra::Vector3::y()),
        ],
    })
}

/// Runs of consecutive bright sectors `(first sector, length)`, cyclic.
pub fn bright_runs(value: u16) -> Vec<(u32, u32)> {
    let bit = |k: u32| codes::sector_bit(value, k % 12);
    let mut runs = Vec::new();
    if (0..12).all(bit) {
        runs.push((0, 12));
        return runs;
    }
    for k in 0..12 {
        // A run starts at a bright sector after a dark one.
        if bit(k) && !bit(k + 11) {
            let len = (0..12).take_while(|&j| bit(k + j)).count() as u32;
            runs.push((k, len));
        }
    }
    runs
}

/// The annular path of sectors `k0 .. k0 + len` (2 r to 3 r).
fn sector_path(
    at: Vector2<f64>,
    r: f64,
    k0: u32,
    len: u32,
    to_svg: &dyn Fn(Vector2<f64>) -> (String, String),
) -> String {
    let (r_in, r_out) = (2.0 * r, 3.0 * r);
    let sector = std::f64::consts::PI / 6.0;
    let point = |radius: f64, a: f64| to_svg(at + Vector2::new(a.cos(), a.sin()) * radius);
    if len >= 12 {
        // A full ring: two circles, even-odd fill.
        let (ox, oy) = point(r_out, 0.0);
        let (ix, iy) = point(r_in, 0.0);
        let (ox2, oy2) = point(r_out, std::f64::consts::PI);
        let (ix2, iy2) = point(r_in, std::f64::consts::PI);
        let (ro, ri) = (num(r_out), num(r_in));
        return format!(
            "M{ox} {oy}A{ro} {ro} 0 1 0 {ox2} {oy2}A{ro} {ro} 0 1 0 {ox} {oy}Z\
             M{ix} {iy}A{ri} {ri} 0 1 1 {ix2} {iy2}A{ri} {ri} 0 1 1 {ix} {iy}Z"
        );
    }
    let (a0, a1) = (k0 as f64 * sector, (k0 + len) as f64 * sector);
    let large = u8::from(len > 6);
    let (x0, y0) = point(r_out, a0);
    let (x1, y1) = point(r_out, a1);
    let (x2, y2) = point(r_in, a1);
    let (x3, y3) = point(r_in, a0);
    let (ro, ri) = (num(r_out), num(r_in));
    // Seen with v up, counter-clockwise on the plate is counter-clockwise
    // on the page; in SVG's y-down frame that is sweep-flag 0.
    format!("M{x0} {y0}A{ro} {ro} 0 {large} 0 {x1} {y1}L{x2} {y2}A{ri} {ri} 0 {large} 1 {x3} {y3}Z")
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use photopose_field::design::default_plate;
    use photopose_field::Target;

    fn one(id: u64, kind: TargetKind) -> Field {
        Field::new(vec![Target {
            id,
            position: Vector3::new(0.0, 0.0, 0.0),
            kind,
            radius: 2.0,
        }])
        .unwrap()
    }

    #[test]
    fn a_single_sector_is_drawn_at_its_angle_with_y_flipped() {
        // Code 1 = 000000000001: only sector 11, [330°, 360°), is bright:
        // below the +u axis on the plate, so *below* the centre on the page
        // (larger SVG y).
        let opts = SvgOptions {
            border_mm: 0.0,
            label_mm: 0.0,
        };
        let svg = plate_svg(&one(1, TargetKind::Coded), &opts).unwrap();
        // Quiet zone 8 mm, no border: the centre is at (8, 8).
        assert!(
            svg.contains(r#"width="16mm" height="16mm" viewBox="0 0 16 16""#),
            "{svg}"
        );
        assert!(
            svg.contains(r#"<circle id="t1" cx="8" cy="8" r="2"/>"#),
            "{svg}"
        );
        // Outer radius 6: from 330° (8 + 6 cos 330°, 8 + 6 sin 30°) to 360°
        // (14, 8), inner radius 4 back from (12, 8) to 330°.
        let want = "M13.1962 11A6 6 0 0 0 14 8L12 8A4 4 0 0 1 11.4641 10Z";
        assert!(svg.contains(want), "{svg}");
        assert_eq!(svg.matches("<path").count(), 1);
    }

    #[test]
    fn runs_merge_adjacent_bright_sectors() {
        // 000000001111 is not a code value, but runs are plain bit runs.
        assert_eq!(bright_runs(0b0000_0000_1111), vec![(8, 4)]);
        assert_eq!(bright_runs(0b1000_0000_0001), vec![(11, 2)]);
        assert_eq!(bright_runs(0b0101_0000_0110), vec![(1, 1), (3, 1), (9, 2)]);
        assert!(bright_runs(0).is_empty());
        // Every bright sector of every code is in exactly one run.
        for id in 1..=350 {
            let v = codes::value_of(id).unwrap();
            let covered: u32 = bright_runs(v).iter().map(|r| r.1).sum();
            assert_eq!(covered, v.count_ones(), "id {id}");
        }
    }

    #[test]
    fn default_plate_is_drawn_whole_with_labels_clear_of_quiet_zones() {
        let field = default_plate();
        let svg = plate_svg(&field, &SvgOptions::default()).unwrap();
        assert_eq!(svg.matches("<circle").count(), field.len());
        // 544 mm between the outer columns (uncoded: 5 mm surround), 10 mm border.
        let width: f64 = svg
            .split("width=\"")
            .nth(1)
            .and_then(|s| s.split("mm\"").next())
            .unwrap()
            .parse()
            .unwrap();
        assert!((width - (544.0 + 2.0 * 5.0 + 20.0)).abs() < 1e-9, "{width}");
        assert_eq!(svg.matches("<text").count(), field.len());
        let uncoded = one(1001, TargetKind::Uncoded);
        let svg = plate_svg(&uncoded, &SvgOptions::default()).unwrap();
        assert!(!svg.contains("<path") && svg.contains(">1001</text>"));
    }
}
