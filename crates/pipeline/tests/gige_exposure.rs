//! The exposure control loop through the whole pipeline on a real GigE
//! Vision stream: the in-process fake camera of `photopose-acquire` serves
//! rendered frames of the default plate whose targets peak at a known
//! share of full scale; the detection workers measure each frame's peak
//! and the GigE source writes the camera's exposure feature
//! (`ExposureTimeAbs` on this camera), read back from the camera. The
//! served image does not depend on the exposure, so the loop runs to a
//! limit: up while the targets read dim, down while they read clipped,
//! one step limit at a time and never outside the limits; a frame without
//! targets changes nothing. Only one GigE Vision peer can answer on
//! 127.0.0.1: this file holds one test.

use photopose_acquire::fake::FakeGigeCamera;
use photopose_acquire::GigeSource;
use photopose_field::design::default_plate;
use photopose_geometry::Exterior;
use photopose_pipeline::config::Source;
use photopose_pipeline::{Config, Pipeline};
use photopose_render::{RenderOptions, Renderer};
use std::time::{Duration, Instant};

/// Waits until the camera's exposure is `end` µs; the values it took on
/// the way, each a step of the law (the test's limit: 15 s).
fn exposures_until(fake: &FakeGigeCamera, end: u32) -> Vec<u32> {
    let mut seen = vec![fake.exposure_us().unwrap()];
    let t0 = Instant::now();
    while *seen.last().unwrap() != end {
        assert!(
            t0.elapsed() < Duration::from_secs(15),
            "{seen:?} never reaches {end} µs"
        );
        std::thread::sleep(Duration::from_millis(5));
        let now = fake.exposure_us().unwrap();
        if now != *seen.last().unwrap() {
            seen.push(now);
        }
    }
    seen
}

#[test]
fn the_exposure_follows_the_targets_peak_within_its_limits() {
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let pose = Exterior::from_kuka_pose([10.0, -20.0, 1000.0, 0.0, 0.0, 0.0]);
    // Targets at `share` of full scale (clipped above 1).
    let frame = |share: f64| {
        let mut renderer = Renderer::new(
            camera,
            &field,
            RenderOptions {
                target: share,
                seed: 7,
                ..RenderOptions::default()
            },
        )
        .unwrap();
        let mut image = renderer.new_image();
        renderer.render(&pose, &mut image).unwrap();
        image
    };
    let (dim, clipped) = (frame(0.3), frame(2.5));
    let blank = photopose_frame::Image::new_mono8(camera.sensor.width, camera.sensor.height);
    let fake = FakeGigeCamera::start("PPEXPO02", &dim).unwrap();
    let config = Config::parse(
        "[source]\nkind = \"gige\"\n[source.gige]\ncamera = \"PPEXPO02\"\nframe_rate = 20.0\n\
         exposure_us = 1000.0\n\
         [source.gige.exposure_control]\nenabled = true\ntarget_peak = 0.8\nmin_us = 500.0\n\
         max_us = 8000.0\ngain = 1.0\nmax_step_ratio = 2.0\ndead_band = 0.1\nevery_frames = 1\n\
         [pipeline]\nworkers = 2\nslots = 6\n",
        "test",
    )
    .unwrap();
    let Source::Gige(gige) = &config.source else {
        panic!("gige source expected")
    };
    let source = GigeSource::new("gige", gige.clone()).unwrap();
    let pipeline = Pipeline::start(&config, camera, field, Box::new(source)).unwrap();
    let exposure = pipeline
        .counters()
        .exposure
        .clone()
        .expect("the GigE source reports its exposure");
    assert!(exposure.steering());

    // The opening sets `exposure_us` (the camera started at its own).
    exposures_until(&fake, 1000);
    // Dim targets (30 % of full scale, the target 80 %): doubled per step
    // (the step limit) up to the longest exposure allowed.
    let up = exposures_until(&fake, 8000);
    assert_eq!(up, [1000, 2000, 4000, 8000], "steps up while dim");
    // Clipped targets: halved per step down to the shortest.
    fake.set_image(&clipped).unwrap();
    let down = exposures_until(&fake, 500);
    assert_eq!(
        down,
        [8000, 4000, 2000, 1000, 500],
        "steps down while clipped"
    );
    // Every step counted once the camera took it (the count follows the
    // read-back of the register).
    let t0 = Instant::now();
    while exposure.writes.get() < 7 {
        assert!(t0.elapsed() < Duration::from_secs(2), "writes counted");
        std::thread::sleep(Duration::from_millis(5));
    }
    // No targets: nothing to hold, nothing changes.
    fake.set_image(&blank).unwrap();
    let writes = exposure.writes.get();
    assert_eq!(writes, 7);
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(1) {
        assert_eq!(fake.exposure_us(), Some(500), "no targets, no change");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(exposure.writes.get(), writes);
    assert_eq!(exposure.write_failures.get(), 0);
    assert!((exposure.exposure_s.get() - 500e-6).abs() < 1e-12);
    pipeline.stop();
    let counters = pipeline.join();
    assert!(counters.frames_processed.get() > 20);
    let metrics = photopose_pipeline::metrics::render(counters);
    for line in [
        "photopose_exposure_time_seconds 0.0005",
        "photopose_exposure_control_enabled 1",
        "photopose_exposure_control_writes_total 7",
        "photopose_exposure_control_write_failures_total 0",
    ] {
        assert!(metrics.contains(line), "{line} not in\n{metrics}");
    }
    drop(fake);
}
