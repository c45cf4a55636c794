//! The `agent` binary: one UAV process of a run (`agent run ...`, started by the
//! supervisor), and the behavior-tree inspection tools (`agent bt show`, `agent bt replay`).

use crate::bt::parse::parse_tree;
use crate::bt::render::render_ascii;
use crate::bt::replay::{replay, OpenCatalog};
use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};

#[derive(Debug, Parser)]
#[command(
    name = "agent",
    version,
    about = "A flockstep UAV agent, and tools to inspect behavior trees"
)]
#[command(args_conflicts_with_subcommands = true)]
struct Cli {
    /// Attach to the running simulation RUN_ID: the world admits this agent on a free route
    /// at the next episode start of each trial.
    #[arg(long, value_name = "RUN_ID")]
    attach: Option<String>,
    #[command(flatten)]
    attach_args: crate::node::AttachArgs,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Behavior-tree tools.
    Bt {
        #[command(subcommand)]
        command: BtCommand,
    },
    /// Run as UAV agent of a simulation (started by the supervisor).
    Run(Box<crate::node::NodeArgs>),
}

#[derive(Debug, Subcommand)]
enum BtCommand {
    /// Print a tree file as an ASCII drawing (any leaf names are accepted).
    Show { tree: PathBuf },
    /// Tick a tree against scripted leaf results; print per tick the root status and the
    /// leaves ticked and halted.
    Replay {
        tree: PathBuf,
        script: PathBuf,
        /// Seed of the learning selectors' tie-breaking.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
}

/// The `agent` program: `args` are its command line (program name first).
pub fn main(args: impl IntoIterator<Item = std::ffi::OsString>) -> std::process::ExitCode {
    flockstep_proto::logging::init("warn");
    let cli = Cli::parse_from(args);
    let result = match (cli.command, cli.attach) {
        (Some(Command::Bt { command: BtCommand::Show { tree } }), _) => show(&tree),
        (Some(Command::Bt { command: BtCommand::Replay { tree, script, seed } }), _) => {
            replay_files(&tree, &script, seed)
        }
        (Some(Command::Run(args)), _) => crate::node::run(&args),
        (None, Some(run_id)) => crate::node::attach(&run_id, &cli.attach_args),
        (None, None) => {
            Err(anyhow::anyhow!("nothing to do: give --attach RUN_ID or a subcommand (see --help)"))
        }
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            flockstep_proto::output::message(&format!("agent: error: {e:#}"));
            if crate::node::world_gone(&e) {
                std::process::ExitCode::from(crate::node::EXIT_WORLD_GONE)
            } else {
                std::process::ExitCode::FAILURE
            }
        }
    }
}

/// Reads a tree or script file, at most [`flockstep_world::map::MAX_INPUT_BYTES`] of it.
fn read(path: &Path) -> Result<String> {
    flockstep_world::map::read_input(path)
        .with_context(|| format!("cannot read {}", path.display()))
}

fn show(path: &Path) -> Result<()> {
    let tree = parse_tree(&path.display().to_string(), &read(path)?, &OpenCatalog::default())?;
    Ok(flockstep_proto::output::text(&render_ascii(&tree))?)
}

fn replay_files(tree_path: &Path, script_path: &Path, seed: u64) -> Result<()> {
    let catalog = OpenCatalog::default();
    let tree = parse_tree(&tree_path.display().to_string(), &read(tree_path)?, &catalog)?;
    let report =
        replay(&tree, &catalog, &script_path.display().to_string(), &read(script_path)?, seed)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(flockstep_proto::output::text(&report.to_string())?)
}
