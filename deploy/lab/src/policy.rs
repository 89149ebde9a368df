//! The demonstration model alone, as a policy (paper section 5.1.2: "over
//! 50 runs and seeing 100 demonstrated transitions from an agent that performs a 1000 score on
//! average, it obtains a median score of 180 when evaluated as a policy on its own").
//!
//! One run with seed `s`:
//! 1. the demonstrations, from one of two sources ([`DemoSource`]):
//!    - the expert's own trajectory: it plays CartPole from a reset seeded by
//!      `derive_seed(s, "demos")`, and the first `demos` (state, expert action) pairs it visits are
//!      the demonstrations (should the episode end first, the environment is reset, unseeded, and
//!      the expert goes on);
//!    - or the queries of a training run (`--queries-config`, e.g. BDQN+KRR with active queries)
//!      with seed `s`, budget `demos` and this expert, stopped once its budget is spent: the states
//!      the learner asked about, as in the paper's algorithm;
//! 2. the model (KRR by default) is fitted on them;
//! 3. the model plays one episode greedily on its p(a|s) (`argmax`, ties to action 0) from a reset
//!    seeded by `derive_seed(s, "eval")`, with the paper's limit of 1000 steps.
//!

use std::ops::ControlFlow;

use alfd_common::config::{EnvName, ExperimentConfig};
use alfd_common::demo_model::{DemoModel, DemoModelKind};
use alfd_common::env::{CartPole, Env};
use alfd_common::policy::argmax;
use alfd_common::rng::derive_seed;
use alfd_common::runner::run_neural;

use crate::error::{usage, Context as _, Result};

/// The paper's CartPole episode limit.
const MAX_STEPS: usize = 1000;

/// Where the demonstrations of a run come from.
#[derive(Debug, Clone)]
pub enum DemoSource {
    /// The states the expert visits itself.
    ExpertTrajectory,
    /// The states a training run with this config queries (seed, budget and expert are set per
    /// run by [`queries_config`]).
    Queries(Box<ExperimentConfig>),
}

/// The config of the training run whose queries give the demonstrations of run `seed`.
pub fn queries_config(
    base: &ExperimentConfig,
    expert: &str,
    demos: usize,
    seed: u64,
) -> Result<ExperimentConfig> {
    if base.env.name != EnvName::Cartpole {
        return Err(usage("the queries config must be a cartpole config"));
    }
    let mut cfg = base.clone();
    cfg.seed = seed;
    cfg.budget.total = demos as i64;
    cfg.expert.name = expert.to_owned();
    cfg.validate()?;
    Ok(cfg)
}

/// One evaluation of the model as a policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolicyRun {
    pub seed: u64,
    /// The return of the model's greedy episode.
    pub ret: f64,
    pub length: u32,
    /// Demonstrations the model was fitted on (fewer than asked if a training run ended first).
    pub demos: usize,
}

/// One run (see the module docs): collect `demos` demonstrations of `expert`, fit `model`, play.
pub fn play(
    expert: &str,
    demos: usize,
    model: DemoModelKind,
    seed: u64,
    source: &DemoSource,
) -> Result<PolicyRun> {
    let mut demonstrator = alfd_demonstrators::registry::cartpole(expert)?;
    let mut env = CartPole::new(MAX_STEPS);
    let mut states = Vec::with_capacity(demos);
    let mut actions = Vec::with_capacity(demos);
    match source {
        DemoSource::ExpertTrajectory => {
            let mut obs = env.reset(Some(derive_seed(seed, "demos")));
            while states.len() < demos {
                let a = demonstrator.act(&obs);
                states.push(obs.iter().map(|&v| f64::from(v)).collect::<Vec<f64>>());
                actions.push(a);
                let step = env
                    .step(a)
                    .context("the expert stepped a finished episode")?;
                obs = if step.done() {
                    env.reset(None)
                } else {
                    step.observation
                };
            }
        }
        DemoSource::Queries(base) => {
            let cfg = queries_config(base, expert, demos, seed)?;
            let run = run_neural(&cfg, demonstrator.as_mut(), |r, _| {
                if r.demos_used as usize >= demos {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            });
            for d in run.expert.demos() {
                states.push(d.state.clone());
                actions.push(d.action);
            }
        }
    }
    let fitted =
        DemoModel::fit(model, &states, &actions, env.num_actions()).with_context(|| {
            format!(
                "fitting the {model} model on {} demonstrations",
                states.len()
            )
        })?;
    let mut obs = env.reset(Some(derive_seed(seed, "eval")));
    let (mut ret, mut length) = (0.0, 0u32);
    loop {
        let s: Vec<f64> = obs.iter().map(|&v| f64::from(v)).collect();
        let step = env
            .step(argmax(&fitted.probs(&s)))
            .context("the model stepped a finished episode")?;
        ret += step.reward;
        length += 1;
        obs = step.observation;
        if step.done() {
            return Ok(PolicyRun {
                seed,
                ret,
                length,
                demos: states.len(),
            });
        }
    }
}
