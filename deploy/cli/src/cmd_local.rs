//! `alfd local`: one experiment config in one process; writes `config.toml`, `episodes.csv`,
//! `demos.jsonl`, and the learned policy (weights as safetensors, or a CliffWalk policy table
//! with its value) to the output directory. With `--checkpoint-every N` it also writes
//! `checkpoint.bin` every N episodes, with `episodes.csv` and `demos.jsonl` as they are then, so
//! that `alfd resume` can continue it.

use std::cell::Cell;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::setup::TabularEnvs;
use alfd_common::agent::{DemoRecord, Demonstrator, PriorDemo};
use alfd_common::config::{DemoModelChoice, EnvName, ExperimentConfig};
use alfd_common::env::cliffwalk::{policy_evaluation, value_iteration, CliffWalk};
use alfd_common::query::Oracle;
use alfd_common::record::{episodes_csv, EpisodeRecord, RunSummary};
use alfd_common::runner::{
    run_neural_on, run_tabular_checkpointed, Checkpoints, NeuralEnvs, NeuralRun, RunError, RunState,
};
use anyhow::Context as _;

use crate::checkpoint_file::{self, CheckpointFile};
use crate::setup;
use crate::usage::usage;
use alfd_harness::run_dir;
use alfd_lab::minari::Dataset;
use alfd_lab::output::write;
use alfd_lab::report::{self, Output};
use alfd_lab::transitions;

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
    /// Print no progress and no summary at the end.
    #[arg(long)]
    pub quiet: bool,
    /// Print only the machine-readable line: the run's summary as JSON on stdout (printed also
    /// without this flag when stdout is not a terminal).
    #[arg(long)]
    pub json: bool,
    /// Write `OUT/checkpoint.bin` every N episodes, so that `alfd resume OUT` can continue the
    /// run if it stops.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub checkpoint_every: Option<u32>,
    /// Also write every transition of the run, episode by episode, to `OUT/transitions.jsonl`
    /// (what `alfd demos export` makes a Minari dataset of; `alfd resume` goes on with it).
    /// Neural agents.
    #[arg(long)]
    pub transitions: bool,
    /// Testing: stop (as a crash would, without the final files) after this many episodes.
    #[arg(long, hide = true, value_name = "N")]
    pub stop_after_episodes: Option<u32>,
}

pub fn run(args: LocalArgs) -> anyhow::Result<()> {
    let cfg = setup::load_config(&args.config, &args.set)?;
    // Every input is checked before the directory is claimed.
    let pieces = Pieces::of(&cfg)?;
    if !cfg.experts.is_empty() && !matches!(pieces, Pieces::Tabular { .. }) {
        // Each of several experts known here (and no person, who needs `alfd run`'s page); a
        // Q-table run's experts are built with its pieces.
        setup::check_demonstrator(&cfg)?;
    }
    if !cfg.experts.is_empty() && args.checkpoint_every.is_some() {
        return Err(usage(
            "--checkpoint-every: a run with several experts (`[[experts]]`) cannot be \
             checkpointed; their qualities and costs are not in a checkpoint",
        ));
    }
    if cfg.env.name.is_remote() && args.checkpoint_every.is_some() {
        return Err(usage(
            "--checkpoint-every: a gymnasium environment's state lives in its Python adapter; \
             checkpointing it is not supported",
        ));
    }
    if args.transitions && cfg.env.name == EnvName::Cliffwalk {
        return Err(usage(
            "--transitions: the environments of the neural agents (observations as vectors)",
        ));
    }
    let _lock = run_dir::claim_new(&args.out)?;
    let resumable = Resumable {
        config_toml: cfg.to_toml(),
        every: args.checkpoint_every,
        from: None,
        stop_after: args.stop_after_episodes,
    };
    let output = Output {
        json: args.json,
        quiet: args.quiet,
    };
    let summary = run_pieces(
        &cfg,
        pieces,
        &args.out,
        output.progress(),
        resumable,
        args.transitions,
    )?;
    finish(&cfg, &args.out, summary, output)
}

/// Reports a run in `dir` that ended (its learning curve, the JSON line, the summary: see
/// [`report`]), or says where a stopped run stopped.
pub(crate) fn finish(
    cfg: &ExperimentConfig,
    dir: &Path,
    summary: Option<RunSummary>,
    output: Output,
) -> anyhow::Result<()> {
    match summary {
        Some(summary) => Ok(report::finish_run(cfg, dir, &summary, output)?),
        None => {
            eprintln!("stopped as asked (--stop-after-episodes); continue with `alfd resume`");
            Ok(())
        }
    }
}

/// How a run checkpoints, and where it starts.
pub(crate) struct Resumable {
    /// The text of the run's `config.toml`, which the checkpoint belongs to.
    pub config_toml: String,
    pub every: Option<u32>,
    /// The checkpoint to continue from (`alfd resume`).
    pub from: Option<CheckpointFile>,
    pub stop_after: Option<u32>,
}

impl Resumable {
    fn none(cfg: &ExperimentConfig) -> Self {
        Self {
            config_toml: cfg.to_toml(),
            every: None,
            from: None,
            stop_after: None,
        }
    }

    /// What the run of kind `run` starts from (`pick` finds its state in the checkpoint) and
    /// how often it checkpoints.
    fn checkpoints<'s, S>(
        &'s self,
        pick: impl Fn(&'s RunState) -> Option<&'s S>,
        run: &str,
    ) -> anyhow::Result<Checkpoints<'s, S>> {
        let from = match &self.from {
            None => None,
            Some(f) => Some(pick(&f.state).ok_or_else(|| {
                usage(format!(
                    "the checkpoint is of another kind of run than config.toml's {run} run"
                ))
            })?),
        };
        Ok(Checkpoints {
            from,
            every: self.every,
        })
    }

    /// Writes the checkpoint, then `episodes.csv` and `demos.jsonl` as they are at it.
    fn save(&self, out: &Path, state: RunState) -> anyhow::Result<()> {
        let demos = match &state {
            RunState::Neural(s) => s.expert.demos.as_slice(),
            RunState::Tabular(_) => &[],
        };
        let (csv, jsonl) = (episodes_csv(state.records()), demos_jsonl(demos)?);
        let file = CheckpointFile {
            every: self.every.expect("only a checkpointing run saves"),
            state,
        };
        checkpoint_file::save(out, &file, &self.config_toml)?;
        write(out, "episodes.csv", csv.as_bytes())?;
        write(out, "demos.jsonl", &jsonl)?;
        tracing::debug!(
            episodes = file.state.progress().episodes,
            "checkpoint written"
        );
        Ok(())
    }
}

fn demos_jsonl(demos: &[DemoRecord]) -> anyhow::Result<Vec<u8>> {
    demos_jsonl_with(demos, None)
}

/// With several experts, each line also says what its answer cost and whether its state was
/// asked of two experts (`cost`, `double_asked`).
fn demos_jsonl_with(
    demos: &[DemoRecord],
    panel: Option<&[(f64, bool)]>,
) -> anyhow::Result<Vec<u8>> {
    let mut jsonl = Vec::new();
    for (i, d) in demos.iter().enumerate() {
        let note = panel.and_then(|p| p.get(i)).copied();
        jsonl.extend(alfd_demonstrators::demo_log::line(d, note));
    }
    Ok(jsonl)
}

/// What a run is built from, beyond its config: everything that reads the user's files or names.
pub(crate) enum Pieces {
    Tabular {
        env: TabularEnvs,
        demonstrator: Box<dyn alfd_common::agent::Demonstrator<usize> + Send>,
        /// `[[experts]]`' demonstrators, in order (none: the one expert answers).
        panel: alfd_common::runner::TabularPanel,
        oracle: Option<Oracle<usize>>,
    },
    Neural {
        demonstrator: Box<dyn alfd_common::agent::Demonstrator<[f32]> + Send>,
        /// `demos.prior`'s expert steps.
        prior: Vec<PriorDemo>,
    },
    /// A Gymnasium environment or an external expert (see `local_remote`); `demos.prior`'s
    /// dataset, checked against the environment once its adapter is up.
    Remote { prior: Option<Dataset> },
}

impl Pieces {
    pub(crate) fn of(cfg: &ExperimentConfig) -> anyhow::Result<Self> {
        let prior = read_prior(cfg)?;
        Ok(match cfg.env.name {
            _ if cfg.agent.kind.is_tabular() => {
                let env = TabularEnvs::of(cfg)?;
                Self::Tabular {
                    demonstrator: env.demonstrator(&cfg.expert.name)?,
                    panel: env.panel(cfg)?,
                    oracle: setup::oracle(cfg, || env.demonstrator(&cfg.expert.name))?,
                    env,
                }
            }
            // Python pieces start with the run (their logs go to its directory).
            _ if crate::local_remote::needed(cfg) => {
                setup::check_demonstrator(cfg)?;
                Self::Remote { prior }
            }
            _ => Self::Neural {
                prior: prior_demos(cfg, prior.as_ref(), &builtin_envs(cfg, Vec::new())?)?,
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
    let summary = run_pieces(
        cfg,
        Pieces::of(cfg)?,
        out,
        progress,
        Resumable::none(cfg),
        false,
    )?;
    Ok(summary.expect("a run without --stop-after-episodes ends"))
}

/// Runs `cfg` to its end (`Some` summary) or until `resumable.stop_after` episodes (`None`);
/// with `transitions`, records them (see `--transitions`).
pub(crate) fn run_pieces(
    cfg: &ExperimentConfig,
    pieces: Pieces,
    out: &Path,
    progress: bool,
    resumable: Resumable,
    transitions: bool,
) -> anyhow::Result<Option<RunSummary>> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output directory {}", out.display()))?;
    if resumable.from.is_none() {
        write(out, "config.toml", cfg.to_toml().as_bytes())?;
    }
    let bar = progress_bar(cfg, progress);
    if let (Some(f), Some(_)) = (&resumable.from, cfg.episode_limit()) {
        bar.set_position(u64::from(f.state.progress().episodes));
    }
    let watch = Watch {
        cfg,
        out,
        resumable,
        transitions,
        bar,
        stopped: Cell::new(false),
        save_error: Cell::new(None),
        board: std::cell::RefCell::new(alfd_harness::tensorboard::Board::open(out, "local", cfg)),
    };
    let start = Instant::now();
    let produced = match pieces {
        Pieces::Tabular {
            env: TabularEnvs::CliffWalk(env),
            mut demonstrator,
            panel,
            oracle,
        } => run_tabular(&watch, &env, (demonstrator.as_mut(), panel), oracle)?,
        Pieces::Tabular {
            env: TabularEnvs::DeepSea(env),
            mut demonstrator,
            panel,
            oracle,
        } => run_deepsea(&watch, *env, (demonstrator.as_mut(), panel), oracle)?,
        Pieces::Remote { prior } => run_remote(&watch, prior.as_ref())?,
        Pieces::Neural {
            mut demonstrator,
            prior,
        } => run_neural(&watch, demonstrator.as_mut(), &prior)?,
    };
    let Some(produced) = produced else {
        return Ok(None);
    };
    let wall = start.elapsed().as_secs_f64();
    watch.bar.finish_and_clear();
    write_outputs(out, produced, wall).map(Some)
}

/// What a run that ended leaves for its common output files.
struct Produced {
    records: Vec<EpisodeRecord>,
    demos: Vec<DemoRecord>,
    /// The value of the greedy policy at the start state (tabular runs).
    greedy: Option<f64>,
    /// The optimal value at the start state (tabular runs).
    optimal: Option<f64>,
    /// Environment steps taken, and the learner's updates (neural runs).
    env_steps: u64,
    updates: Option<u64>,
    /// With several experts: each demonstration's cost and whether its state was asked twice.
    costs: Option<Vec<(f64, bool)>>,
}

/// What a run's callbacks share: the progress bar, the checkpoints, and why the run stopped
/// before its end.
struct Watch<'a> {
    cfg: &'a ExperimentConfig,
    out: &'a Path,
    resumable: Resumable,
    /// Record every transition (`--transitions`).
    transitions: bool,
    bar: indicatif::ProgressBar,
    /// Set when the run stops as asked (`--stop-after-episodes`).
    stopped: Cell<bool>,
    /// The checkpoint that could not be written, which stops the run.
    save_error: Cell<Option<anyhow::Error>>,
    /// The run's TensorBoard scalars (`OUT/tb/`).
    board: std::cell::RefCell<alfd_harness::tensorboard::Board>,
}

impl Watch<'_> {
    /// Shows episode `r` on the progress bar; breaks after `resumable.stop_after` episodes.
    fn show(&self, r: &EpisodeRecord) -> ControlFlow<()> {
        let eval = if r.eval_return.is_nan() {
            String::new()
        } else {
            format!("  eval {:.1}", r.eval_return)
        };
        self.bar
            .set_message(format!("return {:.1}{eval}  demos {}", r.ret, r.demos_used));
        self.board.borrow_mut().episode(r);
        match self.cfg.episode_limit() {
            Some(_) => self.bar.inc(1),
            None => self.bar.set_position(r.total_steps),
        }
        if self
            .resumable
            .stop_after
            .is_some_and(|n| r.episode + 1 >= n)
        {
            self.stopped.set(true);
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    }

    /// Writes a checkpoint; breaks (keeping the error) when it cannot be written.
    fn save(&self, state: RunState) -> ControlFlow<()> {
        match self.resumable.save(self.out, state) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                self.save_error.set(Some(e));
                ControlFlow::Break(())
            }
        }
    }

    /// The run's environments, the training one recording its transitions with
    /// `--transitions`.
    fn envs(&self, envs: NeuralEnvs) -> anyhow::Result<NeuralEnvs> {
        if !self.transitions {
            return Ok(envs);
        }
        let env = match &self.resumable.from {
            Some(f) => {
                let p = f.state.progress();
                transitions::Recorder::resume(envs.env, self.out, p.episodes, p.steps)?
            }
            None => transitions::Recorder::create(envs.env, self.out, self.cfg.env.name.as_str())?,
        };
        Ok(NeuralEnvs {
            env: Box::new(env),
            eval_env: envs.eval_env,
            oracle: envs.oracle,
            panel: envs.panel,
        })
    }

    /// See [`interrupted`].
    fn interrupted(&self) -> anyhow::Result<bool> {
        interrupted(self.save_error.take(), self.stopped.get())
    }
}

/// Trains a tabular run on `env` and writes its `policy.json`; `None` when it stopped before
/// its end.
fn train_tabular<E: alfd_common::env::TabularEnv>(
    watch: &Watch<'_>,
    env: E,
    experts: TabularExperts<'_>,
    oracle: Option<Oracle<usize>>,
) -> anyhow::Result<Option<alfd_common::runner::TabularRun>> {
    let checkpoints = watch.resumable.checkpoints(RunState::tabular, "tabular")?;
    let run = run_tabular_checkpointed(
        watch.cfg,
        env,
        experts,
        oracle,
        checkpoints,
        |s| watch.save(RunState::Tabular(Box::new(s.clone()))),
        |r, _| watch.show(r),
    )
    .map_err(|e| usage(format!("cannot resume from the checkpoint: {e}")))?;
    if watch.interrupted()? {
        return Ok(None);
    }
    let table = serde_json::json!({ "actions": run.greedy_policy });
    write(watch.out, "policy.json", table.to_string().as_bytes())?;
    if let Some(panel) = &run.panel {
        write(watch.out, "experts.csv", panel.csv().as_bytes())?;
    }
    Ok(Some(run))
}

/// A tabular run's expert and its `[[experts]]`.
type TabularExperts<'d> = (
    &'d mut dyn Demonstrator<usize>,
    alfd_common::runner::TabularPanel,
);

/// Runs a DeepSea run; `None` when it stopped before its end. Its greedy value is the return
/// of one greedy episode (DeepSea is deterministic).
fn run_deepsea(
    watch: &Watch<'_>,
    env: alfd_common::env::DeepSeaCells,
    experts: TabularExperts<'_>,
    oracle: Option<Oracle<usize>>,
) -> anyhow::Result<Option<Produced>> {
    let mut eval_env = env.clone();
    let optimal = env.0.optimal_return();
    let Some(run) = train_tabular(watch, env, experts, oracle)? else {
        return Ok(None);
    };
    let policy = &run.greedy_policy;
    let greedy = alfd_common::evaluate::evaluate(&mut eval_env, 1, 0, |&s| policy[s])?;
    Ok(Some(Produced {
        env_steps: run.records.last().map_or(0, |r| r.total_steps),
        updates: None,
        records: run.records,
        demos: run.demos,
        greedy: Some(greedy[0]),
        optimal: Some(optimal),
        costs: run.panel.map(|p| p.answers),
    }))
}

/// Runs a CliffWalk run; `None` when it stopped before its end.
fn run_tabular(
    watch: &Watch<'_>,
    env: &CliffWalk,
    experts: TabularExperts<'_>,
    oracle: Option<Oracle<usize>>,
) -> anyhow::Result<Option<Produced>> {
    let gamma = watch.cfg.agent.gamma;
    let Some(run) = train_tabular(watch, env.clone(), experts, oracle)? else {
        return Ok(None);
    };
    let vi = value_iteration(env, gamma, 1e-10)?;
    let greedy = policy_evaluation(env, &run.greedy_policy, gamma)?;
    let s0 = env.map().start();
    Ok(Some(Produced {
        env_steps: run.records.last().map_or(0, |r| r.total_steps),
        updates: None,
        records: run.records,
        demos: run.demos,
        greedy: Some(greedy[s0]),
        optimal: Some(vi.values[s0]),
        costs: run.panel.map(|p| p.answers),
    }))
}

/// Runs a neural run whose environment or expert lives in Python pieces that it starts (see
/// `local_remote`), and writes its weights; `None` when it stopped before its end.
fn run_remote(watch: &Watch<'_>, prior: Option<&Dataset>) -> anyhow::Result<Option<Produced>> {
    let cfg = watch.cfg;
    let started = crate::local_remote::start(cfg, watch.out)?;
    let (_adapters, mut demonstrator) = (started.guard, started.demonstrator);
    let envs = match started.envs {
        Some(envs) => NeuralEnvs {
            panel: started.panel,
            ..envs
        },
        None => builtin_envs(cfg, started.panel)?,
    };
    let prior = prior_demos(cfg, prior, &envs)?;
    let checkpoints = watch.resumable.checkpoints(RunState::neural, "neural")?;
    let run = run_neural_on(
        cfg,
        watch.envs(envs)?,
        demonstrator.as_mut(),
        &prior,
        checkpoints,
        |s| watch.save(RunState::Neural(Box::new(s.clone()))),
        |r, _| watch.show(r),
    )
    .map_err(|e| match e {
        RunError::Mismatch(e) => usage(format!("cannot resume from the checkpoint: {e}")),
        RunError::Loop(e) => anyhow::Error::new(e).context("the run failed"),
        RunError::Prior(e) => usage(e.to_string()),
        RunError::NoOracle => usage(RunError::NoOracle.to_string()),
    })?;
    if watch.interrupted()? {
        return Ok(None);
    }
    neural_outputs(watch.out, run).map(Some)
}

/// Runs a neural run in this process and writes its weights; `None` when it stopped before
/// its end.
fn run_neural(
    watch: &Watch<'_>,
    demonstrator: &mut dyn Demonstrator<[f32]>,
    prior: &[PriorDemo],
) -> anyhow::Result<Option<Produced>> {
    let envs = builtin_envs(watch.cfg, setup::panel(watch.cfg)?)?;
    let checkpoints = watch.resumable.checkpoints(RunState::neural, "neural")?;
    let run = run_neural_on(
        watch.cfg,
        watch.envs(envs)?,
        demonstrator,
        prior,
        checkpoints,
        |s| watch.save(RunState::Neural(Box::new(s.clone()))),
        |r, _| watch.show(r),
    )
    .map_err(|e| match e {
        RunError::Mismatch(e) => usage(format!("cannot resume from the checkpoint: {e}")),
        RunError::Prior(e) => usage(e.to_string()),
        RunError::NoOracle => usage(RunError::NoOracle.to_string()),
        RunError::Loop(e) => unreachable!("an in-process neural run cannot fail: {e}"),
    })?;
    if watch.interrupted()? {
        return Ok(None);
    }
    neural_outputs(watch.out, run).map(Some)
}

/// The config's built-in environment, to train on and to evaluate on, with the demonstrators of
/// `[[experts]]` in `panel`.
fn builtin_envs(
    cfg: &ExperimentConfig,
    panel: Vec<Box<dyn alfd_common::agent::Demonstrator<[f32]>>>,
) -> anyhow::Result<NeuralEnvs> {
    let env = || alfd_common::env::vector_env(cfg).context("a vector environment");
    Ok(NeuralEnvs {
        env: env()?,
        eval_env: env()?,
        oracle: setup::oracle(cfg, || setup::neural_demonstrator(cfg))?,
        panel,
    })
}

/// The prior demonstrations of `demos.prior` for the run's environment (none without one).
fn prior_demos(
    cfg: &ExperimentConfig,
    prior: Option<&Dataset>,
    envs: &NeuralEnvs,
) -> anyhow::Result<Vec<PriorDemo>> {
    let (dim, actions) = (envs.env.observation_dim(), envs.env.num_actions());
    prior_steps(cfg, prior, dim, actions)
}

/// The expert steps of `prior` for an environment of `obs_dim` values and `num_actions` actions,
/// refused when the config's demonstration model cannot take them with budget B.
pub(crate) fn prior_steps(
    cfg: &ExperimentConfig,
    prior: Option<&Dataset>,
    obs_dim: usize,
    num_actions: usize,
) -> anyhow::Result<Vec<PriorDemo>> {
    let Some(ds) = prior else {
        return Ok(Vec::new());
    };
    let steps = transitions::prior_demos(ds, obs_dim, num_actions)?;
    let max = cfg.max_model_demos();
    if cfg.expert.model != DemoModelChoice::None && steps.len() + cfg.budget() as usize > max {
        return Err(usage(format!(
            "demos.prior: {} demonstrations of dataset {} and a budget of {} are more than \
             the demonstration model (`expert.model`) takes, {max} (`nystrom` takes up to \
             1,000,000)",
            steps.len(),
            ds.id,
            cfg.budget()
        )));
    }
    Ok(steps)
}

/// The dataset `demos.prior` names, read and checked (`None` without one); refused for a
/// tabular run.
pub(crate) fn read_prior(cfg: &ExperimentConfig) -> anyhow::Result<Option<Dataset>> {
    let Some(dir) = &cfg.demos.prior else {
        return Ok(None);
    };
    if cfg.env.name == EnvName::Cliffwalk {
        return Err(usage(
            "demos.prior: prior demonstrations are for the neural agents' environments",
        ));
    }
    let ds = alfd_lab::minari::read(Path::new(dir))
        .map_err(|e| usage(format!("demos.prior: {}", alfd_harness::describe(&e))))?;
    tracing::info!(
        dataset = %ds.id, episodes = ds.episodes.len(), steps = ds.total_steps(),
        "prior demonstrations read"
    );
    Ok(Some(ds))
}

/// Writes a neural run's `weights.safetensors`.
fn neural_outputs(out: &Path, run: NeuralRun) -> anyhow::Result<Produced> {
    write(
        out,
        "weights.safetensors",
        &run.network.to_safetensors_bytes(),
    )?;
    if let Some(panel) = &run.panel {
        write(out, "experts.csv", panel.csv().as_bytes())?;
    }
    Ok(Produced {
        records: run.records,
        demos: run.expert.demos().to_vec(),
        greedy: None,
        optimal: None,
        env_steps: run.env_steps,
        updates: Some(run.updates),
        costs: run.panel.map(|p| p.answers),
    })
}

/// Writes `episodes.csv`, `demos.jsonl` and `summary.json` of a run that ended after `wall`
/// seconds.
fn write_outputs(out: &Path, produced: Produced, wall: f64) -> anyhow::Result<RunSummary> {
    let Produced {
        records,
        demos,
        greedy,
        optimal,
        env_steps,
        updates,
        costs,
    } = produced;
    write(out, "episodes.csv", episodes_csv(&records).as_bytes())?;
    write(
        out,
        "demos.jsonl",
        &demos_jsonl_with(&demos, costs.as_deref())?,
    )?;
    let summary = RunSummary {
        greedy_value_at_start: greedy,
        optimal_value_at_start: optimal,
        env_steps: Some(env_steps),
        updates,
        ..RunSummary::of(&records, wall)
    };
    write(
        out,
        "summary.json",
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    Ok(summary)
}

/// Whether the run stopped as asked (`--stop-after-episodes`); a checkpoint that could not be
/// written is the run's error.
fn interrupted(save_error: Option<anyhow::Error>, stopped: bool) -> anyhow::Result<bool> {
    match save_error {
        Some(e) => Err(e),
        None => Ok(stopped),
    }
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
