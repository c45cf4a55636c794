//! Episodes and the ground truth: where every UAV is, where the target is, who has finished.
//!
//! [`World`] is the world's whole side of a barrier round: [`World::observe`] writes the
//! round's broadcast, [`World::apply`] takes one agent's action, [`World::end_round`] advances
//! every trial by one tick and reports finished episodes. The in-process runner and the
//! `world` process call exactly these, so both transports compute the same thing.
//!
//! Episode rules (SPEC 2): every UAV starts at the map's `start:` pose, on its own route
//! (waypoint 1 in every built-in map, as SPEC 2 has it; a map may name another waypoint,
//! which every route must have); the target is drawn uniformly among the candidate cells; a UAV's
//! episode ends in the tick its `A-endEpisode` runs, its length counting that tick; a UAV
//! that finished hovers until every member finished or the tick cap is reached; then
//! everyone is reset and a new target drawn. After the training budget each trial runs its
//! greedy-evaluation budget with a separate random stream, then it is done.

use crate::scenario::{state_index, state_pose, Scenario};
use flockstep_proto::{
    low_bits, seed, slots_in, Action, AgentView, EpisodeReport, FieldError, Heading, Height,
    Observation, ObservationKind, Phase, Refusal, TrialAction, TrialHeader, MAX_AGENTS, MAX_TRIALS,
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

/// What the world reads of an agent slot's route in every tick of every trial, taken from
/// the scenario once: no look through the scenario's tables and their bounds per use.
#[derive(Debug, Clone)]
struct Route {
    /// Waypoints.
    len: usize,
    /// Per state ([`state_index`]), the candidate targets seen: the route's part of the
    /// scenario's visibility table.
    sees: Box<[u64]>,
}

impl Route {
    fn new(scenario: &Scenario, slot: usize) -> Route {
        let len = scenario.route_len(slot);
        let states = len * Height::ALL.len() * Heading::ALL.len();
        let sees = (0..states).map(|s| scenario.visible_targets(slot, state_pose(s))).collect();
        Route { len, sees }
    }
}

/// The ground truth of one agent slot in one trial.
#[derive(Debug, Clone, Copy)]
struct SlotTruth {
    /// The slot's view in the next observation, for as long as it is a member: its pose,
    /// whether it finished, the flags it sent in the last tick. Kept in wire form, so that
    /// observing a slot is a copy; only `sees_target` is left to the observation.
    view: AgentView,
    /// The episode length if it finished (then its bit in `TrialWorld::finished` and
    /// `view.finished` are set too), else 0.
    finished_at: u32,
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
    /// Agent slots that finished the current episode: whether everyone finished is one
    /// test against `members`, not a walk over the slots, at the end of every tick.
    finished: u64,
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
    /// Slots whose flags changed in this tick's actions so far.
    flags_sent: u64,
    /// The observation's `flags_changed`: the slots whose flags changed in the last tick's
    /// actions (every slot before the first tick).
    flags_changed: u64,
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
            finished: 0,
            slots: vec![SlotTruth { view: AgentView::default(), finished_at: 0 }; slots],
            phase: Phase::Train,
            trained: 0,
            evaluated: 0,
            block_left: 0,
            tick: 0,
            episode_tick: 0,
            episode_start: 0,
            flags_sent: 0,
            flags_changed: u64::MAX,
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
        self.finished = 0;
        self.episode_tick = 0;
        self.episode_start = self.tick;
        let n_targets = self.scenario.n_targets();
        let rng = match self.phase {
            Phase::Train => &mut self.train_rng,
            Phase::Eval => &mut self.eval_rng,
        };
        self.target = rng.random_range(0..n_targets);
        let start = self.scenario.start_pose();
        for truth in &mut self.slots {
            truth.view = AgentView {
                pose: start,
                member: 1,
                flags: truth.view.flags,
                ..AgentView::default()
            };
            truth.finished_at = 0;
        }
    }

    /// Writes this trial's part of the round's broadcast.
    #[inline]
    fn observe(&self, routes: &[Route], out: &mut TrialHeader, views: &mut [AgentView]) {
        out.episode = self.episode();
        out.tick = self.tick;
        out.episode_tick = self.episode_tick;
        out.done = self.done as u8;
        out.phase = self.phase as u8;
        out.members = self.members;
        out.flags_changed = self.flags_changed;
        let slots = views.iter_mut().zip(&self.slots).zip(routes);
        for (slot, ((view, truth), route)) in slots.enumerate() {
            if self.members & (1 << slot) == 0 {
                *view = AgentView::default();
                continue;
            }
            *view = truth.view;
            view.sees_target = (route.sees[state_index(view.pose)] >> self.target & 1) as u8;
        }
    }

    /// Applies agent `slot`'s checked action for this tick: its commands in the order
    /// issued (on its route of `route_len` waypoints), its episode end, its flags.
    #[inline]
    fn apply(&mut self, slot: usize, route_len: usize, action: &TrialAction) {
        let bit = 1 << slot;
        if self.done || self.members & bit == 0 {
            return;
        }
        let truth = &mut self.slots[slot];
        self.flags_sent |= u64::from(truth.view.flags.differs(&action.flags)) << slot;
        truth.view.flags = action.flags;
        if self.finished & bit != 0 {
            return; // hovering: only its flags count
        }
        for command in action.commands() {
            truth.view.pose = truth.view.pose.apply(command, route_len);
        }
        if action.ended == 1 {
            truth.finished_at = self.episode_tick + 1;
            truth.view.finished = 1;
            self.finished |= bit;
        }
    }

    /// Ends the tick. If the shared episode is over (every member finished, or the tick
    /// cap), appends its report to `reports` and
    /// starts the next episode, phase, or marks the trial done.
    #[inline]
    fn end_tick(&mut self, reports: &mut Vec<EpisodeReport>) {
        if self.done {
            return;
        }
        self.tick += 1;
        self.episode_tick += 1;
        self.flags_changed = std::mem::take(&mut self.flags_sent);
        let everyone_finished = self.members & !self.finished == 0;
        if everyone_finished || self.episode_tick >= self.config.tick_cap {
            reports.push(self.end_episode());
        }
    }

    /// Reports the episode that just ended and moves on to the next one. Kept out of
    /// [`TrialWorld::end_tick`], which runs in every tick and is inlined into the round:
    /// episodes end in about one tick in twenty.
    #[inline(never)]
    fn end_episode(&mut self) -> EpisodeReport {
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
        report
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
    /// Per agent slot (one per route, at most `MAX_AGENTS`): its route, the same in every
    /// trial.
    routes: Vec<Route>,
    /// The bits of the scenario's candidate targets: an action's target masks stay within.
    valid_targets: u64,
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
        let live = low_bits(agents);
        let routes = (0..scenario.agent_slots()).map(|slot| Route::new(&scenario, slot)).collect();
        let valid_targets = low_bits(scenario.n_targets());
        let trials = (0..trials)
            .map(|k| TrialWorld::new(scenario.clone(), k, run_seed, config, live))
            .collect();
        Ok(World { trials, round: 0, live, routes, valid_targets })
    }

    /// Writes the broadcast of the current round (a `Stop` once every trial is done).
    pub fn observe(&self, out: &mut Observation) {
        out.round = self.round;
        out.live = self.live;
        let mut all_done = true;
        for (trial, (header, views)) in
            self.trials.iter().zip(out.shape_mut(self.trials.len(), self.slots()))
        {
            trial.observe(&self.routes, header, views);
            all_done &= trial.is_done();
        }
        out.kind = if all_done { ObservationKind::Stop } else { ObservationKind::Tick } as u8;
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
        // An unknown route has no waypoints: its flags fail the check.
        let route_len = self.routes.get(slot).map_or(0, |route| route.len);
        for part in &action.trials[..self.trials.len()] {
            part.check(route_len, self.valid_targets)?;
        }
        for (trial, part) in self.trials.iter_mut().zip(&action.trials) {
            trial.apply(slot, route_len, part);
        }
        Ok(())
    }

    /// Closes the round: every trial ends its tick; finished episodes go to `reports`.
    pub fn end_round(&mut self, reports: &mut Vec<EpisodeReport>) {
        for trial in &mut self.trials {
            trial.end_tick(reports);
        }
        self.round += 1;
    }

    /// Agent slots in the barrier.
    pub fn live(&self) -> u64 {
        self.live
    }

    /// The slot an agent asking for `wanted` gets: that slot if its route is free, never
    /// another (an agent asking for a slot must fly that route: a restarted one's snapshots
    /// are for it); with None, the first free route. The error says why there is none.
    pub fn free_slot(&self, wanted: Option<usize>) -> Result<usize, Refusal> {
        let routes = self.slots();
        let free = |slot: usize| self.live & (1 << slot) == 0;
        match wanted {
            Some(slot) if slot >= routes => Err(Refusal::NoSuchRoute),
            Some(slot) if !free(slot) => Err(Refusal::RouteTaken),
            Some(slot) => Ok(slot),
            None => (0..routes).find(|&slot| free(slot)).ok_or(Refusal::RunFull),
        }
    }

    /// Agent slots of the run: one per route (at most `MAX_AGENTS`).
    pub fn slots(&self) -> usize {
        self.routes.len()
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

#[cfg(test)]
mod tests {
    use super::*;
    use flockstep_proto::{Command, Flags};

    const CONFIG: EpisodeConfig = EpisodeConfig {
        train_episodes: 10,
        eval_episodes: 0,
        eval_every: 0,
        eval_block: 0,
        tick_cap: 100,
    };

    /// A world of s3 (routes of 11 and 5 waypoints, 2 targets), both UAVs, 2 trials.
    fn s3_world() -> World {
        let scenario = Arc::new(Scenario::resolve("s3").expect("s3 is built in"));
        World::new(scenario, 2, 2, 1, CONFIG).expect("a world of s3")
    }

    /// A well-formed action of `slot` for round 0 of `s3_world`.
    fn action(slot: usize) -> Action {
        let mut action = Action::new(slot);
        action.n_trials = 2;
        for part in &mut action.trials[..2] {
            part.push(Command::Rotate);
            part.flags = Flags { valid: 1, waypoint: 4, ..Flags::default() };
        }
        action
    }

    fn observation(world: &World) -> Box<Observation> {
        let mut observation = Box::<Observation>::default();
        world.observe(&mut observation);
        observation
    }

    #[test]
    fn every_bad_field_is_refused_with_its_name_value_and_range() {
        type Spoil = fn(&mut Action);
        let cases: [(usize, Spoil, (&str, u64, &str)); 16] = [
            (0, |a| a.agent = 64, ("action.agent", 64, "< 64")),
            (0, |a| a.agent = 5, ("action.agent", 5, "a live agent slot")),
            (0, |a| a.round = 7, ("action.round", 7, "0")),
            (0, |a| a.n_trials = 999, ("action.n_trials", 999, "2")),
            (0, |a| a.trials[1].flags.waypoint = 11, ("flags.waypoint", 11, "< 11")),
            (1, |a| a.trials[0].flags.waypoint = 5, ("flags.waypoint", 5, "< 5")),
            (1, |a| a.trials[1].flags.sees_target = 2, ("flags.sees_target", 2, "< 2")),
            (0, |a| a.trials[0].ended = 2, ("action.ended", 2, "< 2")),
            (
                0,
                |a| a.trials[1].flags.ruled_out = 0b100,
                ("flags.ruled_out", 4, "a mask within 0x3"),
            ),
            (
                1,
                |a| a.trials[0].flags.confirmed = 1 << 63,
                ("flags.confirmed", 1 << 63, "a mask within 0x3"),
            ),
            (0, |a| a.trials[1].n_commands = 17, ("action.n_commands", 17, "< 17")),
            (0, |a| a.trials[0].commands[0] = 4, ("action.command", 4, "0..=3")),
            (
                1,
                |a| {
                    a.trials[1].push(Command::Elevate);
                    a.trials[1].commands[1] = 255;
                },
                ("action.command", 255, "0..=3"),
            ),
            // The first bad field in message order is the one reported.
            (
                0,
                |a| {
                    a.trials[0].ended = 3;
                    a.trials[0].flags.waypoint = 200;
                },
                ("flags.waypoint", 200, "< 11"),
            ),
            (
                0,
                |a| {
                    a.trials[0].commands[0] = 9;
                    a.trials[0].flags.confirmed = 0b1000;
                },
                ("flags.confirmed", 8, "a mask within 0x3"),
            ),
            (
                0,
                |a| {
                    a.trials[0].n_commands = 40;
                    a.trials[1].flags.sees_target = 7;
                },
                ("action.n_commands", 40, "< 17"),
            ),
        ];
        for (slot, spoil, (field, value, expected)) in cases {
            let mut world = s3_world();
            let before = observation(&world);
            let mut bad = action(slot);
            spoil(&mut bad);
            let err = world.apply(&bad).unwrap_err();
            assert_eq!((err.field, err.value, err.expected.as_str()), (field, value, expected));
            assert_eq!(observation(&world), before, "a bad action changes nothing");
        }
    }

    /// An agent asking for a slot gets that one or a refusal saying why, never another
    /// route; one asking for any gets the first free route.
    #[test]
    fn a_slot_asked_for_is_given_or_refused_with_the_reason() {
        let mut world = s3_world();
        assert_eq!(world.free_slot(Some(1)), Err(Refusal::RouteTaken));
        assert_eq!(world.free_slot(Some(2)), Err(Refusal::NoSuchRoute));
        assert_eq!(world.free_slot(Some(usize::MAX)), Err(Refusal::NoSuchRoute));
        assert_eq!(world.free_slot(None), Err(Refusal::RunFull));
        world.remove(0);
        assert_eq!(world.free_slot(Some(1)), Err(Refusal::RouteTaken), "not the free route 0");
        assert_eq!(world.free_slot(Some(0)), Ok(0));
        assert_eq!(world.free_slot(None), Ok(0));
    }

    #[test]
    fn command_codes_past_the_count_are_not_looked_at() {
        let mut world = s3_world();
        let mut fine = action(0);
        fine.trials[0].commands[1] = 77;
        fine.trials[1].n_commands = 0;
        fine.trials[1].commands[0] = 77;
        assert_eq!(world.apply(&fine), Ok(()));
    }

    #[test]
    fn an_episode_ends_when_every_remaining_member_has_finished() {
        let mut world = s3_world();
        let mut reports = Vec::new();
        let mut first = action(0);
        first.trials[0].ended = 1;
        world.apply(&first).expect("a good action");
        world.apply(&action(1)).expect("a good action");
        world.end_round(&mut reports);
        assert!(reports.is_empty(), "UAV2 still flies");

        world.remove(1);
        let mut hover = action(0);
        hover.round = 1;
        world.apply(&hover).expect("a good action");
        world.end_round(&mut reports);
        let [report] = reports.as_slice() else { panic!("one report: {reports:?}") };
        assert_eq!((report.trial, report.members, report.truncated), (0, 1, 0));
        assert_eq!(report.lengths[..2], [1, 0]);
        let view = observation(&world).trial(0).agents[0];
        assert_eq!(
            (view.finished, view.member, view.pose),
            (0, 1, Scenario::resolve("s3").unwrap().start_pose())
        );
    }

    #[test]
    fn flags_changed_marks_the_slots_whose_relayed_flags_changed_since_the_last_tick() {
        let mut world = s3_world();
        let mut reports = Vec::new();
        let changed = |world: &World, trial| observation(world).trial(trial).header.flags_changed;
        assert_eq!(changed(&world, 0), u64::MAX, "the first tick has nothing to compare with");
        for round in 0..3 {
            let (mut first, mut second) = (action(0), action(1));
            (first.round, second.round) = (round, round);
            if round == 1 {
                first.trials[1].flags.waypoint = 5; // only UAV1 in trial 1 says something new
            }
            world.apply(&first).expect("a good action");
            world.apply(&second).expect("a good action");
            world.end_round(&mut reports);
            let expected = match round {
                0 => [0b11, 0b11], // every slot's flags went from none to some
                1 => [0b00, 0b01],
                _ => [0b00, 0b01], // back to waypoint 4
            };
            assert_eq!([changed(&world, 0), changed(&world, 1)], expected, "after round {round}");
        }
    }
}
