//! The supervisor: runs experiments, in one process or as one world and N agent processes,
//! and turns what the world reports into a results directory.

// `summary.json` is one `json!` literal of some 50 fields, past the macro's recursion at the
// default limit of 128.
#![recursion_limit = "256"]

pub mod children;
pub mod cli;
pub mod config;
pub mod curve;
pub mod inproc;
pub mod interrupt;
pub mod out_lock;
pub mod plot;
pub mod recorder;
pub mod reproduce;
pub mod results;
pub mod run;
pub mod shm;
pub mod summary;
pub mod suspend;

use anyhow::Result;
use cli::{Cli, Command};
use flockstep_proto::output;
use interrupt::Interrupts;

/// First argument that makes the supervisor's executable the world or an agent.
pub const ROLE_WORLD: &str = "world";
pub const ROLE_AGENT: &str = "agent";

/// Exit status of a run or an evaluation stopped by Ctrl-C / SIGTERM (results written,
/// flagged partial).
pub const EXIT_INTERRUPTED: i32 = 130;

/// The `supervisor` binary. It is also the world and the agent programs (`supervisor world
/// ...`, `supervisor agent ...`): it starts its children from its own executable, so
/// building the supervisor alone (`cargo run --bin supervisor`) is enough to run.
pub fn main() -> std::process::ExitCode {
    let mut args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    match args.get(1).and_then(|a| a.to_str()) {
        Some(ROLE_WORLD) => return flockstep_world::node::main(args.drain(1..)),
        Some(ROLE_AGENT) => return flockstep_agents::cli::main(args.drain(1..)),
        _ => {}
    }
    flockstep_proto::logging::init("warn");
    let outcome =
        Cli::parse_noting_run_flags(args).and_then(|(cli, run_flags)| dispatch(cli, &run_flags));
    match outcome {
        Ok(code) => std::process::ExitCode::from(code),
        Err(e) => {
            output::message(&format!("supervisor: error: {e:#}"));
            std::process::ExitCode::from(1)
        }
    }
}

/// Runs what the command line asks for; `run_flags` are the run flags it gave.
fn dispatch(cli: Cli, run_flags: &[String]) -> Result<u8> {
    if let Some(command) = &cli.command {
        command.refuse_ignored_run_flags(run_flags)?;
    }
    match cli.command {
        Some(Command::Optimum { scenario }) => commands::optimum(&scenario).map(|()| 0),
        Some(Command::Plot { curves, out, title }) => {
            commands::plot(&curves, &out, &title).map(|()| 0)
        }
        Some(Command::Eval { qtables, episodes, out, transport, overwrite }) => {
            let stop = Interrupts::catch()?;
            let defaults = cli::RunArgs { overwrite, ..cli.run };
            let complete = commands::eval(&qtables, episodes, out, transport, &defaults, &stop)?;
            Ok(if complete { 0 } else { EXIT_INTERRUPTED as u8 })
        }
        Some(Command::Generate { spec, out }) => commands::generate(&spec, &out).map(|()| 0),
        Some(Command::Reproduce { figure, out, episodes, trials, seed, transport, overwrite }) => {
            let stop = Interrupts::catch()?;
            let base = cli::RunArgs { episodes, trials, seed, transport, overwrite, ..cli.run };
            let complete = reproduce::reproduce(figure, out, &base, &stop)?;
            Ok(if complete { 0 } else { EXIT_INTERRUPTED as u8 })
        }
        None => {
            let config = config::RunConfig::resolve(&cli.run)?;
            let stop = Interrupts::catch()?;
            let outcome = run::run_experiment(&config, &stop)?;
            if !config.quiet {
                let summary = summary::summary_file(&config.out)?;
                for line in summary::closing_lines(&summary) {
                    output::message(&format!("supervisor: {line}"));
                }
            }
            output::line(&config.out.join("summary.json").display().to_string())?;
            Ok(if outcome.complete { 0 } else { EXIT_INTERRUPTED as u8 })
        }
    }
}

mod commands;
