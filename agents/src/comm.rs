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

use flockstep_proto::{low_bits, slots_in, AgentView, FieldError, Flags};

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
    /// `compact`: what all peers reported, fused: (ruled out, confirmed).
    fused: (u64, u64),
    /// The tick whose messages were last taken in, and from which peers: until the state
    /// is reset or a peer forgotten, those peers' unchanged messages need no reading.
    heard_at: Option<u64>,
    heard_peers: u64,
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
            targets: low_bits(targets),
            heard: vec![(0, 0); route_lens.len()],
            own: (0, 0),
            fused: (0, 0),
            heard_at: None,
            heard_peers: 0,
            words: vec![UNKNOWN; bits.div_ceil(64)],
        }
    }

    /// A new episode: everything is unknown again.
    pub fn reset(&mut self) {
        self.words.fill(UNKNOWN);
        self.heard.fill((0, 0));
        self.own = (0, 0);
        self.fused = (0, 0);
        self.heard_at = None;
        self.heard_peers = 0;
    }

    /// A peer left the run: what is known of it is void.
    pub fn forget(&mut self, peer: usize) {
        self.heard_peers &= !1u64.checked_shl(peer as u32).unwrap_or(0);
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
                    self.fuse_all();
                }
            }
        }
    }

    /// Takes in the flags each slot in `peers` sent in the previous tick, as the world
    /// relayed them in `views` (indexed by slot) for the trial's tick `tick`, with the
    /// observation's `flags_changed`. Messages without `valid`, and from slots this state
    /// has no entry for, say nothing. A message out of range (a rogue or buggy sender) is
    /// refused with an error naming the field; what the messages before it said is kept.
    ///
    /// Taking a message in twice changes nothing, so after a tick whose messages were all
    /// taken in, only the peers whose flags changed since and the peers not heard then are
    /// read; otherwise every peer. With 32 UAVs, hearing every peer in every tick had been
    /// three quarters of an agent's instructions.
    #[inline]
    pub fn hear(
        &mut self,
        tick: u64,
        peers: u64,
        flags_changed: u64,
        views: &[AgentView],
    ) -> Result<(), FieldError> {
        let continues = self.heard_at.is_some_and(|at| at.checked_add(1) == Some(tick));
        let read = if continues { peers & (flags_changed | !self.heard_peers) } else { peers };
        let read = read & low_bits(views.len().min(self.route_lens.len()));
        if read != 0 {
            self.take_in(read, views)?;
        }
        self.heard_at = Some(tick);
        self.heard_peers = peers;
        Ok(())
    }

    /// Takes in the messages of the slots in `read`: most ticks have none, and they do not
    /// pay for this call.
    #[inline(never)]
    fn take_in(&mut self, read: u64, views: &[AgentView]) -> Result<(), FieldError> {
        self.heard_at = None;
        match self.mode {
            CommMode::None => Ok(()),
            CommMode::Flags => self.hear_flags(read, views),
            CommMode::Compact => self.hear_compact(read, views),
        }
    }

    /// `flags`: raises each sender's entry for the waypoint it reported.
    #[inline]
    fn hear_flags(&mut self, peers: u64, views: &[AgentView]) -> Result<(), FieldError> {
        for peer in slots_in(peers) {
            let flags = &views[peer].flags;
            let Some(offset) = self.offsets[peer] else { continue };
            if flags.valid == 0 {
                continue;
            }
            flockstep_proto::check_below(
                "flags.waypoint",
                flags.waypoint.into(),
                self.route_lens[peer] as u64,
            )?;
            flockstep_proto::check_below("flags.sees_target", flags.sees_target.into(), 2)?;
            let value = if flags.sees_target == 1 { HIGH } else { LOW };
            let bit = offset + 2 * flags.waypoint as usize;
            if value > self.get(bit) {
                self.set(bit, value);
            }
        }
        Ok(())
    }

    /// `compact`: adds what each sender reported to what it had, and rewrites the words
    /// once if the fused findings grew.
    #[inline]
    fn hear_compact(&mut self, peers: u64, views: &[AgentView]) -> Result<(), FieldError> {
        let (mut ruled, mut confirmed) = (0, 0);
        let mut refused = None;
        for peer in slots_in(peers) {
            let flags = &views[peer].flags;
            if flags.valid == 0 {
                continue;
            }
            if (flags.ruled_out | flags.confirmed) & !self.targets != 0 {
                refused = Some(self.outside_targets(flags));
                break;
            }
            let heard = &mut self.heard[peer];
            heard.0 |= flags.ruled_out;
            heard.1 |= flags.confirmed;
            ruled |= flags.ruled_out;
            confirmed |= flags.confirmed;
        }
        let fused = (self.fused.0 | ruled, self.fused.1 | confirmed);
        if fused != self.fused {
            self.fused = fused;
            self.encode();
        }
        refused.map_or(Ok(()), Err)
    }

    /// The error for a `compact` message naming candidates the scenario does not have.
    #[cold]
    fn outside_targets(&self, flags: &Flags) -> FieldError {
        let (field, value) = if flags.ruled_out & !self.targets != 0 {
            ("flags.ruled_out", flags.ruled_out)
        } else {
            ("flags.confirmed", flags.confirmed)
        };
        FieldError { field, value, expected: format!("a mask within {:#x}", self.targets) }
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

    /// `compact`: fuses again what every peer reported (after a peer is forgotten) and
    /// rewrites the words.
    fn fuse_all(&mut self) {
        self.fused = self.heard.iter().fold((0, 0), |(r, c), &(hr, hc)| (r | hr, c | hc));
        self.encode();
    }

    /// `compact`: writes the words from the fused findings, two bits per candidate
    /// (confirmed wins over ruled out).
    fn encode(&mut self) {
        let (ruled, confirmed) = self.fused;
        let low = ruled & !confirmed;
        for (w, word) in self.words.iter_mut().enumerate().take(2) {
            let half = |mask: u64| spread_bits((mask >> (32 * w)) as u32);
            *word = (half(confirmed) * HIGH) | (half(low) * LOW);
        }
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

/// Bit k of `x` at bit 2k: one candidate's bit at the low bit of its two-bit entry.
#[inline]
fn spread_bits(x: u32) -> u64 {
    let mut x = u64::from(x);
    x = (x | x << 16) & 0x0000_ffff_0000_ffff;
    x = (x | x << 8) & 0x00ff_00ff_00ff_00ff;
    x = (x | x << 4) & 0x0f0f_0f0f_0f0f_0f0f;
    x = (x | x << 2) & 0x3333_3333_3333_3333;
    (x | x << 1) & 0x5555_5555_5555_5555
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hears `messages` (slot, flags) as the world relays them: in views indexed by slot,
    /// every message marked as changed, at a tick after the last one heard. Returns whether
    /// the state changed.
    fn hear(state: &mut CommState, messages: &[(usize, Flags)]) -> Result<bool, FieldError> {
        let mut views = vec![AgentView::default(); flockstep_proto::MAX_AGENTS];
        let mut peers = 0;
        for &(slot, flags) in messages {
            views[slot].flags = flags;
            peers |= 1 << slot;
        }
        let tick = state.heard_at.map_or(0, |at| at + 1);
        hear_at(state, tick, peers, u64::MAX, &views)
    }

    /// [`CommState::hear`]; returns whether the state changed.
    fn hear_at(
        state: &mut CommState,
        tick: u64,
        peers: u64,
        flags_changed: u64,
        views: &[AgentView],
    ) -> Result<bool, FieldError> {
        let before = state.words().to_vec();
        state.hear(tick, peers, flags_changed, views)?;
        Ok(state.words() != before)
    }

    fn flags(state: &CommState, wp: u16, sees: bool) -> Flags {
        state.outgoing(wp, sees)
    }

    #[test]
    fn flag_entries_only_move_up_within_an_episode() {
        let mut c = CommState::new(CommMode::Flags, 0, &[11, 5], 2);
        let f = |wp, sees| flags(&c, wp, sees);
        let (zero, one) = (f(3, false), f(3, true));
        assert_eq!(c.entry(1, 3), None);
        assert!(hear(&mut c, &[(1, zero)]).unwrap());
        assert_eq!(c.entry(1, 3), Some(false));
        assert!(hear(&mut c, &[(1, one)]).unwrap());
        assert_eq!(c.entry(1, 3), Some(true));
        assert!(!hear(&mut c, &[(1, zero)]).unwrap(), "1 never falls back to 0");
        assert_eq!(c.entry(1, 3), Some(true));
        c.reset();
        assert_eq!(c.entry(1, 3), None);
    }

    #[test]
    fn own_slot_and_mode_none_keep_no_state() {
        let mut c = CommState::new(CommMode::Flags, 0, &[11, 5], 2);
        let own = flags(&c, 1, true);
        assert!(!hear(&mut c, &[(0, own)]).unwrap());
        let mut none = CommState::new(CommMode::None, 0, &[11, 5], 2);
        assert!(none.words().is_empty());
        assert!(!hear(&mut none, &[(1, own)]).unwrap());
    }

    #[test]
    fn out_of_range_values_are_refused() {
        let mut c = CommState::new(CommMode::Flags, 1, &[11, 5], 2);
        let err = hear(
            &mut c,
            &[(0, Flags { valid: 1, waypoint: 11, sees_target: 1, ..Flags::default() })],
        )
        .unwrap_err();
        assert_eq!(err.field, "flags.waypoint");
        assert!(hear(
            &mut c,
            &[(0, Flags { valid: 1, waypoint: 10, sees_target: 1, ..Flags::default() })]
        )
        .is_ok());
        let mut compact = CommState::new(CommMode::Compact, 1, &[11, 5], 2);
        let bad = Flags { valid: 1, ruled_out: 0b100, ..Flags::default() };
        assert_eq!(hear(&mut compact, &[(0, bad)]).unwrap_err().field, "flags.ruled_out");
    }

    #[test]
    fn flag_vectors_of_long_routes_span_words() {
        let mut c = CommState::new(CommMode::Flags, 0, &[3, 40, 40], 2);
        assert_eq!(c.words().len(), 3); // 160 bits
        hear(&mut c, &[(2, Flags { valid: 1, waypoint: 39, sees_target: 1, ..Flags::default() })])
            .unwrap();
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
        assert!(hear(&mut me, &[(1, peer.outgoing(0, false))]).unwrap());
        assert_eq!((me.entry(0, 0), me.entry(0, 1)), (Some(false), None));
        let mut other = CommState::new(CommMode::Compact, 2, &routes, 3);
        other.note_own(|| 0b010, true); // candidate 1 in view with the target: confirmed
        assert!(hear(&mut me, &[(2, other.outgoing(0, true))]).unwrap());
        assert_eq!(
            (me.entry(0, 0), me.entry(0, 1), me.entry(0, 2)),
            (Some(false), Some(true), None)
        );
        assert!(!hear(&mut me, &[(2, other.outgoing(0, true))]).unwrap(), "nothing new");
        me.forget(1);
        assert_eq!(me.entry(0, 0), None, "a departed peer's findings are void");
        assert_eq!(me.entry(0, 1), Some(true));
        me.reset();
        assert_eq!(me.entry(0, 1), None);
    }

    #[test]
    fn one_call_takes_in_every_peer_and_keeps_what_came_before_a_bad_message() {
        let routes = [11, 5, 5, 5];
        let mut me = CommState::new(CommMode::Compact, 0, &routes, 3);
        let ruled_0 = Flags { valid: 1, ruled_out: 0b001, ..Flags::default() };
        let confirmed_2 = Flags { valid: 1, confirmed: 0b100, ..Flags::default() };
        let silent = Flags { ruled_out: 0b010, ..Flags::default() };
        assert!(hear(&mut me, &[(1, ruled_0), (2, silent), (3, confirmed_2)]).unwrap());
        assert_eq!(
            (me.entry(0, 0), me.entry(0, 1), me.entry(0, 2)),
            (Some(false), None, Some(true)),
            "a message without `valid` says nothing"
        );
        let outside = Flags { valid: 1, confirmed: 0b1000, ..Flags::default() };
        let confirmed_1 = Flags { valid: 1, confirmed: 0b010, ..Flags::default() };
        let ruled_outside = Flags { valid: 1, ruled_out: 0b1000, ..Flags::default() };
        let err = hear(&mut me, &[(1, confirmed_1), (2, outside), (3, ruled_outside)]).unwrap_err();
        assert_eq!((err.field, err.value), ("flags.confirmed", 0b1000), "the first bad one");
        assert_eq!(me.entry(0, 1), Some(true), "the message before the bad one counts");

        let mut c = CommState::new(CommMode::Flags, 0, &routes, 3);
        let seen = |wp| Flags { valid: 1, sees_target: 1, waypoint: wp, ..Flags::default() };
        assert!(hear(&mut c, &[(1, seen(2)), (3, seen(4))]).unwrap());
        assert_eq!((c.entry(1, 2), c.entry(2, 2), c.entry(3, 4)), (Some(true), None, Some(true)));
        assert!(!hear(&mut c, &[(1, seen(2)), (3, seen(4))]).unwrap(), "nothing new");
        let err = hear(&mut c, &[(2, seen(0)), (3, seen(5))]).unwrap_err();
        assert_eq!((err.field, err.value), ("flags.waypoint", 5));
        assert_eq!(c.entry(2, 0), Some(true), "the message before the bad one counts");
    }

    #[test]
    fn compact_words_hold_every_candidate_of_two_words() {
        // 64 candidates: entries 0..32 in the first word, 32..64 in the second.
        let routes = [5, 5, 5];
        let mut me = CommState::new(CommMode::Compact, 0, &routes, 64);
        assert_eq!(me.words().len(), 2);
        let ruled = 0x8000_0001_8000_0005_u64;
        let confirmed = 0x0000_0001_0000_0004_u64 | 1 << 40;
        let a = Flags { valid: 1, ruled_out: ruled, ..Flags::default() };
        let b = Flags { valid: 1, confirmed, ..Flags::default() };
        assert!(hear(&mut me, &[(1, a), (2, b)]).unwrap());
        for k in 0..64 {
            let expected = if confirmed >> k & 1 == 1 {
                Some(true)
            } else if ruled >> k & 1 == 1 {
                Some(false)
            } else {
                None
            };
            assert_eq!(me.entry(0, k), expected, "candidate {k}");
        }
        me.forget(2);
        assert_eq!((me.entry(0, 2), me.entry(0, 40)), (Some(false), None), "peer 2 forgotten");
    }

    #[test]
    fn after_a_tick_heard_in_full_only_changed_peers_and_new_ones_are_read() {
        let mut me = CommState::new(CommMode::Flags, 0, &[11, 5, 5, 5], 2);
        let mut views = vec![AgentView::default(); 4];
        let at = |wp| Flags { valid: 1, waypoint: wp, ..Flags::default() };
        // A message no one may send: reading it is an error, so it shows what was read.
        let bad = Flags { valid: 1, waypoint: 99, ..Flags::default() };
        for (slot, flags) in [(1, at(0)), (2, at(1))] {
            views[slot].flags = flags;
        }
        assert!(hear_at(&mut me, 7, 0b0110, 0, &views).unwrap(), "no tick heard before: all read");
        views[1].flags = bad;
        views[3].flags = at(2);
        assert!(
            hear_at(&mut me, 8, 0b1110, 0b0100, &views).unwrap(),
            "slot 3 is new to this state"
        );
        assert_eq!(me.entry(3, 2), Some(false));
        assert!(hear_at(&mut me, 10, 0b1110, 0, &views).is_err(), "after a gap every peer is read");
        views[1].flags = at(3);
        assert!(
            hear_at(&mut me, 11, 0b1110, 0, &views).unwrap(),
            "after an error every peer is read"
        );
        assert_eq!(me.entry(1, 3), Some(false));
        views[1].flags = bad;
        assert_eq!(
            hear_at(&mut me, 12, 0b1110, 0b0010, &views).unwrap_err().value,
            99,
            "slot 1 changed"
        );
        views[1].flags = at(3);
        assert!(!hear_at(&mut me, 13, 0b1110, 0, &views).unwrap());
        views[3].flags = bad;
        me.forget(3);
        assert!(hear_at(&mut me, 14, 0b1110, 0, &views).is_err(), "a forgotten peer is read again");
        views[3].flags = at(4);
        assert!(hear_at(&mut me, 15, 0b1110, 0, &views).unwrap());
        me.reset();
        assert!(hear_at(&mut me, 16, 0b1110, 0, &views).unwrap(), "a reset state reads every peer");
        assert_eq!((me.entry(1, 3), me.entry(3, 4)), (Some(false), Some(false)));
    }

    #[test]
    fn reading_only_what_changed_ends_in_the_state_of_reading_everything() {
        // Pseudo-random ticks of 6 peers; a peer's findings only grow within an episode.
        let routes = [9, 9, 9, 9, 9, 9, 9];
        let mut rng = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = |n: u64| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng % n
        };
        for mode in [CommMode::Flags, CommMode::Compact] {
            let (mut skimming, mut reading) =
                (CommState::new(mode, 0, &routes, 8), CommState::new(mode, 0, &routes, 8));
            let mut views = vec![AgentView::default(); routes.len()];
            for tick in 0..2_000u64 {
                let mut changed = 0;
                for (slot, view) in views.iter_mut().enumerate().skip(1) {
                    if next(4) != 0 {
                        continue;
                    }
                    let old = view.flags;
                    let flags = &mut view.flags;
                    flags.valid = 1;
                    flags.waypoint = next(9) as u16;
                    flags.sees_target = next(2) as u8;
                    flags.ruled_out |= 1 << next(8);
                    flags.confirmed |= u64::from(next(8) == 0) << next(8);
                    changed |= u64::from(old.differs(flags)) << slot;
                }
                if tick % 97 == 0 {
                    skimming.reset();
                    reading.reset();
                }
                if tick % 31 == 0 {
                    continue; // a tick neither hears: the next one must read everything
                }
                let peers = 0b111_1110 & !(u64::from(tick % 50 < 5) << 3);
                if tick % 50 == 5 {
                    skimming.forget(3);
                    reading.forget(3);
                }
                skimming.hear(tick, peers, changed, &views).unwrap();
                reading.hear(tick, peers, u64::MAX, &views).unwrap();
                assert_eq!(skimming.words(), reading.words(), "{mode:?}, tick {tick}");
            }
        }
    }
}
