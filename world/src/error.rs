//! The errors of the world crate.
//!
//! A map is written by hand or by a generator, so every refusal points at the place in the
//! file (`file:line:col`) and says what was expected there: the reader fixes the map without
//! opening the source code. The optimum solver has its own errors because an infinite or
//! intractable optimum is a property of a valid map, not a mistake in it.

use std::path::PathBuf;

/// A `.map` file that does not follow `maps/FORMAT.md`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{file}:{line}:{col}: {kind}")]
pub struct MapError {
    /// The file name given to the parser.
    pub file: String,
    /// 1-based line.
    pub line: usize,
    /// 1-based column (characters).
    pub col: usize,
    pub kind: MapErrorKind,
}

/// What is wrong at a [`MapError`]'s position.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MapErrorKind {
    #[error("missing `{item}` line: expected {expected}")]
    Missing { item: &'static str, expected: &'static str },
    #[error("duplicate `{item}` line (first given at line {first})")]
    Duplicate { item: &'static str, first: usize },
    #[error("expected {expected}, found {found}")]
    Syntax { expected: String, found: String },
    #[error(
        "unexpected `{found}`: expected `name:`, `size:`, `start:`, `grid:`, \
         `route UAV<k>:` or `expect UAV<k> T<k>:`"
    )]
    UnknownLine { found: String },
    #[error("the grid has {found} rows, expected {expected} (from `size:`)")]
    GridRows { expected: usize, found: usize },
    #[error("this grid row has {found} cells, expected {expected} (from `size:`)")]
    RaggedRow { expected: usize, found: usize },
    #[error(
        "unknown cell `{token}`: expected `.` (free), `X` (occlusion) or `T<k>` (target, k >= 1)"
    )]
    UnknownCell { token: String },
    #[error("duplicate target `{label}` (first at line {line}, column {col})")]
    DuplicateTarget { label: String, line: usize, col: usize },
    #[error("targets must be labelled T1..T{highest} without gaps, but `T{missing}` is missing")]
    TargetGap { missing: usize, highest: usize },
    #[error("no target cell: expected at least one `T1` in the grid")]
    NoTargets,
    #[error("no `route` line: expected at least one `route UAV1: row,col ...`")]
    NoRoutes,
    #[error("too many {what}: {found}, at most {max} allowed")]
    TooMany { what: &'static str, found: usize, max: usize },
    #[error(
        "expected route name `{expected}` (routes are named UAV1, UAV2, ... in order), \
         found `{found}`"
    )]
    RouteName { expected: String, found: String },
    #[error("route {uav} has no waypoints: expected at least one `row,col`")]
    NoWaypoints { uav: String },
    #[error(
        "waypoint {row},{col} is off the {rows}x{cols} grid: expected row < {rows} and col < {cols}"
    )]
    OffGrid { row: usize, col: usize, rows: usize, cols: usize },
    #[error("waypoint {row},{col} is on an `X` cell: expected a free cell")]
    OnOcclusion { row: usize, col: usize },
    #[error("{what} wp{wp} is beyond {uav}'s route of {len} waypoints")]
    BeyondRoute { what: &'static str, wp: usize, uav: String, len: usize },
    #[error("unknown UAV `{name}`: expected one of UAV1..UAV{n}")]
    UnknownUav { name: String, n: usize },
    #[error("unknown target `{label}`: expected one of T1..T{n}")]
    UnknownTarget { label: String, n: usize },
    #[error("duplicate fact for {uav} {target} (first at line {first})")]
    DuplicateExpect { uav: String, target: String, first: usize },
    #[error("pose {pose} is listed twice")]
    DuplicatePose { pose: String },
}

/// Why a scenario could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The I/O error is in the message, not also a `source`: reports that follow the chain
    /// would print it twice.
    #[error("cannot read {}: {cause}", .path.display())]
    Io { path: PathBuf, cause: std::io::Error },
    /// A `--scenario` that is neither a built-in name, nor a `gen:` spec, nor an existing file.
    #[error(
        "unknown scenario `{spec}`: expected s1, s2, s3, s4, a `gen:` spec or the path of a \
         .map file, and there is no file `{spec}`"
    )]
    UnknownScenario { spec: String },
    #[error(transparent)]
    Map(#[from] MapError),
    /// An `expect` line does not hold; `actual` lists the poses that do see the target.
    /// `uav` and `target` are 0-based indices.
    #[error(
        "{file}:{line}: fact `expect UAV{u} T{t}: {expected}` does not hold: \
         UAV{u} sees T{t} from {actual}",
        u = .uav + 1,
        t = .target + 1
    )]
    Fact { file: String, line: usize, uav: usize, target: usize, expected: String, actual: String },
    /// A `gen:` scenario spec that is malformed, out of range, or cannot be generated.
    #[error("scenario spec `{spec}`: {problem}")]
    Spec { spec: String, problem: String },
    /// A candidate target no pose of any route sees: an episode drawing it could never end.
    #[error(
        "{file}:{line}:{col}: target {label} at {row},{col_in_grid} is visible from no pose of \
         any route: an episode with this target could never end"
    )]
    Unseeable {
        file: String,
        line: usize,
        col: usize,
        label: String,
        row: usize,
        col_in_grid: usize,
    },
}

/// Why the optimum of a route could not be computed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OptimumError {
    #[error("no UAV{} in this scenario (it has {n})", .uav + 1)]
    NoSuchUav { uav: usize, n: usize },
    #[error(
        "UAV{} sees {label} from no pose of its route: the expected episode length is infinite",
        .uav + 1
    )]
    Unseeable { uav: usize, label: String },
    #[error(
        "UAV{} has no trajectory that sees every target without repeating a state: \
         no memoryless policy ends every episode",
        .uav + 1
    )]
    NoSimplePath { uav: usize },
    #[error("the search for UAV{}'s optimum gave up after {expanded} nodes", .uav + 1)]
    TooLarge { uav: usize, expanded: usize },
}
