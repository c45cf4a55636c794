//! One UAV agent: its tree, learner and communication state for every trial.
//!
//! [`UavAgent::act`] turns one [`Observation`] into one [`Action`]; it is the whole agent
//! side of a barrier round, and the in-process runner and the `agent` process call exactly
//! this. Episode boundaries are read from the observation: when a trial's episode or phase
//! changes, the agent closes the previous episode (a truncated one bootstraps from the
//! state it was cut in, using the flags relayed with the boundary) and starts afresh.

use crate::bt::spec::TreeSpec;
use crate::bt::status::Status;
use crate::bt::tree::{TickContext, Tree, TreeError};
use crate::comm::{CommMode, CommState};
use crate::learning::{LearnParams, StateId};
use crate::state::StateSpace;
use crate::uav::Body;
use flockstep_proto::{
    seed, slots_in, Action, FieldError, Observation, Phase, Pose, TrialAction, TrialObservation,
    MAX_TRIALS,
};
use flockstep_world::scenario::Scenario;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

/// Everything that defines one agent of a run.
#[derive(Debug, Clone)]
pub struct AgentSpec {
    /// Agent slot, 0-based (UAV1 is slot 0); it flies route `slot` of the scenario.
    pub slot: usize,
    pub scenario: Arc<Scenario>,
    pub tree: TreeSpec,
    pub comm: CommMode,
    pub params: LearnParams,
    /// The run's seed; each trial's stream is derived from it.
    pub seed: u64,
    pub trials: usize,
}

/// Why an agent cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    #[error(transparent)]
    Tree(#[from] TreeError),
    #[error("agent slot {slot} has no route: scenario `{scenario}` has {routes} routes")]
    NoRoute { slot: usize, scenario: String, routes: usize },
    #[error("{trials} trials requested; between 1 and {max} are supported")]
    Trials { trials: usize, max: usize },
    #[error("{0}")]
    Params(String),
}

/// The tree's view of the UAV during one tick.
struct UavTick<'a> {
    body: Body<'a>,
    states: &'a mut StateSpace,
    comm: &'a CommState,
    state: Option<StateId>,
}

impl TickContext for UavTick<'_> {
    #[inline]
    fn tick_action(&mut self, leaf: u16, progress: &mut u32) -> Status {
        let before = self.body.pose;
        let status = self.body.tick_action(leaf, progress);
        if self.body.pose != before {
            self.state = None;
        }
        status
    }

    #[inline]
    fn halt_action(&mut self, _leaf: u16, progress: &mut u32) {
        self.body.halt_action(progress);
    }

    #[inline]
    fn check_condition(&mut self, leaf: u16) -> bool {
        self.body.check_condition(leaf)
    }

    #[inline]
    fn rl_state(&mut self) -> StateId {
        *self.state.get_or_insert_with(|| self.states.id(self.body.pose, self.comm.words()))
    }
}

/// One agent in one trial.
#[derive(Debug, Clone)]
pub struct TrialAgent {
    slot: usize,
    route_len: usize,
    tree: Tree,
    states: StateSpace,
    comm: CommState,
    /// The map (public knowledge): which candidate cells each pose's camera covers.
    scenario: Arc<Scenario>,
    train_params: LearnParams,
    /// The pose after this agent's last commands (the state a truncated episode ends in).
    pose: Pose,
    /// The (phase, episode) in progress and not yet closed.
    open: Option<(u8, u64)>,
    /// This agent ran `A-endEpisode` in the open episode and hovers.
    finished: bool,
    /// Training episodes closed so far, those behind a restored snapshot included.
    trained_episodes: u64,
    /// Peers taking part in this trial when last observed (departures void what was heard).
    peers: u64,
}

impl TrialAgent {
    /// One trial of the agent, ticking `tree` (a fresh copy; see [`UavAgent::new`]).
    fn new(spec: &AgentSpec, tree: Tree) -> TrialAgent {
        let route_lens: Vec<usize> =
            (0..spec.scenario.n_routes()).map(|r| spec.scenario.route_len(r)).collect();
        let comm = CommState::new(spec.comm, spec.slot, &route_lens, spec.scenario.n_targets());
        TrialAgent {
            slot: spec.slot,
            route_len: spec.scenario.route_len(spec.slot),
            tree,
            states: StateSpace::new(comm.words().len()),
            comm,
            scenario: spec.scenario.clone(),
            train_params: spec.params,
            pose: spec.scenario.start_pose(),
            open: None,
            finished: false,
            trained_episodes: 0,
            peers: 0,
        }
    }

    /// One tick of this trial: reads `obs`, writes this agent's part of the action.
    pub fn act(
        &mut self,
        obs: TrialObservation<'_>,
        live: u64,
        out: &mut TrialAction,
    ) -> Result<(), FieldError> {
        out.clear();
        let view = &obs.agents[self.slot];
        view.pose.validate(self.route_len)?;
        let header = obs.header;
        flockstep_proto::check_below("observation.phase", header.phase.into(), 2)?;
        self.forget_departed(obs, live);
        if header.done != 0 || view.member == 0 {
            self.close_episode(obs, live)?;
            return Ok(());
        }
        if self.open != Some((header.phase, header.episode)) {
            self.close_episode(obs, live)?;
            self.start_episode(header.phase);
            self.open = Some((header.phase, header.episode));
        } else {
            self.hear(obs, live)?;
        }
        self.pose = view.pose;
        let sees_target = view.sees_target == 1;
        self.comm.note_own(|| self.scenario.visible_targets(self.slot, view.pose), sees_target);
        out.flags = self.comm.outgoing(view.pose.waypoint, sees_target);
        if self.finished {
            return Ok(());
        }
        let mut ctx = UavTick {
            body: Body {
                pose: self.pose,
                route_len: self.route_len,
                sees_target,
                ended: false,
                action: out,
            },
            states: &mut self.states,
            comm: &self.comm,
            state: None,
        };
        self.tree.tick(&mut ctx);
        self.pose = ctx.body.pose;
        if ctx.body.ended {
            self.finished = true;
            self.tree.end_episode_terminal();
        }
        Ok(())
    }

    /// What was heard from a peer that no longer takes part in this trial is void.
    fn forget_departed(&mut self, obs: TrialObservation<'_>, live: u64) {
        let peers = obs.header.members & live & !(1 << self.slot);
        for peer in slots_in(self.peers & !peers) {
            self.comm.forget(peer);
        }
        self.peers = peers;
    }

    /// Takes in the flags the world relayed: what each live peer sent in the previous tick.
    #[inline(always)]
    fn hear(&mut self, obs: TrialObservation<'_>, live: u64) -> Result<(), FieldError> {
        let header = obs.header;
        let peers = header.members & live & !(1 << self.slot);
        self.comm.hear(header.tick, peers, header.flags_changed, obs.agents)
    }

    /// Closes the open episode, if any. If this agent did not finish it, the episode was
    /// truncated: the pending learning steps bootstrap from the state it ended in, which
    /// includes the flags sent in its last tick (relayed with this observation).
    fn close_episode(&mut self, obs: TrialObservation<'_>, live: u64) -> Result<(), FieldError> {
        let Some((phase, _)) = self.open.take() else {
            return Ok(());
        };
        if phase == Phase::Train as u8 {
            self.trained_episodes += 1;
        }
        if !self.finished {
            self.hear(obs, live)?;
            let last = self.states.id(self.pose, self.comm.words());
            self.tree.end_episode_truncated(last);
        }
        Ok(())
    }

    fn start_episode(&mut self, phase: u8) {
        let params = match Phase::from_u8(phase) {
            Some(Phase::Eval) => LearnParams::greedy(),
            _ => self.train_params,
        };
        self.tree.set_params(params);
        self.comm.reset();
        self.finished = false;
        let mut scratch = TrialAction::default();
        let mut ctx = UavTick {
            body: Body {
                pose: self.pose,
                route_len: self.route_len,
                sees_target: false,
                ended: false,
                action: &mut scratch,
            },
            states: &mut self.states,
            comm: &self.comm,
            state: None,
        };
        self.tree.halt(&mut ctx);
    }

    pub fn slot(&self) -> usize {
        self.slot
    }

    /// Whether the episode in progress is a training one: between training episodes (the
    /// greedy evaluations, and once the trial is done) the tables do not change.
    pub fn is_training(&self) -> bool {
        self.open.is_some_and(|(phase, _)| phase == Phase::Train as u8)
    }

    /// Training episodes behind this agent's tables in this trial (those of the snapshot it
    /// was restored from included).
    pub fn trained_episodes(&self) -> u64 {
        self.trained_episodes
    }

    /// Sets the training episodes behind the tables (restoring a snapshot).
    pub(crate) fn set_trained_episodes(&mut self, episodes: u64) {
        self.trained_episodes = episodes;
    }

    pub fn tree(&self) -> &Tree {
        &self.tree
    }

    pub fn tree_mut(&mut self) -> &mut Tree {
        &mut self.tree
    }

    /// What this agent knows of the others now.
    pub fn comm(&self) -> &CommState {
        &self.comm
    }

    pub fn states(&self) -> &StateSpace {
        &self.states
    }

    pub fn set_states(&mut self, states: StateSpace) {
        self.states = states;
    }
}

/// One UAV agent: one [`TrialAgent`] per trial.
#[derive(Debug, Clone)]
pub struct UavAgent {
    slot: usize,
    /// Agent slots of the run (one per route): what each observation must carry.
    slots: usize,
    trials: Vec<TrialAgent>,
}

impl UavAgent {
    pub fn new(spec: &AgentSpec) -> Result<UavAgent, AgentError> {
        if spec.slot >= spec.scenario.agent_slots() {
            return Err(AgentError::NoRoute {
                slot: spec.slot,
                scenario: spec.scenario.name().to_string(),
                routes: spec.scenario.n_routes(),
            });
        }
        if spec.trials == 0 || spec.trials > MAX_TRIALS {
            return Err(AgentError::Trials { trials: spec.trials, max: MAX_TRIALS });
        }
        spec.params.validate().map_err(AgentError::Params)?;
        // Each trial has its own RNG stream; the trials' trees share one shape.
        let rng = |trial: usize| {
            Xoshiro256PlusPlus::seed_from_u64(seed::derive(
                spec.seed,
                &[seed::AGENT, spec.slot as u64, trial as u64],
            ))
        };
        let template = Tree::new(&spec.tree, spec.params, rng(0))?;
        let trials =
            (0..spec.trials).map(|k| TrialAgent::new(spec, template.fresh(rng(k)))).collect();
        Ok(UavAgent { slot: spec.slot, slots: spec.scenario.agent_slots(), trials })
    }

    pub fn slot(&self) -> usize {
        self.slot
    }

    /// The agent's half of a barrier round: one trial action per trial.
    pub fn act(&mut self, obs: &Observation, out: &mut Action) -> Result<(), FieldError> {
        if obs.n_trials as usize != self.trials.len() {
            return Err(FieldError {
                field: "observation.n_trials",
                value: obs.n_trials.into(),
                expected: format!("{}", self.trials.len()),
            });
        }
        if obs.n_slots as usize != self.slots {
            return Err(FieldError {
                field: "observation.n_slots",
                value: obs.n_slots.into(),
                expected: format!("{} (the scenario's routes)", self.slots),
            });
        }
        out.round = obs.round;
        out.agent = self.slot as u32;
        out.n_trials = obs.n_trials;
        for (k, trial) in self.trials.iter_mut().enumerate() {
            trial.act(obs.trial(k), obs.live, &mut out.trials[k])?;
        }
        Ok(())
    }

    pub fn trials(&self) -> &[TrialAgent] {
        &self.trials
    }

    pub fn trials_mut(&mut self) -> &mut [TrialAgent] {
        &mut self.trials
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::uav::load_uav_tree;
    use flockstep_world::sim::{EpisodeConfig, World};

    fn s3() -> Arc<Scenario> {
        Arc::new(Scenario::resolve("s3").expect("s3 is built in"))
    }

    /// UAV1 of s3 and the world's first observation of a run with both UAVs and 2 trials.
    fn uav1_and_first_observation() -> (UavAgent, Box<Observation>) {
        let spec = AgentSpec {
            slot: 0,
            scenario: s3(),
            tree: load_uav_tree(None).expect("the Fig. 5 tree loads"),
            comm: CommMode::Flags,
            params: LearnParams::default(),
            seed: 1,
            trials: 2,
        };
        let config = EpisodeConfig {
            train_episodes: 10,
            eval_episodes: 0,
            eval_every: 0,
            eval_block: 0,
            tick_cap: 100,
        };
        let world = World::new(s3(), 2, 2, 1, config).expect("a world of s3");
        let mut observation = Box::<Observation>::default();
        world.observe(&mut observation);
        (UavAgent::new(&spec).expect("UAV1 of s3"), observation)
    }

    #[test]
    fn an_agent_answers_every_trial_of_a_round() {
        let (mut agent, observation) = uav1_and_first_observation();
        let mut action = Box::new(Action::new(0));
        agent.act(&observation, &mut action).expect("a well-formed observation");
        assert_eq!((action.round, action.agent, action.n_trials), (0, 0, 2));
        for trial in &action.trials[..2] {
            assert!(trial.n_commands > 0 || trial.ended == 1, "each trial's tree acts");
            assert_eq!(trial.flags.valid, 1);
        }
    }

    #[test]
    fn an_observation_for_another_number_of_slots_is_refused() {
        let (mut agent, mut observation) = uav1_and_first_observation();
        observation.n_slots = 1;
        let err = agent.act(&observation, &mut Box::new(Action::new(0))).unwrap_err();
        assert_eq!((err.field, err.value), ("observation.n_slots", 1));
        observation.n_slots = 1000;
        let err = agent.act(&observation, &mut Box::new(Action::new(0))).unwrap_err();
        assert_eq!((err.field, err.value), ("observation.n_slots", 1000));
    }
}
