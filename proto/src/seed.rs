//! Seeds of every random stream of a run, derived from the run's one seed.
//!
//! Each stream (the world's target draws of trial k, agent i's choices in trial k, ...) gets
//! its own seed, so the results do not depend on which process draws first: the in-process
//! and the multi-process runs draw the very same numbers.

/// Stream tags, so two kinds of streams never share a seed.
pub const WORLD_TRAIN: u64 = 1;
pub const WORLD_EVAL: u64 = 2;
pub const AGENT: u64 = 3;

/// SplitMix64 finaliser: a bijective mixer with good avalanche.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The seed of stream `path` (e.g. `[AGENT, slot, trial]`) of a run seeded with `seed`.
pub fn derive(seed: u64, path: &[u64]) -> u64 {
    path.iter().fold(mix(seed), |acc, &part| mix(acc ^ mix(part)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_differ_and_are_stable() {
        assert_ne!(derive(1, &[AGENT, 0, 0]), derive(1, &[AGENT, 0, 1]));
        assert_ne!(derive(1, &[AGENT, 0, 1]), derive(1, &[AGENT, 1, 0]));
        assert_ne!(derive(1, &[WORLD_TRAIN, 0]), derive(2, &[WORLD_TRAIN, 0]));
        assert_eq!(derive(7, &[WORLD_EVAL, 3]), derive(7, &[WORLD_EVAL, 3]));
    }
}
