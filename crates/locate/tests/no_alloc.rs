//! Once warm, locating a frame — detection, identification, both
//! resections — allocates nothing: a counting global allocator watches.
#![allow(unsafe_code)] // a counting global allocator is the one way to observe allocations

use photopose_field::design::default_plate;
use photopose_geometry::Exterior;
use photopose_locate::{LocateOptions, Locator, PoseStatus};
use photopose_render::{RenderOptions, Renderer};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn locating_allocates_nothing_once_warm() {
    let camera =
        photopose_formats::parse_camera(include_str!("../../../config/camera.toml"), "camera")
            .unwrap();
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
    let before = ALLOCS.load(Ordering::Relaxed);
    for _ in 0..3 {
        for img in &frames {
            let loc = locator.locate(img.view()).unwrap();
            assert_eq!(*loc.status, PoseStatus::Ok);
        }
    }
    assert_eq!(
        ALLOCS.load(Ordering::Relaxed) - before,
        0,
        "allocations per frame once warm"
    );
}
