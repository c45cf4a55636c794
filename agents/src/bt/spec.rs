//! The shape of a behavior tree: what the text format describes, before it runs.
//!
//! A plain tree of [`NodeSpec`]s. Leaves are resolved against a [`LeafCatalog`] when the file
//! is parsed, so a tree naming an unknown leaf is refused at load time, never at tick time.
//! The run-time state lives elsewhere (`bt::tree`).

use std::fmt;

/// Index of a leaf behaviour in its catalog.
pub type LeafId = u16;

/// Whether a leaf is an action (`A-name`, may be RUNNING, may issue commands) or a condition
/// (`C-name`, SUCCESS or FAILURE only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LeafKind {
    Action,
    Condition,
}

/// Resolves leaf names (without the `A-`/`C-` prefix) to ids.
pub trait LeafCatalog {
    /// The id of leaf `name` of `kind`, or `None` if this catalog has no such leaf.
    fn resolve(&self, kind: LeafKind, name: &str) -> Option<LeafId>;
    /// The names this catalog offers for `kind`, for error messages.
    fn names(&self, kind: LeafKind) -> Vec<String>;
}

/// The kind of one node, with its parameters.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NodeKind {
    /// `AND` (reactive, `memory: false`) or `AND*` (with memory).
    Sequence { memory: bool },
    /// `OR` (reactive, `memory: false`) or `OR*` (with memory).
    Fallback { memory: bool },
    /// `LOR`: the learning selector.
    Learning,
    /// `PAR n m=M`: SUCCESS once M children succeeded, FAILURE once n-M+1 failed.
    Parallel { success_threshold: usize },
    /// `NOT 1`
    Inverter,
    /// `FORCE_SUCCESS 1`
    ForceSuccess,
    /// `FORCE_FAILURE 1`
    ForceFailure,
    /// `REPEAT 1 n=N`: the child must succeed N times in a row.
    Repeat { times: u32 },
    /// `RETRY 1 n=N`: up to N attempts while the child fails.
    Retry { attempts: u32 },
    /// `A-name 0`
    Action { leaf: LeafId, name: String },
    /// `C-name 0`
    Condition { leaf: LeafId, name: String },
}

/// One node and its children, with the line it was declared on (1-based).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeSpec {
    pub kind: NodeKind,
    pub children: Vec<NodeSpec>,
    pub line: usize,
}

/// A parsed tree and the name of the file (or other source) it came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TreeSpec {
    pub source: String,
    pub root: NodeSpec,
}

impl LeafKind {
    /// The prefix of this kind's leaves in the text format: `A-` or `C-`.
    pub fn prefix(self) -> &'static str {
        match self {
            LeafKind::Action => "A-",
            LeafKind::Condition => "C-",
        }
    }

    /// The word for this kind in messages: `action` or `condition`.
    pub fn noun(self) -> &'static str {
        match self {
            LeafKind::Action => "action",
            LeafKind::Condition => "condition",
        }
    }
}

/// How many children a kind of node takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arity {
    /// Leaves: none.
    Leaf,
    /// Decorators: exactly one.
    One,
    /// Composites: one or more.
    Many,
}

impl NodeKind {
    /// How many children this kind takes.
    pub fn arity(&self) -> Arity {
        match self {
            NodeKind::Action { .. } | NodeKind::Condition { .. } => Arity::Leaf,
            NodeKind::Inverter
            | NodeKind::ForceSuccess
            | NodeKind::ForceFailure
            | NodeKind::Repeat { .. }
            | NodeKind::Retry { .. } => Arity::One,
            NodeKind::Sequence { .. }
            | NodeKind::Fallback { .. }
            | NodeKind::Learning
            | NodeKind::Parallel { .. } => Arity::Many,
        }
    }

    /// The `key=value` parameter the text format writes for this kind, if it has one
    /// (`m` of `PAR`, `n` of `REPEAT` and `RETRY`).
    pub fn param(&self) -> Option<(&'static str, u64)> {
        match *self {
            NodeKind::Parallel { success_threshold } => Some(("m", success_threshold as u64)),
            NodeKind::Repeat { times } => Some(("n", times.into())),
            NodeKind::Retry { attempts } => Some(("n", attempts.into())),
            _ => None,
        }
    }

    /// ` key=value` for a kind with a parameter, else nothing: what follows the child count
    /// in the text format, and the kind in a label.
    pub fn param_suffix(&self) -> String {
        self.param().map(|(key, value)| format!(" {key}={value}")).unwrap_or_default()
    }

    /// The kind with its parameter, as drawings and traces name a node (`PAR m=2`).
    pub fn label(&self) -> String {
        format!("{self}{}", self.param_suffix())
    }
}

/// The kind as its token in the text format (`OR*`, `PAR`, `A-rotate`), without the child
/// count or parameters.
impl fmt::Display for NodeKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let token = match self {
            NodeKind::Sequence { memory: false } => "AND",
            NodeKind::Sequence { memory: true } => "AND*",
            NodeKind::Fallback { memory: false } => "OR",
            NodeKind::Fallback { memory: true } => "OR*",
            NodeKind::Learning => "LOR",
            NodeKind::Parallel { .. } => "PAR",
            NodeKind::Inverter => "NOT",
            NodeKind::ForceSuccess => "FORCE_SUCCESS",
            NodeKind::ForceFailure => "FORCE_FAILURE",
            NodeKind::Repeat { .. } => "REPEAT",
            NodeKind::Retry { .. } => "RETRY",
            NodeKind::Action { name, .. } => {
                return write!(f, "{}{name}", LeafKind::Action.prefix())
            }
            NodeKind::Condition { name, .. } => {
                return write!(f, "{}{name}", LeafKind::Condition.prefix())
            }
        };
        f.write_str(token)
    }
}
