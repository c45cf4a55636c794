//! The agent process (`agent run`): one UAV of a multi-process run.
//!
//! Each round it reads the world's observation in place in shared memory, ticks its tree
//! for every trial through [`UavAgent::act`] (the very code the in-process runner calls) and
//! publishes its action. On the stop round it closes its episodes, writes its Q-table
//! snapshots and answers once more, so the world knows they are on disk.

use crate::agent::{AgentSpec, UavAgent};
use crate::bt::parse::parse_tree;
use crate::bt::render::to_text;
use crate::comm::CommMode;
use crate::learning::LearnParams;
use crate::snapshot::write_snapshots;
use crate::trace::Trace;
use crate::uav::UavCatalog;
use anyhow::{Context, Result};
use clap::Args;
use flockstep_proto::transport::{exit_with_parent, RunConfig, RunServices, SignalMode};
use flockstep_proto::{Action, ObservationKind};
use flockstep_world::Scenario;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// Arguments of `agent run` (the supervisor passes them all explicitly).
#[derive(Debug, Clone, Args)]
pub struct NodeArgs {
    #[arg(long)]
    pub run_id: String,
    /// Agent slot, 1-based (UAV1 flies route 1).
    #[arg(long)]
    pub uav: usize,
    /// s1, s2, s3 or a path to a .map file.
    #[arg(long)]
    pub scenario: String,
    #[arg(long)]
    pub trials: usize,
    #[arg(long)]
    pub seed: u64,
    /// none or flags.
    #[arg(long)]
    pub comm: String,
    /// Behavior tree file [default: the thesis's Fig. 5 tree].
    #[arg(long)]
    pub bt: Option<PathBuf>,
    #[arg(long)]
    pub alpha: f64,
    #[arg(long)]
    pub gamma: f64,
    #[arg(long)]
    pub epsilon: f64,
    /// Results directory: snapshots go to `<out>/qtables/`.
    #[arg(long)]
    pub out: PathBuf,
    /// The world silent this long is presumed dead.
    #[arg(long, default_value_t = 30_000)]
    pub world_timeout_ms: u64,
    /// Exit when this process (the supervisor) is gone.
    #[arg(long)]
    pub parent_pid: Option<u32>,
    /// Test aid: append one line per round and trial to this CSV file (see `trace.rs`).
    #[arg(long)]
    pub trace: Option<PathBuf>,
}

pub fn run(args: &NodeArgs) -> Result<()> {
    let run = RunConfig::new(&args.run_id, SignalMode::Supervised);
    if let Some(parent) = args.parent_pid {
        exit_with_parent(parent)?;
    }
    let scenario =
        Arc::new(Scenario::resolve(&args.scenario).map_err(|e| anyhow::anyhow!("scenario: {e}"))?);
    let comm = CommMode::parse(&args.comm)
        .with_context(|| format!("--comm `{}`: expected none or flags", args.comm))?;
    let tree = match &args.bt {
        None => parse_tree("fig5.bt", crate::FIG5_TREE, &UavCatalog)?,
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read tree file {}", path.display()))?;
            parse_tree(&path.display().to_string(), &text, &UavCatalog)?
        }
    };
    let tree_text = to_text(&tree);
    let slot = args.uav.checked_sub(1).context("--uav counts from 1")?;
    let spec = AgentSpec {
        slot,
        scenario: scenario.clone(),
        tree,
        comm,
        params: LearnParams {
            alpha: args.alpha,
            gamma: args.gamma,
            epsilon: args.epsilon,
            learn: true,
        },
        seed: args.seed,
        trials: args.trials,
    };
    let mut agent = UavAgent::new(&spec)?;
    let ports = RunServices::open(&run)?.into_agent()?;
    let mut action = Box::new(Action::new(slot));
    let world_timeout = Duration::from_millis(args.world_timeout_ms);
    let mut trace = args.trace.as_deref().map(Trace::create).transpose()?;
    let mut next_round = 0u64;
    loop {
        let observation = ports.waiter().wait(
            &format_args!("the observation of round {next_round}"),
            world_timeout,
            || {
                while let Some(sample) = ports.try_observation()? {
                    if sample.round >= next_round {
                        return Ok(Some(sample));
                    }
                }
                Ok(None)
            },
        )?;
        next_round = observation.round + 1;
        if !observation.is_live(slot) {
            continue;
        }
        agent
            .act(&observation, &mut action)
            .with_context(|| format!("round {}", observation.round))?;
        if let Some(trace) = trace.as_mut() {
            trace.record(&observation, &action, &agent)?;
        }
        if observation.kind == ObservationKind::Stop as u8 {
            write_snapshots(&agent, &args.out, scenario.name(), comm, &tree_text)?;
            ports.publish_action(&action)?;
            return Ok(());
        }
        ports.publish_action(&action)?;
    }
}
