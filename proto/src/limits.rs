//! Compile-time limits of every message. Payloads are fixed-size, so these bound the run.
//!
//! The services are created for the largest run these limits allow; a run asking for more
//! agents or trials is refused with a clear error before any process starts.

/// Largest number of UAV agents in one run (the live set is a `u64` bit mask).
pub const MAX_AGENTS: usize = 64;
/// Largest number of independent trials carried by one barrier round.
pub const MAX_TRIALS: usize = 16;
/// Largest number of commands one agent may issue in one trial's tick. Trees whose
/// worst case exceeds it are refused when they are loaded.
pub const MAX_COMMANDS: usize = 16;
/// Largest number of candidate target cells of a scenario (masks are `u64`).
pub const MAX_TARGETS: usize = 64;
/// Largest number of waypoints of one route (waypoint indices are `u16`; the agent's
/// communication state packs two bits per peer waypoint).
pub const MAX_WAYPOINTS: usize = 1024;

/// The agent slots set in `mask` (a live set or a trial's members), lowest first: as many
/// steps as slots, not `MAX_AGENTS`, since episode reports and observations are walked
/// this way on every round.
#[inline]
pub fn slots_in(mut mask: u64) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let slot = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            slot
        })
    })
}

/// The mask of the lowest `n` bits (all 64 from `n` = 64 on): the slots of a run of `n`
/// agents, or the candidate targets of a scenario with `n` of them.
#[inline]
pub fn low_bits(n: usize) -> u64 {
    if n >= 64 {
        u64::MAX
    } else {
        (1 << n) - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn low_bits_masks_the_lowest_n_bits() {
        assert_eq!(low_bits(0), 0);
        assert_eq!(low_bits(2), 0b11);
        assert_eq!(low_bits(63), u64::MAX >> 1);
        assert_eq!(low_bits(64), u64::MAX);
        assert_eq!(low_bits(MAX_TARGETS + 1), u64::MAX);
    }

    #[test]
    fn slots_in_lists_the_set_bits_lowest_first() {
        assert_eq!(slots_in(0).count(), 0);
        assert_eq!(slots_in(0b1010_0001).collect::<Vec<_>>(), [0, 5, 7]);
        assert_eq!(slots_in(1 << 63).collect::<Vec<_>>(), [63]);
        assert_eq!(slots_in(u64::MAX).collect::<Vec<_>>(), (0..MAX_AGENTS).collect::<Vec<_>>());
    }
}
