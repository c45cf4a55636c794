//! Behavior trees, the learning selector and the UAV agent.
//!
//! `bt` and `learning` do no I/O and know nothing of UAVs or iceoryx2: they are tested and
//! benchmarked in-process, and the same code runs inside the agent processes.

pub mod agent;
pub mod bt;
pub mod cli;
pub mod comm;
pub mod learning;
pub mod node;
pub mod snapshot;
pub mod state;
pub mod trace;
pub mod uav;

/// The thesis's tree (Fig. 5), the default of every run.
pub const FIG5_TREE: &str = include_str!("../trees/fig5.bt");
