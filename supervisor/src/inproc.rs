//! The in-process transport: the world and every agent in this process, one barrier round
//! after the other. The performance reference, and the twin the multi-process run must
//! match byte for byte: it calls the same `World` and `UavAgent` code with the same messages.

use crate::config::RunConfig;
use crate::recorder::Recorder;
use anyhow::{Context, Result};
use flockstep_agents::agent::UavAgent;
use flockstep_agents::snapshot::{restore_snapshots, write_snapshots};
use flockstep_proto::{Action, Observation, ObservationKind};
use flockstep_world::sim::World;
use std::sync::atomic::{AtomicBool, Ordering};

/// Rounds between looks at the progress display. A look reads the clock (about 27 ns here),
/// a tenth of a 1-trial round.
const REDRAW_EVERY_ROUNDS: u64 = 1024;

/// Runs the whole experiment; returns `true` if it ran to the end, `false` if stopped.
pub fn run(config: &RunConfig, recorder: &mut Recorder, stop: &AtomicBool) -> Result<bool> {
    let mut world = World::new(
        config.scenario.clone(),
        config.uavs,
        config.trials,
        config.seed,
        config.episodes,
    )?;
    let mut agents = (0..config.uavs)
        .map(|slot| UavAgent::new(&config.agent_spec(slot)))
        .collect::<Result<Vec<_>, _>>()?;
    let tree = config.tree_text();
    if let Some(dir) = &config.resume {
        for agent in &mut agents {
            restore_snapshots(agent, dir, config.scenario.name(), config.comm, &tree)?;
        }
    }
    let mut observation = Box::<Observation>::default();
    let mut actions: Vec<Box<Action>> =
        (0..config.uavs).map(|slot| Box::new(Action::new(slot))).collect();
    let mut reports = Vec::new();
    recorder.set_live(config.uavs);
    let finished = loop {
        world.observe(&mut observation);
        for (agent, action) in agents.iter_mut().zip(actions.iter_mut()) {
            agent
                .act(&observation, action)
                .with_context(|| format!("agent {}", agent.slot() + 1))?;
        }
        if observation.kind == ObservationKind::Stop as u8 {
            break true;
        }
        if stop.load(Ordering::Relaxed) {
            break false;
        }
        for action in &actions {
            world.apply(action).context("world rejected an action")?;
        }
        world.end_round(&mut reports);
        for report in reports.drain(..) {
            recorder.record(&report)?;
        }
        if observation.round % REDRAW_EVERY_ROUNDS == 0 {
            recorder.redraw();
        }
    };
    for agent in &agents {
        write_snapshots(agent, &config.out, config.scenario.name(), config.comm, &tree)?;
    }
    Ok(finished)
}
