//! The `[shaping]` table: how the demonstration model shapes the reward (eq. 4 or a potential).

use serde::{Deserialize, Serialize};

use crate::shaping::{ShapingKind, ShapingSchedule};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShapingConfig {
    /// λ of eq. 4 (and of the potential), ≥ 0.
    #[serde(default = "default_lambda")]
    pub lambda: f64,
    /// Shaping starts once this many demonstrations exist.
    #[serde(default = "default_min_demos")]
    pub min_demos: usize,
    /// Shaping stops at this multiple of the global step of the last demonstration, ≥ 0 (`paper`
    /// shaping only).
    #[serde(default = "default_stop_multiple")]
    pub stop_multiple: f64,
    /// `paper`: eq. 4, `r + λ[1 − (p(a|s) − π(a|s))²]`, for a while. `potential`: the
    /// demonstration model as a potential over state-action pairs, `F = γΦ(s',a') − Φ(s,a)` with
    /// `Φ(s,a) = λ p(a|s)`, for the whole run, the agent acting on its Q-values alone, which biases
    /// its greedy policy against the actions the model favours. `advice`: the same shaping with
    /// the agent acting on `Q(s,a) + Φ(s,a)` in training and greedy evaluation, look-ahead advice
    /// as Wiewiora et al. (2003) define it, which leaves the optimal policy unchanged (EXPERIMENTS.md,
    /// "Potential shaping and the greedy policy").
    #[serde(default)]
    pub kind: ShapingKind,
}

fn default_lambda() -> f64 {
    0.75
}
fn default_min_demos() -> usize {
    10
}
fn default_stop_multiple() -> f64 {
    2.0
}

impl Default for ShapingConfig {
    fn default() -> Self {
        Self {
            lambda: default_lambda(),
            min_demos: default_min_demos(),
            stop_multiple: default_stop_multiple(),
            kind: ShapingKind::Paper,
        }
    }
}

impl ShapingConfig {
    pub fn schedule(&self) -> ShapingSchedule {
        ShapingSchedule {
            lambda: self.lambda,
            min_demos: self.min_demos,
            stop_multiple: self.stop_multiple,
            kind: self.kind,
        }
    }
}
