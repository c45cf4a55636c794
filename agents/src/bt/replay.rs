//! `agent bt replay TREE SCRIPT`: ticks a tree against scripted leaf results and reports,
//! per tick, the root's status and the leaves ticked and halted. It is how people debug a
//! tree without a world.
//!
//! Script format, one line per tick (blank lines and `#` comments skipped):
//!
//! ```text
//! # tick 1: the target is not in view, rotating has begun
//! seeTarget=F rotate=R
//! # `*` gives every leaf not named on the line a result
//! seeTarget=S *=S
//! ```
//!
//! Results are `S`, `F`, `R` (SUCCESS, FAILURE, RUNNING; conditions take `S` or `F`). A leaf
//! name stands for every leaf of that name; the tree must have one (`A-name`, `C-name`: of
//! that kind), and a line gives each leaf, and `*`, at most once. A leaf ticked without a
//! result is an error that names the script line. Learning selectors order their children
//! greedily by all-zero Q-values, so ties are broken by the seeded RNG (`--seed`) and the
//! replay is repeatable.
//! The leaves command no UAV, so a run's limits per tick do not apply here; a replay refuses
//! a tree that may tick more than `MAX_REPLAY_LEAVES` leaves in one tick.
//!
//! Output, one line per tick (`name@line` is the node's line in the tree file):
//!
//! ```text
//! tick 1: RUNNING  ticked C-seeTarget@3=FAILURE A-rotate@8=RUNNING  halted -
//! ```

use super::spec::{LeafCatalog, LeafId, LeafKind, TreeSpec};
use super::status::Status;
use super::tree::{NodeId, TickContext, TraceEvent, Tree};
use crate::learning::{LearnParams, StateId};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::cell::RefCell;
use std::collections::HashMap;
use std::fmt::Write as _;

/// A catalog that accepts every leaf name, numbering names as it meets them.
#[derive(Debug, Default)]
pub struct OpenCatalog {
    names: RefCell<Vec<(LeafKind, String)>>,
}

impl OpenCatalog {
    fn name(&self, kind: LeafKind, leaf: LeafId) -> String {
        self.names
            .borrow()
            .iter()
            .filter(|(k, _)| *k == kind)
            .nth(leaf as usize)
            .map(|(_, n)| n.clone())
            .unwrap_or_default()
    }
}

impl LeafCatalog for OpenCatalog {
    fn resolve(&self, kind: LeafKind, name: &str) -> Option<LeafId> {
        let mut names = self.names.borrow_mut();
        let same_kind = || names.iter().filter(|(k, _)| *k == kind);
        if let Some(i) = same_kind().position(|(_, n)| n == name) {
            return Some(i as LeafId);
        }
        let id = same_kind().count() as LeafId;
        names.push((kind, name.to_string()));
        Some(id)
    }

    fn names(&self, kind: LeafKind) -> Vec<String> {
        self.names.borrow().iter().filter(|(k, _)| *k == kind).map(|(_, n)| n.clone()).collect()
    }
}

/// A malformed script, or a tick the script does not cover.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}: {message}")]
pub struct ScriptError {
    pub file: String,
    pub line: usize,
    pub message: String,
}

/// One tick of the script: results by leaf name, and the `*` default.
struct ScriptTick {
    line: usize,
    results: HashMap<String, Status>,
    default: Option<Status>,
}

/// Parses a script for a tree whose leaves `catalog` holds. A name the tree has no leaf of
/// (a typo would otherwise give its result to nothing), and a leaf or `*` given twice on a
/// line (the last would win unseen), are errors naming the line.
fn parse_script(
    file: &str,
    text: &str,
    catalog: &OpenCatalog,
) -> Result<Vec<ScriptTick>, ScriptError> {
    let mut ticks = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let content = raw.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let error = |message: String| ScriptError { file: file.to_string(), line, message };
        let mut tick = ScriptTick { line, results: HashMap::new(), default: None };
        for item in content.split_whitespace() {
            let (name, result) = item
                .split_once('=')
                .ok_or_else(|| error(format!("`{item}`: expected leaf=S, leaf=F or leaf=R")))?;
            let status = match result {
                "S" => Status::Success,
                "F" => Status::Failure,
                "R" => Status::Running,
                other => return Err(error(format!("`{name}={other}`: a result is S, F or R"))),
            };
            if name == "*" {
                if tick.default.replace(status).is_some() {
                    return Err(error(format!("`{item}`: `*` is given twice on this line")));
                }
                continue;
            }
            let leaf = leaf_name(name, catalog).map_err(|m| error(format!("`{item}`: {m}")))?;
            if tick.results.insert(leaf.to_string(), status).is_some() {
                return Err(error(format!("`{item}`: leaf {leaf} is given twice on this line")));
            }
        }
        ticks.push(tick);
    }
    Ok(ticks)
}

/// The leaf name `name` (`A-name`, `C-name` or `name`) stands for, checked to be one the
/// tree has (of that kind, if it says which); else why not, listing the tree's leaves.
fn leaf_name<'a>(name: &'a str, catalog: &OpenCatalog) -> Result<&'a str, String> {
    let (kinds, bare): (&[LeafKind], &str) =
        match (name.strip_prefix("A-"), name.strip_prefix("C-")) {
            (Some(bare), _) => (&[LeafKind::Action], bare),
            (_, Some(bare)) => (&[LeafKind::Condition], bare),
            _ => (&[LeafKind::Action, LeafKind::Condition], name),
        };
    if kinds.iter().any(|&kind| catalog.names(kind).iter().any(|n| n == bare)) {
        return Ok(bare);
    }
    let leaves: Vec<String> = [("A", LeafKind::Action), ("C", LeafKind::Condition)]
        .into_iter()
        .flat_map(|(prefix, kind)| {
            catalog.names(kind).into_iter().map(move |n| format!("{prefix}-{n}"))
        })
        .collect();
    Err(format!("the tree has no leaf {name} (its leaves: {})", leaves.join(" ")))
}

/// The replay's tick context: scripted results, and a log of what happened.
struct Scripted<'a> {
    catalog: &'a OpenCatalog,
    tick: &'a ScriptTick,
    file: &'a str,
    error: Option<ScriptError>,
    ticked: Vec<(NodeId, Status)>,
    halted: Vec<NodeId>,
    leaf_nodes: &'a [bool],
}

impl Scripted<'_> {
    fn result(&mut self, kind: LeafKind, leaf: LeafId) -> Status {
        let name = self.catalog.name(kind, leaf);
        let status = self.tick.results.get(&name).copied().or(self.tick.default);
        match (kind, status) {
            (LeafKind::Condition, Some(Status::Running)) => {
                self.fail(format!("C-{name} is a condition: it returns S or F, never R"));
                Status::Failure
            }
            (_, Some(status)) => status,
            (_, None) => {
                let prefix = if kind == LeafKind::Action { "A" } else { "C" };
                self.fail(format!("{prefix}-{name} was ticked but this line gives it no result (add {name}=S|F|R or *=...)"));
                Status::Failure
            }
        }
    }

    fn fail(&mut self, message: String) {
        if self.error.is_none() {
            self.error =
                Some(ScriptError { file: self.file.to_string(), line: self.tick.line, message });
        }
    }
}

impl TickContext for Scripted<'_> {
    fn tick_action(&mut self, leaf: LeafId, _progress: &mut u32) -> Status {
        self.result(LeafKind::Action, leaf)
    }

    fn halt_action(&mut self, _leaf: LeafId, _progress: &mut u32) {}

    fn check_condition(&mut self, leaf: LeafId) -> bool {
        self.result(LeafKind::Condition, leaf) == Status::Success
    }

    fn rl_state(&mut self) -> StateId {
        0
    }

    fn trace(&mut self, event: TraceEvent) {
        match event {
            TraceEvent::Ticked { node, status } if self.leaf_nodes[node as usize] => {
                self.ticked.push((node, status))
            }
            TraceEvent::Halted { node } if self.leaf_nodes[node as usize] => self.halted.push(node),
            _ => {}
        }
    }
}

/// Replays `script` against `tree` (parsed with `catalog`); returns the report.
pub fn replay(
    tree_spec: &TreeSpec,
    catalog: &OpenCatalog,
    script_file: &str,
    script: &str,
    seed: u64,
) -> Result<String, Box<dyn std::error::Error + Send + Sync>> {
    let ticks = parse_script(script_file, script, catalog)?;
    let rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut tree = Tree::for_replay(tree_spec, LearnParams::greedy(), rng)?;
    let leaf_nodes: Vec<bool> = (0..tree.node_count() as NodeId).map(|n| tree.is_leaf(n)).collect();
    let name = |tree: &Tree, node: NodeId| {
        let (line, label) = tree.label(node);
        format!("{label}@{line}")
    };
    let mut out = String::new();
    for (index, tick) in ticks.iter().enumerate() {
        let mut ctx = Scripted {
            catalog,
            tick,
            file: script_file,
            error: None,
            ticked: Vec::new(),
            halted: Vec::new(),
            leaf_nodes: &leaf_nodes,
        };
        let status = tree.tick(&mut ctx);
        if let Some(error) = ctx.error {
            return Err(error.into());
        }
        let ticked: Vec<String> =
            ctx.ticked.iter().map(|&(n, s)| format!("{}={s}", name(&tree, n))).collect();
        let halted: Vec<String> = ctx.halted.iter().map(|&n| name(&tree, n)).collect();
        let list =
            |items: &[String]| if items.is_empty() { "-".to_string() } else { items.join(" ") };
        writeln!(
            out,
            "tick {}: {status}  ticked {}  halted {}",
            index + 1,
            list(&ticked),
            list(&halted)
        )
        .expect("writing to a String");
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bt::parse::parse_tree;

    /// The replay of `script` against a tree with a condition `done` and actions `report`
    /// and `climb`.
    fn replayed(script: &str) -> Result<String, String> {
        let catalog = OpenCatalog::default();
        let tree = "OR 2\n- AND 2\n-- C-done 0\n-- A-report 0\n- A-climb 0\n";
        let tree = parse_tree("t.bt", tree, &catalog).unwrap();
        replay(&tree, &catalog, "s.script", script, 0).map_err(|e| e.to_string())
    }

    #[test]
    fn a_script_naming_a_leaf_the_tree_lacks_is_refused_naming_it() {
        let leaves = "(its leaves: A-report A-climb C-done)";
        for (item, missing) in
            [("C-nope=S", "C-nope"), ("nope=F", "nope"), ("C-climb=S", "C-climb")]
        {
            let e = replayed(&format!("done=F climb=R\n{item}\n")).unwrap_err();
            assert_eq!(e, format!("s.script:2: `{item}`: the tree has no leaf {missing} {leaves}"));
        }
        assert!(replayed("C-done=F A-climb=R\n").is_ok(), "prefixed names of its leaves");
    }

    #[test]
    fn a_leaf_or_default_given_twice_on_a_line_is_refused() {
        for (line, item, what) in [
            ("done=S done=F", "done=F", "leaf done"),
            ("C-done=S done=F *=S", "done=F", "leaf done"),
            ("*=S *=F", "*=F", "`*`"),
        ] {
            let e = replayed(&format!("{line}\n")).unwrap_err();
            assert_eq!(e, format!("s.script:1: `{item}`: {what} is given twice on this line"));
        }
    }
}
