//! Residual plots as SVG text (pure: the caller writes the file): the
//! residual vectors of every image, magnified, over the sensor; and the
//! radial residual component against the distance from the principal point.
//! A model that fits leaves no pattern in either.

use crate::calibrate::AdjustedImage;
use photopose_geometry::Camera;
use std::fmt::Write;

/// Residual vectors over the sensor, magnified so that the largest used
/// residual is drawn `1/20` of the sensor width long (the factor is printed).
pub fn vector_plot(camera: &Camera, images: &[AdjustedImage]) -> String {
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
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{:.0}" viewBox="-20 -40 {:.0} {:.0}" font-family="sans-serif" font-size="12">"#,
        pw + 40.0,
        ph + 60.0,
        pw + 40.0,
        ph + 60.0
    );
    let _ = writeln!(
        s,
        r#"<text x="0" y="-20">image residuals × {magnification} (largest {largest:.3} px); red: rejected</text>"#
    );
    let _ = writeln!(
        s,
        r#"<rect x="0" y="0" width="{pw:.1}" height="{ph:.1}" fill="white" stroke="black"/>"#
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
    for im in images {
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
    s.push_str("</svg>\n");
    s
}

/// Radial residual component (pixels, positive outwards) against the
/// radius from the principal point (pixels).
pub fn radial_plot(camera: &Camera, images: &[AdjustedImage]) -> String {
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
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" viewBox="-60 -40 {} {}" font-family="sans-serif" font-size="12">"#,
        pw + 80.0,
        ph + 80.0,
        pw + 80.0,
        ph + 80.0
    );
    let _ = writeln!(
        s,
        r#"<text x="0" y="-20">radial residual (px, ±{vmax:.3}) against radius from the principal point (0 … {rmax:.0} px)</text>"#
    );
    let _ = writeln!(
        s,
        r#"<rect x="0" y="0" width="{pw}" height="{ph}" fill="white" stroke="black"/><line x1="0" y1="{}" x2="{pw}" y2="{}" stroke="gray"/>"#,
        ph / 2.0,
        ph / 2.0
    );
    let _ = writeln!(
        s,
        r#"<text x="-55" y="12">+{vmax:.3}</text><text x="-55" y="{ph}">-{vmax:.3}</text><text x="{}" y="{}">{rmax:.0} px</text>"#,
        pw - 50.0,
        ph + 20.0
    );
    for (rad, v, used) in points {
        let x = rad / rmax * pw;
        let y = ph / 2.0 - (v / vmax).clamp(-1.0, 1.0) * ph / 2.0;
        let colour = if used { "black" } else { "red" };
        let _ = writeln!(
            s,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="1.2" fill="{colour}"/>"#
        );
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::Residual;
    use photopose_geometry::{Distortion, Exterior, Interior, Sensor};

    #[test]
    fn plots_draw_every_residual_and_mark_rejected_ones_red() {
        let camera = Camera::new(
            Sensor {
                width: 1300,
                height: 1030,
                pixel_size: 0.0067,
            },
            Interior {
                c: 12.0,
                x0: 0.0,
                y0: 0.0,
            },
            Distortion::default(),
        )
        .unwrap();
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
        let v = vector_plot(&camera, &images);
        assert!(v.starts_with("<svg") && v.ends_with("</svg>\n"));
        assert_eq!(v.matches("<line").count(), 3);
        assert_eq!(v.matches("stroke=\"red\"").count(), 1);
        // Largest residual 0.0539 px drawn 65 px (1/20 of the width) long.
        assert!(v.contains("× 1207"), "{v}");
        let r = radial_plot(&camera, &images);
        assert_eq!(r.matches("r=\"1.2\"").count(), 3);
        assert_eq!(r.matches("fill=\"red\"").count(), 1);
    }
}
