//! Residual plots as SVG text (pure: the caller writes the file): the
//! residual vectors of every image, magnified, over the sensor; and the
//! radial residual component against the distance from the principal point.
//! A model that fits leaves no pattern in either. Both have axes with ticks
//! and units, a title naming the camera and the date, and the residual
//! vector plot a scale arrow and one line per image (natural order).

use crate::calibrate::AdjustedImage;
use crate::report::natural_cmp;
use photopose_geometry::Camera;
use std::fmt::Write;

/// What the caller knows about a plot that the adjustment does not: the
/// camera's name, the date, and any SVG to carry (e.g. a `<metadata>`
/// element with the provenance).
#[derive(Debug, Clone, Copy, Default)]
pub struct PlotLabels<'a> {
    /// The camera, as the title names it (e.g. the camera file written).
    pub camera: &'a str,
    /// The date of the calibration (UTC, RFC 3339).
    pub date: &'a str,
    /// SVG inserted right after the opening tag (already escaped).
    pub metadata: &'a str,
}

/// A tick step of 1, 2 or 5 × 10ⁿ giving about `count` ticks over `range`.
pub fn tick_step(range: f64, count: f64) -> f64 {
    if !(range.is_finite() && range > 0.0) {
        return 1.0;
    }
    let raw = range / count.max(1.0);
    let decade = 10f64.powf(raw.log10().floor());
    let m = raw / decade;
    let nice = if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * decade
}

/// A tick label: as many decimals as the step needs.
fn tick_label(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let s = format!("{v:.decimals$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Escapes text for the SVG.
fn esc(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The title line: what, the camera, the date.
fn title(what: &str, labels: &PlotLabels) -> String {
    let mut t = what.to_string();
    if !labels.camera.is_empty() {
        t.push_str(" — camera ");
        t.push_str(labels.camera);
    }
    if !labels.date.is_empty() {
        t.push_str(" — ");
        t.push_str(labels.date);
    }
    esc(&t)
}

/// Ticks along a horizontal axis at `y` (drawing units), values `0..=max`
/// mapped by `to_x`, labels below.
fn x_ticks(s: &mut String, max: f64, step: f64, y: f64, to_x: impl Fn(f64) -> f64) {
    let mut v = 0.0;
    while v <= max + 1e-9 * step {
        let x = to_x(v);
        let _ = writeln!(
            s,
            r#"<line x1="{x:.1}" y1="{y:.1}" x2="{x:.1}" y2="{:.1}" stroke="black"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            y + 5.0,
            y + 18.0,
            tick_label(v, step)
        );
        v += step;
    }
}

/// Ticks along a vertical axis at `x`, values `lo..=hi` mapped by `to_y`,
/// labels to the left.
fn y_ticks(s: &mut String, (lo, hi): (f64, f64), step: f64, x: f64, to_y: impl Fn(f64) -> f64) {
    let mut v = (lo / step).ceil() * step;
    while v <= hi + 1e-9 * step {
        let y = to_y(v);
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{y:.1}" x2="{x:.1}" y2="{y:.1}" stroke="black"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
            x - 5.0,
            x - 8.0,
            y + 4.0,
            tick_label(v, step)
        );
        v += step;
    }
}

/// Residual vectors over the sensor, magnified so that the largest used
/// residual is drawn `1/20` of the sensor width long; a scale arrow gives
/// the residual length it stands for, the axes the sensor's pixels, and
/// one line per image its points and RMS (images in natural order).
pub fn vector_plot(camera: &Camera, images: &[AdjustedImage], labels: &PlotLabels) -> String {
    let (w, h) = (camera.sensor.width as f64, camera.sensor.height as f64);
    let scale = 800.0 / w;
    let (pw, ph) = (w * scale, h * scale);
    let largest = images
        .iter()
        .flat_map(|im| im.residuals.iter().filter(|r| r.used))
        .map(|r| r.dcol.hypot(r.drow))
        .fold(0.0, f64::max)
        .max(1e-6);
    let magnification = (w / 20.0 / largest).round().max(1.0);
    let mut order: Vec<&AdjustedImage> = images.iter().collect();
    order.sort_by(|a, b| natural_cmp(&a.name, &b.name));
    // Layout: title above, axes left and below, scale arrow and image lines under them.
    let (left, top, right) = (70.0, 60.0, 20.0);
    let arrow_y = ph + 70.0;
    let lines_y = arrow_y + 30.0;
    let total_w = left + pw + right;
    let total_h = top + lines_y + 16.0 * order.len() as f64 + 10.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{total_w:.0}" height="{total_h:.0}" viewBox="{:.0} {:.0} {total_w:.0} {total_h:.0}" font-family="sans-serif" font-size="12">"#,
        -left, -top
    );
    s.push_str(labels.metadata);
    let _ = writeln!(
        s,
        r#"<text x="0" y="-38" font-size="14">{}</text>"#,
        title("Image residuals", labels)
    );
    let _ = writeln!(
        s,
        r#"<text x="0" y="-20">{} images; vectors magnified × {magnification} (largest used {largest:.3} px); red: rejected; blue circle: principal point</text>"#,
        images.len()
    );
    let _ = writeln!(
        s,
        r#"<rect x="0" y="0" width="{pw:.1}" height="{ph:.1}" fill="white" stroke="black"/>"#
    );
    // Axes: sensor columns below, rows on the left, pixels.
    let step = tick_step(w.max(h), 6.0);
    x_ticks(&mut s, w, step, ph, |v| v * scale);
    y_ticks(&mut s, (0.0, h), step, 0.0, |v| v * scale);
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">column [px]</text><text transform="translate({:.1} {:.1}) rotate(-90)" text-anchor="middle">row [px]</text>"#,
        pw / 2.0,
        ph + 36.0,
        -52.0,
        ph / 2.0
    );
    let pp = camera.image_to_pixel(nalgebra::Vector2::new(
        camera.interior.x0,
        camera.interior.y0,
    ));
    let _ = writeln!(
        s,
        r#"<circle cx="{:.1}" cy="{:.1}" r="4" fill="none" stroke="blue"/>"#,
        pp.x * scale,
        pp.y * scale
    );
    for im in &order {
        for r in &im.residuals {
            let (x, y) = (r.col * scale, r.row * scale);
            let (x2, y2) = (
                x + r.dcol * magnification * scale,
                y + r.drow * magnification * scale,
            );
            let colour = if r.used { "black" } else { "red" };
            let _ = writeln!(
                s,
                r#"<circle cx="{x:.1}" cy="{y:.1}" r="0.8" fill="{colour}"/><line x1="{x:.1}" y1="{y:.1}" x2="{x2:.1}" y2="{y2:.1}" stroke="{colour}" stroke-width="0.6"/>"#
            );
        }
    }
    // Scale arrow: a round residual length drawn about 80 units long.
    let per_px = magnification * scale;
    let arrow_px = tick_step(80.0 / per_px, 1.0);
    let len = arrow_px * per_px;
    let _ = writeln!(
        s,
        r#"<g class="scale-arrow"><line x1="0" y1="{arrow_y:.1}" x2="{len:.1}" y2="{arrow_y:.1}" stroke="black" stroke-width="1.5"/><path d="M {len:.1} {arrow_y:.1} l -8 -4 l 0 8 z"/><text x="{:.1}" y="{:.1}">residual scale: this arrow = {} px (1 px = {:.1} drawn px)</text></g>"#,
        len + 12.0,
        arrow_y + 4.0,
        tick_label(arrow_px, arrow_px),
        per_px
    );
    for (k, im) in order.iter().enumerate() {
        let used: Vec<_> = im.residuals.iter().filter(|r| r.used).collect();
        let ss: f64 = used.iter().map(|r| r.dcol * r.dcol + r.drow * r.drow).sum();
        let rms = (ss / (2 * used.len().max(1)) as f64).sqrt();
        let _ = writeln!(
            s,
            r#"<text class="image" x="0" y="{:.1}">{}: {} points used, {} rejected, RMS {rms:.4} px</text>"#,
            lines_y + 16.0 * k as f64,
            esc(&im.name),
            used.len(),
            im.residuals.len() - used.len()
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Radial residual component (pixels, positive outwards) against the
/// radius from the principal point (pixels), with axes and ticks.
pub fn radial_plot(camera: &Camera, images: &[AdjustedImage], labels: &PlotLabels) -> String {
    let pp = camera.image_to_pixel(nalgebra::Vector2::new(
        camera.interior.x0,
        camera.interior.y0,
    ));
    let points: Vec<(f64, f64, bool)> = images
        .iter()
        .flat_map(|im| im.residuals.iter())
        .map(|r| {
            let (dx, dy) = (r.col - pp.x, r.row - pp.y);
            let rad = dx.hypot(dy);
            let radial = if rad > 0.0 {
                (r.dcol * dx + r.drow * dy) / rad
            } else {
                0.0
            };
            (rad, radial, r.used)
        })
        .collect();
    let rmax = (camera.sensor.width as f64).hypot(camera.sensor.height as f64) / 2.0;
    let vmax = points
        .iter()
        .filter(|p| p.2)
        .map(|p| p.1.abs())
        .fold(0.0, f64::max)
        .max(1e-6)
        * 1.1;
    let (pw, ph) = (800.0, 400.0);
    let (left, top) = (80.0, 60.0);
    let (total_w, total_h) = (pw + left + 30.0, ph + top + 60.0);
    let to_x = |r: f64| r / rmax * pw;
    let to_y = |v: f64| ph / 2.0 - (v / vmax).clamp(-1.0, 1.0) * ph / 2.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{total_w}" height="{total_h}" viewBox="{} {} {total_w} {total_h}" font-family="sans-serif" font-size="12">"#,
        -left, -top
    );
    s.push_str(labels.metadata);
    let _ = writeln!(
        s,
        r#"<text x="0" y="-38" font-size="14">{}</text>"#,
        title("Radial residuals", labels)
    );
    let _ = writeln!(
        s,
        r#"<text x="0" y="-20">radial component of each residual (positive outwards) against its distance from the principal point; red: rejected</text>"#
    );
    let _ = writeln!(
        s,
        r#"<rect x="0" y="0" width="{pw}" height="{ph}" fill="white" stroke="black"/><line x1="0" y1="{}" x2="{pw}" y2="{}" stroke="gray"/>"#,
        ph / 2.0,
        ph / 2.0
    );
    let xstep = tick_step(rmax, 8.0);
    x_ticks(&mut s, rmax, xstep, ph, to_x);
    let ystep = tick_step(2.0 * vmax, 8.0);
    y_ticks(&mut s, (-vmax, vmax), ystep, 0.0, to_y);
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">distance from the principal point [px]</text><text transform="translate({:.1} {:.1}) rotate(-90)" text-anchor="middle">radial residual [px]</text>"#,
        pw / 2.0,
        ph + 38.0,
        -62.0,
        ph / 2.0
    );
    for (rad, v, used) in points {
        let colour = if used { "black" } else { "red" };
        let _ = writeln!(
            s,
            r#"<circle cx="{:.1}" cy="{:.1}" r="1.2" fill="{colour}"/>"#,
            to_x(rad),
            to_y(v)
        );
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::Residual;
    use photopose_geometry::Exterior;

    #[test]
    fn plots_draw_every_residual_and_mark_rejected_ones_red() {
        let camera = Camera::reference_ideal();
        let residual = |col: f64, used| Residual {
            id: 1,
            col,
            row: 100.0,
            dcol: 0.05,
            drow: -0.02,
            used,
        };
        let images = [AdjustedImage {
            name: "a".into(),
            exterior: Exterior::from_kuka_pose([0.0, 0.0, 800.0, 0.0, 0.0, 0.0]),
            residuals: vec![
                residual(10.0, true),
                residual(600.0, true),
                residual(900.0, false),
            ],
        }];
        let labels = PlotLabels::default();
        let v = vector_plot(&camera, &images, &labels);
        assert!(v.starts_with("<svg") && v.ends_with("</svg>\n"));
        assert_eq!(v.matches("stroke-width=\"0.6\"").count(), 3);
        assert_eq!(v.matches("stroke=\"red\"").count(), 1);
        // Largest residual 0.0539 px drawn 65 px (1/20 of the width) long.
        assert!(v.contains("× 1207"), "{v}");
        let r = radial_plot(&camera, &images, &labels);
        assert_eq!(r.matches("r=\"1.2\"").count(), 3);
        assert_eq!(r.matches("fill=\"red\"").count(), 1);
    }

    fn camera() -> Camera {
        Camera::reference_ideal()
    }

    fn image(name: &str) -> AdjustedImage {
        AdjustedImage {
            name: name.into(),
            exterior: Exterior::from_kuka_pose([0.0, 0.0, 800.0, 0.0, 0.0, 0.0]),
            residuals: vec![Residual {
                id: 1,
                col: 300.0,
                row: 200.0,
                dcol: 0.05,
                drow: -0.02,
                used: true,
            }],
        }
    }

    #[test]
    fn plots_have_axes_ticks_units_a_scale_arrow_and_a_title() {
        let labels = PlotLabels {
            camera: "cam.toml",
            date: "2026-11-24T16:08:08Z",
            metadata: "<metadata>m</metadata>\n",
        };
        let v = vector_plot(&camera(), &[image("a")], &labels);
        assert!(v.contains("Image residuals — camera cam.toml — 2026-11-24T16:08:08Z"));
        assert!(v.contains("<metadata>m</metadata>"));
        assert!(v.contains("column [px]") && v.contains("row [px]"));
        // Ticks every 200 px: 0 … 1200 along the columns, 0 … 1000 along the rows.
        for t in ["0", "200", "1200", "1000"] {
            assert!(v.contains(&format!(">{t}</text>")), "tick {t}");
        }
        assert!(!v.contains(">1400</text>"));
        // Magnification 1207, 800/1300 drawn px per px: 742.8 per px, so the
        // arrow stands for 0.1 px (74.3 drawn px).
        assert!(
            v.contains("this arrow = 0.1 px (1 px = 742.8 drawn px)"),
            "{v}"
        );
        assert!(v.contains(r#"x2="74.3""#));
        let r = radial_plot(&camera(), &[image("a")], &labels);
        assert!(r.contains("Radial residuals — camera cam.toml — 2026-11-24T16:08:08Z"));
        assert!(r.contains("distance from the principal point [px]"));
        assert!(r.contains("radial residual [px]") && r.contains(">800</text>"));
    }

    #[test]
    fn image_lines_are_in_natural_order() {
        let images: Vec<_> = ["v10", "v2", "v1", "v11"].into_iter().map(image).collect();
        let v = vector_plot(&camera(), &images, &PlotLabels::default());
        let at = |n: &str| v.find(&format!(">{n}: ")).unwrap();
        assert!(at("v1") < at("v2") && at("v2") < at("v10") && at("v10") < at("v11"));
    }

    #[test]
    fn tick_steps_are_one_two_five() {
        assert_eq!(tick_step(1300.0, 6.0), 200.0);
        assert_eq!(tick_step(0.8, 8.0), 0.1);
        assert_eq!(tick_step(0.011, 1.0), 0.01);
        assert_eq!(tick_step(45.0, 1.0), 50.0);
        assert_eq!(tick_label(0.30000000000000004, 0.1), "0.3");
        assert_eq!(tick_label(-0.0, 0.1), "0.0");
    }
}
