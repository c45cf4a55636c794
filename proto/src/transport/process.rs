//! What `/proc` says about the processes of a run. Each process of a run has one iceoryx2
//! node whose id carries the process id, so a process can tell whether a silent peer still
//! exists instead of waiting out its deadline: the world looks at the agents it waits for,
//! an agent at the world. The processes of a run share one pid namespace, as they share
//! `/dev/shm`.

/// The id of the process that created the node `node_id` (iceoryx2 builds the id from it);
/// also the name of the node's directory.
pub fn process_of_node(node_id: u128) -> u32 {
    (node_id >> 64) as u32
}

/// Whether process `pid` exists and is not a zombie (a killed child stays a zombie until its
/// parent reaps it). Pid 0 (unknown) counts as alive: a deadline decides then.
pub fn process_alive(pid: u32) -> bool {
    if pid == 0 {
        return true;
    }
    process_stat(pid).is_some_and(|fields| fields.first().is_some_and(|s| s != "Z" && s != "X"))
}

/// The fields of `/proc/<pid>/stat` after the command name (state, parent pid, ...); the
/// name is in parentheses and may itself contain spaces and parentheses. None if the
/// process is gone.
pub fn process_stat(pid: u32) -> Option<Vec<String>> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let (_, fields) = stat.rsplit_once(')')?;
    Some(fields.split_whitespace().map(str::to_owned).collect())
}

/// Whether a process of that id exists, or cannot be told not to (a zombie exists: its id
/// is still taken).
pub(super) fn process_exists(pid: u32) -> bool {
    !matches!(std::fs::metadata(format!("/proc/{pid}")), Err(e) if e.kind() == std::io::ErrorKind::NotFound)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_process_is_alive_and_its_stat_names_its_parent() {
        let fields = process_stat(std::process::id()).expect("this process has a stat file");
        assert_eq!(fields[1], std::os::unix::process::parent_id().to_string(), "{fields:?}");
        assert!(process_alive(std::process::id()));
        assert!(process_exists(std::process::id()));
        assert!(process_alive(0), "an unknown pid is left to the deadline");
        assert!(process_stat(u32::MAX).is_none(), "no such process");
        assert!(!process_alive(u32::MAX) && !process_exists(u32::MAX));
    }

    #[test]
    fn a_zombie_exists_but_is_not_alive() {
        let mut child = std::process::Command::new("true").spawn().expect("spawn `true`");
        let pid = child.id();
        // Not reaped: once it has exited it stays a zombie. Bounded: `true` exits at once.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while process_alive(pid) {
            assert!(std::time::Instant::now() < deadline, "`true` (process {pid}) did not exit");
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert!(process_exists(pid), "a zombie's id is still taken");
        child.wait().expect("reap");
        assert!(!process_exists(pid), "reaped, it is gone");
    }
}
