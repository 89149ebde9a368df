//! `alfd q-range`: the Q-values a run's learned network takes on its own greedy episodes, against
//! the range every true value lies in — a check for divergence (EXPERIMENTS.md, the CartPole Q-value
//! divergence: a CartPole-1000 network whose Q-values reached 40,000 where no return exceeds 200 had learned to
//! seek failure).
//!
//! Reads each run directory's `config.toml` (the environment, its step limit and γ) and
//! `weights.safetensors`, plays `--episodes` greedy episodes in the native environment and prints
//! one line per run. A run directory that is not a neural run of CartPole, MountainCar or Acrobot
//! is refused with exit code 2, naming what is missing.

use std::path::PathBuf;

use alfd_lab::q_values::{check, EPISODES, SEED};

use crate::usage::usage;

#[derive(Debug, clap::Args)]
pub struct QRangeArgs {
    /// Run directories (as `alfd local`, `alfd run` and `alfd sweep` write them).
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Greedy episodes per run.
    #[arg(long, default_value_t = EPISODES)]
    pub episodes: u32,
    /// Seed of the first episode's reset.
    #[arg(long, default_value_t = SEED)]
    pub seed: u64,
}

pub fn run(args: QRangeArgs) -> anyhow::Result<()> {
    if args.episodes == 0 {
        return Err(usage("--episodes must be at least 1"));
    }
    let mut diverged = 0;
    println!("run\tmin Q\tmax Q\tgreedy return\ttrue values in\tverdict");
    for dir in &args.runs {
        let c = check(dir, args.episodes, args.seed)?;
        diverged += usize::from(c.diverged);
        println!(
            "{}\t{:.1}\t{:.1}\t{:.1}\t[{:.0}, {:.0}]\t{}",
            dir.display(),
            c.range.min,
            c.range.max,
            c.range.mean_return,
            c.bounds.0,
            c.bounds.1,
            if c.diverged { "DIVERGED" } else { "ok" }
        );
    }
    println!(
        "{diverged} of {} diverged (Q-values beyond the true range by more than a quarter of its width)",
        args.runs.len()
    );
    Ok(())
}
