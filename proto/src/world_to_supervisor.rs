//! World -> supervisor: one record per finished episode of one trial.

use crate::limits::MAX_AGENTS;
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
    /// Bit i set: agent slot i is in the barrier when the episode ends (joins and losses
    /// show up here).
    pub live: u64,
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
            live: 0,
            lengths: [0; MAX_AGENTS],
        }
    }
}
