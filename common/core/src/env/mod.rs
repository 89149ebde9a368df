//! Environments with Gymnasium's semantics: `reset(seed)` gives an observation, `step(action)`
//! gives the next observation, the reward, `terminated` and `truncated`.

pub mod acrobot;
pub mod cartpole;
pub mod cliffwalk;
pub mod deepsea;
mod episode;
pub mod mountaincar;

pub use acrobot::Acrobot;
pub use cartpole::CartPole;
pub use cliffwalk::CliffWalk;
pub use deepsea::{DeepSea, DeepSeaCells};
pub use mountaincar::MountainCar;

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
    #[error("a saved environment state does not fit this environment: {0}")]
    BadState(String),
    /// An environment in another process failed or did not answer (the message says which).
    #[error("remote environment: {0}")]
    Remote(String),
    /// What this environment cannot do, named (e.g. restoring a remote environment's state).
    #[error("not supported: {0}")]
    Unsupported(String),
}

/// The whole state of an environment, for a checkpoint: its generator, where it is in its
/// episode life cycle (0 not reset, 1 running, 2 over), the steps of the episode, and its
/// physical state (CartPole's four values, MountainCar's two, Acrobot's four, CliffWalk's
/// position, DeepSea's row and column).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnvState {
    pub rng: crate::rng::RngState,
    pub phase: u8,
    pub elapsed_steps: u64,
    pub state: Vec<f64>,
}

/// A discrete-action environment.
///
/// `reset(Some(seed))` reseeds the environment's generator, `reset(None)` continues with it, as in
/// Gymnasium. The same seed and the same actions always give the same trajectory. An environment
/// that was never seeded behaves as if seeded with 0 (the core never draws entropy from the OS).
/// `common/core/tests/env_conformance.rs` checks every implementation against this contract.
pub trait Env {
    type Observation: Clone + std::fmt::Debug;

    /// Number of discrete actions; actions are `0..num_actions()`.
    fn num_actions(&self) -> usize;
    /// Number of values in an observation (1 for a discrete state id).
    fn observation_dim(&self) -> usize;
    /// The step limit after which an episode is `truncated`.
    fn max_episode_steps(&self) -> usize;
    fn reset(&mut self, seed: Option<u64>) -> Self::Observation;
    fn step(&mut self, action: usize) -> Result<Step<Self::Observation>, EnvError>;
    /// The whole state, to continue exactly from it later ([`Env::restore`]).
    fn snapshot(&self) -> EnvState;
    /// Puts the environment back in a state [`Env::snapshot`] took (of the same environment).
    fn restore(&mut self, state: &EnvState) -> Result<(), EnvError>;
}

/// An environment whose states are ids `0..num_states()` (the tabular agents' environments:
/// CliffWalk, DeepSea's cells).
pub trait TabularEnv: Env<Observation = usize> + Clone {
    fn num_states(&self) -> usize;
}

/// An environment for the neural agents: observations as vectors of `f32`.
pub type VectorEnv = dyn Env<Observation = Vec<f32>>;

/// Adapts an environment with fixed-size array observations to [`VectorEnv`].
#[derive(Debug, Clone)]
pub struct Vectorized<E>(pub E);

impl<E, const N: usize> Env for Vectorized<E>
where
    E: Env<Observation = [f32; N]>,
{
    type Observation = Vec<f32>;

    fn num_actions(&self) -> usize {
        self.0.num_actions()
    }

    fn observation_dim(&self) -> usize {
        N
    }

    fn max_episode_steps(&self) -> usize {
        self.0.max_episode_steps()
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        self.0.reset(seed).to_vec()
    }

    fn step(&mut self, action: usize) -> Result<Step<Vec<f32>>, EnvError> {
        let s = self.0.step(action)?;
        Ok(Step {
            observation: s.observation.to_vec(),
            reward: s.reward,
            terminated: s.terminated,
            truncated: s.truncated,
        })
    }

    fn snapshot(&self) -> EnvState {
        self.0.snapshot()
    }

    fn restore(&mut self, state: &EnvState) -> Result<(), EnvError> {
        self.0.restore(state)
    }
}

/// The environment of a config for the neural agents (the names `EnvName` lists with vector
/// observations, and DeepSea's one-hot grid); `None` for CliffWalk (tabular agents only) and
/// Gymnasium's (served by another process, see `alfd-wire`).
pub fn vector_env(cfg: &crate::config::ExperimentConfig) -> Option<Box<VectorEnv>> {
    let env = &cfg.env;
    if env.name == crate::config::EnvName::Deepsea {
        let sea = DeepSea::with_max_episode_steps(
            env.deepsea_size(),
            cfg.deepsea_mapping_seed(),
            env.max_episode_steps(),
        );
        return sea.ok().map(|sea| Box::new(sea) as Box<VectorEnv>);
    }
    vector_env_named(env.name, env.max_episode_steps())
}

/// The environment `name` with vector observations, truncated after `max_episode_steps` steps;
/// `None` for CliffWalk, for DeepSea (its instance is the config's: [`vector_env`]) and for
/// Gymnasium's (served by another process, see `alfd-wire`).
pub fn vector_env_named(
    name: crate::config::EnvName,
    max_episode_steps: usize,
) -> Option<Box<VectorEnv>> {
    use crate::config::EnvName;
    let limit = max_episode_steps;
    match name {
        EnvName::Cartpole => Some(Box::new(Vectorized(CartPole::new(limit)))),
        EnvName::Mountaincar => Some(Box::new(Vectorized(MountainCar::new(limit)))),
        EnvName::Acrobot => Some(Box::new(Vectorized(Acrobot::new(limit)))),
        // In another process (the Python adapter): built outside the core, by `alfd-wire`.
        EnvName::Cliffwalk | EnvName::Gymnasium | EnvName::Deepsea => None,
    }
}
