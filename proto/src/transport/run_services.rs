//! The run's services: their limits and QoS, created by the world or opened by the others.

use super::{
    setup, termination_requested, Ipc, RunConfig, RunNode, SenderNode, TransportError, WAKE_AGENTS,
    WAKE_SUPERVISOR, WAKE_WORLD, WORLD_NODE_NAME,
};
use crate::limits::MAX_AGENTS;
use crate::services::{self, ACTIONS, CONTROL, EPISODES, JOIN, OBSERVATIONS, RUN_INFO};
use crate::supervisor_to_world::Control;
use crate::{Action, EpisodeBatch, JoinRequest, Observation, RunInfo, EPISODE_BATCH};
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::{EventCreateError, EventOpenError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeCreateError, PublishSubscribeOpenError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};
use std::fmt::Debug;
use std::time::{Duration, Instant};

/// Ports and nodes beyond the planned ones: a test or tool peeking at a run, or a restarted
/// process whose dead predecessor has not been cleaned up yet.
pub const SPARE: usize = 4;
/// Nodes one run may hold: every agent, the world, the supervisor and the spares.
pub const MAX_NODES: usize = MAX_AGENTS + 2 + SPARE;
/// Episode records the supervisor's buffer holds before the world has to wait for it
/// (in batches of [`EPISODE_BATCH`]).
pub const EPISODE_BUFFER: usize = 8192;
/// Pause between attempts while the world has not created a service yet.
pub(super) const OPEN_RETRY: Duration = Duration::from_millis(5);

/// Limits and QoS of one publish/subscribe service. The world creates the service with them;
/// openers require at least them, so a binary built with other limits fails at open time with
/// a clear error instead of misbehaving later.
struct PubSubQos {
    publishers: usize,
    subscribers: usize,
    buffer: usize,
    history: usize,
    safe_overflow: bool,
}

/// World -> agents. Safe overflow: a hung agent must never block the world; a live agent
/// reads every round before the next one exists. History 1 lets an agent that attaches late
/// read the current round too: iceoryx2 delivers it with the world's next publish, which
/// comes within a round, as the world publishes every round.
/// One publisher: while the world lives, no other process can publish observations.
const OBSERVATIONS_QOS: PubSubQos = PubSubQos {
    publishers: 1,
    subscribers: MAX_AGENTS + SPARE,
    buffer: 2,
    history: 1,
    safe_overflow: true,
};
/// Agents -> world. Each agent has one action in flight per round; safe overflow keeps the
/// newest, so a rogue sender cannot block itself or the world (stale rounds are dropped by
/// the world's round check).
const ACTIONS_QOS: PubSubQos = PubSubQos {
    publishers: MAX_AGENTS + SPARE,
    subscribers: 1 + SPARE,
    buffer: 2,
    history: 0,
    safe_overflow: true,
};
/// World -> supervisor. No record may be lost: no safe overflow, a deep buffer, and a
/// publisher that waits (bounded by `report_timeout`) when the supervisor falls behind. Few
/// subscribers, since every one of them must drain or the world stalls.
const EPISODES_QOS: PubSubQos = PubSubQos {
    publishers: 1,
    subscribers: 1 + 1,
    buffer: EPISODE_BUFFER / EPISODE_BATCH,
    history: 0,
    safe_overflow: false,
};
/// Supervisor -> world. Commands are idempotent, so keeping the newest is enough.
const CONTROL_QOS: PubSubQos = PubSubQos {
    publishers: 1 + SPARE,
    subscribers: 1 + SPARE,
    buffer: 4,
    history: 0,
    safe_overflow: true,
};

/// Agents -> world: join requests. Every agent sends one when it starts.
const JOIN_QOS: PubSubQos = PubSubQos {
    publishers: MAX_AGENTS + SPARE,
    subscribers: 1,
    buffer: 4,
    history: 0,
    safe_overflow: true,
};
/// World -> agents: the run's description, once, with history for agents that attach later.
const RUN_INFO_QOS: PubSubQos = PubSubQos {
    publishers: 1,
    subscribers: MAX_AGENTS + 1 + SPARE,
    buffer: 1,
    history: 1,
    safe_overflow: true,
};

fn pubsub<T: Debug + ZeroCopySend>(
    node: &Node<Ipc>,
    name: &ServiceName,
    qos: &PubSubQos,
) -> iceoryx2::service::builder::publish_subscribe::Builder<T, (), Ipc> {
    node.service_builder(name)
        .publish_subscribe::<T>()
        .max_publishers(qos.publishers)
        .max_subscribers(qos.subscribers)
        .max_nodes(MAX_NODES)
        .subscriber_max_buffer_size(qos.buffer)
        .history_size(qos.history)
        .enable_safe_overflow(qos.safe_overflow)
        // An agent may keep last round's observation while it reads the new one.
        .subscriber_max_borrowed_samples(2)
}

/// Limits of one wake-up event service: who may wake whom.
struct WakeQos {
    notifiers: usize,
    listeners: usize,
}

/// Every agent and the supervisor wake the world.
const WAKE_WORLD_QOS: WakeQos = WakeQos { notifiers: MAX_AGENTS + 1 + SPARE, listeners: 1 + SPARE };
/// The world wakes every agent.
const WAKE_AGENTS_QOS: WakeQos = WakeQos { notifiers: 1 + SPARE, listeners: MAX_AGENTS + SPARE };
/// The world wakes the supervisor.
const WAKE_SUPERVISOR_QOS: WakeQos = WakeQos { notifiers: 1 + SPARE, listeners: 1 + SPARE };

fn wake(
    node: &Node<Ipc>,
    name: &ServiceName,
    qos: &WakeQos,
) -> iceoryx2::service::builder::event::Builder<Ipc> {
    node.service_builder(name)
        .event()
        .max_notifiers(qos.notifiers)
        .max_listeners(qos.listeners)
        .max_nodes(MAX_NODES)
        // Only event id 0 is used ("look again"). A listener drains every possible id on each
        // wake-up, and the default range of 256 ids showed up as 9% of the barrier's CPU.
        .event_id_max_value(0)
}

/// Every service of one run, created by the world or opened by the others. Consumed by one of
/// the `into_*` methods, which add the role's ports.
pub struct RunServices {
    pub(super) observations: publish_subscribe::PortFactory<Ipc, Observation, ()>,
    pub(super) actions: publish_subscribe::PortFactory<Ipc, Action, ()>,
    pub(super) episodes: publish_subscribe::PortFactory<Ipc, EpisodeBatch, ()>,
    pub(super) control: publish_subscribe::PortFactory<Ipc, Control, ()>,
    pub(super) join: publish_subscribe::PortFactory<Ipc, JoinRequest, ()>,
    pub(super) run_info: publish_subscribe::PortFactory<Ipc, RunInfo, ()>,
    pub(super) wake_world: event::PortFactory<Ipc>,
    pub(super) wake_agents: event::PortFactory<Ipc>,
    pub(super) wake_supervisor: event::PortFactory<Ipc>,
    // After the services: iceoryx2 removes a service when its last node lets go of it.
    pub(super) node: RunNode,
    pub(super) run: RunConfig,
}

impl RunServices {
    /// The world's constructor: creates every service of the run with its limits. Fails if a
    /// live run already uses the run id.
    pub fn create(run: &RunConfig) -> Result<RunServices, TransportError> {
        let run_node = RunNode::new(run, Some(WORLD_NODE_NAME))?;
        let node = run_node.node();
        let id = &run.run_id;
        let ps = |what: &str| service_name(id, what);
        let obs_name = ps(OBSERVATIONS)?;
        let act_name = ps(ACTIONS)?;
        let epi_name = ps(EPISODES)?;
        let ctl_name = ps(CONTROL)?;
        let (join_name, info_name) = (ps(JOIN)?, ps(RUN_INFO)?);
        let (ww, wa, wsup) = (ps(WAKE_WORLD)?, ps(WAKE_AGENTS)?, ps(WAKE_SUPERVISOR)?);
        let created = |name: &ServiceName, e: ServiceFailure| e.into_error(run, name);
        Ok(RunServices {
            observations: pubsub::<Observation>(node, &obs_name, &OBSERVATIONS_QOS)
                .create()
                .map_err(|e| created(&obs_name, e.into()))?,
            actions: pubsub::<Action>(node, &act_name, &ACTIONS_QOS)
                .create()
                .map_err(|e| created(&act_name, e.into()))?,
            episodes: pubsub::<EpisodeBatch>(node, &epi_name, &EPISODES_QOS)
                .create()
                .map_err(|e| created(&epi_name, e.into()))?,
            control: pubsub::<Control>(node, &ctl_name, &CONTROL_QOS)
                .create()
                .map_err(|e| created(&ctl_name, e.into()))?,
            join: pubsub::<JoinRequest>(node, &join_name, &JOIN_QOS)
                .create()
                .map_err(|e| created(&join_name, e.into()))?,
            run_info: pubsub::<RunInfo>(node, &info_name, &RUN_INFO_QOS)
                .create()
                .map_err(|e| created(&info_name, e.into()))?,
            wake_world: wake(node, &ww, &WAKE_WORLD_QOS)
                .create()
                .map_err(|e| created(&ww, e.into()))?,
            wake_agents: wake(node, &wa, &WAKE_AGENTS_QOS)
                .create()
                .map_err(|e| created(&wa, e.into()))?,
            wake_supervisor: wake(node, &wsup, &WAKE_SUPERVISOR_QOS)
                .create()
                .map_err(|e| created(&wsup, e.into()))?,
            node: run_node,
            run: run.clone(),
        })
    }

    /// The agents' and the supervisor's constructor: opens every service, retrying while the
    /// world has not created it yet, for at most `run.open_timeout` in all.
    pub fn open(run: &RunConfig) -> Result<RunServices, TransportError> {
        let run_node = RunNode::new(run, None)?;
        let node = run_node.node();
        let id = &run.run_id;
        let deadline = Instant::now() + run.open_timeout;
        let ps = |what: &str| service_name(id, what);
        let (obs_name, act_name, epi_name, ctl_name) =
            (ps(OBSERVATIONS)?, ps(ACTIONS)?, ps(EPISODES)?, ps(CONTROL)?);
        let (join_name, info_name) = (ps(JOIN)?, ps(RUN_INFO)?);
        let (ww, wa, wsup) = (ps(WAKE_WORLD)?, ps(WAKE_AGENTS)?, ps(WAKE_SUPERVISOR)?);
        Ok(RunServices {
            observations: retry(run, &obs_name, deadline, || {
                pubsub::<Observation>(node, &obs_name, &OBSERVATIONS_QOS).open()
            })?,
            actions: retry(run, &act_name, deadline, || {
                pubsub::<Action>(node, &act_name, &ACTIONS_QOS).open()
            })?,
            episodes: retry(run, &epi_name, deadline, || {
                pubsub::<EpisodeBatch>(node, &epi_name, &EPISODES_QOS).open()
            })?,
            control: retry(run, &ctl_name, deadline, || {
                pubsub::<Control>(node, &ctl_name, &CONTROL_QOS).open()
            })?,
            join: retry(run, &join_name, deadline, || {
                pubsub::<JoinRequest>(node, &join_name, &JOIN_QOS).open()
            })?,
            run_info: retry(run, &info_name, deadline, || {
                pubsub::<RunInfo>(node, &info_name, &RUN_INFO_QOS).open()
            })?,
            wake_world: retry(run, &ww, deadline, || wake(node, &ww, &WAKE_WORLD_QOS).open())?,
            wake_agents: retry(run, &wa, deadline, || wake(node, &wa, &WAKE_AGENTS_QOS).open())?,
            wake_supervisor: retry(run, &wsup, deadline, || {
                wake(node, &wsup, &WAKE_SUPERVISOR_QOS).open()
            })?,
            node: run_node,
            run: run.clone(),
        })
    }

    pub fn run_id(&self) -> &str {
        &self.run.run_id
    }

    /// Whether a live world serves `run_id`: its services exist. Call it once the resources of
    /// the run's dead nodes are removed ([`super::cleanup_run`], [`super::sweep_stale_runs`]),
    /// which removes a crashed world's services too. Other processes that wait for the run
    /// (an agent attaching before it starts) create none.
    pub fn is_served(run_id: &str) -> Result<bool, TransportError> {
        let config = super::iceoryx_config(run_id)?;
        let name = service_name(run_id, OBSERVATIONS)?;
        <Ipc as iceoryx2::service::Service>::does_exist(
            &name,
            &config,
            iceoryx2::service::messaging_pattern::MessagingPattern::PublishSubscribe,
        )
        .map_err(|e| setup(run_id, "looking for the run's services", e))
    }

    /// Which nodes of this run are gone, as iceoryx2 sees them: a node's process holds a lock
    /// on its monitor file while it lives, and the system releases it as the process ends
    /// (crashed or killed, reaped or not; a stopped process keeps it), and a node whose
    /// resources were removed is no longer listed. Unlike a look at `/proc`, this holds across
    /// pid namespaces, since the run's processes share its files. Listing reads this user's
    /// node directory and each node's monitor (0.3 ms at 2 UAVs, 2.2 ms at 32): for a peer
    /// silent for a while, now and then ([`super::Overdue`]). A listing without this
    /// process's own node is taken as incomplete (the node directory gone, say).
    pub fn departed_nodes(&self) -> DepartedNodes {
        let mut listed = Vec::new();
        let mut maybe_world = false;
        let complete = Node::<Ipc>::list(self.node.node().config(), |state| {
            let entry = match &state {
                NodeState::Alive(node) => {
                    // A node whose details could not be read may be the world.
                    maybe_world |= node
                        .details()
                        .as_ref()
                        .is_none_or(|details| details.name().as_str() == WORLD_NODE_NAME);
                    (node.id().value(), false)
                }
                NodeState::Dead(node) => (node.id().value(), true),
                NodeState::Inaccessible(id) | NodeState::Undefined(id) => {
                    maybe_world = true;
                    (id.value(), false)
                }
            };
            listed.push(entry);
            CallbackProgression::Continue
        })
        .is_ok();
        let own = self.node.node().id().value();
        let complete = complete && listed.iter().any(|&(id, dead)| id == own && !dead);
        DepartedNodes { listed, maybe_world, complete }
    }

    /// Removes the resources of dead nodes of this run (a crashed agent's ports). Returns how
    /// many nodes were cleaned up.
    pub fn cleanup_dead_nodes(&self) -> u64 {
        // First what iceoryx2 would wait on for good; failing that, it still cleans the rest.
        let _ = super::cleanup::remove_empty_segments(self.run_id());
        self.node.node().try_cleanup_dead_nodes().cleanups
    }
}

/// The nodes of a run at one look ([`RunServices::departed_nodes`]).
#[derive(Debug)]
pub struct DepartedNodes {
    /// Each listed node's id, and whether it is dead.
    listed: Vec<(u128, bool)>,
    /// Whether a live node is named [`WORLD_NODE_NAME`], or a node's name or state could not
    /// be read.
    maybe_world: bool,
    /// Whether every node could be listed; if not, none counts as departed.
    complete: bool,
}

impl DepartedNodes {
    /// Whether `node` is gone: listed dead, or no longer listed. A node whose state could not
    /// be read counts as present: a deadline decides then.
    pub fn includes(&self, node: SenderNode) -> bool {
        self.complete
            && self.listed.iter().find(|(id, _)| *id == node.id()).is_none_or(|&(_, dead)| dead)
    }

    /// Whether no live node is the world's: for an agent that never saw the world's
    /// publisher (see [`WORLD_NODE_NAME`]).
    pub fn lacks_a_world(&self) -> bool {
        self.complete && !self.maybe_world
    }
}

fn service_name(run_id: &str, what: &str) -> Result<ServiceName, TransportError> {
    let name = services::service_name(run_id, what);
    ServiceName::new(&name).map_err(|e| setup(run_id, format!("naming service `{name}`"), e))
}

/// A failed create or open of either kind of service, reduced to what decides the reaction:
/// on open, `DoesNotExist` (the world has not created it yet) and `Interrupt` (a signal cut
/// one of iceoryx2's waits short: a Ctrl-C as the supervisor starts must stop the run, not
/// fail it) are retried; `AlreadyExists` on create means a live run holds the run id.
struct ServiceFailure {
    verb: &'static str,
    retried: bool,
    exists: bool,
    source: Box<dyn std::error::Error + Send + Sync>,
}

impl ServiceFailure {
    fn new(
        verb: &'static str,
        retried: bool,
        exists: bool,
        e: impl std::error::Error + Send + Sync + 'static,
    ) -> ServiceFailure {
        ServiceFailure { verb, retried, exists, source: Box::new(e) }
    }

    fn into_error(self, run: &RunConfig, name: &ServiceName) -> TransportError {
        if self.exists {
            return TransportError::RunInUse { run: run.run_id.clone(), service: name.to_string() };
        }
        TransportError::Setup {
            run: run.run_id.clone(),
            what: format!("{} service `{name}`", self.verb),
            cause: self.source,
        }
    }
}

impl From<PublishSubscribeOpenError> for ServiceFailure {
    fn from(e: PublishSubscribeOpenError) -> ServiceFailure {
        use PublishSubscribeOpenError::{DoesNotExist, Interrupt};
        ServiceFailure::new("opening", matches!(e, DoesNotExist | Interrupt), false, e)
    }
}

impl From<EventOpenError> for ServiceFailure {
    fn from(e: EventOpenError) -> ServiceFailure {
        use EventOpenError::{DoesNotExist, Interrupt};
        ServiceFailure::new("opening", matches!(e, DoesNotExist | Interrupt), false, e)
    }
}

impl From<PublishSubscribeCreateError> for ServiceFailure {
    fn from(e: PublishSubscribeCreateError) -> ServiceFailure {
        ServiceFailure::new("creating", false, e == PublishSubscribeCreateError::AlreadyExists, e)
    }
}

impl From<EventCreateError> for ServiceFailure {
    fn from(e: EventCreateError) -> ServiceFailure {
        ServiceFailure::new("creating", false, e == EventCreateError::AlreadyExists, e)
    }
}

fn retry<T, E: Into<ServiceFailure>>(
    run: &RunConfig,
    name: &ServiceName,
    deadline: Instant,
    mut open: impl FnMut() -> Result<T, E>,
) -> Result<T, TransportError> {
    loop {
        let failure: ServiceFailure = match open() {
            Ok(service) => return Ok(service),
            Err(e) => e.into(),
        };
        if !failure.retried {
            return Err(failure.into_error(run, name));
        }
        if termination_requested() {
            return Err(run.terminated(&format!("service `{name}` to open")));
        }
        if Instant::now() >= deadline {
            return Err(TransportError::ServiceMissing {
                run: run.run_id.clone(),
                service: name.to_string(),
                waited: run.open_timeout,
            });
        }
        std::thread::sleep(OPEN_RETRY);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::SignalMode;

    /// Runs [`retry`] over `failures`, then a success; returns its result and the attempts.
    fn open_after<E: Into<ServiceFailure>>(
        failures: Vec<E>,
    ) -> (Result<&'static str, TransportError>, usize) {
        let run = RunConfig::new("t-retry", SignalMode::Untouched);
        let name = ServiceName::new("t-retry/service").expect("a valid service name");
        let deadline = Instant::now() + Duration::from_secs(10);
        let (mut failures, mut attempts) = (failures.into_iter(), 0);
        let opened = retry(&run, &name, deadline, || {
            attempts += 1;
            failures.next().map_or(Ok("opened"), Err)
        });
        (opened, attempts)
    }

    #[test]
    fn an_open_cut_short_by_a_signal_or_made_before_the_world_is_tried_again() {
        use PublishSubscribeOpenError::{DoesNotExist, Interrupt};
        let (opened, attempts) = open_after(vec![Interrupt, DoesNotExist, Interrupt]);
        assert_eq!((opened.expect("opened on the fourth attempt"), attempts), ("opened", 4));
        let (opened, attempts) = open_after(vec![EventOpenError::Interrupt]);
        assert_eq!((opened.expect("opened on the second attempt"), attempts), ("opened", 2));
    }

    #[test]
    fn an_open_that_fails_otherwise_fails_at_once_and_names_the_service() {
        let (opened, attempts) = open_after(vec![PublishSubscribeOpenError::IncompatibleTypes]);
        let error = opened.expect_err("incompatible types are not retried").to_string();
        assert_eq!(attempts, 1, "{error}");
        assert!(error.contains("opening service `t-retry/service`"), "{error}");
        let (opened, attempts) = open_after(vec![EventOpenError::InsufficientPermissions]);
        assert!(opened.is_err());
        assert_eq!(attempts, 1);
    }

    #[test]
    fn a_create_of_a_service_that_exists_says_the_run_is_in_use() {
        let (opened, attempts) = open_after(vec![PublishSubscribeCreateError::AlreadyExists]);
        let error = opened.expect_err("an existing service is not retried");
        assert_eq!(attempts, 1);
        assert!(matches!(error, TransportError::RunInUse { .. }), "{error}");
    }
}
