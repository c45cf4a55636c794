//! Ctrl-Z for a multi-process run. The world and the agents run in process groups of their
//! own (so that Ctrl-C reaches only the supervisor), so a terminal's SIGTSTP stops only the
//! supervisor: its children would run on, fill its buffer of episode records and fail the
//! run once it stayed undrained for the world's report timeout. While a run's children are
//! up, the supervisor therefore catches SIGTSTP and passes it on: it stops its children
//! (SIGSTOP), then itself, and continues them once it is continued (`fg`, `bg`, SIGCONT).
//! Their waits do not count the time they were stopped (`PAUSE_GAP` in
//! `proto/src/transport/wait.rs`), so the run resumes where it was. A SIGSTOP sent to the
//! supervisor alone cannot be caught and stops it alone.

use std::sync::atomic::{AtomicBool, Ordering};

/// Set by the SIGTSTP handler, taken by [`SuspendOnCtrlZ::requested`].
static REQUESTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigtstp(_: libc::c_int) {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// SIGTSTP caught, for as long as it lives; the disposition before it is restored when it
/// is dropped, and a Ctrl-Z caught but not acted on then stops the supervisor at once.
pub struct SuspendOnCtrlZ {
    previous: libc::sigaction,
}

impl SuspendOnCtrlZ {
    /// Catches SIGTSTP from now on.
    pub fn catch() -> std::io::Result<SuspendOnCtrlZ> {
        REQUESTED.store(false, Ordering::SeqCst);
        // SAFETY: sigaction with a handler that only stores to an atomic, and valid
        // pointers to zero-initialised structures.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_sigtstp as *const () as libc::sighandler_t;
            action.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut action.sa_mask);
            let mut previous: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(libc::SIGTSTP, &action, &mut previous) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(SuspendOnCtrlZ { previous })
        }
    }

    /// Whether a Ctrl-Z came since the last call.
    pub fn requested(&self) -> bool {
        REQUESTED.swap(false, Ordering::SeqCst)
    }

    /// Stops this process until it is continued (SIGCONT). Returns how long it was stopped.
    pub fn stop_self(&self) -> std::time::Duration {
        let stopped = std::time::Instant::now();
        // SAFETY: raise(2) of a signal whose default action stops the process.
        unsafe {
            libc::raise(libc::SIGSTOP);
        }
        stopped.elapsed()
    }
}

impl Drop for SuspendOnCtrlZ {
    fn drop(&mut self) {
        // SAFETY: restores the disposition sigaction returned, then raises SIGTSTP, whose
        // default action stops the process.
        unsafe {
            libc::sigaction(libc::SIGTSTP, &self.previous, std::ptr::null_mut());
            if REQUESTED.swap(false, Ordering::SeqCst) {
                libc::raise(libc::SIGTSTP);
            }
        }
    }
}
