//! What crosses flockstep's process boundaries.
//!
//! Every payload here is `#[repr(C)]`, `ZeroCopySend`, fixed-size and free of pointers, so
//! iceoryx2 can hand it from one process to another without copying or serialising. The
//! in-process runner uses the very same structs, which is what makes the two transports
//! produce byte-identical results. Files are named by direction: a reader knows at once who
//! sends what to whom.
//!
//! Values arriving from another process are untrusted: the raw `u8`/`u16` fields are checked
//! by the `validate`/`decode` helpers before use, so an out-of-range field is an error, not a
//! panic.

pub mod agent_to_world;
pub mod flags;
pub mod limits;
pub mod logging;
pub mod output;
pub mod pose;
mod prefetch;
pub mod seed;
pub mod services;
pub mod supervisor_to_world;
pub mod transport;
pub mod world_to_agent;
pub mod world_to_supervisor;

pub use agent_to_world::{Action, JoinRequest, TrialAction, ANY_SLOT};
pub use flags::Flags;
pub use limits::{low_bits, slots_in, MAX_AGENTS, MAX_COMMANDS, MAX_TRIALS};
pub use pose::{Command, Heading, Height, Pose};
pub use world_to_agent::{
    AgentView, Observation, ObservationKind, Phase, Refusal, RunInfo, TrialHeader,
    TrialObservation, SCENARIO_BYTES,
};
pub use world_to_supervisor::{EpisodeBatch, EpisodeReport, Membership, EPISODE_BATCH};

/// A field received from another process held a value outside its range.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldError {
    pub field: &'static str,
    pub value: u64,
    pub expected: String,
}

impl std::fmt::Display for FieldError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "field `{}` = {} out of range (expected {})",
            self.field, self.value, self.expected
        )
    }
}

impl std::error::Error for FieldError {}

/// Checks `value < bound` for a field named `field`. Inlined: it guards every field of
/// every message, so only the failure may cost a call.
#[inline]
pub fn check_below(field: &'static str, value: u64, bound: u64) -> Result<(), FieldError> {
    if value < bound {
        Ok(())
    } else {
        Err(out_of_range(field, value, bound))
    }
}

#[cold]
fn out_of_range(field: &'static str, value: u64, bound: u64) -> FieldError {
    FieldError { field, value, expected: format!("< {bound}") }
}
