//! The family of K-head Q-functions behind one trait: K Q-tables in the tabular case, one network
//! with K heads in the neural case (the neural agents).
//!
//! Values are laid out head-major, `q[k * A + a] = Q_k(s, a)`, the layout of the network's output
//! layer, of [`crate::policy::js_divergence`] and of the bootstrap masks.

use crate::policy::{js_divergence, softmax_into};

/// K Q-functions over the same state and action spaces.
pub trait QFunction {
    /// The state as the Q-function reads it (`usize` for a table, `[f32]` for a network).
    type State: ?Sized;

    /// K, the number of heads.
    fn heads(&self) -> usize;
    /// A, the number of actions.
    fn actions(&self) -> usize;
    /// Writes `Q_k(s, a)` for every head and action into `out` (`K * A` values, head-major).
    fn q_values(&mut self, s: &Self::State, out: &mut [f64]);

    /// The softmax policy of head `k` at `s` (eq. 2) into `out` (A values).
    fn policy(&mut self, s: &Self::State, k: usize, temperature: f64, out: &mut [f64]) {
        let a = self.actions();
        let mut q = vec![0.0; self.heads() * a];
        self.q_values(s, &mut q);
        softmax_into(&q[k * a..(k + 1) * a], temperature, out);
    }

    /// The Jensen-Shannon divergence of the K softmax policies at `s` (eq. 3).
    fn js_divergence(&mut self, s: &Self::State, temperature: f64) -> f64 {
        let mut q = vec![0.0; self.heads() * self.actions()];
        self.q_values(s, &mut q);
        js_divergence(&q, self.heads(), temperature)
    }
}

/// K Q-tables, `Q_k(s, a)` for a finite state space, all starting at `init`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TabularQ {
    states: usize,
    heads: usize,
    actions: usize,
    /// `q[(s * heads + k) * actions + a]`: the K heads of one state are contiguous.
    q: Vec<f64>,
}

impl TabularQ {
    pub fn new(states: usize, heads: usize, actions: usize, init: f64) -> Self {
        assert!(states > 0 && heads > 0 && actions > 0);
        Self {
            states,
            heads,
            actions,
            q: vec![init; states * heads * actions],
        }
    }

    pub fn states(&self) -> usize {
        self.states
    }

    /// `Q_k(s, ·)`.
    pub fn head_values(&self, s: usize, k: usize) -> &[f64] {
        let i = (s * self.heads + k) * self.actions;
        &self.q[i..i + self.actions]
    }

    pub fn get(&self, s: usize, k: usize, a: usize) -> f64 {
        self.q[(s * self.heads + k) * self.actions + a]
    }

    pub fn set(&mut self, s: usize, k: usize, a: usize, value: f64) {
        self.q[(s * self.heads + k) * self.actions + a] = value;
    }

    /// `max_a Q_k(s, a)`.
    pub fn max_value(&self, s: usize, k: usize) -> f64 {
        self.head_values(s, k)
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// Moves `Q_k(s, a)` a step `lr` towards `target`: `Q += lr * (target - Q)`.
    pub fn update_towards(&mut self, s: usize, k: usize, a: usize, target: f64, lr: f64) {
        let i = (s * self.heads + k) * self.actions + a;
        self.q[i] += lr * (target - self.q[i]);
    }

    /// The greedy policy of head `k` (first action on ties).
    pub fn greedy_policy(&self, k: usize) -> Vec<usize> {
        (0..self.states)
            .map(|s| crate::policy::argmax(self.head_values(s, k)))
            .collect()
    }
}

impl QFunction for TabularQ {
    type State = usize;

    fn heads(&self) -> usize {
        self.heads
    }

    fn actions(&self) -> usize {
        self.actions
    }

    fn q_values(&mut self, s: &usize, out: &mut [f64]) {
        let n = self.heads * self.actions;
        out.copy_from_slice(&self.q[s * n..(s + 1) * n]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tabular_layout_is_head_major_per_state() {
        let mut q = TabularQ::new(3, 2, 4, 0.0);
        q.set(1, 0, 2, 5.0);
        q.set(1, 1, 3, -1.0);
        let mut out = vec![0.0; 8];
        q.q_values(&1, &mut out);
        assert_eq!(out, vec![0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
        assert_eq!(q.max_value(1, 0), 5.0);
        assert_eq!(q.greedy_policy(0)[1], 2);
        q.update_towards(1, 0, 2, 7.0, 0.5);
        assert_eq!(q.get(1, 0, 2), 6.0);
        // Heads that agree have no divergence; heads that disagree do.
        assert!(q.js_divergence(&0, 1.0).abs() < 1e-15);
        assert!(q.js_divergence(&1, 1.0) > 0.1);
        let mut pi = vec![0.0; 4];
        q.policy(&1, 0, 1.0, &mut pi);
        assert!(pi[2] > 0.9);
    }
}
