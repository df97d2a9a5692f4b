//! Detector tests on synthetic frames drawn by `testutil`.

use crate::testutil::{Drawn, Rng, Scene, View};
use crate::*;
use photopose_field::codes;

const DEG: f64 = std::f64::consts::PI / 180.0;

fn dot(col: f64, row: f64, radius_px: f64) -> Drawn {
    Drawn {
        col,
        row,
        radius: radius_px,
        view: View::frontal(1.0),
        code: None,
        phase: 0.0,
    }
}

fn coded(col: f64, row: f64, radius_px: f64, view: View, id: u64, phase: f64) -> Drawn {
    Drawn {
        col,
        row,
        radius: radius_px,
        view,
        code: codes::value_of(id),
        phase,
    }
}

fn detect(img: &photopose_frame::Image, codes: CodeSet) -> Detections {
    let mut d = Detector::new(
        img.width(),
        img.height(),
        DetectorOptions {
            codes,
            ..DetectorOptions::default()
        },
    )
    .unwrap();
    d.detect(img.view()).unwrap().clone()
}

/// The detection nearest to `(col, row)` within `tol` px.
fn near(d: &Detections, col: f64, row: f64, tol: f64) -> Option<&Detection> {
    d.targets
        .iter()
        .filter(|t| (t.col - col).hypot(t.row - row) < tol)
        .min_by(|a, b| {
            let da = (a.col - col).hypot(a.row - row);
            let db = (b.col - col).hypot(b.row - row);
            da.total_cmp(&db)
        })
}

#[test]
fn centroids_of_blurred_noisy_dots_are_within_two_hundredths() {
    let mut rng = Rng::new(7);
    let mut sq = 0.0;
    let mut n = 0;
    for frame in 0..4 {
        let mut s = Scene::new(240, 200, 20.0);
        let mut truth = Vec::new();
        for gy in 0..4 {
            for gx in 0..5 {
                let r = 4.0 + 0.5 * ((gx + gy + frame) % 6) as f64; // 8..13 px across
                let c = 30.0 + 45.0 * gx as f64 + rng.range(-0.5, 0.5);
                let rw = 30.0 + 45.0 * gy as f64 + rng.range(-0.5, 0.5);
                s.draw(&dot(c, rw, r), 180.0);
                truth.push((c, rw));
            }
        }
        s.blur(0.6);
        s.noise(2.0, &mut rng);
        let d = detect(&s.to_mono8(), CodeSet::all());
        assert_eq!(d.targets.len(), truth.len(), "{:?}", d.rejected);
        for &(c, r) in &truth {
            let t = near(&d, c, r, 1.0).expect("dot found");
            assert_eq!(t.kind, TargetKind::Uncoded);
            assert_eq!(t.id, None);
            sq += (t.col - c).powi(2) + (t.row - r).powi(2);
            n += 1;
        }
    }
    let rms = (sq / n as f64).sqrt();
    assert!(rms <= 0.02, "centroid RMS {rms:.4} px over {n} dots");
}

#[test]
fn ellipse_axes_and_angle_follow_the_dot() {
    let mut s = Scene::new(80, 80, 10.0);
    let view = View::tilted(1.0, 60.0 * DEG, 30.0 * DEG, 0.0);
    let mut t = dot(40.3, 39.6, 8.0);
    t.view = view;
    s.draw(&t, 200.0);
    let d = detect(&s.to_mono8(), CodeSet::all());
    assert_eq!(d.targets.len(), 1);
    let t = d.targets[0];
    assert!(
        (t.col - 40.3).abs() < 0.01 && (t.row - 39.6).abs() < 0.01,
        "{t:?}"
    );
    assert!((t.semi_major - 8.0).abs() < 0.15, "{t:?}");
    assert!((t.semi_minor - 4.0).abs() < 0.15, "{t:?}");
    // Foreshortened along 30° in the image (y' up) → the major axis is at
    // 120° there, i.e. at −120° ≡ 60° from +col towards +row.
    let ang = t.angle.rem_euclid(std::f64::consts::PI);
    assert!((ang - 60.0 * DEG).abs() < 2.0 * DEG, "angle {}", ang / DEG);
}

fn coded_scene(targets: &[Drawn], seed: u64) -> photopose_frame::Image {
    let mut s = Scene::new(260, 260, 15.0);
    for t in targets {
        s.draw(t, 190.0);
    }
    s.blur(0.6);
    s.noise(2.0, &mut Rng::new(seed));
    s.to_mono8()
}

#[test]
fn coded_targets_read_their_ids_at_any_rotation_and_tilt() {
    let mut rng = Rng::new(11);
    let ids: Vec<u64> = codes::even_ids().step_by(7).collect();
    let mut read = 0;
    let mut total = 0;
    for (f, chunk) in ids.chunks(9).enumerate() {
        let mut targets = Vec::new();
        for (k, &id) in chunk.iter().enumerate() {
            let tilt = [0.0, 30.0, 45.0][k % 3] * DEG;
            let view = View::tilted(
                1.0,
                tilt,
                rng.range(0.0, 360.0) * DEG,
                rng.range(0.0, 360.0) * DEG,
            );
            let c = 45.0 + 85.0 * (k % 3) as f64 + rng.range(-0.5, 0.5);
            let r = 45.0 + 85.0 * (k / 3) as f64 + rng.range(-0.5, 0.5);
            let radius = rng.range(4.0, 6.0);
            targets.push(coded(c, r, radius, view, id, rng.range(0.0, 360.0) * DEG));
        }
        let d = detect(&coded_scene(&targets, f as u64), CodeSet::all());
        for t in &targets {
            if near(&d, t.col, t.row, 1.0).is_none() {
                let r: Vec<_> = d
                    .rejected
                    .iter()
                    .filter(|x| (x.col - t.col).hypot(x.row - t.row) < 3.0)
                    .collect();
                panic!("target {t:?} not found; rejected nearby: {r:?}");
            }
        }
        assert_eq!(
            d.targets.len(),
            targets.len(),
            "ring parts must not become targets: {:?}",
            d.targets,
        );
        for t in &targets {
            let id = codes::id_of(t.code.unwrap()).unwrap();
            let got = near(&d, t.col, t.row, 1.0).expect("coded target found");
            assert_eq!(got.kind, TargetKind::Coded);
            assert!((got.col - t.col).abs() < 0.1 && (got.row - t.row).abs() < 0.1);
            total += 1;
            match got.id {
                Some(g) => {
                    assert_eq!(g, id, "wrong id");
                    read += 1;
                }
                None => eprintln!("id {id} unread: {got:?} drawn {t:?}"),
            }
        }
    }
    assert!(read == total, "read {read} of {total}");
}

#[test]
fn reading_direction_is_counter_clockwise_seen_from_the_front() {
    // Codes whose mirror image is another code.
    let mut checked = 0;
    for id in codes::even_ids() {
        let v = codes::value_of(id).unwrap();
        let reversed = (0..12).fold(0u16, |acc, k| acc | (((v >> k) & 1) << (11 - k)));
        let mirror_id = codes::id_of(reversed).unwrap();
        if mirror_id == id {
            continue;
        }
        let view = View::frontal(1.0);
        let targets = [
            coded(70.0, 70.0, 5.0, view, id, 10.0 * DEG),
            coded(190.0, 70.0, 5.0, view.mirrored(), id, 10.0 * DEG),
        ];
        let d = detect(&coded_scene(&targets, id), CodeSet::all());
        assert_eq!(near(&d, 70.0, 70.0, 1.0).unwrap().id, Some(id));
        assert_eq!(near(&d, 190.0, 70.0, 1.0).unwrap().id, Some(mirror_id));
        // With only the true ids accepted, the mirror image is unidentified.
        let d = detect(&coded_scene(&targets, id), CodeSet::from_ids([id]));
        assert_eq!(near(&d, 70.0, 70.0, 1.0).unwrap().id, Some(id));
        let m = near(&d, 190.0, 70.0, 1.0).unwrap();
        assert_eq!(m.id, None);
        assert_eq!(m.kind, TargetKind::Coded);
        assert!(
            matches!(m.code, CodeStatus::NotInField { .. }),
            "{:?}",
            m.code
        );
        checked += 1;
        if checked == 4 {
            break;
        }
    }
    assert_eq!(checked, 4);
}

#[test]
fn degenerate_frames_give_no_targets() {
    for (value, status) in [
        (0.0, FrameStatus::Empty),
        (255.0, FrameStatus::Saturated),
        (128.0, FrameStatus::Empty),
    ] {
        let s = Scene::new(64, 48, value);
        let d = detect(&s.to_mono8(), CodeSet::all());
        assert!(d.targets.is_empty());
        assert_eq!(d.status, status, "grey {value}");
    }
    // Noise only, at several levels.
    for sigma in [1.0, 3.0, 8.0] {
        let mut s = Scene::new(200, 150, 40.0);
        s.noise(sigma, &mut Rng::new(3));
        let d = detect(&s.to_mono8(), CodeSet::all());
        assert!(d.targets.is_empty(), "σ {sigma}: {:?}", d.targets.first());
    }
    // A frame that is mostly saturated with a dark corner.
    let mut s = Scene::new(64, 48, 255.0);
    s.fill_rect(0, 0, 10, 10, 0.0);
    assert!(detect(&s.to_mono8(), CodeSet::all()).targets.is_empty());
}

#[test]
fn odd_shaped_reflections_are_rejected_with_reasons() {
    let mut s = Scene::new(300, 200, 12.0);
    s.draw(&dot(40.0, 40.0, 5.0), 180.0); // a real target
    s.bar(150.0, 20.0, 0.0, 1.5, 170.0); // a horizontal line across the frame
    s.fill_rect(200, 60, 280, 180, 160.0); // a large bright patch
    s.fill_rect(60, 100, 72, 112, 160.0); // a square
    s.draw(&dot(120.0, 120.0, 5.0), 110.0); // two merged dots
    s.draw(&dot(129.0, 120.0, 5.0), 110.0);
    s.draw(&dot(40.0, 160.0, 5.0), 180.0); // a dot with a tail
    s.fill_rect(44, 159, 64, 161, 170.0);
    s.draw(&dot(160.0, 160.0, 4.0), 300.0); // saturated: measured, flagged
    s.blur(0.6);
    s.noise(2.0, &mut Rng::new(5));
    let d = detect(&s.to_mono8(), CodeSet::all());
    assert_eq!(d.targets.len(), 2, "{:#?}", d.targets);
    assert!(!near(&d, 40.0, 40.0, 0.1).unwrap().saturated);
    assert!(near(&d, 160.0, 160.0, 0.1).unwrap().saturated);
    assert_eq!(d.n_saturated, 1);
    let reason_at = |c: f64, r: f64| {
        d.rejected
            .iter()
            .find(|x| {
                x.bbox[0] as f64 <= c
                    && c <= x.bbox[2] as f64
                    && x.bbox[1] as f64 <= r
                    && r <= x.bbox[3] as f64
            })
            .map(|x| x.reason)
    };
    assert_eq!(reason_at(150.0, 20.0), Some(RejectReason::Border));
    assert_eq!(reason_at(240.0, 120.0), Some(RejectReason::TooLarge));
    assert_eq!(reason_at(66.0, 106.0), Some(RejectReason::Shape));
    assert!(
        matches!(
            reason_at(124.5, 120.0),
            Some(RejectReason::Shape | RejectReason::Elongated)
        ),
        "{:?}",
        d.rejected
    );
    assert!(matches!(
        reason_at(40.0, 160.0),
        Some(RejectReason::Shape | RejectReason::Elongated)
    ));
    // With saturated blobs refused, the same dot is rejected for it.
    let mut old = Detector::new(
        300,
        200,
        DetectorOptions {
            measure_saturated: false,
            ..DetectorOptions::default()
        },
    )
    .unwrap();
    let img = s.to_mono8();
    let d = old.detect(img.view()).unwrap();
    assert_eq!(d.targets.len(), 1, "{:#?}", d.targets);
    assert!(
        d.rejected
            .iter()
            .any(|x| x.reason == RejectReason::Saturated
                && (x.col - 160.0).hypot(x.row - 160.0) < 0.5)
    );
}

/// Over-exposed dots (peak 1×, 1.5×, 2× and 4× the full scale, clipped),
/// 8- and 16-bit: every dot is found and flagged when clipped. The centre
/// of a clipped dot: (a) the intensity-weighted centroid with the clipped
/// plateau weighted uniformly (`saturated_knee` 1, the default), (b) the
/// weights rolled off smoothly from 0.3 of the way to saturation. Neither
/// is biased on these dots (mean error below 0.005 px); (b) halves the
/// phase error of heavily clipped dots here (RMS at 2×: (a) 0.025 px,
/// (b) 0.013 px), but biases the centres on the renderer's frames (see
/// [`DetectorOptions::saturated_knee`]), so (a) is the default.
#[test]
fn over_exposed_dots_are_measured_without_bias() {
    let (bg, full) = (13.0, 255.0);
    let rms_of = |knee: f64, sixteen: bool, factor: f64| -> f64 {
        let mut rng = Rng::new(11);
        let (mut sc, mut sr, mut sq, mut n, mut flagged) = (0.0, 0.0, 0.0, 0usize, 0usize);
        for frame in 0..12 {
            let mut s = Scene::new(240, 200, bg);
            let mut truth = Vec::new();
            for gy in 0..4 {
                for gx in 0..5 {
                    let r = 3.0 + ((gx + 2 * gy + frame) % 6) as f64; // 6..16 px across
                    let c = 30.0 + 45.0 * gx as f64 + rng.range(-0.5, 0.5);
                    let rw = 30.0 + 45.0 * gy as f64 + rng.range(-0.5, 0.5);
                    s.draw(&dot(c, rw, r), factor * (full - bg));
                    truth.push((c, rw));
                }
            }
            s.blur(0.6);
            s.noise(2.0, &mut rng);
            let img = if sixteen {
                s.to_mono16(65535, 257.0)
            } else {
                s.to_mono8()
            };
            let mut det = Detector::new(
                240,
                200,
                DetectorOptions {
                    saturated_knee: knee,
                    ..DetectorOptions::default()
                },
            )
            .unwrap();
            let d = det.detect(img.view()).unwrap();
            assert_eq!(
                d.targets.len(),
                truth.len(),
                "{factor}× full scale, 16-bit {sixteen}: {:?}",
                d.rejected
            );
            for &(c, r) in &truth {
                let t = near(d, c, r, 1.0).expect("dot found");
                sc += t.col - c;
                sr += t.row - r;
                sq += (t.col - c).powi(2) + (t.row - r).powi(2);
                n += 1;
                flagged += t.saturated as usize;
            }
            assert_eq!(
                d.n_saturated,
                d.targets.iter().filter(|t| t.saturated).count()
            );
        }
        let (bc, br) = (sc / n as f64, sr / n as f64);
        let rms = (sq / n as f64).sqrt();
        eprintln!(
            "knee {knee}, {factor}× full scale, {}-bit: {n} dots, {flagged} saturated, bias ({bc:+.4}, {br:+.4}) px, RMS {rms:.4} px",
            if sixteen { 16 } else { 8 }
        );
        if factor >= 1.5 {
            assert_eq!(flagged, n, "every dot at {factor}× is clipped");
        }
        assert!(
            bc.abs() < 0.005 && br.abs() < 0.005,
            "bias ({bc}, {br}) at {factor}×"
        );
        rms
    };
    for sixteen in [false, true] {
        for factor in [1.0, 1.5, 2.0, 4.0] {
            let plateau = rms_of(DetectorOptions::default().saturated_knee, sixteen, factor);
            let knee = rms_of(0.3, sixteen, factor);
            assert!(
                plateau <= 0.03,
                "uniform plateau: RMS {plateau} px at {factor}×"
            );
            assert!(knee <= 0.02, "roll-off: RMS {knee} px at {factor}×");
            if factor >= 2.0 {
                assert!(knee < plateau, "{knee} vs {plateau} at {factor}×");
            }
        }
    }
}

#[test]
fn a_held_threshold_level_is_kept_within_its_band_and_replaced_beyond() {
    let mut s = Scene::new(200, 160, 15.0);
    for (c, r) in [(50.3, 40.7), (120.6, 90.2), (160.1, 50.5)] {
        s.draw(&dot(c, r, 5.0), 190.0);
    }
    s.blur(0.6);
    s.noise(2.0, &mut Rng::new(3));
    let base = s.to_mono8();
    // The same frame brighter by `by` grey values.
    let brighter = |by: u8| {
        let mut img = base.clone();
        if let photopose_frame::Pixels::Mono8(px) = img.pixels_mut() {
            for p in px.iter_mut() {
                *p = p.saturating_add(by);
            }
        }
        img
    };
    let level = |det: &mut Detector, img: &photopose_frame::Image| {
        det.detect(img.view()).unwrap().threshold.threshold.level()
    };
    let mut plain = Detector::new(200, 160, DetectorOptions::default()).unwrap();
    let held_options = DetectorOptions {
        threshold_hold: 1.0,
        ..DetectorOptions::default()
    };
    let mut held = Detector::new(200, 160, held_options).unwrap();
    let first = level(&mut held, &base);
    assert_eq!(first, level(&mut plain, &base));
    // One grey value brighter: Otsu moves, the held level stays.
    let one = brighter(1);
    assert_ne!(level(&mut plain, &one), first);
    assert_eq!(level(&mut held, &one), first);
    // Far brighter: a new level, held from then on.
    let far = brighter(30);
    let new = level(&mut plain, &far);
    assert_eq!(level(&mut held, &far), new);
    assert_ne!(new, first);
}
