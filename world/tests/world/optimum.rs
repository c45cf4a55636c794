//! The exact optimum of one memoryless UAV, and the bound of a UAV that knows the target.

use flockstep_proto::{Heading, Height, Pose};
use flockstep_world::optimum::{
    optimum, optimum_with_known_target, route_optima, KnownTarget, Optimum, RouteOptima,
};
use flockstep_world::{OptimumError, Scenario};

use crate::common::TINY;

fn scenario(name: &str) -> Scenario {
    Scenario::builtin(name).expect("builtin scenario")
}

/// The path starts at the start pose, follows its moves, and sees each target at the tick
/// its length says.
fn assert_consistent(s: &Scenario, uav: usize, best: &Optimum) {
    assert_eq!(best.path.first().map(|step| step.pose), Some(s.start_pose()));
    for pair in best.path.windows(2) {
        let command = pair[0].then.expect("every step but the last has a move");
        assert_eq!(pair[0].pose.apply(command, s.route_len(uav)), pair[1].pose);
    }
    assert_eq!(best.path.last().and_then(|step| step.then), None);
    for (k, &length) in best.lengths.iter().enumerate() {
        let first = best.path.iter().position(|step| step.sees & (1 << k) != 0);
        assert_eq!(first, Some(length as usize - 1), "T{}", k + 1);
        let step = &best.path[length as usize - 1];
        assert_eq!(s.visible_targets(uav, step.pose), step.sees);
    }
    let mean = best.lengths.iter().sum::<u64>() as f64 / best.lengths.len() as f64;
    assert_eq!(best.expected_ticks, mean);
}

#[test]
fn scenario_1_takes_13_ticks() {
    // From wp1 low facing N: three rotations to face W (ticks 0-2), nine translations to wp10
    // (ticks 3-11), where T1, the only target, is in sight at tick 12: 13 ticks with the
    // episode's end. (The pose below is 0-based: waypoint 9 is wp10.)
    let s1 = scenario("s1");
    let best = optimum(&s1, 0).expect("optimum");
    assert_eq!((best.expected_ticks, best.lengths.as_slice()), (13.0, &[13][..]));
    assert_eq!(best.path.last().map(|s| s.pose), Some(Pose::new(9, Height::Low, Heading::W)));
    assert_consistent(&s1, 0, &best);
    assert_eq!(optimum_with_known_target(&s1, 0).expect("bound").expected_ticks, 13.0);
}

#[test]
fn scenario_2_takes_11_5_ticks_t1_first() {
    // T1 at tick 7 (5 translations, elevate, rotate), then T2 at tick 14 (4 translations,
    // deElevate, 2 rotations): lengths 8 and 15.
    let s2 = scenario("s2");
    let best = optimum(&s2, 0).expect("optimum");
    assert_eq!((best.expected_ticks, best.lengths.as_slice()), (11.5, &[8, 15][..]));
    assert_consistent(&s2, 0, &best);
    let text = best.to_string();
    assert!(text.starts_with("expected episode length 11.5 ticks (T1: 8, T2: 15)"), "{text}");
    assert!(text.contains("tick 7: wp6 high E sees T1 -> "), "{text}");
    assert!(text.contains("tick 14: wp10 low W sees T2\n"), "{text}");
    // Knowing the target, T2 is reached straight away: (8 + 13) / 2.
    let bound = optimum_with_known_target(&s2, 0).expect("bound");
    assert_eq!((bound.expected_ticks, bound.lengths.as_slice()), (10.5, &[8, 13][..]));
}

#[test]
fn scenario_3_each_uav_alone() {
    let s3 = scenario("s3");
    let uav1 = optimum(&s3, 0).expect("UAV1");
    assert_eq!((uav1.expected_ticks, uav1.lengths.as_slice()), (11.5, &[8, 15][..]));
    assert_consistent(&s3, 0, &uav1);
    // UAV2: rotate, translate, sees T1 at tick 2; rotate, 2 translations, T2 at tick 5.
    let uav2 = optimum(&s3, 1).expect("UAV2");
    assert_eq!((uav2.expected_ticks, uav2.lengths.as_slice()), (4.5, &[3, 6][..]));
    assert_consistent(&s3, 1, &uav2);
    assert_eq!(optimum_with_known_target(&s3, 0).expect("bound").expected_ticks, 10.5);
    assert_eq!(optimum_with_known_target(&s3, 1).expect("bound").expected_ticks, 4.5);
}

#[test]
fn a_target_the_uav_never_sees_makes_the_optimum_infinite() {
    let tiny = Scenario::from_text("tiny.map", TINY).expect("tiny");
    let err = optimum(&tiny, 1).expect_err("UAV2 never sees T1");
    assert_eq!(err, OptimumError::Unseeable { uav: 1, label: "T1".to_string() });
    assert!(err.to_string().contains("UAV2 sees T1 from no pose of its route"), "{err}");
    assert!(optimum_with_known_target(&tiny, 1).is_err());
    assert_eq!(optimum(&tiny, 2), Err(OptimumError::NoSuchUav { uav: 2, n: 2 }));
}

/// `supervisor optimum` prints every route: one that never sees a target says so, naming
/// itself once, and the other routes' optima are still there. Before, the first such route
/// failed the whole command, with its name twice ("UAV2: UAV2 sees ...").
#[test]
fn a_route_without_an_optimum_does_not_hide_the_others() {
    let tiny = Scenario::from_text("tiny.map", TINY).expect("tiny");
    let routes = route_optima(&tiny);
    assert_eq!(routes.len(), 2);
    assert_eq!(routes[0].memoryless, optimum(&tiny, 0));
    assert_eq!(routes[0].known_target, optimum_with_known_target(&tiny, 0));
    let uav1 = routes[0].to_string();
    let best = optimum(&tiny, 0).expect("UAV1's optimum");
    let bound = optimum_with_known_target(&tiny, 0).expect("UAV1's bound");
    let header = format!(
        "UAV1: memoryless optimum {:.4} ticks (per target {:?}); knowing the target {:.4}\n",
        best.expected_ticks, best.lengths, bound.expected_ticks
    );
    assert_eq!(uav1, format!("{header}{best}"));
    let unseeable = OptimumError::Unseeable { uav: 1, label: "T1".to_string() };
    assert_eq!(routes[1].memoryless, Err(unseeable.clone()));
    assert_eq!(routes[1].known_target, Err(unseeable));
    assert_eq!(
        routes[1].to_string(),
        "UAV2 sees T1 from no pose of its route: the expected episode length is infinite\n"
    );
}

/// A route whose memoryless optimum is infinite for want of a simple path still has its
/// known-target bound, and shows it.
#[test]
fn a_route_without_a_memoryless_optimum_still_shows_its_bound() {
    let route = RouteOptima {
        uav: 0,
        memoryless: Err(OptimumError::NoSimplePath { uav: 0 }),
        known_target: Ok(KnownTarget { expected_ticks: 10.5, lengths: vec![8, 13] }),
    };
    assert_eq!(
        route.to_string(),
        "UAV1 has no trajectory that sees every target without repeating a state: no \
         memoryless policy ends every episode; knowing the target 10.5000\n"
    );
}

#[test]
fn a_target_seen_from_the_start_ends_the_episode_at_once() {
    // UAV1 of the small map sees T1 from its start pose, wp1 low N.
    let tiny = Scenario::from_text("tiny.map", TINY).expect("tiny");
    let best = optimum(&tiny, 0).expect("optimum");
    assert_eq!(best.lengths[0], 1);
    assert_consistent(&tiny, 0, &best);
}
