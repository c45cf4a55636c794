//! Integration tests: the real binaries, spawned as a user would run them.
//! Every test uses its own results directory and run id, so they run in parallel.

/// `agent --attach` refused by the world: the reason, at once.
mod attach;
/// `agent bt show` and `agent bt replay`.
mod bt_tools;
/// Bad flags and files: one clear line, a non-zero exit, nothing left behind.
mod cli_errors;
/// Same seed, same bytes; another seed, other bytes.
mod determinism;
/// Attach, dead agents, restarts, Ctrl-C, a killed world, a rogue publisher.
mod faults;
/// Spawns binaries and reports failures with the command, status, stdout and stderr.
mod harness;
/// The thesis's learning results in-process: optima reached, communication helps.
mod learning;
/// Real world and agent processes: equivalence, lockstep, isolation, clean shutdown.
mod shm;
/// Evaluating and resuming from Q-table snapshots.
mod snapshots;
/// The progress bar on a terminal.
mod terminal;
