//! The agent of a run, built from its config in one place: the learner, each actor's core and
//! the tabular agent, each drawing from its named seed stream, and the seeds of the environments
//! and of greedy evaluation. The single-process runner and the processes of a multi-process run
//! build through here, so a one-actor run starts from `alfd local`'s numbers by construction.

use crate::agent::{NeuralActor, NeuralLearner, TabularAgent};
use crate::config::ExperimentConfig;
use crate::rng::{derive_seed, seeded};

/// The names of the run's seed streams (`derive_seed(cfg.seed, name)`).
pub mod stream {
    /// The learner's: network initialisation, bootstrap masks, minibatches.
    pub const LEARNER: &str = "learner";
    /// Greedy evaluation's environment.
    pub const EVAL: &str = "eval";
    /// The tabular agent's (one process: it acts and learns).
    pub const TABULAR: &str = "agent";

    /// An actor's two streams, its core's and its environment's. Actor 0's first incarnation
    /// has the single-process runner's (`actor-0`, `env`); a restarted actor (incarnation > 1)
    /// gets streams of its own, so it does not replay its predecessor's episodes.
    pub fn actor(actor_id: u16, incarnation: u64) -> (String, String) {
        match (actor_id, incarnation) {
            (0, 1) => ("actor-0".to_owned(), "env".to_owned()),
            (a, 1) => (format!("actor-{a}"), format!("env-{a}")),
            (a, i) => (format!("actor-{a}-r{i}"), format!("env-{a}-r{i}")),
        }
    }
}

/// The learner of a neural run.
pub fn neural_learner(cfg: &ExperimentConfig, obs_dim: usize, actions: usize) -> NeuralLearner {
    NeuralLearner::new(
        &cfg.agent,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, stream::LEARNER)),
    )
}

/// The core of actor `actor_id` (incarnation `incarnation`) of a neural run.
pub fn neural_actor(
    cfg: &ExperimentConfig,
    obs_dim: usize,
    actions: usize,
    actor_id: u16,
    incarnation: u64,
) -> NeuralActor {
    let (core, _) = stream::actor(actor_id, incarnation);
    NeuralActor::new(
        &cfg.agent,
        &cfg.rule_spec(),
        cfg.shaping.kind,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, &core)),
    )
}

/// The agent of a tabular run.
pub fn tabular_agent(cfg: &ExperimentConfig, states: usize, actions: usize) -> TabularAgent {
    TabularAgent::new(
        &cfg.agent,
        &cfg.rule_spec(),
        states,
        actions,
        seeded(derive_seed(cfg.seed, stream::TABULAR)),
    )
}

/// The seed of actor `actor_id`'s environment (its first reset; later episodes derive theirs).
pub fn env_seed(cfg: &ExperimentConfig, actor_id: u16, incarnation: u64) -> u64 {
    derive_seed(cfg.seed, &stream::actor(actor_id, incarnation).1)
}

/// The seed of greedy evaluation's environment (the same at every evaluation).
pub fn eval_seed(cfg: &ExperimentConfig) -> u64 {
    derive_seed(cfg.seed, stream::EVAL)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn actor_zero_has_the_single_process_streams_and_restarts_have_their_own() {
        assert_eq!(stream::actor(0, 1), ("actor-0".into(), "env".into()));
        assert_eq!(stream::actor(3, 1), ("actor-3".into(), "env-3".into()));
        assert_eq!(
            stream::actor(0, 2),
            ("actor-0-r2".into(), "env-0-r2".into())
        );
        let cfg = ExperimentConfig::from_toml(
            "seed = 5\nepisodes = 1\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n",
        )
        .unwrap();
        assert_eq!(env_seed(&cfg, 0, 1), derive_seed(5, "env"));
        assert_ne!(env_seed(&cfg, 0, 2), env_seed(&cfg, 0, 1));
        assert_eq!(eval_seed(&cfg), derive_seed(5, "eval"));
    }
}
