//! A loaded scenario: a map, its visibility lookup table, and its verified facts.
//!
//! The thesis gives each UAV a lookup table from state (waypoint, height, heading) to the
//! cells it sees. Here the table holds, per state, the bit mask of candidate targets seen,
//! so the simulation's "does this UAV see the target" is one load and one AND. The table
//! is built once, when the map is loaded; the map's `expect` facts are then checked against
//! it, so a map that does not mean what its author thinks is refused before any run.

use std::path::Path;

use flockstep_proto::{Heading, Height, Pose, MAX_AGENTS};

use crate::error::WorldError;
use crate::map::{fact_poses, parse_map, pose_key, target_label, Expect, MapFile};
use crate::visibility;

/// The thesis's maps (s1-s3) and s4 (s3 with a free third route for attaching agents),
/// embedded so that a run needs no files: (name, file name, text).
const BUILTIN: [(&str, &str, &str); 4] = [
    ("s1", "s1_one_uav_one_target.map", include_str!("../maps/s1_one_uav_one_target.map")),
    ("s2", "s2_one_uav_two_targets.map", include_str!("../maps/s2_one_uav_two_targets.map")),
    ("s3", "s3_two_uavs_two_targets.map", include_str!("../maps/s3_two_uavs_two_targets.map")),
    ("s4", "s4_three_uavs_two_targets.map", include_str!("../maps/s4_three_uavs_two_targets.map")),
];

/// The file name and text of built-in scenario `name`.
fn builtin_map(name: &str) -> Option<(&'static str, &'static str)> {
    BUILTIN.iter().find(|b| b.0 == name).map(|&(_, file, text)| (file, text))
}

/// Index of `pose` within its UAV's slice of the table: 2 heights x 4 headings a waypoint.
#[inline]
pub(crate) fn state_index(pose: Pose) -> usize {
    // Masking keeps a malformed height or heading inside its waypoint's 8 entries.
    (pose.waypoint as usize * 2 + (pose.height & 1) as usize) * 4 + (pose.heading & 3) as usize
}

/// The pose at index `index` of a UAV's slice of the table; inverse of [`state_index`].
pub(crate) fn state_pose(index: usize) -> Pose {
    Pose::new(index / 8, Height::ALL[(index / 4) % 2], Heading::ALL[index % 4])
}

/// A map ready to simulate.
#[derive(Debug, Clone)]
pub struct Scenario {
    map: MapFile,
    source_text: String,
    /// The map in canonical text form, rendered once when first asked for.
    map_text: std::sync::OnceLock<String>,
    /// Visible-target masks of every route's states, routes one after the other.
    table: Vec<u64>,
    /// `table[offsets[u]..offsets[u + 1]]` is UAV `u`'s slice.
    offsets: Vec<usize>,
}

impl Scenario {
    /// Reads (at most [`crate::map::MAX_INPUT_BYTES`]), parses, builds and verifies the map
    /// at `path`.
    pub fn load(path: &Path) -> Result<Scenario, WorldError> {
        let text = crate::map::read_input(path)
            .map_err(|cause| WorldError::Io { path: path.to_path_buf(), cause })?;
        Scenario::from_text(&path.display().to_string(), &text)
    }

    /// Parses, builds and verifies a map; `source` names it in errors.
    pub fn from_text(source: &str, text: &str) -> Result<Scenario, WorldError> {
        let map = parse_map(source, text)?;
        Scenario::build(source, map, text.to_string())
    }

    /// A built-in scenario: the thesis's `s1`, `s2`, `s3`, or `s4` (s3 with a free third route).
    pub fn builtin(name: &str) -> Option<Scenario> {
        let (file, text) = builtin_map(name)?;
        // The embedded maps are verified by the tests, so this never discards an error.
        Scenario::from_text(file, text).ok()
    }

    /// A built-in scenario (`s1` to `s4`), a generated scenario `gen:key=value,...` (see
    /// [`crate::generate`]), or else the path of a `.map` file (write `./gen:...` for a
    /// file whose name starts with `gen:`).
    pub fn resolve(spec: &str) -> Result<Scenario, WorldError> {
        if let Some((file, text)) = builtin_map(spec) {
            return Scenario::from_text(file, text);
        }
        if crate::generate::GenSpec::is_gen(spec) {
            return crate::generate::generate(spec);
        }
        Scenario::load(Path::new(spec)).map_err(|e| match e {
            WorldError::Io { cause, .. } if cause.kind() == std::io::ErrorKind::NotFound => {
                WorldError::UnknownScenario { spec: spec.to_string() }
            }
            e => e,
        })
    }

    fn build(source: &str, map: MapFile, source_text: String) -> Result<Scenario, WorldError> {
        let mut table = Vec::new();
        let mut offsets = vec![0];
        for route in &map.routes {
            for &cell in route {
                for height in Height::ALL {
                    for heading in Heading::ALL {
                        table.push(target_mask(&map, cell, height, heading));
                    }
                }
            }
            offsets.push(table.len());
        }
        let map_text = std::sync::OnceLock::new();
        let scenario = Scenario { map, source_text, map_text, table, offsets };
        // The map's own claims first: a failed fact says most precisely what is wrong.
        for fact in &scenario.map.expects {
            scenario.check_fact(source, fact)?;
        }
        scenario.check_every_target_seen(source)?;
        Ok(scenario)
    }

    /// Refuses a target no pose of any route sees: an episode drawing it could not end.
    fn check_every_target_seen(&self, source: &str) -> Result<(), WorldError> {
        let seen = self.table.iter().fold(0, |acc, mask| acc | mask);
        let Some(k) = (0..self.n_targets()).find(|&k| seen & (1 << k) == 0) else {
            return Ok(());
        };
        let (line, col) = self.map.target_at.get(k).copied().unwrap_or((1, 1));
        let (row, col_in_grid) = self.map.targets[k];
        let file = source.to_string();
        Err(WorldError::Unseeable { file, line, col, label: target_label(k), row, col_in_grid })
    }

    /// Refuses a fact whose listed poses are not exactly those that see the target.
    fn check_fact(&self, source: &str, fact: &Expect) -> Result<(), WorldError> {
        let actual = self.poses_seeing(fact.uav, fact.target);
        if actual == fact.poses {
            return Ok(());
        }
        // The truth is written as the thesis states it: `wp6 high E, wp7 low N`.
        let actual: Vec<String> = actual.iter().map(Pose::to_string).collect();
        Err(WorldError::Fact {
            file: source.to_string(),
            line: fact.line,
            uav: fact.uav,
            target: fact.target,
            expected: fact_poses(&fact.poses),
            actual: if actual.is_empty() { "no pose".to_string() } else { actual.join(", ") },
        })
    }

    /// Every pose of `uav` that sees target `target`, sorted as the facts are.
    pub fn poses_seeing(&self, uav: usize, target: usize) -> Vec<Pose> {
        let mut poses = Vec::new();
        for wp in 0..self.route_len(uav) {
            for height in Height::ALL {
                for heading in Heading::ALL {
                    let pose = Pose::new(wp, height, heading);
                    if self.visible_targets(uav, pose) & (1 << target) != 0 {
                        poses.push(pose);
                    }
                }
            }
        }
        poses.sort_by_key(pose_key);
        poses
    }

    /// The `name:` of the map.
    pub fn name(&self) -> &str {
        &self.map.name
    }

    /// Number of routes, i.e. of UAVs the map can hold.
    pub fn n_routes(&self) -> usize {
        self.map.routes.len()
    }

    /// Agent slots of a run on this map: one per route, at most `MAX_AGENTS`. Every
    /// observation carries this many.
    pub fn agent_slots(&self) -> usize {
        self.n_routes().min(MAX_AGENTS)
    }

    /// Number of waypoints of UAV `uav`'s route (0 for an unknown UAV).
    pub fn route_len(&self, uav: usize) -> usize {
        self.map.routes.get(uav).map_or(0, Vec::len)
    }

    /// Number of candidate target cells.
    pub fn n_targets(&self) -> usize {
        self.map.targets.len()
    }

    /// `T1` for target 0.
    pub fn target_label(&self, target: usize) -> String {
        target_label(target)
    }

    /// Every UAV's pose at the start of an episode, on its own route (0-based waypoint).
    pub fn start_pose(&self) -> Pose {
        self.map.start
    }

    /// The (row, col) of waypoint `wp` (0-based) of UAV `uav`.
    ///
    /// # Panics
    /// If the UAV or the waypoint does not exist.
    pub fn route_waypoint(&self, uav: usize, wp: usize) -> (usize, usize) {
        self.map.routes[uav][wp]
    }

    /// Bit k is set when UAV `uav` at `pose` sees target k: one table load.
    ///
    /// `pose` must be valid for the UAV's route ([`Pose::validate`]), as every pose the
    /// world holds is.
    ///
    /// # Panics
    /// If `uav` does not exist or the pose's waypoint is beyond its route.
    #[inline]
    pub fn visible_targets(&self, uav: usize, pose: Pose) -> u64 {
        debug_assert!(pose.validate(self.route_len(uav)).is_ok(), "invalid pose {pose:?}");
        self.table[self.offsets[uav]..self.offsets[uav + 1]][state_index(pose)]
    }

    /// Every cell UAV `uav` sees at `pose`, in row-major order (for debugging and tools).
    ///
    /// # Panics
    /// If the UAV or the pose's waypoint does not exist.
    pub fn visible_cells(&self, uav: usize, pose: Pose) -> Vec<(usize, usize)> {
        let cell = self.route_waypoint(uav, pose.waypoint as usize);
        visibility::visible_cells(&self.map, cell, pose.height(), pose.heading())
    }

    /// The parsed map.
    pub fn map(&self) -> &MapFile {
        &self.map
    }

    /// The map in canonical text form ([`MapFile::to_text`]): what a snapshot records of the
    /// map it was learned on, and compares when loaded. Rendered once, on first use.
    pub fn map_text(&self) -> &str {
        self.map_text.get_or_init(|| self.map.to_text())
    }

    /// The text the map was read from, to be copied into a run's results.
    pub fn source_text(&self) -> &str {
        &self.source_text
    }
}

/// Bit k set when a camera at `cell` sees target k.
fn target_mask(map: &MapFile, cell: (usize, usize), height: Height, heading: Heading) -> u64 {
    map.targets.iter().enumerate().fold(0, |mask, (k, &target)| {
        if visibility::is_visible(map, cell, height, heading, target) {
            mask | (1 << k)
        } else {
            mask
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mistaken path to an endless device is refused after the size bound, naming the
    /// file and the limit, rather than read until memory runs out.
    #[test]
    fn an_endless_map_file_is_refused_at_the_size_bound() {
        let e = Scenario::resolve("/dev/zero").unwrap_err().to_string();
        assert_eq!(e, "cannot read /dev/zero: larger than 16 MiB, the limit for an input file");
    }
}
