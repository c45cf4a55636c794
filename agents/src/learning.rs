//! Tabular Q-learning for the learning selector (SPEC 1.3).
//!
//! States are dense ids handed out by the agent (see `state::StateInterner`); a table row
//! that was never written reads as all zeros, the SPEC's initial value, so tables grow only
//! as states are met. Values are `f64` and every operation is deterministic, so a seed fixes
//! every table bit for bit.

use serde::{Deserialize, Serialize};

/// Dense id of an RL state within one agent.
pub type StateId = u32;

/// Learning rate, discount, exploration, and whether updates happen at all.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LearnParams {
    pub alpha: f64,
    pub gamma: f64,
    pub epsilon: f64,
    /// `false` for greedy evaluation and replays: tables are read, never written.
    pub learn: bool,
}

impl Default for LearnParams {
    /// The SPEC's defaults: alpha 0.1, gamma 1.0 (the thesis's update has no discount),
    /// epsilon 0.1.
    fn default() -> Self {
        LearnParams { alpha: 0.1, gamma: 1.0, epsilon: 0.1, learn: true }
    }
}

impl LearnParams {
    /// Greedy evaluation: epsilon 0, no learning.
    pub fn greedy() -> Self {
        LearnParams { epsilon: 0.0, learn: false, ..LearnParams::default() }
    }

    /// Checks the ranges a Q-learner needs; the message names the parameter.
    pub fn validate(&self) -> Result<(), String> {
        let check = |name: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(format!("--{name} {v} is out of range [{lo}, {hi}]"))
            }
        };
        check("alpha", self.alpha, 0.0, 1.0)?;
        check("gamma", self.gamma, 0.0, 1.0)?;
        check("epsilon", self.epsilon, 0.0, 1.0)
    }
}

/// The reward of every learning step (the thesis counts ticks).
pub const STEP_REWARD: f64 = -1.0;

/// Eight values aligned to a cache line: the row of a selector of up to eight children
/// takes one line, where rows back to back would straddle two for every other state. A
/// tick reads or writes two rows of each selector, and in the multi-process run they are
/// rarely still in cache (`benches/round.rs`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C, align(64))]
struct Line([f64; 8]);

/// Values per [`Line`].
const LINE: usize = 8;

/// Q(s, a) for one learning selector with `n_actions` children.
///
/// A snapshot stores the values row by row without padding (`n_actions`, then `values`).
#[derive(Debug, Clone, PartialEq)]
pub struct QTable {
    n_actions: usize,
    /// Lines per state row.
    row_lines: usize,
    /// State `s`'s row is `lines[s * row_lines..(s + 1) * row_lines]`; values past
    /// `n_actions` stay zero.
    lines: Vec<Line>,
}

impl QTable {
    pub fn new(n_actions: usize) -> Self {
        QTable { n_actions, row_lines: n_actions.div_ceil(LINE).max(1), lines: Vec::new() }
    }

    pub fn n_actions(&self) -> usize {
        self.n_actions
    }

    /// Number of state rows stored (rows beyond it read as zero).
    pub fn n_rows(&self) -> usize {
        self.lines.len() / self.row_lines
    }

    #[inline]
    pub fn get(&self, state: StateId, action: usize) -> f64 {
        let line = state as usize * self.row_lines + action / LINE;
        self.lines.get(line).map_or(0.0, |line| line.0[action % LINE])
    }

    /// The values of `state`'s row, or None if it was never written.
    #[inline]
    fn stored_row(&self, state: StateId) -> Option<impl Iterator<Item = f64> + '_> {
        let start = state as usize * self.row_lines;
        let lines = self.lines.get(start..start + self.row_lines)?;
        Some(lines.iter().flat_map(|line| line.0).take(self.n_actions))
    }

    /// max_b Q(s, b).
    #[inline]
    pub fn max(&self, state: StateId) -> f64 {
        match self.stored_row(state) {
            Some(row) => row.fold(f64::NEG_INFINITY, f64::max),
            None => 0.0,
        }
    }

    /// Q(s, a) to write, making room for the row if it was never written.
    #[inline]
    fn value_mut(&mut self, state: StateId, action: usize) -> &mut f64 {
        let line = state as usize * self.row_lines + action / LINE;
        if line >= self.lines.len() {
            self.lines.resize((state as usize + 1) * self.row_lines, Line::default());
        }
        &mut self.lines[line].0[action % LINE]
    }

    /// One Q-learning step towards `target`: Q(s,a) += alpha * (target - Q(s,a)).
    #[inline]
    pub fn step(&mut self, state: StateId, action: usize, target: f64, alpha: f64) {
        let q = self.value_mut(state, action);
        *q += alpha * (target - *q);
    }

    /// Q-learning update for a non-terminal step: target r + gamma * max_b Q(s', b).
    #[inline]
    pub fn bootstrap(&mut self, s: StateId, a: usize, next: StateId, params: &LearnParams) {
        let target = STEP_REWARD + params.gamma * self.max(next);
        self.step(s, a, target, params.alpha);
    }

    /// Q-learning update for the step that ended the episode: target r.
    #[inline]
    pub fn terminal(&mut self, s: StateId, a: usize, params: &LearnParams) {
        self.step(s, a, STEP_REWARD, params.alpha);
    }

    /// The row of state `s` (zeros if never written).
    pub fn row(&self, state: StateId) -> Vec<f64> {
        (0..self.n_actions).map(|a| self.get(state, a)).collect()
    }
}

impl Serialize for QTable {
    /// As `{ n_actions, values }` with the rows back to back, without padding.
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        /// The stored rows' values, row by row.
        struct Values<'a>(&'a QTable);
        impl Serialize for Values<'_> {
            fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                use serde::ser::SerializeSeq;
                let table = self.0;
                let mut values =
                    serializer.serialize_seq(Some(table.n_rows() * table.n_actions))?;
                for state in 0..table.n_rows() as StateId {
                    for q in table.stored_row(state).into_iter().flatten() {
                        values.serialize_element(&q)?;
                    }
                }
                values.end()
            }
        }
        let mut table = serializer.serialize_struct("QTable", 2)?;
        table.serialize_field("n_actions", &self.n_actions)?;
        table.serialize_field("values", &Values(self))?;
        table.end()
    }
}

/// A table as a snapshot stores it.
#[derive(Deserialize)]
#[serde(rename = "QTable")]
struct StoredTable {
    n_actions: usize,
    values: Vec<f64>,
}

impl<'de> Deserialize<'de> for QTable {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let stored = StoredTable::deserialize(deserializer)?;
        let whole_rows = match stored.n_actions {
            0 => stored.values.is_empty(),
            n => stored.values.len() % n == 0,
        };
        if !whole_rows {
            return Err(serde::de::Error::custom(format!(
                "a table of {} actions cannot hold {} values",
                stored.n_actions,
                stored.values.len()
            )));
        }
        let mut table = QTable::new(stored.n_actions);
        for (state, row) in stored.values.chunks_exact(stored.n_actions.max(1)).enumerate() {
            for (action, &q) in row.iter().enumerate() {
                *table.value_mut(state as StateId, action) = q;
            }
        }
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unwritten_rows_read_as_zero() {
        let t = QTable::new(3);
        assert_eq!(t.get(7, 2), 0.0);
        assert_eq!(t.max(7), 0.0);
    }

    #[test]
    fn bootstrap_and_terminal_follow_the_update_rule() {
        let p = LearnParams { alpha: 0.5, gamma: 1.0, epsilon: 0.0, learn: true };
        let mut t = QTable::new(2);
        t.step(1, 0, -4.0, 1.0); // Q(1,0) = -4, Q(1,1) = 0 -> max = 0
        t.step(1, 1, -2.0, 1.0); // max Q(1, .) = -2
        t.bootstrap(0, 1, 1, &p); // 0 + 0.5 * (-1 + -2 - 0) = -1.5
        assert_eq!(t.get(0, 1), -1.5);
        t.terminal(0, 1, &p); // -1.5 + 0.5 * (-1 + 1.5) = -1.25
        assert_eq!(t.get(0, 1), -1.25);
    }

    /// The layout snapshots have always stored: the rows back to back.
    #[derive(Serialize)]
    struct Unpadded {
        n_actions: usize,
        values: Vec<f64>,
    }

    fn encode<T: Serialize>(value: &T) -> Vec<u8> {
        bincode::serde::encode_to_vec(value, bincode::config::standard()).unwrap()
    }

    #[test]
    fn tables_are_stored_row_by_row_without_padding_and_read_back() {
        for n_actions in [1, 5, 8, 9, 20] {
            let mut t = QTable::new(n_actions);
            t.step(2, n_actions - 1, -3.0, 1.0);
            t.step(0, 0, -1.5, 1.0);
            let mut values = vec![0.0; 3 * n_actions];
            values[2 * n_actions + n_actions - 1] = -3.0;
            values[0] = -1.5;
            let bytes = encode(&t);
            assert_eq!(bytes, encode(&Unpadded { n_actions, values }), "{n_actions} actions");
            let (back, _): (QTable, usize) =
                bincode::serde::decode_from_slice(&bytes, bincode::config::standard()).unwrap();
            assert_eq!(back, t);
            assert_eq!((back.n_rows(), back.get(2, n_actions - 1), back.max(1)), (3, -3.0, 0.0));
        }
    }

    #[test]
    fn a_stored_table_with_a_partial_row_is_refused() {
        let bytes = encode(&Unpadded { n_actions: 5, values: vec![0.0; 7] });
        let err =
            bincode::serde::decode_from_slice::<QTable, _>(&bytes, bincode::config::standard())
                .unwrap_err()
                .to_string();
        assert!(err.contains("a table of 5 actions cannot hold 7 values"), "{err}");
    }

    #[test]
    fn params_are_range_checked() {
        assert!(LearnParams::default().validate().is_ok());
        let bad = LearnParams { alpha: 1.5, ..LearnParams::default() };
        assert!(bad.validate().unwrap_err().contains("--alpha"));
        let nan = LearnParams { epsilon: f64::NAN, ..LearnParams::default() };
        assert!(nan.validate().is_err());
    }
}
