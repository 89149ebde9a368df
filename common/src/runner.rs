//! The single-process runner: one experiment config, Algorithm 1 in one process, deterministic
//! from the config's seed. It builds the pieces and hands them to the one
//! [`environment_loop::run`] with in-memory transports; it returns the episode records (writing
//! them is the caller's business: [`crate::record::episodes_csv`]).

use std::ops::ControlFlow;

use crate::agent::{
    Demonstrator, ExpertCore, NetworkDemonstrator, NeuralActor, NeuralLearner, TabularAgent,
};
use crate::config::ExperimentConfig;
use crate::env::{vector_env, CartPole, CliffWalk, Env, VectorEnv};
use crate::environment_loop::in_process::{LearnerHandle, LocalExpert};
use crate::environment_loop::{self, GenericActor, Schedule};
use crate::nn::Mlp;
use crate::record::EpisodeRecord;
use crate::rng::{derive_seed, seeded};

/// What a tabular run leaves behind.
#[derive(Debug, Clone)]
pub struct TabularRun {
    pub records: Vec<EpisodeRecord>,
    /// The greedy policy learned (mean over heads).
    pub greedy_policy: Vec<usize>,
    pub agent: TabularAgent,
}

/// What a neural run leaves behind.
#[derive(Debug, Clone)]
pub struct NeuralRun {
    pub records: Vec<EpisodeRecord>,
    pub network: Mlp,
    pub expert: ExpertCore,
}

/// The expert's side of a config: budget B, demonstration model, shaping schedule.
pub fn expert_core(cfg: &ExperimentConfig, num_actions: usize) -> ExpertCore {
    ExpertCore::new(
        cfg.budget(),
        cfg.expert.model,
        num_actions,
        cfg.shaping.schedule(),
    )
}

/// The schedule of the single-process run (actor 0, the `env` seed stream).
fn schedule(cfg: &ExperimentConfig) -> Schedule {
    Schedule {
        env_seed: derive_seed(cfg.seed, "env"),
        episodes: cfg.episode_limit(),
        steps: cfg.step_limit(),
        actor_id: 0,
    }
}

/// Runs a tabular experiment (CliffWalk) on `env` with `demonstrator` as the expert.
/// `on_episode` sees each record and the agent as each episode completes (progress, evaluation)
/// and may stop the run early with `ControlFlow::Break`.
pub fn run_tabular(
    cfg: &ExperimentConfig,
    mut env: CliffWalk,
    demonstrator: &mut dyn Demonstrator<usize>,
    mut on_episode: impl FnMut(&EpisodeRecord, &TabularAgent) -> ControlFlow<()>,
) -> TabularRun {
    let mut agent = TabularAgent::new(
        &cfg.agent,
        &cfg.query,
        env.num_states(),
        env.num_actions(),
        seeded(derive_seed(cfg.seed, "agent")),
    );
    let core = expert_core(cfg, env.num_actions());
    let mut expert = LocalExpert::new(core, demonstrator, &cfg.expert.name, false);
    let mut records = Vec::new();
    environment_loop::run(
        &mut env,
        &mut agent,
        &mut expert,
        schedule(cfg),
        |r, agent| {
            records.push(*r);
            Ok(on_episode(r, agent))
        },
    )
    .expect("an in-process tabular run cannot fail");
    TabularRun {
        records,
        greedy_policy: agent.greedy_policy(),
        agent,
    }
}

/// Runs a neural experiment (the config's environment, e.g. CartPole): Algorithm 1 with the
/// actor and the learner in one process, the actor acting on the learner's newest weights at
/// every step. `on_episode` sees each record and the learner's network, and may stop the run
/// early.
///
/// # Panics
/// If the config's environment has no vector observations (a tabular config: a validated
/// [`ExperimentConfig`] never pairs it with a neural agent).
pub fn run_neural(
    cfg: &ExperimentConfig,
    demonstrator: &mut dyn Demonstrator<[f32]>,
    mut on_episode: impl FnMut(&EpisodeRecord, &Mlp) -> ControlFlow<()>,
) -> NeuralRun {
    let mut env = vector_env(&cfg.env).expect("a neural agent runs on a vector environment");
    let (obs_dim, actions) = (env.observation_dim(), env.num_actions());
    let learner = NeuralLearner::new(
        &cfg.agent,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, "learner")),
    );
    let handle = LearnerHandle::new(learner);
    let core = NeuralActor::new(
        &cfg.agent,
        &cfg.query,
        cfg.shaping.kind,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, "actor-0")),
    );
    let mut actor = GenericActor::new(core, handle.adder(), handle.variables());
    let expert_core = expert_core(cfg, actions);
    let mut expert = LocalExpert::new(
        expert_core,
        demonstrator,
        &cfg.expert.name,
        cfg.shaping_enabled(),
    );
    let mut records = Vec::new();
    let mut eval_env = vector_env(&cfg.env).expect("the same environment");
    let eval_seed = derive_seed(cfg.seed, "eval");
    environment_loop::run(
        env.as_mut(),
        &mut actor,
        &mut expert,
        schedule(cfg),
        |r, actor| {
            if cfg.evaluation.due(r.episode) {
                r.eval_return = evaluate_greedy(
                    actor.core.network(),
                    eval_env.as_mut(),
                    cfg.evaluation.episodes,
                    eval_seed,
                );
            }
            records.push(*r);
            Ok(on_episode(r, handle.learner().network()))
        },
    )
    .expect("an in-process neural run cannot fail");
    drop(actor);
    NeuralRun {
        records,
        network: handle.into_inner().network().clone(),
        expert: expert.core,
    }
}

/// Mean return of `episodes` episodes of `env` played greedily by `net` (on the mean of its
/// heads' Q-values), the first reset seeded with `seed`: the `eval_return` of a record.
pub fn evaluate_greedy(net: &Mlp, env: &mut VectorEnv, episodes: u32, seed: u64) -> f64 {
    let mut policy = NetworkDemonstrator::new(net.clone());
    let returns = evaluate(env, episodes as usize, seed, |obs| policy.act(obs));
    returns.iter().sum::<f64>() / returns.len().max(1) as f64
}

/// Returns of `episodes` episodes of `env` played by `act`, the first reset seeded with `seed`.
pub fn evaluate<E: Env + ?Sized>(
    env: &mut E,
    episodes: usize,
    seed: u64,
    mut act: impl FnMut(&E::Observation) -> usize,
) -> Vec<f64> {
    (0..episodes)
        .map(|i| {
            let mut obs = env.reset(if i == 0 { Some(seed) } else { None });
            let mut ret = 0.0;
            loop {
                let step = env.step(act(&obs)).expect("valid action on a live episode");
                ret += step.reward;
                let done = step.done();
                obs = step.observation;
                if done {
                    return ret;
                }
            }
        })
        .collect()
}

/// Returns of `episodes` CartPole episodes (limit `max_steps`) played by `policy`.
pub fn evaluate_cartpole(
    policy: &mut dyn Demonstrator<[f32]>,
    episodes: usize,
    seed: u64,
    max_steps: usize,
) -> Vec<f64> {
    evaluate(&mut CartPole::new(max_steps), episodes, seed, |obs| {
        policy.act(obs)
    })
}

/// Returns of `episodes` CliffWalk episodes played by `policy` on a clone of `env`.
pub fn evaluate_cliffwalk(
    policy: &mut dyn Demonstrator<usize>,
    env: &CliffWalk,
    episodes: usize,
    seed: u64,
) -> Vec<f64> {
    evaluate(&mut env.clone(), episodes, seed, |s| policy.act(s))
}
