//! Determinism (issue 2, acceptance 5): the same command twice gives byte-identical
//! `episodes.csv`; another seed gives different bytes.

use crate::harness::{first_difference, read, scratch, supervise};

fn episodes(seed: &str) -> Vec<u8> {
    let dir = scratch();
    supervise(
        dir.path(),
        &[
            "--transport",
            "inproc",
            "--scenario",
            "s3",
            "--uavs",
            "2",
            "--episodes",
            "500",
            "--trials",
            "2",
            "--seed",
            seed,
        ],
    );
    read(&dir.path().join("episodes.csv"))
}

#[test]
fn same_seed_gives_identical_episodes_and_another_seed_does_not() {
    let first = episodes("7");
    assert!(first.len() > 1000, "episodes.csv is suspiciously short");
    if let Some(difference) = first_difference(&first, &episodes("7")) {
        panic!("two runs with seed 7 differ: {difference}");
    }
    assert_ne!(first, episodes("8"), "seeds 7 and 8 gave the same episodes");
}
