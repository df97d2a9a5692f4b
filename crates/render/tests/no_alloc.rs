//! Rendering allocates nothing once the renderer has rendered a frame.
#![allow(unsafe_code)] // a counting global allocator is the one way to observe allocations

use photopose_field::design::default_plate;
use photopose_geometry::{Camera, Distortion, Exterior, Interior, Sensor};
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
fn rendering_allocates_nothing_once_warm() {
    let cam = Camera::new(
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
        Distortion {
            k1: -1e-4,
            ..Distortion::default()
        },
    )
    .unwrap();
    let mut r = Renderer::new(cam, &default_plate(), RenderOptions::default()).unwrap();
    let mut img = r.new_image();
    let poses = [
        Exterior::from_kuka_pose([0.0, 0.0, 1000.0, 0.0, 0.0, 0.0]),
        Exterior::from_kuka_pose([40.0, -30.0, 800.0, 30.0, 10.0, -5.0]),
    ];
    r.render(&poses[0], &mut img).unwrap();
    let before = ALLOCS.load(Ordering::Relaxed);
    for e in &poses {
        r.render(e, &mut img).unwrap();
    }
    assert_eq!(ALLOCS.load(Ordering::Relaxed) - before, 0);
}
