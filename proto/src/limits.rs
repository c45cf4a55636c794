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
