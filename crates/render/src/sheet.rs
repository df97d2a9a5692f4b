//! Printing the plate drawing: the annotated drawing (a white margin with a
//! scale-check bar, the field's origin and axes, its name and checksum) and
//! its layout on ISO A paper at 1:1 — centred on one sheet when it fits,
//! otherwise as tiles that overlap, carry alignment crosses in the overlaps
//! and a label `rRcC` (row R, column C, from the top left).
//!
//! Every length is a millimetre of the print: pages are SVGs whose `width`
//! and `height` are in `mm` and whose `viewBox` counts millimetres.

use crate::svg::{Drawing, DrawnTarget};
use crate::RenderError;
use std::fmt::Write;

/// Margin left blank at every page edge (printers do not print there), mm.
pub const PRINTER_MARGIN_MM: f64 = 10.0;
/// Length of the scale-check bar, mm.
pub const SCALE_BAR_MM: f64 = 100.0;
/// White margin around the plate of an annotated drawing (left, top, right), mm.
const SIDE_MM: f64 = 15.0;
/// Height of the bottom strip with the bar and the texts, mm.
const STRIP_MM: f64 = 40.0;

/// An ISO 216 A paper size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Paper {
    /// 841 × 1189 mm.
    A0,
    /// 594 × 841 mm.
    A1,
    /// 420 × 594 mm.
    A2,
    /// 297 × 420 mm.
    A3,
    /// 210 × 297 mm.
    A4,
}

impl Paper {
    /// Every size, largest first.
    pub const ALL: [Paper; 5] = [Paper::A0, Paper::A1, Paper::A2, Paper::A3, Paper::A4];

    /// Short and long side, mm.
    pub fn size_mm(self) -> (f64, f64) {
        match self {
            Paper::A0 => (841.0, 1189.0),
            Paper::A1 => (594.0, 841.0),
            Paper::A2 => (420.0, 594.0),
            Paper::A3 => (297.0, 420.0),
            Paper::A4 => (210.0, 297.0),
        }
    }

    /// Its name (`A3`).
    pub fn name(self) -> &'static str {
        match self {
            Paper::A0 => "A0",
            Paper::A1 => "A1",
            Paper::A2 => "A2",
            Paper::A3 => "A3",
            Paper::A4 => "A4",
        }
    }

    /// The size of a name (`a3` or `A3`).
    pub fn parse(name: &str) -> Option<Paper> {
        Paper::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(name.trim()))
    }
}

/// What the annotations say about the field.
#[derive(Debug, Clone, Copy, Default)]
pub struct SheetText<'a> {
    /// The field's name (e.g. its file name).
    pub name: &'a str,
    /// A checksum of the field file (e.g. the first hex digits of its SHA-256).
    pub checksum: &'a str,
    /// One more line (e.g. tool and date).
    pub footer: &'a str,
}

/// Escapes text for the SVG.
fn esc(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// `drawing` in a white margin that carries the scale-check bar
/// ([`SCALE_BAR_MM`] with a tick every 10 mm and "measure: must be
/// 100.0 mm"), ticks marking the field's origin on all four sides, arrows
/// of the field's `X` and `Y` axes, the field's name and checksum.
pub fn annotate(drawing: &Drawing, text: &SheetText) -> Drawing {
    let (dx, dy) = (SIDE_MM, SIDE_MM);
    let width = (drawing.width_mm + 2.0 * SIDE_MM).max(SCALE_BAR_MM + 200.0);
    let height = drawing.height_mm + SIDE_MM + STRIP_MM;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r##"<rect x="0" y="0" width="{width:.3}" height="{height:.3}" fill="#fff"/>"##
    );
    let _ = writeln!(s, r#"<g transform="translate({dx} {dy})">"#);
    s.push_str(&drawing.content);
    let _ = writeln!(s, "</g>");
    let _ = writeln!(
        s,
        r##"<g class="annotations" stroke="#000" stroke-width="0.3" fill="none">"##
    );
    // The field's origin: ticks on the four sides, where its lines meet them.
    let (ox, oy) = (drawing.origin.0 + dx, drawing.origin.1 + dy);
    let (top, bottom) = (dy, dy + drawing.height_mm);
    let (left, right) = (dx, dx + drawing.width_mm);
    let mut labels = String::new();
    if (left..=right).contains(&ox) {
        let _ = writeln!(
            s,
            r#"<path class="origin" d="M{ox:.3} {:.3}V{:.3}M{ox:.3} {:.3}V{:.3}"/>"#,
            top - 10.0,
            top - 1.0,
            bottom + 1.0,
            bottom + 10.0
        );
        let _ = writeln!(
            labels,
            r#"<text x="{:.3}" y="{:.3}">origin</text>"#,
            ox + 1.5,
            top - 6.0
        );
    }
    if (top..=bottom).contains(&oy) {
        let _ = writeln!(
            s,
            r#"<path class="origin" d="M{:.3} {oy:.3}H{:.3}M{:.3} {oy:.3}H{:.3}"/>"#,
            left - 10.0,
            left - 1.0,
            right + 1.0,
            right + 10.0
        );
    }
    // The axes, drawn in the bottom strip's left corner.
    let base = (dx + 6.0, bottom + 31.0);
    for (k, (ux, uy)) in drawing.axes.iter().enumerate() {
        let tip = (base.0 + 16.0 * ux, base.1 + 16.0 * uy);
        // Arrow head: two strokes back from the tip.
        let back = |a: f64| {
            let (c, sn) = (a.cos(), a.sin());
            (
                tip.0 - 3.0 * (ux * c - uy * sn),
                tip.1 - 3.0 * (ux * sn + uy * c),
            )
        };
        let (h1, h2) = (back(0.45), back(-0.45));
        let _ = writeln!(
            s,
            r#"<path class="axis" d="M{:.3} {:.3}L{:.3} {:.3}M{:.3} {:.3}L{:.3} {:.3}L{:.3} {:.3}"/>"#,
            base.0, base.1, tip.0, tip.1, h1.0, h1.1, tip.0, tip.1, h2.0, h2.1
        );
        let _ = writeln!(
            labels,
            r#"<text x="{:.3}" y="{:.3}" text-anchor="middle">{}</text>"#,
            base.0 + 20.0 * ux,
            base.1 + 20.0 * uy + 1.2,
            ["X", "Y"][k]
        );
    }
    // The scale-check bar with a tick every 10 mm.
    let (bx, by) = (dx + 40.0, bottom + 14.0);
    let _ = writeln!(
        s,
        r#"<path class="scale-bar" stroke-width="0.5" d="M{bx:.3} {by:.3}H{:.3}"/>"#,
        bx + SCALE_BAR_MM
    );
    let mut d = String::new();
    for k in 0..=(SCALE_BAR_MM / 10.0) as usize {
        let x = bx + 10.0 * k as f64;
        let len = if k % 5 == 0 { 5.0 } else { 3.0 };
        let _ = write!(d, "M{x:.3} {by:.3}V{:.3}", by - len);
    }
    let _ = writeln!(s, r#"<path class="scale-ticks" d="{d}"/>"#);
    let _ = writeln!(s, "</g>");
    let _ = writeln!(
        s,
        r##"<g class="annotation-text" fill="#000" font-family="sans-serif" font-size="3.5">"##
    );
    s.push_str(&labels);
    let _ = writeln!(
        s,
        r#"<text x="{bx:.3}" y="{:.3}">0</text><text x="{:.3}" y="{:.3}" text-anchor="end">{} mm</text>"#,
        by - 6.0,
        bx + SCALE_BAR_MM,
        by - 6.0,
        SCALE_BAR_MM
    );
    let _ = writeln!(
        s,
        r#"<text x="{bx:.3}" y="{:.3}">measure: must be {:.1} mm</text><text x="{bx:.3}" y="{:.3}">(print at 100 %, no fitting to the page)</text>"#,
        by + 7.0,
        SCALE_BAR_MM,
        by + 13.0
    );
    let tx = bx + SCALE_BAR_MM + 25.0;
    for (k, line) in [
        format!("field: {}", esc(text.name)),
        format!("field file sha256: {}", esc(text.checksum)),
        esc(text.footer),
    ]
    .iter()
    .enumerate()
    {
        let _ = writeln!(
            s,
            r#"<text x="{tx:.3}" y="{:.3}">{line}</text>"#,
            by - 4.0 + 6.0 * k as f64
        );
    }
    let _ = writeln!(s, "</g>");
    Drawing {
        width_mm: width,
        height_mm: height,
        comment: drawing.comment.clone(),
        content: s,
        targets: drawing
            .targets
            .iter()
            .map(|t| DrawnTarget {
                x: t.x + dx,
                y: t.y + dy,
                ..*t
            })
            .collect(),
        origin: (ox, oy),
        axes: drawing.axes,
    }
}

/// One tile: the window of the drawing it prints, drawing mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tile {
    /// Row, from 0 at the top.
    pub row: usize,
    /// Column, from 0 at the left.
    pub col: usize,
    /// Left edge of the window.
    pub x: f64,
    /// Top edge of the window.
    pub y: f64,
    /// Width of the window.
    pub w: f64,
    /// Height of the window.
    pub h: f64,
}

impl Tile {
    /// The label printed on it: `r1c2` is the first row, second column.
    pub fn label(&self) -> String {
        format!("r{}c{}", self.row + 1, self.col + 1)
    }

    /// True when the whole disc `(x, y, radius)` lies inside the window.
    pub fn holds(&self, t: &DrawnTarget) -> bool {
        t.x - t.radius >= self.x
            && t.x + t.radius <= self.x + self.w
            && t.y - t.radius >= self.y
            && t.y + t.radius <= self.y + self.h
    }
}

/// How a drawing goes onto sheets of one paper size.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// The paper.
    pub paper: Paper,
    /// Long side horizontal.
    pub landscape: bool,
    /// Page width, mm.
    pub page_w: f64,
    /// Page height, mm.
    pub page_h: f64,
    /// Tile rows.
    pub rows: usize,
    /// Tile columns.
    pub cols: usize,
    /// Smallest overlap of neighbouring tiles, mm.
    pub overlap_mm: f64,
    /// The tiles, row by row.
    pub tiles: Vec<Tile>,
}

/// Windows along one axis: `(start, length)` of each, overlapping by at
/// least `overlap`, spread evenly over `length` with windows of `printable`.
fn windows(length: f64, printable: f64, overlap: f64) -> Vec<(f64, f64)> {
    if length <= printable {
        return vec![(0.0, length)];
    }
    let n = ((length - overlap) / (printable - overlap)).ceil().max(2.0) as usize;
    let step = (length - printable) / (n - 1) as f64;
    (0..n).map(|k| (k as f64 * step, printable)).collect()
}

/// The layout of a `width` × `height` mm drawing on `paper` at 1:1 with
/// tiles overlapping by at least `overlap_mm`; of the two orientations the
/// one with fewer sheets (landscape when equal).
pub fn layout(
    width: f64,
    height: f64,
    paper: Paper,
    overlap_mm: f64,
) -> Result<Layout, RenderError> {
    let (short, long) = paper.size_mm();
    let printable = short - 2.0 * PRINTER_MARGIN_MM;
    if !(overlap_mm.is_finite() && overlap_mm >= 0.0 && overlap_mm < printable / 2.0) {
        return Err(RenderError::BadSheet {
            what: format!(
                "overlap {overlap_mm} mm must be ≥ 0 and less than half the printable {printable} mm of {}",
                paper.name()
            ),
        });
    }
    if !(width.is_finite() && height.is_finite() && width > 0.0 && height > 0.0) {
        return Err(RenderError::BadSheet {
            what: format!("drawing size {width} × {height} mm"),
        });
    }
    let make = |landscape: bool| {
        let (page_w, page_h) = if landscape {
            (long, short)
        } else {
            (short, long)
        };
        let cols = windows(width, page_w - 2.0 * PRINTER_MARGIN_MM, overlap_mm);
        let rows = windows(height, page_h - 2.0 * PRINTER_MARGIN_MM, overlap_mm);
        let mut tiles = Vec::with_capacity(rows.len() * cols.len());
        for (row, &(y, h)) in rows.iter().enumerate() {
            for (col, &(x, w)) in cols.iter().enumerate() {
                tiles.push(Tile {
                    row,
                    col,
                    x,
                    y,
                    w,
                    h,
                });
            }
        }
        Layout {
            paper,
            landscape,
            page_w,
            page_h,
            rows: rows.len(),
            cols: cols.len(),
            overlap_mm,
            tiles,
        }
    };
    let (land, port) = (make(true), make(false));
    Ok(if port.tiles.len() < land.tiles.len() {
        port
    } else {
        land
    })
}

/// Alignment crosses at the middle of every overlap, in drawing mm: where
/// the overlap of two neighbouring columns meets the middle of each row's
/// window, and the overlap of two rows the middle of each column's.
fn crosses(layout: &Layout) -> Vec<(f64, f64)> {
    let col = |c: usize| layout.tiles[c];
    let row = |r: usize| layout.tiles[r * layout.cols];
    let mut out = Vec::new();
    for c in 0..layout.cols.saturating_sub(1) {
        let x = 0.5 * (col(c + 1).x + col(c).x + col(c).w);
        for r in 0..layout.rows {
            out.push((x, row(r).y + 0.5 * row(r).h));
        }
    }
    for r in 0..layout.rows.saturating_sub(1) {
        let y = 0.5 * (row(r + 1).y + row(r).y + row(r).h);
        for c in 0..layout.cols {
            out.push((col(c).x + 0.5 * col(c).w, y));
        }
    }
    out
}

/// One printed page.
#[derive(Debug, Clone, PartialEq)]
pub struct Sheet {
    /// `r1c2`, or `sheet` when the drawing fits one page.
    pub label: String,
    /// The page as SVG, 1:1 in mm.
    pub svg: String,
}

/// The pages of `drawing` on `layout`: one page with the drawing centred
/// when it fits, else one page per tile with its window of the drawing at
/// the printer margin, the alignment crosses (red, in the overlaps: lay the
/// next tile over this one so that they coincide) and its label.
pub fn sheets(drawing: &Drawing, layout: &Layout) -> Vec<Sheet> {
    let (pw, ph) = (layout.page_w, layout.page_h);
    let one = layout.tiles.len() == 1;
    let marks = crosses(layout);
    let mut mark_svg = String::new();
    if !marks.is_empty() {
        let _ = writeln!(
            mark_svg,
            r##"<g class="alignment" stroke="#e00000" stroke-width="0.25" fill="none">"##
        );
        for (x, y) in &marks {
            let _ = writeln!(
                mark_svg,
                r#"<path d="M{:.3} {y:.3}H{:.3}M{x:.3} {:.3}V{:.3}"/><circle cx="{x:.3}" cy="{y:.3}" r="2.5"/>"#,
                x - 6.0,
                x + 6.0,
                y - 6.0,
                y + 6.0
            );
        }
        let _ = writeln!(mark_svg, "</g>");
    }
    layout
        .tiles
        .iter()
        .map(|t| {
            let label = if one { "sheet".to_string() } else { t.label() };
            let (px, py) = if one {
                (0.5 * (pw - t.w), 0.5 * (ph - t.h))
            } else {
                (PRINTER_MARGIN_MM, PRINTER_MARGIN_MM)
            };
            let mut s = String::new();
            let _ = writeln!(s, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
            let _ = writeln!(
                s,
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="{pw}mm" height="{ph}mm" viewBox="0 0 {pw} {ph}">"#
            );
            let _ = writeln!(
                s,
                "<title>plate drawing, {} {}, 1:1, {label}</title>",
                layout.paper.name(),
                if layout.landscape {
                    "landscape"
                } else {
                    "portrait"
                }
            );
            s.push_str(&drawing.comment);
            let _ = writeln!(
                s,
                r#"<svg class="window" x="{px:.3}" y="{py:.3}" width="{:.3}" height="{:.3}" viewBox="{:.3} {:.3} {:.3} {:.3}" overflow="hidden">"#,
                t.w, t.h, t.x, t.y, t.w, t.h
            );
            s.push_str(&drawing.content);
            s.push_str(&mark_svg);
            let _ = writeln!(s, "</svg>");
            if !one {
                let _ = writeln!(
                    s,
                    r##"<text class="tile-label" x="{:.3}" y="{:.3}" font-family="sans-serif" font-size="4" fill="#000">{label} (row {}, column {} of {} × {}; overlap ≥ {} mm: lay neighbours over each other so that the red crosses coincide)</text>"##,
                    PRINTER_MARGIN_MM,
                    PRINTER_MARGIN_MM - 3.0,
                    t.row + 1,
                    t.col + 1,
                    layout.rows,
                    layout.cols,
                    layout.overlap_mm
                );
            }
            let _ = writeln!(s, "</svg>");
            Sheet { label, svg: s }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::svg::{plate_drawing, SvgOptions};
    use photopose_field::design::default_plate;

    #[test]
    fn paper_names_parse() {
        assert_eq!(Paper::parse("a3"), Some(Paper::A3));
        assert_eq!(Paper::parse(" A0 "), Some(Paper::A0));
        assert_eq!(Paper::parse("B4"), None);
    }

    #[test]
    fn a_574_by_432_drawing_takes_four_a3_and_two_a2_sheets_and_one_a1() {
        let a3 = layout(574.0, 432.0, Paper::A3, 20.0).unwrap();
        assert_eq!(
            (a3.tiles.len(), a3.rows, a3.cols, a3.landscape),
            (4, 2, 2, true)
        );
        let a2 = layout(574.0, 432.0, Paper::A2, 20.0).unwrap();
        assert_eq!(a2.tiles.len(), 2);
        let a1 = layout(574.0, 432.0, Paper::A1, 20.0).unwrap();
        assert_eq!(a1.tiles.len(), 1);
        assert_eq!((a1.page_w, a1.page_h), (841.0, 594.0));
        // Windows never exceed the printable area and overlap enough.
        for l in [&a3, &a2] {
            for t in &l.tiles {
                assert!(t.w <= l.page_w - 2.0 * PRINTER_MARGIN_MM + 1e-9);
                assert!(t.h <= l.page_h - 2.0 * PRINTER_MARGIN_MM + 1e-9);
            }
            for pair in l.tiles.windows(2).filter(|p| p[0].row == p[1].row) {
                assert!(pair[0].x + pair[0].w - pair[1].x >= 20.0 - 1e-9);
            }
            let last = l.tiles.last().unwrap();
            assert!(
                (last.x + last.w - 574.0).abs() < 1e-9 && (last.y + last.h - 432.0).abs() < 1e-9
            );
        }
        assert!(layout(574.0, 432.0, Paper::A4, 200.0).is_err());
    }

    fn default_drawing() -> Drawing {
        let d = plate_drawing(&default_plate(), &SvgOptions::default()).unwrap();
        annotate(
            &d,
            &SheetText {
                name: "plate.csv",
                checksum: "0123456789ab",
                footer: "photopose test",
            },
        )
    }

    #[test]
    fn every_target_lies_wholly_on_some_tile() {
        let d = default_drawing();
        for paper in Paper::ALL {
            let l = layout(d.width_mm, d.height_mm, paper, 20.0).unwrap();
            for t in &d.targets {
                assert!(
                    l.tiles.iter().any(|tile| tile.holds(t)),
                    "target {} on {}",
                    t.id,
                    paper.name()
                );
            }
        }
        // 604 × 487 mm annotated: portrait A4 (190 × 277 mm printable) in
        // 4 columns and 2 rows.
        let a4 = layout(d.width_mm, d.height_mm, Paper::A4, 20.0).unwrap();
        assert_eq!((a4.cols, a4.rows, a4.landscape), (4, 2, false));
        assert_eq!(
            layout(d.width_mm, d.height_mm, Paper::A2, 20.0)
                .unwrap()
                .tiles
                .len(),
            2
        );
    }

    #[test]
    fn sheets_are_1_to_1_in_mm_with_labels_and_crosses() {
        let d = default_drawing();
        let l = layout(d.width_mm, d.height_mm, Paper::A3, 20.0).unwrap();
        let pages = sheets(&d, &l);
        assert_eq!(pages.len(), l.tiles.len());
        for (p, t) in pages.iter().zip(&l.tiles) {
            assert!(p
                .svg
                .contains(r#"width="420mm" height="297mm" viewBox="0 0 420 297""#));
            // The window: as many mm of the drawing as of the page.
            assert!(p.svg.contains(&format!(
                r#"width="{:.3}" height="{:.3}" viewBox="{:.3} {:.3} {:.3} {:.3}""#,
                t.w, t.h, t.x, t.y, t.w, t.h
            )));
            assert!(p.svg.contains(&format!(">{} (row", t.label())));
            assert!(p.svg.contains("<g class=\"alignment\""));
        }
        assert_eq!(pages[1].label, "r1c2");
        let one = sheets(
            &d,
            &layout(d.width_mm, d.height_mm, Paper::A0, 20.0).unwrap(),
        );
        assert_eq!(one.len(), 1);
        assert!(one[0].svg.contains(r#"width="1189mm" height="841mm""#));
        assert!(!one[0].svg.contains("alignment"));
    }

    #[test]
    fn the_annotations_carry_scale_bar_origin_axes_name_and_checksum() {
        let plain = plate_drawing(&default_plate(), &SvgOptions::default()).unwrap();
        let d = default_drawing();
        assert_eq!(d.width_mm, plain.width_mm + 30.0);
        assert_eq!(d.height_mm, plain.height_mm + 55.0);
        let s = d.to_svg();
        // A 100 mm bar in drawing (= printed) millimetres, 11 ticks.
        let bar = s.split("class=\"scale-bar\"").nth(1).unwrap();
        let path: &str = bar
            .split("d=\"M")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap();
        let (start, end) = path.split_once('H').unwrap();
        let x0: f64 = start.split(' ').next().unwrap().parse().unwrap();
        let x1: f64 = end.parse().unwrap();
        assert!((x1 - x0 - 100.0).abs() < 1e-9, "{path}");
        let ticks = s.split("class=\"scale-ticks\"").nth(1).unwrap();
        assert_eq!(ticks.split('"').nth(1).unwrap().matches('M').count(), 11);
        assert!(s.contains("measure: must be 100.0 mm"));
        assert!(s.contains("field: plate.csv") && s.contains("sha256: 0123456789ab"));
        assert_eq!(s.matches("class=\"origin\"").count(), 2);
        assert_eq!(s.matches("class=\"axis\"").count(), 2);
        assert!(s.contains(">X</text>") && s.contains(">Y</text>"));
        // The default plate's axes: X right, Y up the page.
        assert!((d.axes[0].0 - 1.0).abs() < 1e-9 && (d.axes[1].1 + 1.0).abs() < 1e-9);
        // Its origin is the centre of the targets, where the drawing put it.
        assert!((d.origin.0 - (plain.origin.0 + 15.0)).abs() < 1e-9);
    }
}
