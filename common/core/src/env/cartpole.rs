//! CartPole-v1 with Gymnasium's dynamics: the same constants, explicit Euler integration in the
//! same order of operations, float64 internal state, float32 observations.
//!
//! The dynamics are checked against trajectories recorded from Gymnasium 1.4.0 to 1e-9
//! (`common/core/tests/gymnasium_reference.rs`). The one deliberate difference from `gym.make`: the
//! episode limit defaults to 1000 steps (the paper's) instead of 500.

use rand::Rng as _;

use super::episode::Episode;
use super::{Env, EnvError, Step};
use crate::math::{cos, sin};

/// Acceleration of gravity (m/s²).
pub const GRAVITY: f64 = 9.8;
/// Mass of the cart (kg).
pub const MASS_CART: f64 = 1.0;
/// Mass of the pole (kg).
pub const MASS_POLE: f64 = 0.1;
/// Cart plus pole.
pub const TOTAL_MASS: f64 = MASS_POLE + MASS_CART;
/// Half the pole's length (m), as Gymnasium's `length`.
pub const LENGTH: f64 = 0.5;
/// `MASS_POLE * LENGTH`.
pub const POLE_MASS_LENGTH: f64 = MASS_POLE * LENGTH;
/// Magnitude of the force applied to the cart (N).
pub const FORCE_MAG: f64 = 10.0;
/// Seconds between state updates.
pub const TAU: f64 = 0.02;
/// The pole angle beyond which the episode terminates: 12 degrees, in radians.
pub const THETA_THRESHOLD_RADIANS: f64 = 12.0 * 2.0 * std::f64::consts::PI / 360.0;
/// The cart position beyond which the episode terminates.
pub const X_THRESHOLD: f64 = 2.4;
/// The paper's episode limit.
pub const DEFAULT_MAX_EPISODE_STEPS: usize = 1000;
/// Each state value is drawn from `uniform(-RESET_BOUND, RESET_BOUND)` at reset.
pub const RESET_BOUND: f64 = 0.05;

/// CartPole-v1. Actions: 0 pushes the cart left, 1 pushes it right. The reward is +1 on every
/// step, including the one that terminates.
///
/// The observation is `[x, x_dot, theta, theta_dot]` as `f32` (Gymnasium's observation dtype);
/// [`CartPole::state`] gives the float64 internal state.
///
/// An environment that was never seeded behaves as if `reset(Some(0))` had been called first,
/// so that nothing in the core depends on entropy from the operating system.
#[derive(Debug, Clone)]
pub struct CartPole {
    episode: Episode,
    state: [f64; 4],
}

impl Default for CartPole {
    fn default() -> Self {
        Self::new(DEFAULT_MAX_EPISODE_STEPS)
    }
}

impl CartPole {
    /// A CartPole whose episodes are truncated after `max_episode_steps` steps, with Gymnasium's
    /// `TimeLimit` semantics (a limit of 0 truncates at the first step, as a limit of 1 does).
    pub fn new(max_episode_steps: usize) -> Self {
        Self {
            episode: Episode::new(max_episode_steps),
            state: [0.0; 4],
        }
    }

    /// The float64 internal state `[x, x_dot, theta, theta_dot]`.
    pub fn state(&self) -> [f64; 4] {
        self.state
    }

    /// Begins an episode from the given state (as Gymnasium's `env.unwrapped.state = s` right
    /// after a reset): the step counter restarts at 0 and the generator is left untouched.
    pub fn set_state(&mut self, s: [f64; 4]) {
        self.state = s;
        self.episode.start_at_given_state();
    }

    fn observation(&self) -> [f32; 4] {
        self.state.map(|v| v as f32)
    }

    /// One Euler step of the dynamics, in Gymnasium's order of operations.
    fn integrate(state: [f64; 4], action: usize) -> [f64; 4] {
        let [x, x_dot, theta, theta_dot] = state;
        let force = if action == 1 { FORCE_MAG } else { -FORCE_MAG };
        let costheta = cos(theta);
        let sintheta = sin(theta);
        let temp = (force + POLE_MASS_LENGTH * (theta_dot * theta_dot) * sintheta) / TOTAL_MASS;
        let thetaacc = (GRAVITY * sintheta - costheta * temp)
            / (LENGTH * (4.0 / 3.0 - MASS_POLE * (costheta * costheta) / TOTAL_MASS));
        let xacc = temp - POLE_MASS_LENGTH * thetaacc * costheta / TOTAL_MASS;
        [
            x + TAU * x_dot,
            x_dot + TAU * xacc,
            theta + TAU * theta_dot,
            theta_dot + TAU * thetaacc,
        ]
    }

    /// Whether `state` is outside the thresholds (Gymnasium's `terminated`).
    pub fn is_terminal(state: &[f64; 4]) -> bool {
        let [x, _, theta, _] = *state;
        // Gymnasium's `x < -x_threshold or x > x_threshold or ...`: the same comparisons, so a
        // state exactly on a threshold (or NaN) is not terminal.
        x.abs() > X_THRESHOLD || theta.abs() > THETA_THRESHOLD_RADIANS
    }
}

impl Env for CartPole {
    type Observation = [f32; 4];

    fn num_actions(&self) -> usize {
        2
    }

    fn observation_dim(&self) -> usize {
        4
    }

    fn max_episode_steps(&self) -> usize {
        self.episode.max_steps()
    }

    fn reset(&mut self, seed: Option<u64>) -> [f32; 4] {
        let rng = self.episode.begin(seed);
        for v in &mut self.state {
            *v = rng.random_range(-RESET_BOUND..RESET_BOUND);
        }
        tracing::trace!(state = ?self.state, "cartpole reset");
        self.observation()
    }

    fn step(&mut self, action: usize) -> Result<Step<[f32; 4]>, EnvError> {
        self.episode.check_step(action, self.num_actions())?;
        self.state = Self::integrate(self.state, action);
        let terminated = Self::is_terminal(&self.state);
        let truncated = self.episode.count_step(terminated);
        Ok(Step {
            observation: self.observation(),
            reward: 1.0,
            terminated,
            truncated,
        })
    }

    fn snapshot(&self) -> super::EnvState {
        self.episode.snapshot(&self.state)
    }

    fn restore(&mut self, state: &super::EnvState) -> Result<(), EnvError> {
        self.episode.restore(state, &mut self.state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reset_draws_each_value_within_bounds_and_reseeds() {
        let mut env = CartPole::default();
        let first = env.reset(Some(3));
        let s = env.state();
        assert!(s.iter().all(|v| v.abs() < RESET_BOUND));
        assert!(s.iter().any(|&v| v != 0.0));
        assert_eq!(first, s.map(|v| v as f32));
        assert_eq!(env.reset(Some(3)), first);
        assert_ne!(env.reset(None), first);
    }

    #[test]
    fn termination_beyond_the_angle_threshold_still_pays_one() {
        let mut env = CartPole::new(1000);
        // Falling to the right fast: the next Euler step crosses 12 degrees.
        env.set_state([0.0, 0.0, THETA_THRESHOLD_RADIANS - 1e-4, 1.0]);
        let step = env.step(1).expect("running");
        assert!(step.terminated);
        assert!(!step.truncated);
        assert_eq!(step.reward, 1.0);
        assert_eq!(env.step(0), Err(EnvError::EpisodeOver));
    }

    #[test]
    fn termination_on_the_limit_step_is_both_terminated_and_truncated() {
        let mut env = CartPole::new(1);
        env.set_state([X_THRESHOLD, 1.0, 0.0, 0.0]);
        let step = env.step(1).expect("running");
        assert!(step.terminated && step.truncated);
    }

    #[test]
    fn a_state_exactly_on_the_threshold_is_not_terminal() {
        // Gymnasium uses strict comparisons: x > 2.4 terminates, x == 2.4 does not.
        assert!(!CartPole::is_terminal(&[X_THRESHOLD, 0.0, 0.0, 0.0]));
        assert!(CartPole::is_terminal(&[X_THRESHOLD + 1e-12, 0.0, 0.0, 0.0]));
        assert!(!CartPole::is_terminal(&[
            0.0,
            0.0,
            -THETA_THRESHOLD_RADIANS,
            0.0
        ]));
        assert!(CartPole::is_terminal(&[
            0.0,
            0.0,
            -THETA_THRESHOLD_RADIANS - 1e-12,
            0.0
        ]));
    }

    #[test]
    fn one_step_from_rest_matches_the_closed_form() {
        // From rest, push right: temp = 10/1.1, thetaacc = -temp / (0.5 * (4/3 - 0.1/1.1)).
        let mut env = CartPole::new(10);
        env.set_state([0.0; 4]);
        env.step(1).expect("running");
        let temp = 10.0 / 1.1;
        let thetaacc = -temp / (0.5 * (4.0 / 3.0 - 0.1 / 1.1));
        let xacc = temp - 0.05 * thetaacc / 1.1;
        let s = env.state();
        assert_eq!(s[0], 0.0);
        assert!((s[1] - 0.02 * xacc).abs() < 1e-15);
        assert_eq!(s[2], 0.0);
        assert!((s[3] - 0.02 * thetaacc).abs() < 1e-15);
        assert!((s[1] - 0.1951219512195122).abs() < 1e-12);
    }
}
