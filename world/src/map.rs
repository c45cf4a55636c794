//! A scenario map as written in a `.map` file (`maps/FORMAT.md`): the grid, the candidate
//! target cells, the UAV routes, the start pose and the facts the map claims.
//!
//! This is only the file's content, checked for consistency; what a pose sees is computed
//! by [`crate::visibility`] and the facts are verified by [`crate::scenario`]. Keeping the
//! text form separate lets a generator build a `MapFile`, write it with [`MapFile::to_text`]
//! and load it back like any hand-written map.

mod parse;

use std::fmt;
use std::io::Read;
use std::path::Path;

use flockstep_proto::Pose;

pub use parse::parse_map;

/// One grid cell. A candidate target cell is `Free` (targets are listed in
/// [`MapFile::targets`]), since a target must be visible and an `X` never is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cell {
    Free,
    /// An opaque building: never visible, blocks low lines of sight.
    Occlusion,
}

/// A fact of the map: among all poses of UAV `uav`, exactly `poses` see target `target`.
#[derive(Debug, Clone)]
pub struct Expect {
    /// 0-based route index (`UAV1` is 0).
    pub uav: usize,
    /// 0-based target index (`T1` is 0).
    pub target: usize,
    /// Sorted by (waypoint, height, heading); empty for `none`.
    pub poses: Vec<Pose>,
    /// 1-based line of the `expect` line, to point at a fact that fails.
    pub line: usize,
}

/// The content of a `.map` file.
///
/// Equality compares the world and its facts, not where they were written: line and
/// column numbers are ignored, so `parse_map(to_text(m)) == m`.
#[derive(Debug, Clone)]
pub struct MapFile {
    /// Free text from the `name:` line.
    pub name: String,
    pub rows: usize,
    pub cols: usize,
    /// Row-major, `rows * cols` cells; row 0 is the north edge.
    pub cells: Vec<Cell>,
    /// `targets[k]` is the (row, col) of the label `T<k+1>`.
    pub targets: Vec<(usize, usize)>,
    /// `target_at[k]` is the (line, column) where `T<k+1>` is written.
    pub target_at: Vec<(usize, usize)>,
    /// `routes[u]` is UAV`u+1`'s waypoint cells in visiting order (cyclic).
    pub routes: Vec<Vec<(usize, usize)>>,
    /// Every UAV's pose at the start of an episode (0-based waypoint).
    pub start: Pose,
    pub expects: Vec<Expect>,
}

impl PartialEq for Expect {
    fn eq(&self, other: &Self) -> bool {
        self.uav == other.uav && self.target == other.target && self.poses == other.poses
    }
}

impl PartialEq for MapFile {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
            && self.rows == other.rows
            && self.cols == other.cols
            && self.cells == other.cells
            && self.targets == other.targets
            && self.routes == other.routes
            && self.start == other.start
            && self.expects == other.expects
    }
}

/// The largest text file a user gives that flockstep reads whole: maps, trees, replay
/// scripts, the `summary.json` of `eval`. 16 MiB is far past any real one
/// (a generated 64-UAV map is under 100 KiB), and a mistaken `--scenario /dev/zero` is then
/// an error naming the file, not a read that runs until memory does.
pub const MAX_INPUT_BYTES: u64 = 16 << 20;

/// Reads the text file `path` given by a user, at most [`MAX_INPUT_BYTES`] of it: a larger
/// file (or an endless device) is an error, as is a file that is not UTF-8. Every such read
/// goes through here, so the bound and its message are the same for every kind of file.
pub fn read_input(path: &Path) -> std::io::Result<String> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.take(MAX_INPUT_BYTES + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > MAX_INPUT_BYTES {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {} MiB, the limit for an input file", MAX_INPUT_BYTES >> 20),
        ));
    }
    String::from_utf8(bytes).map_err(|_| {
        std::io::Error::new(std::io::ErrorKind::InvalidData, "not a text file (not UTF-8)")
    })
}

/// `UAV1` for route index 0.
pub fn uav_name(uav: usize) -> String {
    format!("UAV{}", uav + 1)
}

/// `T1` for target index 0.
pub fn target_label(target: usize) -> String {
    format!("T{}", target + 1)
}

/// A fact's poses as an `expect` line writes them: `6 high E, 3 high N`, or `none`.
pub(crate) fn fact_poses(poses: &[Pose]) -> String {
    if poses.is_empty() {
        return "none".to_string();
    }
    let text: Vec<String> = poses
        .iter()
        .map(|p| format!("{} {} {}", p.waypoint + 1, p.height().name(), p.heading().name()))
        .collect();
    text.join(", ")
}

/// The order in which a fact's poses are kept and written.
pub(crate) fn pose_key(pose: &Pose) -> (u16, u8, u8) {
    (pose.waypoint, pose.height, pose.heading)
}

impl MapFile {
    /// The cell at (row, col), or `None` off the grid.
    pub fn cell(&self, row: usize, col: usize) -> Option<Cell> {
        if row < self.rows && col < self.cols {
            self.cells.get(row.checked_mul(self.cols)?.checked_add(col)?).copied()
        } else {
            None
        }
    }

    /// Whether (row, col) is an `X`; cells off the grid are not.
    pub fn is_occluded(&self, row: usize, col: usize) -> bool {
        self.cell(row, col) == Some(Cell::Occlusion)
    }

    /// The map in the `.map` format; parsing it gives back an equal `MapFile`.
    /// The name must be one line without `#`, as any name read by [`parse_map`] is.
    pub fn to_text(&self) -> String {
        self.to_string()
    }

    /// The grid token of (row, col): `.`, `X` or `T<k>`.
    fn token(&self, row: usize, col: usize) -> String {
        if let Some(k) = self.targets.iter().position(|&t| t == (row, col)) {
            target_label(k)
        } else if self.is_occluded(row, col) {
            "X".to_string()
        } else {
            ".".to_string()
        }
    }
}

impl fmt::Display for MapFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "name: {}", self.name)?;
        writeln!(f, "size: {} {}", self.rows, self.cols)?;
        let start = self.start;
        writeln!(f, "start: {start}")?;
        writeln!(f, "grid:")?;
        // Pad the tokens to one width so the columns line up, as in the hand-written maps.
        let width = (0..self.targets.len()).map(|k| target_label(k).len()).max().unwrap_or(1);
        for row in 0..self.rows {
            let tokens: Vec<String> =
                (0..self.cols).map(|col| format!("{:<width$}", self.token(row, col))).collect();
            writeln!(f, "{}", tokens.join(" ").trim_end())?;
        }
        for (uav, route) in self.routes.iter().enumerate() {
            write!(f, "route {}:", uav_name(uav))?;
            for (row, col) in route {
                write!(f, " {row},{col}")?;
            }
            writeln!(f)?;
        }
        for fact in &self.expects {
            let (uav, target) = (uav_name(fact.uav), target_label(fact.target));
            writeln!(f, "expect {uav} {target}: {}", fact_poses(&fact.poses))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn input_files_are_read_up_to_the_bound_and_must_be_text() {
        let path = std::env::temp_dir().join(format!("flockstep-input-{}.txt", std::process::id()));
        std::fs::write(&path, vec![b'x'; MAX_INPUT_BYTES as usize]).unwrap();
        let whole = read_input(&path).map(|text| text.len() as u64);
        std::fs::write(&path, [b'x', 0xff]).unwrap();
        let binary = read_input(&path).map_err(|e| e.to_string());
        std::fs::remove_file(&path).unwrap();
        assert_eq!(whole.unwrap(), MAX_INPUT_BYTES, "a file of the limit's size is read");
        assert_eq!(binary.unwrap_err(), "not a text file (not UTF-8)");
        let endless = read_input(Path::new("/dev/zero")).unwrap_err().to_string();
        assert_eq!(endless, "larger than 16 MiB, the limit for an input file");
    }
}
