//! World -> agents: one broadcast per barrier round with every trial and every agent slot.
//!
//! Each agent reads its own slot (pose, what its camera sees) and the relayed flags of its
//! peers. One message for all agents keeps the barrier to a single publish per round.

use crate::flags::Flags;
use crate::limits::{MAX_AGENTS, MAX_TRIALS};
use crate::pose::Pose;
use iceoryx2::prelude::ZeroCopySend;

/// One agent slot in one trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::AgentView")]
pub struct AgentView {
    /// Pose at the start of this tick.
    pub pose: Pose,
    /// 1 if the target cell is visible from `pose`.
    pub sees_target: u8,
    /// 1 if this agent has finished its episode and hovers.
    pub finished: u8,
    /// 1 if this agent takes part in this trial's episode (agents that attach join a trial
    /// at its next episode start).
    pub member: u8,
    pub _reserved: u8,
    /// The flags this agent sent in the previous tick (`valid` 0 if none).
    pub flags: Flags,
}

/// One trial's state at the start of a tick; its agents' views follow all the headers in
/// [`Observation::views`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::TrialHeader")]
pub struct TrialHeader {
    /// Episode index (0-based) this tick belongs to.
    pub episode: u64,
    /// Ticks of this trial executed before this one (the trial's clock).
    pub tick: u64,
    /// Ticks of the current episode executed before this one (0 = episode start).
    pub episode_tick: u32,
    /// 1 once the trial has run its episode budget: nothing more to tick.
    pub done: u8,
    /// [`Phase`] as `u8`: training, or greedy evaluation of what was learned.
    pub phase: u8,
    pub _reserved: [u8; 2],
    /// Bit i set: agent slot i takes part in this trial's episode (its view's `member`).
    pub members: u64,
    /// Bit i clear: slot i's relayed flags are those relayed in this trial's previous tick,
    /// if slot i was a member then too (at the trial's first tick every bit is set). Taking
    /// a message in twice changes nothing, so an agent that took in every peer's message
    /// of the previous tick reads only the views of the slots set here and of new members:
    /// with N UAVs a few views a tick instead of N - 1.
    pub flags_changed: u64,
}

impl Default for TrialHeader {
    fn default() -> Self {
        TrialHeader {
            episode: 0,
            tick: 0,
            episode_tick: 0,
            done: 0,
            phase: Phase::Train as u8,
            _reserved: [0; 2],
            members: 0,
            flags_changed: u64::MAX,
        }
    }
}

/// One trial's part of an observation: its header and the views of the slots in use.
#[derive(Debug, Clone, Copy)]
pub struct TrialObservation<'a> {
    pub header: &'a TrialHeader,
    /// Indexed by agent slot; `Observation::n_slots` entries.
    pub agents: &'a [AgentView],
}

/// What a trial is doing: agents learn while training and act greedily (epsilon 0, no
/// learning) while evaluating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Phase {
    Train = 0,
    Eval = 1,
}

impl Phase {
    pub fn from_u8(v: u8) -> Option<Phase> {
        match v {
            0 => Some(Phase::Train),
            1 => Some(Phase::Eval),
            _ => None,
        }
    }
}

/// What a round asks of the agents.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ObservationKind {
    /// Tick every trial that is not done and answer with an action.
    Tick = 0,
    /// The run is over: finish learning from the last tick, write results, exit.
    Stop = 1,
}

/// Why the world refused a join request: the agent that sent it learns the reason from
/// [`Observation::refusal`], so it can say what is wrong instead of asking until it times out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Refusal {
    /// The request asked for any free route, and every route of the scenario is taken.
    RunFull = 1,
    /// The slot asked for is not a route of the scenario.
    NoSuchRoute = 2,
    /// The slot asked for is held by another agent.
    RouteTaken = 3,
}

impl Refusal {
    pub fn from_u8(v: u8) -> Option<Refusal> {
        match v {
            1 => Some(Refusal::RunFull),
            2 => Some(Refusal::NoSuchRoute),
            3 => Some(Refusal::RouteTaken),
            _ => None,
        }
    }
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Refusal::RunFull => "every route of the scenario is taken",
            Refusal::NoSuchRoute => "the scenario has no such route",
            Refusal::RouteTaken => "the route asked for is taken by another agent",
        })
    }
}

/// The broadcast of one barrier round.
///
/// The message has room for every trial and agent slot, but a round fills only the ones in
/// use, packed at the front: the trial headers side by side, then the views trial by trial.
/// What a run of 2 UAVs and 4 trials reads and writes each round is about 8 cache lines in
/// the first 1.4 KB, where a full block per trial spread it over 9 KB.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Observation")]
pub struct Observation {
    /// Barrier round, counting from 0; actions answer it by echoing it.
    pub round: u64,
    /// Bit i set: agent slot i is part of the barrier in this round.
    pub live: u64,
    /// [`ObservationKind`] as `u8`.
    pub kind: u8,
    /// [`Refusal`] as `u8`: why the request of `refused_nonce` was refused (0: none was).
    pub refusal: u8,
    pub _reserved: [u8; 2],
    /// Number of valid entries of `trials`.
    pub n_trials: u32,
    /// The `nonce` of a join request refused in this round (0: none); `refusal` says why.
    pub refused_nonce: u64,
    /// Agent slots of the run (one per route): valid entries of `owners`, and views per trial.
    pub n_slots: u32,
    pub _reserved_slots: u32,
    /// Per slot: the `nonce` of the join request of the agent that holds it (0: free). An
    /// agent finds its slot here, and learns here if the world has dropped it.
    pub owners: [u64; MAX_AGENTS],
    pub trials: [TrialHeader; MAX_TRIALS],
    /// Trial k's view of slot i is `views[k * n_slots + i]` (see [`Observation::trial`]).
    pub views: [AgentView; MAX_TRIALS * MAX_AGENTS],
}

impl Default for Observation {
    fn default() -> Self {
        Observation {
            round: 0,
            live: 0,
            kind: ObservationKind::Tick as u8,
            refusal: 0,
            _reserved: [0; 2],
            n_trials: 0,
            refused_nonce: 0,
            n_slots: 0,
            _reserved_slots: 0,
            owners: [0; MAX_AGENTS],
            trials: [TrialHeader::default(); MAX_TRIALS],
            views: [AgentView::default(); MAX_TRIALS * MAX_AGENTS],
        }
    }
}

impl Observation {
    pub fn kind(&self) -> Option<ObservationKind> {
        match self.kind {
            0 => Some(ObservationKind::Tick),
            1 => Some(ObservationKind::Stop),
            _ => None,
        }
    }

    /// Slots in use, as far as the message can hold them (a reader checks `n_slots` against
    /// what it expects; this never indexes past the arrays).
    #[inline]
    fn slots(&self) -> usize {
        (self.n_slots as usize).min(MAX_AGENTS)
    }

    /// The owners of the slots in use.
    pub fn slot_owners(&self) -> &[u64] {
        &self.owners[..self.slots()]
    }

    /// Trial `trial`'s header and views.
    ///
    /// # Panics
    /// If `trial >= MAX_TRIALS` (a reader's own trial count, never a received one).
    #[inline]
    pub fn trial(&self, trial: usize) -> TrialObservation<'_> {
        let n = self.slots();
        TrialObservation { header: &self.trials[trial], agents: &self.views[trial * n..][..n] }
    }

    /// Starts loading the parts a reader of this round will touch (the header, the owners,
    /// the trials and views in use), written on the world's core: see `proto/src/prefetch.rs`.
    #[inline]
    pub fn prefetch_used(&self) {
        let (trials, slots) = ((self.n_trials as usize).min(MAX_TRIALS), self.slots());
        crate::prefetch::prefetch(std::slice::from_ref(&self.round));
        crate::prefetch::prefetch(&self.owners[..slots]);
        crate::prefetch::prefetch(&self.trials[..trials]);
        crate::prefetch::prefetch(&self.views[..trials * slots]);
    }

    /// Sets the round's shape and hands out each trial's header and views, to be written.
    ///
    /// # Panics
    /// If `n_trials > MAX_TRIALS` or `n_slots > MAX_AGENTS` (the world's own counts).
    #[inline]
    pub fn shape_mut(
        &mut self,
        n_trials: usize,
        n_slots: usize,
    ) -> impl Iterator<Item = (&mut TrialHeader, &mut [AgentView])> {
        assert!(n_trials <= MAX_TRIALS && n_slots <= MAX_AGENTS, "observation shape too big");
        self.n_trials = n_trials as u32;
        self.n_slots = n_slots as u32;
        let views =
            self.views.chunks_exact_mut(n_slots.max(1)).map(move |chunk| &mut chunk[..n_slots]);
        self.trials[..n_trials].iter_mut().zip(views)
    }
}

/// Longest scenario (name, `gen:` spec or path) a run can hand on to attaching agents.
pub const SCENARIO_BYTES: usize = 512;

/// What an agent needs to know to attach to a running run; published once by the world with
/// history, so an agent that attaches later reads it.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::RunInfo")]
pub struct RunInfo {
    /// The scenario as given to the world (`s3`, a path, `gen:...`), UTF-8, NUL-padded.
    pub scenario: [u8; SCENARIO_BYTES],
    pub seed: u64,
    pub trials: u32,
    /// Communication mode name, UTF-8, NUL-padded (`none`, `flags`, ...).
    pub comm: [u8; 16],
    pub alpha: f64,
    pub gamma: f64,
    pub epsilon: f64,
}

impl RunInfo {
    /// Packs `text` into a NUL-padded field; `None` if it does not fit.
    pub fn pack<const N: usize>(text: &str) -> Option<[u8; N]> {
        let bytes = text.as_bytes();
        if bytes.len() > N || bytes.contains(&0) {
            return None;
        }
        let mut field = [0u8; N];
        field[..bytes.len()].copy_from_slice(bytes);
        Some(field)
    }

    /// The text of a NUL-padded field; an error names the field if it is not UTF-8.
    pub fn unpack(field: &[u8], name: &'static str) -> Result<String, crate::FieldError> {
        let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
        std::str::from_utf8(&field[..end]).map(str::to_string).map_err(|_| crate::FieldError {
            field: name,
            value: 0,
            expected: "UTF-8 text".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trials_and_slots_in_use_are_packed_at_the_front() {
        let mut observation = Box::<Observation>::default();
        for (k, (header, views)) in observation.shape_mut(3, 2).enumerate() {
            header.episode = k as u64;
            for (slot, view) in views.iter_mut().enumerate() {
                view.pose.waypoint = (10 * k + slot) as u16;
            }
        }
        assert_eq!((observation.n_trials, observation.n_slots), (3, 2));
        let waypoints: Vec<u16> = observation.views[..6].iter().map(|v| v.pose.waypoint).collect();
        assert_eq!(waypoints, [0, 1, 10, 11, 20, 21], "trial by trial, n_slots each");
        let trial = observation.trial(2);
        assert_eq!(trial.header.episode, 2);
        assert_eq!(trial.agents.iter().map(|v| v.pose.waypoint).collect::<Vec<_>>(), [20, 21]);
        assert_eq!(observation.slot_owners().len(), 2);
    }

    #[test]
    fn a_received_slot_count_past_the_limit_never_indexes_past_the_arrays() {
        let mut observation = Box::<Observation>::default();
        observation.n_slots = 1000;
        assert_eq!(observation.slot_owners().len(), MAX_AGENTS);
        assert_eq!(observation.trial(MAX_TRIALS - 1).agents.len(), MAX_AGENTS);
    }
}
