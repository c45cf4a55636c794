//! The supervisor's command line (clap derive).
//!
//! Without a subcommand it runs an experiment. Defaults follow the thesis: `--uavs 2` runs
//! scenario 3 with communication, `--uavs 1` scenario 2 without; `--scenario` picks any other
//! map (s1, s2, s3, s4, a generated `gen:...` one or a path).

use clap::error::{ContextKind, ContextValue, ErrorKind};
use clap::parser::ValueSource;
use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand, ValueEnum};
use std::ffi::OsString;
use std::path::PathBuf;

#[derive(Debug, Parser)]
#[command(
    name = "supervisor",
    version,
    about = "Run flockstep experiments: UAVs learning behavior trees in lockstep"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    #[command(flatten)]
    pub run: RunArgs,
}

impl Cli {
    /// Parses the command line as `Cli::parse_from` does, and also returns the run flags
    /// given on it (as typed, e.g. `--uavs`): a subcommand refuses those it would ignore
    /// ([`Command::refuse_ignored_run_flags`]). A run flag typed after a subcommand's name,
    /// which clap finds unknown there, is refused with where it belongs.
    pub fn parse_noting_run_flags(
        args: impl IntoIterator<Item = OsString>,
    ) -> anyhow::Result<(Cli, Vec<String>)> {
        let args: Vec<OsString> = args.into_iter().collect();
        let command = Cli::command();
        let matches = match command.clone().try_get_matches_from(&args) {
            Ok(matches) => matches,
            Err(error) => match run_flag_after_subcommand(&command, &args, &error) {
                Some(refusal) => return Err(refusal),
                None => error.exit(),
            },
        };
        let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
        let given = command
            .get_arguments()
            .filter(|arg| {
                matches.value_source(arg.get_id().as_str()) == Some(ValueSource::CommandLine)
            })
            .filter_map(|arg| arg.get_long().map(|long| format!("--{long}")))
            .collect();
        Ok((cli, given))
    }
}

/// If `error` is clap's "unexpected argument" for a run flag typed after a subcommand's
/// name (`supervisor reproduce fig10 --quiet`), the refusal that says where it belongs. The
/// subcommand is found by parsing again without the run flags typed after it.
fn run_flag_after_subcommand(
    command: &clap::Command,
    args: &[OsString],
    error: &clap::Error,
) -> Option<anyhow::Error> {
    let (mut rest, flag) = without_run_flag(command, args, error)?;
    loop {
        match Cli::try_parse_from(&rest) {
            Ok(cli) => return Some(cli.command?.misplaced_run_flag(&flag, Placed::After)),
            Err(next) => rest = without_run_flag(command, &rest, &next)?.0,
        }
    }
}

/// If `error` is clap's "unexpected argument" for one of the run flags of `command`: `args`
/// without that flag and its value, and the flag.
fn without_run_flag(
    command: &clap::Command,
    args: &[OsString],
    error: &clap::Error,
) -> Option<(Vec<OsString>, String)> {
    if error.kind() != ErrorKind::UnknownArgument {
        return None;
    }
    let Some(ContextValue::String(flag)) = error.get(ContextKind::InvalidArg) else {
        return None;
    };
    let run_arg = command
        .get_arguments()
        .find(|arg| arg.get_long().is_some_and(|long| flag.strip_prefix("--") == Some(long)))?;
    // Whether `arg` is the flag, as `--flag` (false) or as `--flag=value` (true).
    let typed_with_value = |arg: &OsString| {
        let arg = arg.to_str()?;
        if arg == flag {
            Some(false)
        } else {
            arg.strip_prefix(flag.as_str())?.starts_with('=').then_some(true)
        }
    };
    let (at, inline_value) =
        args.iter().enumerate().find_map(|(i, arg)| Some((i, typed_with_value(arg)?)))?;
    let len = 1 + usize::from(run_arg.get_action().takes_values() && !inline_value);
    let mut rest = args.to_vec();
    rest.drain(at..(at + len).min(args.len()));
    Some((rest, flag.clone()))
}

/// Where a run flag was typed, relative to a subcommand's name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Placed {
    Before,
    After,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Exact optimal expected episode length of a single memoryless UAV on a scenario.
    Optimum {
        /// s1, s2, s3, s4, gen:KEY=VALUE,... or a path to a .map file.
        #[arg(long, default_value = "s2")]
        scenario: String,
    },
    /// Reproduce a figure of the thesis: run its experiments (multi-process by default) and
    /// plot them. fig10: s1, one UAV. fig11: s2 without vs s3 with communication.
    Reproduce {
        #[arg(value_enum)]
        figure: Figure,
        /// Directory for the runs and the plot [default: results/FIGURE, e.g. results/fig10].
        #[arg(long)]
        out: Option<PathBuf>,
        #[arg(long, default_value_t = 50_000)]
        episodes: u64,
        /// Trials of each run; 1 to 16.
        #[arg(long, default_value_t = 4)]
        trials: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long, value_enum, default_value_t = Transport::Shm)]
        transport: Transport,
        /// Replace the results of earlier runs in `--out`.
        #[arg(long)]
        overwrite: bool,
    },
    /// Evaluate the Q-tables of a finished run greedily (epsilon 0, no learning) on the
    /// same scenario, tree and seed; results go to `<DIR>/eval/` unless `--out` is given.
    Eval {
        /// The results directory of the run (its qtables/, summary.json, scenario.map, tree.bt).
        #[arg(long)]
        qtables: PathBuf,
        /// Greedy episodes per trial (at least 1).
        #[arg(long, default_value_t = 1000)]
        episodes: u64,
        /// Directory for the evaluation's results (summary.json, greedy_episodes.csv, ...)
        /// [default: DIR/eval, DIR being --qtables].
        #[arg(long)]
        out: Option<PathBuf>,
        /// In-process by default; `shm` runs a world and agent processes, and is what
        /// --agent-timeout-ms and --restart (before `eval`) apply to.
        #[arg(long, value_enum, default_value_t = Transport::Inproc)]
        transport: Transport,
        /// Replace the results of an earlier evaluation in `--out`.
        #[arg(long)]
        overwrite: bool,
    },
    /// Write a generated scenario (`gen:uavs=N,...`) as a .map file.
    Generate {
        /// e.g. `gen:uavs=8,targets=4,occlusion=0.15,cover=all,seed=1`.
        spec: String,
        #[arg(long)]
        out: PathBuf,
    },
    /// Draw several learning curves (curve.csv files) on one plot, e.g. the thesis's Fig. 11.
    Plot {
        /// `PATH/curve.csv=LABEL`; repeat for each curve. Agent 1's curve is drawn.
        #[arg(long = "curve", required = true)]
        curves: Vec<String>,
        /// Output file (.svg).
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value = "Episode length vs iterations")]
        title: String,
    },
}

impl Command {
    /// The subcommand as typed.
    fn name(&self) -> &'static str {
        match self {
            Command::Optimum { .. } => "optimum",
            Command::Reproduce { .. } => "reproduce",
            Command::Eval { .. } => "eval",
            Command::Generate { .. } => "generate",
            Command::Plot { .. } => "plot",
        }
    }

    /// Whether this subcommand takes `flag` from before its name. `reproduce` runs ordinary
    /// runs but picks their scenario, UAVs, communication and directories itself; `eval`
    /// takes the run's settings from its `summary.json`.
    fn uses_run_flag(&self, flag: &str) -> bool {
        /// How the processes of a run are watched.
        const SUPERVISION: &[&str] = &["--quiet", "--agent-timeout-ms", "--restart", "--fault"];
        /// How a run learns and is evaluated, whatever its scenario.
        const LEARNING: &[&str] = &[
            "--bt",
            "--alpha",
            "--gamma",
            "--epsilon",
            "--tick-cap",
            "--eval-episodes",
            "--eval-every",
            "--eval-block",
            "--smoothing",
            "--snapshot-every",
        ];
        match self {
            Command::Reproduce { .. } => SUPERVISION.contains(&flag) || LEARNING.contains(&flag),
            Command::Eval { .. } => SUPERVISION.contains(&flag),
            Command::Optimum { .. } | Command::Generate { .. } | Command::Plot { .. } => false,
        }
    }

    /// Refuses a run flag given before this subcommand that it would silently ignore
    /// (`supervisor --episodes 100 reproduce fig10` would run 50 000 episodes).
    pub fn refuse_ignored_run_flags(&self, given: &[String]) -> anyhow::Result<()> {
        match given.iter().find(|flag| !self.uses_run_flag(flag)) {
            Some(ignored) => Err(self.misplaced_run_flag(ignored, Placed::Before)),
            None => Ok(()),
        }
    }

    /// Why run flag `flag` cannot stand where it was typed, and where it belongs.
    fn misplaced_run_flag(&self, flag: &str, placed: Placed) -> anyhow::Error {
        let name = self.name();
        let takes_its_own = || {
            Cli::command().find_subcommand(name).is_some_and(|sub| {
                sub.get_arguments().any(|arg| arg.get_long() == flag.strip_prefix("--"))
            })
        };
        match placed {
            Placed::Before if takes_its_own() => anyhow::anyhow!(
                "{flag} before `{name}` would be ignored: give it after `{name}` \
                 (supervisor {name} ... {flag} ...)"
            ),
            Placed::After if self.uses_run_flag(flag) => anyhow::anyhow!(
                "{flag} after `{name}` is a flag of the run: give it before `{name}` \
                 (supervisor {flag} ... {name} ...)"
            ),
            _ => anyhow::anyhow!(
                "{flag} is a flag of a run, which `{name}` does not use (see supervisor {name} --help)"
            ),
        }
    }
}

/// A figure of the thesis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Figure {
    /// Learning curve of one UAV, one target (scenario 1).
    Fig10,
    /// One UAV without vs two UAVs with communication, two candidate targets (s2 vs s3).
    Fig11,
}

/// What the supervisor does when an agent process fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Restart {
    Never,
    /// Start it again from its latest snapshot (at most a few times per agent).
    OnFailure,
}

/// How the world and agents talk.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Transport {
    /// Everything in this process: the reference for tests and speed.
    Inproc,
    /// One world and N agent processes over iceoryx2 shared memory.
    Shm,
}

#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Number of UAV agents.
    #[arg(long, default_value_t = 2)]
    pub uavs: usize,
    /// Training episodes per trial (0 only with --resume: evaluate only).
    #[arg(long, default_value_t = 50_000)]
    pub episodes: u64,
    /// Independent trials (own seed, world and learners), advanced together; 1 to 16.
    #[arg(long, default_value_t = 4)]
    pub trials: usize,
    /// Seed of the run; every random stream is derived from it.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// s1, s2, s3, s4, gen:KEY=VALUE,... or a path to a .map file [default: s2 for 1 UAV,
    /// s3 for 2, a generated map for more].
    #[arg(long)]
    pub scenario: Option<String>,
    /// Communication: none, flags or compact [default: none for 1 UAV, flags for 2,
    /// compact for more].
    #[arg(long)]
    pub comm: Option<String>,
    /// Behavior tree file [default: the thesis's Fig. 5 tree].
    #[arg(long)]
    pub bt: Option<PathBuf>,
    /// Learning rate of the Q-learning update, in [0, 1].
    // Negative numbers are read as values, so `--alpha -1` is refused for its range (the
    // same message as `--alpha 2`), not taken for an unknown flag.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    pub alpha: f64,
    /// Discount factor, in [0, 1] (1: the thesis's update, no discount).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub gamma: f64,
    /// Exploration rate of the learning selectors during training, in [0, 1].
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    pub epsilon: f64,
    /// Ticks after which a shared episode is cut (truncated).
    #[arg(long, default_value_t = 1000)]
    pub tick_cap: u32,
    /// Greedy evaluation episodes per trial after training (epsilon 0, no learning).
    #[arg(long, default_value_t = 1000)]
    pub eval_episodes: u64,
    /// Evaluate the greedy policy for `--eval-block` episodes after every N training
    /// episodes (0: only after training); drawn on the curve plot, in greedy_curve.csv.
    #[arg(long, default_value_t = 0)]
    pub eval_every: u64,
    /// Episodes of each periodic greedy evaluation (only with --eval-every) [default: 100].
    #[arg(long)]
    pub eval_block: Option<u64>,
    /// Smoothing window (episodes) of the learning curve [default: a hundredth of the
    /// training episodes flown (of --episodes unless stopped early), at least 1].
    #[arg(long)]
    pub smoothing: Option<usize>,
    /// Start every agent from the Q-table snapshots of an earlier run (`DIR/qtables/`).
    /// With `--episodes 0` the run only evaluates them greedily.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Results directory [default: results/RUN_ID].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the results of an earlier run in `--out` (without it such a directory is
    /// refused, so that no finished run is lost by a repeated command).
    #[arg(long)]
    pub overwrite: bool,
    #[arg(long, value_enum, default_value_t = Transport::Shm)]
    pub transport: Transport,
    /// Run id naming the run's shared-memory services [default: derived from pid and time].
    #[arg(long)]
    pub run_id: Option<String>,
    /// No progress bar (it is also hidden when stderr is not a terminal).
    #[arg(long)]
    pub quiet: bool,
    // The flags below are of the multi-process transport only: None when not given, so that
    // an in-process run can refuse them rather than ignore them (`RunConfig::resolve`).
    /// An agent silent this long within a round is presumed dead and dropped (shm; a
    /// crashed agent is noticed sooner, its process is watched) [default: 500].
    #[arg(long)]
    pub agent_timeout_ms: Option<u64>,
    /// What to do when an agent process fails (shm): nothing, or start it again from its
    /// latest Q-table snapshot [default: never].
    #[arg(long, value_enum)]
    pub restart: Option<Restart>,
    /// Agents save their Q-tables every N training episodes of a trial (shm; 0: only at
    /// the end). Restarts resume from these. The barrier waits while an agent writes one
    /// (about 0.3 ms for s3): 10 000 episodes are about 0.7 s of a 4-trial s3 run
    /// [default: 10000].
    #[arg(long)]
    pub snapshot_every: Option<u64>,
    /// Test aid (shm only), off by default: `N=SPEC` makes agent N misbehave; SPEC is
    /// `crash-before-join`, `join-after-file=PATH`, `crash-at-round=R`, `hang-at-round=R`,
    /// `hang-at-stop` or `ignore-sigterm` (several separated by commas).
    #[arg(long = "fault", hide = true)]
    pub faults: Vec<String>,
    /// Test aid (shm only): each agent writes a per-round trace `uav<N>.trace.csv` here.
    #[arg(long, hide = true)]
    pub trace_dir: Option<PathBuf>,
}
