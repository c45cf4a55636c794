//! A UAV's pose and the commands that change it.
//!
//! The world applies commands to find the truth; the agent applies the same commands to its
//! own copy of the pose while it ticks its tree, so a leaf ticked later in the same tick sees
//! the effect of an earlier one. Both use [`Pose::apply`], so they cannot disagree.

use iceoryx2::prelude::ZeroCopySend;

/// Camera height.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Height {
    Low = 0,
    High = 1,
}

/// Heading; rotation is clockwise N -> E -> S -> W -> N.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Heading {
    N = 0,
    E = 1,
    S = 2,
    W = 3,
}

impl Height {
    pub const ALL: [Height; 2] = [Height::Low, Height::High];

    pub fn from_u8(v: u8) -> Option<Height> {
        match v {
            0 => Some(Height::Low),
            1 => Some(Height::High),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Height::Low => "low",
            Height::High => "high",
        }
    }

    pub fn parse(s: &str) -> Option<Height> {
        match s {
            "low" => Some(Height::Low),
            "high" => Some(Height::High),
            _ => None,
        }
    }
}

impl Heading {
    pub const ALL: [Heading; 4] = [Heading::N, Heading::E, Heading::S, Heading::W];

    pub fn from_u8(v: u8) -> Option<Heading> {
        Heading::ALL.get(v as usize).copied()
    }

    /// Unit step (d_row, d_col) of "forward"; row 0 is the north edge.
    pub fn forward(self) -> (i32, i32) {
        match self {
            Heading::N => (-1, 0),
            Heading::E => (0, 1),
            Heading::S => (1, 0),
            Heading::W => (0, -1),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Heading::N => "N",
            Heading::E => "E",
            Heading::S => "S",
            Heading::W => "W",
        }
    }

    pub fn parse(s: &str) -> Option<Heading> {
        match s {
            "N" => Some(Heading::N),
            "E" => Some(Heading::E),
            "S" => Some(Heading::S),
            "W" => Some(Heading::W),
            _ => None,
        }
    }
}

/// One pose change, issued by an action leaf. Encoded as `u8` on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Command {
    /// Turn 90 degrees clockwise.
    Rotate = 0,
    /// Go to the high height (no change if already there).
    Elevate = 1,
    /// Go to the low height (no change if already there).
    DeElevate = 2,
    /// Go to the next waypoint of the route (cyclic).
    NextWaypoint = 3,
}

impl Command {
    /// The largest valid code: the codes are `0..=MAX_CODE`.
    pub const MAX_CODE: u8 = Command::NextWaypoint as u8;

    #[inline]
    pub fn from_u8(v: u8) -> Option<Command> {
        match v {
            0 => Some(Command::Rotate),
            1 => Some(Command::Elevate),
            2 => Some(Command::DeElevate),
            3 => Some(Command::NextWaypoint),
            _ => None,
        }
    }
}

/// Where a UAV is: waypoint index on its route (0-based), height and heading.
/// Wire form: raw integers, checked by [`Pose::validate`] on receipt.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("flockstep::Pose")]
pub struct Pose {
    pub waypoint: u16,
    pub height: u8,
    pub heading: u8,
}

impl Pose {
    pub fn new(waypoint: usize, height: Height, heading: Heading) -> Pose {
        Pose { waypoint: waypoint as u16, height: height as u8, heading: heading as u8 }
    }

    pub fn height(self) -> Height {
        Height::from_u8(self.height).unwrap_or(Height::Low)
    }

    pub fn heading(self) -> Heading {
        Heading::from_u8(self.heading).unwrap_or(Heading::N)
    }

    /// Checks every field against the route length of its UAV. Inlined: agents check every
    /// pose they receive.
    #[inline]
    pub fn validate(self, route_len: usize) -> Result<(), crate::FieldError> {
        crate::check_below("pose.waypoint", self.waypoint.into(), route_len as u64)?;
        crate::check_below("pose.height", self.height.into(), 2)?;
        crate::check_below("pose.heading", self.heading.into(), 4)
    }

    /// The pose after `command`, on a route of `route_len` waypoints.
    #[inline]
    pub fn apply(self, command: Command, route_len: usize) -> Pose {
        let mut next = self;
        match command {
            Command::Rotate => next.heading = (self.heading + 1) % 4,
            Command::Elevate => next.height = Height::High as u8,
            Command::DeElevate => next.height = Height::Low as u8,
            Command::NextWaypoint => {
                next.waypoint = ((self.waypoint as usize + 1) % route_len) as u16;
            }
        }
        next
    }
}

impl std::fmt::Display for Pose {
    /// 1-based waypoint, as the maps and the thesis write it: `wp6 high E`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "wp{} {} {}", self.waypoint + 1, self.height().name(), self.heading().name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_is_clockwise_and_cyclic() {
        let mut p = Pose::new(0, Height::Low, Heading::N);
        let mut seen = vec![];
        for _ in 0..4 {
            p = p.apply(Command::Rotate, 5);
            seen.push(p.heading());
        }
        assert_eq!(seen, vec![Heading::E, Heading::S, Heading::W, Heading::N]);
    }

    #[test]
    fn waypoints_wrap_and_heights_saturate() {
        let p = Pose::new(4, Height::Low, Heading::N);
        assert_eq!(p.apply(Command::NextWaypoint, 5).waypoint, 0);
        let high = p.apply(Command::Elevate, 5);
        assert_eq!(high.height(), Height::High);
        assert_eq!(high.apply(Command::Elevate, 5), high);
        assert_eq!(high.apply(Command::DeElevate, 5).height(), Height::Low);
        assert_eq!(p.apply(Command::DeElevate, 5), p);
    }

    #[test]
    fn validate_rejects_out_of_range_fields() {
        assert!(Pose { waypoint: 5, height: 0, heading: 0 }.validate(5).is_err());
        assert!(Pose { waypoint: 0, height: 2, heading: 0 }.validate(5).is_err());
        assert!(Pose { waypoint: 0, height: 0, heading: 4 }.validate(5).is_err());
        assert!(Pose { waypoint: 4, height: 1, heading: 3 }.validate(5).is_ok());
    }
}
