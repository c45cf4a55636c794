//! The best expected episode length one UAV can reach: the yardstick for learning curves.
//!
//! [`optimum`] is the exact best of a memoryless deterministic policy over the state
//! (waypoint, height, heading), the policy class a LOR learns without communication: at
//! every tick the UAV first looks (the episode ends at that tick if it sees the target),
//! otherwise it rotates, elevates, de-elevates or moves to the next waypoint. The target is
//! drawn uniformly among the candidates, so the expected length is the mean, over targets,
//! of the tick at which the trajectory first sees it, plus one.
//!
//! [`optimum_with_known_target`] is the mean shortest episode when the UAV knows the target
//! in advance: no policy, with or without communication, can do better.
//!
//! [`route_optima`] computes both for every route of a scenario, what `supervisor optimum`
//! prints: a route without an optimum says why beside the other routes' numbers.

mod search;

use std::fmt;

use flockstep_proto::{Command, Pose};

use crate::error::OptimumError;
use crate::map::target_label;
use crate::scenario::{state_index, state_pose, Scenario};
use search::{Failure, Graph};

/// Nodes each search phase may expand before giving up (the thesis maps need hundreds).
const SEARCH_BUDGET: usize = 2_000_000;

const MOVES: [Command; 4] =
    [Command::Rotate, Command::Elevate, Command::DeElevate, Command::NextWaypoint];

/// One tick of the optimal trajectory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Step {
    pub pose: Pose,
    /// Bit k set when the pose sees target k.
    pub sees: u64,
    /// The move to the next step; `None` on the last step, where the last target is seen.
    pub then: Option<Command>,
}

/// The best memoryless policy's trajectory and its expected episode length.
#[derive(Debug, Clone, PartialEq)]
pub struct Optimum {
    /// Mean of `lengths`: the expected episode length in ticks.
    pub expected_ticks: f64,
    /// `lengths[k]`: episode length (ticks, the seeing tick included) when the target is k.
    pub lengths: Vec<u64>,
    /// The trajectory from the start pose to the tick where the last target is first seen.
    pub path: Vec<Step>,
}

/// The best episode lengths of a UAV told the target in advance.
#[derive(Debug, Clone, PartialEq)]
pub struct KnownTarget {
    /// Mean of `lengths`: a lower bound of any policy's expected episode length.
    pub expected_ticks: f64,
    /// `lengths[k]`: shortest episode (ticks) when the target is k.
    pub lengths: Vec<u64>,
}

/// Both optima of one route flown alone, each computed on its own: a route may lack the
/// memoryless optimum (no trajectory sees every target without repeating a state) and still
/// have the known-target bound, and a scenario's routes without either do not hide the
/// others' numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct RouteOptima {
    /// The route's slot: 0 is UAV1.
    pub uav: usize,
    pub memoryless: Result<Optimum, OptimumError>,
    pub known_target: Result<KnownTarget, OptimumError>,
}

/// The optima of every route of `scenario`, flown alone, in route order.
pub fn route_optima(scenario: &Scenario) -> Vec<RouteOptima> {
    (0..scenario.n_routes())
        .map(|uav| RouteOptima {
            uav,
            memoryless: optimum(scenario, uav),
            known_target: optimum_with_known_target(scenario, uav),
        })
        .collect()
}

/// The exact best expected episode length of UAV `uav` alone under a memoryless policy.
pub fn optimum(scenario: &Scenario, uav: usize) -> Result<Optimum, OptimumError> {
    let graph = graph(scenario, uav)?;
    let (cost, states) = search::solve(&graph, SEARCH_BUDGET).map_err(|failure| match failure {
        Failure::NoSimplePath => OptimumError::NoSimplePath { uav },
        Failure::TooLarge(expanded) => OptimumError::TooLarge { uav, expanded },
    })?;
    let lengths: Vec<u64> = (0..scenario.n_targets())
        .map(|k| {
            let first = states.iter().position(|&s| graph.sees[s] & (1 << k) != 0);
            // The search only ends once every target has been seen.
            first.map_or(u64::MAX, |tick| tick as u64 + 1)
        })
        .collect();
    // The search's cost counts, tick by tick, the targets not yet seen: the same sum.
    debug_assert_eq!(lengths.iter().sum::<u64>(), cost);
    let path = states
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            let pose = state_pose(s);
            let then = states.get(i + 1).and_then(|&t| {
                MOVES.into_iter().find(|&m| pose.apply(m, scenario.route_len(uav)) == state_pose(t))
            });
            Step { pose, sees: graph.sees[s], then }
        })
        .collect();
    Ok(Optimum { expected_ticks: mean(&lengths), lengths, path })
}

/// The mean, over targets, of the shortest episode of UAV `uav` if it knew the target.
pub fn optimum_with_known_target(
    scenario: &Scenario,
    uav: usize,
) -> Result<KnownTarget, OptimumError> {
    let graph = graph(scenario, uav)?;
    let mut dist = vec![u64::MAX; graph.succ.len()];
    let mut queue = std::collections::VecDeque::from([graph.start]);
    dist[graph.start] = 0;
    while let Some(s) = queue.pop_front() {
        for &t in &graph.succ[s] {
            if dist[t] == u64::MAX {
                dist[t] = dist[s] + 1;
                queue.push_back(t);
            }
        }
    }
    let mut lengths = Vec::with_capacity(scenario.n_targets());
    for k in 0..scenario.n_targets() {
        let seeing = (0..dist.len()).filter(|&s| graph.sees[s] & (1 << k) != 0);
        match seeing.map(|s| dist[s]).min().filter(|&d| d != u64::MAX) {
            Some(d) => lengths.push(d + 1),
            None => return Err(OptimumError::Unseeable { uav, label: target_label(k) }),
        }
    }
    Ok(KnownTarget { expected_ticks: mean(&lengths), lengths })
}

fn mean(lengths: &[u64]) -> f64 {
    lengths.iter().sum::<u64>() as f64 / lengths.len().max(1) as f64
}

/// UAV `uav`'s state graph; refuses a target it never sees, whose optimum is infinite.
fn graph(scenario: &Scenario, uav: usize) -> Result<Graph, OptimumError> {
    let len = scenario.route_len(uav);
    if len == 0 {
        return Err(OptimumError::NoSuchUav { uav, n: scenario.n_routes() });
    }
    let n = len * 8;
    let sees: Vec<u64> = (0..n).map(|s| scenario.visible_targets(uav, state_pose(s))).collect();
    let union = sees.iter().fold(0, |acc, m| acc | m);
    if let Some(k) = (0..scenario.n_targets()).find(|&k| union & (1 << k) == 0) {
        return Err(OptimumError::Unseeable { uav, label: target_label(k) });
    }
    let succ = (0..n)
        .map(|s| {
            let pose = state_pose(s);
            // A move that changes nothing (elevate when high, ...) would loop: left out.
            MOVES
                .iter()
                .map(|&m| pose.apply(m, len))
                .filter(|&p| p != pose)
                .map(state_index)
                .collect()
        })
        .collect();
    let start = state_index(scenario.start_pose());
    // A scenario has at most MAX_TARGETS = 64 targets.
    let n_targets = scenario.n_targets() as u32;
    Ok(Graph { start, succ, sees, n_targets })
}

fn move_name(command: Command) -> &'static str {
    match command {
        Command::Rotate => "rotate",
        Command::Elevate => "elevate",
        Command::DeElevate => "deElevate",
        Command::NextWaypoint => "waypointTranslation",
    }
}

impl fmt::Display for RouteOptima {
    /// One line naming the route, `UAV1: memoryless optimum 11.5000 ticks (per target [8,
    /// 15]); knowing the target 10.5000`, then the optimal trajectory. A missing optimum is
    /// its error, which names the route itself: `UAV2 sees T1 from no pose of its route: ...`
    /// (once when both optima fail for the same reason, as a target the route never sees).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.memoryless {
            Ok(best) => write!(
                f,
                "UAV{}: memoryless optimum {:.4} ticks (per target {:?})",
                self.uav + 1,
                best.expected_ticks,
                best.lengths
            )?,
            Err(error) => write!(f, "{error}")?,
        }
        match &self.known_target {
            Ok(known) => writeln!(f, "; knowing the target {:.4}", known.expected_ticks)?,
            Err(error) if self.memoryless.as_ref().err() == Some(error) => writeln!(f)?,
            Err(error) => writeln!(f, "; {error}")?,
        }
        match &self.memoryless {
            Ok(best) => write!(f, "{best}"),
            Err(_) => Ok(()),
        }
    }
}

impl fmt::Display for Optimum {
    /// The value, then one line per tick: `tick 7: wp6 high E sees T1 -> waypointTranslation`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lengths: Vec<String> = self
            .lengths
            .iter()
            .enumerate()
            .map(|(k, l)| format!("{}: {l}", target_label(k)))
            .collect();
        writeln!(
            f,
            "expected episode length {} ticks ({})",
            self.expected_ticks,
            lengths.join(", ")
        )?;
        for (tick, step) in self.path.iter().enumerate() {
            write!(f, "tick {tick}: {}", step.pose)?;
            let seen: Vec<String> =
                (0..64).filter(|&k| step.sees & (1u64 << k) != 0).map(target_label).collect();
            if !seen.is_empty() {
                write!(f, " sees {}", seen.join(" "))?;
            }
            if let Some(command) = step.then {
                write!(f, " -> {}", move_name(command))?;
            }
            writeln!(f)?;
        }
        Ok(())
    }
}
