//! MountainCar-v0 with Gymnasium's dynamics: the same constants, the same order of operations,
//! float64 internal state, float32 observations, and the 200-step limit of `gym.make`.
//!
//! The dynamics are checked against trajectories recorded from Gymnasium 1.4.0 to 1e-9
//! (`common/core/tests/gymnasium_reference.rs`). The reward is sparse: -1 on every step until the
//! car reaches the flag, so a policy that never gets there scores -200.

use rand::Rng as _;

use super::episode::Episode;
use super::{Env, EnvError, Step};
use crate::math::cos;

/// The left wall: the position is clipped here and the car stops.
pub const MIN_POSITION: f64 = -1.2;
/// The right end of the track.
pub const MAX_POSITION: f64 = 0.6;
/// The velocity is clipped to `[-MAX_SPEED, MAX_SPEED]`.
pub const MAX_SPEED: f64 = 0.07;
/// The flag: the episode terminates once the position reaches it...
pub const GOAL_POSITION: f64 = 0.5;
/// ...with at least this velocity (Gymnasium's default `goal_velocity`).
pub const GOAL_VELOCITY: f64 = 0.0;
/// The acceleration of a push.
pub const FORCE: f64 = 0.001;
/// The pull of the slope, scaled by `cos(3 · position)`.
pub const GRAVITY: f64 = 0.0025;
/// `gym.make("MountainCar-v0")`'s episode limit.
pub const DEFAULT_MAX_EPISODE_STEPS: usize = 200;
/// The initial position is drawn from `uniform(RESET_LOW, RESET_HIGH)`, the velocity is 0.
pub const RESET_LOW: f64 = -0.6;
/// See [`RESET_LOW`].
pub const RESET_HIGH: f64 = -0.4;

/// MountainCar-v0. Actions: 0 accelerates left, 1 does nothing, 2 accelerates right. The reward
/// is -1 on every step, including the one that reaches the flag.
///
/// The observation is `[position, velocity]` as `f32`; [`MountainCar::state`] gives the float64
/// internal state. An environment that was never seeded behaves as if `reset(Some(0))` had been
/// called first.
#[derive(Debug, Clone)]
pub struct MountainCar {
    episode: Episode,
    state: [f64; 2],
}

impl Default for MountainCar {
    fn default() -> Self {
        Self::new(DEFAULT_MAX_EPISODE_STEPS)
    }
}

impl MountainCar {
    /// A MountainCar whose episodes are truncated after `max_episode_steps` steps.
    pub fn new(max_episode_steps: usize) -> Self {
        Self {
            episode: Episode::new(max_episode_steps),
            state: [0.0; 2],
        }
    }

    /// The float64 internal state `[position, velocity]`.
    pub fn state(&self) -> [f64; 2] {
        self.state
    }

    /// Begins an episode from the given state (as Gymnasium's `env.unwrapped.state = s` right
    /// after a reset): the step counter restarts at 0 and the generator is left untouched.
    pub fn set_state(&mut self, s: [f64; 2]) {
        self.state = s;
        self.episode.start_at_given_state();
    }

    fn observation(&self) -> [f32; 2] {
        self.state.map(|v| v as f32)
    }

    /// One step of the dynamics, in Gymnasium's order of operations.
    pub fn integrate(state: [f64; 2], action: usize) -> [f64; 2] {
        let [position, velocity] = state;
        let push = (action as f64 - 1.0) * FORCE;
        let velocity =
            (velocity + (push + cos(3.0 * position) * -GRAVITY)).clamp(-MAX_SPEED, MAX_SPEED);
        let position = (position + velocity).clamp(MIN_POSITION, MAX_POSITION);
        // An inelastic collision with the left wall.
        let velocity = if position == MIN_POSITION && velocity < 0.0 {
            0.0
        } else {
            velocity
        };
        [position, velocity]
    }

    /// Whether the car is at the flag (Gymnasium's `terminated`).
    pub fn is_terminal(state: &[f64; 2]) -> bool {
        state[0] >= GOAL_POSITION && state[1] >= GOAL_VELOCITY
    }
}

impl Env for MountainCar {
    type Observation = [f32; 2];

    fn num_actions(&self) -> usize {
        3
    }

    fn observation_dim(&self) -> usize {
        2
    }

    fn max_episode_steps(&self) -> usize {
        self.episode.max_steps()
    }

    fn reset(&mut self, seed: Option<u64>) -> [f32; 2] {
        let position = self.episode.begin(seed).random_range(RESET_LOW..RESET_HIGH);
        self.state = [position, 0.0];
        tracing::trace!(state = ?self.state, "mountaincar reset");
        self.observation()
    }

    fn step(&mut self, action: usize) -> Result<Step<[f32; 2]>, EnvError> {
        self.episode.check_step(action, self.num_actions())?;
        self.state = Self::integrate(self.state, action);
        let terminated = Self::is_terminal(&self.state);
        let truncated = self.episode.count_step(terminated);
        Ok(Step {
            observation: self.observation(),
            reward: -1.0,
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
    fn reset_draws_the_position_in_range_at_rest_and_reseeds() {
        let mut env = MountainCar::default();
        let first = env.reset(Some(3));
        let [position, velocity] = env.state();
        assert!((RESET_LOW..RESET_HIGH).contains(&position), "{position}");
        assert_eq!(velocity, 0.0);
        assert_eq!(first, [position as f32, 0.0]);
        assert_eq!(env.reset(Some(3)), first);
        assert_ne!(env.reset(None), first);
    }

    #[test]
    fn one_step_from_the_valley_floor_matches_the_closed_form() {
        // At position -pi/6, cos(3 x) = 0: only the push acts.
        let x = -std::f64::consts::PI / 6.0;
        let [p, v] = MountainCar::integrate([x, 0.0], 2);
        let slope = (3.0 * x).cos() * -GRAVITY;
        assert!(slope.abs() < 1e-18);
        assert_eq!(v, FORCE + slope);
        assert_eq!(p, x + v);
        let [_, v] = MountainCar::integrate([x, 0.0], 1);
        assert_eq!(v, slope);
    }

    #[test]
    fn speed_is_clipped_and_the_left_wall_stops_the_car() {
        let [_, v] = MountainCar::integrate([-0.5, 0.0699], 2);
        assert_eq!(v, MAX_SPEED);
        let [p, v] = MountainCar::integrate([-1.19, -0.05], 0);
        assert_eq!((p, v), (MIN_POSITION, 0.0));
        // At the wall moving right, the velocity is kept.
        let [p, v] = MountainCar::integrate([MIN_POSITION, 0.0], 2);
        assert!(p > MIN_POSITION && v > 0.0);
    }

    #[test]
    fn reaching_the_flag_terminates_with_the_usual_reward() {
        let mut env = MountainCar::new(200);
        env.set_state([0.49, 0.03]);
        let step = env.step(2).expect("running");
        assert!(step.terminated && !step.truncated);
        assert_eq!(step.reward, -1.0);
        assert_eq!(env.step(1), Err(EnvError::EpisodeOver));
        // At the flag but rolling back: not terminal (goal_velocity 0).
        assert!(!MountainCar::is_terminal(&[0.5, -1e-9]));
        assert!(MountainCar::is_terminal(&[0.5, 0.0]));
        assert!(!MountainCar::is_terminal(&[0.5 - 1e-12, 0.07]));
    }
}
