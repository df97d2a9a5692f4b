//! Property tests of the hand-eye calibration on simulated stations with
//! seeded noise: a camera on a robot flange looks at the default plate from
//! about 600 mm with tilts up to 25° and rolls up to ±90°; the robot's
//! poses get its repeatability (0.02 mm, 0.005°), the camera poses the
//! covariance photopose predicts for the default camera and plate at
//! 0.05 px image noise (about 0.03–0.06 mm and 0.003–0.006°, correlated).
//! The transforms must come out within their reported 3σ, degenerate
//! motion must be refused, and a station with a gross error named.

use nalgebra::{Cholesky, Isometry3, Matrix6, Vector3, Vector6};
use photopose_field::Field;
use photopose_geometry::pose::{
    camera_pose, camera_pose_covariance, isometry_from_xyzabc, perturbed,
};
use photopose_geometry::precision::{predict, visible_points};
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Exterior};
use photopose_handeye::{solve, CameraPose, HandEye, HandEyeError, HandEyeOptions, Station};

const PLATE: &str = include_str!("../../../config/plate.csv");

/// The true transforms: camera on the flange, looking along the tool's z.
fn truth() -> (Isometry3<f64>, Isometry3<f64>) {
    (
        isometry_from_xyzabc([35.0, -80.0, 160.0, 91.0, 2.5, 178.5]),
        isometry_from_xyzabc([1100.0, 200.0, 15.0, 25.0, 0.8, -0.6]),
    )
}

struct Sim {
    camera: Camera,
    points: Vec<Vector3<f64>>,
    sigma_px: f64,
}

impl Sim {
    fn new() -> Self {
        let field = Field::parse_csv(PLATE, "plate.csv").unwrap();
        Sim {
            camera: photopose_formats::default_camera(),
            points: field.targets().iter().map(|t| t.position).collect(),
            sigma_px: 0.05,
        }
    }

    /// A camera pose looking at the plate: tilt up to `tilt_deg` from the
    /// plate normal, roll about the optical axis up to `roll_deg`.
    fn view(&self, rng: &mut SplitMix64, tilt_deg: f64, roll_deg: f64) -> Exterior {
        let target = Vector3::new((rng.unit() - 0.5) * 100.0, (rng.unit() - 0.5) * 80.0, 0.0);
        let tilt = (rng.unit() * tilt_deg).to_radians();
        let azimuth = rng.unit() * std::f64::consts::TAU;
        let dist = 560.0 + rng.unit() * 80.0;
        let dir = Vector3::new(
            tilt.sin() * azimuth.cos(),
            tilt.sin() * azimuth.sin(),
            tilt.cos(),
        );
        let roll = ((rng.unit() * 2.0 - 1.0) * roll_deg).to_radians();
        let up = Vector3::new(roll.sin(), roll.cos(), 0.0);
        Exterior::look_at(target + dir * dist, target, up).unwrap()
    }

    /// The covariance photopose reports for a camera at `e` (centre,
    /// rotations about the plate's axes), scaled by `factor`.
    fn covariance(&self, e: &Exterior) -> Matrix6<f64> {
        let mut visible = Vec::new();
        visible_points(
            &self.camera,
            e,
            self.points.iter().copied(),
            5.0,
            &mut visible,
        );
        predict(&self.camera, e, &visible, self.sigma_px)
            .unwrap()
            .covariance
    }
}

fn normal6(rng: &mut SplitMix64) -> Vector6<f64> {
    Vector6::from_fn(|_, _| rng.normal())
}

/// Stations seen from `views`; `noise_factor` scales the robot and camera
/// noise actually added (the reported covariance and the options' robot
/// repeatability stay as they are).
fn stations(
    sim: &Sim,
    views: &[Exterior],
    rng: &mut SplitMix64,
    noise_factor: f64,
) -> Vec<Station> {
    let (x, z) = truth();
    let robot_mm = 0.02;
    let robot_rad = 0.005f64.to_radians();
    views
        .iter()
        .enumerate()
        .map(|(k, e)| {
            let b = camera_pose(e);
            let a = z * b * x.inverse();
            let cov = camera_pose_covariance(&sim.covariance(e));
            let l = Cholesky::new(cov).unwrap().l();
            let d = l * normal6(rng) * noise_factor;
            let b_meas = perturbed(
                &b,
                &Vector3::new(d[0], d[1], d[2]),
                &Vector3::new(d[3], d[4], d[5]),
            );
            let r = normal6(rng);
            let a_meas = perturbed(
                &a,
                &(Vector3::new(r[0], r[1], r[2]) * robot_mm * noise_factor),
                &(Vector3::new(r[3], r[4], r[5]) * robot_rad * noise_factor),
            );
            Station {
                name: format!("s{:02}", k + 1),
                robot: a_meas,
                camera: CameraPose {
                    pose: b_meas,
                    covariance: cov,
                },
            }
        })
        .collect()
}

/// Errors of the 12 unknowns in the covariance's parametrisation, divided
/// by their reported standard deviations.
fn normalised_errors(he: &HandEye) -> [f64; 12] {
    let (x, z) = truth();
    let mut e = [0.0; 12];
    let tx = he.camera_in_tcp.translation.vector - x.translation.vector;
    let wx = (he.camera_in_tcp.rotation * x.rotation.inverse()).scaled_axis();
    let tz = he.plate_in_base.translation.vector - z.translation.vector;
    let wz = (he.plate_in_base.rotation * z.rotation.inverse()).scaled_axis();
    for k in 0..3 {
        e[k] = tx[k];
        e[3 + k] = wx[k];
        e[6 + k] = tz[k];
        e[9 + k] = wz[k];
    }
    std::array::from_fn(|k| e[k] / he.covariance[(k, k)].sqrt())
}

struct Figures {
    n: usize,
    within_3: usize,
    max_abs: f64,
    rms: f64,
    mean_sigma0: f64,
    rejected: usize,
    seeds: usize,
}

fn recovery(seeds: std::ops::Range<u64>, n_stations: usize, noise_factor: f64) -> Figures {
    let sim = Sim::new();
    let mut all = Vec::new();
    let mut sigma0 = 0.0;
    let mut rejected = 0;
    let n_seeds = seeds.end - seeds.start;
    for seed in seeds {
        let mut rng = SplitMix64::new(0xC0FFEE ^ seed.wrapping_mul(0x9E37_79B9));
        let views: Vec<_> = (0..n_stations)
            .map(|_| sim.view(&mut rng, 25.0, 90.0))
            .collect();
        let st = stations(&sim, &views, &mut rng, noise_factor);
        let he = solve(&st, &HandEyeOptions::default()).unwrap();
        sigma0 += he.sigma0;
        rejected += he.rejected.len();
        all.extend(normalised_errors(&he));
    }
    let n = all.len();
    Figures {
        n,
        within_3: all.iter().filter(|z| z.abs() <= 3.0).count(),
        max_abs: all.iter().fold(0.0f64, |m, z| m.max(z.abs())),
        rms: (all.iter().map(|z| z * z).sum::<f64>() / n as f64).sqrt(),
        mean_sigma0: sigma0 / n_seeds as f64,
        rejected,
        seeds: n_seeds as usize,
    }
}

fn print(label: &str, f: &Figures) {
    println!(
        "{label}: {} seeds, {} errors/σ: within 3σ {:.2} %, max |e/σ| {:.2}, rms e/σ {:.3}, \
         mean σ0 {:.3}, stations rejected {}",
        f.seeds,
        f.n,
        100.0 * f.within_3 as f64 / f.n as f64,
        f.max_abs,
        f.rms,
        f.mean_sigma0,
        f.rejected
    );
}

#[test]
fn twelve_stations_are_recovered_within_the_reported_3_sigma() {
    let f = recovery(0..40, 12, 1.0);
    print("12 stations, nominal noise", &f);
    assert!(f.within_3 as f64 >= 0.98 * f.n as f64);
    assert!(f.max_abs < 4.5, "max |e/σ| {}", f.max_abs);
    assert!((0.8..1.25).contains(&f.rms), "rms e/σ {}", f.rms);
    assert!((0.9..1.1).contains(&f.mean_sigma0), "σ0 {}", f.mean_sigma0);
    assert!(
        f.rejected <= 2,
        "{} stations rejected without gross errors",
        f.rejected
    );
}

#[test]
fn ten_stations_with_underrated_noise_are_covered_by_sigma0() {
    // Robot and camera are three times noisier than their a-priori
    // standard deviations: σ0 shows it and the scaled covariance still
    // covers the errors.
    let f = recovery(100..130, 10, 3.0);
    print("10 stations, noise 3× the a-priori", &f);
    assert!((2.6..3.4).contains(&f.mean_sigma0), "σ0 {}", f.mean_sigma0);
    assert!(f.within_3 as f64 >= 0.97 * f.n as f64);
    assert!((0.75..1.3).contains(&f.rms), "rms e/σ {}", f.rms);
}

/// Many seeds, run by hand: `cargo test --release -p photopose-handeye
/// --test recovery -- --ignored --nocapture`.
#[test]
#[ignore]
fn recovery_figures_over_many_seeds() {
    for (n, label) in [
        (10, "10 stations"),
        (12, "12 stations"),
        (20, "20 stations"),
    ] {
        let f = recovery(1000..2000, n, 1.0);
        print(label, &f);
        assert!(f.within_3 as f64 >= 0.99 * f.n as f64);
    }
}

#[test]
fn a_station_with_a_gross_error_is_named_and_the_rest_still_fit() {
    let sim = Sim::new();
    for (seed, bad, shift_mm, turn_deg) in [
        (1u64, 4usize, 1.0, 0.0f64),
        (2, 9, 0.0, 0.05),
        (3, 0, 0.5, 0.0),
        // A station far off (a wrong frame or a robot pose typed wrongly):
        // the closed form is pulled away, the refinement and test recover.
        (4, 7, 25.0, 5.0),
    ] {
        let mut rng = SplitMix64::new(seed);
        let views: Vec<_> = (0..12).map(|_| sim.view(&mut rng, 25.0, 90.0)).collect();
        let mut st = stations(&sim, &views, &mut rng, 1.0);
        // The robot reported a wrong pose at one station.
        st[bad].robot = perturbed(
            &st[bad].robot,
            &Vector3::new(shift_mm * 0.6, -shift_mm * 0.8, 0.0),
            &Vector3::new(0.0, turn_deg.to_radians(), 0.0),
        );
        let he = solve(&st, &HandEyeOptions::default()).unwrap();
        assert_eq!(he.rejected, vec![st[bad].name.clone()], "seed {seed}");
        assert!(!he.residuals[bad].used);
        let crit = he.critical.unwrap();
        assert!(he.residuals[bad].test.unwrap() > crit);
        assert!(he
            .residuals
            .iter()
            .filter(|r| r.used)
            .all(|r| r.test.unwrap() <= crit));
        let e = normalised_errors(&he);
        assert!(e.iter().all(|z| z.abs() < 4.0), "seed {seed}: {e:?}");
        assert!(he.sigma0 < 1.5, "σ0 {}", he.sigma0);
    }
}

#[test]
fn two_stations_with_gross_errors_are_both_rejected() {
    let sim = Sim::new();
    let mut rng = SplitMix64::new(21);
    let views: Vec<_> = (0..14).map(|_| sim.view(&mut rng, 25.0, 90.0)).collect();
    let mut st = stations(&sim, &views, &mut rng, 1.0);
    st[2].robot = perturbed(
        &st[2].robot,
        &Vector3::new(0.0, 0.0, 2.0),
        &Vector3::zeros(),
    );
    st[11].camera.pose = perturbed(
        &st[11].camera.pose,
        &Vector3::zeros(),
        &Vector3::new(0.2f64.to_radians(), 0.0, 0.0),
    );
    let he = solve(&st, &HandEyeOptions::default()).unwrap();
    let mut rejected = he.rejected.clone();
    rejected.sort();
    assert_eq!(rejected, vec!["s03".to_string(), "s12".to_string()]);
    assert!(normalised_errors(&he).iter().all(|z| z.abs() < 4.0));
    // With rejection switched off the errors stay in and σ0 shows them.
    let keep = HandEyeOptions {
        max_rejected_share: 0.0,
        ..HandEyeOptions::default()
    };
    let he = solve(&st, &keep).unwrap();
    assert!(
        he.rejected.is_empty() && he.sigma0 > 3.0,
        "σ0 {}",
        he.sigma0
    );
}

#[test]
fn rotations_about_parallel_axes_only_are_refused() {
    let sim = Sim::new();
    let mut rng = SplitMix64::new(5);
    // The camera looks straight down and only turns about its optical axis:
    // every relative rotation of the flange is about the same axis.
    let views: Vec<_> = (0..12)
        .map(|_| {
            let roll = (rng.unit() * 160.0 - 80.0).to_radians();
            let eye = Vector3::new(
                (rng.unit() - 0.5) * 150.0,
                (rng.unit() - 0.5) * 100.0,
                600.0,
            );
            Exterior::look_at(
                eye,
                eye - Vector3::z() * 600.0,
                Vector3::new(roll.sin(), roll.cos(), 0.0),
            )
            .unwrap()
        })
        .collect();
    let st = stations(&sim, &views, &mut rng, 1.0);
    match solve(&st, &HandEyeOptions::default()) {
        Err(HandEyeError::DegenerateMotion { what }) => {
            assert!(what.contains("parallel axes"), "{what}")
        }
        other => panic!("not refused: {other:?}"),
    }
    // Translations only.
    let e = sim.view(&mut rng, 10.0, 10.0);
    let views: Vec<_> = (0..10)
        .map(|k| {
            Exterior::new(
                e.rotation,
                e.center + Vector3::new(k as f64 * 10.0, 0.0, 0.0),
            )
        })
        .collect();
    let st = stations(&sim, &views, &mut rng, 1.0);
    let err = solve(&st, &HandEyeOptions::default()).unwrap_err();
    assert!(
        matches!(err, HandEyeError::DegenerateMotion { .. }),
        "{err}"
    );
    assert!(err.to_string().contains("not determinable"), "{err}");
}

#[test]
fn too_few_stations_and_bad_options_are_errors() {
    let sim = Sim::new();
    let mut rng = SplitMix64::new(9);
    let views: Vec<_> = (0..2).map(|_| sim.view(&mut rng, 25.0, 90.0)).collect();
    let st = stations(&sim, &views, &mut rng, 1.0);
    assert_eq!(
        solve(&st, &HandEyeOptions::default()).unwrap_err(),
        HandEyeError::TooFewStations { got: 2, need: 3 }
    );
    let options = HandEyeOptions {
        robot_std_mm: 0.0,
        ..HandEyeOptions::default()
    };
    assert!(solve(&st, &options)
        .unwrap_err()
        .to_string()
        .contains("robot_std_mm"));
}
