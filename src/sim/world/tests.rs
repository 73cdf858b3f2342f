//! Tests of [`super`] (world).

use super::*;

fn straight_path() -> Vec<DVec3> {
    (0..=100)
        .map(|i| DVec3::new(i as f64 - 50.0, 0.0, 0.0))
        .collect()
}

#[test]
fn every_scene_builds_and_the_road_stays_clear() {
    for kind in SceneKind::ALL {
        let w = World::build(kind, &straight_path(), 1);
        assert!(
            !w.bvh.triangles.is_empty() || kind == SceneKind::Featureless,
            "{kind:?}"
        );
        // Looking down the road from the driver's seat: the first hit straight ahead is far.
        if let Some(h) = w.trace(Vec3::new(-40.0, 0.0, 1.5), Vec3::X, 200.0) {
            assert!(h.t > 20.0, "{kind:?}: something on the road at {}", h.t);
        }
    }
}

#[test]
fn wide_and_baseline_surfaces_are_bit_identical() {
    // Both copies of the texture code (`sim::wide`), run here without the CPU features,
    // agree bit for bit on rays in every direction from points along the road.
    let w = World::build(SceneKind::Urban, &straight_path(), 2);
    let mut checked = 0;
    for i in 0..4000u32 {
        let h = |k: u32| hash64(i as u64 * 8 + k as u64) as f32 / u64::MAX as f32;
        let o = Vec3::new(-40.0 + 80.0 * h(0), 10.0 * h(1) - 5.0, 0.5 + 3.0 * h(2));
        let d = Vec3::new(h(3) - 0.5, h(4) - 0.5, h(5) - 0.7).normalize_or_zero();
        let Some(hit) = w.trace(o, d, 300.0) else {
            continue;
        };
        let footprint = hit.t * 0.0006 * (0.5 + h(6));
        let (a, b) = (
            w.surface_in::<true>(&hit, footprint),
            w.surface_in::<false>(&hit, footprint),
        );
        assert_eq!(
            a.albedo.to_array().map(f32::to_bits),
            b.albedo.to_array().map(f32::to_bits)
        );
        assert_eq!(a.reflectivity.to_bits(), b.reflectivity.to_bits());
        assert_eq!(w.surface(&hit, footprint).albedo, a.albedo);
        checked += 1;
    }
    assert!(checked > 2000, "{checked}");
}

#[test]
fn urban_has_buildings_beside_the_road() {
    let w = World::build(SceneKind::Urban, &straight_path(), 2);
    let hits = (0..20)
        .filter(|i| {
            let o = Vec3::new(-30.0 + *i as f32 * 3.0, 0.0, 2.0);
            w.trace(o, Vec3::Y, 60.0)
                .is_some_and(|h| h.t > SIDEWALK_OUTER_M && h.t < 30.0)
        })
        .count();
    assert!(hits >= 10, "{hits}");
    assert_eq!(w.ground.abs_distance(0.0, 3.0).round(), 3.0);
}

#[test]
fn a_tall_rig_gets_a_raised_ring_of_boards_and_a_car_does_not() {
    let car = World::build_for_rig(SceneKind::Checkerboard, &straight_path(), 3, 0.32);
    let truck = World::build_for_rig(SceneKind::Checkerboard, &straight_path(), 3, 1.45);
    assert_eq!(car.boards.len(), 8);
    assert_eq!(truck.boards.len(), 16);
    let highest = |w: &World| w.boards.iter().map(|b| b.origin.z).fold(0.0f32, f32::max);
    assert!(highest(&truck) > highest(&car) + 1.0);
}

#[test]
fn checkerboard_scene_has_boards_with_corners() {
    let w = World::build(
        SceneKind::Checkerboard,
        &[DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0)],
        3,
    );
    assert!(w.boards.len() >= 6);
    assert_eq!(w.boards[0].inner_corners().len(), 7 * 5);
}

#[test]
fn scene_names_parse() {
    for k in SceneKind::ALL {
        assert_eq!(k.as_str().parse::<SceneKind>().unwrap(), k);
    }
    assert!("moon".parse::<SceneKind>().is_err());
}
