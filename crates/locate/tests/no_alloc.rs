//! Once warm, locating a frame — detection, identification, both
//! resections — allocates nothing, nor does tracking a frame from a pose,
//! nor a lost track and its whole-frame fallback: a counting global
//! allocator watches.

use photopose_field::design::default_plate;
use photopose_geometry::Exterior;
use photopose_locate::track::{Prior, TrackOptions};
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_render::{RenderOptions, Renderer};
use photopose_testkit::{allocations, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn locating_allocates_nothing_once_warm() {
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let mut renderer = Renderer::new(camera, &field, RenderOptions::default()).unwrap();
    let poses = [
        Exterior::from_kuka_pose([0.0, 0.0, 1000.0, 0.0, 0.0, 0.0]),
        Exterior::from_kuka_pose([40.0, -30.0, 900.0, 30.0, 10.0, -5.0]),
        Exterior::from_kuka_pose([-60.0, 50.0, 1100.0, -120.0, -12.0, 8.0]),
    ];
    let frames: Vec<_> = poses
        .iter()
        .map(|e| {
            let mut img = renderer.new_image();
            renderer.render(e, &mut img).unwrap();
            img
        })
        .collect();
    let mut locator = Locator::new(camera, field, LocateOptions::default()).unwrap();
    for img in &frames {
        assert_eq!(*locator.locate(img.view()).unwrap().status, PoseStatus::Ok);
    }
    let before = allocations();
    for _ in 0..3 {
        for img in &frames {
            let loc = locator.locate(img.view()).unwrap();
            assert_eq!(*loc.status, PoseStatus::Ok);
        }
    }
    assert_eq!(allocations() - before, 0, "allocations per frame once warm");
    // Tracking mode from each frame's own pose.
    let priors: Vec<Prior> = frames
        .iter()
        .map(|img| {
            let loc = locator.locate(img.view()).unwrap();
            let pose = loc.pose.unwrap();
            Prior {
                exterior: pose.exterior,
                covariance: pose.covariance,
                motion_px: 1.0,
                threshold: loc.detections.threshold,
            }
        })
        .collect();
    let options = TrackOptions::default();
    for (img, prior) in frames.iter().zip(&priors) {
        locator.track(img.view(), prior, &options).unwrap();
    }
    let before = allocations();
    for _ in 0..3 {
        for (img, prior) in frames.iter().zip(&priors) {
            locator.track(img.view(), prior, &options).unwrap();
        }
    }
    assert_eq!(allocations() - before, 0, "allocations per tracked frame");
    // A track lost (a prediction a grid step off: too few targets, a code
    // mismatch or a jump) and the frame then located whole, as the pipeline
    // falls back.
    let lost: Vec<Prior> = priors
        .iter()
        .map(|p| Prior {
            exterior: Exterior::new(
                p.exterior.rotation,
                p.exterior.center + photopose_geometry::Vector3::new(20.0, 0.0, 0.0),
            ),
            motion_px: 0.0,
            ..*p
        })
        .collect();
    for (img, prior) in frames.iter().zip(&lost) {
        assert!(locator.track(img.view(), prior, &options).is_err());
        assert_eq!(*locator.locate(img.view()).unwrap().status, PoseStatus::Ok);
    }
    let before = allocations();
    for _ in 0..2 {
        for (img, prior) in frames.iter().zip(&lost) {
            assert!(locator.track(img.view(), prior, &options).is_err());
            assert_eq!(*locator.locate(img.view()).unwrap().status, PoseStatus::Ok);
        }
    }
    assert_eq!(
        allocations() - before,
        0,
        "allocations per lost track and whole-frame fallback"
    );
}
