//! Ctrl-C and SIGTERM, counted. The first asks for an orderly stop: at the end of a round,
//! for everyone at the same round, and once every agent has written its final Q-tables,
//! which can take the world's whole stop-round deadline when an agent hangs. A second one
//! asks for a stop at once: the supervisor then brings its children down without waiting
//! for that round (each agent still saves its tables as it leaves).

use anyhow::Result;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;

/// How many times the process was interrupted.
#[derive(Debug, Default)]
pub struct Interrupts {
    count: AtomicU32,
}

impl Interrupts {
    /// Counts Ctrl-C and SIGTERM from now on (the `ctrlc` crate's handler; it may be set once
    /// per process).
    pub fn catch() -> Result<Arc<Interrupts>> {
        let interrupts = Arc::new(Interrupts::default());
        let counter = interrupts.clone();
        ctrlc::set_handler(move || counter.interrupt())?;
        Ok(interrupts)
    }

    /// Counts one interrupt.
    pub fn interrupt(&self) {
        self.count.fetch_add(1, Ordering::SeqCst);
    }

    /// Whether an orderly stop was asked for.
    pub fn stop_asked(&self) -> bool {
        self.count.load(Ordering::SeqCst) >= 1
    }

    /// Whether a stop at once was asked for: a second interrupt.
    pub fn hurry_asked(&self) -> bool {
        self.count.load(Ordering::SeqCst) >= 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_interrupt_asks_to_stop_and_the_second_to_hurry() {
        let interrupts = Interrupts::default();
        assert!(!interrupts.stop_asked() && !interrupts.hurry_asked());
        interrupts.interrupt();
        assert!(interrupts.stop_asked() && !interrupts.hurry_asked());
        interrupts.interrupt();
        assert!(interrupts.stop_asked() && interrupts.hurry_asked());
    }
}
