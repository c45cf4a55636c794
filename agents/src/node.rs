//! The agent process: one UAV of a multi-process run, started by the supervisor
//! (`agent run`) or attached to a running simulation (`agent --attach RUN_ID`).
//!
//! It asks the world for a slot, then each round reads the world's observation in place in
//! shared memory, ticks its tree for every trial through [`UavAgent::act`] (the very code the
//! in-process runner calls) and publishes its action. Every `--snapshot-every` training
//! episodes, and when a trial's training pauses or ends, it saves its Q-tables, so a
//! restarted agent can go on from them (`--resume`). On the stop round it closes its
//! episodes, writes its snapshots and answers once more, so the world knows they are on
//! disk; a flight ended otherwise (SIGTERM, Ctrl-C for an attached agent, the world gone)
//! saves them too. `docs/MEMBERSHIP.md` describes the protocol.

use crate::agent::{AgentSpec, UavAgent};
use crate::bt::render::to_text;
use crate::bt::spec::TreeSpec;
use crate::comm::CommMode;
use crate::learning::LearnParams;
use crate::snapshot::{restore_snapshots, write_snapshot, write_snapshots, Learned};
use crate::trace::Trace;
use crate::uav::load_uav_tree;
use anyhow::{bail, Context, Result};
use clap::Args;
use flockstep_proto::transport::{
    exit_with_parent, termination_requested, ActionLoan, AgentPorts, ObservationSample, RunConfig,
    RunServices, SignalMode, TransportError,
};
use flockstep_proto::{
    FieldError, JoinRequest, ObservationKind, Refusal, RunInfo, ANY_SLOT, MAX_AGENTS,
};
use flockstep_world::Scenario;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Tree and learning options shared by `agent run` and `agent --attach`.
#[derive(Debug, Clone, Args)]
pub struct LearnerArgs {
    /// Behavior tree file [default: the thesis's Fig. 5 tree].
    #[arg(long)]
    pub bt: Option<PathBuf>,
    /// Learning rate [default: the run's].
    #[arg(long)]
    pub alpha: Option<f64>,
    /// Discount [default: the run's].
    #[arg(long)]
    pub gamma: Option<f64>,
    /// Exploration [default: the run's].
    #[arg(long)]
    pub epsilon: Option<f64>,
    /// Start from the Q-table snapshots in `<DIR>/qtables/` (those of this agent's slot).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Save this agent's Q-tables every N training episodes of a trial (0: only at the end).
    #[arg(long, default_value_t = 0)]
    pub snapshot_every: u64,
    /// The world silent this long is presumed dead: also bounds the wait for the run's
    /// services at start, so `--attach` to a run that is not running fails after it.
    #[arg(long, default_value_t = 30_000)]
    pub world_timeout_ms: u64,
    /// Test aid: append one line per round and trial to this CSV file (see `trace.rs`).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Test aid, off by default, comma-separated: `crash-before-join` (abort before asking
    /// to join), `join-after-file=PATH` (ask to join once PATH exists), `crash-at-round=N`
    /// (abort), `hang-at-round=N` (stop answering, still obey SIGTERM), `hang-at-stop` (the
    /// same at the stop round, before the final snapshots), `ignore-sigterm`.
    #[arg(long)]
    pub fault: Option<String>,
}

/// Arguments of `agent run` (the supervisor passes them all explicitly).
#[derive(Debug, Clone, Args)]
pub struct NodeArgs {
    #[arg(long)]
    pub run_id: String,
    /// Agent slot, 1-based (UAV1 flies route 1).
    #[arg(long)]
    pub uav: usize,
    /// s1, s2, s3, gen:... or a path to a .map file.
    #[arg(long)]
    pub scenario: String,
    #[arg(long)]
    pub trials: usize,
    #[arg(long)]
    pub seed: u64,
    /// none, flags or compact.
    #[arg(long)]
    pub comm: String,
    /// Results directory: snapshots go to `<out>/qtables/`.
    #[arg(long)]
    pub out: PathBuf,
    /// Exit when this process (the supervisor) is gone.
    #[arg(long)]
    pub parent_pid: Option<u32>,
    #[command(flatten)]
    pub learner: LearnerArgs,
}

/// Arguments of `agent --attach RUN_ID`: the run tells the rest.
#[derive(Debug, Clone, Args)]
pub struct AttachArgs {
    /// Results directory for this agent's snapshots [default: results/RUN_ID].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Ask for this slot (1-based); the agent exits if the run has no such route or another
    /// agent holds it [default: any free route].
    #[arg(long)]
    pub uav: Option<usize>,
    #[command(flatten)]
    pub learner: LearnerArgs,
}

/// A test aid that makes the agent misbehave on purpose.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Fault {
    CrashBeforeJoin,
    /// Waits for this file before asking to join, so a test can act before the agent does.
    JoinAfterFile(PathBuf),
    CrashAtRound(u64),
    HangAtRound(u64),
    /// Stops answering at the stop round, before writing its final snapshots.
    HangAtStop,
    IgnoreSigterm,
}

/// The faults of a `--fault` value: specs separated by commas. The supervisor checks its
/// `--fault N=SPEC` with this before it starts any process.
pub fn parse_faults(specs: &str) -> Result<Vec<Fault>> {
    specs.split(',').map(parse_fault).collect()
}

fn parse_fault(spec: &str) -> Result<Fault> {
    let round = |value: &str| {
        value
            .parse::<u64>()
            .with_context(|| format!("--fault `{spec}`: `{value}` is not a round number"))
    };
    match spec.split_once('=') {
        Some(("crash-at-round", n)) => Ok(Fault::CrashAtRound(round(n)?)),
        Some(("hang-at-round", n)) => Ok(Fault::HangAtRound(round(n)?)),
        Some(("join-after-file", path)) if !path.is_empty() => {
            Ok(Fault::JoinAfterFile(PathBuf::from(path)))
        }
        None if spec == "crash-before-join" => Ok(Fault::CrashBeforeJoin),
        None if spec == "ignore-sigterm" => Ok(Fault::IgnoreSigterm),
        None if spec == "hang-at-stop" => Ok(Fault::HangAtStop),
        _ => bail!(
            "--fault `{spec}`: expected crash-before-join, join-after-file=PATH, crash-at-round=N, \
             hang-at-round=N, hang-at-stop or ignore-sigterm"
        ),
    }
}

/// `agent run`: a supervised agent asking for its own slot.
pub fn run(args: &NodeArgs) -> Result<()> {
    let run = RunConfig::new(&args.run_id, SignalMode::Supervised);
    if let Some(parent) = args.parent_pid {
        exit_with_parent(parent)?;
    }
    let slot = slot_of(args.uav)?;
    let setup = Setup {
        scenario: args.scenario.clone(),
        trials: args.trials,
        seed: args.seed,
        comm: args.comm.clone(),
        params: None,
    };
    serve(&run, Ask::Own(slot), Some(setup), &args.learner, &args.out)
}

/// `agent --attach RUN_ID`: joins a running simulation on a free route, or the one its
/// `--uav` names.
pub fn attach(run_id: &str, args: &AttachArgs) -> Result<()> {
    let run = RunConfig::new(run_id, SignalMode::Interactive);
    let ask = args.uav.map_or(Ok(Ask::Any), |uav| slot_of(uav).map(Ask::Route))?;
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("results").join(run_id));
    serve(&run, ask, None, &args.learner, &out)
}

/// The slot (0-based) of `--uav N`.
fn slot_of(uav: usize) -> Result<usize> {
    let slot = uav.checked_sub(1).context("--uav counts from 1")?;
    if slot >= MAX_AGENTS {
        bail!("--uav {uav}: a run has at most {MAX_AGENTS} routes");
    }
    Ok(slot)
}

/// The slot an agent asks the world for, and what it does when the world refuses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ask {
    /// `agent run --uav N`: the supervisor's agent of slot N-1, which must fly that route
    /// (a restarted one loads its snapshots). Refused because the route is taken, it asks
    /// again: a restarted agent asks while the world has not yet dropped its dead
    /// predecessor, and gets the slot once it has.
    Own(usize),
    /// `agent --attach --uav N`: slot N-1 if its route is free; a refusal ends the agent.
    Route(usize),
    /// `agent --attach`: any free route; a refusal ends the agent.
    Any,
}

impl Ask {
    /// `JoinRequest::slot`.
    fn slot(self) -> u32 {
        match self {
            // Below `MAX_AGENTS` (`slot_of`), so never `ANY_SLOT`.
            Ask::Own(slot) | Ask::Route(slot) => slot as u32,
            Ask::Any => ANY_SLOT,
        }
    }

    /// What the agent makes of the world's refusal `code` ([`Refusal`] as `u8`) in a round
    /// of a run with `routes` routes: None to ask again, else the error it exits with.
    fn refused(self, code: u8, routes: u32, run: &str) -> Option<anyhow::Error> {
        let Some(why) = Refusal::from_u8(code) else {
            let field = "observation.refusal";
            return Some(FieldError { field, value: code.into(), expected: "1..=3".into() }.into());
        };
        let error = match (self, why) {
            (Ask::Own(_), Refusal::RouteTaken) => return None,
            (Ask::Own(slot) | Ask::Route(slot), Refusal::NoSuchRoute) => {
                let plural = if routes == 1 { "" } else { "s" };
                anyhow::anyhow!("--uav {}: run `{run}` has {routes} route{plural}", slot + 1)
            }
            (Ask::Route(slot), Refusal::RouteTaken) => anyhow::anyhow!(
                "--uav {}: route {} of run `{run}` is taken by another agent",
                slot + 1,
                slot + 1
            ),
            (_, why) => anyhow::anyhow!("run `{run}`: the world refused this agent: {why}"),
        };
        Some(error)
    }
}

/// What the agent must agree on with the run: given on the command line, or read from the
/// run's description when attaching.
#[derive(Debug, Clone)]
struct Setup {
    scenario: String,
    trials: usize,
    seed: u64,
    comm: String,
    /// The run's learning parameters, when known from its description.
    params: Option<LearnParams>,
}

/// Serves one run: `setup` None means "read it from the run's description" (attaching).
fn serve(
    run: &RunConfig,
    ask: Ask,
    setup: Option<Setup>,
    learner: &LearnerArgs,
    out: &Path,
) -> Result<()> {
    let faults = learner.fault.as_deref().map_or(Ok(Vec::new()), parse_faults)?;
    // Its own inputs are checked before it looks for the run: a mistake must not take a
    // route, even for a moment. A directory without a trial's snapshot is normal (a restart
    // before the first one); a directory that is not there is a mistake, not a fresh start.
    let tree = load_uav_tree(learner.bt.as_deref())?;
    if let Some(dir) = learner.resume.as_deref().filter(|dir| !dir.is_dir()) {
        bail!("--resume {}: no such directory", dir.display());
    }
    let world_timeout = Duration::from_millis(learner.world_timeout_ms);
    let ports = open_ports(run, world_timeout, setup.is_none())?;
    if faults.contains(&Fault::IgnoreSigterm) {
        // SAFETY: setting a signal's disposition to "ignore".
        unsafe {
            libc::signal(libc::SIGTERM, libc::SIG_IGN);
        }
    }
    if faults.contains(&Fault::CrashBeforeJoin) {
        std::process::abort();
    }
    for fault in &faults {
        if let Fault::JoinAfterFile(path) = fault {
            ports.waiter().wait(
                &format_args!("{} (--fault join-after-file)", path.display()),
                world_timeout,
                || Ok(path.exists().then_some(())),
            )?;
        }
    }
    let nonce = join_nonce();
    let (slot, first) = await_admission(&ports, ask, nonce, world_timeout)?;
    let setup = match setup {
        Some(setup) => setup,
        None => read_run_info(&ports, world_timeout)?,
    };
    let mut session = Session::new(slot, &setup, tree, learner, out)?;
    tracing::info!(uav = slot + 1, "admitted");
    let mut trace = learner.trace.as_deref().map(Trace::create).transpose()?;
    let flown = fly(&ports, &mut session, first, nonce, &faults, world_timeout, trace.as_mut());
    let error = match flown {
        // The stop round is answered once the final tables are on disk: the world takes no
        // answer for a sign they are lost.
        Ok(stop_answer) => {
            session.save_all()?;
            stop_answer.send()?;
            if !ports.await_world_gone(world_timeout)? && !termination_requested() {
                tracing::warn!("the world did not leave after the stop round; leaving anyway");
            }
            if ask != Ask::Own(slot) {
                // Nobody else tells the user of an attached agent that it is done.
                flockstep_proto::output::message(&format!(
                    "agent: run `{}` ended; the Q-tables of UAV{} are in {}",
                    ports.run_id(),
                    slot + 1,
                    out.join("qtables").display()
                ));
            }
            return Ok(());
        }
        Err(error) => error,
    };
    // Whatever ended the flight early (a termination request, the world gone or its verdict
    // that this agent is dead), what it learned is kept: a restart or `--resume` goes on
    // from there.
    if let Err(not_saved) = session.save_all() {
        bail!("{error:#}; and its Q-tables could not be saved: {not_saved:#}");
    }
    let dir = out.join("qtables");
    if termination_requested() && ask != Ask::Own(slot) {
        // An attached agent asked to leave (Ctrl-C): the world drops it once it is gone.
        flockstep_proto::output::message(&format!(
            "agent: UAV{} left run `{}`; its Q-tables are in {}",
            slot + 1,
            ports.run_id(),
            dir.display()
        ));
        return Ok(());
    }
    let said = format!("{error:#}; its Q-tables are saved in {}", dir.display());
    if world_gone(&error) {
        return Err(WorldGone(said).into());
    }
    bail!(said)
}

/// Whether `error` ended an agent because the world was gone: after admission
/// ([`WorldGone`]) or before it (the transport's error as it is).
pub fn world_gone(error: &anyhow::Error) -> bool {
    error.downcast_ref::<WorldGone>().is_some()
        || matches!(error.downcast_ref::<TransportError>(), Some(TransportError::WorldGone { .. }))
}

/// The exit status of an agent that left because the world's node was gone. Once the world
/// has exited too, the supervisor takes it for a consequence of the world's end: it neither
/// blames the agent for the run's failure nor restarts it. Without it, a supervisor that
/// looked at its children late (stopped, or busy) found these agents failed first.
pub const EXIT_WORLD_GONE: u8 = 3;

/// The error of an agent that left because the world was gone (exit status
/// [`EXIT_WORLD_GONE`]); its tables are saved.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct WorldGone(String);

/// Answers every round from `first` (the round that admitted the agent) up to the stop
/// round, whose answer it returns unsent: it goes out once the final snapshots are written.
fn fly<'a>(
    ports: &'a AgentPorts,
    session: &mut Session,
    first: ObservationSample,
    nonce: u64,
    faults: &[Fault],
    world_timeout: Duration,
    mut trace: Option<&mut Trace>,
) -> Result<ActionLoan<'a>> {
    let slot = session.agent.slot();
    let mut next_round = first.round;
    let mut admission = Some(first);
    loop {
        let observation = match admission.take() {
            Some(first) => first,
            None => ports.wait_on_world(
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
            )?,
        };
        observation.prefetch_used();
        next_round = observation.round + 1;
        if observation.slot_owners().get(slot) != Some(&nonce) {
            bail!("the world dropped UAV{} from the run (presumed dead)", slot + 1);
        }
        for fault in faults {
            match *fault {
                Fault::CrashAtRound(r) if observation.round == r => std::process::abort(),
                Fault::HangAtRound(r) if observation.round == r => hang(r),
                Fault::HangAtStop if observation.kind == ObservationKind::Stop as u8 => {
                    hang(observation.round)
                }
                _ => {}
            }
        }
        let mut action = ports.loan_action()?;
        session
            .agent
            .act(&observation, &mut action)
            .with_context(|| format!("round {}", observation.round))?;
        if let Some(trace) = trace.as_deref_mut() {
            trace.record(&observation, &action, &session.agent)?;
        }
        if observation.kind == ObservationKind::Stop as u8 {
            return Ok(action);
        }
        session.save_due();
        action.send()?;
    }
}

/// Opens the run's services and this agent's ports. A world that has not created the
/// services yet is silent like any other, so `--world-timeout-ms` bounds the wait for them
/// too. An attaching agent that finds none says so with the run id it was given: most likely
/// the id is mistyped or its run has ended.
fn open_ports(run: &RunConfig, world_timeout: Duration, attaching: bool) -> Result<AgentPorts> {
    let run = RunConfig { open_timeout: world_timeout, ..run.clone() };
    match RunServices::open(&run).and_then(RunServices::into_agent) {
        Err(TransportError::ServiceMissing { waited, .. }) if attaching => {
            bail!(
                "run `{}`: not running: no world created its services within {waited:?} \
                 (--world-timeout-ms)",
                run.run_id
            )
        }
        opened => Ok(opened?),
    }
}

/// A nonce naming this agent's join request: unique among the run's agents.
fn join_nonce() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    (u64::from(std::process::id()) << 32 ^ nanos) | 1
}

/// How often an agent not yet admitted repeats its join request.
const REJOIN_PAUSE: Duration = Duration::from_millis(50);

/// Asks the world for a slot (request `nonce`) and waits for its answer; returns the slot
/// and the observation that admitted the agent, which is the first round it must answer.
/// The request is repeated until it is answered: one sent while the world is still setting
/// up its ports is lost, and a restarted agent asking for its own slot is refused until the
/// world has dropped its dead predecessor. Any other refusal ends the wait with an error
/// that says why ([`Ask::refused`]).
fn await_admission(
    ports: &AgentPorts,
    ask: Ask,
    nonce: u64,
    timeout: Duration,
) -> Result<(usize, ObservationSample)> {
    let request = JoinRequest::new(nonce, ask.slot());
    let mut asked: Option<Instant> = None;
    ports.wait_on_world(&"admission by the world", timeout, || {
        if asked.is_none_or(|at| at.elapsed() >= REJOIN_PAUSE) {
            ports.send_join(&request)?;
            asked = Some(Instant::now());
        }
        while let Some(sample) = ports.try_observation()? {
            if let Some(slot) = sample.slot_owners().iter().position(|&n| n == nonce) {
                return Ok(Some(Ok((slot, sample))));
            }
            if sample.refused_nonce == nonce {
                if let Some(error) = ask.refused(sample.refusal, sample.n_slots, ports.run_id()) {
                    return Ok(Some(Err(error)));
                }
            }
        }
        Ok(None)
    })?
}

/// Reads the run's description (for an attaching agent).
fn read_run_info(ports: &AgentPorts, timeout: Duration) -> Result<Setup> {
    let info = ports.wait_on_world(&"the run's description", timeout, || ports.try_run_info())?;
    Ok(Setup {
        scenario: RunInfo::unpack(&info.scenario, "run_info.scenario")?,
        trials: info.trials as usize,
        seed: info.seed,
        comm: RunInfo::unpack(&info.comm, "run_info.comm")?,
        params: Some(LearnParams {
            alpha: info.alpha,
            gamma: info.gamma,
            epsilon: info.epsilon,
            learn: true,
        }),
    })
}

/// Stops answering (fault injection) but still leaves on SIGTERM.
fn hang(round: u64) -> ! {
    // In the agent's log: a test waits for it before it acts on the hung agent.
    tracing::warn!(round, "hanging here (--fault)");
    loop {
        std::thread::sleep(Duration::from_millis(10));
        if termination_requested() {
            std::process::exit(1);
        }
    }
}

/// The agent with what it needs to save itself.
struct Session {
    agent: UavAgent,
    scenario: Arc<Scenario>,
    comm: CommMode,
    tree_text: String,
    out: PathBuf,
    snapshot_every: u64,
    /// Per trial: training episodes behind the last saved snapshot.
    saved: Vec<u64>,
}

impl Session {
    fn new(
        slot: usize,
        setup: &Setup,
        tree: TreeSpec,
        learner: &LearnerArgs,
        out: &Path,
    ) -> Result<Session> {
        let scenario = Arc::new(
            Scenario::resolve(&setup.scenario).map_err(|e| anyhow::anyhow!("scenario: {e}"))?,
        );
        let comm = CommMode::parse(&setup.comm).with_context(|| {
            format!("communication mode `{}`: expected none, flags or compact", setup.comm)
        })?;
        let tree_text = to_text(&tree);
        let base = setup.params.unwrap_or_default();
        let params = LearnParams {
            alpha: learner.alpha.unwrap_or(base.alpha),
            gamma: learner.gamma.unwrap_or(base.gamma),
            epsilon: learner.epsilon.unwrap_or(base.epsilon),
            learn: true,
        };
        let spec = AgentSpec {
            slot,
            scenario: scenario.clone(),
            tree,
            comm,
            params,
            seed: setup.seed,
            trials: setup.trials,
        };
        let mut agent = UavAgent::new(&spec)?;
        if let Some(dir) = &learner.resume {
            // A restart before the first periodic snapshot starts those trials afresh.
            let learned = Learned { scenario: &scenario, comm, tree: &tree_text };
            for trial in restore_snapshots(&mut agent, dir, &learned)? {
                tracing::warn!(trial, "no snapshot for this trial: it starts from scratch");
            }
        }
        let saved = agent.trials().iter().map(|t| t.trained_episodes()).collect();
        Ok(Session {
            agent,
            scenario,
            comm,
            tree_text,
            out: out.to_path_buf(),
            snapshot_every: learner.snapshot_every,
            saved,
        })
    }

    /// What this agent's tables are learned on, as its snapshots say.
    fn learned(&self) -> Learned<'_> {
        Learned { scenario: &self.scenario, comm: self.comm, tree: &self.tree_text }
    }

    fn save_all(&self) -> Result<()> {
        write_snapshots(&self.agent, &self.out, &self.learned())
            .with_context(|| format!("saving the Q-tables of UAV{}", self.agent.slot() + 1))
    }

    /// Saves a trial's tables once it has trained `snapshot_every` more episodes (0: never
    /// for that reason), and whenever its training pauses or ends with episodes not yet
    /// saved (a greedy evaluation starts, the trial is done): a failure in the final
    /// evaluation, which can take long, then loses nothing learned. A snapshot that cannot
    /// be written is logged and tried again at the next occasion: the agent flies on, and
    /// only the final tables, which the stop round waits for, decide the run.
    fn save_due(&mut self) {
        for (trial, part) in self.agent.trials().iter().enumerate() {
            let unsaved = part.trained_episodes() - self.saved[trial];
            let due = self.snapshot_every > 0 && unsaved >= self.snapshot_every;
            if !due && (unsaved == 0 || part.is_training()) {
                continue;
            }
            self.saved[trial] = part.trained_episodes();
            let written = write_snapshot(part, &self.out, trial, &self.learned());
            if let Err(e) = written {
                tracing::warn!(trial, "snapshot not saved, the agent flies on: {e}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_and_a_bad_one_is_named() {
        assert_eq!(
            parse_faults("crash-at-round=7,join-after-file=/tmp/go,ignore-sigterm").unwrap(),
            [Fault::CrashAtRound(7), Fault::JoinAfterFile("/tmp/go".into()), Fault::IgnoreSigterm]
        );
        let no_round = parse_faults("hang-at-round=soon").unwrap_err().to_string();
        assert!(no_round.contains("`soon` is not a round number"), "{no_round}");
        let no_path = parse_faults("join-after-file=").unwrap_err().to_string();
        assert!(no_path.contains("--fault `join-after-file=`: expected"), "{no_path}");
    }

    /// The message an agent exits with when the world refuses it, or None if it asks again.
    fn refused(ask: Ask, why: Refusal, routes: u32) -> Option<String> {
        ask.refused(why as u8, routes, "r1").map(|e| e.to_string())
    }

    #[test]
    fn a_refused_agent_says_why_and_only_a_supervised_one_asks_again_for_a_taken_route() {
        assert_eq!(
            refused(Ask::Route(8), Refusal::NoSuchRoute, 3).as_deref(),
            Some("--uav 9: run `r1` has 3 routes")
        );
        assert_eq!(
            refused(Ask::Route(1), Refusal::RouteTaken, 3).as_deref(),
            Some("--uav 2: route 2 of run `r1` is taken by another agent")
        );
        assert_eq!(
            refused(Ask::Any, Refusal::RunFull, 2).as_deref(),
            Some("run `r1`: the world refused this agent: every route of the scenario is taken")
        );
        // A restarted agent's dead predecessor may still hold its route: it asks again.
        assert_eq!(refused(Ask::Own(1), Refusal::RouteTaken, 2), None);
        assert_eq!(
            refused(Ask::Own(2), Refusal::NoSuchRoute, 1).as_deref(),
            Some("--uav 3: run `r1` has 1 route")
        );
        let unknown = Ask::Any.refused(9, 2, "r1").expect("an error").to_string();
        assert!(unknown.contains("observation.refusal") && unknown.contains("= 9"), "{unknown}");
    }

    #[test]
    fn uav_counts_from_1_up_to_the_largest_run() {
        assert_eq!(slot_of(1).unwrap(), 0);
        assert_eq!(slot_of(0).unwrap_err().to_string(), "--uav counts from 1");
        assert_eq!(
            slot_of(MAX_AGENTS + 1).unwrap_err().to_string(),
            format!("--uav {}: a run has at most {MAX_AGENTS} routes", MAX_AGENTS + 1)
        );
        assert_ne!(Ask::Route(MAX_AGENTS - 1).slot(), ANY_SLOT);
    }
}
