//! Exact search for the trajectory with the least expected episode length.
//!
//! A memoryless deterministic policy that has not seen the target yet follows one fixed
//! trajectory of states, which must not repeat a state before every target is seen (it
//! would loop forever). Its cost is the sum, over ticks, of the number of targets not yet
//! seen before that tick; divided by the number of targets, that is the expected episode
//! length. Costs are integers, so the optimum is exact.
//!
//! First a Dijkstra search over (state, targets seen) finds the best trajectory when
//! states may repeat. Its cost is a lower bound; when its trajectory happens to repeat no
//! state, it is the answer. Otherwise a depth-first branch and bound over simple paths
//! finds the answer, stopping early if it meets the lower bound.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

/// The state graph of one UAV: successors and the targets each state sees.
pub(super) struct Graph {
    pub start: usize,
    /// Distinct states one move away (moves that change nothing are left out).
    pub succ: Vec<Vec<usize>>,
    /// Bit k set when the state sees target k.
    pub sees: Vec<u64>,
    pub n_targets: u32,
}

/// Why no trajectory was found.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Failure {
    /// Every trajectory that sees all targets repeats a state.
    NoSimplePath,
    /// The search expanded more nodes than its budget.
    TooLarge(usize),
}

impl Graph {
    fn full(&self) -> u64 {
        u64::MAX.checked_shr(64 - self.n_targets).unwrap_or(0)
    }

    /// Cost of the tick after a state from which `seen` targets have been seen.
    fn step_cost(&self, seen: u64) -> u64 {
        u64::from(self.n_targets - seen.count_ones())
    }

    /// For each target, the number of moves from each state to the nearest state that
    /// sees it (`u32::MAX` if none): a backward breadth-first search per target.
    fn distances(&self) -> Vec<Vec<u32>> {
        let mut pred = vec![Vec::new(); self.succ.len()];
        for (s, next) in self.succ.iter().enumerate() {
            for &t in next {
                pred[t].push(s);
            }
        }
        (0..self.n_targets)
            .map(|k| {
                let mut dist = vec![u32::MAX; self.succ.len()];
                let mut queue = std::collections::VecDeque::new();
                for (s, &mask) in self.sees.iter().enumerate() {
                    if mask & (1 << k) != 0 {
                        dist[s] = 0;
                        queue.push_back(s);
                    }
                }
                while let Some(s) = queue.pop_front() {
                    for &p in &pred[s] {
                        if dist[p] == u32::MAX {
                            dist[p] = dist[s] + 1;
                            queue.push_back(p);
                        }
                    }
                }
                dist
            })
            .collect()
    }
}

/// The optimal trajectory (states from the start to the one where the last target is first
/// seen) and its cost, searching at most `budget` nodes in each phase.
pub(super) fn solve(graph: &Graph, budget: usize) -> Result<(u64, Vec<usize>), Failure> {
    let (bound, path) = relaxed(graph, budget)?;
    let mut seen = vec![false; graph.succ.len()];
    if path.iter().all(|&s| !std::mem::replace(&mut seen[s], true)) {
        return Ok((bound, path));
    }
    simple(graph, bound, budget)
}

/// Dijkstra over (state, targets seen): the best trajectory if states could repeat.
fn relaxed(graph: &Graph, budget: usize) -> Result<(u64, Vec<usize>), Failure> {
    type Node = (usize, u64);
    let full = graph.full();
    let start: Node = (graph.start, graph.sees[graph.start]);
    // Node -> (cost, parent); the heap holds (cost, node), smallest first.
    let mut best: HashMap<Node, (u64, Option<Node>)> = HashMap::new();
    let mut heap = BinaryHeap::new();
    best.insert(start, (u64::from(graph.n_targets), None));
    heap.push(Reverse((u64::from(graph.n_targets), start)));
    let mut expanded = 0;
    while let Some(Reverse((cost, node))) = heap.pop() {
        if best.get(&node).is_some_and(|&(c, _)| c < cost) {
            continue;
        }
        let (state, seen) = node;
        if seen == full {
            let mut path = vec![state];
            let mut at = node;
            while let Some(&(_, Some(parent))) = best.get(&at) {
                path.push(parent.0);
                at = parent;
            }
            path.reverse();
            return Ok((cost, path));
        }
        expanded += 1;
        if expanded > budget {
            return Err(Failure::TooLarge(expanded));
        }
        let next_cost = cost + graph.step_cost(seen);
        for &t in &graph.succ[state] {
            let next = (t, seen | graph.sees[t]);
            if best.get(&next).is_none_or(|&(c, _)| next_cost < c) {
                best.insert(next, (next_cost, Some(node)));
                heap.push(Reverse((next_cost, next)));
            }
        }
    }
    // Unreachable for a strongly connected graph whose states see every target; a caller's
    // graph that is neither has no trajectory at all.
    Err(Failure::NoSimplePath)
}

/// One node of the depth-first search: a state on the current path.
struct Frame {
    state: usize,
    seen: u64,
    cost: u64,
    /// Successors, most promising first.
    children: Vec<usize>,
    next: usize,
}

/// Branch and bound over trajectories that repeat no state; `bound` is a known lower
/// bound of the answer, so the search stops as soon as it finds a trajectory that cheap.
fn simple(graph: &Graph, bound: u64, budget: usize) -> Result<(u64, Vec<usize>), Failure> {
    let full = graph.full();
    let dist = graph.distances();
    // Each target not yet seen stays unseen at least as many more ticks as the moves to the
    // nearest state that sees it; None if some target cannot be reached any more.
    let remaining = |state: usize, seen: u64| -> Option<u64> {
        (0..graph.n_targets).filter(|&k| seen & (1 << k) == 0).try_fold(0, |sum, k| {
            let d = dist[k as usize][state];
            (d != u32::MAX).then(|| sum + u64::from(d))
        })
    };
    let frame = |state: usize, seen: u64, cost: u64| {
        let step = graph.step_cost(seen);
        let mut children: Vec<(u64, usize)> = graph.succ[state]
            .iter()
            .filter_map(|&t| Some((remaining(t, seen | graph.sees[t])?.saturating_add(step), t)))
            .collect();
        children.sort_unstable();
        Frame { state, seen, cost, children: children.into_iter().map(|c| c.1).collect(), next: 0 }
    };
    let mut best: Option<(u64, Vec<usize>)> = None;
    let mut on_path = vec![false; graph.succ.len()];
    let start_seen = graph.sees[graph.start];
    let mut stack = vec![frame(graph.start, start_seen, u64::from(graph.n_targets))];
    on_path[graph.start] = true;
    let mut expanded = 0;
    while let Some(top) = stack.last_mut() {
        let Some(&child) = top.children.get(top.next) else {
            on_path[top.state] = false;
            stack.pop();
            continue;
        };
        top.next += 1;
        if on_path[child] {
            continue;
        }
        let (seen, cost) = (top.seen | graph.sees[child], top.cost + graph.step_cost(top.seen));
        let best_cost = best.as_ref().map_or(u64::MAX, |b| b.0);
        if seen == full {
            if cost < best_cost {
                let path = stack.iter().map(|f| f.state).chain([child]).collect();
                best = Some((cost, path));
                if cost == bound {
                    break;
                }
            }
            continue;
        }
        match remaining(child, seen) {
            Some(rest) if cost + rest < best_cost => {}
            _ => continue,
        }
        expanded += 1;
        if expanded > budget {
            return Err(Failure::TooLarge(expanded));
        }
        on_path[child] = true;
        stack.push(frame(child, seen, cost));
    }
    best.ok_or(Failure::NoSimplePath)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A graph from an edge list; `sees[s]` are the targets state s sees.
    fn graph(n: usize, edges: &[(usize, usize)], sees: Vec<u64>, n_targets: u32) -> Graph {
        let mut succ = vec![Vec::new(); n];
        for &(a, b) in edges {
            succ[a].push(b);
        }
        Graph { start: 0, succ, sees, n_targets }
    }

    #[test]
    fn a_path_through_both_targets_is_found_by_dijkstra() {
        // 0 -> 1 (T1) -> 2 (T2): T1 at tick 1, T2 at tick 2, so (2 + 3) / 2.
        let g = graph(3, &[(0, 1), (1, 2), (2, 0)], vec![0, 1, 2], 2);
        assert_eq!(solve(&g, 1000), Ok((5, vec![0, 1, 2])));
    }

    #[test]
    fn a_repeated_state_sends_the_search_to_branch_and_bound() {
        // Start 0 is a hub; leaf 1 sees T1 and leads back to 0 or along 3 -> 4 to leaf 2,
        // which sees T2. Going back through 0 is cheaper (0 1 0 2: 2 + 4 = 6) but repeats
        // state 0, so the best policy goes round: 0 1 3 4 2 sees T2 at tick 4 (2 + 5 = 7).
        let edges = [(0, 1), (1, 0), (0, 2), (2, 0), (1, 3), (3, 4), (4, 2)];
        let g = graph(5, &edges, vec![0, 1, 2, 0, 0], 2);
        assert_eq!(relaxed(&g, 1000).map(|r| r.0), Ok(6));
        assert_eq!(solve(&g, 1000), Ok((7, vec![0, 1, 3, 4, 2])));
    }

    #[test]
    fn no_simple_path_is_reported() {
        // Both leaves hang off the hub: seeing both needs to pass the hub twice.
        let g = graph(3, &[(0, 1), (1, 0), (0, 2), (2, 0)], vec![0, 1, 2], 2);
        assert_eq!(solve(&g, 1000), Err(Failure::NoSimplePath));
    }

    #[test]
    fn the_budget_bounds_the_search() {
        let g = graph(3, &[(0, 1), (1, 2), (2, 0)], vec![0, 1, 2], 2);
        assert_eq!(solve(&g, 1), Err(Failure::TooLarge(2)));
    }

    #[test]
    fn a_target_seen_at_the_start_costs_one_tick() {
        let g = graph(2, &[(0, 1), (1, 0)], vec![1, 0], 1);
        assert_eq!(solve(&g, 1000), Ok((1, vec![0])));
    }
}
