//! Reward shaping with the demonstration model (paper section 3.5, eq. 4), and when it is on.

use serde::{Deserialize, Serialize};

/// Which shaping.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum ShapingKind {
    /// Eq. 4, for a while (see `shaping.stop_multiple`).
    #[default]
    Paper,
    /// Potential-based shaping with the demonstration model, for the whole run.
    Potential,
    /// `potential`'s shaping, with the agent acting on `Q(s,a) + Φ(s,a)` (look-ahead advice as
    /// Wiewiora et al. 2003 define it), in training and in greedy evaluation.
    Advice,
}

impl ShapingKind {
    /// Whether the reward gets the potential-based bonus (`potential`, `advice`).
    pub fn is_potential(self) -> bool {
        matches!(self, ShapingKind::Potential | ShapingKind::Advice)
    }

    /// What an agent adds to its action values (the model and λ of `shaping`, the shaping of
    /// the step): under `advice` only.
    pub fn advice<M>(self, shaping: Option<(M, f64)>) -> Option<(M, f64)> {
        shaping.filter(|_| self == ShapingKind::Advice)
    }
}

/// Eq. 4: `r̂ = r + λ [1 − (p(a|s, demo model) − π(a|s))²]`.
pub fn shaped_reward(reward: f64, lambda: f64, p_demo: f64, pi: f64) -> f64 {
    let d = p_demo - pi;
    reward + lambda * (1.0 - d * d)
}

/// Potential-based shaping (look-ahead advice): `F = γΦ(s',a') − Φ(s,a)`, given `Φ(s',a')`
/// (`phi_next`, 0 after a terminal step) and `Φ(s,a)` (`phi`).
pub fn potential_bonus(gamma: f64, phi_next: f64, phi: f64) -> f64 {
    gamma * phi_next - phi
}

/// When shaping applies: from the moment `min_demos` demonstrations exist until `stop_multiple`
/// times the (global) step of the last demonstration (potential-based shaping: to the end).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapingSchedule {
    /// λ of eq. 4.
    pub lambda: f64,
    /// Shaping starts once this many demonstrations exist (and a model is fitted on them).
    pub min_demos: usize,
    /// Shaping stops at `stop_multiple × (step of the last demonstration)`.
    pub stop_multiple: f64,
    pub kind: ShapingKind,
}

impl ShapingSchedule {
    /// Whether the reward of global step `step` is shaped, given `demos` demonstrations so far,
    /// the last of them at global step `last_demo_step`.
    pub fn active(&self, step: u64, demos: usize, last_demo_step: u64) -> bool {
        demos > 0
            && demos >= self.min_demos
            && (self.kind.is_potential()
                || (step as f64) < self.stop_multiple * (last_demo_step as f64))
    }

    /// The model and λ to shape the reward of global step `step` with (Algorithm 1 line 18), or
    /// `None` when shaping is off then or no model is fitted yet. `demos` and `last_demo_step`
    /// describe the demonstration set `model` was fitted on.
    pub fn model_for<'a, M>(
        &self,
        step: u64,
        demos: usize,
        last_demo_step: u64,
        model: Option<&'a M>,
    ) -> Option<(&'a M, f64)> {
        let model = model?;
        self.active(step, demos, last_demo_step)
            .then_some((model, self.lambda))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq4_bonus_is_largest_when_policy_agrees_with_demo_model() {
        assert_eq!(shaped_reward(1.0, 0.75, 0.8, 0.8), 1.75);
        assert!((shaped_reward(1.0, 0.75, 1.0, 0.0) - 1.0).abs() < 1e-15);
        assert!((shaped_reward(0.0, 0.75, 0.9, 0.5) - 0.75 * (1.0 - 0.16)).abs() < 1e-12);
    }

    #[test]
    fn schedule_starts_at_min_demos_and_stops_at_twice_last_demo() {
        let s = ShapingSchedule {
            lambda: 0.75,
            min_demos: 10,
            stop_multiple: 2.0,
            kind: ShapingKind::Paper,
        };
        assert!(!s.active(50, 9, 40), "not enough demos yet");
        assert!(s.active(50, 10, 40));
        assert!(s.active(79, 10, 40));
        assert!(!s.active(80, 10, 40), "stops at twice the last demo's step");
        // A new demonstration moves the end.
        assert!(s.active(150, 11, 100));
        assert!(!s.active(0, 0, 0));
        assert_eq!(
            s.model_for(50, 10, 40, Some(&"model")),
            Some((&"model", 0.75))
        );
        assert_eq!(s.model_for::<&str>(50, 10, 40, None), None);
        assert_eq!(s.model_for(80, 10, 40, Some(&"model")), None);
        let p = ShapingSchedule {
            kind: ShapingKind::Potential,
            ..s
        };
        assert!(p.active(1_000_000, 10, 40), "potential shaping never stops");
        assert!(!p.active(50, 9, 40), "but starts at min_demos");
    }

    #[test]
    fn potential_shaping_telescopes_over_an_episode() {
        // F_t = γΦ_{t+1} − Φ_t with Φ = 0 after the end: Σ γ^t F_t = −Φ_0.
        let (gamma, phi): (f64, [f64; 4]) = (0.9, [0.3, 0.6, 0.1, 0.75]);
        let f = |t: usize| gamma * phi.get(t + 1).copied().unwrap_or(0.0) - phi[t];
        let total: f64 = (0..4).map(|t| gamma.powi(t as i32) * f(t)).sum();
        assert!((total + phi[0]).abs() < 1e-12, "{total}");
        assert!((potential_bonus(gamma, 0.6, 0.3) - (0.9 * 0.6 - 0.3)).abs() < 1e-15);
    }
}
