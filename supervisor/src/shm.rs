//! The multi-process transport: one `world` and N `agent` processes over iceoryx2.
//!
//! The supervisor sweeps the stale resources of crashed runs, starts the world (which creates
//! the run's services), opens the run as a reader of episode records, starts the agents, and
//! then records what the world reports until the world exits. It watches its children: a
//! failed agent is reported (the world drops it from the barrier) and, with `--restart
//! on-failure`, started again from its latest snapshot; an agent the world dropped whose
//! process still runs (hung; the world names the process of each slot whenever the
//! barrier's membership changes) is brought down and is then a failed agent too; a failed
//! world ends the run at once, and so does an agent that fails in the barrier as the run
//! ends (its final Q-tables are lost). Ctrl-C asks the world to stop at the end of the
//! current round; a second one brings every process down without that round
//! ([`crate::interrupt`]); Ctrl-Z pauses them all with the supervisor ([`crate::suspend`]).
//! Every child is finally brought down by the shutdown ladder and what is left of the run in
//! shared memory removed. Agents that attach and leave are noted too.

use crate::children::{bring_all_down, shut_down, Process};
use crate::cli::Restart;
use crate::config::RunConfig;
use crate::interrupt::Interrupts;
use crate::recorder::Recorder;
use crate::run::Outcome;
use crate::suspend::SuspendOnCtrlZ;
use anyhow::{bail, Context, Result};
use flockstep_agents::node::EXIT_WORLD_GONE;
use flockstep_agents::snapshot::{read_snapshot, snapshot_path};
use flockstep_proto::supervisor_to_world::Control;
use flockstep_proto::transport::{
    cleanup_run, sweep_stale_runs, FromWorld, RunConfig as RunIdentity, RunServices, SignalMode,
    SupervisorPorts, TransportError, REPORT_TIMEOUT,
};
use flockstep_proto::{Membership, MAX_AGENTS};
use flockstep_world::node::{EXIT_TERMINATED, STOP_ROUND_WAIT};
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::time::{Duration, Instant};

/// How long the world may take to create the run's services.
const WORLD_START: Duration = Duration::from_secs(30);
/// How long children may take to leave by themselves once the world is done.
const GRACE: Duration = Duration::from_secs(10);
/// What a world asked to stop gets beyond its own waits (see `Fleet::stop_bound`).
const STOP_SPARE: Duration = Duration::from_secs(10);
/// Restarts of one agent before the supervisor gives up on it.
const MAX_RESTARTS: u32 = 5;

pub fn run(config: &RunConfig, recorder: &mut Recorder, stop: &Interrupts) -> Result<Outcome> {
    let logs = config.out.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("cannot create {}", logs.display()))?;
    if let Some(dir) = &config.trace_dir {
        create_trace_files(dir, config.uavs)?;
    }
    // Before the first child starts: a Ctrl-Z from then on waits for the run to pause it.
    let ctrl_z = SuspendOnCtrlZ::catch().context("catching Ctrl-Z (SIGTSTP)")?;
    let world = Process::spawn("world", world_command(config)?, &logs.join("world.log"))?;
    let mut fleet = Fleet {
        config,
        ctrl_z,
        world,
        agents: Vec::new(),
        restarts: vec![0; config.uavs],
        membership: Membership::default(),
    };
    let result = open_ports(config, &mut fleet.world).and_then(|ports| {
        for slot in 0..config.uavs {
            fleet.spawn_agent(slot, false)?;
        }
        recorder.set_live(config.uavs);
        announce(config, recorder);
        fleet.supervise(&ports, recorder, stop)
    });
    // A failed run brings its children down at once; a finished one lets them leave.
    let grace = if result.is_ok() { GRACE } else { Duration::ZERO };
    let mut processes: Vec<&mut Process> = fleet.processes().collect();
    let forced = shut_down(&mut processes, grace);
    // Also when a child could not be brought down: its files go at the next start-up sweep.
    let cleaned = cleanup_run(&config.run_id).context("removing the run's shared-memory resources");
    if let (Err(_), Err(unstopped)) = (&result, &forced) {
        // The run's own failure is the error; a child left running is worth a note.
        recorder.note(format!("{unstopped:#}"));
    }
    let mut outcome = result?;
    let forced = forced?;
    cleaned?;
    outcome.peak_rss_kib =
        processes.iter().filter_map(|p| Some((p.name.clone(), p.peak_rss_kib?))).collect();
    if !forced.is_empty() {
        recorder.note(format!("had to signal {} to stop", forced.join(", ")));
    }
    Ok(outcome)
}

/// Before anything is written or started: removes the stale resources of dead runs (a
/// crashed run of this id included), then refuses a run id that a live run uses (`--run-id`
/// given twice): this run's world would fail to create its services, after its supervisor
/// had opened the other run's.
pub fn prepare(run_id: &str) -> Result<()> {
    let swept = sweep_stale_runs().map_err(|e| match e {
        // Not about the earlier runs: this user's root itself is refused, and says why.
        TransportError::UnsafeRoot { .. } => anyhow::Error::new(e),
        e => anyhow::Error::new(e).context("cleaning stale resources of earlier runs"),
    })?;
    if !swept.runs_cleaned.is_empty() {
        tracing::info!(runs = ?swept.runs_cleaned, "removed stale resources of dead runs");
    }
    for (run, why) in &swept.failed {
        if run == run_id {
            bail!(
                "--run-id {run_id}: an earlier run of this id left files that cannot be \
                 removed: {why}"
            );
        }
        tracing::warn!("left the files of run `{run}` in place, they cannot be removed: {why}");
    }
    if RunServices::is_served(run_id)? {
        bail!("--run-id {run_id}: a live run uses this id; choose another");
    }
    Ok(())
}

/// Says which run this is and, if the scenario has routes no agent was started for, how
/// another agent joins it: the run id is otherwise in no output of a run given `--out`.
fn announce(config: &RunConfig, recorder: &Recorder) {
    let id = &config.run_id;
    recorder.say(&format!(
        "run {id}: a world and {}, results in {}",
        count(config.uavs, "agent"),
        config.out.display()
    ));
    let free = config.scenario.agent_slots().saturating_sub(config.uavs);
    if free > 0 {
        let me = own_path().map_or_else(|_| "supervisor".to_string(), |p| p.display().to_string());
        let (routes, agent) = (count(free, "route"), crate::ROLE_AGENT);
        recorder
            .say(&format!("{routes} free; another agent joins with: {me} {agent} --attach {id}"));
    }
}

/// "1 agent", "2 agents".
fn count(n: usize, thing: &str) -> String {
    format!("{n} {thing}{}", if n == 1 { "" } else { "s" })
}

/// The world and the agent processes of a run.
struct Fleet<'a> {
    config: &'a RunConfig,
    ctrl_z: SuspendOnCtrlZ,
    world: Process,
    /// Every agent process started, restarts included, in the order they were started.
    agents: Vec<AgentProcess>,
    restarts: Vec<u32>,
    /// The barrier's membership as the world last told it.
    membership: Membership,
}

/// An agent process the supervisor started, and what it knows of it.
struct AgentProcess {
    process: Process,
    /// The slot it serves.
    slot: usize,
    /// Where it stands in the barrier, as the world tells it.
    seat: Seat,
    /// Its failure has been noted.
    noted: bool,
}

/// Where an agent process stands in the barrier. The world tells every change of the
/// barrier's membership, in order, with the process that holds each slot
/// ([`flockstep_proto::Membership`]), so a restart is never taken for its predecessor, nor
/// for an agent that attached on its route.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seat {
    /// Not admitted yet.
    Waiting,
    /// The world named it as its slot's agent.
    InBarrier,
    /// The world stopped naming it: it dropped the process (for good).
    Dropped,
}

impl AgentProcess {
    /// Whether the supervisor brings it down: the world dropped it, or it began to already.
    fn to_bring_down(&self) -> bool {
        self.process.brought_down() || self.seat == Seat::Dropped
    }
}

impl Seat {
    /// The seat after a change of membership; `held`: the world names this process as the
    /// agent of its slot.
    fn after(self, held: bool) -> Seat {
        match self {
            Seat::Waiting if held => Seat::InBarrier,
            Seat::InBarrier if !held => Seat::Dropped,
            seat => seat,
        }
    }
}

impl Fleet<'_> {
    fn spawn_agent(&mut self, slot: usize, restarted: bool) -> Result<()> {
        let logs = self.config.out.join("logs");
        let (name, log) = match self.restarts[slot] {
            0 => (format!("UAV{}", slot + 1), logs.join(format!("uav{}.log", slot + 1))),
            n => (
                format!("UAV{} (restart {n})", slot + 1),
                logs.join(format!("uav{}.restart{n}.log", slot + 1)),
            ),
        };
        let command = agent_command(self.config, slot, restarted)?;
        let process = Process::spawn(&name, command, &log)?;
        self.agents.push(AgentProcess { process, slot, seat: Seat::Waiting, noted: false });
        Ok(())
    }

    /// Records the episode reports the world has sent, and follows through its changes of
    /// membership where each agent process stands in the barrier; then redraws the progress,
    /// so the bar shows what every drain found, the last one too.
    fn record_reports(&mut self, ports: &SupervisorPorts, recorder: &mut Recorder) -> Result<()> {
        while let Some(next) = ports.try_next()? {
            match next {
                FromWorld::Episode(report) => recorder.record(&report)?,
                FromWorld::Membership(membership) => {
                    recorder.set_live(membership.count());
                    for agent in &mut self.agents {
                        let held = membership.holds(agent.slot, agent.process.pid());
                        agent.seat = agent.seat.after(held);
                    }
                    let own = |pid| self.agents.iter().any(|a| a.process.pid() == pid);
                    let (came, left) = attached_changes(&self.membership, &membership, own);
                    for (slot, pid) in came {
                        recorder.say(&format!("UAV{} attached (process {pid})", slot + 1));
                    }
                    for (slot, pid) in left {
                        recorder.note(format!("UAV{} (attached, process {pid}) left", slot + 1));
                    }
                    self.membership = membership;
                }
            }
        }
        recorder.redraw();
        Ok(())
    }

    /// Brings down the agent processes the world dropped while they still run: it drops an
    /// agent whose process is gone or that stayed silent past `--agent-timeout-ms`, so a
    /// dropped process that runs is hung (SPEC 4: presumed dead). Once it has exited it is a
    /// failed agent like any other, reported and, if asked, restarted. Those being brought
    /// down are taken a step further (SIGKILL after SIGTERM's grace). Also once the run
    /// stops: a dropped agent is outside the barrier, with no last answer to give.
    fn bring_down_dropped(&mut self) -> Result<()> {
        for agent in &mut self.agents {
            if agent.to_bring_down() && agent.process.status()?.is_none() {
                agent.process.bring_down();
            }
        }
        Ok(())
    }

    /// Brings down the agent processes `which` picks, once the world has exited: dropped
    /// ones (see [`Fleet::bring_down_dropped`]) would not leave by themselves, and the
    /// shutdown ladder would first give them its grace. Bounded ([`bring_all_down`]), then
    /// they are left to the ladder.
    fn bring_agents_down(&mut self, which: fn(&AgentProcess) -> bool) -> Result<()> {
        let mut due: Vec<&mut Process> =
            self.agents.iter_mut().filter(|a| which(a)).map(|a| &mut a.process).collect();
        bring_all_down(&mut due)?;
        Ok(())
    }

    /// Records episode reports until the world exits; asks it to stop on Ctrl-C; reports
    /// and, if asked, restarts failed agents. An agent that fails in the stop round, where it
    /// writes its final Q-tables, fails the world and so the run (an in-process run that
    /// cannot write them fails the same way).
    fn supervise(
        &mut self,
        ports: &SupervisorPorts,
        recorder: &mut Recorder,
        stop: &Interrupts,
    ) -> Result<Outcome> {
        // Everything told to the world so far; each message repeats it all.
        let mut control = Control::default();
        // Named when the world fails: its "every agent is gone" says nothing of why.
        let mut first_failure: Option<String> = None;
        // When a world asked to stop must have ended the run (see `stop_bound`).
        let mut stop_deadline: Option<Instant> = None;
        let mut stopped_at_once: Option<&str> = None;
        loop {
            self.record_reports(ports, recorder)?;
            if stop.stop_asked() && control.stop == 0 {
                control.stop = 1;
                ports.send_control(&control)?;
                stop_deadline = Some(Instant::now() + self.stop_bound());
                // The stop round waits for every agent's final tables: up to 30 s for one
                // that hangs, so say what is going on.
                recorder.say(
                    "stopping: every agent saves its Q-tables in the next round (Ctrl-C or \
                     SIGTERM again to stop at once)",
                );
            }
            if self.ctrl_z.requested() {
                let paused = self.pause(recorder)?;
                // The stop round did not go on meanwhile.
                stop_deadline = stop_deadline.map(|deadline| deadline + paused);
            }
            if stopped_at_once.is_none() {
                stopped_at_once = if stop.hurry_asked() {
                    Some("stopped at once by a second Ctrl-C or SIGTERM")
                } else if stop_deadline.is_some_and(|deadline| Instant::now() >= deadline) {
                    Some("stopped at once: the world had not ended the stop round in time")
                } else {
                    None
                };
            }
            // Once the world has ended by itself, the run ends as it would have.
            if let Some(why) = stopped_at_once {
                if self.world.status()?.is_none() {
                    if !self.world.brought_down() {
                        recorder.say(&format!(
                            "{why}: every process is told to leave now (an agent saves its \
                             Q-tables as it leaves)"
                        ));
                    }
                    self.hurry()?;
                }
            }
            if let Some(status) = self.world.status()? {
                self.record_reports(ports, recorder)?;
                if self.world.brought_down() {
                    let why = stopped_at_once.unwrap_or("stopped at once");
                    return self.finish_hurrying(status, why, recorder);
                }
                if !status.success() {
                    // An agent may have failed since the last look, and be why the world did.
                    let late = self.newly_failed_agents()?;
                    let first = first_failure.or_else(|| late.first().map(|(_, n)| n.clone()));
                    let cause = first.map_or_else(String::new, |n| format!("; first to fail: {n}"));
                    bail!(
                        "the world process failed ({status}): {}{cause}",
                        self.world.last_words()
                    );
                }
                self.bring_agents_down(AgentProcess::to_bring_down)?;
                for (_, note) in self.newly_failed_agents()? {
                    recorder.note(format!("{note}; not restarted (the run has ended)"));
                }
                return Ok(Outcome { complete: control.stop == 0, peak_rss_kib: vec![] });
            }
            if stopped_at_once.is_some() {
                // Every process is being brought down: none failed, none is restarted.
                ports.waiter().sleep(DRAIN_EVERY)?;
                continue;
            }
            self.bring_down_dropped()?;
            for (slot, note) in self.newly_failed_agents()? {
                first_failure.get_or_insert_with(|| note.clone());
                let restart = self.config.restart == Restart::OnFailure
                    && control.stop == 0
                    && self.restarts[slot] < MAX_RESTARTS;
                if restart {
                    recorder.note(note);
                    self.restarts[slot] += 1;
                    // Before the new agent starts: these are the snapshots it reads.
                    let note = restart_note(self.config, slot);
                    self.spawn_agent(slot, true)?;
                    recorder.note(note);
                } else {
                    let why = if control.stop == 1 {
                        "the run is stopping".to_string()
                    } else if self.config.restart == Restart::Never {
                        "--restart never".to_string()
                    } else {
                        format!("restarted {MAX_RESTARTS} times already")
                    };
                    recorder.note(format!("{note}; not restarted ({why})"));
                    control.gone |= 1 << slot;
                    ports.send_control(&control)?;
                }
            }
            // Sleeps rather than polls: waking up for each record made the supervisor yield
            // the CPU dozens of times per record, CPU the world and the agents need.
            ports.waiter().sleep(DRAIN_EVERY)?;
        }
    }

    /// Every process of the run: the world, then the agents in the order they were started.
    fn processes(&mut self) -> impl Iterator<Item = &mut Process> {
        std::iter::once(&mut self.world).chain(self.agents.iter_mut().map(|a| &mut a.process))
    }

    /// How long a world asked to stop may take to end the run: the round under way (each
    /// agent's answer may take `--agent-timeout-ms`), the stop round (the agents' final
    /// tables, [`STOP_ROUND_WAIT`] at least) and the last records (the world's
    /// [`REPORT_TIMEOUT`]), and [`STOP_SPARE`]. Past it the world is taken for hung (stopped
    /// by someone, or stuck) and the run is stopped at once, as by a second Ctrl-C: a single
    /// SIGTERM to the supervisor must end the run.
    fn stop_bound(&self) -> Duration {
        let agent_timeout = Duration::from_millis(self.config.agent_timeout_ms);
        agent_timeout + agent_timeout.max(STOP_ROUND_WAIT) + REPORT_TIMEOUT + STOP_SPARE
    }

    /// Ctrl-Z: stops the world and the agents, then the supervisor itself; once continued,
    /// continues the agents, then the world (see [`crate::suspend`]), and notes the pause
    /// (the run's timings include it). Returns how long the run was paused.
    fn pause(&mut self, recorder: &mut Recorder) -> Result<Duration> {
        // Continued before it took effect (`kill -TSTP` then `kill -CONT` at once): no pause.
        if self.ctrl_z.continued() {
            return Ok(Duration::ZERO);
        }
        recorder.say("pausing (Ctrl-Z): the world and the agents stop with the supervisor");
        self.each_running(|process| process.pause())?;
        let paused = self.ctrl_z.stop_self();
        let processes: Vec<&mut Process> = self.processes().collect();
        for process in processes.iter().rev() {
            process.resume();
        }
        if let Some(paused) = paused {
            recorder.note(format!(
                "paused for {:.1} s by Ctrl-Z (the timings include it)",
                paused.as_secs_f64()
            ));
        }
        Ok(paused.unwrap_or_default())
    }

    /// Takes every process that still runs a step down the shutdown ladder, without the stop
    /// round (a second Ctrl-C, while the world runs): the world leaves at once; an agent
    /// leaves at its next wait and saves its tables first (or, hung, gets SIGKILL after
    /// SIGTERM's grace).
    fn hurry(&mut self) -> Result<()> {
        self.each_running(Process::bring_down)
    }

    /// Takes `step` on every process of the run that still runs.
    fn each_running(&mut self, step: fn(&mut Process)) -> Result<()> {
        for process in self.processes() {
            if process.status()?.is_none() {
                step(process);
            }
        }
        Ok(())
    }

    /// Ends a run stopped at once (`why`), once the world has left (`world`, its exit):
    /// brings the agents down and notes how each one that had not already failed left, with
    /// its last words (where its tables are, or why they are not), and a world that failed
    /// by itself rather than leave as asked.
    fn finish_hurrying(
        &mut self,
        world: ExitStatus,
        why: &str,
        recorder: &mut Recorder,
    ) -> Result<Outcome> {
        self.bring_agents_down(|_| true)?;
        recorder.note(format!(
            "{why}: the processes left without the stop round, each at its next wait"
        ));
        // Or it finished the run just as it was told to leave.
        let left_as_asked = world.success()
            || world.code() == Some(EXIT_TERMINATED.into())
            || matches!(world.signal(), Some(libc::SIGTERM | libc::SIGKILL));
        if !left_as_asked {
            recorder
                .note(format!("the world process failed ({world}): {}", self.world.last_words()));
        }
        for AgentProcess { process, noted, .. } in &mut self.agents {
            let Some(status) = process.status()? else { continue };
            if !status.success() && !*noted {
                *noted = true;
                recorder.note(format!(
                    "{} left ({status}): {}",
                    process.name,
                    process.last_words()
                ));
            }
        }
        Ok(Outcome { complete: false, peak_rss_kib: vec![] })
    }

    /// The agent processes that failed since the last call, with their slot and a note
    /// naming the process and how it ended: its exit and last words, or, for one brought
    /// down because the world dropped it, that. One that left because the world was gone
    /// ([`EXIT_WORLD_GONE`]) did not fail once the world has ended.
    fn newly_failed_agents(&mut self) -> Result<Vec<(usize, String)>> {
        let mut failed = Vec::new();
        for AgentProcess { process, slot, noted, .. } in &mut self.agents {
            let Some(status) = process.status()? else { continue };
            if (status.success() && !process.brought_down()) || *noted {
                continue;
            }
            *noted = true;
            // It left because the world had: the world's end is the news. Looked at after
            // the agent's exit, which comes after the world's.
            let left_with_world = status.code() == Some(EXIT_WORLD_GONE.into())
                && !process.brought_down()
                && self.world.status()?.is_some();
            if left_with_world {
                continue;
            }
            let note = if process.brought_down() {
                format!(
                    "{} was dropped by the world: silent past the deadline (--agent-timeout-ms \
                     {}); the supervisor stopped it ({status})",
                    process.name, self.config.agent_timeout_ms
                )
            } else {
                format!("{} failed ({status}): {}", process.name, process.last_words())
            };
            failed.push((*slot, note));
        }
        Ok(failed)
    }
}

/// Attached agents as (slot, process id).
type Attached = Vec<(usize, u32)>;

/// The agents that attached and those that left between memberships `before` and `after`:
/// every process that held a slot and is not one of the supervisor's own (`own`).
fn attached_changes(
    before: &Membership,
    after: &Membership,
    own: impl Fn(u32) -> bool,
) -> (Attached, Attached) {
    let holder = |m: &Membership, slot: usize| {
        let pid = m.pids[slot];
        (m.live >> slot & 1 == 1 && pid != 0 && !own(pid)).then_some(pid)
    };
    let (mut came, mut left) = (Vec::new(), Vec::new());
    for slot in 0..MAX_AGENTS {
        let (was, is) = (holder(before, slot), holder(after, slot));
        if was != is {
            left.extend(was.map(|pid| (slot, pid)));
            came.extend(is.map(|pid| (slot, pid)));
        }
    }
    (came, left)
}

/// What a restart of agent `slot` goes on from: its latest snapshots in `--out`, read as the
/// agent reads them. Trials that have none (no `--resume`, and the agent failed before its
/// first `--snapshot-every`) start again from empty tables, and the note says so; one whose
/// snapshot cannot be read makes the restarted agent fail, and the note says why.
fn restart_note(config: &RunConfig, slot: usize) -> String {
    let mut fresh = Vec::new();
    let mut unreadable = Vec::new();
    for trial in 0..config.trials {
        match read_snapshot(&snapshot_path(&config.out, slot, trial)) {
            Ok(Some(_)) => {}
            Ok(None) => fresh.push(trial.to_string()),
            Err(e) => unreadable.push(e.to_string()),
        }
    }
    let mut note = format!("UAV{} restarted from its latest snapshot", slot + 1);
    if !fresh.is_empty() {
        note +=
            &format!("; trial(s) {} had none yet and start from empty tables", fresh.join(", "));
    }
    if !unreadable.is_empty() {
        note += &format!("; it will fail on {}", unreadable.join("; "));
    }
    note
}

/// The supervisor drains the world's episode records at least this often; the world also
/// wakes it once per `EPISODE_WAKE_EVERY` records, well before its buffer fills.
const DRAIN_EVERY: Duration = Duration::from_millis(10);

/// A command running this executable in `role` (the supervisor is also the world and the
/// agent program, see [`crate::main`]).
fn own_executable(role: &str) -> Result<Command> {
    let mut command = Command::new(own_path()?);
    command.arg(role);
    Ok(command)
}

/// The path of this executable.
fn own_path() -> Result<PathBuf> {
    std::env::current_exe().context("cannot find the supervisor's own executable")
}

fn world_command(config: &RunConfig) -> Result<Command> {
    let mut command = own_executable(crate::ROLE_WORLD)?;
    command
        .arg("--run-id")
        .arg(&config.run_id)
        .args(["--uavs", &config.uavs.to_string()])
        .args(["--episodes", &config.episodes.train_episodes.to_string()])
        .args(["--eval-episodes", &config.episodes.eval_episodes.to_string()])
        .args(["--eval-every", &config.episodes.eval_every.to_string()])
        .args(["--eval-block", &config.episodes.eval_block.to_string()])
        .args(["--tick-cap", &config.episodes.tick_cap.to_string()])
        .args(["--agent-timeout-ms", &config.agent_timeout_ms.to_string()]);
    shared_args(&mut command, config);
    Ok(command)
}

fn agent_command(config: &RunConfig, slot: usize, restarted: bool) -> Result<Command> {
    let mut command = own_executable(crate::ROLE_AGENT)?;
    command
        .arg("run")
        .arg("--run-id")
        .arg(&config.run_id)
        .args(["--uav", &(slot + 1).to_string()])
        .args(["--snapshot-every", &config.snapshot_every.to_string()])
        .arg("--out")
        .arg(&config.out);
    shared_args(&mut command, config);
    if let Some(bt) = &config.bt_path {
        command.arg("--bt").arg(bt);
    }
    // A restarted agent goes on from its own latest snapshot in `--out`, where a resumed run
    // also finds the ones it resumes from (copied there before any process starts).
    if restarted || config.resume.is_some() {
        command.arg("--resume").arg(&config.out);
    }
    if let Some(dir) = &config.trace_dir {
        command.arg("--trace").arg(trace_path(dir, slot));
    }
    // A fault is injected once: a restarted agent behaves.
    if let Some((_, fault)) = config.faults.iter().find(|(s, _)| *s == slot).filter(|_| !restarted)
    {
        command.args(["--fault", fault]);
    }
    Ok(command)
}

/// The arguments the world and every agent take alike: what the run simulates and learns,
/// and the supervisor's pid (`--parent-pid`).
fn shared_args(command: &mut Command, config: &RunConfig) {
    command
        .arg("--scenario")
        .arg(&config.scenario_arg)
        .args(["--trials", &config.trials.to_string()])
        .args(["--seed", &config.seed.to_string()])
        .args(["--comm", config.comm.name()])
        .args(["--alpha", &config.params.alpha.to_string()])
        .args(["--gamma", &config.params.gamma.to_string()])
        .args(["--epsilon", &config.params.epsilon.to_string()])
        .args(["--parent-pid", &std::process::id().to_string()]);
}

/// Where agent `slot` writes its `--trace-dir` trace.
fn trace_path(dir: &Path, slot: usize) -> PathBuf {
    dir.join(format!("uav{}.trace.csv", slot + 1))
}

/// Creates the (empty) trace files the agents will write, so a directory that cannot hold
/// them is an error before any process starts rather than agents failing in the run.
fn create_trace_files(dir: &Path, uavs: usize) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("--trace-dir: cannot create {}", dir.display()))?;
    for slot in 0..uavs {
        let path = trace_path(dir, slot);
        std::fs::File::create(&path)
            .with_context(|| format!("--trace-dir: cannot create {}", path.display()))?;
    }
    Ok(())
}

/// Opens the run once the world has created it; fails at once if the world dies first.
fn open_ports(config: &RunConfig, world: &mut Process) -> Result<SupervisorPorts> {
    let deadline = Instant::now() + WORLD_START;
    loop {
        let mut identity = RunIdentity::new(&config.run_id, SignalMode::Untouched);
        identity.open_timeout = Duration::from_millis(100);
        match RunServices::open(&identity).and_then(RunServices::into_supervisor) {
            Ok(ports) => return Ok(ports),
            Err(
                TransportError::ServiceMissing { .. } | TransportError::PublisherMissing { .. },
            ) => {}
            Err(e) => return Err(e.into()),
        }
        if let Some(status) = world.status()? {
            bail!(
                "the world process exited ({status}) before the run started: {}",
                world.last_words()
            );
        }
        // The open's own error would name its own 100 ms.
        if Instant::now() >= deadline {
            bail!(
                "the world process had not created the run's services {} s after it started: {}",
                WORLD_START.as_secs(),
                world.last_words()
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{attached_changes, Seat};
    use flockstep_proto::Membership;

    /// A membership of `(slot, pid)`s.
    fn members(held: &[(usize, u32)]) -> Membership {
        let mut membership = Membership::default();
        for &(slot, pid) in held {
            membership.live |= 1 << slot;
            membership.pids[slot] = pid;
        }
        membership
    }

    #[test]
    fn attached_agents_are_told_apart_from_the_supervisors_own_as_they_come_and_go() {
        let own = |pid| pid == 11 || pid == 12;
        let start = members(&[(0, 11), (1, 12)]);
        let attached = members(&[(0, 11), (1, 12), (2, 30)]);
        assert_eq!(attached_changes(&start, &attached, own), (vec![(2, 30)], vec![]));
        // The attached agent leaves; the own agent of slot 0 is dropped: not an attached one.
        let after = members(&[(1, 12)]);
        assert_eq!(attached_changes(&attached, &after, own), (vec![], vec![(2, 30)]));
        // Another process takes an own agent's route while its restart waits.
        let taken = members(&[(0, 31), (1, 12)]);
        assert_eq!(attached_changes(&after, &taken, own), (vec![(0, 31)], vec![]));
        let swapped = members(&[(0, 32), (1, 12)]);
        assert_eq!(attached_changes(&taken, &swapped, own), (vec![(0, 32)], vec![(0, 31)]));
    }

    /// Where a process that starts waiting stands after changes of membership that name it
    /// (`true`) or not (`false`) in turn.
    fn after(held: &[bool]) -> Seat {
        held.iter().fold(Seat::Waiting, |seat, &held| seat.after(held))
    }

    #[test]
    fn an_agent_is_admitted_when_the_world_names_it_and_dropped_when_it_no_longer_does() {
        assert_eq!(after(&[]), Seat::Waiting);
        assert_eq!(after(&[false, false]), Seat::Waiting, "another process holds the slot");
        assert_eq!(after(&[false, true]), Seat::InBarrier);
        assert_eq!(after(&[true, true, false]), Seat::Dropped);
        assert_eq!(after(&[true, false, true]), Seat::Dropped, "a drop is for good");
    }
}
