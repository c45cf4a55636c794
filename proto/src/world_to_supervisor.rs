//! World -> supervisor: one record per finished episode of one trial, sent in batches, and
//! with each batch the barrier's membership.
//!
//! At 4 trials an episode ends in about one round in four; one sample per record cost the
//! world a loan and a send in each of those rounds, and the supervisor a receive per record.
//! The world gathers records in an [`EpisodeBatch`] and sends it when it is full, once per
//! millisecond, and when its rounds end; and at once, records or not, when an agent joins or
//! is dropped, so the supervisor sees every change of [`Membership`] in order: which of its
//! processes the world admitted, and which it dropped while they still run (hung).

use crate::limits::MAX_AGENTS;
use crate::FieldError;
use iceoryx2::prelude::ZeroCopySend;

/// The lengths of every agent in one finished episode of one trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::EpisodeReport")]
pub struct EpisodeReport {
    pub trial: u32,
    /// Index of the candidate target cell drawn for this episode.
    pub target: u16,
    /// [`crate::Phase`] of the episode: training or greedy evaluation.
    pub phase: u8,
    pub _reserved: u8,
    pub episode: u64,
    /// The trial's clock when the episode started.
    pub start_tick: u64,
    /// Bit i set: agent slot i took part in this episode.
    pub members: u64,
    /// Bit i set: agent slot i did not finish before the tick cap.
    pub truncated: u64,
    /// Ticks up to and including the agent's `A-endEpisode` (the cap if truncated).
    pub lengths: [u32; MAX_AGENTS],
}

impl Default for EpisodeReport {
    fn default() -> Self {
        EpisodeReport {
            trial: 0,
            target: 0,
            phase: 0,
            _reserved: 0,
            episode: 0,
            start_tick: 0,
            members: 0,
            truncated: 0,
            lengths: [0; MAX_AGENTS],
        }
    }
}

/// Which agent process holds each slot of the barrier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Membership")]
pub struct Membership {
    /// Bit i set: agent slot i is in the barrier.
    pub live: u64,
    /// The process id of slot i's agent while it is live (0 if the world could not tell).
    pub pids: [u32; MAX_AGENTS],
}

impl Default for Membership {
    fn default() -> Self {
        Membership { live: 0, pids: [0; MAX_AGENTS] }
    }
}

impl Membership {
    /// Whether process `pid` holds `slot` in the barrier.
    pub fn holds(&self, slot: usize, pid: u32) -> bool {
        slot < MAX_AGENTS && self.live >> slot & 1 == 1 && self.pids[slot] == pid && pid != 0
    }

    /// Agents in the barrier.
    pub fn count(&self) -> usize {
        self.live.count_ones() as usize
    }
}

/// Records one [`EpisodeBatch`] holds.
pub const EPISODE_BATCH: usize = 64;

/// Up to [`EPISODE_BATCH`] records, in the order the episodes ended, and the membership
/// when the batch was sent (after those episodes ended).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::EpisodeBatch")]
pub struct EpisodeBatch {
    /// Records in use, at the front of `reports`.
    pub count: u32,
    pub _reserved: u32,
    pub membership: Membership,
    pub reports: [EpisodeReport; EPISODE_BATCH],
}

impl Default for EpisodeBatch {
    fn default() -> Self {
        EpisodeBatch {
            count: 0,
            _reserved: 0,
            membership: Membership::default(),
            reports: [EpisodeReport::default(); EPISODE_BATCH],
        }
    }
}

impl EpisodeBatch {
    /// The records in use; a count past the capacity (from another process) is refused.
    pub fn reports(&self) -> Result<&[EpisodeReport], FieldError> {
        crate::check_below("episode_batch.count", self.count.into(), EPISODE_BATCH as u64 + 1)?;
        Ok(&self.reports[..self.count as usize])
    }

    /// Adds a record; false if the batch is full.
    pub fn push(&mut self, report: &EpisodeReport) -> bool {
        let Some(slot) = self.reports.get_mut(self.count as usize) else { return false };
        *slot = *report;
        self.count += 1;
        true
    }

    pub fn is_full(&self) -> bool {
        self.count as usize >= EPISODE_BATCH
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_fills_up_to_its_capacity_in_order() {
        let mut batch = EpisodeBatch::default();
        assert!(batch.is_empty());
        for episode in 0..EPISODE_BATCH as u64 {
            assert!(batch.push(&EpisodeReport { episode, ..EpisodeReport::default() }));
        }
        assert!(batch.is_full());
        assert!(!batch.push(&EpisodeReport::default()), "a full batch takes no more");
        let episodes: Vec<u64> = batch.reports().unwrap().iter().map(|r| r.episode).collect();
        assert_eq!(episodes, (0..EPISODE_BATCH as u64).collect::<Vec<_>>());
    }

    #[test]
    fn a_slot_is_held_by_the_process_named_while_it_is_live() {
        let mut membership = Membership { live: 0b101, ..Membership::default() };
        membership.pids[0] = 41;
        membership.pids[1] = 42;
        assert!(membership.holds(0, 41));
        assert!(!membership.holds(0, 42), "another process");
        assert!(!membership.holds(1, 42), "slot 1 is not live");
        assert!(!membership.holds(2, 0), "an unknown process holds nothing");
        assert!(!membership.holds(MAX_AGENTS, 41));
        assert_eq!(membership.count(), 2);
    }

    #[test]
    fn a_received_count_past_the_capacity_is_refused() {
        let batch = EpisodeBatch { count: EPISODE_BATCH as u32 + 1, ..EpisodeBatch::default() };
        let error = batch.reports().unwrap_err();
        assert_eq!(error.field, "episode_batch.count");
    }
}
