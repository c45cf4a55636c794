//! What a UAV knows of the others (SPEC 3), in a form that is part of its RL state.
//!
//! - `flags` (the thesis's): per other UAV, one entry per waypoint of that UAV's route,
//!   unknown / 0 / 1 (did it see the target from there), packed two bits an entry.
//!   The state grows with every peer's route: 3^(sum of peer route lengths) values.
//! - `compact`: one entry per candidate target cell, unknown / ruled out / confirmed, fused
//!   over all peers. A peer rules out the candidate cells its camera covered without seeing
//!   the target and confirms those it covered while seeing it (the map is public, so each
//!   UAV knows which candidates are in view of a pose). The state has 3^(candidates) values,
//!   whatever the number of UAVs.
//! - `none`: no words.
//!
//! Entries only move up within an episode and are reset when an episode starts; a peer that
//! leaves the run is forgotten. The packed words go straight into the state key.

use flockstep_proto::{FieldError, Flags};

/// Which communication the agents use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum CommMode {
    /// No messages: the state is the pose alone.
    None,
    /// The thesis's flag vectors.
    Flags,
    /// One tri-state per candidate target cell.
    Compact,
}

impl CommMode {
    pub fn parse(s: &str) -> Option<CommMode> {
        match s {
            "none" => Some(CommMode::None),
            "flags" => Some(CommMode::Flags),
            "compact" => Some(CommMode::Compact),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            CommMode::None => "none",
            CommMode::Flags => "flags",
            CommMode::Compact => "compact",
        }
    }
}

const UNKNOWN: u64 = 0;
/// `flags`: seen from there, target not in view. `compact`: ruled out.
const LOW: u64 = 1;
/// `flags`: seen from there, target in view. `compact`: confirmed.
const HIGH: u64 = 2;

/// One UAV's communication state within one trial.
#[derive(Debug, Clone)]
pub struct CommState {
    mode: CommMode,
    /// `flags`: per agent slot, bit offset of its vector in `words` (`None` for itself).
    offsets: Vec<Option<usize>>,
    route_lens: Vec<usize>,
    /// `compact`: bits of the valid candidate cells.
    targets: u64,
    /// `compact`: per slot, the candidates it has reported (ruled out, confirmed).
    heard: Vec<(u64, u64)>,
    /// `compact`: this UAV's own findings in the episode, which it sends.
    own: (u64, u64),
    words: Vec<u64>,
}

impl CommState {
    /// `route_lens[j]` is the route length of agent slot j; `me` is this UAV's slot;
    /// `targets` the number of candidate target cells.
    pub fn new(mode: CommMode, me: usize, route_lens: &[usize], targets: usize) -> CommState {
        let mut offsets = vec![None; route_lens.len()];
        let bits = match mode {
            CommMode::None => 0,
            CommMode::Compact => 2 * targets,
            CommMode::Flags => {
                let mut bits = 0;
                for (slot, len) in route_lens.iter().enumerate().filter(|&(slot, _)| slot != me) {
                    offsets[slot] = Some(bits);
                    bits += 2 * len;
                }
                bits
            }
        };
        CommState {
            mode,
            offsets,
            route_lens: route_lens.to_vec(),
            targets: flockstep_proto::low_bits(targets),
            heard: vec![(0, 0); route_lens.len()],
            own: (0, 0),
            words: vec![UNKNOWN; bits.div_ceil(64)],
        }
    }

    /// A new episode: everything is unknown again.
    pub fn reset(&mut self) {
        self.words.fill(UNKNOWN);
        self.heard.fill((0, 0));
        self.own = (0, 0);
    }

    /// A peer left the run: what is known of it is void.
    pub fn forget(&mut self, peer: usize) {
        match self.mode {
            CommMode::None => {}
            CommMode::Flags => {
                if let Some(Some(offset)) = self.offsets.get(peer).copied() {
                    for k in 0..self.route_lens[peer] {
                        self.set(offset + 2 * k, UNKNOWN);
                    }
                }
            }
            CommMode::Compact => {
                if let Some(heard) = self.heard.get_mut(peer) {
                    *heard = (0, 0);
                    self.fuse();
                }
            }
        }
    }

    /// Takes in the flags peer `peer` sent in the previous tick. Returns whether the state
    /// changed. Values out of range are refused (a rogue or buggy sender).
    #[inline]
    pub fn hear(&mut self, peer: usize, flags: &Flags) -> Result<bool, FieldError> {
        if flags.valid == 0 || peer >= self.route_lens.len() {
            return Ok(false);
        }
        match self.mode {
            CommMode::None => Ok(false),
            CommMode::Flags => {
                let Some(offset) = self.offsets[peer] else { return Ok(false) };
                flockstep_proto::check_below(
                    "flags.waypoint",
                    flags.waypoint.into(),
                    self.route_lens[peer] as u64,
                )?;
                flockstep_proto::check_below("flags.sees_target", flags.sees_target.into(), 2)?;
                let value = if flags.sees_target == 1 { HIGH } else { LOW };
                let bit = offset + 2 * flags.waypoint as usize;
                if value <= self.get(bit) {
                    return Ok(false);
                }
                self.set(bit, value);
                Ok(true)
            }
            CommMode::Compact => {
                for (field, mask) in
                    [("flags.ruled_out", flags.ruled_out), ("flags.confirmed", flags.confirmed)]
                {
                    if mask & !self.targets != 0 {
                        return Err(FieldError {
                            field,
                            value: mask,
                            expected: format!("a mask within {:#x}", self.targets),
                        });
                    }
                }
                let heard = &mut self.heard[peer];
                let merged = (heard.0 | flags.ruled_out, heard.1 | flags.confirmed);
                if merged == *heard {
                    return Ok(false);
                }
                *heard = merged;
                Ok(self.fuse())
            }
        }
    }

    /// Notes this UAV's own camera result: `in_view` gives the candidate cells its pose
    /// covers. Only `compact` uses it (the flags carry the waypoint and the result as they
    /// are), so only `compact` looks them up.
    #[inline]
    pub fn note_own(&mut self, in_view: impl FnOnce() -> u64, sees_target: bool) {
        if self.mode == CommMode::Compact {
            let in_view = in_view();
            if sees_target {
                self.own.1 |= in_view;
            } else {
                self.own.0 |= in_view;
            }
        }
    }

    /// The flags this UAV sends about the tick it just observed.
    pub fn outgoing(&self, waypoint: u16, sees_target: bool) -> Flags {
        Flags {
            valid: 1,
            sees_target: sees_target as u8,
            waypoint,
            ruled_out: self.own.0,
            confirmed: self.own.1,
            ..Flags::default()
        }
    }

    /// `compact`: rewrites the words from what every peer reported; true if they changed.
    fn fuse(&mut self) -> bool {
        let (ruled, confirmed) =
            self.heard.iter().fold((0, 0), |(r, c), &(hr, hc)| (r | hr, c | hc));
        let before = self.words.clone();
        for k in 0..64usize.min(self.words.len() * 32) {
            let value = if confirmed >> k & 1 == 1 {
                HIGH
            } else if ruled >> k & 1 == 1 {
                LOW
            } else {
                UNKNOWN
            };
            self.set(2 * k, value);
        }
        before != self.words
    }

    #[inline]
    fn get(&self, bit: usize) -> u64 {
        (self.words[bit / 64] >> (bit % 64)) & 3
    }

    #[inline]
    fn set(&mut self, bit: usize, value: u64) {
        let word = &mut self.words[bit / 64];
        *word = (*word & !(3 << (bit % 64))) | (value << (bit % 64));
    }

    /// The packed entries, part of the RL state.
    #[inline]
    pub fn words(&self) -> &[u64] {
        &self.words
    }

    /// `flags`: entry k of peer `peer`'s vector. `compact`: entry k (candidate k) of the
    /// fused vector, `peer` ignored. `None` unknown, `Some(false)` 0 / ruled out,
    /// `Some(true)` 1 / confirmed.
    pub fn entry(&self, peer: usize, k: usize) -> Option<bool> {
        let bit = match self.mode {
            CommMode::None => return None,
            CommMode::Flags => {
                let offset = self.offsets.get(peer).copied().flatten()?;
                if k >= self.route_lens[peer] {
                    return None;
                }
                offset + 2 * k
            }
            CommMode::Compact => {
                if k >= 64 || self.targets >> k & 1 == 0 {
                    return None;
                }
                2 * k
            }
        };
        match self.get(bit) {
            LOW => Some(false),
            HIGH => Some(true),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flags(state: &CommState, wp: u16, sees: bool) -> Flags {
        state.outgoing(wp, sees)
    }

    #[test]
    fn flag_entries_only_move_up_within_an_episode() {
        let mut c = CommState::new(CommMode::Flags, 0, &[11, 5], 2);
        let f = |wp, sees| flags(&c, wp, sees);
        let (zero, one) = (f(3, false), f(3, true));
        assert_eq!(c.entry(1, 3), None);
        assert!(c.hear(1, &zero).unwrap());
        assert_eq!(c.entry(1, 3), Some(false));
        assert!(c.hear(1, &one).unwrap());
        assert_eq!(c.entry(1, 3), Some(true));
        assert!(!c.hear(1, &zero).unwrap(), "1 never falls back to 0");
        assert_eq!(c.entry(1, 3), Some(true));
        c.reset();
        assert_eq!(c.entry(1, 3), None);
    }

    #[test]
    fn own_slot_and_mode_none_keep_no_state() {
        let mut c = CommState::new(CommMode::Flags, 0, &[11, 5], 2);
        let own = flags(&c, 1, true);
        assert!(!c.hear(0, &own).unwrap());
        let mut none = CommState::new(CommMode::None, 0, &[11, 5], 2);
        assert!(none.words().is_empty());
        assert!(!none.hear(1, &own).unwrap());
    }

    #[test]
    fn out_of_range_values_are_refused() {
        let mut c = CommState::new(CommMode::Flags, 1, &[11, 5], 2);
        let err = c.hear(0, &flags(&c, 11, true)).unwrap_err();
        assert_eq!(err.field, "flags.waypoint");
        assert!(c.hear(0, &flags(&c, 10, true)).is_ok());
        let mut compact = CommState::new(CommMode::Compact, 1, &[11, 5], 2);
        let bad = Flags { valid: 1, ruled_out: 0b100, ..Flags::default() };
        assert_eq!(compact.hear(0, &bad).unwrap_err().field, "flags.ruled_out");
    }

    #[test]
    fn flag_vectors_of_long_routes_span_words() {
        let mut c = CommState::new(CommMode::Flags, 0, &[3, 40, 40], 2);
        assert_eq!(c.words().len(), 3); // 160 bits
        c.hear(2, &flags(&c, 39, true)).unwrap();
        assert_eq!(c.entry(2, 39), Some(true));
        assert_eq!(c.entry(1, 39), None);
        c.forget(2);
        assert_eq!(c.entry(2, 39), None);
    }

    #[test]
    fn compact_fuses_what_peers_ruled_out_and_confirmed() {
        let routes = [11, 5, 5];
        let mut me = CommState::new(CommMode::Compact, 0, &routes, 3);
        assert_eq!(me.words().len(), 1, "3 candidates: 6 bits, whatever the routes");
        let mut peer = CommState::new(CommMode::Compact, 1, &routes, 3);
        peer.note_own(|| 0b001, false); // candidate 0 in view, no target: ruled out
        assert!(me.hear(1, &peer.outgoing(0, false)).unwrap());
        assert_eq!((me.entry(0, 0), me.entry(0, 1)), (Some(false), None));
        let mut other = CommState::new(CommMode::Compact, 2, &routes, 3);
        other.note_own(|| 0b010, true); // candidate 1 in view with the target: confirmed
        assert!(me.hear(2, &other.outgoing(0, true)).unwrap());
        assert_eq!(
            (me.entry(0, 0), me.entry(0, 1), me.entry(0, 2)),
            (Some(false), Some(true), None)
        );
        assert!(!me.hear(2, &other.outgoing(0, true)).unwrap(), "nothing new");
        me.forget(1);
        assert_eq!(me.entry(0, 0), None, "a departed peer's findings are void");
        assert_eq!(me.entry(0, 1), Some(true));
        me.reset();
        assert_eq!(me.entry(0, 1), None);
    }
}
