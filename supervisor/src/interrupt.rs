//! Ctrl-C and SIGTERM, counted. The first asks for an orderly stop: at the end of a round,
//! for everyone at the same round, and once every agent has written its final Q-tables,
//! which can take the world's whole stop-round deadline when an agent hangs. A second one
//! asks for a stop at once: the supervisor then brings its children down without waiting
//! for that round (each agent still saves its tables as it leaves).

use anyhow::Result;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// A second interrupt counts only this long after the first: one signal can arrive twice,
/// as when coreutils `timeout` sends it to the supervisor and then to its whole process
/// group, or a closed terminal's SIGHUP comes from the kernel and from the shell; a user
/// who presses Ctrl-C again does so after reading "stopping".
pub const HURRY_AFTER: Duration = Duration::from_millis(500);

/// The interrupts the process received, as far as they ask for anything.
#[derive(Debug, Default)]
pub struct Interrupts {
    first: OnceLock<Instant>,
    hurry: AtomicBool,
}

impl Interrupts {
    /// Counts Ctrl-C and SIGTERM (and SIGHUP) from now on (the `ctrlc` crate's handler, which
    /// runs on a thread of its own; it may be set once per process).
    pub fn catch() -> Result<Arc<Interrupts>> {
        let interrupts = Arc::new(Interrupts::default());
        let counter = interrupts.clone();
        ctrlc::set_handler(move || counter.interrupt(Instant::now()))?;
        Ok(interrupts)
    }

    /// Counts one interrupt received `at`.
    pub fn interrupt(&self, at: Instant) {
        let first = *self.first.get_or_init(|| at);
        if at.saturating_duration_since(first) >= HURRY_AFTER {
            self.hurry.store(true, Ordering::Relaxed);
        }
    }

    /// Whether an orderly stop was asked for.
    pub fn stop_asked(&self) -> bool {
        self.first.get().is_some()
    }

    /// Whether a stop at once was asked for: a second interrupt, [`HURRY_AFTER`] or more
    /// after the first.
    pub fn hurry_asked(&self) -> bool {
        self.hurry.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_interrupt_asks_to_stop_and_a_later_one_to_hurry() {
        let interrupts = Interrupts::default();
        assert!(!interrupts.stop_asked() && !interrupts.hurry_asked());
        let first = Instant::now();
        interrupts.interrupt(first);
        assert!(interrupts.stop_asked() && !interrupts.hurry_asked());
        // The same signal delivered twice (`timeout` to the child, then to its group).
        interrupts.interrupt(first + Duration::from_millis(1));
        assert!(!interrupts.hurry_asked(), "one signal twice is one interrupt");
        interrupts.interrupt(first + HURRY_AFTER);
        assert!(interrupts.stop_asked() && interrupts.hurry_asked());
    }
}
