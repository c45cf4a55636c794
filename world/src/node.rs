//! The `world` process: owns a run's services, the barrier, the membership and the ground
//! truth.
//!
//! Each round it admits agents that asked to join, publishes the observation of every
//! trial, waits until every live agent has answered that round, applies the actions, and
//! hands finished episodes to the supervisor. An agent whose process is gone, or that stays
//! silent past `--agent-timeout-ms`, is dropped from the barrier and the run goes on. It
//! drives the same [`World`] as the in-process runner; only the message passing differs.
//! `docs/MEMBERSHIP.md` describes the protocol and the failure model.

use crate::scenario::Scenario;
use crate::sim::{EpisodeConfig, World};
use anyhow::{bail, Context, Result};
use clap::Parser;
use flockstep_proto::supervisor_to_world::Control;
use flockstep_proto::transport::{
    cleanup_run, exit_with_parent, process_stat, RunConfig, RunServices, SenderNode, SignalMode,
    TransportError, WorldPorts, LOOK_FOR_GONE_AGENTS,
};
use flockstep_proto::{
    slots_in, JoinRequest, Membership, ObservationKind, Refusal, RunInfo, ANY_SLOT, MAX_AGENTS,
    SCENARIO_BYTES,
};
use std::sync::Arc;
use std::time::{Duration, Instant};

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
    /// s1, s2, s3, gen:... or a path to a .map file.
    #[arg(long)]
    pub scenario: String,
    /// Agents that start with the run (slots 1..=N); more may attach later.
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
    #[arg(long, default_value_t = 0)]
    pub eval_every: u64,
    #[arg(long, default_value_t = 0)]
    pub eval_block: u64,
    #[arg(long)]
    pub tick_cap: u32,
    /// The run's communication mode and learning parameters, told to attaching agents.
    #[arg(long)]
    pub comm: String,
    #[arg(long)]
    pub alpha: f64,
    #[arg(long)]
    pub gamma: f64,
    #[arg(long)]
    pub epsilon: f64,
    /// An agent silent this long within a round is presumed dead (a crashed agent is
    /// noticed sooner: its process is watched).
    #[arg(long, default_value_t = 500)]
    pub agent_timeout_ms: u64,
    /// How long to wait for the starting agents and the supervisor to connect.
    #[arg(long, default_value_t = 30_000)]
    pub startup_timeout_ms: u64,
    /// Exit when this process (the supervisor) is gone.
    #[arg(long)]
    pub parent_pid: Option<u32>,
}

/// The `world` process: `args` are its command line (program name first).
pub fn main(args: impl IntoIterator<Item = std::ffi::OsString>) -> std::process::ExitCode {
    flockstep_proto::logging::init("info");
    match run(&WorldArgs::parse_from(args)) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            flockstep_proto::output::message(&format!("world: error: {e:#}"));
            if flockstep_proto::transport::termination_requested() {
                std::process::ExitCode::from(EXIT_TERMINATED)
            } else {
                std::process::ExitCode::FAILURE
            }
        }
    }
}

/// The world's exit status when it left because SIGTERM asked it to (128 + SIGTERM, as a
/// shell reports a process SIGTERM ended): the supervisor tells a world it brought down from
/// one that failed by itself.
pub const EXIT_TERMINATED: u8 = 143;

/// The least the world waits for the agents' answers to the stop round: each answers once
/// its final Q-tables are written.
pub const STOP_ROUND_WAIT: Duration = Duration::from_secs(30);

pub fn run(args: &WorldArgs) -> Result<()> {
    let run = RunConfig::new(&args.run_id, SignalMode::Supervised);
    if let Some(parent) = args.parent_pid {
        exit_with_parent(parent)?;
    }
    let scenario =
        Scenario::resolve(&args.scenario).map_err(|e| anyhow::anyhow!("--scenario: {e}"))?;
    let config = EpisodeConfig {
        train_episodes: args.episodes,
        eval_episodes: args.eval_episodes,
        eval_every: args.eval_every,
        eval_block: args.eval_block,
        tick_cap: args.tick_cap,
    };
    let world = World::new(Arc::new(scenario), args.uavs, args.trials, args.seed, config)?;
    // A world started by hand has no supervisor to sweep before it (`supervisor::shm::prepare`):
    // what a killed world of its run id left, its services among them, would read as a live
    // run's. A live run's services stay, and creating them then fails. Best effort: what
    // cannot be removed shows as the create's own error.
    if args.parent_pid.is_none() {
        if let Err(e) = cleanup_run(&run.run_id) {
            tracing::warn!(
                "could not remove what earlier processes of run `{}` left: {e}",
                run.run_id
            );
        }
    }
    let ports = RunServices::create(&run)?.into_world()?;
    ports.publish_run_info(&run_info(args)?)?;
    let startup = Duration::from_millis(args.startup_timeout_ms);
    ports.wait_for_peers(0, true, startup)?;
    let mut node = WorldNode {
        world,
        ports,
        members: Members::default(),
        agent_timeout: Duration::from_millis(args.agent_timeout_ms),
        supervisor: args.parent_pid,
    };
    let stop_requested = node.await_starting_agents(args.uavs, startup)?;
    node.barrier(stop_requested)
}

fn run_info(args: &WorldArgs) -> Result<RunInfo> {
    Ok(RunInfo {
        scenario: RunInfo::pack(&args.scenario)
            .with_context(|| format!("--scenario is longer than {SCENARIO_BYTES} bytes"))?,
        seed: args.seed,
        trials: args.trials as u32,
        comm: RunInfo::pack(&args.comm).context("--comm is longer than 16 bytes")?,
        alpha: args.alpha,
        gamma: args.gamma,
        epsilon: args.epsilon,
    })
}

/// Who holds which slot: the nonce of its join request, and the iceoryx2 node that sent the
/// request, the only one whose actions answer for the slot (and whose process is watched).
#[derive(Debug)]
struct Members {
    owners: [u64; MAX_AGENTS],
    nodes: [Option<SenderNode>; MAX_AGENTS],
    /// Join requests read and not yet answered: the next round answers them.
    waiting: Vec<(JoinRequest, SenderNode)>,
    /// The last join request refused, and why: every round tells its sender until the next
    /// requests are read (a millisecond, hundreds of rounds), since the observation service
    /// keeps only the newest rounds and an agent preempted for a few rounds would miss a
    /// single one. One at a time: another refused request is answered when it is repeated.
    refused: Option<(u64, Refusal)>,
}

impl Members {
    /// Agents repeat their join request until they see it answered: a repeat of a request
    /// already admitted is not a new one.
    fn is_repeat(&self, request: &JoinRequest) -> bool {
        request.nonce != 0 && self.owners.contains(&request.nonce)
    }

    /// Gives `slot` to the agent that sent `request` from `node`.
    fn seat(&mut self, slot: usize, request: &JoinRequest, node: SenderNode) {
        self.owners[slot] = request.nonce;
        self.nodes[slot] = Some(node);
    }

    /// Frees `slot`.
    fn vacate(&mut self, slot: usize) {
        self.owners[slot] = 0;
        self.nodes[slot] = None;
    }

    /// The process of `slot`'s agent; 0 if unknown, which leaves its death to the deadline.
    fn pid(&self, slot: usize) -> u32 {
        self.nodes[slot].and_then(|node| node.pid()).unwrap_or(0)
    }
}

impl Default for Members {
    fn default() -> Self {
        Members {
            owners: [0; MAX_AGENTS],
            nodes: [None; MAX_AGENTS],
            waiting: Vec::new(),
            refused: None,
        }
    }
}

struct WorldNode {
    world: World,
    ports: WorldPorts,
    members: Members,
    agent_timeout: Duration,
    /// The supervisor's process id (`--parent-pid`): control commands count from it only.
    supervisor: Option<u32>,
}

/// The next control command sent by the supervisor's process, if any; commands from any
/// other process are logged and skipped. Without a known supervisor every command counts.
fn next_control(
    ports: &WorldPorts,
    supervisor: Option<u32>,
) -> Result<Option<Control>, TransportError> {
    while let Some((control, sender)) = ports.try_control()? {
        match (supervisor, sender.pid()) {
            (Some(expected), pid) if pid != Some(expected) => {
                tracing::warn!(?pid, "ignored a control command from a process not the supervisor");
            }
            _ => return Ok(Some(control)),
        }
    }
    Ok(None)
}

impl WorldNode {
    /// Waits until each agent the supervisor starts (slots 0..uavs) has asked to join, or
    /// the supervisor says its process ended before it did: the run goes on without those,
    /// and their routes stay free for agents that attach. A starting slot goes only to a
    /// child of the supervisor ([`started_by`]); any other request waits for the first
    /// round. Returns whether the supervisor asked to stop meanwhile.
    fn await_starting_agents(&mut self, uavs: usize, timeout: Duration) -> Result<bool> {
        let Self { ports, members, supervisor, .. } = self;
        let (mut gone, mut stop) = (0u64, false);
        ports.waiter().wait(
            &format_args!("the join requests of the {uavs} starting agents"),
            timeout,
            || {
                while let Some((request, node)) = ports.try_join()? {
                    let slot = request.slot as usize;
                    if members.is_repeat(&request) {
                        continue;
                    }
                    let starting = request.nonce != 0 && slot < uavs && members.owners[slot] == 0;
                    if starting && started_by(*supervisor, node) {
                        members.seat(slot, &request, node);
                    } else {
                        if starting {
                            tracing::warn!(
                                uav = slot + 1,
                                pid = ?node.pid(),
                                "a join request for a slot the supervisor starts an agent on \
                                 came from a process it did not start: it is answered as an \
                                 attaching agent's, once the run is under way"
                            );
                        }
                        members.waiting.push((request, node));
                    }
                }
                while let Some(control) = next_control(ports, *supervisor)? {
                    gone |= control.gone;
                    stop |= control.stop == 1;
                }
                let settled = |slot: usize| members.owners[slot] != 0 || gone & (1 << slot) != 0;
                Ok((0..uavs).all(settled).then_some(()))
            },
        )?;
        for slot in (0..uavs).filter(|&slot| self.members.owners[slot] == 0) {
            tracing::warn!(uav = slot + 1, "its process ended before it asked to join");
            self.world.remove(slot);
        }
        self.tell_membership()?;
        if self.world.live() == 0 {
            bail!("every starting agent ended before it asked to join: the run cannot go on");
        }
        Ok(stop)
    }

    /// Answers the join requests read so far: the route asked for, or with [`ANY_SLOT`] the
    /// first free one, from the next round on; or a refusal that says why (no such route,
    /// route taken, none free). The trials let the agent in at their next episode start.
    fn admit_joiners(&mut self) -> Result<()> {
        if !self.members.waiting.is_empty() {
            self.members.refused = None;
        }
        let mut admitted = false;
        for (request, node) in std::mem::take(&mut self.members.waiting) {
            if self.members.is_repeat(&request) {
                continue;
            }
            if request.nonce == 0 {
                tracing::warn!(pid = ?node.pid(), "ignored a join request with a zero nonce");
                continue;
            }
            let wanted = (request.slot != ANY_SLOT).then_some(request.slot as usize);
            match self.world.free_slot(wanted) {
                Ok(slot) => {
                    self.world.admit(slot);
                    self.members.seat(slot, &request, node);
                    admitted = true;
                    tracing::info!(
                        uav = slot + 1,
                        pid = ?node.pid(),
                        "agent admitted; it joins each trial at its next episode"
                    );
                }
                Err(why) => {
                    self.members.refused = Some((request.nonce, why));
                    tracing::warn!(pid = ?node.pid(), slot = request.slot, "join refused: {why}");
                }
            }
            // An attaching agent subscribed to the run's description after it was published.
            self.ports.serve_run_info()?;
        }
        if admitted {
            self.tell_membership()?;
        }
        Ok(())
    }

    /// Tells the supervisor who is in the barrier now, with the process of each agent: it
    /// follows its own processes by this (admitted, or dropped while still running).
    fn tell_membership(&mut self) -> Result<()> {
        let mut membership = Membership { live: self.world.live(), ..Membership::default() };
        for slot in slots_in(membership.live) {
            membership.pids[slot] = self.members.pid(slot);
        }
        Ok(self.ports.set_membership(&membership)?)
    }

    /// Drops agent `slot` from the barrier and every trial.
    fn drop_agent(&mut self, slot: usize, why: &str) -> Result<()> {
        tracing::warn!(
            uav = slot + 1,
            pid = self.members.pid(slot),
            "agent dropped from the run: {why}"
        );
        self.world.remove(slot);
        self.members.vacate(slot);
        let cleaned = self.ports.services().cleanup_dead_nodes();
        if cleaned > 0 {
            tracing::info!(nodes = cleaned, "removed the resources of dead nodes");
        }
        self.tell_membership()
    }

    /// Runs rounds until every trial is done or the supervisor asks to stop (`stop_requested`:
    /// it already has), then tells the agents to stop and waits for each one's last answer
    /// (its snapshots are written then).
    ///
    /// Between publishing a round and the first answer the world has nothing to do, so what
    /// does not shape the round waits for then: the episode records of the round before, and
    /// reading join requests and control commands (acted on in the next round). Those are
    /// rare, and each look costs two reads of iceoryx2 queues, so the world looks once per
    /// [`LOOK_FOR_REQUESTS_EVERY`], not every round, and sends the records it queued then.
    /// Whatever ends the rounds, the queued records are sent: a failed run keeps them too.
    fn barrier(&mut self, stop_requested: bool) -> Result<()> {
        let rounds = self.rounds(stop_requested);
        // Unless a stalled supervisor is what failed: sending again would only wait again.
        let stalled = rounds
            .as_ref()
            .err()
            .and_then(|e| e.downcast_ref::<TransportError>())
            .is_some_and(|e| matches!(e, TransportError::ReportsStalled { .. }));
        let flushed = if stalled { Ok(()) } else { self.ports.flush_episodes() };
        rounds?;
        Ok(flushed?)
    }

    fn rounds(&mut self, mut stop_requested: bool) -> Result<()> {
        let mut reports = Vec::new();
        let mut last_look = Instant::now();
        loop {
            self.admit_joiners()?;
            let Self { world, ports, members, .. } = &mut *self;
            let mut round = Round::default();
            ports.publish_observation(|observation| {
                world.observe(observation);
                let slots = observation.n_slots as usize;
                observation.owners[..slots].copy_from_slice(&members.owners[..slots]);
                let (nonce, why) = members.refused.map_or((0, 0), |(n, why)| (n, why as u8));
                observation.refused_nonce = nonce;
                observation.refusal = why;
                if stop_requested {
                    observation.kind = ObservationKind::Stop as u8;
                }
                round = Round {
                    number: observation.round,
                    live: observation.live,
                    kind: observation.kind,
                };
            })?;
            for report in reports.drain(..) {
                self.ports.queue_episode(&report)?;
            }
            if round.number.is_multiple_of(ROUNDS_BETWEEN_CLOCK_READS)
                && last_look.elapsed() >= LOOK_FOR_REQUESTS_EVERY
            {
                last_look = Instant::now();
                self.ports.flush_episodes()?;
                while let Some(joiner) = self.ports.try_join()? {
                    self.members.waiting.push(joiner);
                }
                while let Some(control) = next_control(&self.ports, self.supervisor)? {
                    stop_requested |= control.stop == 1;
                }
            }
            let stopping = round.kind == ObservationKind::Stop as u8;
            // The agents' last answer comes after their snapshots: allow for writing them.
            let timeout =
                if stopping { self.agent_timeout.max(STOP_ROUND_WAIT) } else { self.agent_timeout };
            let answered = self.collect_actions(round, timeout, !stopping)?;
            if stopping {
                // An agent answers the stop round once its final snapshots are written: one
                // that did not (gone, or silent past the timeout) lost them, and so the run.
                let missing: Vec<String> = slots_in(round.live & !answered.answered)
                    .map(|slot| format!("UAV{}", slot + 1))
                    .collect();
                anyhow::ensure!(
                    missing.is_empty(),
                    "final Q-tables may not be saved: {} did not answer the stop round (process \
                     gone, or silent for {timeout:?})",
                    missing.join(", ")
                );
                return Ok(());
            }
            for slot in slots_in(round.live & !answered.answered) {
                let why = if answered.gone & (1 << slot) != 0 {
                    "its process is gone"
                } else {
                    "silent past the deadline"
                };
                self.drop_agent(slot, why)?;
            }
            if self.world.live() == 0 {
                bail!("every agent is gone: the run cannot go on");
            }
            self.world.end_round(&mut reports);
        }
    }

    /// Waits for the answer of every live agent to `this_round` and applies them
    /// (unless `apply` is false: the answers to a stop). Answers to other rounds, from slots
    /// not in the barrier, sent by a process other than the one admitted to their slot, or
    /// that fail the checks are logged and dropped. Ends early when
    /// every agent still missing is known to be dead; ends at `timeout` otherwise.
    fn collect_actions(
        &mut self,
        this_round: Round,
        timeout: Duration,
        apply: bool,
    ) -> Result<Answers> {
        let Self { world, ports, members, .. } = self;
        let (round, live) = (this_round.number, this_round.live);
        // Rounds take microseconds: only a round this slow is worth a look at processes.
        let mut overdue =
            ports.waiter().overdue_after(LOOK_FOR_GONE_AGENTS.0, LOOK_FOR_GONE_AGENTS.1);
        let mut answers = Answers::default();
        let waited =
            ports.waiter().wait(&format_args!("the answers of round {round}"), timeout, || {
                while let Some(action) = ports.try_action()? {
                    action.prefetch_used();
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
                    // Checked before the second-answer check, so a copy sent first cannot
                    // shut out the agent's own answer.
                    if Some(SenderNode::of(&action)) != members.nodes[slot] {
                        tracing::warn!(
                            round,
                            uav = slot + 1,
                            "dropped an action sent for this agent by another process"
                        );
                        continue;
                    }
                    if answers.answered & (1 << slot) != 0 {
                        tracing::warn!(
                            round,
                            uav = slot + 1,
                            "dropped a second action of one agent in one round"
                        );
                        continue;
                    }
                    if apply {
                        if let Err(e) = world.apply(&action) {
                            tracing::warn!(round, uav = slot + 1, "dropped an invalid action: {e}");
                            continue;
                        }
                    }
                    answers.answered |= 1 << slot;
                }
                let missing = live & !answers.answered;
                if missing == 0 {
                    return Ok(Some(()));
                }
                if overdue.check() {
                    let departed = ports.services().departed_nodes();
                    answers.gone = slots_in(missing)
                        .filter(|&s| members.nodes[s].is_some_and(|node| departed.includes(node)))
                        .fold(0, |m, s| m | 1 << s);
                    if answers.gone == missing {
                        return Ok(Some(()));
                    }
                }
                Ok(None)
            });
        match waited {
            Ok(()) | Err(TransportError::Timeout { .. }) => Ok(answers),
            Err(e) => Err(e.into()),
        }
    }
}

/// What the world keeps of a round it published.
#[derive(Debug, Default, Clone, Copy)]
struct Round {
    number: u64,
    live: u64,
    kind: u8,
}

/// Who answered a round, and who is known to be dead.
#[derive(Debug, Default, Clone, Copy)]
struct Answers {
    answered: u64,
    gone: u64,
}

/// How often the world reads join requests and control commands, and sends the episode
/// records it queued.
const LOOK_FOR_REQUESTS_EVERY: Duration = Duration::from_millis(1);

/// A clock read costs about 27 ns here, half a percent of a round, and rounds used to read
/// it for nothing but rare events. The world reads it for requests every this many rounds
/// (about 0.1 ms at 2 UAVs, 1.6 ms at 32), and for dead agents only once its waiter blocks.
const ROUNDS_BETWEEN_CLOCK_READS: u64 = 16;

/// Whether the process of `node` is a child of the supervisor, as the agents it starts
/// are: only those take the starting slots, so a stray process that asks for one first
/// cannot shut its agent out. Without a known supervisor every process counts.
fn started_by(supervisor: Option<u32>, node: SenderNode) -> bool {
    let Some(supervisor) = supervisor else { return true };
    let parent = node.pid().and_then(process_stat).and_then(|fields| fields.get(1)?.parse().ok());
    parent == Some(supervisor)
}
