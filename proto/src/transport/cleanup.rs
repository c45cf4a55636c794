//! Clean-up of a run's files: dead nodes' resources, and the node-id counter segment iceoryx2
//! keeps per prefix, which nothing in iceoryx2 removes. Also lists what a run left behind, so
//! tests and the supervisor can check that a shutdown was clean.

use super::root::effective_uid;
use super::{run_prefix, setup, Ipc, TransportError, PREFIX_HEAD};
use crate::services;
use iceoryx2::prelude::*;
use std::collections::BTreeSet;
use std::os::unix::fs::MetadataExt;
use std::path::{Path as StdPath, PathBuf};
use std::time::Duration;

/// Where POSIX shared memory appears as files (Linux).
const SHM_DIR: &str = "/dev/shm";

/// What [`cleanup_run`] did for one run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunCleanup {
    /// Dead nodes whose resources were removed.
    pub dead_nodes: usize,
    /// Nodes alive, or that could not be inspected or removed; while there are any, the run
    /// keeps its node-id counter segment.
    pub live_nodes: usize,
    /// Files of the run removed besides the nodes' own (the node-id counter segment).
    pub files: usize,
}

/// Removes what a run left behind: the resources of its dead nodes and, once no node of the
/// run is left, the per-prefix node-id counter segment (`*.global_mgmt`) that iceoryx2 keeps
/// in `/dev/shm` for the life of the machine (only this user's: see [`names_owned_by`]).
pub fn cleanup_run(run_id: &str) -> Result<RunCleanup, TransportError> {
    let config = super::iceoryx_config(run_id)?;
    let mut report = RunCleanup::default();
    Node::<Ipc>::list(&config, |state| {
        match state {
            NodeState::Dead(dead) => {
                // Waits briefly if another process is cleaning the same node. A node that
                // cannot be removed (permissions) still holds the run's files.
                if dead.blocking_remove_stale_resources(Duration::from_millis(100)).is_ok() {
                    report.dead_nodes += 1;
                } else {
                    report.live_nodes += 1;
                }
            }
            _ => report.live_nodes += 1,
        }
        CallbackProgression::Continue
    })
    .map_err(|e| setup(run_id, "listing the run's nodes", e))?;
    if report.live_nodes == 0 {
        let suffix = std::str::from_utf8(config.global.node.global_mgmt_suffix.as_bytes())
            .unwrap_or(".global_mgmt");
        let prefix = run_prefix(run_id);
        for name in names_owned_by(StdPath::new(SHM_DIR), effective_uid())? {
            if name.starts_with(&prefix) && name.ends_with(suffix) {
                shm_unlink(&name)?;
                report.files += 1;
            }
        }
    }
    Ok(report)
}

fn shm_unlink(name: &str) -> Result<(), TransportError> {
    let io = |cause| TransportError::Io { what: format!("removing shared memory `{name}`"), cause };
    let c_name =
        std::ffi::CString::new(format!("/{name}")).map_err(|e| io(std::io::Error::other(e)))?;
    // SAFETY: a valid NUL-terminated name.
    if unsafe { libc::shm_unlink(c_name.as_ptr()) } != 0 {
        let e = std::io::Error::last_os_error();
        // Someone else removed it first: the goal is reached.
        if e.kind() != std::io::ErrorKind::NotFound {
            return Err(io(e));
        }
    }
    Ok(())
}

/// What [`sweep_stale_runs`] did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SweepReport {
    pub runs_cleaned: Vec<String>,
    pub live_runs: Vec<String>,
    pub dead_nodes: usize,
    /// Runs whose files could not be removed (e.g. another user's), with the error's
    /// message: the sweep went on without them, and its caller says so.
    pub failed: Vec<(String, String)>,
}

/// Start-up clean-up across runs: every flockstep run found in `/dev/shm` or under this
/// user's iceoryx2 root gets [`cleanup_run`]. Live runs keep everything but their dead nodes.
///
/// A run that cannot be cleaned is listed in [`SweepReport::failed`] and skipped: one old
/// run's files that this user may not remove must not stop every later run, whose files
/// carry their own prefix (a run id still in use is refused when the run creates its
/// services). Only an error listing the directories, or a root that cannot be trusted,
/// fails the sweep.
pub fn sweep_stale_runs() -> Result<SweepReport, TransportError> {
    let mut runs = BTreeSet::new();
    for dir in candidate_dirs()? {
        for name in names_owned_by(&dir, effective_uid())? {
            if let Some(run_id) =
                name.strip_prefix(PREFIX_HEAD).and_then(|rest| rest.split('.').next())
            {
                if services::validate_run_id(run_id).is_ok() {
                    runs.insert(run_id.to_string());
                }
            }
        }
    }
    let mut report = SweepReport::default();
    for run_id in runs {
        match cleanup_run(&run_id) {
            Ok(cleaned) => {
                report.dead_nodes += cleaned.dead_nodes;
                if cleaned.live_nodes == 0 {
                    report.runs_cleaned.push(run_id);
                } else {
                    report.live_runs.push(run_id);
                }
            }
            Err(e) => report.failed.push((run_id, e.to_string())),
        }
    }
    Ok(report)
}

/// Every file of a run still present in `/dev/shm` or under this user's iceoryx2 root. Empty
/// once the last process of a run has exited cleanly.
pub fn leftover_files(run_id: &str) -> Result<Vec<PathBuf>, TransportError> {
    services::validate_run_id(run_id).map_err(TransportError::InvalidRunId)?;
    let prefix = run_prefix(run_id);
    let mut found = Vec::new();
    let mut dirs = candidate_dirs()?;
    while let Some(dir) = dirs.pop() {
        let entries = match std::fs::read_dir(&dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(cause) => {
                return Err(TransportError::Io {
                    what: format!("listing {}", dir.display()),
                    cause,
                })
            }
        };
        for entry in entries.flatten() {
            let path = entry.path();
            // Node directories are named by node id; their files carry the prefix.
            if path.is_dir() && dir.ends_with("nodes") {
                dirs.push(path);
            } else if entry.file_name().to_string_lossy().starts_with(&prefix) {
                found.push(path);
            }
        }
    }
    found.sort();
    Ok(found)
}

/// `/dev/shm` and this user's iceoryx2 root with its node and service directories, taken
/// from the configuration every run's node uses, so they are the directories its files are in.
fn candidate_dirs() -> Result<Vec<PathBuf>, TransportError> {
    let global = super::default_config()?.global;
    let path = |p: &iceoryx2::prelude::Path| {
        PathBuf::from(String::from_utf8_lossy(p.as_bytes()).into_owned())
    };
    Ok(vec![
        PathBuf::from(SHM_DIR),
        path(global.root_path()),
        path(&global.node_dir()),
        path(&global.service_dir()),
    ])
}

/// Names of the entries of `dir` that belong to `uid` (this user, but for tests). `/dev/shm`
/// is shared by every user, but a run's nodes are listed only under its own user's root: from
/// here another user's live run looks dead, and as root the clean-up could remove its files.
fn names_owned_by(dir: &StdPath, uid: u32) -> Result<Vec<String>, TransportError> {
    match std::fs::read_dir(dir) {
        Ok(entries) => Ok(entries
            .flatten()
            .filter(|e| e.metadata().is_ok_and(|m| m.uid() == uid))
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Vec::new()),
        Err(cause) => Err(TransportError::Io { what: format!("listing {}", dir.display()), cause }),
    }
}

/// Runs when a process's last port of the run is gone: if it was the run's last node, the
/// run's node-id counter segment goes too, so a clean shutdown leaves nothing in /dev/shm.
/// Two processes leaving at the same instant may each still see the other; the next
/// [`sweep_stale_runs`] removes what they left.
pub(super) struct LastOut {
    run_id: String,
}

impl LastOut {
    pub(super) fn new(run_id: &str) -> LastOut {
        LastOut { run_id: run_id.into() }
    }
}

impl Drop for LastOut {
    fn drop(&mut self) {
        // Nothing useful can be done with an error while dropping; the sweep retries.
        let _ = cleanup_run(&self.run_id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_given_users_files_are_taken_for_clean_up() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("flockstep.r.x.global_mgmt"), b"").unwrap();
        let mine = names_owned_by(tmp.path(), effective_uid()).unwrap();
        assert_eq!(mine, ["flockstep.r.x.global_mgmt"]);
        let others = names_owned_by(tmp.path(), effective_uid().wrapping_add(1)).unwrap();
        assert!(others.is_empty(), "{others:?}");
    }
}
