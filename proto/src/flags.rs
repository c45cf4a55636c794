//! The inter-UAV message (SPEC section 3).
//!
//! Design: flags travel inside the agent's [`crate::Action`] for tick t and the world relays
//! them to every agent in the [`crate::Observation`] of tick t+1. The world is the one
//! sequencer of the run, so relaying through it makes "sent at t, in the receiver's state at
//! t+1" hold by construction, adds no service and no wait (the world waits for the actions
//! anyway), and costs one broadcast instead of N x N agent-to-agent connections.

use iceoryx2::prelude::ZeroCopySend;

/// What one UAV tells the others in one tick of one trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Flags")]
pub struct Flags {
    /// 1 if this message carries information (the sender was live and sent it).
    pub valid: u8,
    /// 1 if the sender saw the target from `waypoint` at the start of the tick.
    pub sees_target: u8,
    /// The sender's waypoint index (0-based) when it looked.
    pub waypoint: u16,
    pub _reserved: u32,
    /// Compact mode: candidate target cells the sender has ruled out (bit k = candidate k).
    pub ruled_out: u64,
    /// Compact mode: candidate target cells the sender has confirmed.
    pub confirmed: u64,
}

impl Flags {
    /// Whether `self` and `other` differ in any field: the test the world makes for every
    /// agent's flags in every tick, so it folds the fields together instead of comparing
    /// them one by one with a branch each.
    #[inline]
    pub fn differs(&self, other: &Flags) -> bool {
        let small = |f: &Flags| {
            u64::from(f.valid)
                | u64::from(f.sees_target) << 8
                | u64::from(f.waypoint) << 16
                | u64::from(f._reserved) << 32
        };
        (small(self) ^ small(other))
            | (self.ruled_out ^ other.ruled_out)
            | (self.confirmed ^ other.confirmed)
            != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn differs_agrees_with_equality_field_by_field() {
        let base = Flags {
            valid: 1,
            sees_target: 1,
            waypoint: 7,
            _reserved: 0,
            ruled_out: 0b1010,
            confirmed: 0b0100,
        };
        assert!(!base.differs(&base));
        let changes: [fn(&mut Flags); 6] = [
            |f| f.valid = 0,
            |f| f.sees_target = 0,
            |f| f.waypoint = 7 + 256,
            |f| f._reserved = 1 << 31,
            |f| f.ruled_out |= 1 << 63,
            |f| f.confirmed = 0,
        ];
        for (i, change) in changes.iter().enumerate() {
            let mut other = base;
            change(&mut other);
            assert!(base.differs(&other) && other.differs(&base), "field {i}");
            assert_eq!(base.differs(&other), base != other);
        }
    }
}
