//! The multi-process transport (written next).
use crate::config::RunConfig;
use crate::recorder::Recorder;
use crate::run::Outcome;
use std::sync::atomic::AtomicBool;

/// Runs the experiment as one world and N agent processes.
pub fn run(_config: &RunConfig, _recorder: &mut Recorder, _stop: &AtomicBool) -> anyhow::Result<Outcome> {
    anyhow::bail!("--transport shm is not built yet")
}
