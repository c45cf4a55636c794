//! Learning works (issue 2, acceptance 4): with `--trials 4 --seed 1` in-process, the
//! greedy policy of s1 reaches the exact optimum, s2 comes within 5% of its optimum, and in
//! s3 the flags from UAV2 make UAV1's greedy episodes shorter than s2's without them. The
//! optima are computed by the world crate's exact solver, not written down here.

use crate::harness::{number, scratch, supervise};
use flockstep_world::optimum::optimum;
use flockstep_world::Scenario;

fn memoryless_optimum(name: &str) -> f64 {
    let scenario = Scenario::builtin(name).expect("a built-in scenario");
    optimum(&scenario, 0).expect("an optimum").expected_ticks
}

/// UAV1's mean greedy episode length after training (in process, 4 trials, seed 1).
fn greedy(scenario: &str, uavs: &str, comm: &str, episodes: &str) -> f64 {
    let dir = scratch();
    let s = supervise(
        dir.path(),
        &[
            "--transport",
            "inproc",
            "--scenario",
            scenario,
            "--uavs",
            uavs,
            "--comm",
            comm,
            "--episodes",
            episodes,
            "--trials",
            "4",
            "--seed",
            "1",
        ],
    );
    assert_eq!(
        number(&s, "greedy_truncated", 0),
        0.0,
        "a greedy UAV1 episode hit the tick cap: {s:#}"
    );
    number(&s, "greedy_episode_length", 0)
}

#[test]
fn s1_greedy_policy_reaches_the_exact_optimum() {
    let best = memoryless_optimum("s1");
    assert_eq!(
        best, 13.0,
        "the s1 optimum under SPEC semantics is 13 ticks (derived in world/tests/world/optimum.rs)"
    );
    let greedy = greedy("s1", "1", "none", "3000");
    assert_eq!(greedy, best);
}

#[test]
fn s2_greedy_policy_is_within_five_percent_of_the_optimum() {
    let best = memoryless_optimum("s2");
    let greedy = greedy("s2", "1", "none", "5000");
    assert!((greedy - best).abs() <= 0.05 * best, "greedy {greedy} vs optimum {best}");
}

#[test]
fn s3_flags_shorten_uav1_greedy_episodes_below_s2_without_communication() {
    let alone = greedy("s2", "1", "none", "20000");
    let informed = greedy("s3", "2", "flags", "20000");
    assert!(informed < alone, "s3 flags greedy {informed} is not below s2 none {alone}");
}
