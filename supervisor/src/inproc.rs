//! The in-process transport: the world and every agent in this process, one barrier round
//! after the other. The performance reference, and the twin the multi-process run must
//! match byte for byte: it calls the same `World` and `UavAgent` code with the same messages.

use crate::config::RunConfig;
use crate::interrupt::Interrupts;
use crate::recorder::Recorder;
use anyhow::{Context, Result};
use flockstep_agents::agent::UavAgent;
use flockstep_agents::snapshot::{restore_snapshots, write_snapshots};
use flockstep_proto::{Action, EpisodeReport, Observation, ObservationKind};
use flockstep_world::sim::World;

/// Rounds between looks at the progress display. A look reads the clock (about 27 ns here),
/// a tenth of a 1-trial round.
const REDRAW_EVERY_ROUNDS: u64 = 1024;

/// The world, its agents and the messages between them, in one process. A barrier round is
/// [`Simulation::act`] then [`Simulation::step`]; `benches/round.rs` times exactly these.
pub struct Simulation {
    world: World,
    agents: Vec<UavAgent>,
    observation: Box<Observation>,
    actions: Vec<Action>,
    reports: Vec<EpisodeReport>,
}

impl Simulation {
    /// A fresh world and agents for `config` (untrained; see [`run`] for `--resume`).
    pub fn new(config: &RunConfig) -> Result<Simulation> {
        let world = World::new(
            config.scenario.clone(),
            config.uavs,
            config.trials,
            config.seed,
            config.episodes,
        )?;
        let agents = (0..config.uavs)
            .map(|slot| UavAgent::new(&config.agent_spec(slot)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Simulation {
            world,
            agents,
            observation: Box::default(),
            actions: (0..config.uavs).map(Action::new).collect(),
            reports: Vec::new(),
        })
    }

    /// The first half of a round: the world's broadcast and every agent's answer to it.
    /// Returns whether this was the stop round (every trial done; nothing more to step).
    pub fn act(&mut self) -> Result<bool> {
        self.world.observe(&mut self.observation);
        for (agent, action) in self.agents.iter_mut().zip(self.actions.iter_mut()) {
            agent
                .act(&self.observation, action)
                .with_context(|| format!("agent {}", agent.slot() + 1))?;
        }
        Ok(self.observation.kind == ObservationKind::Stop as u8)
    }

    /// The second half: the world applies the answers and ends the round. Returns the
    /// episodes that ended in it.
    pub fn step(&mut self) -> Result<std::vec::Drain<'_, EpisodeReport>> {
        for action in &self.actions {
            self.world.apply(action).context("world rejected an action")?;
        }
        self.world.end_round(&mut self.reports);
        Ok(self.reports.drain(..))
    }

    /// The round the last [`Simulation::act`] answered.
    pub fn round(&self) -> u64 {
        self.observation.round
    }
}

/// Runs the whole experiment; returns `true` if it ran to the end, `false` if stopped.
pub fn run(config: &RunConfig, recorder: &mut Recorder, stop: &Interrupts) -> Result<bool> {
    let mut simulation = Simulation::new(config)?;
    let tree = config.tree_text();
    if let Some(dir) = &config.resume {
        for agent in &mut simulation.agents {
            restore_snapshots(agent, dir, &config.learned(&tree))?;
        }
    }
    recorder.set_live(config.uavs);
    let finished = loop {
        if simulation.act()? {
            break true;
        }
        if stop.stop_asked() {
            break false;
        }
        let round = simulation.round();
        for report in simulation.step()? {
            recorder.record(&report)?;
        }
        if round % REDRAW_EVERY_ROUNDS == 0 {
            recorder.redraw();
        }
    };
    // The episodes of the rounds since the last look: the bar shows where the run ended.
    recorder.redraw();
    // Every agent's tables are written that can be; then a failure fails the run, as a lost
    // result (an agent process that cannot write its tables fails a multi-process run too).
    let mut unsaved = Vec::new();
    for agent in &simulation.agents {
        if let Err(e) = write_snapshots(agent, &config.out, &config.learned(&tree)) {
            unsaved.push(format!("UAV{}: {e:#}", agent.slot() + 1));
        }
    }
    anyhow::ensure!(unsaved.is_empty(), "final Q-tables not all saved: {}", unsaved.join("; "));
    Ok(finished)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::{Collector, EvalPlan};
    use clap::Parser;
    use flockstep_proto::Phase;

    /// The rounds after the last look at the progress still count: once the run has ended
    /// the bar shows every episode, drawn at once.
    #[test]
    fn the_bar_shows_every_episode_once_the_run_has_ended() {
        let dir = tempfile::tempdir().expect("a scratch directory");
        let out = dir.path().to_str().expect("a UTF-8 path");
        let setup = ["--transport", "inproc", "--scenario", "s1", "--uavs", "1", "--trials", "1"];
        let length = ["--episodes", "300", "--eval-episodes", "0", "--seed", "7", "--out", out];
        let flags = ["supervisor"].iter().chain(&setup).chain(&length);
        let cli = crate::cli::Cli::try_parse_from(flags).expect("valid flags");
        let config = RunConfig::resolve(&cli.run).expect("a valid run");
        let collector = Collector::create(dir.path(), 1, 1, EvalPlan::default()).unwrap();
        let (mut recorder, terminal) = Recorder::on_test_terminal(collector, 300, Phase::Train);

        let finished = run(&config, &mut recorder, &Interrupts::default()).expect("a run");

        assert!(finished, "the run was not stopped");
        let screen = terminal.contents();
        assert!(
            screen.contains("] 300/300 episodes  mean length "),
            "the bar does not show the run's last episode; the terminal shows:\n{screen}"
        );
    }
}
