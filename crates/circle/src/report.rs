//! The circular test as text, the way ballbar software summarises a run,
//! in ISO 230-4's words: the fitted circle, the circular deviation `G` raw
//! and filtered, the radial deviation `F` when the nominal circle is given,
//! out-of-plane and orientation deviations, and the largest radial
//! harmonics. (The JSON report is the
//! serde serialisation of [`crate::CircleTest`].)

use crate::analysis::{CircleTest, Profile};
use std::fmt::Write;

/// The text report of `test`, headed by `title` (e.g. what was measured).
pub fn text(title: &str, test: &CircleTest) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{title}");
    let _ = writeln!(s, "{}", "=".repeat(title.chars().count()));
    let c = test.center_mm;
    let n = test.plane.normal;
    let _ = writeln!(
        s,
        "samples              {} ({:.1}° swept, {})",
        test.n_samples,
        test.coverage_deg,
        match test.direction {
            crate::Direction::Ccw => "counter-clockwise",
            crate::Direction::Cw => "clockwise",
        }
    );
    let _ = writeln!(
        s,
        "least-squares circle centre X,Y,Z = {:.4}, {:.4}, {:.4} mm (σ {:.4}, {:.4} mm in the plane)",
        c[0], c[1], c[2], test.std_center_mm[0], test.std_center_mm[1]
    );
    let _ = writeln!(
        s,
        "                     radius {:.4} mm (σ {:.4} mm), plane normal {:.5}, {:.5}, {:.5}",
        test.radius_mm, test.std_radius_mm, n[0], n[1], n[2]
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "circular deviation G {:.1} µm (radial range of the samples about the least-squares centre)",
        test.g_um
    );
    match test.g_filtered_um {
        Some(g) => {
            let _ = writeln!(
                s,
                "G filtered           {:.1} µm (harmonics up to {} per revolution)",
                g, test.harmonics_upr
            );
        }
        None if test.harmonics_upr > 0 => {
            let _ = writeln!(
                s,
                "G filtered           — (the samples do not cover the circle densely enough)"
            );
        }
        None => {}
    }
    match (&test.nominal, &test.f_um) {
        (Some(n), Some(f)) => {
            let c = n.center_mm;
            let _ = writeln!(
                s,
                "radial deviation F   max {:+.1} µm, min {:+.1} µm from the nominal circle \
                 (centre {:.4}, {:.4}, {:.4} mm, radius {:.4} mm)",
                f.max, f.min, c[0], c[1], c[2], n.radius_mm
            );
        }
        _ => {
            let _ = writeln!(
                s,
                "radial deviation F   — (no nominal circle given for this path: --nominal-center, --nominal-radius)"
            );
        }
    }
    let _ = writeln!(
        s,
        "circular hysteresis H — (needs a clockwise and a counter-clockwise run)"
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "{:<22}{:>11}{:>11}{:>11}{:>11}{:>14}",
        "profile", "min", "max", "span", "rms", "span filtered"
    );
    row(&mut s, "radial [mm]", &test.radial_mm, 4);
    row(&mut s, "out of plane [mm]", &test.out_of_plane_mm, 4);
    row(&mut s, "rotation X [°]", &test.rotation_x_deg, 5);
    row(&mut s, "rotation Y [°]", &test.rotation_y_deg, 5);
    row(&mut s, "rotation Z [°]", &test.rotation_z_deg, 5);
    let a = test.mean_orientation_abc_deg;
    let _ = writeln!(
        s,
        "mean orientation A,B,C = {:.4}, {:.4}, {:.4}°; largest rotation from it {:.5}°",
        a[0], a[1], a[2], test.rotation_max_angle_deg
    );
    if let Some(f) = &test.radial_mm.filtered {
        let mut terms = f.harmonics.clone();
        terms.sort_by(|x, y| y.amplitude.total_cmp(&x.amplitude));
        let _ = writeln!(s);
        let _ = writeln!(s, "largest radial harmonics (amplitude · cos(kθ − φ)):");
        for t in terms.iter().take(5) {
            let _ = writeln!(
                s,
                "  k = {:>2}   {:.4} mm   φ = {:7.2}°",
                t.order, t.amplitude, t.phase_deg
            );
        }
    }
    s
}

fn row(s: &mut String, name: &str, p: &Profile, decimals: usize) {
    let filtered = p
        .filtered
        .as_ref()
        .map(|f| format!("{:.decimals$}", f.span))
        .unwrap_or_else(|| "—".into());
    let _ = writeln!(
        s,
        "{name:<22}{:>11.decimals$}{:>11.decimals$}{:>11.decimals$}{:>11.decimals$}{filtered:>14}",
        p.min, p.max, p.span, p.rms
    );
}
