//! What `/proc` says about a process: which process made an iceoryx2 node (its id carries
//! the process id), whether a process id is still taken, and a process's parent. Whether a
//! run's peer is gone is not asked here but of iceoryx2 ([`super::RunServices::departed_nodes`]):
//! a process id means nothing in another pid namespace, where an attached agent may run (a
//! container sharing `/dev/shm`). The process ids a run reports (membership, clean-up) are
//! still those of the namespace that reads them.

/// The id of the process that created the node `node_id` (iceoryx2 builds the id from it);
/// also the name of the node's directory.
pub fn process_of_node(node_id: u128) -> u32 {
    (node_id >> 64) as u32
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
    fn a_live_process_exists_and_its_stat_names_its_parent() {
        let fields = process_stat(std::process::id()).expect("this process has a stat file");
        assert_eq!(fields[1], std::os::unix::process::parent_id().to_string(), "{fields:?}");
        assert!(process_exists(std::process::id()));
        assert!(process_stat(u32::MAX).is_none(), "no such process");
        assert!(!process_exists(u32::MAX));
    }

    #[test]
    fn a_zombies_id_is_taken_until_it_is_reaped() {
        let mut child = std::process::Command::new("true").spawn().expect("spawn `true`");
        let pid = child.id();
        // Not reaped: once it has exited it stays a zombie. Bounded: `true` exits at once.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while process_stat(pid).is_some_and(|fields| fields[0] != "Z") {
            assert!(std::time::Instant::now() < deadline, "`true` (process {pid}) did not exit");
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert!(process_exists(pid), "a zombie's id is still taken");
        child.wait().expect("reap");
        assert!(!process_exists(pid), "reaped, it is gone");
    }
}
