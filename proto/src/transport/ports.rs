//! Each role's ports on the run's services: what the world, an agent and the supervisor
//! publish, read and wait on. Every publish is followed by a notify on the reader's wake-up
//! event.

use super::{
    termination_requested, Ipc, RunServices, TransportError, Waiter, LOOK_FOR_GONE_WORLD,
    WAKE_AGENTS, WAKE_SUPERVISOR, WAKE_WORLD,
};
use crate::services::{ACTIONS, CONTROL, EPISODES, JOIN, OBSERVATIONS, RUN_INFO};
use crate::supervisor_to_world::Control;
use crate::{Action, EpisodeBatch, EpisodeReport, JoinRequest, Membership, Observation, RunInfo};
use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::port::{BackpressureAction, BackpressureInfo, SendError};
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use std::fmt::Debug;
use std::time::{Duration, Instant};

/// The world wakes the supervisor once per this many episode records, a quarter of the
/// records the supervisor's buffer holds when its batches are full. Batches sent every
/// millisecond are often far from full, so what keeps the buffer from filling is the
/// supervisor's own drain every 10 ms (docs/TRANSPORT.md).
pub const EPISODE_WAKE_EVERY: u64 = (super::EPISODE_BUFFER / 4) as u64;

/// An observation as the agent reads it: straight from shared memory, no copy.
pub type ObservationSample = Sample<Ipc, Observation, ()>;

/// An action as the world reads it: straight from shared memory, no copy.
pub type ActionSample = Sample<Ipc, Action, ()>;

/// The iceoryx2 node a sample was sent from. Each process of a run has one node, whose id
/// iceoryx2 writes into the header of every sample the process sends, so it tells
/// processes apart where a message's own fields (slot, round) can be copied: the world
/// binds each agent slot to the node that asked to join on it, and takes control commands
/// only from the supervisor's process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SenderNode(UniqueNodeId);

impl SenderNode {
    /// The node that sent `sample`.
    #[inline]
    pub fn of<T: Debug + ZeroCopySend>(sample: &Sample<Ipc, T, ()>) -> SenderNode {
        SenderNode(sample.header().node_id())
    }

    /// The node's id, as iceoryx2 lists it.
    pub fn id(&self) -> u128 {
        self.0.value()
    }

    /// The process that created the node (iceoryx2 builds the id from it).
    pub fn pid(&self) -> Option<u32> {
        let pid = self.0.pid::<Ipc>().ok()?.value();
        u32::try_from(pid).ok()
    }
}

impl RunServices {
    /// The world's ports.
    pub fn into_world(self) -> Result<WorldPorts, TransportError> {
        let report_timeout = self.run.report_timeout;
        let episodes = self
            .episodes
            .publisher_builder()
            .max_loaned_samples(1)
            .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
            // Blocks while the supervisor's buffer is full, but never forever: past the bound
            // (or on SIGTERM) the send fails and the world reports a stalled supervisor.
            .set_backpressure_handler(move |info: &BackpressureInfo| {
                if termination_requested() || info.elapsed_time >= report_timeout {
                    BackpressureAction::DiscardDataAndFail
                } else {
                    BackpressureAction::Retry
                }
            })
            .create()
            .map_err(|e| self.port_err(EPISODES, "creating the publisher", e))?;
        Ok(WorldPorts {
            observations: self.publisher(&self.observations, OBSERVATIONS)?,
            actions: self.subscriber(&self.actions, ACTIONS)?,
            episodes,
            control: self.subscriber(&self.control, CONTROL)?,
            join: self.subscriber(&self.join, JOIN)?,
            run_info: self.publisher(&self.run_info, RUN_INFO)?,
            wake_agents: self.notifier(&self.wake_agents, WAKE_AGENTS)?,
            wake_supervisor: self.notifier(&self.wake_supervisor, WAKE_SUPERVISOR)?,
            batch: Box::default(),
            membership_changed: false,
            episodes_published: 0,
            waiter: self.waiter(&self.wake_world, WAKE_WORLD)?,
            services: self,
        })
    }

    /// An agent's ports. The listener comes first, so once the world counts an agent's
    /// subscriber, its wake-ups can no longer be missed.
    pub fn into_agent(self) -> Result<AgentPorts, TransportError> {
        let waiter = self.waiter(&self.wake_agents, WAKE_AGENTS)?;
        Ok(AgentPorts {
            run_info: self.subscriber(&self.run_info, RUN_INFO)?,
            join: self.publisher(&self.join, JOIN)?,
            observations: self.subscriber(&self.observations, OBSERVATIONS)?,
            actions: self.publisher(&self.actions, ACTIONS)?,
            wake_world: self.notifier(&self.wake_world, WAKE_WORLD)?,
            waiter,
            world: std::cell::Cell::new(None),
            services: self,
        })
    }

    /// The supervisor's ports, once its episode subscriber is connected to the world's
    /// publisher (waiting for it at most `open_timeout`).
    pub fn into_supervisor(self) -> Result<SupervisorPorts, TransportError> {
        let waiter = self.waiter(&self.wake_supervisor, WAKE_SUPERVISOR)?;
        let episodes = self.subscriber(&self.episodes, EPISODES)?;
        self.connect_to_episode_publisher(&episodes)?;
        Ok(SupervisorPorts {
            episodes,
            received: std::cell::RefCell::new(None),
            membership: std::cell::Cell::new(Membership::default()),
            control: self.publisher(&self.control, CONTROL)?,
            wake_world: self.notifier(&self.wake_world, WAKE_WORLD)?,
            waiter,
            services: self,
        })
    }

    /// iceoryx2 connects a subscriber made before the publisher only when the subscriber
    /// next receives or updates its connections, and a publisher skips an unconnected
    /// subscriber once that subscriber's buffer is full: the records sent to it are lost,
    /// even under `RetryUntilDelivered`. Connecting here, before the supervisor starts any
    /// agent, means no record is sent before the connection exists.
    fn connect_to_episode_publisher(
        &self,
        episodes: &Subscriber<Ipc, EpisodeBatch, ()>,
    ) -> Result<(), TransportError> {
        let start = Instant::now();
        while self.episodes.dynamic_config().number_of_publishers() == 0 {
            if termination_requested() {
                return Err(self.run.terminated("the world's episode publisher"));
            }
            let waited = start.elapsed();
            if waited >= self.run.open_timeout {
                return Err(TransportError::PublisherMissing {
                    run: self.run.run_id.clone(),
                    service: EPISODES.into(),
                    waited,
                });
            }
            std::thread::sleep(super::run_services::OPEN_RETRY);
        }
        episodes.update_connections().map_err(|e| self.port_err(EPISODES, "connecting", e))
    }

    /// A publisher on `service` that loans one sample at a time.
    fn publisher<T: Debug + ZeroCopySend>(
        &self,
        service: &publish_subscribe::PortFactory<Ipc, T, ()>,
        what: &str,
    ) -> Result<Publisher<Ipc, T, ()>, TransportError> {
        service
            .publisher_builder()
            .max_loaned_samples(1)
            .create()
            .map_err(|e| self.port_err(what, "creating the publisher", e))
    }

    fn subscriber<T: Debug + ZeroCopySend>(
        &self,
        service: &publish_subscribe::PortFactory<Ipc, T, ()>,
        what: &str,
    ) -> Result<Subscriber<Ipc, T, ()>, TransportError> {
        service
            .subscriber_builder()
            .create()
            .map_err(|e| self.port_err(what, "creating the subscriber", e))
    }

    fn notifier(
        &self,
        service: &event::PortFactory<Ipc>,
        what: &str,
    ) -> Result<Notifier<Ipc>, TransportError> {
        service
            .notifier_builder()
            .create()
            .map_err(|e| self.port_err(what, "creating the notifier", e))
    }

    fn waiter(
        &self,
        service: &event::PortFactory<Ipc>,
        what: &str,
    ) -> Result<Waiter, TransportError> {
        let listener = service
            .listener_builder()
            .create()
            .map_err(|e| self.port_err(what, "creating the listener", e))?;
        Ok(Waiter::new(listener, self.run.wait, &self.run.run_id, what))
    }

    fn port_err(
        &self,
        service: &str,
        op: &'static str,
        e: impl std::error::Error + Send + Sync + 'static,
    ) -> TransportError {
        port_error(&self.run.run_id, service, op, e)
    }
}

fn port_error(
    run: &str,
    service: &str,
    op: &'static str,
    e: impl std::error::Error + Send + Sync + 'static,
) -> TransportError {
    TransportError::Port { run: run.into(), service: service.into(), op, cause: Box::new(e) }
}

/// Who is connected, as the world sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Peers {
    pub observation_subscribers: usize,
    pub action_publishers: usize,
    pub agent_listeners: usize,
    pub episode_subscribers: usize,
    pub supervisor_listeners: usize,
}

/// The world's side: publishes observations and episode records, reads actions and control.
pub struct WorldPorts {
    observations: Publisher<Ipc, Observation, ()>,
    actions: Subscriber<Ipc, Action, ()>,
    episodes: Publisher<Ipc, EpisodeBatch, ()>,
    control: Subscriber<Ipc, Control, ()>,
    join: Subscriber<Ipc, JoinRequest, ()>,
    run_info: Publisher<Ipc, RunInfo, ()>,
    wake_agents: Notifier<Ipc>,
    wake_supervisor: Notifier<Ipc>,
    /// Records queued and not yet sent, and the barrier's membership.
    batch: Box<EpisodeBatch>,
    /// The membership changed since the last batch went out.
    membership_changed: bool,
    episodes_published: u64,
    waiter: Waiter,
    services: RunServices,
}

impl WorldPorts {
    /// Broadcasts one round to every agent and wakes them. `fill` writes the round straight
    /// into the shared-memory sample: only what it writes is touched, never the whole
    /// fixed-size message (33 KB, of which a run uses its trials' and agents' slots).
    pub fn publish_observation(
        &self,
        fill: impl FnOnce(&mut Observation),
    ) -> Result<(), TransportError> {
        let loan = self
            .observations
            .loan_uninit()
            .map_err(|e| self.err(OBSERVATIONS, "loaning a sample", e))?;
        // SAFETY: `Observation` is made of integers only, so every byte pattern is a valid
        // value, and a sample's memory is always initialised: the data segment is zero-filled
        // shared memory when it is created, and holds earlier rounds after that. Agents read
        // only the parts the world writes each round (the trials and agent slots in use).
        let mut sample = unsafe { loan.assume_init() };
        fill(&mut sample);
        sample.send().map_err(|e| self.err(OBSERVATIONS, "sending", e))?;
        self.wake_agents.notify().map_err(|e| self.err(WAKE_AGENTS, "notifying", e))?;
        Ok(())
    }

    /// The next action in arrival order, if any, read in place: only what the world looks
    /// at (the header and the trials in use) crosses from the agent's core.
    pub fn try_action(&self) -> Result<Option<ActionSample>, TransportError> {
        self.actions.receive().map_err(|e| self.err(ACTIONS, "receiving", e))
    }

    /// Queues one record for the supervisor; a full batch is sent at once. Queued records
    /// go out at the next [`WorldPorts::flush_episodes`].
    pub fn queue_episode(&mut self, report: &EpisodeReport) -> Result<(), TransportError> {
        if self.batch.is_full() {
            // Left full by a send that failed.
            self.flush_episodes()?;
        }
        let queued = self.batch.push(report);
        debug_assert!(queued, "the batch has room after a flush");
        if self.batch.is_full() {
            self.flush_episodes()?;
        }
        Ok(())
    }

    /// Tells the supervisor who is in the barrier now: the queued records go out at once
    /// with it, and it wakes. Agents join and leave rarely; the supervisor follows each of
    /// its processes through these changes, so none is left for a later batch.
    pub fn set_membership(&mut self, membership: &Membership) -> Result<(), TransportError> {
        self.batch.membership = *membership;
        self.membership_changed = true;
        self.flush_episodes()
    }

    /// Sends the queued records, and the membership if it changed, if either. Waits (bounded
    /// by `report_timeout`) while the supervisor's buffer is full; never drops a record
    /// silently.
    pub fn flush_episodes(&mut self) -> Result<(), TransportError> {
        if self.batch.is_empty() && !self.membership_changed {
            return Ok(());
        }
        let loan =
            self.episodes.loan_uninit().map_err(|e| self.err(EPISODES, "loaning a sample", e))?;
        // SAFETY: `EpisodeBatch` is made of integers only, so every byte pattern is a valid
        // value, and a sample's memory is always initialised (zero-filled shared memory when
        // created, earlier batches after that). The supervisor reads `count` and only the
        // records below it, which are written here.
        let mut sample = unsafe { loan.assume_init() };
        let count = self.batch.count as usize;
        sample.count = self.batch.count;
        sample.membership = self.batch.membership;
        sample.reports[..count].copy_from_slice(&self.batch.reports[..count]);
        match sample.send() {
            Ok(_) => {}
            // The backpressure handler gave up: on SIGTERM, or at `report_timeout`.
            Err(SendError::UnableToDeliver) if termination_requested() => {
                return Err(self.services.run.terminated("the supervisor to drain its records"))
            }
            Err(SendError::UnableToDeliver) => {
                return Err(TransportError::ReportsStalled {
                    run: self.services.run.run_id.clone(),
                    service: EPISODES.into(),
                    waited: self.services.run.report_timeout,
                })
            }
            Err(e) => return Err(self.err(EPISODES, "sending", e)),
        }
        self.batch.count = 0;
        // Waking the supervisor for every record cost the barrier about a quarter of its
        // rounds (measured by `benches/throughput.rs`): it is woken each time another
        // `EPISODE_WAKE_EVERY` records went out, and when the membership changed, and
        // otherwise drains on its own schedule.
        let before = self.episodes_published;
        self.episodes_published += count as u64;
        let wake = std::mem::take(&mut self.membership_changed)
            || self.episodes_published / EPISODE_WAKE_EVERY > before / EPISODE_WAKE_EVERY;
        if wake {
            self.wake_supervisor.notify().map_err(|e| self.err(WAKE_SUPERVISOR, "notifying", e))?;
        }
        Ok(())
    }

    /// The next control command, if any, with the node that sent it.
    pub fn try_control(&self) -> Result<Option<(Control, SenderNode)>, TransportError> {
        let sample = self.control.receive().map_err(|e| self.err(CONTROL, "receiving", e))?;
        Ok(sample.map(|s| (*s, SenderNode::of(&s))))
    }

    /// The next join request, if any, with the node that sent it.
    pub fn try_join(&self) -> Result<Option<(JoinRequest, SenderNode)>, TransportError> {
        let sample = self.join.receive().map_err(|e| self.err(JOIN, "receiving", e))?;
        Ok(sample.map(|s| (*s, SenderNode::of(&s))))
    }

    /// Publishes the run's description (kept as history for agents that attach later).
    pub fn publish_run_info(&self, info: &RunInfo) -> Result<(), TransportError> {
        self.run_info.send_copy(*info).map_err(|e| self.err(RUN_INFO, "sending", e))?;
        Ok(())
    }

    /// Hands the run's description to agents that subscribed since it was published;
    /// iceoryx2 delivers history only when the publisher updates its connections.
    pub fn serve_run_info(&self) -> Result<(), TransportError> {
        self.run_info
            .update_connections()
            .map_err(|e| self.err(RUN_INFO, "updating connections", e))
    }

    /// Woken by actions and control commands.
    pub fn waiter(&self) -> &Waiter {
        &self.waiter
    }

    pub fn peers(&self) -> Peers {
        let s = &self.services;
        Peers {
            observation_subscribers: s.observations.dynamic_config().number_of_subscribers(),
            action_publishers: s.actions.dynamic_config().number_of_publishers(),
            agent_listeners: s.wake_agents.dynamic_config().number_of_listeners(),
            episode_subscribers: s.episodes.dynamic_config().number_of_subscribers(),
            supervisor_listeners: s.wake_supervisor.dynamic_config().number_of_listeners(),
        }
    }

    /// Start-up barrier: waits until `agents` agents (and the supervisor, if `supervisor`)
    /// have all their ports, since a sample published before a subscriber connects is lost.
    pub fn wait_for_peers(
        &self,
        agents: usize,
        supervisor: bool,
        timeout: Duration,
    ) -> Result<(), TransportError> {
        let start = Instant::now();
        loop {
            let p = self.peers();
            let sup = usize::from(supervisor);
            let mut missing = Vec::new();
            for (have, need, what) in [
                (p.observation_subscribers, agents, "observation subscribers"),
                (p.action_publishers, agents, "action publishers"),
                (p.agent_listeners, agents, "agent listeners"),
                (p.episode_subscribers, sup, "episode subscribers"),
                (p.supervisor_listeners, sup, "supervisor listeners"),
            ] {
                if have < need {
                    missing.push(format!("{what} {have}/{need}"));
                }
            }
            if missing.is_empty() {
                return Ok(());
            }
            if termination_requested() {
                return Err(self.services.run.terminated("the run's peers"));
            }
            let waited = start.elapsed();
            if waited >= timeout {
                return Err(TransportError::PeersMissing {
                    run: self.services.run.run_id.clone(),
                    missing: missing.join(", "),
                    waited,
                });
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The run's services, e.g. to clean up after agents that died.
    pub fn services(&self) -> &RunServices {
        &self.services
    }

    fn err(
        &self,
        service: &str,
        op: &'static str,
        e: impl std::error::Error + Send + Sync + 'static,
    ) -> TransportError {
        port_error(&self.services.run.run_id, service, op, e)
    }
}

/// An agent's side: reads observations, publishes actions.
pub struct AgentPorts {
    run_info: Subscriber<Ipc, RunInfo, ()>,
    join: Publisher<Ipc, JoinRequest, ()>,
    observations: Subscriber<Ipc, Observation, ()>,
    actions: Publisher<Ipc, Action, ()>,
    wake_world: Notifier<Ipc>,
    waiter: Waiter,
    /// The world's node, once seen ([`AgentPorts::world`]).
    world: std::cell::Cell<Option<SenderNode>>,
    services: RunServices,
}

impl AgentPorts {
    /// The next observation, read in place in shared memory. Its sender is the world
    /// ([`Self::world`]), remembered from the first one.
    pub fn try_observation(&self) -> Result<Option<ObservationSample>, TransportError> {
        let observation = self
            .observations
            .receive()
            .map_err(|e| port_error(&self.services.run.run_id, OBSERVATIONS, "receiving", e))?;
        if let (Some(sample), None) = (&observation, self.world.get()) {
            self.world.set(Some(SenderNode::of(sample)));
        }
        Ok(observation)
    }

    pub fn run_id(&self) -> &str {
        &self.services.run.run_id
    }

    /// Asks the world for a place in the barrier and wakes it.
    pub fn send_join(&self, request: &JoinRequest) -> Result<(), TransportError> {
        let run = &self.services.run.run_id;
        self.join.send_copy(*request).map_err(|e| port_error(run, JOIN, "sending", e))?;
        self.wake_world.notify().map_err(|e| port_error(run, WAKE_WORLD, "notifying", e))?;
        Ok(())
    }

    /// The run's description, if it has arrived (the world hands it over when it answers a
    /// join request).
    pub fn try_run_info(&self) -> Result<Option<RunInfo>, TransportError> {
        let sample = self
            .run_info
            .receive()
            .map_err(|e| port_error(&self.services.run.run_id, RUN_INFO, "receiving", e))?;
        Ok(sample.map(|s| *s))
    }

    /// A shared-memory sample to write this round's answer into; [`ActionLoan::send`] sends
    /// it. As with observations, only what is written is touched: the header and the trials
    /// in use, not the whole fixed-size message.
    pub fn loan_action(&self) -> Result<ActionLoan<'_>, TransportError> {
        let run = &self.services.run.run_id;
        let loan = self
            .actions
            .loan_uninit()
            .map_err(|e| port_error(run, ACTIONS, "loaning a sample", e))?;
        // SAFETY: as in `WorldPorts::publish_observation`: `Action` is made of integers only,
        // and a sample's memory is zero-filled shared memory or an earlier round's answer.
        // The world reads only the header and the `n_trials` trials the agent writes.
        let sample = unsafe { loan.assume_init() };
        Ok(ActionLoan { sample, ports: self })
    }

    /// Answers a round with a copy of `action` and wakes the world: for tests and tools that
    /// hold a whole `Action` (a rogue sender in `tests/integration/faults.rs`); the agent
    /// writes its answer in place with [`AgentPorts::loan_action`].
    pub fn publish_action(&self, action: &Action) -> Result<(), TransportError> {
        let mut loan = self.loan_action()?;
        *loan = *action;
        loan.send()
    }

    /// Woken by observations.
    pub fn waiter(&self) -> &Waiter {
        &self.waiter
    }

    /// The world's node: the one publisher of observations (the service allows one),
    /// remembered once seen (as a publisher, or as the sender of an observation), so it is
    /// known after the world has gone and a clean-up has removed its ports too. None before
    /// the world has made its publisher.
    pub fn world(&self) -> Option<SenderNode> {
        if self.world.get().is_none() {
            self.services.observations.dynamic_config().list_publishers(|publisher| {
                self.world.set(Some(SenderNode(publisher.node_id)));
                CallbackProgression::Stop
            });
        }
        self.world.get()
    }

    /// Waits for `poll` as [`Waiter::wait`] does, and also ends once the world's node
    /// ([`Self::world`]) is gone, with [`TransportError::WorldGone`]. It looks for the node
    /// once the wait has lasted a while and then now and then ([`LOOK_FOR_GONE_WORLD`])
    /// ([`RunServices::departed_nodes`]), so a world killed with SIGKILL is noticed within
    /// about a second instead of at `timeout` (`--world-timeout-ms`, 30 s): the supervisor
    /// brings down the agents it started, but an attached agent has only this. Before the
    /// world's publisher is seen (or once a clean-up removed it unseen), the world is gone
    /// when no live node bears its name ([`crate::transport::WORLD_NODE_NAME`]).
    pub fn wait_on_world<T>(
        &self,
        what: &dyn std::fmt::Display,
        timeout: Duration,
        mut poll: impl FnMut() -> Result<Option<T>, TransportError>,
    ) -> Result<T, TransportError> {
        let mut overdue = self.waiter.overdue_after(LOOK_FOR_GONE_WORLD.0, LOOK_FOR_GONE_WORLD.1);
        self.waiter.wait(what, timeout, || {
            let found = poll()?;
            if found.is_some() || !overdue.check() {
                return Ok(found);
            }
            let departed = self.services.departed_nodes();
            let world = self.world();
            let gone = world.map_or(departed.lacks_a_world(), |world| departed.includes(world));
            if gone {
                let process = world
                    .and_then(|world| world.pid())
                    .map_or("process unknown".into(), |pid| format!("process {pid}"));
                return Err(TransportError::WorldGone {
                    run: self.run_id().to_owned(),
                    world: process,
                    what: what.to_string(),
                });
            }
            Ok(found)
        })
    }

    /// Waits until the world has left the run (its observation publisher or its node, as in
    /// [`Self::wait_on_world`], is gone), at most `timeout`, or until this process is asked
    /// to terminate; true if the world left. An agent's answer to the stop
    /// round is its last sample, and a process that ended right after sending it lost it
    /// now and then (a Ctrl-C at start-up failed about one run in seven with the world
    /// waiting for a stop answer from an agent already gone): an agent leaves after the
    /// world, which reads every answer before it ends.
    pub fn await_world_gone(&self, timeout: Duration) -> Result<bool, TransportError> {
        let observations = &self.services.observations;
        let gone = || Ok((observations.dynamic_config().number_of_publishers() == 0).then_some(()));
        match self.wait_on_world(&"the world to leave", timeout, gone) {
            Ok(()) | Err(TransportError::WorldGone { .. }) => Ok(true),
            Err(TransportError::Timeout { .. } | TransportError::Terminated { .. }) => Ok(false),
            Err(e) => Err(e),
        }
    }
}

/// An agent's answer being written in shared memory (see [`AgentPorts::loan_action`]).
/// Dropped without [`send`](Self::send), nothing is sent.
pub struct ActionLoan<'a> {
    sample: SampleMut<Ipc, Action, ()>,
    ports: &'a AgentPorts,
}

impl ActionLoan<'_> {
    /// Sends the answer and wakes the world.
    pub fn send(self) -> Result<(), TransportError> {
        let run = &self.ports.services.run.run_id;
        self.sample.send().map_err(|e| port_error(run, ACTIONS, "sending", e))?;
        self.ports.wake_world.notify().map_err(|e| port_error(run, WAKE_WORLD, "notifying", e))?;
        Ok(())
    }
}

impl std::ops::Deref for ActionLoan<'_> {
    type Target = Action;
    fn deref(&self) -> &Action {
        &self.sample
    }
}

impl std::ops::DerefMut for ActionLoan<'_> {
    fn deref_mut(&mut self) -> &mut Action {
        &mut self.sample
    }
}

/// The batch of episode records the supervisor is reading.
struct ReceivedBatch {
    batch: Sample<Ipc, EpisodeBatch, ()>,
    /// Records already handed out.
    handed_out: usize,
}

/// What the world tells the supervisor, in the order it happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FromWorld {
    /// One finished episode of one trial.
    Episode(EpisodeReport),
    /// Who is in the barrier now; told when it differs from what was last told.
    Membership(Membership),
}

/// The supervisor's side: reads episode records, sends control commands.
pub struct SupervisorPorts {
    episodes: Subscriber<Ipc, EpisodeBatch, ()>,
    received: std::cell::RefCell<Option<ReceivedBatch>>,
    /// The membership last handed out.
    membership: std::cell::Cell<Membership>,
    control: Publisher<Ipc, Control, ()>,
    wake_world: Notifier<Ipc>,
    waiter: Waiter,
    services: RunServices,
}

impl SupervisorPorts {
    /// The next episode record or change of membership, if any, in the order the world
    /// sent them: a batch's records, then its membership if it changed.
    pub fn try_next(&self) -> Result<Option<FromWorld>, TransportError> {
        let run = &self.services.run.run_id;
        let mut received = self.received.borrow_mut();
        loop {
            if let Some(current) = received.as_mut() {
                let reports = current
                    .batch
                    .reports()
                    .map_err(|e| port_error(run, EPISODES, "reading a batch", e))?;
                if let Some(report) = reports.get(current.handed_out) {
                    current.handed_out += 1;
                    return Ok(Some(FromWorld::Episode(*report)));
                }
                // Told once: once told, it is the membership last told.
                let membership = current.batch.membership;
                if membership != self.membership.get() {
                    self.membership.set(membership);
                    return Ok(Some(FromWorld::Membership(membership)));
                }
            }
            let next =
                self.episodes.receive().map_err(|e| port_error(run, EPISODES, "receiving", e))?;
            match next {
                Some(batch) => *received = Some(ReceivedBatch { batch, handed_out: 0 }),
                None => {
                    *received = None;
                    return Ok(None);
                }
            }
        }
    }

    /// Sends a command and wakes the world, which may be blocked waiting for agents.
    pub fn send_control(&self, control: &Control) -> Result<(), TransportError> {
        let run = &self.services.run.run_id;
        self.control.send_copy(*control).map_err(|e| port_error(run, CONTROL, "sending", e))?;
        self.wake_world.notify().map_err(|e| port_error(run, WAKE_WORLD, "notifying", e))?;
        Ok(())
    }

    /// Woken by episode records.
    pub fn waiter(&self) -> &Waiter {
        &self.waiter
    }
}

#[cfg(test)]
mod tests {
    use crate::transport::{RunConfig, RunServices, SignalMode, TransportError, EPISODE_BUFFER};
    use crate::EpisodeReport;
    use iceoryx2::prelude::PortFactory;
    use std::time::{Duration, Instant};

    const BOUND: Duration = Duration::from_secs(10);

    /// Without the connection made in `into_supervisor`, the world skipped a supervisor
    /// that opened the run before the world's publisher existed and had not received yet:
    /// its records past a full buffer were lost and the flush below succeeded.
    #[test]
    fn a_supervisor_that_opened_before_the_publisher_is_never_skipped() {
        let mut run =
            RunConfig::new(format!("early-{}", std::process::id()), SignalMode::Untouched);
        run.report_timeout = Duration::from_millis(50);
        run.open_timeout = BOUND;
        let services = RunServices::create(&run).expect("a run of its own");
        let (connected_tx, connected) = std::sync::mpsc::channel();
        let (release_tx, release) = std::sync::mpsc::channel::<()>();
        let opener = {
            let run = run.clone();
            // The ports are not Send: the thread opens and holds them, never reading.
            std::thread::spawn(move || {
                let ports = RunServices::open(&run)?.into_supervisor()?;
                connected_tx.send(()).expect("the test waits for the supervisor");
                let _ = release.recv_timeout(BOUND);
                drop(ports);
                Ok::<(), TransportError>(())
            })
        };
        let start = Instant::now();
        while services.episodes.dynamic_config().number_of_subscribers() == 0 {
            assert!(start.elapsed() < BOUND, "the supervisor made no subscriber within {BOUND:?}");
            std::thread::sleep(Duration::from_millis(1));
        }
        let mut world = services.into_world().expect("the world's ports");
        if connected.recv_timeout(BOUND).is_err() {
            panic!("the supervisor did not connect: {:?}", opener.join());
        }
        for _ in 0..EPISODE_BUFFER {
            world.queue_episode(&EpisodeReport::default()).expect("room in the buffer");
        }
        world.queue_episode(&EpisodeReport::default()).expect("a batch of its own");
        let flushed = world.flush_episodes();
        release_tx.send(()).expect("the supervisor holds on");
        opener.join().expect("the supervisor's thread").expect("the supervisor's ports");
        assert!(
            matches!(flushed, Err(TransportError::ReportsStalled { .. })),
            "the idle supervisor was skipped: {flushed:?}"
        );
    }
}
