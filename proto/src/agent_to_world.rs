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

    /// Checks the command count and every command code: the world calls it before it
    /// applies anything of an action.
    pub fn check_commands(&self) -> Result<(), crate::FieldError> {
        crate::check_below("action.n_commands", self.n_commands.into(), MAX_COMMANDS as u64 + 1)?;
        match self.commands[..self.n_commands as usize]
            .iter()
            .find(|&&c| Command::from_u8(c).is_none())
        {
            Some(&code) => Err(crate::FieldError {
                field: "action.command",
                value: code.into(),
                expected: "0..=3".into(),
            }),
            None => Ok(()),
        }
    }

    /// The commands in the order issued (of a checked action: unknown codes are skipped).
    #[inline]
    pub fn commands(&self) -> impl Iterator<Item = Command> + '_ {
        let n = (self.n_commands as usize).min(MAX_COMMANDS);
        self.commands[..n].iter().filter_map(|&code| Command::from_u8(code))
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
}

/// Asks the world for a place in the barrier: sent once by every agent when it starts (the
/// supervisor's agents ask for their own slot, an attaching agent for any free route).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::JoinRequest")]
pub struct JoinRequest {
    /// Identifies the request in the world's answer (`Observation::admitted_nonce`); not 0.
    pub nonce: u64,
    /// The agent's process id: the world watches it to notice a dead agent at once.
    pub pid: u32,
    /// The slot asked for (0-based), or [`ANY_SLOT`].
    pub slot: u32,
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
        assert_eq!(action.check_commands(), Ok(()));
        assert_eq!(action.commands().collect::<Vec<_>>(), [Command::Rotate, Command::NextWaypoint]);

        let mut bad_code = action;
        bad_code.commands[1] = 77;
        let err = bad_code.check_commands().unwrap_err();
        assert_eq!((err.field, err.value), ("action.command", 77));

        let mut too_many = action;
        too_many.n_commands = MAX_COMMANDS as u8 + 1;
        let err = too_many.check_commands().unwrap_err();
        assert_eq!((err.field, err.value), ("action.n_commands", MAX_COMMANDS as u64 + 1));
        assert_eq!(too_many.commands().count(), MAX_COMMANDS, "never reads past the array");
    }
}
