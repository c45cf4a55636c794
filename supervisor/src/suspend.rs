//! Ctrl-Z for a multi-process run. The world and the agents run in process groups of their
//! own (so that Ctrl-C reaches only the supervisor), so a terminal's SIGTSTP stops only the
//! supervisor: its children would run on, fill its buffer of episode records and fail the
//! run once it stayed undrained for the world's report timeout. While a run's children are
//! up, the supervisor therefore catches SIGTSTP and passes it on: it stops its children
//! (SIGSTOP), then itself, and continues them once it is continued (`fg`, `bg`, SIGCONT).
//! Their waits do not count the time they were stopped (`PAUSE_GAP` in
//! `proto/src/transport/wait.rs`), so the run resumes where it was. A SIGSTOP sent to the
//! supervisor alone cannot be caught and stops it alone.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Set by the SIGTSTP handler, taken by [`SuspendOnCtrlZ::requested`].
static REQUESTED: AtomicBool = AtomicBool::new(false);
/// SIGCONTs received, counted by their handler.
static CONTINUED: AtomicU64 = AtomicU64::new(0);
/// [`CONTINUED`] when the last SIGTSTP came: a SIGCONT since continued the Ctrl-Z before the
/// supervisor acted on it (a script's `kill -TSTP` then `kill -CONT`), and stopping then
/// would wait for a continue that has come already.
static CONTINUED_AT_REQUEST: AtomicU64 = AtomicU64::new(0);

extern "C" fn on_sigtstp(_: libc::c_int) {
    CONTINUED_AT_REQUEST.store(CONTINUED.load(Ordering::SeqCst), Ordering::SeqCst);
    REQUESTED.store(true, Ordering::SeqCst);
}

extern "C" fn on_sigcont(_: libc::c_int) {
    CONTINUED.fetch_add(1, Ordering::SeqCst);
}

/// SIGTSTP and SIGCONT caught, for as long as it lives; the dispositions before it are
/// restored when it is dropped, and a Ctrl-Z caught but not acted on then stops the
/// supervisor at once.
pub struct SuspendOnCtrlZ {
    previous: [(libc::c_int, libc::sigaction); 2],
}

impl SuspendOnCtrlZ {
    /// Catches SIGTSTP and SIGCONT from now on.
    pub fn catch() -> std::io::Result<SuspendOnCtrlZ> {
        REQUESTED.store(false, Ordering::SeqCst);
        let on_sigtstp: extern "C" fn(libc::c_int) = on_sigtstp;
        let on_sigcont: extern "C" fn(libc::c_int) = on_sigcont;
        let tstp = (libc::SIGTSTP, catch_signal(libc::SIGTSTP, on_sigtstp)?);
        let cont = match catch_signal(libc::SIGCONT, on_sigcont) {
            Ok(previous) => (libc::SIGCONT, previous),
            Err(e) => {
                restore(&tstp);
                return Err(e);
            }
        };
        Ok(SuspendOnCtrlZ { previous: [tstp, cont] })
    }

    /// Whether a Ctrl-Z came since the last call.
    pub fn requested(&self) -> bool {
        REQUESTED.swap(false, Ordering::SeqCst)
    }

    /// Whether a SIGCONT came since the last Ctrl-Z: it is continued already.
    pub fn continued(&self) -> bool {
        CONTINUED.load(Ordering::SeqCst) != CONTINUED_AT_REQUEST.load(Ordering::SeqCst)
    }

    /// Stops this process until it is continued (SIGCONT), unless it was continued since the
    /// Ctrl-Z already. Returns how long it was stopped, or None if it was not. (A SIGCONT in
    /// the instant between the check and the stop is still missed.)
    pub fn stop_self(&self) -> Option<Duration> {
        if self.continued() {
            return None;
        }
        let stopped = Instant::now();
        // SAFETY: raise(2) of a signal whose default action stops the process.
        unsafe {
            libc::raise(libc::SIGSTOP);
        }
        Some(stopped.elapsed())
    }
}

/// Installs `handler` for `signal`; returns the disposition it replaces.
fn catch_signal(
    signal: libc::c_int,
    handler: extern "C" fn(libc::c_int),
) -> std::io::Result<libc::sigaction> {
    // SAFETY: sigaction with a handler that only touches atomics, and valid pointers to
    // zero-initialised structures.
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = handler as *const () as libc::sighandler_t;
        action.sa_flags = libc::SA_RESTART;
        libc::sigemptyset(&mut action.sa_mask);
        let mut previous: libc::sigaction = std::mem::zeroed();
        if libc::sigaction(signal, &action, &mut previous) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        Ok(previous)
    }
}

/// Restores a disposition [`catch_signal`] replaced.
fn restore((signal, previous): &(libc::c_int, libc::sigaction)) {
    // SAFETY: a disposition sigaction returned.
    unsafe {
        libc::sigaction(*signal, previous, std::ptr::null_mut());
    }
}

impl Drop for SuspendOnCtrlZ {
    fn drop(&mut self) {
        for previous in &self.previous {
            restore(previous);
        }
        if REQUESTED.swap(false, Ordering::SeqCst) && !self.continued() {
            // SAFETY: raise(2) of SIGTSTP, whose restored default action stops the process.
            unsafe {
                libc::raise(libc::SIGTSTP);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Ctrl-Z continued before the supervisor acted on it (`kill -TSTP` then `kill -CONT`
    /// from a script) does not stop it: stopping then would wait for a continue that has
    /// come already, with the whole run stopped.
    #[test]
    fn a_ctrl_z_continued_before_it_is_acted_on_stops_nothing() {
        let ctrl_z = SuspendOnCtrlZ::catch().expect("handlers installed");
        // SAFETY: raise(2) of signals this process now handles.
        unsafe { libc::raise(libc::SIGTSTP) };
        assert!(ctrl_z.requested(), "the Ctrl-Z is seen");
        assert!(!ctrl_z.continued());
        unsafe { libc::raise(libc::SIGCONT) };
        assert!(ctrl_z.continued(), "the continue is seen");
        assert_eq!(ctrl_z.stop_self(), None, "nothing to stop for");
    }
}
