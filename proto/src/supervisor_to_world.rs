//! Supervisor -> world: run control.

use iceoryx2::prelude::ZeroCopySend;

/// Asks the world to stop at the end of the current round (Ctrl-C, operator request).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Control")]
pub struct Control {
    /// 1 = stop now (results so far are kept and flagged partial).
    pub stop: u8,
    pub _reserved: [u8; 7],
}
