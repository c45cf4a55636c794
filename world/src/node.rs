//! The `world` process: owns a run's services, the barrier and the ground truth.
//!
//! Each round it publishes the observation of every trial, waits until every live agent has
//! answered that round (each wait bounded: an agent silent past `--agent-timeout-ms` is
//! presumed dead), applies the actions, and hands finished episodes to the supervisor. It is
//! the same [`World`] the in-process runner drives; only the message passing differs.

use crate::scenario::Scenario;
use crate::sim::{EpisodeConfig, World};
use anyhow::{bail, Result};
use clap::Parser;
use flockstep_proto::transport::{
    exit_with_parent, RunConfig, RunServices, SignalMode, WorldPorts,
};
use flockstep_proto::{Observation, ObservationKind, MAX_AGENTS};
use std::sync::Arc;
use std::time::Duration;

/// The world process of a run (started by the supervisor).
#[derive(Debug, Clone, Parser)]
#[command(
    name = "world",
    version,
    about = "The world process of a flockstep run (started by the supervisor)"
)]
pub struct WorldArgs {
    #[arg(long)]
    pub run_id: String,
    /// s1, s2, s3 or a path to a .map file.
    #[arg(long)]
    pub scenario: String,
    #[arg(long)]
    pub uavs: usize,
    #[arg(long)]
    pub trials: usize,
    #[arg(long)]
    pub seed: u64,
    #[arg(long)]
    pub episodes: u64,
    #[arg(long)]
    pub eval_episodes: u64,
    #[arg(long)]
    pub tick_cap: u32,
    /// An agent silent this long within a round is presumed dead.
    #[arg(long, default_value_t = 2000)]
    pub agent_timeout_ms: u64,
    /// How long to wait for every agent and the supervisor to connect.
    #[arg(long, default_value_t = 30_000)]
    pub startup_timeout_ms: u64,
    /// Exit when this process (the supervisor) is gone.
    #[arg(long)]
    pub parent_pid: Option<u32>,
}

/// The `world` binary.
pub fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("FLOCKSTEP_LOG")
                .unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match run(&WorldArgs::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("world: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

pub fn run(args: &WorldArgs) -> Result<()> {
    let run = RunConfig::new(&args.run_id, SignalMode::Supervised);
    if let Some(parent) = args.parent_pid {
        exit_with_parent(parent)?;
    }
    let scenario =
        Scenario::resolve(&args.scenario).map_err(|e| anyhow::anyhow!("scenario: {e}"))?;
    let config = EpisodeConfig {
        train_episodes: args.episodes,
        eval_episodes: args.eval_episodes,
        tick_cap: args.tick_cap,
    };
    let mut world = World::new(Arc::new(scenario), args.uavs, args.trials, args.seed, config)?;
    let ports = RunServices::create(&run)?.into_world()?;
    ports.wait_for_peers(args.uavs, true, Duration::from_millis(args.startup_timeout_ms))?;
    barrier(&mut world, &ports, Duration::from_millis(args.agent_timeout_ms))
}

/// Runs rounds until every trial is done or the supervisor asks to stop, then tells the
/// agents to stop and waits for each one's last answer (its snapshots are written then).
fn barrier(world: &mut World, ports: &WorldPorts, agent_timeout: Duration) -> Result<()> {
    let mut observation = Box::<Observation>::default();
    let mut reports = Vec::new();
    let mut stop_requested = false;
    loop {
        world.observe(&mut observation);
        if stop_requested {
            observation.kind = ObservationKind::Stop as u8;
        }
        ports.publish_observation(&observation)?;
        let stopping = observation.kind == ObservationKind::Stop as u8;
        // The agents' last answer comes after their snapshots: allow for writing them.
        let timeout =
            if stopping { agent_timeout.max(Duration::from_secs(30)) } else { agent_timeout };
        collect_actions(world, ports, &observation, timeout, &mut stop_requested, !stopping)?;
        if stopping {
            return Ok(());
        }
        world.end_round(&mut reports);
        for report in reports.drain(..) {
            ports.publish_episode(&report)?;
        }
    }
}

/// Waits for the answer of every live agent to `observation`'s round and applies them
/// (unless `apply` is false: the answers to a stop). Answers to other rounds, from slots
/// not in the barrier, or that fail the checks are logged and dropped.
fn collect_actions(
    world: &mut World,
    ports: &WorldPorts,
    observation: &Observation,
    timeout: Duration,
    stop_requested: &mut bool,
    apply: bool,
) -> Result<()> {
    let round = observation.round;
    let live = observation.live;
    let mut answered = 0u64;
    let waited =
        ports.waiter().wait(&format_args!("the answers of round {round}"), timeout, || {
            while let Some(action) = ports.try_action()? {
                let slot = action.agent as usize;
                if action.round != round || slot >= MAX_AGENTS || live & (1 << slot) == 0 {
                    tracing::warn!(
                        round,
                        action.round,
                        action.agent,
                        "dropped an action that does not answer this round"
                    );
                    continue;
                }
                if answered & (1 << slot) != 0 {
                    tracing::warn!(
                        round,
                        agent = slot + 1,
                        "dropped a second action of one agent in one round"
                    );
                    continue;
                }
                if apply {
                    if let Err(e) = world.apply(&action) {
                        tracing::warn!(round, agent = slot + 1, "dropped an invalid action: {e}");
                        continue;
                    }
                }
                answered |= 1 << slot;
            }
            while let Some(control) = ports.try_control()? {
                *stop_requested |= control.stop == 1;
            }
            Ok((answered == live).then_some(()))
        });
    if let Err(e) = waited {
        let silent: Vec<String> = (0..MAX_AGENTS)
            .filter(|&slot| live & !answered & (1 << slot) != 0)
            .map(|slot| format!("UAV{}", slot + 1))
            .collect();
        bail!("{e}; silent: {} (presumed dead)", silent.join(", "));
    }
    Ok(())
}
