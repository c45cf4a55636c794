//! The thesis's three maps (Fig. 7-9): they load, and their facts (thesis 3.2) hold.

use std::path::Path;

use flockstep_proto::{Heading, Height, Pose};
use flockstep_world::Scenario;

fn pose(wp: usize, height: Height, heading: Heading) -> Pose {
    Pose::new(wp - 1, height, heading)
}

/// UAV `uav` (0-based) sees target `target` (0-based) from exactly `poses`.
fn assert_seen_only_from(scenario: &Scenario, uav: usize, target: usize, poses: &[Pose]) {
    assert_eq!(scenario.poses_seeing(uav, target), poses, "UAV{} T{}", uav + 1, target + 1);
    for &p in poses {
        assert_ne!(scenario.visible_targets(uav, p) & (1 << target), 0);
        assert!(scenario.visible_cells(uav, p).contains(&scenario.map().targets[target]));
    }
}

#[test]
fn scenario_1_t1_only_from_wp10_low_west() {
    let s1 = Scenario::builtin("s1").expect("s1");
    assert_eq!(
        (s1.name(), s1.n_routes(), s1.route_len(0), s1.n_targets()),
        ("s1_one_uav_one_target", 1, 11, 1)
    );
    assert_seen_only_from(&s1, 0, 0, &[pose(10, Height::Low, Heading::W)]);
}

#[test]
fn scenario_2_t1_from_wp6_high_east_and_t2_from_wp10_low_west() {
    let s2 = Scenario::builtin("s2").expect("s2");
    assert_eq!((s2.n_routes(), s2.route_len(0), s2.n_targets()), (1, 11, 2));
    assert_seen_only_from(&s2, 0, 0, &[pose(6, Height::High, Heading::E)]);
    assert_seen_only_from(&s2, 0, 1, &[pose(10, Height::Low, Heading::W)]);
}

#[test]
fn scenario_3_adds_uav2_seeing_t1_from_wp2_and_t2_from_wp4() {
    let s3 = Scenario::builtin("s3").expect("s3");
    assert_eq!((s3.n_routes(), s3.route_len(0), s3.route_len(1), s3.n_targets()), (2, 11, 5, 2));
    assert_seen_only_from(&s3, 0, 0, &[pose(6, Height::High, Heading::E)]);
    assert_seen_only_from(&s3, 0, 1, &[pose(10, Height::Low, Heading::W)]);
    assert_seen_only_from(&s3, 1, 0, &[pose(2, Height::Low, Heading::E)]);
    assert_seen_only_from(&s3, 1, 1, &[pose(4, Height::Low, Heading::S)]);
}

#[test]
fn the_accessors_describe_scenario_3() {
    let s3 = Scenario::builtin("s3").expect("s3");
    assert_eq!(s3.start_pose(), Pose::new(0, Height::Low, Heading::N));
    assert_eq!((s3.route_waypoint(0, 0), s3.route_waypoint(0, 10)), ((3, 5), (4, 7)));
    assert_eq!((s3.route_waypoint(1, 0), s3.route_waypoint(1, 4)), ((5, 6), (4, 6)));
    assert_eq!((s3.target_label(0), s3.target_label(1)), ("T1".to_string(), "T2".to_string()));
    assert_eq!((s3.map().targets[0], s3.map().targets[1]), ((6, 7), (5, 8)));
    assert_eq!(s3.map().expects.len(), 4);
    assert_eq!(s3.visible_targets(1, Pose::new(3, Height::Low, Heading::S)), 0b10);
    assert_eq!(s3.visible_targets(0, s3.start_pose()), 0);
}

#[test]
fn the_builtin_maps_are_the_files_on_disk() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("maps");
    for (name, file) in [
        ("s1", "s1_one_uav_one_target.map"),
        ("s2", "s2_one_uav_two_targets.map"),
        ("s3", "s3_two_uavs_two_targets.map"),
    ] {
        let builtin = Scenario::builtin(name).expect("builtin");
        let loaded = Scenario::load(&dir.join(file)).expect("the file loads");
        assert_eq!(builtin.source_text(), loaded.source_text());
        assert_eq!(builtin.map(), loaded.map());
        let resolved = Scenario::resolve(name).expect("resolve a builtin name");
        assert_eq!(resolved.map(), builtin.map());
        let by_path = dir.join(file).display().to_string();
        assert_eq!(Scenario::resolve(&by_path).expect("resolve a path").map(), builtin.map());
    }
    assert!(Scenario::builtin("s99").is_none());
}
