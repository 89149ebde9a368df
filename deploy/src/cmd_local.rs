//! `alfd local`: one experiment config in one process; writes `config.toml`, `episodes.csv`,
//! `demos.jsonl`, and the learned policy (weights as safetensors, or a CliffWalk policy table
//! with its value) to the output directory.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use alfd_common::config::{EnvName, ExperimentConfig};
use alfd_common::env::cliffwalk::{policy_evaluation, value_iteration};
use alfd_common::record::{episodes_csv, EpisodeRecord, RunSummary};
use alfd_common::runner::{run_neural, run_tabular};
use anyhow::Context as _;

use crate::{run_dir, setup};

#[derive(Debug, clap::Args)]
pub struct LocalArgs {
    /// The experiment config (TOML).
    #[arg(long)]
    pub config: PathBuf,
    /// Override a config value, e.g. `--set agent.heads=3` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Output directory (created if missing); it must not hold a run already.
    #[arg(long)]
    pub out: PathBuf,
    /// Print no progress.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(args: LocalArgs) -> anyhow::Result<()> {
    let cfg = setup::load_config(&args.config, &args.set)?;
    // Every input is checked before the directory is claimed.
    let pieces = Pieces::of(&cfg)?;
    let _lock = run_dir::claim_new(&args.out)?;
    let summary = run_pieces(&cfg, pieces, &args.out, !args.quiet)?;
    println!("{}", serde_json::to_string(&summary)?);
    Ok(())
}

/// What a run is built from, beyond its config: everything that reads the user's files or names.
enum Pieces {
    Tabular {
        env: Box<alfd_common::env::cliffwalk::CliffWalk>,
        demonstrator: Box<dyn alfd_common::agent::Demonstrator<usize> + Send>,
    },
    Neural {
        demonstrator: Box<dyn alfd_common::agent::Demonstrator<[f32]> + Send>,
    },
}

impl Pieces {
    fn of(cfg: &ExperimentConfig) -> anyhow::Result<Self> {
        Ok(match cfg.env.name {
            EnvName::Cliffwalk => {
                let env = setup::cliffwalk(cfg)?;
                let demonstrator = alfd_expert::registry::cliffwalk(&cfg.expert.name, &env)?;
                Self::Tabular {
                    env: Box::new(env),
                    demonstrator,
                }
            }
            _ => Self::Neural {
                demonstrator: setup::neural_demonstrator(cfg)?,
            },
        })
    }
}

/// Runs `cfg` in this process and writes its outputs to `out` (`alfd sweep`, which owns `out`).
pub fn run_config(
    cfg: &ExperimentConfig,
    out: &Path,
    progress: bool,
) -> anyhow::Result<RunSummary> {
    run_pieces(cfg, Pieces::of(cfg)?, out, progress)
}

fn run_pieces(
    cfg: &ExperimentConfig,
    pieces: Pieces,
    out: &Path,
    progress: bool,
) -> anyhow::Result<RunSummary> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output directory {}", out.display()))?;
    write(out, "config.toml", cfg.to_toml().as_bytes())?;
    let bar = progress_bar(cfg, progress);
    let show = |r: &EpisodeRecord| {
        let eval = if r.eval_return.is_nan() {
            String::new()
        } else {
            format!("  eval {:.1}", r.eval_return)
        };
        bar.set_message(format!("return {:.1}{eval}  demos {}", r.ret, r.demos_used));
        match cfg.episode_limit() {
            Some(_) => bar.inc(1),
            None => bar.set_position(r.total_steps),
        }
        ControlFlow::Continue(())
    };
    let start = Instant::now();
    let (records, demos, greedy, optimal) = match pieces {
        Pieces::Tabular {
            env,
            mut demonstrator,
        } => {
            let run = run_tabular(cfg, (*env).clone(), demonstrator.as_mut(), |r, _| show(r));
            let vi = value_iteration(&env, cfg.agent.gamma, 1e-10)?;
            let greedy = policy_evaluation(&env, &run.greedy_policy, cfg.agent.gamma)?;
            let s0 = env.map().start();
            let table = serde_json::json!({ "actions": run.greedy_policy });
            write(out, "policy.json", table.to_string().as_bytes())?;
            (
                run.records,
                Vec::new(),
                Some(greedy[s0]),
                Some(vi.values[s0]),
            )
        }
        Pieces::Neural { mut demonstrator } => {
            let run = run_neural(cfg, demonstrator.as_mut(), |r, _| show(r));
            write(
                out,
                "weights.safetensors",
                &run.network.to_safetensors_bytes(),
            )?;
            (run.records, run.expert.demos().to_vec(), None, None)
        }
    };
    let wall = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    write(out, "episodes.csv", episodes_csv(&records).as_bytes())?;
    let mut jsonl = Vec::new();
    for d in &demos {
        serde_json::to_writer(&mut jsonl, d)?;
        jsonl.push(b'\n');
    }
    write(out, "demos.jsonl", &jsonl)?;
    let summary = RunSummary {
        greedy_value_at_start: greedy,
        optimal_value_at_start: optimal,
        ..RunSummary::of(&records, wall)
    };
    write(
        out,
        "summary.json",
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    Ok(summary)
}

fn progress_bar(cfg: &ExperimentConfig, show: bool) -> indicatif::ProgressBar {
    if !show {
        return indicatif::ProgressBar::hidden();
    }
    let (len, unit) = match cfg.episode_limit() {
        Some(n) => (u64::from(n), "episodes"),
        None => (cfg.steps, "steps"),
    };
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{elapsed_precise}} [{{bar:30}}] {{pos}}/{{len}} {unit}  {{msg}}  (eta {{eta}})"
        ))
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar
}

/// Writes `dir/name` whole (see [`alfd_harness::write_atomically`]).
pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    alfd_harness::write_atomically(&dir.join(name), bytes)
}
