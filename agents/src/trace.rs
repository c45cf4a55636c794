//! A test aid: the agent process's per-round trace (`agent run --trace FILE`), which lets a
//! test check lockstep from outside: which rounds each agent ticked, and what it knew of
//! its peers in each of them.
//!
//! CSV columns: `round,kind,trial,episode,episode_tick,member,sent_waypoint,sent_sees,comm`,
//! one line per round and trial; `kind` is `tick` or `stop`; `member` is 1 if the world
//! counts the agent in the trial's episode (an agent that attached joins at the next
//! episode start); `comm` is the agent's communication words after taking in the round's
//! relayed flags, as hex, `-`-separated (empty in mode `none`).

use crate::agent::UavAgent;
use anyhow::{Context, Result};
use flockstep_proto::{Action, Observation, ObservationKind};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

pub struct Trace {
    file: BufWriter<File>,
}

impl Trace {
    pub fn create(path: &Path) -> Result<Trace> {
        let file = File::create(path)
            .with_context(|| format!("cannot create trace {}", path.display()))?;
        let mut file = BufWriter::new(file);
        writeln!(
            file,
            "round,kind,trial,episode,episode_tick,member,sent_waypoint,sent_sees,comm"
        )?;
        Ok(Trace { file })
    }

    pub fn record(
        &mut self,
        observation: &Observation,
        action: &Action,
        agent: &UavAgent,
    ) -> Result<()> {
        let kind = if observation.kind == ObservationKind::Stop as u8 { "stop" } else { "tick" };
        for (k, part) in agent.trials().iter().enumerate() {
            let trial = observation.trial(k);
            let flags = &action.trials[k].flags;
            let comm: Vec<String> = part.comm().words().iter().map(|w| format!("{w:x}")).collect();
            writeln!(
                self.file,
                "{},{kind},{k},{},{},{},{},{},{}",
                observation.round,
                trial.header.episode,
                trial.header.episode_tick,
                trial.agents[agent.slot()].member,
                flags.waypoint,
                flags.sees_target,
                comm.join("-")
            )?;
        }
        if kind == "stop" {
            self.file.flush()?;
        }
        Ok(())
    }
}
