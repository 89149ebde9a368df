//! `alfd expert list|eval|add|remove` and `alfd train-experts`: the demonstrators of known quality.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use alfd_common::agent::{NetworkDemonstrator, TablePolicy};
use alfd_common::config::{EnvName, ExperimentConfig};
use alfd_common::env::vector_env_named;
use alfd_common::evaluate::{evaluate, evaluate_cartpole, evaluate_cliffwalk};
use alfd_common::record::ReturnStats;
use alfd_common::runner::{run_neural, run_tabular};
use alfd_demonstrators::registry::{self, ExpertEntry};
use anyhow::Context as _;

use crate::usage::usage;
use alfd_lab::output::write;

#[derive(Debug, clap::Args)]
pub struct ExpertArgs {
    #[command(subcommand)]
    pub command: ExpertCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum ExpertCommand {
    /// List the demonstrators with their measured quality.
    List,
    /// Evaluate a demonstrator: prints {"mean":…,"median":…,"std":…} as one JSON line.
    Eval {
        /// Its name (see `alfd expert list`).
        name: String,
        /// Episodes to play (at most 1,000,000).
        #[arg(long, default_value_t = 100)]
        episodes: usize,
        /// Seed of the first reset (and, for DeepSea, of its action mapping).
        #[arg(long, default_value_t = 12345)]
        seed: u64,
        /// DeepSea's N, for its experts (default 10).
        #[arg(long)]
        size: Option<usize>,
    },
    /// Add an expert to a live run's experts (`[[experts]]`, or its one expert): a new expert
    /// process routes among them all and takes over once up, as `alfd swap-expert` does.
    Add {
        /// The run directory of a live run.
        #[arg(long)]
        run: PathBuf,
        /// The expert, by name (`alfd expert list`, or `python:MODULE:FUNCTION`, `sb3:ALGO:PATH`).
        name: String,
        /// What one of its answers costs (> 0).
        #[arg(long, default_value_t = 1.0)]
        cost: f64,
        /// A name for tables and plots (default: its name).
        #[arg(long)]
        label: Option<String>,
        /// Seconds to wait for the change to complete.
        #[arg(long, default_value_t = 90)]
        timeout: u64,
    },
    /// Remove an expert from a live run's experts; the others go on answering.
    Remove {
        /// The run directory of a live run.
        #[arg(long)]
        run: PathBuf,
        /// The expert, by name.
        name: String,
        /// Seconds to wait for the change to complete.
        #[arg(long, default_value_t = 90)]
        timeout: u64,
    },
}

/// The most episodes `alfd expert eval` plays (their returns are kept to compute the median).
const MAX_EVAL_EPISODES: usize = 1_000_000;

pub fn run(args: ExpertArgs) -> anyhow::Result<()> {
    match args.command {
        ExpertCommand::Add {
            run,
            name,
            cost,
            label,
            timeout,
        } => {
            let entry = alfd_common::config::PanelEntry {
                name,
                cost,
                label,
                becomes: None,
                after: None,
            };
            crate::cmd_swap::add(&run, entry, timeout)
        }
        ExpertCommand::Remove { run, name, timeout } => {
            crate::cmd_swap::remove(&run, name, timeout)
        }
        ExpertCommand::List => {
            println!(
                "{:<28} {:<12} {:<16} {:>9} {:>9}",
                "name", "env", "kind", "mean", "median"
            );
            for e in registry::list() {
                let f = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.1}"));
                println!(
                    "{:<28} {:<12} {:<16} {:>9} {:>9}",
                    e.name,
                    e.env,
                    e.kind,
                    f(e.mean),
                    f(e.median)
                );
            }
            println!(
                "\nmean, median: the undiscounted return per episode, measured as `alfd expert eval` \
                 does (manifest.json says how). `alfd env show` gives V*(S) instead, the optimal \
                 discounted value (γ = 0.99) at the start, a different number for the same policy."
            );
            Ok(())
        }
        ExpertCommand::Eval {
            name,
            episodes,
            seed,
            size,
        } => {
            if episodes == 0 {
                return Err(usage("--episodes must be at least 1"));
            }
            if episodes > MAX_EVAL_EPISODES {
                return Err(usage(format!(
                    "--episodes {episodes}: at most {MAX_EVAL_EPISODES} episodes are evaluated"
                )));
            }
            let stats = evaluate_named(&name, episodes, seed, size)?;
            println!("{}", serde_json::to_string(&stats)?);
            Ok(())
        }
    }
}

/// Evaluates a demonstrator by name on its environment with the default step limit
/// (CartPole-1000, the default CliffWalk, MountainCar-v0, Acrobot-v1, DeepSea(`size`) with the
/// action mapping of `seed`).
pub fn evaluate_named(
    name: &str,
    episodes: usize,
    seed: u64,
    size: Option<usize>,
) -> anyhow::Result<ReturnStats> {
    let entry = registry::list().into_iter().find(|e| e.name == name);
    let env = match entry {
        Some(e) => e.env.parse().map_err(anyhow::Error::msg)?,
        // Not listed: the registry's error names the CartPole experts.
        None => EnvName::Cartpole,
    };
    if size.is_some() && env != EnvName::Deepsea {
        return Err(usage(format!(
            "--size: DeepSea's experts take a size; `{name}` demonstrates {env}"
        )));
    }
    let returns = match env {
        EnvName::Cliffwalk => {
            let env = crate::setup::cliffwalk(&cliffwalk_config())?;
            let mut d = registry::cliffwalk(name, &env)?;
            evaluate_cliffwalk(d.as_mut(), &env, episodes, seed)
        }
        EnvName::Deepsea => {
            let mut env = crate::setup::deepsea(&deepsea_config(size, seed)?)?;
            let mut d = registry::deepsea(name, &env)?;
            evaluate(&mut env, episodes, seed, |s| d.act(s))
                .map_err(|e| anyhow::anyhow!("evaluating {name}: {e}"))?
        }
        _ => {
            let mut d = registry::for_env(env, name)?;
            let mut env = vector_env_named(env, env.default_max_episode_steps())
                .expect("every env but cliffwalk has vector observations");
            evaluate(env.as_mut(), episodes, seed, |obs| d.act(obs))
                .map_err(|e| anyhow::anyhow!("evaluating {name}: {e}"))?
        }
    };
    Ok(ReturnStats::of(&returns))
}

/// A DeepSea config of `size` (the config's default without one), its mapping drawn from `seed`.
fn deepsea_config(size: Option<usize>, seed: u64) -> anyhow::Result<ExperimentConfig> {
    let size_line = size.map_or(String::new(), |n| format!("size = {n}\n"));
    let text = format!(
        "seed = {seed}\nepisodes = 1\n[env]\nname = \"deepsea\"\n{size_line}\
         [agent]\nkind = \"qlearning\"\n"
    );
    ExperimentConfig::from_toml(&text).map_err(|e| match size {
        Some(n) => usage(format!("--size {n}: {e}")),
        None => usage(e.to_string()),
    })
}

fn cliffwalk_config() -> ExperimentConfig {
    ExperimentConfig::from_toml(
        "seed = 0\nepisodes = 1\n[env]\nname = \"cliffwalk\"\n[agent]\nkind = \"qlearning\"\n",
    )
    .expect("a valid built-in config")
}

#[derive(Debug, clap::Args)]
pub struct TrainExpertsArgs {
    /// `cartpole` or `cliffwalk`.
    #[arg(long)]
    pub env: String,
    /// Where to write the demonstrators and their manifest entries.
    #[arg(long, default_value = "common/demonstrators/shipped")]
    pub out: PathBuf,
    /// First training seed; further seeds are tried until every level is found.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Give up after this many training runs.
    #[arg(long, default_value_t = 8)]
    pub max_runs: u64,
}

/// CartPole quality levels of the paper (section 5.2).
pub const LEVELS: [f64; 5] = [50.0, 100.0, 200.0, 500.0, 1000.0];
const EVAL_SEED: u64 = 1_000_003;
const VERIFY_SEED: u64 = 2_000_003;

pub fn train(args: TrainExpertsArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    match args.env.as_str() {
        "cartpole" => train_cartpole(&args),
        "cliffwalk" => train_cliffwalk(&args),
        other => Err(usage(format!(
            "unknown env `{other}`: expected cartpole or cliffwalk"
        ))),
    }
}

const DQN_CONFIG: &str = r#"
seed = 0
episodes = 800
[env]
name = "cartpole"
[agent]
kind = "dqn"
[query]
mode = "never"
"#;

/// Trains DQN and saves a checkpoint whenever the greedy policy's mean over 100 evaluation
/// episodes is within ±10% of a level not yet saved, and again within ±10% on 100 other episodes.
fn train_cartpole(args: &TrainExpertsArgs) -> anyhow::Result<()> {
    let mut found: Vec<ExpertEntry> = Vec::new();
    for run in 0..args.max_runs {
        let seed = args.seed + run;
        let cfg =
            ExperimentConfig::from_toml_with_overrides(DQN_CONFIG, &[format!("seed={seed}")])?;
        let mut no_expert = alfd_common::agent::BalancingController;
        run_neural(&cfg, &mut no_expert, |r, net| {
            let missing: Vec<f64> = LEVELS
                .iter()
                .copied()
                .filter(|l| !found.iter().any(|e| e.name == level_name(*l)))
                .collect();
            if missing.is_empty() {
                return ControlFlow::Break(());
            }
            let mut d = NetworkDemonstrator::new(net.clone());
            let stats = ReturnStats::of(&evaluate_cartpole(&mut d, 100, EVAL_SEED, 1000));
            for level in missing {
                if (stats.mean - level).abs() <= 0.1 * level {
                    let verify =
                        ReturnStats::of(&evaluate_cartpole(&mut d, 100, VERIFY_SEED, 1000));
                    if (verify.mean - level).abs() > 0.1 * level {
                        tracing::info!(
                            level,
                            eval = stats.mean,
                            verify = verify.mean,
                            "candidate not verified"
                        );
                        continue;
                    }
                    let file = format!("{}.safetensors", level_name(level));
                    if let Err(e) = write(&args.out, &file, &net.to_safetensors_bytes()) {
                        tracing::error!(error = %e, "cannot save checkpoint");
                        continue;
                    }
                    eprintln!(
                        "saved {file}: seed {seed}, episode {}, mean {:.1}, verified {:.1}",
                        r.episode, stats.mean, verify.mean
                    );
                    found.push(ExpertEntry {
                        name: level_name(level),
                        env: "cartpole".into(),
                        kind: "dqn-checkpoint".into(),
                        file: Some(file),
                        mean: Some(verify.mean),
                        median: Some(verify.median),
                        std: Some(verify.std),
                        evaluation: Some(format!("greedy policy, 100 CartPole-1000 episodes from seed {VERIFY_SEED}")),
                        provenance: Some(format!(
                            "alfd train-experts --env cartpole: DQN seed {seed}, after episode {}; mean {:.1} on 100 episodes from seed {EVAL_SEED}",
                            r.episode, stats.mean
                        )),
                    });
                    break;
                }
            }
            ControlFlow::Continue(())
        });
        if found.len() == LEVELS.len() {
            break;
        }
    }
    let missing: Vec<String> = LEVELS
        .iter()
        .map(|l| level_name(*l))
        .filter(|n| !found.iter().any(|e| &e.name == n))
        .collect();
    update_manifest(&args.out, found)?;
    if !missing.is_empty() {
        anyhow::bail!(
            "no checkpoint reached {} within {} runs",
            missing.join(", "),
            args.max_runs
        );
    }
    Ok(())
}

fn level_name(level: f64) -> String {
    format!("cartpole-{level}")
}

const TABULAR_CONFIG: &str = r#"
seed = 0
episodes = 3000
[env]
name = "cliffwalk"
[agent]
kind = "qlearning"
temperature = 1.0
learning_rate = 1.0
learning_rate_decay = 0.6
[query]
mode = "never"
"#;

/// CliffWalk: greedy policies of Q-learning and SARSA at several stages of training.
fn train_cliffwalk(args: &TrainExpertsArgs) -> anyhow::Result<()> {
    const STAGES: [u32; 4] = [50, 200, 1000, 3000];
    let mut found = Vec::new();
    {
        let env = crate::setup::cliffwalk(&cliffwalk_config())?;
        let mut optimal = registry::cliffwalk("cliffwalk-optimal", &env)?;
        let stats = ReturnStats::of(&evaluate_cliffwalk(optimal.as_mut(), &env, 1000, EVAL_SEED));
        let mut entry = registry::list()
            .into_iter()
            .find(|e| e.name == "cliffwalk-optimal")
            .expect("shipped");
        entry.mean = Some(stats.mean);
        entry.median = Some(stats.median);
        entry.std = Some(stats.std);
        entry.evaluation = Some(format!(
            "1000 episodes on the default map from seed {EVAL_SEED}"
        ));
        eprintln!(
            "cliffwalk-optimal: mean {:.2}, median {:.2}",
            stats.mean, stats.median
        );
        found.push(entry);
    }
    for kind in ["qlearning", "sarsa"] {
        let cfg = ExperimentConfig::from_toml_with_overrides(
            TABULAR_CONFIG,
            &[format!("agent.kind={kind}"), format!("seed={}", args.seed)],
        )?;
        let env = crate::setup::cliffwalk(&cfg)?;
        let mut optimal = registry::cliffwalk("cliffwalk-optimal", &env)?;
        let mut snapshots = Vec::new();
        run_tabular(&cfg, env.clone(), optimal.as_mut(), |r, agent| {
            if STAGES.contains(&(r.episode + 1)) {
                snapshots.push((r.episode + 1, agent.greedy_policy()));
            }
            ControlFlow::Continue(())
        });
        for (episodes, policy) in snapshots {
            let mut table = TablePolicy { actions: policy };
            let stats = ReturnStats::of(&evaluate_cliffwalk(&mut table, &env, 1000, EVAL_SEED));
            let name = format!("cliffwalk-{kind}-{episodes}");
            let file = format!("{name}.json");
            write(&args.out, &file, serde_json::to_string(&table)?.as_bytes())?;
            eprintln!(
                "saved {file}: mean {:.2}, median {:.2}",
                stats.mean, stats.median
            );
            found.push(ExpertEntry {
                name,
                env: "cliffwalk".into(),
                kind: "policy-table".into(),
                file: Some(file),
                mean: Some(stats.mean),
                median: Some(stats.median),
                std: Some(stats.std),
                evaluation: Some(format!("1000 episodes on the default map from seed {EVAL_SEED}")),
                provenance: Some(format!("alfd train-experts --env cliffwalk: greedy policy of {kind} (softmax exploration, seed {}) after {episodes} episodes", args.seed)),
            });
        }
    }
    update_manifest(&args.out, found)
}

/// Adds or replaces entries in `dir/manifest.json`, keeping the others.
fn update_manifest(dir: &Path, entries: Vec<ExpertEntry>) -> anyhow::Result<()> {
    let path = dir.join("manifest.json");
    let mut all: Vec<ExpertEntry> = match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str(&text)
            .with_context(|| format!("{} is not a valid manifest", path.display()))?,
        Err(_) => Vec::new(),
    };
    for e in entries {
        all.retain(|x| x.name != e.name);
        all.push(e);
    }
    write(
        dir,
        "manifest.json",
        (serde_json::to_string_pretty(&all)? + "\n").as_bytes(),
    )?;
    Ok(())
}
