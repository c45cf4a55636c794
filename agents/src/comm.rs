//! What a UAV knows of the others (SPEC 3), in a form that is part of its RL state.
//!
//! Mode `flags` (the thesis's): per other UAV, one entry per waypoint of that UAV's route,
//! unknown / 0 / 1, packed two bits an entry into `u64` words that go straight into the
//! state key. Entries only move up (unknown -> 0 -> 1) within an episode and are reset when
//! an episode starts. Mode `none` keeps no words.

use flockstep_proto::{FieldError, Flags, MAX_AGENTS};

/// Which communication the agents use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum CommMode {
    /// No messages: the state is the pose alone.
    None,
    /// The thesis's flag vectors.
    Flags,
}

impl CommMode {
    pub fn parse(s: &str) -> Option<CommMode> {
        match s {
            "none" => Some(CommMode::None),
            "flags" => Some(CommMode::Flags),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            CommMode::None => "none",
            CommMode::Flags => "flags",
        }
    }
}

const UNKNOWN: u64 = 0;
const SEEN_ZERO: u64 = 1;
const SEEN_ONE: u64 = 2;

/// One UAV's communication state within one trial.
#[derive(Debug, Clone)]
pub struct CommState {
    mode: CommMode,
    /// Per agent slot: bit offset of its vector in `words`, or `None` for itself.
    offsets: Vec<Option<usize>>,
    route_lens: Vec<usize>,
    words: Vec<u64>,
}

impl CommState {
    /// `route_lens[j]` is the route length of agent slot j; `me` is this UAV's slot.
    pub fn new(mode: CommMode, me: usize, route_lens: &[usize]) -> CommState {
        let mut offsets = Vec::with_capacity(route_lens.len());
        let mut bits = 0usize;
        for (slot, len) in route_lens.iter().enumerate() {
            if mode == CommMode::None || slot == me {
                offsets.push(None);
            } else {
                offsets.push(Some(bits));
                bits += 2 * len;
            }
        }
        CommState {
            mode,
            offsets,
            route_lens: route_lens.to_vec(),
            words: vec![UNKNOWN; bits.div_ceil(64)],
        }
    }

    /// A new episode: everything is unknown again.
    pub fn reset(&mut self) {
        self.words.fill(UNKNOWN);
    }

    /// A peer left the run: what is known of it is void.
    pub fn forget(&mut self, peer: usize) {
        if let Some(Some(offset)) = self.offsets.get(peer) {
            for k in 0..self.route_lens[peer] {
                let bit = offset + 2 * k;
                self.words[bit / 64] &= !(3 << (bit % 64));
            }
        }
    }

    /// Takes in the flags peer `peer` sent in the previous tick. Returns whether the state
    /// changed. A waypoint outside the peer's route is refused (a rogue or buggy sender).
    #[inline]
    pub fn hear(&mut self, peer: usize, flags: &Flags) -> Result<bool, FieldError> {
        let Some(Some(offset)) = self.offsets.get(peer).copied() else {
            return Ok(false);
        };
        if flags.valid == 0 {
            return Ok(false);
        }
        flockstep_proto::check_below(
            "flags.waypoint",
            flags.waypoint.into(),
            self.route_lens[peer] as u64,
        )?;
        flockstep_proto::check_below("flags.sees_target", flags.sees_target.into(), 2)?;
        let value = if flags.sees_target == 1 { SEEN_ONE } else { SEEN_ZERO };
        let bit = offset + 2 * flags.waypoint as usize;
        let word = &mut self.words[bit / 64];
        let old = (*word >> (bit % 64)) & 3;
        if value > old {
            *word = (*word & !(3 << (bit % 64))) | (value << (bit % 64));
            return Ok(true);
        }
        Ok(false)
    }

    /// The packed vectors, part of the RL state.
    #[inline]
    pub fn words(&self) -> &[u64] {
        &self.words
    }

    pub fn mode(&self) -> CommMode {
        self.mode
    }

    /// Entry k of peer `peer`'s vector: `None` unknown, `Some(false)` 0, `Some(true)` 1.
    pub fn entry(&self, peer: usize, k: usize) -> Option<bool> {
        let offset = self.offsets.get(peer).copied().flatten()?;
        if k >= self.route_lens[peer] {
            return None;
        }
        let bit = offset + 2 * k;
        match (self.words[bit / 64] >> (bit % 64)) & 3 {
            SEEN_ZERO => Some(false),
            SEEN_ONE => Some(true),
            _ => None,
        }
    }
}

/// The flags a UAV sends about the tick it just observed.
pub fn outgoing_flags(waypoint: u16, sees_target: bool) -> Flags {
    Flags { valid: 1, sees_target: sees_target as u8, waypoint, ..Flags::default() }
}

const _: () = assert!(MAX_AGENTS <= 64, "live masks are u64");

#[cfg(test)]
mod tests {
    use super::*;

    fn flag(wp: u16, sees: bool) -> Flags {
        outgoing_flags(wp, sees)
    }

    #[test]
    fn entries_only_move_up_within_an_episode() {
        let mut c = CommState::new(CommMode::Flags, 0, &[11, 5]);
        assert_eq!(c.entry(1, 3), None);
        assert!(c.hear(1, &flag(3, false)).unwrap());
        assert_eq!(c.entry(1, 3), Some(false));
        assert!(c.hear(1, &flag(3, true)).unwrap());
        assert_eq!(c.entry(1, 3), Some(true));
        assert!(!c.hear(1, &flag(3, false)).unwrap(), "1 never falls back to 0");
        assert_eq!(c.entry(1, 3), Some(true));
        c.reset();
        assert_eq!(c.entry(1, 3), None);
    }

    #[test]
    fn own_slot_and_mode_none_keep_no_state() {
        let mut c = CommState::new(CommMode::Flags, 0, &[11, 5]);
        assert!(!c.hear(0, &flag(1, true)).unwrap());
        let mut none = CommState::new(CommMode::None, 0, &[11, 5]);
        assert!(none.words().is_empty());
        assert!(!none.hear(1, &flag(1, true)).unwrap());
    }

    #[test]
    fn out_of_range_waypoints_are_refused() {
        let mut c = CommState::new(CommMode::Flags, 1, &[11, 5]);
        let err = c.hear(0, &flag(11, true)).unwrap_err();
        assert_eq!(err.field, "flags.waypoint");
        assert!(c.hear(0, &flag(10, true)).is_ok());
    }

    #[test]
    fn vectors_of_long_routes_span_words() {
        let mut c = CommState::new(CommMode::Flags, 0, &[3, 40, 40]);
        assert_eq!(c.words().len(), 3); // 160 bits
        c.hear(2, &flag(39, true)).unwrap();
        assert_eq!(c.entry(2, 39), Some(true));
        assert_eq!(c.entry(1, 39), None);
        c.forget(2);
        assert_eq!(c.entry(2, 39), None);
    }
}
