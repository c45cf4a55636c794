//! Dense ids for RL states.
//!
//! A state is the pose packed into one word followed by the communication words. Each
//! distinct state gets the next id the first time it is met, so Q-tables are plain vectors
//! indexed by id, correct for any number of UAVs. The keys are kept in id order, which is
//! what a snapshot stores.
//!
//! Looking up the state is on every tick's path, so the keys live back to back in one
//! vector (every key of an agent has the same length) and the hash table holds only ids:
//! a lookup hashes the words where they are, reads one table slot and compares one key,
//! with no allocation and no pointer to chase.

use flockstep_proto::Pose;
use hashbrown::HashTable;
use rustc_hash::FxHasher;
use std::hash::Hasher;

use crate::learning::StateId;

/// Interns RL states of one agent in one trial.
#[derive(Debug, Clone)]
pub struct StateSpace {
    /// Words per key: the pose word and the communication words.
    key_len: usize,
    /// Key of state `id` at `keys[id * key_len..(id + 1) * key_len]`.
    keys: Vec<u64>,
    ids: HashTable<StateId>,
}

/// The pose as one word: waypoint | height << 16 | heading << 17.
#[inline]
pub fn pose_word(pose: Pose) -> u64 {
    u64::from(pose.waypoint) | u64::from(pose.height) << 16 | u64::from(pose.heading) << 17
}

#[inline]
fn hash_key(first: u64, rest: &[u64]) -> u64 {
    let mut hasher = FxHasher::default();
    hasher.write_u64(first);
    for &word in rest {
        hasher.write_u64(word);
    }
    hasher.finish()
}

impl StateSpace {
    /// An empty space for states of a pose word and `comm_words` communication words.
    pub fn new(comm_words: usize) -> StateSpace {
        StateSpace { key_len: 1 + comm_words, keys: Vec::new(), ids: HashTable::new() }
    }

    /// The id of the state (pose, communication words), assigning the next id if new.
    /// `comm` has the length this space was made for.
    #[inline]
    pub fn id(&mut self, pose: Pose, comm: &[u64]) -> StateId {
        self.intern(pose_word(pose), comm)
    }

    /// The id of the key (`first`, `rest`...), assigning the next id if new.
    #[inline]
    fn intern(&mut self, first: u64, rest: &[u64]) -> StateId {
        debug_assert_eq!(rest.len() + 1, self.key_len, "a state key of the wrong length");
        let hash = hash_key(first, rest);
        let (keys, key_len) = (&self.keys, self.key_len);
        let key = |id: StateId| &keys[id as usize * key_len..(id as usize + 1) * key_len];
        if let Some(&id) = self.ids.find(hash, |&id| {
            let stored = key(id);
            // Word by word: a slice comparison would call `memcmp` for a word or two.
            stored[0] == first && stored[1..].iter().zip(rest).all(|(a, b)| a == b)
        }) {
            return id;
        }
        let id = (keys.len() / key_len) as StateId;
        self.ids.insert_unique(hash, id, |&id| {
            let stored = key(id);
            hash_key(stored[0], &stored[1..])
        });
        self.keys.push(first);
        self.keys.extend_from_slice(rest);
        id
    }

    /// Number of states met so far.
    pub fn len(&self) -> usize {
        self.keys.len() / self.key_len
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Keys in id order.
    pub fn keys(&self) -> impl Iterator<Item = &[u64]> {
        self.keys.chunks_exact(self.key_len)
    }

    /// Rebuilds from keys in id order (a snapshot), each of a pose word and `comm_words`
    /// communication words.
    pub fn from_keys(comm_words: usize, keys: &[Vec<u64>]) -> Result<StateSpace, String> {
        let mut space = StateSpace::new(comm_words);
        for (i, key) in keys.iter().enumerate() {
            if key.len() != space.key_len {
                return Err(format!(
                    "state {i} has {} words; this agent's states have {}",
                    key.len(),
                    space.key_len
                ));
            }
            let id = space.intern(key[0], &key[1..]);
            if id as usize != i {
                return Err(format!("state {i} appears twice (first as state {id})"));
            }
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
        let mut s = StateSpace::new(1);
        let a = Pose::new(3, Height::High, Heading::W);
        let b = Pose::new(3, Height::Low, Heading::W);
        assert_eq!(s.id(a, &[0]), 0);
        assert_eq!(s.id(b, &[0]), 1);
        assert_eq!(s.id(a, &[0]), 0);
        assert_eq!(s.id(a, &[5]), 2, "communication words are part of the state");
        assert_eq!(s.len(), 3);
        let keys: Vec<Vec<u64>> = s.keys().map(<[u64]>::to_vec).collect();
        assert_eq!(keys[2], vec![pose_word(a), 5]);
        let rebuilt = StateSpace::from_keys(1, &keys).unwrap();
        assert!(rebuilt.keys().eq(s.keys()));
        let mut rebuilt = rebuilt;
        assert_eq!(rebuilt.id(b, &[0]), 1, "a rebuilt space gives the same ids");
    }

    #[test]
    fn thousands_of_states_keep_their_ids_through_growth() {
        let mut s = StateSpace::new(2);
        let pose = |w: usize| Pose::new(w, Height::High, Heading::N);
        for i in 0..5000u64 {
            assert_eq!(s.id(pose((i % 7) as usize), &[i, i / 3]), i as StateId);
        }
        for i in (0..5000u64).rev() {
            assert_eq!(s.id(pose((i % 7) as usize), &[i, i / 3]), i as StateId);
        }
    }

    #[test]
    fn snapshots_with_wrong_or_repeated_keys_are_refused() {
        let err = StateSpace::from_keys(1, &[vec![1, 2], vec![3]]).unwrap_err();
        assert!(err.contains("state 1 has 1 words; this agent's states have 2"), "{err}");
        let err = StateSpace::from_keys(0, &[vec![1], vec![1]]).unwrap_err();
        assert!(err.contains("state 1 appears twice (first as state 0)"), "{err}");
    }
}
