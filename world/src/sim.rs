//! Episodes and the ground truth: where every UAV is, where the target is, who has finished.
//!
//! [`World`] is the world's whole side of a barrier round: [`World::observe`] writes the
//! round's broadcast, [`World::apply`] takes one agent's action, [`World::end_round`] advances
//! every trial by one tick and reports finished episodes. The in-process runner and the
//! `world` process call exactly these, so both transports compute the same thing.
//!
//! Episode rules (SPEC 2): every UAV starts at its route's waypoint 1 with the map's start
//! height and heading; the target is drawn uniformly among the candidate cells; a UAV's
//! episode ends in the tick its `A-endEpisode` runs, its length counting that tick; a UAV
//! that finished hovers until every member finished or the tick cap is reached; then
//! everyone is reset and a new target drawn. After the training budget each trial runs its
//! greedy-evaluation budget with a separate random stream, then it is done.

use crate::scenario::Scenario;
use flockstep_proto::{
    seed, slots_in, Action, AgentView, EpisodeReport, FieldError, Flags, Observation,
    ObservationKind, Phase, Pose, TrialAction, TrialHeader, MAX_AGENTS, MAX_TRIALS,
};
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

/// Budgets and limits of a run's episodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EpisodeConfig {
    /// Training episodes per trial.
    pub train_episodes: u64,
    /// Greedy evaluation episodes per trial after training (0: none).
    pub eval_episodes: u64,
    /// A block of `eval_block` greedy episodes after every `eval_every` training episodes
    /// (0: none), to follow the greedy policy while it learns.
    pub eval_every: u64,
    pub eval_block: u64,
    /// Ticks after which a shared episode is cut (truncated).
    pub tick_cap: u32,
}

/// The ground truth of one agent slot in one trial.
#[derive(Debug, Clone, Copy)]
struct SlotTruth {
    pose: Pose,
    /// The episode length if it finished, else 0.
    finished_at: u32,
    /// The flags it sent in the last tick, relayed in the next observation.
    flags: Flags,
}

/// The ground truth of one trial.
#[derive(Debug, Clone)]
pub struct TrialWorld {
    scenario: Arc<Scenario>,
    trial: u32,
    config: EpisodeConfig,
    train_rng: Xoshiro256PlusPlus,
    eval_rng: Xoshiro256PlusPlus,
    /// Agent slots taking part in the current episode.
    members: u64,
    /// Agent slots admitted to the run that join at the next episode start.
    joining: u64,
    /// Per agent slot, side by side: a tick reads and writes each slot's fields together.
    slots: Vec<SlotTruth>,
    phase: Phase,
    /// Training episodes finished.
    trained: u64,
    /// Evaluation episodes finished (all blocks together).
    evaluated: u64,
    /// Evaluation episodes left in the current block.
    block_left: u64,
    tick: u64,
    episode_tick: u32,
    episode_start: u64,
    target: usize,
    done: bool,
}

impl TrialWorld {
    /// Trial `trial` of a run seeded with `seed`, with agent slots `members` taking part.
    pub fn new(
        scenario: Arc<Scenario>,
        trial: usize,
        run_seed: u64,
        config: EpisodeConfig,
        members: u64,
    ) -> Self {
        let slots = scenario.n_routes();
        let rng = |stream| {
            Xoshiro256PlusPlus::seed_from_u64(seed::derive(run_seed, &[stream, trial as u64]))
        };
        let mut world = TrialWorld {
            trial: trial as u32,
            config,
            train_rng: rng(seed::WORLD_TRAIN),
            eval_rng: rng(seed::WORLD_EVAL),
            members,
            joining: 0,
            slots: vec![
                SlotTruth {
                    pose: scenario.start_pose(),
                    finished_at: 0,
                    flags: Flags::default()
                };
                slots
            ],
            phase: Phase::Train,
            trained: 0,
            evaluated: 0,
            block_left: 0,
            tick: 0,
            episode_tick: 0,
            episode_start: 0,
            target: 0,
            done: false,
            scenario,
        };
        if config.train_episodes == 0 {
            world.begin_eval(config.eval_episodes);
        }
        world.start_episode();
        world
    }

    /// Starts a block of `episodes` greedy episodes; after the last training episode a
    /// block of none means the trial is done.
    fn begin_eval(&mut self, episodes: u64) {
        if episodes == 0 {
            self.done = self.trained == self.config.train_episodes;
            return;
        }
        self.phase = Phase::Eval;
        self.block_left = episodes;
    }

    /// The index of the episode in progress within its phase.
    fn episode(&self) -> u64 {
        match self.phase {
            Phase::Train => self.trained,
            Phase::Eval => self.evaluated,
        }
    }

    /// Moves on after an episode: evaluation blocks after every `eval_every` training
    /// episodes and after the last one; training again after a block; done at the end.
    fn next_episode(&mut self) {
        let config = self.config;
        match self.phase {
            Phase::Train => {
                self.trained += 1;
                if self.trained == config.train_episodes {
                    self.begin_eval(config.eval_episodes);
                } else if config.eval_every > 0
                    && config.eval_block > 0
                    && self.trained.is_multiple_of(config.eval_every)
                {
                    self.begin_eval(config.eval_block);
                }
            }
            Phase::Eval => {
                self.evaluated += 1;
                self.block_left -= 1;
                if self.block_left == 0 {
                    if self.trained == config.train_episodes {
                        self.done = true;
                    } else {
                        self.phase = Phase::Train;
                    }
                }
            }
        }
    }

    fn start_episode(&mut self) {
        self.members |= self.joining;
        self.joining = 0;
        let start = self.scenario.start_pose();
        for slot in &mut self.slots {
            slot.pose = start;
            slot.finished_at = 0;
        }
        self.episode_tick = 0;
        self.episode_start = self.tick;
        let n_targets = self.scenario.n_targets();
        let rng = match self.phase {
            Phase::Train => &mut self.train_rng,
            Phase::Eval => &mut self.eval_rng,
        };
        self.target = rng.random_range(0..n_targets);
    }

    /// Writes this trial's part of the round's broadcast.
    pub fn observe(&self, out: &mut TrialHeader, views: &mut [AgentView]) {
        out.episode = self.episode();
        out.tick = self.tick;
        out.episode_tick = self.episode_tick;
        out.done = self.done as u8;
        out.phase = self.phase as u8;
        out.members = self.members;
        for (slot, (view, truth)) in views.iter_mut().zip(&self.slots).enumerate() {
            if self.members & (1 << slot) == 0 {
                *view = Default::default();
                continue;
            }
            view.pose = truth.pose;
            view.sees_target =
                (self.scenario.visible_targets(slot, truth.pose) >> self.target & 1) as u8;
            view.finished = (truth.finished_at != 0) as u8;
            view.member = 1;
            view.flags = truth.flags;
        }
    }

    /// Checks agent `slot`'s action against its route before anything is applied.
    pub fn check(&self, slot: usize, action: &TrialAction) -> Result<(), FieldError> {
        let route_len = self.scenario.route_len(slot) as u64;
        flockstep_proto::check_below("flags.waypoint", action.flags.waypoint.into(), route_len)?;
        flockstep_proto::check_below("flags.sees_target", action.flags.sees_target.into(), 2)?;
        flockstep_proto::check_below("action.ended", action.ended.into(), 2)?;
        let targets = self.scenario.n_targets();
        let valid = if targets >= 64 { u64::MAX } else { (1 << targets) - 1 };
        for (field, mask) in [
            ("flags.ruled_out", action.flags.ruled_out),
            ("flags.confirmed", action.flags.confirmed),
        ] {
            if mask & !valid != 0 {
                return Err(FieldError {
                    field,
                    value: mask,
                    expected: format!("a mask within {valid:#x}"),
                });
            }
        }
        action.check_commands()
    }

    /// Applies agent `slot`'s checked action for this tick: its commands in the order
    /// issued, its episode end, its flags.
    pub fn apply(&mut self, slot: usize, action: &TrialAction) {
        if self.done || self.members & (1 << slot) == 0 {
            return;
        }
        let route_len = self.scenario.route_len(slot);
        let truth = &mut self.slots[slot];
        truth.flags = action.flags;
        if truth.finished_at != 0 {
            return; // hovering: only its flags count
        }
        for command in action.commands() {
            truth.pose = truth.pose.apply(command, route_len);
        }
        if action.ended == 1 {
            truth.finished_at = self.episode_tick + 1;
        }
    }

    /// Ends the tick. If the shared episode is over (every member finished, or the tick
    /// cap), returns its report and starts the next episode, phase, or marks the trial done.
    pub fn end_tick(&mut self) -> Option<EpisodeReport> {
        if self.done {
            return None;
        }
        self.tick += 1;
        self.episode_tick += 1;
        let everyone_finished =
            slots_in(self.members).all(|slot| self.slots[slot].finished_at != 0);
        if !everyone_finished && self.episode_tick < self.config.tick_cap {
            return None;
        }
        let mut report = EpisodeReport {
            trial: self.trial,
            target: self.target as u16,
            phase: self.phase as u8,
            episode: self.episode(),
            start_tick: self.episode_start,
            members: self.members,
            ..EpisodeReport::default()
        };
        for slot in slots_in(self.members) {
            let finished = self.slots[slot].finished_at;
            report.lengths[slot] = if finished != 0 { finished } else { self.episode_tick };
            if finished == 0 {
                report.truncated |= 1 << slot;
            }
        }
        self.next_episode();
        if !self.done {
            self.start_episode();
        }
        Some(report)
    }

    pub fn is_done(&self) -> bool {
        self.done
    }

    /// Agent `slot` joins this trial at its next episode start.
    pub fn admit(&mut self, slot: usize) {
        self.joining |= 1 << slot;
    }

    /// Agent `slot` is gone: the episode in progress goes on without it, and its part of
    /// that episode is not reported.
    pub fn remove(&mut self, slot: usize) {
        self.members &= !(1 << slot);
        self.joining &= !(1 << slot);
    }
}

/// Every trial of a run: the world's side of the barrier.
#[derive(Debug, Clone)]
pub struct World {
    trials: Vec<TrialWorld>,
    round: u64,
    live: u64,
}

/// Why a world cannot be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WorldSetupError {
    #[error("{trials} trials requested; between 1 and {max} are supported")]
    Trials { trials: usize, max: usize },
    #[error("{agents} UAVs requested, but scenario `{scenario}` has {routes} routes")]
    TooManyAgents { agents: usize, scenario: String, routes: usize },
    #[error("the tick cap must be at least 1")]
    TickCap,
}

impl World {
    /// A world of `trials` trials with agent slots `0..agents` taking part.
    pub fn new(
        scenario: Arc<Scenario>,
        agents: usize,
        trials: usize,
        run_seed: u64,
        config: EpisodeConfig,
    ) -> Result<World, WorldSetupError> {
        if trials == 0 || trials > MAX_TRIALS {
            return Err(WorldSetupError::Trials { trials, max: MAX_TRIALS });
        }
        if agents == 0 || agents > scenario.n_routes() || agents > MAX_AGENTS {
            return Err(WorldSetupError::TooManyAgents {
                agents,
                scenario: scenario.name().to_string(),
                routes: scenario.n_routes(),
            });
        }
        if config.tick_cap == 0 {
            return Err(WorldSetupError::TickCap);
        }
        let live = if agents == 64 { u64::MAX } else { (1u64 << agents) - 1 };
        let trials = (0..trials)
            .map(|k| TrialWorld::new(scenario.clone(), k, run_seed, config, live))
            .collect();
        Ok(World { trials, round: 0, live })
    }

    /// Writes the broadcast of the current round (a `Stop` once every trial is done).
    pub fn observe(&self, out: &mut Observation) {
        out.round = self.round;
        out.live = self.live;
        out.kind =
            if self.all_done() { ObservationKind::Stop } else { ObservationKind::Tick } as u8;
        for (trial, (header, views)) in
            self.trials.iter().zip(out.shape_mut(self.trials.len(), self.slots()))
        {
            trial.observe(header, views);
        }
    }

    /// Takes one agent's action for the current round, after checking it answers this
    /// round, comes from a live slot and carries every trial: a bad action changes nothing.
    pub fn apply(&mut self, action: &Action) -> Result<(), FieldError> {
        let slot = action.agent as usize;
        flockstep_proto::check_below("action.agent", slot as u64, MAX_AGENTS as u64)?;
        if self.live & (1 << slot) == 0 {
            return Err(FieldError {
                field: "action.agent",
                value: slot as u64,
                expected: "a live agent slot".into(),
            });
        }
        if action.round != self.round {
            return Err(FieldError {
                field: "action.round",
                value: action.round,
                expected: format!("{}", self.round),
            });
        }
        if action.n_trials as usize != self.trials.len() {
            return Err(FieldError {
                field: "action.n_trials",
                value: action.n_trials.into(),
                expected: format!("{}", self.trials.len()),
            });
        }
        for (trial, part) in self.trials.iter().zip(&action.trials) {
            trial.check(slot, part)?;
        }
        for (trial, part) in self.trials.iter_mut().zip(&action.trials) {
            trial.apply(slot, part);
        }
        Ok(())
    }

    /// Closes the round: every trial ends its tick; finished episodes go to `reports`.
    pub fn end_round(&mut self, reports: &mut Vec<EpisodeReport>) {
        let first = reports.len();
        reports.extend(self.trials.iter_mut().filter_map(TrialWorld::end_tick));
        for report in &mut reports[first..] {
            report.live = self.live;
        }
        self.round += 1;
    }

    pub fn all_done(&self) -> bool {
        self.trials.iter().all(TrialWorld::is_done)
    }

    /// Agent slots in the barrier.
    pub fn live(&self) -> u64 {
        self.live
    }

    /// The slot an agent asking for `wanted` gets: that slot if its route is free (an agent
    /// asking for its own slot must fly that route: its snapshots are for it); with None,
    /// the first free route. None if there is no such route.
    pub fn free_slot(&self, wanted: Option<usize>) -> Option<usize> {
        let routes = self.slots();
        let free = |slot: &usize| *slot < routes && self.live & (1 << slot) == 0;
        match wanted {
            Some(slot) => Some(slot).filter(free),
            None => (0..routes).find(free),
        }
    }

    /// Agent slots of the run: one per route (at most `MAX_AGENTS`).
    pub fn slots(&self) -> usize {
        self.trials.first().map_or(0, |t| t.scenario.agent_slots())
    }

    /// Admits agent `slot` to the barrier from the next round on; each trial lets it take
    /// part from its next episode start.
    pub fn admit(&mut self, slot: usize) {
        self.live |= 1 << slot;
        for trial in &mut self.trials {
            trial.admit(slot);
        }
    }

    /// Drops agent `slot` from the barrier and from every trial.
    pub fn remove(&mut self, slot: usize) {
        self.live &= !(1 << slot);
        for trial in &mut self.trials {
            trial.remove(slot);
        }
    }
}
