//! Rendered frames of the default plate over the real GigE Vision stream:
//! the in-process fake camera of `photopose-acquire` (aravis' GvFakeCamera
//! on 127.0.0.1) serves frames rendered by `photopose-render`; the daemon's
//! pipeline acquires them through the `gige` source and its poses agree with
//! the render truth. Only one GigE Vision peer can answer on 127.0.0.1:
//! this file holds one test.

use photopose_acquire::fake::FakeGigeCamera;
use photopose_acquire::GigeSource;
use photopose_field::design::default_plate;
use photopose_geometry::Exterior;
use photopose_pipeline::config::Source;
use photopose_pipeline::{Config, Pipeline};
use photopose_render::{RenderOptions, Renderer};
use std::net::UdpSocket;
use std::time::{Duration, Instant};

#[test]
fn poses_from_rendered_frames_over_gige_agree_with_the_truth() {
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let mut renderer = Renderer::new(
        camera,
        &field,
        RenderOptions {
            noise_dn: 2.0,
            blur_px: 0.6,
            seed: 7,
            ..RenderOptions::default()
        },
    )
    .unwrap();
    let poses = [
        [10.0, -20.0, 1000.0, 0.0, 0.0, 0.0],
        [-60.0, 40.0, 900.0, 15.0, 5.0, -4.0],
        [80.0, 10.0, 1100.0, -30.0, -6.0, 3.0],
    ];
    let frames: Vec<_> = poses
        .iter()
        .map(|p| {
            let mut image = renderer.new_image();
            renderer
                .render(&Exterior::from_kuka_pose(*p), &mut image)
                .unwrap();
            image
        })
        .collect();
    let fake = FakeGigeCamera::start("PPRENDER", &frames[0]).unwrap();
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    let config = Config::parse(
        &format!(
            "[source]\nkind = \"gige\"\n[source.gige]\ncamera = \"PPRENDER\"\nframe_rate = 20.0\n\
             [pipeline]\nworkers = 2\nslots = 6\n[output]\nudp = [\"{}\"]\n",
            rx.local_addr().unwrap()
        ),
        "test",
    )
    .unwrap();
    let Source::Gige(gige) = &config.source else {
        panic!("gige source expected")
    };
    let source = GigeSource::new("gige", gige.clone()).unwrap();
    let pipeline = Pipeline::start(&config, camera, field, Box::new(source)).unwrap();
    let mut buf = [0u8; 4096];
    let mut last_seq = None;
    for (k, pose) in poses.iter().enumerate() {
        fake.set_image(&frames[k]).unwrap();
        let truth = Exterior::from_kuka_pose(*pose);
        // Frames of the previous image may still be in flight: wait until
        // the stream shows this pose, then check several frames.
        let (mut agreeing, t0) = (0, Instant::now());
        while agreeing < 5 {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "pose {k}: no agreeing frames within 20 s"
            );
            let Ok(n) = rx.recv(&mut buf) else { continue };
            let v: serde_json::Value = serde_json::from_slice(&buf[..n]).unwrap();
            if v["status"] != "ok" {
                continue;
            }
            let seq = v["seq"].as_u64().unwrap();
            assert!(last_seq.is_none_or(|l| seq > l), "frames in order");
            last_seq = Some(seq);
            assert!(
                v["time"]["camera_clock_ns"].as_u64().unwrap() > 0,
                "camera timestamp kept"
            );
            let c: Vec<f64> = v["pose"]["position_mm"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let err = (0..3)
                .map(|i| (c[i] - truth.center[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            if err < 0.1 {
                agreeing += 1;
            } else {
                // Only a frame of an earlier image may disagree.
                assert!(
                    agreeing == 0,
                    "pose {k}: centre {c:?} is {err} mm from the truth {:?}",
                    truth.center
                );
            }
        }
    }
    pipeline.stop();
    let counters = pipeline.join();
    assert!(counters.poses_ok.get() >= 15);
    drop(fake);
}
