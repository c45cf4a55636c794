//! Agent -> world: the tick's commands for every trial, plus the flags the world relays.

use crate::flags::Flags;
use crate::limits::{MAX_COMMANDS, MAX_TRIALS};
use crate::pose::Command;
use iceoryx2::prelude::ZeroCopySend;

/// One trial's part of an agent's action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::TrialAction")]
pub struct TrialAction {
    /// Number of valid entries of `commands`.
    pub n_commands: u8,
    /// 1 if the tree ran `A-endEpisode` in this tick.
    pub ended: u8,
    /// `Command` codes in the order the tree issued them.
    pub commands: [u8; MAX_COMMANDS],
    pub _reserved: [u8; 6],
    pub flags: Flags,
}

impl Default for TrialAction {
    fn default() -> Self {
        TrialAction {
            n_commands: 0,
            ended: 0,
            commands: [0; MAX_COMMANDS],
            _reserved: [0; 6],
            flags: Flags::default(),
        }
    }
}

impl TrialAction {
    pub fn clear(&mut self) {
        *self = TrialAction::default();
    }

    /// Appends a command; returns false if the message is full.
    #[inline]
    pub fn push(&mut self, command: Command) -> bool {
        let n = self.n_commands as usize;
        if n >= MAX_COMMANDS {
            return false;
        }
        self.commands[n] = command as u8;
        self.n_commands += 1;
        true
    }

    /// Checks every field against the sender's route, `route_len` waypoints, and the
    /// scenario's candidate targets, the bits of `valid_targets`: the world calls it before
    /// it applies anything of an action. The error names the first bad field in message
    /// order.
    ///
    /// It runs for every trial of every action, so it is inlined and first tests all fields
    /// in one expression; only a failure takes the field-by-field path that builds the error.
    #[inline]
    pub fn check(&self, route_len: usize, valid_targets: u64) -> Result<(), crate::FieldError> {
        if self.in_range(route_len, valid_targets) {
            Ok(())
        } else {
            self.check_each_field(route_len, valid_targets)
        }
    }

    /// Whether [`TrialAction::check`] passes: a few compares of combined fields, no error
    /// built, no field named.
    #[inline]
    fn in_range(&self, route_len: usize, valid_targets: u64) -> bool {
        let flags = &self.flags;
        // A count past the array finds no codes. The codes are valid up to a power of two
        // less one, so all are valid when their OR is.
        let codes_valid = self.commands.get(..self.n_commands as usize).is_some_and(|codes| {
            codes.iter().fold(0, |any, &code| any | code) <= Command::MAX_CODE
        });
        (usize::from(flags.waypoint) < route_len)
            & ((flags.sees_target | self.ended) < 2)
            & ((flags.ruled_out | flags.confirmed) & !valid_targets == 0)
            & codes_valid
    }

    /// The fields one by one, in message order: the first bad one is the error.
    #[cold]
    fn check_each_field(
        &self,
        route_len: usize,
        valid_targets: u64,
    ) -> Result<(), crate::FieldError> {
        let flags = &self.flags;
        crate::check_below("flags.waypoint", flags.waypoint.into(), route_len as u64)?;
        crate::check_below("flags.sees_target", flags.sees_target.into(), 2)?;
        crate::check_below("action.ended", self.ended.into(), 2)?;
        for (field, mask) in
            [("flags.ruled_out", flags.ruled_out), ("flags.confirmed", flags.confirmed)]
        {
            if mask & !valid_targets != 0 {
                return Err(crate::FieldError {
                    field,
                    value: mask,
                    expected: format!("a mask within {valid_targets:#x}"),
                });
            }
        }
        crate::check_below("action.n_commands", self.n_commands.into(), MAX_COMMANDS as u64 + 1)?;
        match self.command_codes().iter().find(|&&c| Command::from_u8(c).is_none()) {
            Some(&code) => Err(crate::FieldError {
                field: "action.command",
                value: code.into(),
                expected: "0..=3".into(),
            }),
            None => Ok(()),
        }
    }

    /// The command codes counted by `n_commands` (all of them if the count is too big).
    #[inline]
    fn command_codes(&self) -> &[u8] {
        &self.commands[..(self.n_commands as usize).min(MAX_COMMANDS)]
    }

    /// The commands in the order issued (of a checked action: unknown codes are skipped).
    #[inline]
    pub fn commands(&self) -> impl Iterator<Item = Command> + '_ {
        self.command_codes().iter().filter_map(|&code| Command::from_u8(code))
    }
}

/// One agent's message for one barrier round.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Action")]
pub struct Action {
    /// The barrier round this answers (equals the observation's `round`).
    pub round: u64,
    /// Sender's agent slot (0-based; agent 1 in the results is slot 0).
    pub agent: u32,
    /// Number of valid trials (equals the observation's).
    pub n_trials: u32,
    pub trials: [TrialAction; MAX_TRIALS],
}

impl Action {
    pub fn new(agent: usize) -> Action {
        Action {
            round: 0,
            agent: agent as u32,
            n_trials: 0,
            trials: [TrialAction::default(); MAX_TRIALS],
        }
    }

    /// Starts loading the header and the trials in use, written on the agent's core: see
    /// `proto/src/prefetch.rs`.
    #[inline]
    pub fn prefetch_used(&self) {
        let trials = (self.n_trials as usize).min(MAX_TRIALS);
        crate::prefetch::prefetch(std::slice::from_ref(&self.round));
        crate::prefetch::prefetch(&self.trials[..trials]);
    }
}

/// Asks the world for a place in the barrier: sent by every agent when it starts, and
/// repeated until the world answers (the supervisor's agents ask for their own slot, an
/// attaching agent for any free route or the one its `--uav` names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::JoinRequest")]
pub struct JoinRequest {
    /// Identifies the request in the world's answer (`Observation::owners`); not 0.
    pub nonce: u64,
    /// The slot asked for (0-based), or [`ANY_SLOT`].
    pub slot: u32,
    pub _reserved: u32,
}

impl JoinRequest {
    /// The request of an agent that asks for `slot`. The world learns the agent's process
    /// from the request's sender (its iceoryx2 node), not from anything the request says.
    pub fn new(nonce: u64, slot: u32) -> JoinRequest {
        JoinRequest { nonce, slot, _reserved: 0 }
    }
}

/// `JoinRequest::slot` of an agent that takes any free route.
pub const ANY_SLOT: u32 = u32::MAX;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_are_checked_in_count_and_code() {
        let mut action = TrialAction::default();
        assert!(action.push(Command::Rotate) && action.push(Command::NextWaypoint));
        assert_eq!(action.check(1, 0), Ok(()));
        assert_eq!(action.commands().collect::<Vec<_>>(), [Command::Rotate, Command::NextWaypoint]);

        let mut bad_code = action;
        bad_code.commands[1] = 77;
        let err = bad_code.check(1, 0).unwrap_err();
        assert_eq!((err.field, err.value), ("action.command", 77));

        let mut too_many = action;
        too_many.n_commands = MAX_COMMANDS as u8 + 1;
        let err = too_many.check(1, 0).unwrap_err();
        assert_eq!((err.field, err.value), ("action.n_commands", MAX_COMMANDS as u64 + 1));
        assert_eq!(too_many.commands().count(), MAX_COMMANDS, "never reads past the array");
    }

    /// The combined test passes exactly the actions the field-by-field one passes, for
    /// every mix of values at and around each field's bounds.
    #[test]
    fn the_combined_test_agrees_with_the_field_by_field_one() {
        let (route_len, valid) = (11, 0b11);
        let masks = [0, valid, valid + 1, 1 << 63];
        let mut checked = 0;
        for waypoint in [0, 10, 11, u16::MAX] {
            for (sees_target, ended) in [(0, 0), (1, 1), (2, 0), (0, 2), (255, 1)] {
                for (ruled_out, confirmed) in masks.iter().flat_map(|&r| masks.map(|c| (r, c))) {
                    for n_commands in [0, 1, 15, 16, 17, 255] {
                        // No bad code, or one at the first, a middle or the last slot.
                        for bad_at in [None, Some(0), Some(7), Some(15)] {
                            let mut action = TrialAction {
                                n_commands,
                                ended,
                                commands: [Command::NextWaypoint as u8; MAX_COMMANDS],
                                flags: Flags {
                                    waypoint,
                                    sees_target,
                                    ruled_out,
                                    confirmed,
                                    ..Flags::default()
                                },
                                ..TrialAction::default()
                            };
                            if let Some(k) = bad_at {
                                action.commands[k] = Command::MAX_CODE + 1;
                            }
                            let fields = action.check_each_field(route_len, valid);
                            assert_eq!(
                                action.in_range(route_len, valid),
                                fields.is_ok(),
                                "{action:?}"
                            );
                            assert_eq!(action.check(route_len, valid), fields);
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(checked, 4 * 5 * 16 * 6 * 4);
    }
}
