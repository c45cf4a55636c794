//! The inter-UAV message (SPEC section 3).
//!
//! Design: flags travel inside the agent's [`crate::Action`] for tick t and the world relays
//! them to every agent in the [`crate::Observation`] of tick t+1. The world is the one
//! sequencer of the run, so relaying through it makes "sent at t, in the receiver's state at
//! t+1" hold by construction, adds no service and no wait (the world waits for the actions
//! anyway), and costs one broadcast instead of N x N agent-to-agent connections.

use iceoryx2::prelude::ZeroCopySend;

/// What one UAV tells the others in one tick of one trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Flags")]
pub struct Flags {
    /// 1 if this message carries information (the sender was live and sent it).
    pub valid: u8,
    /// 1 if the sender saw the target from `waypoint` at the start of the tick.
    pub sees_target: u8,
    /// The sender's waypoint index (0-based) when it looked.
    pub waypoint: u16,
    pub _reserved: u32,
    /// Compact mode: candidate target cells the sender has ruled out (bit k = candidate k).
    pub ruled_out: u64,
    /// Compact mode: candidate target cells the sender has confirmed.
    pub confirmed: u64,
}
