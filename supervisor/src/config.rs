//! A run's configuration, resolved from the command line and checked before anything starts.

use crate::cli::{Restart, RunArgs, Transport};
use crate::results::{EvalPlan, MAX_EVAL_BLOCKS};
use anyhow::{bail, Context, Result};
use flockstep_agents::agent::{AgentSpec, UavAgent};
use flockstep_agents::bt::render::to_text;
use flockstep_agents::bt::spec::TreeSpec;
use flockstep_agents::comm::CommMode;
use flockstep_agents::learning::LearnParams;
use flockstep_agents::snapshot::Learned;
use flockstep_agents::uav::load_uav_tree;
use flockstep_proto::{RunInfo, MAX_AGENTS, MAX_TRIALS, SCENARIO_BYTES};
use flockstep_world::generate::GenSpec;
use flockstep_world::scenario::Scenario;
use flockstep_world::sim::EpisodeConfig;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Everything a run needs, validated.
#[derive(Debug, Clone)]
pub struct RunConfig {
    /// The scenario as the child processes get it: a built-in name (`s1`-`s4`) or a `gen:`
    /// spec as given, a `.map` path made absolute (the world hands it on to agents that
    /// attach, which may start in another directory).
    pub scenario_arg: String,
    pub scenario: Arc<Scenario>,
    /// The tree file as given (None: the built-in Fig. 5 tree).
    pub bt_path: Option<PathBuf>,
    pub tree: TreeSpec,
    pub comm: CommMode,
    pub params: LearnParams,
    pub episodes: EpisodeConfig,
    pub uavs: usize,
    pub trials: usize,
    pub seed: u64,
    /// The learning curve's window, if given (`--smoothing`); else it follows the episodes
    /// the run trained ([`crate::curve::window`]).
    pub smoothing: Option<usize>,
    pub out: PathBuf,
    /// `out` may hold an earlier run's results, which the run removes first.
    pub overwrite: bool,
    pub transport: Transport,
    pub run_id: String,
    pub quiet: bool,
    pub trace_dir: Option<PathBuf>,
    /// Snapshots every agent starts from (checked to exist for every agent and trial).
    pub resume: Option<PathBuf>,
    pub agent_timeout_ms: u64,
    pub restart: Restart,
    pub snapshot_every: u64,
    /// Per agent slot: the fault to inject (test aid).
    pub faults: Vec<(usize, String)>,
    /// What the summary's `notes` say about the configuration before anything the run
    /// notes itself (`eval` says which agents of the run it evaluates).
    pub notes: Vec<String>,
}

impl RunConfig {
    pub fn resolve(args: &RunArgs) -> Result<RunConfig> {
        RunConfig::resolve_resuming_as(args, "--resume")
    }

    /// As [`RunConfig::resolve`], with `resume_flag` naming where `args.resume` came from in
    /// the errors of its snapshots (`eval` reads a finished run's through it).
    pub fn resolve_resuming_as(args: &RunArgs, resume_flag: &str) -> Result<RunConfig> {
        if args.uavs == 0 {
            bail!("--uavs must be at least 1");
        }
        if args.uavs > MAX_AGENTS {
            bail!("--uavs {} exceeds the supported maximum of {MAX_AGENTS}", args.uavs);
        }
        if args.trials == 0 || args.trials > MAX_TRIALS {
            bail!("--trials {} is out of range 1..={MAX_TRIALS}", args.trials);
        }
        if args.episodes == 0 && (args.resume.is_none() || args.eval_episodes == 0) {
            bail!("--episodes must be at least 1 (0 only to evaluate snapshots: --resume DIR with --eval-episodes)");
        }
        if args.tick_cap == 0 {
            bail!("--tick-cap must be at least 1");
        }
        check_eval_every(args)?;
        if args.smoothing == Some(0) {
            bail!("--smoothing must be at least 1 episode");
        }
        // A window past the training would average the whole curve into one value, or
        // smooth nothing at all (`--episodes 0`): a flag with no use is refused.
        if let Some(window) = args.smoothing.filter(|&window| window as u64 > args.episodes) {
            bail!(
                "--smoothing {window} is more than the {} training episodes of a trial \
                 (--episodes): give at most that, or leave --smoothing out",
                args.episodes
            );
        }
        if args.agent_timeout_ms == Some(0) {
            bail!("--agent-timeout-ms must be at least 1: an agent silent that long in a round is dropped");
        }
        check_episode_counts(args)?;
        let scenario_arg = args.scenario.clone().unwrap_or_else(|| default_scenario(args.uavs));
        let scenario =
            Scenario::resolve(&scenario_arg).map_err(|e| anyhow::anyhow!("--scenario: {e}"))?;
        if args.uavs > scenario.n_routes() {
            bail!(
                "--uavs {} but scenario `{}` has only {} route(s); use a scenario with more routes",
                args.uavs,
                scenario_arg,
                scenario.n_routes()
            );
        }
        let scenario_arg = scenario_for_children(&scenario_arg)?;
        let comm = match &args.comm {
            Some(c) => CommMode::parse(c)
                .with_context(|| format!("--comm `{c}`: expected none, flags or compact"))?,
            None => default_comm(args.uavs),
        };
        let tree = load_uav_tree(args.bt.as_deref())?;
        let params = LearnParams {
            alpha: args.alpha,
            gamma: args.gamma,
            epsilon: args.epsilon,
            learn: true,
        };
        params.validate().map_err(anyhow::Error::msg)?;
        let run_id = match &args.run_id {
            Some(id) => id.clone(),
            None => default_run_id(),
        };
        flockstep_proto::services::validate_run_id(&run_id)
            .map_err(|e| anyhow::anyhow!("--run-id: {e}"))?;
        let out = args.out.clone().unwrap_or_else(|| PathBuf::from("results").join(&run_id));
        let resume = args.resume.as_deref().map(|dir| (dir, resume_flag));
        check_out_dir(&out, args.overwrite, resume)?;
        let config = RunConfig {
            scenario_arg,
            scenario: Arc::new(scenario),
            bt_path: args.bt.clone(),
            tree,
            comm,
            params,
            episodes: EpisodeConfig {
                train_episodes: args.episodes,
                eval_episodes: args.eval_episodes,
                eval_every: args.eval_every,
                eval_block: eval_block(args),
                tick_cap: args.tick_cap,
            },
            uavs: args.uavs,
            trials: args.trials,
            seed: args.seed,
            smoothing: args.smoothing,
            out,
            transport: args.transport,
            run_id,
            quiet: args.quiet,
            overwrite: args.overwrite,
            trace_dir: args.trace_dir.clone(),
            resume: args.resume.clone(),
            agent_timeout_ms: args.agent_timeout_ms.unwrap_or(DEFAULT_AGENT_TIMEOUT_MS),
            restart: args.restart.unwrap_or(Restart::Never),
            snapshot_every: args.snapshot_every.unwrap_or(DEFAULT_SNAPSHOT_EVERY),
            faults: parse_faults(&args.faults, args.uavs)?,
            notes: Vec::new(),
        };
        if config.transport == Transport::Inproc {
            refuse_process_flags(args)?;
        }
        if let Some(dir) = &config.resume {
            check_snapshots(&config, dir, resume_flag)?;
        }
        Ok(config)
    }

    /// The spec of agent `slot`, as the in-process runner and the agent process build it.
    pub fn agent_spec(&self, slot: usize) -> AgentSpec {
        AgentSpec {
            slot,
            scenario: self.scenario.clone(),
            tree: self.tree.clone(),
            comm: self.comm,
            params: self.params,
            seed: self.seed,
            trials: self.trials,
        }
    }

    /// The tree in canonical text form (stored with snapshots and results).
    pub fn tree_text(&self) -> String {
        to_text(&self.tree)
    }

    /// What this run's tables are learned on, its tree given in canonical text form
    /// ([`RunConfig::tree_text`]): what its snapshots record and must match when loaded.
    pub fn learned<'a>(&'a self, tree: &'a str) -> Learned<'a> {
        Learned { scenario: &self.scenario, comm: self.comm, tree }
    }
}

/// `--agent-timeout-ms` unless given: a round that waits this long for an agent is rare
/// enough not to be slow, and a hung agent is noticed within half a second.
const DEFAULT_AGENT_TIMEOUT_MS: u64 = 500;

/// `--snapshot-every` unless given (README: 10 000 episodes of a 4-trial s3 run cost about
/// 0.7 s of waiting for snapshots).
const DEFAULT_SNAPSHOT_EVERY: u64 = 10_000;

/// `--eval-block` unless given: 100 greedy episodes a block.
const DEFAULT_EVAL_BLOCK: u64 = 100;

/// The episodes of each periodic greedy evaluation.
fn eval_block(args: &RunArgs) -> u64 {
    args.eval_block.unwrap_or(DEFAULT_EVAL_BLOCK)
}

/// Refuses periodic-evaluation flags that would be ignored or evaluate nothing: an
/// `--eval-block` without `--eval-every`, an `--eval-every` the training never reaches
/// before its last episode (the periodic evaluations run after every N training episodes
/// but the last, which the final evaluation follows), a block of no episodes.
fn check_eval_every(args: &RunArgs) -> Result<()> {
    if args.eval_every == 0 {
        if let Some(block) = args.eval_block {
            bail!(
                "--eval-block {block} sizes the periodic greedy evaluations of --eval-every, \
                 which is not given: give --eval-every N, or leave --eval-block out"
            );
        }
        return Ok(());
    }
    if args.eval_every >= args.episodes {
        bail!(
            "--eval-every {every} with --episodes {}: no periodic greedy evaluation would run \
             (one runs after every {every} training episodes, before the last); give an \
             --eval-every below --episodes, or leave it out",
            args.episodes,
            every = args.eval_every,
        );
    }
    if eval_block(args) == 0 {
        bail!("--eval-every {} needs an --eval-block of at least 1 episode", args.eval_every);
    }
    Ok(())
}

/// Refuses, for an in-process run, the flags that only watch or shape agent processes: it
/// has none, and a flag it would ignore is refused as elsewhere (the values were checked
/// first, so a bad value is named as such on both transports).
fn refuse_process_flags(args: &RunArgs) -> Result<()> {
    let given = [
        ("--agent-timeout-ms", args.agent_timeout_ms.is_some()),
        ("--restart", args.restart.is_some()),
        ("--snapshot-every", args.snapshot_every.is_some()),
        ("--fault", !args.faults.is_empty()),
        ("--trace-dir", args.trace_dir.is_some()),
    ];
    match given.into_iter().find(|&(_, given)| given) {
        Some((flag, _)) => bail!(
            "{flag} applies to agent processes, and an in-process run (--transport inproc) has \
             none: give --transport shm, or leave {flag} out"
        ),
        None => Ok(()),
    }
}

/// The thesis's scenarios for one and two UAVs: one UAV searches two candidate cells (s2),
/// two UAVs share them (s3). More UAVs fly a generated map on which every route sees every
/// candidate cell (see `flockstep_world::generate::default_generated_spec`).
pub fn default_scenario(uavs: usize) -> String {
    match uavs {
        1 => "s2".to_string(),
        2 => "s3".to_string(),
        n => flockstep_world::generate::default_generated_spec(n),
    }
}

/// The thesis's modes for one and two UAVs (none, flags); for more, the compact mode,
/// whose state does not grow with the number of UAVs (flags' does, exponentially).
pub fn default_comm(uavs: usize) -> CommMode {
    match uavs {
        1 => CommMode::None,
        2 => CommMode::Flags,
        _ => CommMode::Compact,
    }
}

/// Refuses episode counts the run cannot count or keep: training or greedy episodes over
/// all trials past `u64` (each is counted over every trial), more periodic evaluations than
/// [`MAX_EVAL_BLOCKS`] (the collector keeps a total per agent and evaluation from the start).
fn check_episode_counts(args: &RunArgs) -> Result<()> {
    let trials = args.trials as u64;
    if args.episodes.checked_mul(trials).is_none() {
        bail!(
            "--episodes {} with --trials {}: more training episodes in all than a run can count",
            args.episodes,
            args.trials
        );
    }
    let plan = EvalPlan::new(args.episodes, args.eval_every, eval_block(args));
    if plan.blocks > MAX_EVAL_BLOCKS {
        bail!(
            "--eval-every {} with --episodes {}: {} periodic greedy evaluations per trial, at \
             most {MAX_EVAL_BLOCKS} are supported; evaluate less often",
            args.eval_every,
            args.episodes,
            plan.blocks
        );
    }
    let Some(per_trial) = plan.greedy_episodes(args.eval_episodes) else {
        bail!(
            "--eval-block {} with --eval-episodes {}: {} blocks and the final evaluation are \
             more greedy episodes per trial than a run can count",
            plan.block,
            args.eval_episodes,
            plan.blocks
        );
    };
    if per_trial.checked_mul(trials).is_none() {
        bail!(
            "--eval-episodes {} with --trials {}: more greedy episodes in all than a run can \
             count",
            args.eval_episodes,
            args.trials
        );
    }
    Ok(())
}

/// The scenario as the child processes get it: a built-in name (checked first, as
/// [`Scenario::resolve`] does) or a `gen:` spec unchanged, a path made absolute. The world
/// hands it on to agents that attach (`RunInfo`), which may have started elsewhere.
fn scenario_for_children(arg: &str) -> Result<String> {
    if Scenario::builtin(arg).is_some() || GenSpec::is_gen(arg) {
        return Ok(arg.to_string());
    }
    let path = Path::new(arg).canonicalize().with_context(|| format!("--scenario {arg}"))?;
    let text = path.to_str().with_context(|| {
        format!("--scenario {arg}: its absolute path {} is not UTF-8", path.display())
    })?;
    // Checked here, not by the world at start-up, which would name a path nobody typed.
    anyhow::ensure!(
        RunInfo::pack::<SCENARIO_BYTES>(text).is_some(),
        "--scenario {arg}: its absolute path {text} is longer than the {SCENARIO_BYTES} bytes \
         a run hands on to attaching agents; move the map to a shorter path"
    );
    Ok(text.to_string())
}

/// Checks that `dir` holds, for every agent and trial, a snapshot this run can load. Each is
/// loaded into a fresh copy of its agent, as the in-process runner and the agent process load
/// it (scenario, slot, communication mode, tree and tables checked), so a bad one is refused
/// here, before any process starts, and not by an agent process that then dies mid-run.
fn check_snapshots(config: &RunConfig, dir: &Path, flag: &str) -> Result<()> {
    use flockstep_agents::snapshot::{restore_snapshots, snapshot_path};
    let tree = config.tree_text();
    for slot in 0..config.uavs {
        let mut agent = UavAgent::new(&config.agent_spec(slot))?;
        let missing = restore_snapshots(&mut agent, dir, &config.learned(&tree))
            .with_context(|| format!("{flag} {}", dir.display()))?;
        if let Some(&trial) = missing.first() {
            bail!(
                "{flag} {}: no snapshot {} (UAV{}, trial {trial})",
                dir.display(),
                snapshot_path(dir, slot, trial).display(),
                slot + 1
            );
        }
    }
    Ok(())
}

/// Refuses an `out` that holds an earlier run's results unless `overwrite`, and an
/// `overwrite` that would remove the snapshots `resume` starts from (the directory, named by
/// its flag): `out` itself, whose `qtables/` it removes, or a directory inside an entry it
/// removes (`out/eval/`, which `eval` writes with a copy of the tables). Both before anything
/// is removed or written; the second also when `out` holds no earlier run, as `--overwrite`
/// removes those entries all the same.
fn check_out_dir(out: &Path, overwrite: bool, resume: Option<(&Path, &str)>) -> Result<()> {
    if out.exists() && !out.is_dir() {
        bail!("results directory {}: is a file, not a directory", out.display());
    }
    if let Some((resume, flag)) = resume.filter(|_| overwrite) {
        if same_dir(resume, out) {
            bail!(
                "--overwrite: {flag} {} is the results directory it would replace; give another --out",
                resume.display()
            );
        }
        if let Some(entry) = crate::results::removed_entry_holding(out, resume) {
            bail!(
                "{flag} {} would be removed by --overwrite, which removes {} from the results \
                 directory {}; give another --out, or copy the snapshots elsewhere first",
                resume.display(),
                entry.display(),
                out.display()
            );
        }
    }
    let Some(found) = crate::results::earlier_results(out) else { return Ok(()) };
    // A run still writing there is what to say, not its results so far, which --overwrite
    // would not be let to replace: the run takes the lock for good later.
    crate::out_lock::OutDirLock::take(out)?;
    // Not `--out DIR`: `reproduce` and `eval` choose the directory when no --out is given.
    if !overwrite {
        bail!(
            "results directory {}: holds the results of an earlier run ({found}); choose \
             another directory (--out), or --overwrite to replace them",
            out.display()
        );
    }
    Ok(())
}

/// Whether `a` and `b` are the same existing directory (false if either is missing).
pub fn same_dir(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// `N=SPEC` pairs (N 1-based) into (slot, SPEC), SPEC checked by the agent's own parser.
fn parse_faults(faults: &[String], uavs: usize) -> Result<Vec<(usize, String)>> {
    faults
        .iter()
        .map(|f| {
            let (uav, spec) =
                f.split_once('=').with_context(|| format!("--fault `{f}`: expected N=SPEC"))?;
            let uav: usize = uav
                .parse()
                .with_context(|| format!("--fault `{f}`: `{uav}` is not an agent number"))?;
            anyhow::ensure!(
                (1..=uavs).contains(&uav),
                "--fault `{f}`: agent {uav} is not one of 1..={uavs}"
            );
            flockstep_agents::node::parse_faults(spec)?;
            Ok((uav - 1, spec.to_string()))
        })
        .collect()
}

fn default_run_id() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    format!("run-{}-{}", std::process::id(), secs)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Agents that attach read the scenario from the world, and may start elsewhere: a path
    /// goes on absolute, names and specs as given.
    #[test]
    fn a_scenario_path_goes_to_the_children_absolute_and_names_as_given() {
        for spec in ["s1", "s4", "gen:uavs=3"] {
            assert_eq!(scenario_for_children(spec).unwrap(), spec);
        }
        // Unit tests run in the crate's directory.
        let relative = "../world/maps/s1_one_uav_one_target.map";
        let absolute = scenario_for_children(relative).unwrap();
        let expected = Path::new(env!("CARGO_MANIFEST_DIR")).join(relative).canonicalize();
        assert_eq!(Path::new(&absolute), expected.unwrap());
        assert!(!absolute.contains(".."), "{absolute}");
    }

    /// The run flags of `supervisor FLAGS...`.
    fn args(flags: &[&str]) -> RunArgs {
        use clap::Parser;
        let cli = crate::cli::Cli::try_parse_from(["supervisor"].iter().chain(flags)).unwrap();
        cli.run
    }

    /// The error of the run flags `flags`, checked as far as the episode counts.
    fn refused(flags: &[&str]) -> String {
        let args = args(flags);
        check_eval_every(&args).and_then(|()| check_episode_counts(&args)).unwrap_err().to_string()
    }

    /// `--eval-block` alone, or an `--eval-every` the run never reaches before its last
    /// episode, would be ignored: no periodic evaluation runs.
    #[test]
    fn periodic_evaluation_flags_that_evaluate_nothing_are_refused() {
        assert_eq!(
            refused(&["--eval-block", "50"]),
            "--eval-block 50 sizes the periodic greedy evaluations of --eval-every, which is \
             not given: give --eval-every N, or leave --eval-block out"
        );
        for every in ["10", "100"] {
            let e = refused(&["--eval-every", every, "--episodes", "10"]);
            assert!(
                e.starts_with(&format!(
                    "--eval-every {every} with --episodes 10: no periodic greedy evaluation would run"
                )),
                "{e}"
            );
        }
        let runs = args(&["--eval-every", "9", "--episodes", "10", "--eval-block", "5"]);
        check_eval_every(&runs).expect("one evaluation, after episode 9");
        assert_eq!(eval_block(&runs), 5);
        assert_eq!(eval_block(&args(&["--eval-every", "9"])), DEFAULT_EVAL_BLOCK);
    }

    /// Greedy episodes are counted over all trials as training episodes are: past `u64`
    /// either way, by whichever flag, is refused.
    #[test]
    fn greedy_episodes_past_what_a_run_can_count_are_refused_as_training_ones_are() {
        let most = u64::MAX.to_string();
        assert_eq!(
            refused(&["--eval-episodes", &most]),
            format!(
                "--eval-episodes {most} with --trials 4: more greedy episodes in all than a run \
                 can count"
            )
        );
        assert_eq!(
            refused(&["--episodes", &most]),
            format!(
                "--episodes {most} with --trials 4: more training episodes in all than a run can \
                 count"
            )
        );
        let one_trial = args(&["--eval-episodes", &most, "--trials", "1"]);
        check_episode_counts(&one_trial).expect("as many as a u64 counts");
        let e = refused(&["--eval-every", "1000", "--episodes", "2001", "--eval-block", &most]);
        assert!(e.contains("more greedy episodes per trial than a run can count"), "{e}");
    }

    /// `--overwrite` removes `eval/` whole, with the copy of the tables `eval` wrote there: a
    /// `--resume` there is refused before anything is removed (it used to be removed, the
    /// earlier run with it, and the run failed for want of snapshots), also when the
    /// directory holds no earlier run and however the path is spelt. A directory beside the
    /// removed entries is kept, and may be resumed from.
    #[test]
    fn overwrite_refuses_a_resume_directory_inside_what_it_removes() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        for kept in ["eval/qtables", "evaluated/qtables"] {
            std::fs::create_dir_all(out.join(kept)).unwrap();
        }
        let resume = out.join("eval");
        let refused = |resume: &Path| {
            check_out_dir(out, true, Some((resume, "--resume"))).unwrap_err().to_string()
        };
        let expected = format!(
            "--resume {} would be removed by --overwrite, which removes {} from the results \
             directory {}; give another --out, or copy the snapshots elsewhere first",
            resume.display(),
            out.join("eval").display(),
            out.display()
        );
        assert_eq!(refused(&resume), expected, "no earlier run in {}", out.display());
        std::fs::write(out.join("summary.json"), "{}").unwrap();
        assert_eq!(refused(&resume), expected);
        let spelt = out.join("evaluated").join("..").join("eval").join("qtables");
        assert!(refused(&spelt).contains("which removes"), "{}", spelt.display());
        check_out_dir(out, true, Some((&out.join("evaluated"), "--resume"))).expect("kept");
        let e = refused(out);
        assert!(
            e.ends_with("is the results directory it would replace; give another --out"),
            "{e}"
        );
        let e = check_out_dir(out, false, Some((&resume, "--resume"))).unwrap_err().to_string();
        assert!(e.contains("holds the results of an earlier run"), "{e}");
    }

    /// `reproduce` and `eval` choose a results directory when no `--out` is given: the
    /// refusal names the directory, not a `--out` the user did not type.
    #[test]
    fn a_results_directory_holding_a_run_is_refused_without_claiming_an_out_flag() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("summary.json"), "{}").unwrap();
        let e = check_out_dir(dir.path(), false, None).unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "results directory {}: holds the results of an earlier run (summary.json); \
                 choose another directory (--out), or --overwrite to replace them",
                dir.path().display()
            )
        );
    }
}
