//! A scripted [`TickContext`] shared by the behavior-tree semantics and learning tests.
//!
//! Trees are written in the text format and parsed with [`OpenCatalog`], so any leaf name
//! works (`A-a`, `C-c`...). Each action leaf follows a script (a fixed list of results, a
//! constant result, or "takes N ticks, then returns X"), keeps a progress counter the way
//! the UAV's leaves do (incremented while RUNNING, back to 0 when it finishes or is halted)
//! and counts its ticks, starts (ticks from progress 0) and halts. Conditions have settable
//! booleans. `rl_state()` returns a settable state id. Every leaf call of the current tick
//! is logged as `c=S`, `a=R`, `halt a`, so a test can assert exactly what a tick did.
//!
//! Every test binary uses only part of this module.
#![allow(dead_code)]

use flockstep_agents::bt::parse::parse_tree;
use flockstep_agents::bt::replay::OpenCatalog;
use flockstep_agents::bt::spec::{LeafCatalog, LeafId, LeafKind};
use flockstep_agents::bt::status::Status;
use flockstep_agents::bt::tree::{NodeId, TickContext, TraceEvent, Tree};
use flockstep_agents::learning::{LearnParams, QTable, StateId};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::collections::VecDeque;

pub use Status::{Failure as F, Running as R, Success as S};

/// How an action leaf answers its ticks.
#[derive(Debug, Clone)]
pub enum Behaviour {
    /// Not scripted: ticking it fails the test.
    Unscripted,
    /// These results in turn; ticking it once more fails the test.
    List(VecDeque<Status>),
    /// Always this result.
    Always(Status),
    /// RUNNING on the first `ticks - 1` ticks from progress 0, then `result` (progress back
    /// to 0, so it can run again). A halt restarts it from the beginning.
    Takes { ticks: u32, result: Status },
}

#[derive(Debug, Clone)]
pub struct Action {
    pub name: String,
    pub behaviour: Behaviour,
    /// Times ticked.
    pub ticks: u32,
    /// Times ticked with progress 0 (a fresh start).
    pub starts: u32,
    /// Times halted through `halt_action`.
    pub halts: u32,
    /// The progress handed to each tick, in order.
    pub progress_seen: Vec<u32>,
    /// The progress handed to each halt, in order.
    pub progress_at_halt: Vec<u32>,
    /// If set, ticking this action moves the RL state there (the world changed under it).
    pub moves_state_to: Option<StateId>,
}

#[derive(Debug, Clone)]
pub struct Condition {
    pub name: String,
    pub value: bool,
    /// Times checked.
    pub checks: u32,
}

/// The scripted context: leaves by [`LeafId`], the RL state, and what happened.
#[derive(Debug, Clone)]
pub struct Ctx {
    pub actions: Vec<Action>,
    pub conditions: Vec<Condition>,
    /// What `rl_state()` returns.
    pub state: StateId,
    /// Times `rl_state()` was called.
    pub observations: u32,
    /// Every trace event since the tree was built.
    pub events: Vec<TraceEvent>,
    /// Leaf calls of the current tick: `c=S`, `a=R`, `halt a`.
    pub log: Vec<String>,
}

fn letter(status: Status) -> &'static str {
    match status {
        Status::Success => "S",
        Status::Failure => "F",
        Status::Running => "R",
    }
}

impl TickContext for Ctx {
    fn tick_action(&mut self, leaf: LeafId, progress: &mut u32) -> Status {
        let action = &mut self.actions[leaf as usize];
        action.ticks += 1;
        action.progress_seen.push(*progress);
        if *progress == 0 {
            action.starts += 1;
        }
        let status = match &mut action.behaviour {
            Behaviour::Unscripted => panic!("A-{} was ticked but is not scripted", action.name),
            Behaviour::List(list) => list
                .pop_front()
                .unwrap_or_else(|| panic!("A-{} was ticked more often than scripted", action.name)),
            Behaviour::Always(status) => *status,
            Behaviour::Takes { ticks, result } => {
                if *progress + 1 >= *ticks {
                    *result
                } else {
                    Status::Running
                }
            }
        };
        // Like the UAV's rotate: progress counts RUNNING ticks and is 0 once finished.
        *progress = if status == Status::Running { *progress + 1 } else { 0 };
        if let Some(state) = action.moves_state_to {
            self.state = state;
        }
        let entry = format!("{}={}", action.name, letter(status));
        self.log.push(entry);
        status
    }

    fn halt_action(&mut self, leaf: LeafId, progress: &mut u32) {
        let action = &mut self.actions[leaf as usize];
        action.halts += 1;
        action.progress_at_halt.push(*progress);
        *progress = 0;
        let entry = format!("halt {}", action.name);
        self.log.push(entry);
    }

    fn check_condition(&mut self, leaf: LeafId) -> bool {
        let condition = &mut self.conditions[leaf as usize];
        condition.checks += 1;
        let entry = format!("{}={}", condition.name, if condition.value { "S" } else { "F" });
        let value = condition.value;
        self.log.push(entry);
        value
    }

    fn rl_state(&mut self) -> StateId {
        self.observations += 1;
        self.state
    }

    fn trace(&mut self, event: TraceEvent) {
        self.events.push(event);
    }
}

/// A parsed tree and its scripted context.
pub struct Bt {
    pub tree: Tree,
    pub ctx: Ctx,
    /// Index into `ctx.events` where the last tick's events begin.
    last_tick_events: usize,
}

/// Learning parameters that never learn nor explore: for pure tick-semantics tests.
pub fn frozen() -> LearnParams {
    LearnParams { alpha: 0.0, gamma: 1.0, epsilon: 0.0, learn: false }
}

impl Bt {
    /// Parses `text` (panics on a parse error: the trees of the tests are valid).
    pub fn new(text: &str) -> Bt {
        Bt::with(text, frozen(), 0)
    }

    pub fn with(text: &str, params: LearnParams, seed: u64) -> Bt {
        let catalog = OpenCatalog::default();
        let spec = parse_tree("test.bt", text, &catalog).unwrap_or_else(|e| panic!("{e}"));
        let tree = Tree::new(&spec, params, Xoshiro256PlusPlus::seed_from_u64(seed))
            .unwrap_or_else(|e| panic!("{e}"));
        let actions = catalog
            .names(LeafKind::Action)
            .into_iter()
            .map(|name| Action {
                name,
                behaviour: Behaviour::Unscripted,
                ticks: 0,
                starts: 0,
                halts: 0,
                progress_seen: Vec::new(),
                progress_at_halt: Vec::new(),
                moves_state_to: None,
            })
            .collect();
        let conditions = catalog
            .names(LeafKind::Condition)
            .into_iter()
            .map(|name| Condition { name, value: false, checks: 0 })
            .collect();
        let ctx = Ctx {
            actions,
            conditions,
            state: 0,
            observations: 0,
            events: Vec::new(),
            log: Vec::new(),
        };
        Bt { tree, ctx, last_tick_events: 0 }
    }

    /// Ticks the root once; the log then holds this tick's leaf calls.
    pub fn tick(&mut self) -> Status {
        self.ctx.log.clear();
        self.last_tick_events = self.ctx.events.len();
        self.tree.tick(&mut self.ctx)
    }

    /// Ticks once and returns the status with the leaf calls of the tick.
    pub fn step(&mut self) -> (Status, Vec<String>) {
        let status = self.tick();
        (status, self.ctx.log.clone())
    }

    /// Ticks once and asserts the root's status and the exact leaf calls of the tick.
    #[track_caller]
    pub fn expect(&mut self, status: Status, log: &[&str]) {
        let got = self.step();
        let expected: Vec<String> = log.iter().map(|entry| entry.to_string()).collect();
        assert_eq!(got, (status, expected), "(status, leaf calls) of this tick");
    }

    /// Halts the whole tree (as at the end of an episode); the log holds the halts.
    pub fn halt(&mut self) {
        self.ctx.log.clear();
        self.last_tick_events = self.ctx.events.len();
        self.tree.halt(&mut self.ctx);
    }

    /// Ticks until the root is not RUNNING, at most `limit` times; returns the status and
    /// the number of ticks.
    pub fn run(&mut self, limit: u32) -> (Status, u32) {
        for n in 1..=limit {
            let status = self.tick();
            if status != Status::Running {
                return (status, n);
            }
        }
        panic!("still RUNNING after {limit} ticks");
    }

    fn action_id(&self, name: &str) -> usize {
        self.ctx
            .actions
            .iter()
            .position(|a| a.name == name)
            .unwrap_or_else(|| panic!("no action A-{name} in the tree"))
    }

    fn condition_id(&self, name: &str) -> usize {
        self.ctx
            .conditions
            .iter()
            .position(|c| c.name == name)
            .unwrap_or_else(|| panic!("no condition C-{name} in the tree"))
    }

    pub fn action(&mut self, name: &str) -> &mut Action {
        let id = self.action_id(name);
        &mut self.ctx.actions[id]
    }

    pub fn get(&self, name: &str) -> &Action {
        &self.ctx.actions[self.action_id(name)]
    }

    /// Scripts action `name` to return `results` in turn.
    pub fn returns(&mut self, name: &str, results: &[Status]) -> &mut Self {
        self.action(name).behaviour = Behaviour::List(results.iter().copied().collect());
        self
    }

    /// Scripts action `name` to always return `result`.
    pub fn always(&mut self, name: &str, result: Status) -> &mut Self {
        self.action(name).behaviour = Behaviour::Always(result);
        self
    }

    /// Scripts action `name` to take `ticks` ticks (RUNNING before), then return `result`.
    pub fn takes(&mut self, name: &str, ticks: u32, result: Status) -> &mut Self {
        self.action(name).behaviour = Behaviour::Takes { ticks, result };
        self
    }

    /// Sets condition `name`.
    pub fn set(&mut self, name: &str, value: bool) -> &mut Self {
        let id = self.condition_id(name);
        self.ctx.conditions[id].value = value;
        self
    }

    pub fn ticks(&self, name: &str) -> u32 {
        self.get(name).ticks
    }

    pub fn starts(&self, name: &str) -> u32 {
        self.get(name).starts
    }

    pub fn halts(&self, name: &str) -> u32 {
        self.get(name).halts
    }

    pub fn checks(&self, name: &str) -> u32 {
        self.ctx.conditions[self.condition_id(name)].checks
    }

    /// Labels (`A-a`, `OR*`, `PAR m=2`) of the nodes halted in the last tick, in order.
    pub fn halted(&self) -> Vec<String> {
        self.ctx.events[self.last_tick_events..]
            .iter()
            .filter_map(|event| match *event {
                TraceEvent::Halted { node } => Some(self.label(node)),
                _ => None,
            })
            .collect()
    }

    /// Status each node labelled `label` returned in the last tick (in tick order).
    pub fn returned(&self, label: &str) -> Vec<Status> {
        self.ctx.events[self.last_tick_events..]
            .iter()
            .filter_map(|event| match *event {
                TraceEvent::Ticked { node, status } if self.label(node) == label => Some(status),
                _ => None,
            })
            .collect()
    }

    /// The children (0-based) learning selectors chose in the last tick, in order.
    pub fn chosen(&self) -> Vec<u32> {
        self.ctx.events[self.last_tick_events..]
            .iter()
            .filter_map(|event| match *event {
                TraceEvent::Chose { child, .. } => Some(child),
                _ => None,
            })
            .collect()
    }

    pub fn label(&self, node: NodeId) -> String {
        self.tree.label(node).1.to_string()
    }

    /// The `i`-th learning selector's Q-table (pre-order).
    pub fn table(&self, i: usize) -> QTable {
        self.tree.tables()[i].clone()
    }

    /// Q(`state`, .) of the `i`-th learning selector (zeros if the row was never written).
    pub fn row(&self, i: usize, state: StateId) -> Vec<f64> {
        row(&self.table(i), state)
    }
}

/// Q(`state`, .) of `table` (zeros if the row was never written).
pub fn row(table: &QTable, state: StateId) -> Vec<f64> {
    (0..table.n_actions()).map(|action| table.get(state, action)).collect()
}

/// A Q-table with the given rows: `rows[k] = (state, [Q(state, 0), Q(state, 1), ...])`.
/// Every value is stored exactly (a step with alpha 1 from 0 lands on the target).
pub fn table(n_actions: usize, rows: &[(StateId, &[f64])]) -> QTable {
    let mut table = QTable::new(n_actions);
    for (state, values) in rows {
        assert_eq!(values.len(), n_actions, "row of state {state}");
        for (action, &value) in values.iter().enumerate() {
            table.step(*state, action, value, 1.0);
        }
    }
    for (state, values) in rows {
        assert_eq!(&row(&table, *state), values, "preloading state {state}");
    }
    table
}

/// `a` and `b` agree to 1e-12 (Q-values computed two ways may differ in the last bit).
#[track_caller]
pub fn assert_close(actual: f64, expected: f64) {
    assert!((actual - expected).abs() <= 1e-12, "Q = {actual}, expected {expected}");
}
