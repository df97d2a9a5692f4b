//! The plots of a circular test as SVG text, in the form of the reference
//! paper's figure 2: the path with its radial deviations magnified
//! ([`path_svg`]), the radial deviation against the phase angle
//! ([`radial_svg`]) and the orientation deviations against the phase angle
//! ([`angular_svg`]). Raw samples are drawn thin and light, the harmonically
//! filtered profile thick. Pure: each returns a `String`.

use crate::analysis::{CircleTest, Direction};
use crate::harmonics::Series;
use std::f64::consts::TAU;
use std::fmt::Write;

const FONT: &str = "font-family=\"DejaVu Sans, Helvetica, Arial, sans-serif\"";
const COLORS: [&str; 3] = ["#d62728", "#2ca02c", "#1f77b4"];
/// Points on which a filtered series is drawn.
const CURVE_POINTS: usize = 720;

/// ` · F max …, min … µm` when the nominal circle was given, else nothing.
fn f_text(test: &CircleTest) -> String {
    test.f_um
        .map(|f| format!(" · F max {:+.1}, min {:+.1} µm", f.max, f.min))
        .unwrap_or_default()
}

/// A "nice" step (1, 2 or 5 × 10ⁿ) of about `raw`.
fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(raw.log10().floor());
    let f = raw / p;
    let m = if f <= 1.0 {
        1.0
    } else if f <= 2.0 {
        2.0
    } else if f <= 5.0 {
        5.0
    } else {
        10.0
    };
    m * p
}

/// Decimals needed to print multiples of `step`.
fn decimals(step: f64) -> usize {
    (-step.log10().floor()).max(0.0) as usize
}

fn open(s: &mut String, w: f64, h: f64) {
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\">"
    );
    let _ = writeln!(s, "<rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>");
}

fn text(s: &mut String, x: f64, y: f64, size: f64, anchor: &str, body: &str) {
    let _ = writeln!(
        s,
        "<text x=\"{x:.1}\" y=\"{y:.1}\" font-size=\"{size}\" text-anchor=\"{anchor}\" {FONT}>{}</text>",
        escape(body)
    );
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn polyline(s: &mut String, pts: &[(f64, f64)], stroke: &str, width: f64, extra: &str) {
    if pts.len() < 2 {
        return;
    }
    let _ = write!(
        s,
        "<polyline fill=\"none\" stroke=\"{stroke}\" stroke-width=\"{width}\" {extra} points=\""
    );
    for (x, y) in pts {
        let _ = write!(s, "{x:.2},{y:.2} ");
    }
    let _ = writeln!(s, "\"/>");
}

/// The path in its plane seen from the normal's tip (`u` right, `v` up),
/// the least-squares circle as reference and every radial deviation
/// multiplied by `magnify`; rings mark deviation steps.
pub fn path_svg(test: &CircleTest, title: &str, magnify: f64) -> String {
    let (w, h) = (720.0, 780.0);
    let (cx, cy, rpx) = (360.0, 430.0, 250.0);
    let r = test.radius_mm;
    let scale = rpx / r;
    let at = |theta: f64, dev: f64| {
        let rho = (r + magnify * dev) * scale;
        (cx + rho * theta.cos(), cy - rho * theta.sin())
    };
    let series = test.radial_series();
    let reach = match &series {
        Some(s) => {
            let (lo, hi) = s.extremes();
            lo.abs().max(hi.abs())
        }
        None => test.radial_mm.min.abs().max(test.radial_mm.max.abs()),
    };
    let step = nice_step(reach / 2.0);
    let mut s = String::new();
    open(&mut s, w, h);
    text(&mut s, w / 2.0, 30.0, 18.0, "middle", title);
    let filtered = test
        .g_filtered_um
        .map(|g| format!(", filtered {g:.1} µm ({} UPR)", test.harmonics_upr))
        .unwrap_or_default();
    text(
        &mut s,
        w / 2.0,
        56.0,
        13.0,
        "middle",
        &format!(
            "LSQ circle R = {:.4} mm · circular deviation G = {:.1} µm{filtered}{}",
            r,
            test.g_um,
            f_text(test)
        ),
    );
    text(
        &mut s,
        w / 2.0,
        76.0,
        13.0,
        "middle",
        &format!(
            "radial deviations × {magnify} · rings every {} µm · seen from the plane normal",
            fmt_num(step * 1e3, decimals(step * 1e3))
        ),
    );
    // Axes through the centre.
    let _ = writeln!(
        s,
        "<g stroke=\"#bbbbbb\" stroke-width=\"0.8\"><line x1=\"{:.1}\" y1=\"{cy}\" x2=\"{:.1}\" y2=\"{cy}\"/><line x1=\"{cx}\" y1=\"{:.1}\" x2=\"{cx}\" y2=\"{:.1}\"/></g>",
        cx - rpx - 60.0,
        cx + rpx + 60.0,
        cy - rpx - 60.0,
        cy + rpx + 60.0
    );
    text(&mut s, cx + rpx + 64.0, cy + 4.0, 12.0, "start", "u");
    text(&mut s, cx, cy - rpx - 66.0, 12.0, "middle", "v");
    for (deg, anchor, dx, dy) in [
        (0.0, "start", 4.0, -6.0),
        (90.0, "start", 6.0, -4.0),
        (180.0, "end", -4.0, -6.0),
        (270.0, "start", 6.0, 14.0),
    ] {
        let (x, y) = at(f64::to_radians(deg), 0.0);
        text(&mut s, x + dx, y + dy, 11.0, anchor, &format!("{deg}°"));
    }
    // Deviation rings, the reference circle dashed.
    // Every ring if they are far enough apart, else the outermost two.
    let n_rings = (reach / step).ceil().max(1.0) as i64;
    let dense = magnify * step * scale < 12.0;
    for k in -n_rings..=n_rings {
        if dense && k != 0 && k.abs() != n_rings {
            continue;
        }
        let rho = (r + magnify * k as f64 * step) * scale;
        if rho <= 0.0 {
            continue;
        }
        let style = if k == 0 {
            "stroke=\"#555555\" stroke-width=\"1\" stroke-dasharray=\"6 4\""
        } else {
            "stroke=\"#cccccc\" stroke-width=\"0.8\""
        };
        let _ = writeln!(
            s,
            "<circle cx=\"{cx}\" cy=\"{cy}\" r=\"{rho:.2}\" fill=\"none\" {style}/>"
        );
        if k == 0 {
            continue;
        }
        // Positive rings labelled outside at 50°, negative inside at 130°.
        let value = fmt_num(k as f64 * step * 1e3, decimals(step * 1e3));
        let (deg, anchor, dx, sign) = if k > 0 {
            (50f64, "start", 3.0, "+")
        } else {
            (130f64, "end", -3.0, "")
        };
        let a = deg.to_radians();
        text(
            &mut s,
            cx + rho * a.cos() + dx,
            cy - rho * a.sin(),
            9.0,
            anchor,
            &format!("{sign}{value} µm"),
        );
    }
    // Raw samples in time order, then the filtered profile.
    let raw: Vec<_> = test
        .samples
        .iter()
        .map(|p| at(p.phase_deg.to_radians(), p.radial_mm))
        .collect();
    polyline(&mut s, &raw, "#9a9a9a", 0.6, "stroke-opacity=\"0.8\"");
    if let Some(series) = &series {
        let curve: Vec<_> = (0..=CURVE_POINTS)
            .map(|i| {
                let t = TAU * i as f64 / CURVE_POINTS as f64;
                at(t, series.eval(t))
            })
            .collect();
        polyline(&mut s, &curve, COLORS[2], 2.0, "");
    }
    // Centre, start and direction.
    let _ = writeln!(
        s,
        "<g stroke=\"black\" stroke-width=\"1\"><line x1=\"{:.1}\" y1=\"{cy}\" x2=\"{:.1}\" y2=\"{cy}\"/><line x1=\"{cx}\" y1=\"{:.1}\" x2=\"{cx}\" y2=\"{:.1}\"/></g>",
        cx - 6.0,
        cx + 6.0,
        cy - 6.0,
        cy + 6.0
    );
    if let Some(first) = raw.first() {
        let _ = writeln!(
            s,
            "<circle cx=\"{:.2}\" cy=\"{:.2}\" r=\"4\" fill=\"black\"/>",
            first.0, first.1
        );
        text(
            &mut s,
            first.0 + 6.0,
            first.1 + 16.0,
            11.0,
            "start",
            "start",
        );
    }
    let dir = match test.direction {
        Direction::Ccw => "counter-clockwise",
        Direction::Cw => "clockwise",
    };
    let c = test.center_mm;
    text(
        &mut s,
        w / 2.0,
        h - 34.0,
        12.0,
        "middle",
        &format!(
            "{} samples, {dir}, {:.0}° swept · centre {:.3}, {:.3}, {:.3} mm",
            test.n_samples, test.coverage_deg, c[0], c[1], c[2]
        ),
    );
    text(
        &mut s,
        w / 2.0,
        h - 16.0,
        12.0,
        "middle",
        "dashed: least-squares circle · grey: samples · blue: filtered profile",
    );
    s.push_str("</svg>\n");
    s
}

/// Plot area of a chart against the phase angle (0–360°).
struct Chart {
    left: f64,
    top: f64,
    width: f64,
    height: f64,
    y0: f64,
    y1: f64,
    step: f64,
}

impl Chart {
    fn new(lo: f64, hi: f64, width: f64, height: f64) -> Chart {
        let (lo, hi) = if hi - lo > 1e-15 {
            (lo, hi)
        } else {
            (lo - 1.0, hi + 1.0)
        };
        let step = nice_step((hi - lo) / 6.0);
        Chart {
            left: 80.0,
            top: 70.0,
            width,
            height,
            y0: (lo / step).floor() * step,
            y1: (hi / step).ceil() * step,
            step,
        }
    }

    fn x(&self, deg: f64) -> f64 {
        self.left + self.width * deg / 360.0
    }

    fn y(&self, v: f64) -> f64 {
        self.top + self.height * (self.y1 - v) / (self.y1 - self.y0)
    }

    fn axes(&self, s: &mut String, y_label: &str) {
        let d = decimals(self.step);
        let n = ((self.y1 - self.y0) / self.step).round() as i64;
        for k in 0..=n {
            let v = self.y0 + k as f64 * self.step;
            let y = self.y(v);
            let stroke = if v.abs() < self.step * 1e-6 {
                "#888888"
            } else {
                "#e4e4e4"
            };
            let _ = writeln!(
                s,
                "<line x1=\"{:.1}\" y1=\"{y:.2}\" x2=\"{:.1}\" y2=\"{y:.2}\" stroke=\"{stroke}\" stroke-width=\"0.8\"/>",
                self.left,
                self.left + self.width
            );
            text(s, self.left - 6.0, y + 4.0, 11.0, "end", &fmt_num(v, d));
        }
        for k in 0..=8 {
            let deg = 45.0 * k as f64;
            let x = self.x(deg);
            let _ = writeln!(
                s,
                "<line x1=\"{x:.1}\" y1=\"{:.1}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#e4e4e4\" stroke-width=\"0.8\"/>",
                self.top,
                self.top + self.height
            );
            text(
                s,
                x,
                self.top + self.height + 16.0,
                11.0,
                "middle",
                &format!("{deg}"),
            );
        }
        let _ = writeln!(
            s,
            "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#444444\" stroke-width=\"1\"/>",
            self.left, self.top, self.width, self.height
        );
        text(
            s,
            self.left + self.width / 2.0,
            self.top + self.height + 36.0,
            12.0,
            "middle",
            "phase angle [°]",
        );
        let (x, y) = (self.left - 56.0, self.top + self.height / 2.0);
        let _ = writeln!(
            s,
            "<text x=\"{x:.1}\" y=\"{y:.1}\" font-size=\"12\" text-anchor=\"middle\" transform=\"rotate(-90 {x:.1} {y:.1})\" {FONT}>{}</text>",
            escape(y_label)
        );
    }

    /// Samples as polylines, broken where the angle wraps around.
    fn samples(&self, s: &mut String, pts: impl Iterator<Item = (f64, f64)>, stroke: &str) {
        let mut run: Vec<(f64, f64)> = Vec::new();
        let mut last: Option<f64> = None;
        for (deg, v) in pts {
            if let Some(l) = last {
                if (deg - l).abs() > 180.0 {
                    polyline(s, &run, stroke, 0.6, "stroke-opacity=\"0.45\"");
                    run.clear();
                }
            }
            last = Some(deg);
            run.push((self.x(deg), self.y(v)));
        }
        polyline(s, &run, stroke, 0.6, "stroke-opacity=\"0.45\"");
    }

    fn curve(&self, s: &mut String, series: &Series, factor: f64, stroke: &str) {
        let pts: Vec<_> = (0..=CURVE_POINTS)
            .map(|i| {
                let deg = 360.0 * i as f64 / CURVE_POINTS as f64;
                (self.x(deg), self.y(factor * series.eval(deg.to_radians())))
            })
            .collect();
        polyline(s, &pts, stroke, 2.0, "");
    }
}

fn fmt_num(v: f64, d: usize) -> String {
    let t = format!("{v:.d$}");
    if t.starts_with('-') && t[1..].chars().all(|c| c == '0' || c == '.') {
        t[1..].to_string()
    } else {
        t
    }
}

/// Radial deviation from the least-squares circle (µm) against the phase
/// angle: samples, filtered profile, and its extremes (whose difference is
/// the filtered `F`).
pub fn radial_svg(test: &CircleTest, title: &str) -> String {
    let (w, h) = (860.0, 420.0);
    let series = test.radial_series();
    let (lo, hi) = (test.radial_mm.min * 1e3, test.radial_mm.max * 1e3);
    let chart = Chart::new(lo, hi, w - 110.0, h - 130.0);
    let mut s = String::new();
    open(&mut s, w, h);
    text(&mut s, w / 2.0, 28.0, 17.0, "middle", title);
    let filtered = test
        .g_filtered_um
        .map(|g| format!(" · filtered ({} UPR) G = {g:.2} µm", test.harmonics_upr))
        .unwrap_or_default();
    text(
        &mut s,
        w / 2.0,
        50.0,
        13.0,
        "middle",
        &format!(
            "circular deviation G = {:.2} µm{filtered}{}",
            test.g_um,
            f_text(test)
        ),
    );
    chart.axes(&mut s, "radial deviation [µm]");
    chart.samples(
        &mut s,
        test.samples
            .iter()
            .map(|p| (p.phase_deg, p.radial_mm * 1e3)),
        "#808080",
    );
    if let Some(series) = &series {
        let (a, b) = series.extremes();
        for v in [a, b] {
            let y = chart.y(v * 1e3);
            let _ = writeln!(
                s,
                "<line x1=\"{:.1}\" y1=\"{y:.2}\" x2=\"{:.1}\" y2=\"{y:.2}\" stroke=\"{}\" stroke-width=\"1\" stroke-dasharray=\"5 4\"/>",
                chart.left,
                chart.left + chart.width,
                COLORS[2]
            );
        }
        chart.curve(&mut s, series, 1e3, COLORS[2]);
    }
    s.push_str("</svg>\n");
    s
}

/// Several circular tests of the same circle overlaid (e.g. measure-only
/// and corrected): the radial deviation of each from its least-squares
/// circle (µm) against the phase angle, in its own colour, with a legend
/// giving each one's `G` and `F`.
pub fn radial_overlay_svg(tests: &[(&CircleTest, &str)], title: &str) -> String {
    let (w, h) = (860.0, 440.0);
    let deviation = |_: &CircleTest, p: &crate::SampleDeviation| p.radial_mm;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (t, _) in tests {
        for p in &t.samples {
            let v = deviation(t, p) * 1e3;
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        (lo, hi) = (-1.0, 1.0);
    }
    let chart = Chart::new(lo, hi, w - 110.0, h - 150.0);
    let mut s = String::new();
    open(&mut s, w, h);
    text(&mut s, w / 2.0, 28.0, 17.0, "middle", title);
    for (k, (t, name)) in tests.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        text(
            &mut s,
            w / 2.0,
            46.0 + 13.0 * k as f64,
            12.0,
            "middle",
            &format!("{name} ({color}): G = {:.2} µm{}", t.g_um, f_text(t)),
        );
    }
    chart.axes(&mut s, "radial deviation [µm]");
    for (k, (t, _)) in tests.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        chart.samples(
            &mut s,
            t.samples
                .iter()
                .map(|p| (p.phase_deg, deviation(t, p) * 1e3)),
            color,
        );
    }
    s.push_str("</svg>\n");
    s
}

/// Orientation deviations from the mean orientation (small rotations about
/// the field's `X`, `Y`, `Z` axes, degrees) against the phase angle.
pub fn angular_svg(test: &CircleTest, title: &str) -> String {
    let (w, h) = (860.0, 420.0);
    let profiles = [
        &test.rotation_x_deg,
        &test.rotation_y_deg,
        &test.rotation_z_deg,
    ];
    let lo = profiles.iter().map(|p| p.min).fold(f64::INFINITY, f64::min);
    let hi = profiles
        .iter()
        .map(|p| p.max)
        .fold(f64::NEG_INFINITY, f64::max);
    let chart = Chart::new(lo, hi, w - 110.0, h - 130.0);
    let mut s = String::new();
    open(&mut s, w, h);
    text(&mut s, w / 2.0, 28.0, 17.0, "middle", title);
    let spans: Vec<String> = ["X", "Y", "Z"]
        .iter()
        .zip(profiles)
        .map(|(a, p)| {
            let f = p
                .filtered
                .as_ref()
                .map(|f| format!(" ({:.4}° filtered)", f.span))
                .unwrap_or_default();
            format!("{a}: {:.4}°{f}", p.span)
        })
        .collect();
    text(
        &mut s,
        w / 2.0,
        50.0,
        13.0,
        "middle",
        &format!("orientation deviation spans  {}", spans.join("  ")),
    );
    chart.axes(&mut s, "rotation from the mean orientation [°]");
    for (k, color) in COLORS.iter().enumerate() {
        chart.samples(
            &mut s,
            test.samples
                .iter()
                .map(|p| (p.phase_deg, p.rotation_deg[k])),
            color,
        );
    }
    for (k, color) in COLORS.iter().enumerate() {
        if let Some(series) = test.rotation_series(k) {
            chart.curve(&mut s, &series, 1.0, color);
        }
    }
    let _ = writeln!(
        s,
        "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"272\" height=\"22\" fill=\"white\" fill-opacity=\"0.85\" stroke=\"#cccccc\"/>",
        chart.left + 4.0,
        chart.top + 3.0
    );
    for (k, name) in ["about X", "about Y", "about Z"].iter().enumerate() {
        let x = chart.left + 10.0 + 90.0 * k as f64;
        let y = chart.top + 14.0;
        let _ = writeln!(
            s,
            "<line x1=\"{x:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"{}\" stroke-width=\"3\"/>",
            x + 18.0,
            COLORS[k]
        );
        text(&mut s, x + 22.0, y + 4.0, 11.0, "start", name);
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_steps() {
        assert_eq!(nice_step(0.0031), 0.005);
        assert_eq!(nice_step(7.0), 10.0);
        assert_eq!(nice_step(1.5), 2.0);
        assert_eq!(decimals(0.005), 3);
        assert_eq!(fmt_num(-0.0, 2), "0.00");
    }
}
