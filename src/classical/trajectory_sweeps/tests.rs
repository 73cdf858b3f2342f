use super::*;

/// Sweeps every `step_m` along a straight road, one per index.
fn road(sweeps: usize, step_m: f64) -> (Vec<usize>, impl Fn(usize) -> Option<DVec3>) {
    ((0..sweeps).collect(), move |i: usize| {
        Some(DVec3::new(i as f64 * step_m, 0.0, 0.0))
    })
}

#[test]
fn a_short_drive_keeps_the_even_spread() {
    // 80 sweeps 1 m apart: ten spread evenly are 8 m apart, well within the overlap.
    let (usable, at) = road(80, 1.0);
    assert_eq!(
        pick_among(&usable, 10, at),
        Picked::Sweeps(spread_evenly(&usable, 10))
    );
}

#[test]
fn a_long_drive_is_taken_in_overlapping_pairs() {
    // 3000 sweeps 1 m apart: an even spread of ten would be 300 m apart.
    let (usable, at) = road(3000, 1.0);
    let Picked::Sweeps(picked) = pick_among(&usable, 10, &at) else {
        panic!("a dense long drive has pairs");
    };
    assert_eq!(picked.len(), 10);
    for pair in picked.chunks(2) {
        let travel = at(pair[1]).unwrap().distance(at(pair[0]).unwrap());
        assert!((PAIR_TRAVEL_M..=OVERLAP_M).contains(&travel), "{travel}");
    }
    // The pairs still cover the drive.
    assert!(picked[0] < 600 && picked[9] > 2400, "{picked:?}");
}

#[test]
fn a_sparse_sample_is_not_fitted() {
    // KITTI-360's sample: 20 frames 20–220 m apart, two of them close.
    let usable: Vec<usize> = (0..20).collect();
    let at = |i: usize| {
        Some(DVec3::new(
            90.0 * i as f64 - if i == 7 { 70.0 } else { 0.0 },
            0.0,
            0.0,
        ))
    };
    assert_eq!(pick_among(&usable, 10, at), Picked::TooSparse { pairs: 1 });
    let (usable, at) = road(20, 90.0);
    assert_eq!(pick_among(&usable, 10, at), Picked::TooSparse { pairs: 0 });
}

#[test]
fn close_sweeps_away_from_the_anchors_or_a_standing_vehicle_are_not_fitted() {
    // 20 sweeps 90 m apart but for three close pairs no anchor reaches: not enough to fit.
    let usable: Vec<usize> = (0..20).collect();
    let at = |i: usize| {
        let close = [4, 10, 16].contains(&i);
        Some(DVec3::new(
            90.0 * i as f64 - if close { 75.0 } else { 0.0 },
            0.0,
            0.0,
        ))
    };
    assert!(matches!(
        pick_among(&usable, 10, at),
        Picked::TooSparse { .. }
    ));
    // Sweeps in two bursts 500 m apart, each within 2 m: no pair travels 10 m.
    let at = |i: usize| {
        Some(DVec3::new(
            if i < 10 { 0.2 * i as f64 } else { 500.0 },
            0.0,
            0.0,
        ))
    };
    assert_eq!(pick_among(&usable, 4, at), Picked::TooSparse { pairs: 0 });
}

#[test]
fn pairs_stay_in_time_order_when_the_vehicle_stands_across_anchors() {
    // Stopped for the first 1000 sweeps, then 1 m a sweep: anchors in the stop share partners.
    let usable: Vec<usize> = (0..3000).collect();
    let at = |i: usize| Some(DVec3::new(i.saturating_sub(1000) as f64, 0.0, 0.0));
    let Picked::Sweeps(picked) = pick_among(&usable, 10, at) else {
        panic!("the moving part has pairs");
    };
    assert!(picked.windows(2).all(|w| w[0] < w[1]), "{picked:?}");
    for pair in picked.chunks(2) {
        let travel = at(pair[1]).unwrap().distance(at(pair[0]).unwrap());
        assert!((PAIR_TRAVEL_M..=OVERLAP_M).contains(&travel), "{picked:?}");
    }
}
