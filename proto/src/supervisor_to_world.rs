//! Supervisor -> world: run control.

use iceoryx2::prelude::ZeroCopySend;

/// What the supervisor tells the world about the run. Each message holds everything said so
/// far, so a message lost to a full buffer loses nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Control")]
pub struct Control {
    /// 1 = stop at the end of the current round (Ctrl-C, operator request; results so far
    /// are kept and flagged partial).
    pub stop: u8,
    pub _reserved: [u8; 7],
    /// Bit i set: the process started for agent slot i has ended and will not be started
    /// again. The world learns of an agent's death from its process id once it has joined;
    /// this is for one that dies before it asked to join: the world, waiting for the
    /// starting agents, stops waiting for it (and ignores the mask after start-up).
    pub gone: u64,
}
