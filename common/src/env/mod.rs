//! Environments with Gymnasium's semantics: `reset(seed)` gives an observation, `step(action)`
//! gives the next observation, the reward, `terminated` and `truncated`.

pub mod cartpole;
pub mod cliffwalk;

pub use cartpole::CartPole;
pub use cliffwalk::CliffWalk;

/// What one call to [`Env::step`] returns, as Gymnasium's `step` does.
#[derive(Debug, Clone, PartialEq)]
pub struct Step<O> {
    pub observation: O,
    pub reward: f64,
    /// The episode reached a terminal state of the MDP (no bootstrapping from `observation`).
    pub terminated: bool,
    /// The episode was cut by the step limit (bootstrapping from `observation` is correct).
    pub truncated: bool,
}

impl<O> Step<O> {
    /// The episode is over, for either reason.
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// Misuse of an environment.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EnvError {
    #[error("action {action} is outside the action space {{0..{num_actions}}}")]
    InvalidAction { action: usize, num_actions: usize },
    #[error("step called after the episode ended (terminated or truncated); call reset first")]
    EpisodeOver,
    #[error("step called before reset")]
    NotReset,
}

/// A discrete-action environment.
///
/// `reset(Some(seed))` reseeds the environment's generator, `reset(None)` continues with it, as in
/// Gymnasium. The same seed and the same actions always give the same trajectory. An environment
/// that was never seeded behaves as if seeded with 0 (the core never draws entropy from the OS).
/// `common/tests/env_conformance.rs` checks every implementation against this contract.
pub trait Env {
    type Observation: Clone + std::fmt::Debug;

    /// Number of discrete actions; actions are `0..num_actions()`.
    fn num_actions(&self) -> usize;
    /// The step limit after which an episode is `truncated`.
    fn max_episode_steps(&self) -> usize;
    fn reset(&mut self, seed: Option<u64>) -> Self::Observation;
    fn step(&mut self, action: usize) -> Result<Step<Self::Observation>, EnvError>;
}
