//! Rendering allocates nothing once the renderer has rendered a frame
//! (still or with motion blur).

use photopose_field::design::default_plate;
use photopose_geometry::{Camera, Distortion, Exterior, Interior, Sensor};
use photopose_render::{RenderOptions, Renderer};
use photopose_testkit::{allocations, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

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
    r.render_moving(&poses[0], &poses[1], &mut img).unwrap();
    let before = allocations();
    for e in &poses {
        r.render(e, &mut img).unwrap();
    }
    // Motion blur: many sub-exposures, one box per target.
    r.render_moving(&poses[1], &poses[0], &mut img).unwrap();
    assert_eq!(allocations() - before, 0);
}
