//! The UAV's leaves (SPEC 1.4) and the catalog that names them.
//!
//! Actions change the agent's own copy of its pose at once and queue the matching command
//! for the world, which applies the same change with the same function
//! (`flockstep_proto::Pose::apply`). `C-seeTarget` reads the camera frame of the tick: the
//! world observes once per tick, at the tick's start pose.

use crate::bt::spec::{LeafCatalog, LeafId, LeafKind};
use crate::bt::status::Status;
use flockstep_proto::{Command, Pose, TrialAction};

pub const ROTATE: LeafId = 0;
pub const ELEVATE: LeafId = 1;
pub const DE_ELEVATE: LeafId = 2;
pub const WAYPOINT_TRANSLATION: LeafId = 3;
pub const END_EPISODE: LeafId = 4;
pub const SEE_TARGET: LeafId = 0;

const ACTIONS: [&str; 5] = ["rotate", "elevate", "deElevate", "waypointTranslation", "endEpisode"];
const CONDITIONS: [&str; 1] = ["seeTarget"];

/// The leaves a UAV tree may name.
#[derive(Debug, Clone, Copy, Default)]
pub struct UavCatalog;

impl LeafCatalog for UavCatalog {
    fn resolve(&self, kind: LeafKind, name: &str) -> Option<LeafId> {
        let names: &[&str] = match kind {
            LeafKind::Action => &ACTIONS,
            LeafKind::Condition => &CONDITIONS,
        };
        names.iter().position(|n| *n == name).map(|i| i as LeafId)
    }

    fn names(&self, kind: LeafKind) -> Vec<String> {
        match kind {
            LeafKind::Action => ACTIONS.iter().map(|s| s.to_string()).collect(),
            LeafKind::Condition => CONDITIONS.iter().map(|s| s.to_string()).collect(),
        }
    }
}

/// Reads (at most [`flockstep_world::map::MAX_INPUT_BYTES`]), parses and checks against the
/// engine's limits ([`crate::bt::tree::Tree::check`]) a UAV tree file, or the built-in Fig. 5
/// tree when `path` is None: a process refuses a bad tree before it joins or starts a run.
pub fn load_uav_tree(path: Option<&std::path::Path>) -> anyhow::Result<crate::bt::spec::TreeSpec> {
    use anyhow::Context;
    let (source, text) = match path {
        None => ("fig5.bt".to_string(), crate::FIG5_TREE.to_string()),
        Some(path) => (
            path.display().to_string(),
            flockstep_world::map::read_input(path)
                .with_context(|| format!("cannot read tree file {}", path.display()))?,
        ),
    };
    let spec = crate::bt::parse::parse_tree(&source, &text, &UavCatalog)?;
    crate::bt::tree::Tree::check(&spec)?;
    Ok(spec)
}

/// The UAV's body during one tick: its pose, what its camera sees, and the commands and
/// episode end the tree has issued so far.
pub struct Body<'a> {
    pub pose: Pose,
    pub route_len: usize,
    pub sees_target: bool,
    pub ended: bool,
    pub action: &'a mut TrialAction,
}

impl Body<'_> {
    /// Ticks action `leaf` and returns its status; the command it issues is in `pose` and
    /// `action`.
    #[inline]
    pub fn tick_action(&mut self, leaf: LeafId, progress: &mut u32) -> Status {
        match leaf {
            ROTATE => {
                self.command(Command::Rotate);
                // RUNNING until the UAV faces the heading it started from: R, R, R, S.
                *progress += 1;
                if *progress == 4 {
                    *progress = 0;
                    Status::Success
                } else {
                    Status::Running
                }
            }
            ELEVATE => {
                self.command(Command::Elevate);
                Status::Success
            }
            DE_ELEVATE => {
                self.command(Command::DeElevate);
                Status::Success
            }
            WAYPOINT_TRANSLATION => {
                self.command(Command::NextWaypoint);
                Status::Success
            }
            END_EPISODE => {
                self.ended = true;
                self.action.ended = 1;
                Status::Success
            }
            _ => unreachable!("leaf ids come from UavCatalog"),
        }
    }

    /// A halted rotation keeps the heading it reached and starts afresh next time.
    #[inline]
    pub fn halt_action(&mut self, progress: &mut u32) {
        *progress = 0;
    }

    #[inline]
    pub fn check_condition(&self, leaf: LeafId) -> bool {
        debug_assert_eq!(leaf, SEE_TARGET);
        self.sees_target
    }

    #[inline]
    fn command(&mut self, command: Command) {
        self.pose = self.pose.apply(command, self.route_len);
        let pushed = self.action.push(command);
        debug_assert!(pushed, "Tree::new bounds the commands of one tick by MAX_COMMANDS");
    }
}
