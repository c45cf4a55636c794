//! Dense ids for RL states.
//!
//! A state is the pose packed into one word followed by the communication words. Each
//! distinct state gets the next id the first time it is met, so Q-tables are plain vectors
//! indexed by id, correct for any number of UAVs. The keys are kept in id order, which is
//! what a snapshot stores.

use flockstep_proto::Pose;
use rustc_hash::FxHashMap;

use crate::learning::StateId;

/// Interns RL states of one agent in one trial.
#[derive(Debug, Clone, Default)]
pub struct StateSpace {
    ids: FxHashMap<Box<[u64]>, StateId>,
    keys: Vec<Box<[u64]>>,
    scratch: Vec<u64>,
}

/// The pose as one word: waypoint | height << 16 | heading << 17.
#[inline]
pub fn pose_word(pose: Pose) -> u64 {
    u64::from(pose.waypoint) | u64::from(pose.height) << 16 | u64::from(pose.heading) << 17
}

impl StateSpace {
    /// The id of the state (pose, communication words), assigning the next id if new.
    #[inline]
    pub fn id(&mut self, pose: Pose, comm: &[u64]) -> StateId {
        self.scratch.clear();
        self.scratch.push(pose_word(pose));
        self.scratch.extend_from_slice(comm);
        if let Some(&id) = self.ids.get(self.scratch.as_slice()) {
            return id;
        }
        let id = self.keys.len() as StateId;
        let key: Box<[u64]> = self.scratch.as_slice().into();
        self.ids.insert(key.clone(), id);
        self.keys.push(key);
        id
    }

    /// Keys in id order.
    pub fn keys(&self) -> &[Box<[u64]>] {
        &self.keys
    }

    /// Rebuilds from keys in id order (a snapshot).
    pub fn from_keys(keys: Vec<Box<[u64]>>) -> Result<StateSpace, String> {
        let mut space = StateSpace::default();
        for (i, key) in keys.into_iter().enumerate() {
            if space.ids.insert(key.clone(), i as StateId).is_some() {
                return Err(format!("state {i} appears twice"));
            }
            space.keys.push(key);
        }
        Ok(space)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use flockstep_proto::{Heading, Height};

    #[test]
    fn equal_states_share_an_id_and_new_ones_count_up() {
        let mut s = StateSpace::default();
        let a = Pose::new(3, Height::High, Heading::W);
        let b = Pose::new(3, Height::Low, Heading::W);
        assert_eq!(s.id(a, &[]), 0);
        assert_eq!(s.id(b, &[]), 1);
        assert_eq!(s.id(a, &[]), 0);
        assert_eq!(s.id(a, &[5]), 2, "communication words are part of the state");
        let rebuilt = StateSpace::from_keys(s.keys().to_vec()).unwrap();
        assert_eq!(rebuilt.keys(), s.keys());
    }
}
