//! `alfd demo-model-policy`: the demonstration model alone, as a policy (paper section 5.1.2: "over
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
//! Prints `{"median":…,"mean":…,"std":…,"min":…,"max":…,"returns":[…]}` as one JSON line.

use std::ops::ControlFlow;
use std::path::PathBuf;

use alfd_common::config::{EnvName, ExperimentConfig};
use alfd_common::demo_model::{DemoModel, DemoModelKind, MAX_DEMOS};
use alfd_common::env::{CartPole, Env};
use alfd_common::policy::argmax;
use alfd_common::record::ReturnStats;
use alfd_common::rng::derive_seed;
use alfd_common::runner::run_neural;
use anyhow::Context as _;

use crate::cmd_demo_model::KindArg;
use crate::setup;
use crate::usage::usage;

/// The paper's CartPole episode limit.
const MAX_STEPS: usize = 1000;

/// Arguments of `alfd demo-model-policy`.
#[derive(Debug, Clone, clap::Args)]
pub struct DemoModelPolicyArgs {
    /// The demonstrator (`alfd expert list`; CartPole only).
    #[arg(long, default_value = "cartpole-1000")]
    pub expert: String,
    /// Demonstrations the model is fitted on.
    #[arg(long, default_value_t = 100)]
    pub demos: usize,
    /// Runs (each with its own demonstrations, model and evaluation episode).
    #[arg(long, default_value_t = 50)]
    pub runs: u64,
    /// The demonstration model.
    #[arg(long, value_enum, default_value = "krr")]
    pub model: KindArg,
    /// Seed of the first run; run i uses seed + i.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Take the demonstrations a training run with this config asks for (its seed, budget and
    /// expert set by this command), instead of the expert's own trajectory.
    #[arg(long)]
    pub queries_config: Option<PathBuf>,
}

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
) -> anyhow::Result<ExperimentConfig> {
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

pub fn run(args: DemoModelPolicyArgs) -> anyhow::Result<()> {
    if args.runs == 0 {
        return Err(usage("--runs must be at least 1"));
    }
    if args.demos == 0 {
        return Err(usage("--demos must be at least 1"));
    }
    if args.demos > MAX_DEMOS {
        return Err(usage(format!(
            "--demos {}: a demonstration model is fitted on at most {MAX_DEMOS} demonstrations",
            args.demos
        )));
    }
    if args.seed.checked_add(args.runs - 1).is_none() {
        return Err(usage(format!(
            "--seed {} --runs {}: the last run's seed would be beyond {}",
            args.seed,
            args.runs,
            u64::MAX
        )));
    }
    alfd_expert::registry::cartpole(&args.expert)?;
    let source = match &args.queries_config {
        None => DemoSource::ExpertTrajectory,
        Some(path) => {
            let cfg = setup::load_config(path, &[])?;
            queries_config(&cfg, &args.expert, args.demos, 0)?;
            DemoSource::Queries(Box::new(cfg))
        }
    };
    let returns = (0..args.runs)
        .map(|i| args.seed + i)
        .map(|s| play(&args.expert, args.demos, args.model.into(), s, &source).map(|r| r.ret))
        .collect::<anyhow::Result<Vec<f64>>>()?;
    let stats = ReturnStats::of(&returns);
    let line = serde_json::json!({
        "median": stats.median,
        "mean": stats.mean,
        "std": stats.std,
        "min": returns.iter().copied().fold(f64::INFINITY, f64::min),
        "max": returns.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        "returns": returns,
    });
    println!("{line}");
    Ok(())
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
) -> anyhow::Result<PolicyRun> {
    let mut demonstrator = alfd_expert::registry::cartpole(expert)?;
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
