//! A behavior tree at run time: tick semantics, halting, and the learning selector.
//!
//! The [`TreeSpec`] is flattened into an arena of nodes, the tree's shape, which the copies
//! of a tree share (a UAV ticks one copy per trial); each copy keeps its own run-time state
//! per node (running or not, memory index, decorator counter, action progress), its
//! parallel nodes' results, its learning selectors and its RNG. A tick walks the shape by
//! reference while it changes the run-time state, so neither is reached through the other.
//! Leaves run through a [`TickContext`] callback, so the tree does no I/O and knows nothing
//! of UAVs: the same engine drives the agent, the tests and `agent bt replay`.
//!
//! Semantics (SPEC 1.2, agreeing with BehaviorTree.CPP): `AND`/`OR` are reactive
//! (ReactiveSequence / ReactiveFallback), `AND*`/`OR*` resume at their running child
//! (Sequence / Fallback), `PAR` stops ticking a child once it finished and returns as soon as
//! its threshold is met, `REPEAT` and `RETRY` loop within one tick while the child finishes.
//! A node that was RUNNING and is not reached, or is preempted, is halted; halting an action
//! resets its progress. The learning selector is described on `Run::tick_learning`.

use super::spec::{LeafId, NodeKind, NodeSpec, TreeSpec};
use super::status::Status;
use crate::learning::{LearnParams, QTable, StateId};
use flockstep_proto::MAX_COMMANDS;
use rand::Rng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::Arc;

/// Index of a node in the flattened tree (pre-order: the root is 0).
pub type NodeId = u32;

/// What the tree asks of its owner while it ticks.
pub trait TickContext {
    /// Ticks action `leaf`; `progress` is the leaf's own state (0 when idle).
    fn tick_action(&mut self, leaf: LeafId, progress: &mut u32) -> Status;
    /// Halts a RUNNING action: it must forget its progress.
    fn halt_action(&mut self, leaf: LeafId, progress: &mut u32);
    /// Evaluates condition `leaf` (conditions never return RUNNING).
    fn check_condition(&mut self, leaf: LeafId) -> bool;
    /// The agent's RL state as it is now (learning selectors observe it on every tick).
    fn rl_state(&mut self) -> StateId;
    /// Observes the tick for debugging (`agent bt replay`); free when not overridden.
    #[inline]
    fn trace(&mut self, _event: TraceEvent) {}
}

/// What [`TickContext::trace`] reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceEvent {
    /// `node` was ticked and returned `status`.
    Ticked { node: NodeId, status: Status },
    /// `node` was RUNNING and has been halted.
    Halted { node: NodeId },
    /// A learning selector ordered or stepped: it chose child number `child` (0-based).
    Chose { node: NodeId, child: u32 },
}

/// Why a tree cannot run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TreeError {
    /// `line` and `node` name the deepest node whose own worst case is past the limit (a
    /// `REPEAT` count, or a composite whose children together are): the one to change.
    #[error("{file}:{line}: this {node} may {} up to {worst} {} in one tick{}; the limit is {limit}", .counted.verb(), .counted.noun(), whole_tree(*.worst, *.tree_worst))]
    TooMuchInOneTick {
        file: String,
        line: usize,
        node: String,
        counted: PerTick,
        worst: u64,
        tree_worst: u64,
        limit: usize,
    },
    #[error("{file}:{line}: this learning selector has {children} children; the limit is {limit}")]
    WideLearningSelector { file: String, line: usize, children: usize, limit: usize },
}

/// Most leaves one tick of `agent bt replay` may tick: a replay lists every leaf it ticks,
/// so three nested `REPEAT n=1000` would otherwise run out of memory. Far past any tree of
/// the thesis, which ticks a handful.
pub const MAX_REPLAY_LEAVES: usize = 1_000_000;

/// Most leaves, conditions included, one tick of a run may tick. A condition issues no
/// command, so loops over conditions alone pass [`MAX_COMMANDS`]: three nested
/// `RETRY n=1000` over a condition that fails would tick it a billion times in one tick,
/// while every process of the barrier waits. Far past any tree of the thesis.
pub const MAX_LEAF_TICKS: usize = 1024;

/// What a tick's worst case counts, for the engine's limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PerTick {
    /// Commands to the UAV: one per action ticked.
    Commands,
    /// Leaves ticked: actions and conditions.
    Leaves,
}

impl PerTick {
    fn verb(self) -> &'static str {
        match self {
            PerTick::Commands => "issue",
            PerTick::Leaves => "tick",
        }
    }

    fn noun(self) -> &'static str {
        match self {
            PerTick::Commands => "commands",
            PerTick::Leaves => "leaves",
        }
    }
}

/// Most children a learning selector may have: a tick keeps the children it tried in one
/// word. (Its Q-table has a column per child; 64 actions is far past any tree of the thesis.)
pub const MAX_LEARNING_CHILDREN: usize = 64;

#[derive(Debug, Clone, Copy)]
enum Op {
    Sequence,
    SequenceMemory,
    Fallback,
    FallbackMemory,
    Learning { lor: u32 },
    Parallel { success_threshold: u32 },
    Inverter,
    ForceSuccess,
    ForceFailure,
    Repeat { times: u32 },
    Retry { attempts: u32 },
    Action { leaf: LeafId },
    Condition { leaf: LeafId },
}

/// One node of a tree's shape: what it does and where its children are.
#[derive(Debug, Clone, Copy)]
struct NodeShape {
    op: Op,
    /// Children are `children[first..first + count]`.
    first: u32,
    count: u32,
}

/// What every copy of a tree shares (a UAV has one copy per trial): the nodes, their
/// children and labels. Only the run-time state differs between copies, so the copies
/// of one agent read the same shape, which stays in cache from one trial to the next.
#[derive(Debug)]
struct Shape {
    nodes: Vec<NodeShape>,
    children: Vec<NodeId>,
    /// Node id -> source line and label, for traces and errors.
    labels: Vec<(usize, String)>,
}

/// The run-time state of one node.
#[derive(Debug, Clone, Copy, Default)]
struct NodeState {
    /// The node returned RUNNING on its last tick and has not been halted since.
    running: bool,
    /// Memory child index, decorator counter, or action progress.
    memory: u32,
}

/// Run-time state of one learning selector.
#[derive(Debug, Clone)]
struct Lor {
    table: QTable,
    /// Child (0-based position) that returned RUNNING on the previous tick.
    running_child: Option<u32>,
    /// The step waiting for its next state: (s, child).
    pending: Option<(StateId, u32)>,
}

/// A behavior tree ready to tick, with its learning selectors' Q-tables and RNG.
#[derive(Debug, Clone)]
pub struct Tree {
    shape: Arc<Shape>,
    run: Run,
}

/// The run-time state of one copy of a tree; every tick function walks `shape` beside it.
#[derive(Debug, Clone)]
struct Run {
    /// Run-time state by node id.
    state: Vec<NodeState>,
    /// Parallel nodes: per child slot, 0 = not finished, 1 = SUCCESS, 2 = FAILURE.
    finished: Vec<u8>,
    lors: Vec<Lor>,
    params: LearnParams,
    rng: Xoshiro256PlusPlus,
}

impl Tree {
    /// Builds the run-time tree of a UAV. `rng` orders the learning selectors' children.
    pub fn new(
        spec: &TreeSpec,
        params: LearnParams,
        rng: Xoshiro256PlusPlus,
    ) -> Result<Tree, TreeError> {
        Tree::check(spec)?;
        Ok(Tree::build(spec, params, rng))
    }

    /// Builds a tree whose actions command no UAV (`agent bt replay` answers them from a
    /// script), so the run's limits per tick do not apply; the learning selector width,
    /// which the engine itself needs, is checked, and so is [`MAX_REPLAY_LEAVES`], which
    /// bounds what a replay's tick does and lists.
    pub fn for_replay(
        spec: &TreeSpec,
        params: LearnParams,
        rng: Xoshiro256PlusPlus,
    ) -> Result<Tree, TreeError> {
        check_width(spec)?;
        check_per_tick(spec, PerTick::Leaves, MAX_REPLAY_LEAVES)?;
        Ok(Tree::build(spec, params, rng))
    }

    /// Whether the tree fits the engine's limits (commands and leaves per tick, learning
    /// selector width). [`Tree::new`] checks this too; a run checks it before it starts any
    /// process.
    pub fn check(spec: &TreeSpec) -> Result<(), TreeError> {
        check_per_tick(spec, PerTick::Commands, MAX_COMMANDS)?;
        check_per_tick(spec, PerTick::Leaves, MAX_LEAF_TICKS)?;
        check_width(spec)
    }

    fn build(spec: &TreeSpec, params: LearnParams, rng: Xoshiro256PlusPlus) -> Tree {
        let mut shape = Shape { nodes: Vec::new(), children: Vec::new(), labels: Vec::new() };
        shape.flatten(&spec.root, &mut 0);
        Tree::with_shape(Arc::new(shape), params, rng)
    }

    /// A new, untrained copy of this tree with its own RNG, sharing the shape.
    pub fn fresh(&self, rng: Xoshiro256PlusPlus) -> Tree {
        Tree::with_shape(self.shape.clone(), self.run.params, rng)
    }

    fn with_shape(shape: Arc<Shape>, params: LearnParams, rng: Xoshiro256PlusPlus) -> Tree {
        // Learning selectors are numbered in pre-order, the order of the nodes.
        let lors = shape
            .nodes
            .iter()
            .filter(|node| matches!(node.op, Op::Learning { .. }))
            .map(|node| Lor {
                table: QTable::new(node.count as usize),
                running_child: None,
                pending: None,
            })
            .collect();
        let run = Run {
            state: vec![NodeState::default(); shape.nodes.len()],
            finished: vec![0; shape.children.len()],
            lors,
            params,
            rng,
        };
        Tree { shape, run }
    }

    /// Ticks the tree once from the root.
    pub fn tick(&mut self, ctx: &mut impl TickContext) -> Status {
        self.run.tick_node(&self.shape, 0, ctx)
    }

    /// Halts every running node (e.g. when an episode ends) without learning from it.
    pub fn halt(&mut self, ctx: &mut impl TickContext) {
        self.run.halt_node(&self.shape, 0, ctx);
    }

    /// The episode ended because the UAV finished: every pending learning step gets the
    /// terminal update (no bootstrap), so the choice that revealed the target gets credit.
    pub fn end_episode_terminal(&mut self) {
        let params = self.run.params;
        for lor in &mut self.run.lors {
            if let Some((s, a)) = lor.pending.take() {
                if params.learn {
                    lor.table.terminal(s, a as usize, &params);
                }
            }
        }
    }

    /// The episode was cut by the tick cap in state `last`: pending steps bootstrap from it.
    pub fn end_episode_truncated(&mut self, last: StateId) {
        let params = self.run.params;
        for lor in &mut self.run.lors {
            if let Some((s, a)) = lor.pending.take() {
                if params.learn {
                    lor.table.bootstrap(s, a as usize, last, &params);
                }
            }
        }
    }

    pub fn set_params(&mut self, params: LearnParams) {
        self.run.params = params;
    }

    /// The learning selectors' Q-tables, in pre-order.
    pub fn tables(&self) -> Vec<&QTable> {
        self.run.lors.iter().map(|l| &l.table).collect()
    }

    /// Replaces the Q-tables (loading a snapshot). Shapes must match.
    pub fn set_tables(&mut self, tables: Vec<QTable>) -> Result<(), String> {
        let lors = &mut self.run.lors;
        if tables.len() != lors.len() {
            return Err(format!(
                "snapshot has {} learning selectors, the tree has {}",
                tables.len(),
                lors.len()
            ));
        }
        for (i, (lor, table)) in lors.iter().zip(&tables).enumerate() {
            if lor.table.n_actions() != table.n_actions() {
                return Err(format!(
                    "learning selector {} has {} children, its snapshot table {}",
                    i + 1,
                    lor.table.n_actions(),
                    table.n_actions()
                ));
            }
        }
        for (lor, table) in lors.iter_mut().zip(tables) {
            lor.table = table;
        }
        Ok(())
    }

    /// Source line and label (`A-rotate`, `PAR m=2`...) of a node.
    pub fn label(&self, node: NodeId) -> (usize, &str) {
        let (line, label) = &self.shape.labels[node as usize];
        (*line, label)
    }

    pub fn is_leaf(&self, node: NodeId) -> bool {
        matches!(self.shape.nodes[node as usize].op, Op::Action { .. } | Op::Condition { .. })
    }

    pub fn node_count(&self) -> usize {
        self.shape.nodes.len()
    }
}

impl Shape {
    #[inline]
    fn child(&self, node: NodeId, i: u32) -> NodeId {
        self.children[(self.nodes[node as usize].first + i) as usize]
    }
}

impl Run {
    fn tick_node(&mut self, shape: &Shape, id: NodeId, ctx: &mut impl TickContext) -> Status {
        let node = shape.nodes[id as usize];
        let status = match node.op {
            Op::Condition { leaf } => {
                if ctx.check_condition(leaf) {
                    Status::Success
                } else {
                    Status::Failure
                }
            }
            Op::Action { leaf } => {
                let mut progress = self.state[id as usize].memory;
                let status = ctx.tick_action(leaf, &mut progress);
                self.state[id as usize].memory = progress;
                status
            }
            Op::Sequence => self.tick_reactive(shape, id, Status::Success, ctx),
            Op::Fallback => self.tick_reactive(shape, id, Status::Failure, ctx),
            Op::SequenceMemory => self.tick_memory(shape, id, Status::Success, ctx),
            Op::FallbackMemory => self.tick_memory(shape, id, Status::Failure, ctx),
            Op::Learning { lor } => self.tick_learning(shape, id, lor as usize, ctx),
            Op::Parallel { success_threshold } => {
                self.tick_parallel(shape, id, success_threshold, ctx)
            }
            Op::Inverter => match self.tick_node(shape, shape.child(id, 0), ctx) {
                Status::Success => Status::Failure,
                Status::Failure => Status::Success,
                Status::Running => Status::Running,
            },
            Op::ForceSuccess => match self.tick_node(shape, shape.child(id, 0), ctx) {
                Status::Running => Status::Running,
                _ => Status::Success,
            },
            Op::ForceFailure => match self.tick_node(shape, shape.child(id, 0), ctx) {
                Status::Running => Status::Running,
                _ => Status::Failure,
            },
            Op::Repeat { times } => self.tick_loop(shape, id, times, Status::Success, ctx),
            Op::Retry { attempts } => self.tick_loop(shape, id, attempts, Status::Failure, ctx),
        };
        self.state[id as usize].running = status == Status::Running;
        ctx.trace(TraceEvent::Ticked { node: id, status });
        status
    }

    /// `AND` (`go_on` = SUCCESS) and `OR` (`go_on` = FAILURE): tick from the first child on
    /// every tick; the first child not returning `go_on` decides, and every later child that
    /// was still RUNNING from an earlier tick is halted (it is no longer reached).
    fn tick_reactive(
        &mut self,
        shape: &Shape,
        id: NodeId,
        go_on: Status,
        ctx: &mut impl TickContext,
    ) -> Status {
        let count = shape.nodes[id as usize].count;
        for i in 0..count {
            let status = self.tick_node(shape, shape.child(id, i), ctx);
            if status != go_on {
                self.halt_children_from(shape, id, i + 1, ctx);
                return status;
            }
        }
        go_on
    }

    /// `AND*` / `OR*`: resume at the child that was RUNNING; forget it once the node
    /// returns SUCCESS or FAILURE.
    fn tick_memory(
        &mut self,
        shape: &Shape,
        id: NodeId,
        go_on: Status,
        ctx: &mut impl TickContext,
    ) -> Status {
        let count = shape.nodes[id as usize].count;
        let mut i = self.state[id as usize].memory;
        while i < count {
            let status = self.tick_node(shape, shape.child(id, i), ctx);
            if status == Status::Running {
                self.state[id as usize].memory = i;
                return Status::Running;
            }
            if status != go_on {
                self.state[id as usize].memory = 0;
                return status;
            }
            i += 1;
        }
        self.state[id as usize].memory = 0;
        go_on
    }

    /// `PAR n m=M`: ticks the children that have not finished, in order; SUCCESS as soon as
    /// M succeeded, FAILURE as soon as n-M+1 failed (success is then impossible); either way
    /// the still-running children are halted and the results forgotten.
    fn tick_parallel(
        &mut self,
        shape: &Shape,
        id: NodeId,
        threshold: u32,
        ctx: &mut impl TickContext,
    ) -> Status {
        let NodeShape { first, count, .. } = shape.nodes[id as usize];
        let slots = first as usize..(first + count) as usize;
        let mut successes = self.finished[slots.clone()].iter().filter(|&&f| f == 1).count() as u32;
        let mut failures = self.finished[slots.clone()].iter().filter(|&&f| f == 2).count() as u32;
        for slot in slots.clone() {
            if self.finished[slot] != 0 {
                continue;
            }
            match self.tick_node(shape, shape.children[slot], ctx) {
                Status::Success => {
                    self.finished[slot] = 1;
                    successes += 1;
                }
                Status::Failure => {
                    self.finished[slot] = 2;
                    failures += 1;
                }
                Status::Running => {}
            }
            let decided = if successes >= threshold {
                Some(Status::Success)
            } else if failures > count - threshold {
                Some(Status::Failure)
            } else {
                None
            };
            if let Some(status) = decided {
                self.halt_children_from(shape, id, 0, ctx);
                self.finished[slots].fill(0);
                return status;
            }
        }
        Status::Running
    }

    /// `REPEAT n` (`go_on` = SUCCESS: the child must succeed n times) and `RETRY n`
    /// (`go_on` = FAILURE: up to n attempts). Loops within the tick while the child
    /// finishes with `go_on`; the count survives a RUNNING child.
    fn tick_loop(
        &mut self,
        shape: &Shape,
        id: NodeId,
        limit: u32,
        go_on: Status,
        ctx: &mut impl TickContext,
    ) -> Status {
        let child = shape.child(id, 0);
        loop {
            let status = self.tick_node(shape, child, ctx);
            if status == Status::Running {
                return Status::Running;
            }
            if status != go_on {
                self.state[id as usize].memory = 0;
                return status;
            }
            let done = self.state[id as usize].memory + 1;
            if done >= limit {
                self.state[id as usize].memory = 0;
                return go_on;
            }
            self.state[id as usize].memory = done;
        }
    }

    /// The learning selector (SPEC 1.3). On every tick it observes the RL state s, first
    /// completes the previous tick's learning step with s as the next state, then orders
    /// its children by Q(s, .) from high to low (ties broken by the RNG) or, with
    /// probability epsilon, uniformly at random, and ticks them in that order like a
    /// selector. A child returning FAILURE is a learning step with s' = s, taken before the
    /// next child is tried. The child returning SUCCESS or RUNNING becomes the pending step;
    /// a child that was RUNNING on the previous tick and is not that child is halted.
    ///
    /// The order is drawn lazily: only as many children as are tried are ranked, which
    /// gives the same distribution as sorting the whole list (uniform among ties). The
    /// children tried so far are a local mask, so nested selectors keep theirs apart.
    fn tick_learning(
        &mut self,
        shape: &Shape,
        id: NodeId,
        lor: usize,
        ctx: &mut impl TickContext,
    ) -> Status {
        let state = ctx.rl_state();
        let params = self.params;
        if let Some((s, a)) = self.lors[lor].pending.take() {
            if params.learn {
                self.lors[lor].table.bootstrap(s, a as usize, state, &params);
            }
        }
        let count = shape.nodes[id as usize].count;
        let explore = params.epsilon > 0.0 && self.rng.random::<f64>() < params.epsilon;
        let mut tried = 0u64;
        for remaining in (1..=count).rev() {
            let pick = if explore {
                random_untried(tried, remaining, &mut self.rng)
            } else {
                match self.lors[lor].table.stored_row(state) {
                    Some(row) => best_untried(tried, row.iter().copied(), &mut self.rng),
                    // A row never written reads as zeros: every untried child ties.
                    None => best_untried(tried, (0..count).map(|_| 0.0), &mut self.rng),
                }
            };
            tried |= 1 << pick;
            ctx.trace(TraceEvent::Chose { node: id, child: pick });
            let status = self.tick_node(shape, shape.child(id, pick), ctx);
            if status == Status::Failure {
                if params.learn {
                    self.lors[lor].table.bootstrap(state, pick as usize, state, &params);
                }
                continue;
            }
            self.halt_previous_running(shape, id, lor, pick, ctx);
            let entry = &mut self.lors[lor];
            entry.running_child = (status == Status::Running).then_some(pick);
            entry.pending = Some((state, pick));
            return status;
        }
        self.halt_previous_running(shape, id, lor, u32::MAX, ctx);
        self.lors[lor].running_child = None;
        Status::Failure
    }

    fn halt_previous_running(
        &mut self,
        shape: &Shape,
        id: NodeId,
        lor: usize,
        now: u32,
        ctx: &mut impl TickContext,
    ) {
        if let Some(previous) = self.lors[lor].running_child {
            if previous != now {
                self.halt_node(shape, shape.child(id, previous), ctx);
                self.lors[lor].running_child = None;
            }
        }
    }

    /// Halts children `from..` of `id` that are still RUNNING.
    fn halt_children_from(
        &mut self,
        shape: &Shape,
        id: NodeId,
        from: u32,
        ctx: &mut impl TickContext,
    ) {
        let NodeShape { first, count, .. } = shape.nodes[id as usize];
        for &child in &shape.children[(first + from.min(count)) as usize..(first + count) as usize]
        {
            self.halt_node(shape, child, ctx);
        }
    }

    /// Halts `id` if it is RUNNING: its running descendants first, then its own state.
    fn halt_node(&mut self, shape: &Shape, id: NodeId, ctx: &mut impl TickContext) {
        if !self.state[id as usize].running {
            return;
        }
        let node = shape.nodes[id as usize];
        match node.op {
            Op::Action { leaf } => {
                let mut progress = self.state[id as usize].memory;
                ctx.halt_action(leaf, &mut progress);
                self.state[id as usize].memory = progress;
            }
            Op::Condition { .. } => {}
            Op::Parallel { .. } => {
                let slots = node.first as usize..(node.first + node.count) as usize;
                self.halt_children_from(shape, id, 0, ctx);
                self.finished[slots].fill(0);
            }
            Op::Learning { lor } => {
                self.halt_children_from(shape, id, 0, ctx);
                self.lors[lor as usize].running_child = None;
            }
            _ => self.halt_children_from(shape, id, 0, ctx),
        }
        let state = &mut self.state[id as usize];
        state.running = false;
        if !matches!(node.op, Op::Action { .. }) {
            state.memory = 0;
        }
        ctx.trace(TraceEvent::Halted { node: id });
    }
}

impl Shape {
    /// Pre-order flattening; children of a node get contiguous slots in `children`, and
    /// learning selectors are numbered in pre-order (`lors` counts them).
    fn flatten(&mut self, spec: &NodeSpec, lors: &mut u32) -> NodeId {
        let id = self.nodes.len() as NodeId;
        let op = match &spec.kind {
            NodeKind::Sequence { memory: false } => Op::Sequence,
            NodeKind::Sequence { memory: true } => Op::SequenceMemory,
            NodeKind::Fallback { memory: false } => Op::Fallback,
            NodeKind::Fallback { memory: true } => Op::FallbackMemory,
            NodeKind::Learning => {
                *lors += 1;
                Op::Learning { lor: *lors - 1 }
            }
            NodeKind::Parallel { success_threshold } => {
                Op::Parallel { success_threshold: *success_threshold as u32 }
            }
            NodeKind::Inverter => Op::Inverter,
            NodeKind::ForceSuccess => Op::ForceSuccess,
            NodeKind::ForceFailure => Op::ForceFailure,
            NodeKind::Repeat { times } => Op::Repeat { times: *times },
            NodeKind::Retry { attempts } => Op::Retry { attempts: *attempts },
            NodeKind::Action { leaf, .. } => Op::Action { leaf: *leaf },
            NodeKind::Condition { leaf, .. } => Op::Condition { leaf: *leaf },
        };
        self.nodes.push(NodeShape { op, first: 0, count: 0 });
        self.labels.push((spec.line, spec.kind.label()));
        let first = self.children.len();
        self.children.extend(std::iter::repeat_n(0, spec.children.len()));
        for (i, child) in spec.children.iter().enumerate() {
            let child_id = self.flatten(child, lors);
            self.children[first + i] = child_id;
        }
        let node = &mut self.nodes[id as usize];
        node.first = first as u32;
        node.count = spec.children.len() as u32;
        id
    }
}

/// The position of the highest of `values` (one per child) among the children not in
/// `tried`; ties are broken uniformly by `rng`, the k-th tie replacing the choice with
/// probability 1/k, so the draws depend only on the values.
#[inline]
fn best_untried(
    tried: u64,
    values: impl Iterator<Item = f64>,
    rng: &mut Xoshiro256PlusPlus,
) -> u32 {
    let mut best = u32::MAX;
    let mut best_q = f64::NEG_INFINITY;
    let mut ties = 0u32;
    for (a, q) in values.enumerate() {
        if tried >> a & 1 == 1 {
            continue;
        }
        if q > best_q || best == u32::MAX {
            best = a as u32;
            best_q = q;
            ties = 1;
        } else if q == best_q {
            ties += 1;
            if rng.random_range(0..ties) == 0 {
                best = a as u32;
            }
        }
    }
    best
}

/// A uniformly chosen child not in `tried`, `remaining` children being untried.
fn random_untried(tried: u64, remaining: u32, rng: &mut Xoshiro256PlusPlus) -> u32 {
    let mut k = rng.random_range(0..remaining);
    let mut untried = !tried;
    loop {
        let a = untried.trailing_zeros();
        if k == 0 {
            return a;
        }
        k -= 1;
        untried &= untried - 1;
    }
}

/// Refuses a tree whose tick may count more than `limit`: a run's [`MAX_COMMANDS`] (what an
/// action message holds) and [`MAX_LEAF_TICKS`], or a replay's [`MAX_REPLAY_LEAVES`].
fn check_per_tick(spec: &TreeSpec, counted: PerTick, limit: usize) -> Result<(), TreeError> {
    let (tree_worst, culprit) = worst_case(&spec.root, counted, limit as u64);
    match culprit {
        Some((node, worst)) => Err(TreeError::TooMuchInOneTick {
            file: spec.source.clone(),
            line: node.line,
            node: node.kind.label(),
            counted,
            worst,
            tree_worst,
            limit,
        }),
        None => Ok(()),
    }
}

/// What a [`TreeError::TooMuchInOneTick`] adds when the node it names is not the root: the
/// worst case of the whole tree, which is what the limit applies to.
fn whole_tree(worst: u64, tree_worst: u64) -> String {
    if tree_worst == worst {
        String::new()
    } else {
        format!(" (the whole tree up to {tree_worst})")
    }
}

/// Refuses a tree with a learning selector wider than a tick's mask of tried children.
fn check_width(spec: &TreeSpec) -> Result<(), TreeError> {
    match widest_learning_selector(&spec.root) {
        Some(wide) => Err(TreeError::WideLearningSelector {
            file: spec.source.clone(),
            line: wide.line,
            children: wide.children.len(),
            limit: MAX_LEARNING_CHILDREN,
        }),
        None => Ok(()),
    }
}

/// The first learning selector (in pre-order) with more children than a tick's mask holds.
fn widest_learning_selector(spec: &NodeSpec) -> Option<&NodeSpec> {
    if spec.kind == NodeKind::Learning && spec.children.len() > MAX_LEARNING_CHILDREN {
        return Some(spec);
    }
    spec.children.iter().find_map(widest_learning_selector)
}

/// Upper bound of what one tick can count (commands or leaves): a leaf is ticked at most
/// once per pass, a composite ticks each child at most once, and loops multiply their
/// child's bound. Also the node to blame if the bound is past `limit`, with its own bound:
/// the deepest node past it (followed down the first child past it), since the root's line
/// says nothing when a `REPEAT` deep inside is the cause; `None` if the tree is within the
/// limit.
fn worst_case(spec: &NodeSpec, counted: PerTick, limit: u64) -> (u64, Option<(&NodeSpec, u64)>) {
    let mut children: u64 = 0;
    let mut culprit = None;
    for child in &spec.children {
        let (worst, deeper) = worst_case(child, counted, limit);
        children = children.saturating_add(worst);
        culprit = culprit.or(deeper);
    }
    let worst = match &spec.kind {
        NodeKind::Action { .. } => 1,
        NodeKind::Condition { .. } => u64::from(counted == PerTick::Leaves),
        NodeKind::Repeat { times } => children.saturating_mul(u64::from(*times)),
        NodeKind::Retry { attempts } => children.saturating_mul(u64::from(*attempts)),
        _ => children,
    };
    if culprit.is_none() && worst > limit {
        culprit = Some((spec, worst));
    }
    (worst, culprit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bt::parse::parse_tree;
    use crate::uav::UavCatalog;
    use rand::SeedableRng;

    /// The line and message of the command-limit error for tree `text`.
    fn refusal(text: &str) -> (usize, String) {
        let spec = parse_tree("t.bt", text, &UavCatalog).expect("a valid tree");
        match Tree::check(&spec) {
            Err(error @ TreeError::TooMuchInOneTick { line, .. }) => (line, error.to_string()),
            other => panic!("expected the command limit, got {other:?}"),
        }
    }

    #[test]
    fn a_repeat_past_the_limit_is_named_not_the_root() {
        let (line, message) = refusal("OR 2\n- REPEAT 1 n=100\n-- A-rotate 0\n- A-elevate 0\n");
        assert_eq!(line, 2);
        assert_eq!(message, "t.bt:2: this REPEAT n=100 may issue up to 100 commands in one tick (the whole tree up to 101); the limit is 16");
    }

    #[test]
    fn the_deepest_node_past_the_limit_is_named() {
        // Both RETRY (line 2) and REPEAT (line 3) are past the limit; the REPEAT is the cause.
        let (line, _) = refusal("AND 1\n- RETRY 1 n=2\n-- REPEAT 1 n=17\n--- A-rotate 0\n");
        assert_eq!(line, 3);
    }

    #[test]
    fn children_past_the_limit_only_together_name_their_parent() {
        let text = format!("OR 2\n- C-seeTarget 0\n- AND 17\n{}", "-- A-rotate 0\n".repeat(17));
        let (line, message) = refusal(&text);
        assert_eq!(line, 3);
        assert_eq!(
            message,
            "t.bt:3: this AND may issue up to 17 commands in one tick; the limit is 16"
        );
    }

    #[test]
    fn a_tree_at_the_limit_passes() {
        let spec =
            parse_tree("t.bt", "REPEAT 1 n=16\n- A-rotate 0\n", &UavCatalog).expect("a tree");
        assert_eq!(Tree::check(&spec), Ok(()));
    }

    /// Conditions issue no command, so loops over them alone are bounded by the leaves a
    /// tick may tick. Before, this tree passed and a tick out of the target's view ticked
    /// `C-seeTarget` a million times (a billion with one more level).
    #[test]
    fn loops_over_conditions_alone_are_bounded_by_the_leaves_a_tick_may_tick() {
        let (line, message) = refusal("RETRY 1 n=1000\n- RETRY 1 n=1000\n-- C-seeTarget 0\n");
        assert_eq!(line, 1);
        assert_eq!(
            message,
            "t.bt:1: this RETRY n=1000 may tick up to 1000000 leaves in one tick; the limit is 1024"
        );
        let within = parse_tree("t.bt", "RETRY 1 n=1000\n- C-seeTarget 0\n", &UavCatalog);
        assert_eq!(Tree::check(&within.expect("a tree")), Ok(()));
    }

    /// A replay lists every leaf it ticks, so its limit counts conditions as well as
    /// actions: here a million commands, within the limit, but two million leaves.
    #[test]
    fn a_replay_counts_conditions_and_actions_against_its_leaf_limit() {
        let text =
            "REPEAT 1 n=1000\n- REPEAT 1 n=1000\n-- AND 2\n--- C-seeTarget 0\n--- A-rotate 0\n";
        let spec = parse_tree("t.bt", text, &UavCatalog).expect("a tree");
        let rng = Xoshiro256PlusPlus::seed_from_u64(1);
        let error = Tree::for_replay(&spec, LearnParams::greedy(), rng).unwrap_err();
        assert_eq!(
            error.to_string(),
            "t.bt:1: this REPEAT n=1000 may tick up to 2000000 leaves in one tick; the limit is \
             1000000"
        );
    }
}
