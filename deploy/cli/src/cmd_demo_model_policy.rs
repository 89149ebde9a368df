//! `alfd demo-model-policy`: the demonstration model alone, as a policy (paper section 5.1.2),
//! over `--runs` seeds: each run is [`alfd_lab::policy::play`] (the demonstrations, the model
//! fitted on them, one greedy episode).
//!
//! Prints `{"median":…,"mean":…,"std":…,"min":…,"max":…,"returns":[…]}` as one JSON line.

use std::path::PathBuf;

use alfd_common::demo_model::MAX_DEMOS;
use alfd_common::record::ReturnStats;
use alfd_lab::policy::{play, queries_config, DemoSource};

use crate::cmd_demo_model::KindArg;
use crate::setup;
use crate::usage::usage;

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
    alfd_demonstrators::registry::cartpole(&args.expert)?;
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
        .collect::<alfd_lab::Result<Vec<f64>>>()?;
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
