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

/// Q(s, a) for one learning selector with `n_actions` children.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QTable {
    n_actions: usize,
    values: Vec<f64>,
}

impl QTable {
    pub fn new(n_actions: usize) -> Self {
        QTable { n_actions, values: Vec::new() }
    }

    pub fn n_actions(&self) -> usize {
        self.n_actions
    }

    /// Number of state rows stored (rows beyond it read as zero).
    pub fn n_rows(&self) -> usize {
        self.values.len() / self.n_actions.max(1)
    }

    #[inline]
    pub fn get(&self, state: StateId, action: usize) -> f64 {
        self.values.get(state as usize * self.n_actions + action).copied().unwrap_or(0.0)
    }

    /// The stored values of state `s`, or `None` if its row was never written (all zeros).
    /// One bounds check for the whole row: the learning selector scans it on every tick.
    #[inline]
    pub fn stored_row(&self, state: StateId) -> Option<&[f64]> {
        let start = state as usize * self.n_actions;
        self.values.get(start..start + self.n_actions)
    }

    /// max_b Q(s, b). Values are never NaN (updates keep them finite, snapshots with
    /// others are refused), so a plain comparison does: `f64::max` would spend about 60
    /// instructions on NaN handling for a row of 5, on every tick.
    #[inline]
    pub fn max(&self, state: StateId) -> f64 {
        match self.stored_row(state) {
            Some(row) => {
                row.iter().fold(f64::NEG_INFINITY, |max, &q| if q > max { q } else { max })
            }
            None => 0.0,
        }
    }

    /// One Q-learning step towards `target`: Q(s,a) += alpha * (target - Q(s,a)).
    #[inline]
    pub fn step(&mut self, state: StateId, action: usize, target: f64, alpha: f64) {
        let index = state as usize * self.n_actions + action;
        if index >= self.values.len() {
            self.values.resize((state as usize + 1) * self.n_actions, 0.0);
        }
        let q = &mut self.values[index];
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

    /// Whether a table read from outside (a snapshot) is one this learner could have made:
    /// whole rows of finite values. The message names the first offending value.
    pub fn check(&self) -> Result<(), String> {
        if self.n_actions == 0 || !self.values.len().is_multiple_of(self.n_actions) {
            return Err(format!(
                "{} values do not make rows of {} actions",
                self.values.len(),
                self.n_actions
            ));
        }
        match self.values.iter().position(|q| !q.is_finite()) {
            Some(i) => Err(format!(
                "Q(state {}, child {}) is {}; Q-values are finite",
                i / self.n_actions,
                i % self.n_actions + 1,
                self.values[i]
            )),
            None => Ok(()),
        }
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

    #[test]
    fn tables_of_partial_rows_or_non_finite_values_fail_the_check() {
        let mut t = QTable::new(2);
        t.step(1, 1, -3.0, 1.0);
        assert_eq!(t.check(), Ok(()));
        t.values[3] = f64::NAN;
        assert_eq!(t.check().unwrap_err(), "Q(state 1, child 2) is NaN; Q-values are finite");
        t.values[3] = f64::NEG_INFINITY;
        assert!(t.check().unwrap_err().contains("is -inf"));
        t.values.pop();
        assert_eq!(t.check().unwrap_err(), "3 values do not make rows of 2 actions");
        assert!(QTable::new(0).check().is_err(), "a selector has children");
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
