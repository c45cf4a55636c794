//! Clean-up of a run's files: dead nodes' resources, and what iceoryx2 itself never removes
//! (the node-id counter segment it keeps per prefix, and the remnants of a process killed
//! while it created a file). Also lists what a run left behind, so tests and the
//! supervisor can check that a shutdown was clean.

use super::process::{process_exists, process_of_node};
use super::root::effective_uid;
use super::{run_prefix, setup, Ipc, TransportError, PREFIX_HEAD};
use crate::services;
use iceoryx2::node::NodeView;
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
    /// Files of the run removed besides the nodes' own: empty segments, service descriptions
    /// left in creation and, once no node was left, every segment, socket and description no
    /// process used (the node-id counter among them).
    pub files: usize,
    /// Empty node directories of processes that died as they created them, of any run of
    /// this user (see [`remove_abandoned_node_dirs`]).
    pub abandoned_node_dirs: usize,
}

/// Removes what a run left behind: the resources of its dead nodes, what iceoryx2 never
/// removes of a process killed as it created a file (see [`remove_empty_segments`],
/// [`remove_descriptions_left_in_creation`],
/// [`remove_nodes_that_died_starting`], [`remove_node_without_details`],
/// [`remove_abandoned_node_dirs`]) and, once no node of the run is left, every file of the
/// run no process uses ([`remove_unused_files`]), among them the per-prefix node-id counter
/// segment (`*.global_mgmt`) that iceoryx2 keeps in `/dev/shm` for the life of the machine
/// (only this user's: see [`names_owned_by`]).
pub fn cleanup_run(run_id: &str) -> Result<RunCleanup, TransportError> {
    let config = super::iceoryx_config(run_id)?;
    let mut report = RunCleanup {
        files: remove_empty_segments(run_id)?
            + remove_descriptions_left_in_creation(&config, run_id)?,
        dead_nodes: remove_nodes_that_died_starting(&config, &run_prefix(run_id))?,
        live_nodes: 0,
        abandoned_node_dirs: remove_abandoned_node_dirs(&config)?,
    };
    Node::<Ipc>::list(&config, |state| {
        match state {
            NodeState::Dead(dead) => {
                // Waits briefly if another process is cleaning the same node. A node that
                // cannot be removed (permissions), or that another process is removing,
                // still holds the run's files.
                let node_id = dead.id().value();
                let removed = (dead.details().is_some()
                    && dead.blocking_remove_stale_resources(Duration::from_millis(100)).is_ok())
                    || remove_node_without_details(&config, node_id).is_ok_and(|done| done);
                if removed {
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
        report.files += remove_unused_files(&config, run_id)?;
    }
    Ok(report)
}

/// Removes the run's empty segments in `/dev/shm` that no process has open: left by a
/// process killed between creating a segment and giving it its size. iceoryx2 must never
/// meet one while it removes a dead node's resources: opening it waits for a size that never
/// comes, without the timeout its other waits have (0.10 `posix_shared_memory::open_impl`,
/// `MappingSizeIsZero`), so the world, or the supervisor's start-up sweep, hung for good
/// (4 of about 1 000 agents killed 0 to 40 ms after they started). A segment still being
/// created is empty too, but its creator holds it open. Returns how many were removed.
pub(super) fn remove_empty_segments(run_id: &str) -> Result<usize, TransportError> {
    remove_unused(StdPath::new(SHM_DIR), run_id, |m| m.is_file() && m.len() == 0)
}

/// Removes the run's service descriptions (`*.service` in iceoryx2's service directory) that
/// a creator killed as it made them left writable, which no process has open. iceoryx2
/// creates a description writable (0600), holds it open from that exclusive create on for
/// as long as the service lives, writes it, and makes it read-only (0400) once complete; it
/// reads a writable one as a service still being created. So its clean-up of the dead
/// creator removes only the service's tag, and every later create of the service waits for
/// the creation to end and fails as if the service existed: a world started by hand after
/// one of its run id was killed as it created its services said "another live run uses
/// this run id" (3 of 10 worlds killed as their first service appeared). A description
/// being created is held open by its creator, so one that is writable and that no process
/// has open is no one's, with live nodes in the run or not. Returns how many were removed.
fn remove_descriptions_left_in_creation(
    config: &Config,
    run_id: &str,
) -> Result<usize, TransportError> {
    let service_dir = std_path(&config.global.service_dir());
    remove_unused(&service_dir, run_id, |m| m.is_file() && m.mode() & 0o200 != 0)
}

/// Removes the run's segments that no process has open or mapped, and its listener sockets
/// without a segment: called once no node of the run is left. Among them is the node-id
/// counter (`*.global_mgmt`), which iceoryx2 never removes, and what a process killed as it
/// created a port left before iceoryx2 recorded the port, named by nothing but the run's
/// prefix: a listener's segment (`*.event_mgmt`) and socket (`*.event` under the root), 1
/// of about 250 agents killed 0 to 40 ms after they started; a lone socket and a
/// publisher-subscriber `*.connection` segment, 1 each in about 400 more. And finished
/// service descriptions whose service is otherwise gone, which nothing lists once the dead
/// node that used them is: two clean-ups of the same dead node at once (a world's and a
/// starting supervisor's sweep) left 5 of a killed world's and 1 of a killed agent's run in
/// about a dozen runs of the fault tests side by side, and the 5 made the next world of that
/// run id fail as if a live run held it. A process that uses a service holds its
/// description open, so one no process has open is no one's.
///
/// A process holds every segment it creates open until it has mapped it, and keeps it mapped
/// while it uses it (iceoryx2 closes the descriptor once it is mapped), so one that no
/// process has open or mapped is no one's, even with a run of the same id starting
/// meanwhile. A listener creates its segment, then its socket, and removes the segment,
/// then the socket, when dropped: a socket without a segment is no one's either. Returns
/// how many files were removed.
fn remove_unused_files(config: &Config, run_id: &str) -> Result<usize, TransportError> {
    let prefix = run_prefix(run_id);
    let uid = effective_uid();
    let mut removed = remove_unused(StdPath::new(SHM_DIR), run_id, |_| true)?;
    removed += remove_unused(&std_path(&config.global.service_dir()), run_id, |_| true)?;
    let socket_suffix =
        String::from_utf8_lossy(config.global.service.event_connection_suffix.as_bytes());
    let socket_dir = std_path(config.global.root_path());
    for name in names_owned_by(&socket_dir, uid)? {
        let Some(stem) = name.strip_suffix(&*socket_suffix) else { continue };
        let segment = StdPath::new(SHM_DIR).join(format!("{stem}{socket_suffix}_mgmt"));
        if stem.starts_with(&prefix) && !segment.exists() {
            remove_file(&socket_dir.join(&name))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Removes what is left of a dead node whose details are gone, which iceoryx2 never does:
/// it removes a dead node's resources by the configuration kept in its details, and without
/// them looks under the default one. Such a node is one killed while it created a port or
/// service tag, whose clean-up then removed its details and failed: iceoryx2 does not list a
/// half-made tag (one still writable), so it is not removed and the node's directory
/// cannot be (5 of 60 agents killed 0 to 40 ms after they started left one). Or one whose
/// clean-up was killed after it emptied or removed the directory, before the monitor. Its
/// directory holds only half-made files then, or nothing, or is gone; one that holds any
/// other is not such a node. While another process removes the node it holds the monitor's
/// lock open, and the node is left to it. Returns whether it removed the node.
fn remove_node_without_details(config: &Config, node_id: u128) -> std::io::Result<bool> {
    let node_id = node_id.to_string();
    let node_dir = std_path(&config.global.node_dir());
    let modes: Vec<u32> = match std::fs::read_dir(node_dir.join(&node_id)) {
        Ok(entries) => {
            entries.flatten().filter_map(|e| e.metadata().ok()).map(|m| m.mode()).collect()
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(e),
    };
    // Made read-only once complete, as every iceoryx2 file in a node's directory.
    let complete = modes.iter().any(|mode| mode & 0o200 == 0);
    let monitor = monitor_files(config, &node_id).map_err(std::io::Error::other)?;
    if complete || monitor.iter().any(|name| in_use(&node_dir.join(name))) {
        return Ok(false);
    }
    remove_node_files(config, &node_id)?;
    Ok(true)
}

/// Removes the node directories that a process killed between creating one and writing its
/// node's details into it left empty, which nothing lists or names but the node id. A
/// node's id carries the id of the process that made it (iceoryx2 0.10 `UniqueSystemId`:
/// seconds, nanoseconds, process id and counter, 32 bits each from the lowest), so such a
/// directory is the one empty directory whose process is gone; a node still starting keeps
/// its process. The run it belonged to cannot be told, so the clean-up of any run removes
/// any of this user's. Returns how many were removed.
fn remove_abandoned_node_dirs(config: &Config) -> Result<usize, TransportError> {
    let node_dir = std_path(&config.global.node_dir());
    let mut removed = 0;
    for node_id in names_owned_by(&node_dir, effective_uid())? {
        let dir = node_dir.join(&node_id);
        let empty = std::fs::read_dir(&dir).is_ok_and(|mut entries| entries.next().is_none());
        let gone = node_id.parse().is_ok_and(|id| !process_exists(process_of_node(id)));
        // Fails, and is left, if the directory is no longer empty.
        if empty && gone && std::fs::remove_dir(&dir).is_ok() {
            removed += 1;
        }
    }
    Ok(removed)
}

/// Removes the directories and monitors of the run's nodes whose process died as the node
/// started, which nothing lists: iceoryx2 writes a node's details, then creates the monitor
/// that lists the node once complete (of about 500 agents killed 0 to 40 ms after they
/// started, one died before the monitor, one while it was made). A node still starting looks
/// the same, but its process holds its details open from their creation on. Returns how many
/// were removed.
fn remove_nodes_that_died_starting(config: &Config, prefix: &str) -> Result<usize, TransportError> {
    let uid = effective_uid();
    let node_dir = std_path(&config.global.node_dir());
    let monitor_suffix = String::from_utf8_lossy(config.global.node.monitor_suffix.as_bytes());
    let mut removed = 0;
    for node_id in names_owned_by(&node_dir, uid)? {
        let dir = node_dir.join(&node_id);
        let monitor = node_dir.join(format!("{prefix}{node_id}{monitor_suffix}"));
        // Made readable once complete, as every iceoryx2 file.
        let monitored = std::fs::metadata(&monitor).is_ok_and(|m| m.mode() & 0o400 != 0);
        if monitored || !dir.is_dir() {
            continue;
        }
        let files = names_owned_by(&dir, uid)?;
        let of_this_run = !files.is_empty() && files.iter().all(|name| name.starts_with(prefix));
        if of_this_run && !files.iter().any(|name| in_use(&dir.join(name))) {
            remove_node_files(config, &node_id).map_err(|cause| TransportError::Io {
                what: format!("removing {}", dir.display()),
                cause,
            })?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Removes a dead node's directory and then its monitor files, all named by its id; an
/// interrupted removal leaves the monitor, so the next clean-up finds the node again.
fn remove_node_files(config: &Config, node_id: &str) -> std::io::Result<()> {
    let node_dir = std_path(&config.global.node_dir());
    let gone_already = |result: std::io::Result<()>| match result {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        other => other,
    };
    gone_already(std::fs::remove_dir_all(node_dir.join(node_id)))?;
    for name in monitor_files(config, node_id).map_err(std::io::Error::other)? {
        gone_already(std::fs::remove_file(node_dir.join(name)))?;
    }
    Ok(())
}

/// The names of the node's monitor files in the node directory: the monitor, its owner
/// lock and its context.
fn monitor_files(config: &Config, node_id: &str) -> Result<Vec<String>, TransportError> {
    let monitor = format!("{}{node_id}.", String::from_utf8_lossy(config.global.prefix.as_bytes()));
    let node_dir = std_path(&config.global.node_dir());
    let mut names = names_owned_by(&node_dir, effective_uid())?;
    names.retain(|name| name.starts_with(&monitor));
    Ok(names)
}

/// Whether a process has `path` open or mapped (Linux: `/proc/PID/fd` and `/proc/PID/maps`).
/// Yes if `/proc` cannot be listed, so nothing is removed blindly. A process that cannot be
/// looked into counts as not using it: here PID 1 cannot be, even by root, and flockstep's
/// own processes always can. Processes that share these directories from another pid
/// namespace cannot be seen at all.
fn in_use(path: &StdPath) -> bool {
    let (Ok(path), Ok(processes)) = (path.canonicalize(), std::fs::read_dir("/proc")) else {
        return true;
    };
    let mapped = |maps: String| {
        // A file's mapping ends its line with the file's path, the line's first `/`.
        maps.lines().any(|line| line.find('/').is_some_and(|at| StdPath::new(&line[at..]) == path))
    };
    processes.flatten().any(|process| {
        let open = std::fs::read_dir(process.path().join("fd")).is_ok_and(|fds| {
            fds.flatten().any(|fd| std::fs::read_link(fd.path()).is_ok_and(|to| to == path))
        });
        open || std::fs::read_to_string(process.path().join("maps")).is_ok_and(mapped)
    })
}

/// Removes the files of run `run_id` in `dir` that `left_behind` picks by their metadata and
/// that no process has open or mapped ([`in_use`]). Returns how many were removed.
fn remove_unused(
    dir: &StdPath,
    run_id: &str,
    left_behind: impl Fn(&std::fs::Metadata) -> bool,
) -> Result<usize, TransportError> {
    let prefix = run_prefix(run_id);
    let mut removed = 0;
    for name in names_owned_by(dir, effective_uid())? {
        let path = dir.join(&name);
        let picked =
            name.starts_with(&prefix) && std::fs::metadata(&path).is_ok_and(|m| left_behind(&m));
        if picked && !in_use(&path) {
            remove_file(&path)?;
            removed += 1;
        }
    }
    Ok(removed)
}

fn remove_file(path: &StdPath) -> Result<(), TransportError> {
    match std::fs::remove_file(path) {
        // Someone else removed it first: the goal is reached.
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(TransportError::Io { what: format!("removing {}", path.display()), cause: e })
        }
        _ => Ok(()),
    }
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
    for path in files_of_this_user()? {
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        if let Some(run_id) = name.strip_prefix(PREFIX_HEAD).and_then(|rest| rest.split('.').next())
        {
            if services::validate_run_id(run_id).is_ok() {
                runs.insert(run_id.to_string());
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
    let mut found: Vec<PathBuf> = files_of_this_user()?
        .into_iter()
        .filter(|path| path.file_name().is_some_and(|n| n.to_string_lossy().starts_with(&prefix)))
        .collect();
    found.sort();
    Ok(found)
}

/// This user's files in the [`candidate_dirs`] and in the node directories (named by node
/// id) under the node directory.
fn files_of_this_user() -> Result<Vec<PathBuf>, TransportError> {
    let uid = effective_uid();
    let node_dir = std_path(&super::default_config()?.global.node_dir());
    let mut files = Vec::new();
    let mut dirs = candidate_dirs()?;
    while let Some(dir) = dirs.pop() {
        for name in names_owned_by(&dir, uid)? {
            let path = dir.join(name);
            if dir == node_dir && path.is_dir() {
                dirs.push(path);
            } else {
                files.push(path);
            }
        }
    }
    Ok(files)
}

/// `/dev/shm` and this user's iceoryx2 root with its node and service directories, taken
/// from the configuration every run's node uses, so they are the directories its files are in.
fn candidate_dirs() -> Result<Vec<PathBuf>, TransportError> {
    let global = super::default_config()?.global;
    Ok(vec![
        PathBuf::from(SHM_DIR),
        std_path(global.root_path()),
        std_path(&global.node_dir()),
        std_path(&global.service_dir()),
    ])
}

fn std_path(path: &iceoryx2::prelude::Path) -> PathBuf {
    PathBuf::from(String::from_utf8_lossy(path.as_bytes()).into_owned())
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
