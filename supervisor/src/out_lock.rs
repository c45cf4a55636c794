//! An exclusive lock on a run's results directory for as long as the run writes there, so
//! that a second run given the same `--out` (with `--overwrite`, or `--resume` of it) is
//! refused instead of removing, or mixing its own into, the files of the run still writing.

use anyhow::{bail, Context, Result};
use std::fs::File;
use std::os::fd::AsRawFd;
use std::path::Path;

/// Held while the run lives; the kernel releases it when the process ends, however it ends.
#[derive(Debug)]
pub struct OutDirLock {
    _dir: File,
}

impl OutDirLock {
    /// Locks `dir` (it must exist), or says that another run holds it.
    pub fn take(dir: &Path) -> Result<OutDirLock> {
        let file = File::open(dir)
            .with_context(|| format!("cannot open results directory {}", dir.display()))?;
        // SAFETY: flock(2) on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let error = std::io::Error::last_os_error();
            if error.raw_os_error() == Some(libc::EWOULDBLOCK) {
                bail!(
                    "--out {}: another run is writing its results there; choose another \
                     directory, or wait until it has ended",
                    dir.display()
                );
            }
            return Err(error).with_context(|| format!("cannot lock {}", dir.display()));
        }
        Ok(OutDirLock { _dir: file })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_directory_is_locked_once_until_its_lock_is_dropped() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let held = OutDirLock::take(dir.path()).expect("the first lock");
        let refused = OutDirLock::take(dir.path()).expect_err("a second lock while held");
        assert!(format!("{refused:#}").contains("another run is writing"), "{refused:#}");
        drop(held);
        OutDirLock::take(dir.path()).expect("the lock once released");
    }
}
