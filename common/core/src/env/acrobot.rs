//! Acrobot-v1 with Gymnasium's dynamics: the "book" equations of motion (Sutton & Barto), one
//! classic Runge-Kutta step of 0.2 s per action as Gymnasium's `rk4` takes it, angles wrapped to
//! [-π, π] and velocities clipped after the step, float64 internal state, float32 observations.
//!
//! The dynamics are checked against trajectories recorded from Gymnasium 1.4.0 to 1e-9
//! (`common/core/tests/gymnasium_reference.rs`). The reward is sparse: -1 per step, 0 on the step that
//! lifts the tip above the bar, so a policy that never gets there scores -500.

use std::f64::consts::PI;

use rand::Rng as _;

use super::episode::Episode;
use super::{Env, EnvError, Step};
use crate::math::{cos, sin};

/// Seconds integrated per step.
pub const DT: f64 = 0.2;
/// Length of link 1 (m).
pub const LINK_LENGTH_1: f64 = 1.0;
/// Mass of link 1 (kg).
pub const LINK_MASS_1: f64 = 1.0;
/// Mass of link 2 (kg).
pub const LINK_MASS_2: f64 = 1.0;
/// Position of the centre of mass of link 1 (m).
pub const LINK_COM_POS_1: f64 = 0.5;
/// Position of the centre of mass of link 2 (m).
pub const LINK_COM_POS_2: f64 = 0.5;
/// Moment of inertia of either link.
pub const LINK_MOI: f64 = 1.0;
/// Acceleration of gravity (m/s²).
pub const GRAVITY: f64 = 9.8;
/// θ̇1 is clipped to `[-MAX_VEL_1, MAX_VEL_1]`.
pub const MAX_VEL_1: f64 = 4.0 * PI;
/// θ̇2 is clipped to `[-MAX_VEL_2, MAX_VEL_2]`.
pub const MAX_VEL_2: f64 = 9.0 * PI;
/// The torque on the joint between the links, by action.
pub const TORQUES: [f64; 3] = [-1.0, 0.0, 1.0];
/// `gym.make("Acrobot-v1")`'s episode limit.
pub const DEFAULT_MAX_EPISODE_STEPS: usize = 500;
/// Each state value is drawn from `uniform(-RESET_BOUND, RESET_BOUND)` at reset.
pub const RESET_BOUND: f64 = 0.1;

/// Acrobot-v1. Actions: torque -1, 0 or +1 on the joint between the two links (no torque noise).
/// The internal state is `[θ1, θ2, θ̇1, θ̇2]`: θ1 the angle of the first link from hanging
/// straight down, θ2 the angle of the second link relative to the first. The episode terminates
/// when the tip rises more than one link length above the pivot,
/// `-cos θ1 - cos(θ1 + θ2) > 1`; that step pays 0, every other step -1.
///
/// The observation is `[cos θ1, sin θ1, cos θ2, sin θ2, θ̇1, θ̇2]` as `f32`;
/// [`Acrobot::state`] gives the float64 internal state. An environment that was never seeded
/// behaves as if `reset(Some(0))` had been called first.
#[derive(Debug, Clone)]
pub struct Acrobot {
    episode: Episode,
    state: [f64; 4],
}

impl Default for Acrobot {
    fn default() -> Self {
        Self::new(DEFAULT_MAX_EPISODE_STEPS)
    }
}

impl Acrobot {
    /// An Acrobot whose episodes are truncated after `max_episode_steps` steps.
    pub fn new(max_episode_steps: usize) -> Self {
        Self {
            episode: Episode::new(max_episode_steps),
            state: [0.0; 4],
        }
    }

    /// The float64 internal state `[θ1, θ2, θ̇1, θ̇2]`.
    pub fn state(&self) -> [f64; 4] {
        self.state
    }

    /// Begins an episode from the given state (as Gymnasium's `env.unwrapped.state = s` right
    /// after a reset): the step counter restarts at 0 and the generator is left untouched.
    pub fn set_state(&mut self, s: [f64; 4]) {
        self.state = s;
        self.episode.start_at_given_state();
    }

    /// The observation of a state.
    pub fn observe(state: &[f64; 4]) -> [f32; 6] {
        let [t1, t2, dt1, dt2] = *state;
        [cos(t1), sin(t1), cos(t2), sin(t2), dt1, dt2].map(|v| v as f32)
    }

    /// The time derivative of `[θ1, θ2, θ̇1, θ̇2]` under `torque` (the book's equations, in
    /// Gymnasium's order of operations).
    fn derivatives(s: [f64; 4], torque: f64) -> [f64; 4] {
        let (m1, m2, l1) = (LINK_MASS_1, LINK_MASS_2, LINK_LENGTH_1);
        let (lc1, lc2) = (LINK_COM_POS_1, LINK_COM_POS_2);
        let (i1, i2, g) = (LINK_MOI, LINK_MOI, GRAVITY);
        let [theta1, theta2, dtheta1, dtheta2] = s;
        let d1 =
            m1 * (lc1 * lc1) + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * cos(theta2)) + i1 + i2;
        let d2 = m2 * (lc2 * lc2 + l1 * lc2 * cos(theta2)) + i2;
        let phi2 = m2 * lc2 * g * cos(theta1 + theta2 - PI / 2.0);
        let phi1 = -m2 * l1 * lc2 * (dtheta2 * dtheta2) * sin(theta2)
            - 2.0 * m2 * l1 * lc2 * dtheta2 * dtheta1 * sin(theta2)
            + (m1 * lc1 + m2 * l1) * g * cos(theta1 - PI / 2.0)
            + phi2;
        let ddtheta2 =
            (torque + d2 / d1 * phi1 - m2 * l1 * lc2 * (dtheta1 * dtheta1) * sin(theta2) - phi2)
                / (m2 * (lc2 * lc2) + i2 - (d2 * d2) / d1);
        let ddtheta1 = -(d2 * ddtheta2 + phi1) / d1;
        [dtheta1, dtheta2, ddtheta1, ddtheta2]
    }

    /// One step: a single classic Runge-Kutta step over [0, DT], then the angles wrapped and
    /// the velocities clipped.
    pub fn integrate(state: [f64; 4], action: usize) -> [f64; 4] {
        let torque = TORQUES[action];
        let f = |y: [f64; 4]| Self::derivatives(y, torque);
        let along = |k: [f64; 4], h: f64| std::array::from_fn(|i| state[i] + h * k[i]);
        let half = DT / 2.0;
        let k1 = f(state);
        let k2 = f(along(k1, half));
        let k3 = f(along(k2, half));
        let k4 = f(along(k3, DT));
        let y: [f64; 4] = std::array::from_fn(|i| {
            state[i] + DT / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        });
        [
            wrap(y[0], -PI, PI),
            wrap(y[1], -PI, PI),
            y[2].clamp(-MAX_VEL_1, MAX_VEL_1),
            y[3].clamp(-MAX_VEL_2, MAX_VEL_2),
        ]
    }

    /// Whether the tip is above the bar (Gymnasium's `terminated`).
    pub fn is_terminal(state: &[f64; 4]) -> bool {
        -cos(state[0]) - cos(state[1] + state[0]) > 1.0
    }
}

/// `x` moved into `[low, high]` by whole turns of `high - low`.
fn wrap(mut x: f64, low: f64, high: f64) -> f64 {
    let turn = high - low;
    while x > high {
        x -= turn;
    }
    while x < low {
        x += turn;
    }
    x
}

impl Env for Acrobot {
    type Observation = [f32; 6];

    fn num_actions(&self) -> usize {
        TORQUES.len()
    }

    fn observation_dim(&self) -> usize {
        6
    }

    fn max_episode_steps(&self) -> usize {
        self.episode.max_steps()
    }

    fn reset(&mut self, seed: Option<u64>) -> [f32; 6] {
        let rng = self.episode.begin(seed);
        for v in &mut self.state {
            // Gymnasium draws the initial state as float32.
            *v = f64::from(rng.random_range(-RESET_BOUND..RESET_BOUND) as f32);
        }
        tracing::trace!(state = ?self.state, "acrobot reset");
        Self::observe(&self.state)
    }

    fn step(&mut self, action: usize) -> Result<Step<[f32; 6]>, EnvError> {
        self.episode.check_step(action, self.num_actions())?;
        self.state = Self::integrate(self.state, action);
        let terminated = Self::is_terminal(&self.state);
        let truncated = self.episode.count_step(terminated);
        Ok(Step {
            observation: Self::observe(&self.state),
            reward: if terminated { 0.0 } else { -1.0 },
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
    fn reset_draws_float32_values_within_bounds_and_reseeds() {
        let mut env = Acrobot::default();
        let first = env.reset(Some(3));
        let s = env.state();
        assert!(s.iter().all(|v| v.abs() <= RESET_BOUND));
        assert!(s.iter().all(|&v| f64::from(v as f32) == v));
        assert_eq!(first, Acrobot::observe(&s));
        assert_eq!(env.reset(Some(3)), first);
        assert_ne!(env.reset(None), first);
    }

    #[test]
    fn hanging_at_rest_without_torque_stays_at_rest() {
        // (Only up to cos(-pi/2) = 6e-17 in floating point.)
        let s = Acrobot::integrate([0.0; 4], 1);
        assert!(s.iter().all(|v| v.abs() < 1e-14), "{s:?}");
        // A torque turns the links against each other, the second one faster.
        let [_, t2, dt1, dt2] = Acrobot::integrate([0.0; 4], 2);
        assert!(t2 > 0.0 && dt2 > 0.0 && dt1 < 0.0, "{t2} {dt1} {dt2}");
    }

    #[test]
    fn angles_wrap_and_velocities_clip() {
        assert_eq!(wrap(PI + 0.5, -PI, PI), PI + 0.5 - 2.0 * PI);
        assert_eq!(wrap(-PI - 0.5, -PI, PI), -PI - 0.5 + 2.0 * PI);
        assert_eq!(wrap(PI, -PI, PI), PI);
        assert!((wrap(7.0 * PI, -PI, PI) - PI).abs() < 1e-14);
        // Spinning fast over the top: θ1 wraps to just above -π, and a velocity pushed beyond
        // its bound is clipped to it.
        let s = Acrobot::integrate([PI - 1e-3, 0.0, MAX_VEL_1, 0.0], 1);
        assert!(s[0] < 0.0 && s[0] >= -PI, "{s:?}");
        let s = Acrobot::integrate([0.0, 0.0, 0.0, MAX_VEL_2], 2);
        assert_eq!(s[3], MAX_VEL_2, "{s:?}");
    }

    #[test]
    fn the_tip_above_the_bar_terminates_with_reward_zero() {
        // Straight up: the tip is 2 above the pivot; horizontal: 0; the bar is at 1.
        assert!(Acrobot::is_terminal(&[PI, 0.0, 0.0, 0.0]));
        assert!(!Acrobot::is_terminal(&[PI / 2.0, 0.0, 0.0, 0.0]));
        let mut env = Acrobot::new(500);
        env.set_state([PI - 0.1, 0.0, 0.0, 0.0]);
        let step = env.step(1).expect("running");
        assert!(step.terminated && !step.truncated);
        assert_eq!(step.reward, 0.0);
        assert_eq!(env.step(1), Err(EnvError::EpisodeOver));
        env.set_state([0.0; 4]);
        assert_eq!(env.step(1).expect("running").reward, -1.0);
    }
}
