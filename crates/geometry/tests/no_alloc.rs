//! A warm `Resection` allocates nothing, also on the first frame whose
//! adjustment rejects an observation (data snooping) after many clean ones:
//! the list of rejected ids has its room from the first solve.

use photopose_field::design::default_plate;
use photopose_geometry::rng::SplitMix64;
use photopose_geometry::{Camera, Exterior, Observation, Resection, ResectionOptions};
use photopose_testkit::{allocations, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_first_rejection_after_clean_frames_does_not_allocate() {
    let cam = Camera::reference();
    let plate = default_plate();
    let truth = Exterior::from_kuka_pose([-40.0, 25.0, 950.0, -30.0, 10.0, 6.0]);
    let mut rng = SplitMix64::new(5);
    let mut obs = Vec::with_capacity(plate.len());
    let observe = |obs: &mut Vec<Observation>, rng: &mut SplitMix64| {
        obs.clear();
        for t in plate.targets() {
            let Some(px) = truth.project_pixel(&cam, &t.position) else {
                continue;
            };
            if cam.contains_pixel(px, 5.0) {
                let (col, row) = (px.x + 0.05 * rng.normal(), px.y + 0.05 * rng.normal());
                obs.push(Observation::from_pixel(&cam, t.id, t.position, col, row));
            }
        }
    };
    let mut rs = Resection::new(&cam, ResectionOptions::default());
    // Warm: clean frames, nothing rejected.
    for _ in 0..3 {
        observe(&mut obs, &mut rng);
        rs.solve(&obs).unwrap();
        assert!(rs.rejected_ids().is_empty());
    }
    observe(&mut obs, &mut rng);
    // One observation 5 px off: a gross error the adjustment rejects.
    let bad = obs.len() / 2;
    let moved = Observation::from_pixel(
        &cam,
        obs[bad].id,
        obs[bad].object,
        truth.project_pixel(&cam, &obs[bad].object).unwrap().x + 5.0,
        truth.project_pixel(&cam, &obs[bad].object).unwrap().y,
    );
    obs[bad] = moved;
    let before = allocations();
    let solved = rs.solve(&obs).map(|r| r.n_points);
    let refined = rs.refine(&obs, truth).map(|r| r.n_points);
    let allocated = allocations() - before;
    assert_eq!(rs.rejected_ids(), &[obs[bad].id], "{solved:?} {refined:?}");
    assert_eq!(allocated, 0, "allocations by a warm resection");
}
