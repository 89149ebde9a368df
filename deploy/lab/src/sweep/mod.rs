//! `alfd sweep`: runs every method of an experiment file over many seeds in the single-process
//! mode, several runs at a time, and writes the learning curves (`curves.csv`), a plot (SVG, and
//! PNG when a font is available) and a summary table (`summary.md`).
//!
//! Layout of the output directory `DIR`:
//! - `DIR/runs/METHOD/SEED/`: each run's outputs, as `alfd local` writes them (`config.toml`,
//!   `episodes.csv`, `demos.jsonl`, weights or policy, and `summary.json`, written last);
//! - `DIR/curves.csv`: `method,X,mean,std,median,count,ci_low,ci_high` of the return across
//!   seeds, X being `episode` or `steps` (the experiment's `x`), `ci_*` the 95% bootstrap
//!   interval of the mean;
//! - `DIR/EXPERIMENT.svg`, `DIR/EXPERIMENT.png`: the mean and its 95% interval per method;
//! - `DIR/summary.md`: per method, with 95% bootstrap intervals over the seeds: the final return
//!   (mean and interquartile mean), the area under the curve, the first x at which the mean
//!   return reaches each threshold, the final greedy-evaluation return when the runs record one;
//!   then the mean over the last episodes, the demonstrations used and the wall-clock time.
//!
//! The statistics are in `stats.rs` (point estimates), `stats/bootstrap.rs` (intervals) and
//! `summary.rs` (from runs to tables).
//!
//! Runs are deterministic, so a sweep re-run gives the same numbers. A run whose `summary.json`
//! exists is complete and is not redone: an interrupted sweep resumes where it stopped (an
//! unfinished run is run again in its directory, under the directory's lock, so a second sweep of
//! the same `--out` cannot run it at the same time). A complete run of a different config (say,
//! other episodes) is refused rather than mixed in.
//!
//! `--shard I/N` runs only a share of the runs and `--collect DIR...` merges the shards into the
//! usual outputs (`shard.rs`), so that a cluster's scheduler can spread a sweep over machines.

mod budget;
mod experiment;
pub(crate) mod plot;
mod runs;
pub mod scaling;
mod shard;
mod stats;
mod summary;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use crate::error::Context as _;
use alfd_common::config::{ExperimentConfig, RuleKind};
use alfd_common::record::ReturnStats;

use crate::error::usage;
use crate::output::{png_from_svg, write};
use crate::policy::{self, PolicyRun};
use crate::report::{Output, SweepReport};
use crate::{LabError, Trainer};
use alfd_common::record::RunSummary;
use experiment::{Experiment, ExperimentKind, Method, MethodSpec};

#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// The experiment file (TOML; see `deploy/experiments/`). Method configs are found relative
    /// to its directory.
    #[arg(long)]
    pub config: PathBuf,
    /// Number of seeds (runs use seeds 0..N, or F..F+N with --first-seed F); overrides the
    /// experiment file's `seeds`.
    #[arg(long)]
    pub seeds: Option<u64>,
    /// The first seed (default 0): `--first-seed 1000 --seeds 20` runs seeds 1000-1019, the
    /// tuning seeds of EXPERIMENTS.md, so that settings are chosen on other seeds than the
    /// reported 0..N.
    #[arg(long)]
    pub first_seed: Option<u64>,
    /// Runs at a time (default: the number of cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output directory (created if missing; complete runs in it are kept).
    #[arg(long)]
    pub out: PathBuf,
    /// Training episodes of every run; overrides the experiment file's and the configs'.
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Print no progress bar and no summary at the end.
    #[arg(long)]
    pub quiet: bool,
    /// Print only a machine-readable line: the sweep's numbers and files as JSON on stdout.
    /// (Without it, a stdout that is not a terminal gets the one-line summary.)
    #[arg(long)]
    pub json: bool,
    /// Run only shard I of N (1-based) of a training sweep: the runs whose index k in the fixed
    /// method-major order (method, then seed) has k % N == I - 1. Writes the runs and
    /// `shard.json`, no curves or summary; merge the shards with `--collect`.
    #[arg(long, value_name = "I/N", conflicts_with = "collect")]
    pub shard: Option<String>,
    /// Merge the output directories of every shard (`--shard I/N`, same experiment, seeds and
    /// episodes) into --out, and write the curves, plot and summary as the unsharded sweep does.
    #[arg(long, value_name = "DIR", num_args = 1..)]
    pub collect: Vec<PathBuf>,
}

/// What a sweep does: all of its runs, one shard of them, or the merge of the shards.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Whole,
    Shard(shard::Shard),
    Collect,
}

/// The most runs a sweep runs at a time.
const MAX_JOBS: usize = 256;

/// Runs the sweep `args` name, its training runs by `trainer`.
pub fn run(args: SweepArgs, trainer: &dyn Trainer) -> crate::Result<()> {
    let mode = match &args.shard {
        Some(s) => Mode::Shard(shard::Shard::parse(s)?),
        None if !args.collect.is_empty() => Mode::Collect,
        None => Mode::Whole,
    };
    let mut exp = Experiment::load(&args.config, args.seeds, args.episodes, trainer)?;
    if let Some(first) = args.first_seed {
        exp = exp.with_first_seed(first)?;
    }
    if mode != Mode::Whole && exp.kind != ExperimentKind::Training {
        return Err(usage(format!(
            "--shard and --collect split training sweeps; {} is a {:?} experiment (it runs no \
             run directories)",
            args.config.display(),
            exp.kind
        )));
    }
    let jobs = jobs(args.jobs)?;
    // A collect creates its output directory itself, once every shard has been checked: a
    // refused one leaves nothing behind.
    if !matches!(mode, Mode::Collect) {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create output directory {}", args.out.display()))?;
    }
    let command = command_line(&args, &exp, jobs, mode)?;
    match mode {
        Mode::Whole => {}
        Mode::Shard(s) => shard::begin(&exp, s, &args.out)?,
        Mode::Collect => shard::collect(&exp, &args.collect, &args.out)?,
    }
    let output = Output {
        json: args.json,
        quiet: args.quiet,
    };
    let ctx = Ctx {
        exp: &exp,
        trainer,
        out: &args.out,
        jobs,
        mode,
        progress: output.progress(),
        output,
        command,
        start: Instant::now(),
    };
    match exp.kind {
        ExperimentKind::Training => run_training(&ctx),
        ExperimentKind::DemoModelPolicy => run_policy(&ctx),
    }
}

/// `--jobs`, checked: runs at a time (by default one per core).
fn jobs(asked: Option<usize>) -> crate::Result<usize> {
    match asked {
        Some(0) => Err(usage("--jobs must be at least 1")),
        Some(j) if j > MAX_JOBS => Err(usage(format!(
            "--jobs {j}: at most {MAX_JOBS} runs at a time (one thread each)"
        ))),
        Some(j) => Ok(j),
        None => Ok(std::thread::available_parallelism().map_or(1, usize::from)),
    }
}

/// The command that makes this sweep's output, as its files record it.
fn command_line(
    args: &SweepArgs,
    exp: &Experiment,
    jobs: usize,
    mode: Mode,
) -> crate::Result<String> {
    let mut command = format!(
        "alfd sweep --config {} --seeds {} --jobs {jobs}",
        args.config.display(),
        exp.seeds
    );
    if exp.first_seed != 0 {
        write!(command, " --first-seed {}", exp.first_seed)?;
    }
    if let Some(e) = args.episodes {
        write!(command, " --episodes {e}")?;
    }
    match mode {
        Mode::Whole => {}
        Mode::Shard(s) => write!(command, " --shard {s}")?,
        Mode::Collect => {
            command.push_str(" --collect");
            for d in &args.collect {
                write!(command, " {}", d.display())?;
            }
        }
    }
    write!(command, " --out {}", args.out.display())?;
    Ok(command)
}

struct Ctx<'a> {
    exp: &'a Experiment,
    trainer: &'a dyn Trainer,
    out: &'a Path,
    jobs: usize,
    mode: Mode,
    progress: bool,
    output: Output,
    command: String,
    start: Instant,
}

/// One run of a training sweep.
struct Job<'a> {
    method: &'a Method,
    seed: u64,
    dir: PathBuf,
    cfg: ExperimentConfig,
}

fn run_training(ctx: &Ctx) -> crate::Result<()> {
    let exp = ctx.exp;
    let Planned {
        pending,
        resumed,
        total,
    } = plan_training(ctx)?;
    if ctx.mode == Mode::Collect && !pending.is_empty() {
        crate::error::bail!(
            "--collect: {} runs are still missing in {} after copying the shards'",
            pending.len(),
            ctx.out.display()
        );
    }
    tracing::info!(total, resumed, jobs = ctx.jobs, "sweep {}", exp.name);
    // Runs that replay another run's query steps (rule `random`) go after every other run.
    let (replays, first): (Vec<Job>, Vec<Job>) = pending
        .into_iter()
        .partition(|j| j.cfg.query.rule == RuleKind::Random);
    run_jobs(ctx.trainer, &first, ctx.jobs, total, resumed, ctx.progress)?;
    let done = resumed + first.len() as u64;
    run_jobs(ctx.trainer, &replays, ctx.jobs, total, done, ctx.progress)?;
    let pending_len = first.len() + replays.len();
    if let Mode::Shard(s) = ctx.mode {
        let wall = ctx.start.elapsed().as_secs_f64();
        return shard::finish(exp, s, ctx.out, ctx.output, pending_len, resumed, wall);
    }

    let analysed = analyse_training(ctx)?;
    write(
        ctx.out,
        "runs.csv",
        runs::runs_csv(&analysed.rows).as_bytes(),
    )?;
    let plotted = write_curves(ctx, &analysed.results, "curves.csv", &exp.name, "return")?;
    let wall = ctx.start.elapsed().as_secs_f64();
    let md = training_markdown(ctx, &analysed, pending_len, resumed, wall, &plotted)?;
    write(ctx.out, "summary.md", md.as_bytes())?;
    let line = format!(
        "sweep {}: {} runs, {} run now, {} resumed (complete already), {:.1} s; see {}",
        exp.name,
        total,
        pending_len,
        resumed,
        wall,
        ctx.out.join("summary.md").display()
    );
    let files = ["summary.md", "curves.csv", "runs.csv"].map(str::to_owned);
    sweep_report(
        ctx,
        total,
        pending_len,
        resumed,
        wall,
        &files,
        &plotted,
        line,
    )
    .print(ctx.output)
}

/// The runs of a training sweep (of its shard, with `--shard`): those still to run, and how many
/// are complete already out of how many.
struct Planned<'a> {
    pending: Vec<Job<'a>>,
    resumed: u64,
    total: u64,
}

/// Every run's config first, seed-major so that an interrupted sweep has whole seeds done.
fn plan_training<'a>(ctx: &Ctx<'a>) -> crate::Result<Planned<'a>> {
    let exp = ctx.exp;
    let mut planned = Planned {
        pending: Vec::new(),
        resumed: 0,
        total: 0,
    };
    for seed in exp.seed_range() {
        for (m, method) in exp.methods.iter().enumerate() {
            if let Mode::Shard(s) = ctx.mode {
                if !s.owns(shard::index_of(exp, m, seed)) {
                    continue;
                }
            }
            planned.total += 1;
            let cfg = job_config(ctx, method, seed)?;
            let dir = run_dir(ctx.out, &method.name, seed);
            if is_complete(&dir, &cfg)? {
                planned.resumed += 1;
            } else {
                planned.pending.push(Job {
                    method,
                    seed,
                    dir,
                    cfg,
                });
            }
        }
    }
    Ok(planned)
}

/// The config of `method`'s run with `seed` in this sweep.
fn job_config(ctx: &Ctx, method: &Method, seed: u64) -> crate::Result<ExperimentConfig> {
    let exp = ctx.exp;
    let mut cfg = method.config(seed, exp.episodes)?;
    // A matched control's schedule names another method's runs of this sweep: `{out}` is the
    // sweep's directory, `{other_seed}` the sweep's next seed (the last one's is the first).
    if let Some(path) = &mut cfg.query.schedule {
        let other = exp.first_seed + (seed - exp.first_seed + 1) % exp.seeds;
        *path = path
            .replace("{out}", &ctx.out.display().to_string())
            .replace("{other_seed}", &other.to_string());
    }
    Ok(cfg)
}

/// What a training sweep's runs add up to, per method in the experiment's order.
struct Analysed<'a> {
    results: Vec<summary::MethodResult<'a>>,
    /// Each method's runs, as read back.
    all_runs: Vec<Vec<summary::Run>>,
    /// The query-rule view, filled when the experiment asks for `by_budget`.
    by_budget: budget::Table,
    /// Every run as a row of `runs.csv`.
    rows: Vec<runs::RunRow>,
}

/// Reads back every method's runs and analyses them.
fn analyse_training<'a>(ctx: &Ctx<'a>) -> crate::Result<Analysed<'a>> {
    let exp = ctx.exp;
    let mut analysed = Analysed {
        results: Vec::with_capacity(exp.methods.len()),
        all_runs: Vec::with_capacity(exp.methods.len()),
        by_budget: budget::Table::new(),
        rows: Vec::new(),
    };
    for method in &exp.methods {
        let runs = read_runs(ctx.out, method, exp.seed_range())?;
        for (seed, run) in exp.seed_range().zip(&runs) {
            let budget = method.config(seed, exp.episodes)?.budget();
            let row = runs::RunRow::of(&method.name, seed, budget, run, exp.eval_threshold);
            analysed.rows.push(row);
        }
        let own;
        let curve_runs = if exp.learner_episodes_only {
            own = with_episodes(&runs, summary::Episodes::without_expert);
            &own
        } else {
            &runs
        };
        analysed
            .results
            .push(summary::analyse(method, curve_runs, exp)?);
        if exp.by_budget {
            let cfg = method.config(exp.first_seed, exp.episodes)?;
            let cell = budget::cell(&runs, exp.eval_threshold, &method.name);
            analysed
                .by_budget
                .entry(budget::row_name(&cfg))
                .or_default()
                .insert(cfg.budget(), cell);
        }
        analysed.all_runs.push(runs);
    }
    Ok(analysed)
}

/// The `summary.md` of a training sweep; writes the files of its evaluation-curve and
/// query-rule sections when the experiment asks for them.
fn training_markdown(
    ctx: &Ctx,
    analysed: &Analysed<'_>,
    run_now: usize,
    resumed: u64,
    wall: f64,
    plotted: &[String],
) -> crate::Result<String> {
    let exp = ctx.exp;
    let mut md = summary::training_summary(ctx, &analysed.results, run_now, resumed, wall, plotted);
    if exp.learner_episodes_only {
        md.push_str(
            "\nThe training-return curves, crossings, areas and final returns leave out the \
             episodes in which the expert acted: they are the learner's own play.\n",
        );
    }
    if exp.eval_curves {
        md.push_str(&eval_curves(ctx, &analysed.all_runs)?);
    }
    if exp.by_budget {
        md.push_str(&budget_section(ctx, &analysed.by_budget)?);
    }
    md.push_str(&runs::section(exp, &analysed.rows));
    Ok(md)
}

/// The end of a sweep, for [`SweepReport::print`].
#[allow(clippy::too_many_arguments)]
fn sweep_report(
    ctx: &Ctx,
    runs: u64,
    run_now: usize,
    resumed: u64,
    wall_clock_s: f64,
    files: &[String],
    plotted: &[String],
    line: String,
) -> SweepReport {
    SweepReport {
        sweep: ctx.exp.name.clone(),
        out: ctx.out.display().to_string(),
        methods: ctx.exp.methods.iter().map(|m| m.name.clone()).collect(),
        seeds: ctx.exp.seeds,
        runs,
        run_now,
        resumed,
        wall_clock_s,
        files: files.iter().chain(plotted).cloned().collect(),
        line,
    }
}

fn run_dir(out: &Path, method: &str, seed: u64) -> PathBuf {
    out.join("runs").join(method).join(seed.to_string())
}

/// Whether `dir` holds a complete run of `cfg`. A complete run of another config is an error.
fn is_complete(dir: &Path, cfg: &ExperimentConfig) -> crate::Result<bool> {
    if !dir.join("summary.json").is_file() {
        return Ok(false);
    }
    let recorded = std::fs::read_to_string(dir.join("config.toml")).unwrap_or_default();
    if recorded != cfg.to_toml() {
        return Err(usage(format!(
            "{} holds a complete run of a different config than this sweep's (changed experiment, \
             config or --episodes?): use another --out, or delete that directory",
            dir.display()
        )));
    }
    Ok(true)
}

/// Runs the jobs on `jobs` threads, showing progress over `total` runs of which `done` are done.
fn run_jobs(
    trainer: &dyn Trainer,
    pending: &[Job],
    jobs: usize,
    total: u64,
    done: u64,
    progress: bool,
) -> crate::Result<()> {
    let bar = if progress {
        indicatif::ProgressBar::new(total)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} runs  (eta {eta})  {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_position(done);
    bar.reset_eta();
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let failure: Mutex<Option<LabError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(pending.len()) {
            scope.spawn(|| {
                while !stop.load(Ordering::Relaxed) {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(job) = pending.get(i) else { break };
                    let run = train_job(trainer, job);
                    match run {
                        Ok(summary) => {
                            tracing::debug!(method = %job.method.name, seed = job.seed, wall = summary.wall_clock_s, "run done");
                            bar.set_message(format!(
                                "{} seed {}: last-50 mean {:.1}",
                                job.method.name, job.seed, summary.mean_return_last_50
                            ));
                            bar.inc(1);
                        }
                        Err(e) => {
                            stop.store(true, Ordering::Relaxed);
                            let e = LabError::Failed {
                                what: format!(
                                    "run of method `{}` with seed {} ({})",
                                    job.method.name,
                                    job.seed,
                                    job.dir.display()
                                ),
                                source: e,
                            };
                            failure
                                .lock()
                                .unwrap_or_else(std::sync::PoisonError::into_inner)
                                .get_or_insert(e);
                        }
                    }
                }
            });
        }
    });
    bar.finish_and_clear();
    match failure
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
    {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Trains one job in the sweep's own run directory, re-run in place if unfinished; locked so
/// that two sweeps of one --out never run the same job at once.
fn train_job(trainer: &dyn Trainer, job: &Job) -> Result<RunSummary, crate::BoxError> {
    let _lock = alfd_harness::run_dir::lock(&job.dir)?;
    let mut cfg = job.cfg.clone();
    cfg.load_schedule(alfd_harness::read_text)?;
    trainer.train(&cfg, &job.dir)
}

/// `f` over `items` on `jobs` threads, results in the order of `items`; the first error wins.
fn parallel_map<T: Sync, R: Send>(
    items: &[T],
    jobs: usize,
    f: impl Fn(&T) -> crate::Result<R> + Sync,
) -> crate::Result<Vec<R>> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<crate::Result<R>>>> =
        Mutex::new(items.iter().map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(items.len()) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(item) = items.get(i) else { break };
                let r = f(item);
                results
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)[i] = Some(r);
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .into_iter()
        .map(|r| r.expect("every item was mapped"))
        .collect()
}

/// Each seed's run of `method`, read back from its directory.
fn read_runs(
    out: &Path,
    method: &Method,
    seeds: std::ops::Range<u64>,
) -> crate::Result<Vec<summary::Run>> {
    seeds
        .map(|seed| {
            let dir = run_dir(out, &method.name, seed);
            let path = dir.join("episodes.csv");
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            let episodes =
                summary::parse_episodes(&text).with_context(|| format!("in {}", path.display()))?;
            let path = dir.join("summary.json");
            let s: RunSummary = serde_json::from_str(
                &std::fs::read_to_string(&path)
                    .with_context(|| format!("cannot read {}", path.display()))?,
            )
            .with_context(|| format!("in {}", path.display()))?;
            Ok(summary::Run {
                episodes,
                wall_clock_s: s.wall_clock_s,
                greedy_value: s.greedy_value_at_start,
                optimal_value: s.optimal_value_at_start,
                costs: demo_costs(&dir)?,
            })
        })
        .collect()
}

/// A run of several experts (`experts.csv` beside it): each demonstration's `cost` in
/// `demos.jsonl`, in order (none without demonstrations); `None` for a run of one expert.
fn demo_costs(dir: &Path) -> crate::Result<Option<Vec<f64>>> {
    if !dir.join("experts.csv").is_file() {
        return Ok(None);
    }
    let path = dir.join("demos.jsonl");
    let text = std::fs::read_to_string(&path).unwrap_or_default();
    let mut costs = Vec::new();
    for (i, line) in text.lines().filter(|l| !l.trim().is_empty()).enumerate() {
        let v: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("line {} of {}", i + 1, path.display()))?;
        match v.get("cost").and_then(serde_json::Value::as_f64) {
            Some(c) => costs.push(c),
            None => crate::error::bail!("line {} of {} has no `cost`", i + 1, path.display()),
        }
    }
    Ok(Some(costs))
}

/// The query-rule view of the sweep ([`budget`]): its Markdown, its plots against B and
/// `by-budget.csv`.
fn budget_section(ctx: &Ctx, table: &budget::Table) -> crate::Result<String> {
    let exp = ctx.exp;
    let score_desc = if table
        .values()
        .flat_map(|m| m.values())
        .any(|c| c.demos_to.is_some())
    {
        "Final greedy evaluation (each seed's last `eval_return`)"
    } else {
        "Final greedy score (each seed's last `eval_return`, or CliffWalk's greedy V(S))"
    };
    let mut md = budget::markdown(table, exp.eval_threshold, score_desc);
    let mut csv = String::from(
        "rule,budget,seeds,score,score_low,score_high,demos_to,demos_to_low,demos_to_high,reached,expert_share\n",
    );
    for (rule, cells) in table {
        for (b, c) in cells {
            let e = |x: Option<&budget::Estimate>| {
                x.map_or(",,".to_owned(), |e| {
                    format!("{},{},{}", e.value, e.ci.low, e.ci.high)
                })
            };
            let _ = writeln!(
                csv,
                "{rule},{b},{},{},{},{},{}",
                c.seeds,
                e(c.score.as_ref()),
                e(c.demos_to.as_ref()),
                c.reached,
                c.expert_share
            );
        }
    }
    write(ctx.out, "by-budget.csv", csv.as_bytes())?;
    let seeds = summary::count(exp.seeds, "seed");
    let mut plots = vec![(
        "eval",
        format!("final greedy score: mean of {seeds}"),
        budget::series(table, |c| c.score),
    )];
    if let Some(t) = exp.eval_threshold {
        plots.push((
            "demos",
            format!("demonstrations to greedy eval ≥ {t}: median of {seeds}"),
            budget::series(table, |c| c.demos_to),
        ));
    }
    let mut files = Vec::new();
    for (tag, y_desc, series) in &plots {
        let svg = plot::svg(&plot::Plot {
            title: &summary::title_with_count(&exp.title, exp.seeds, "seed"),
            x_desc: "budget B (demonstrations)",
            y_desc,
            log_y: false,
            y_range: None,
            legend: exp.legend,
            band_desc: Some("band: 95% bootstrap CI"),
            series,
        })?;
        let name = format!("{}-by-budget-{tag}", exp.name);
        write(ctx.out, &format!("{name}.svg"), svg.as_bytes())?;
        files.push(format!("{name}.svg"));
        if let Some(png) = png_from_svg(&svg)? {
            write(ctx.out, &format!("{name}.png"), &png)?;
            files.push(format!("{name}.png"));
        }
    }
    let _ = writeln!(
        md,
        "\nPlots against B: {}; table: by-budget.csv.",
        files.join(", ")
    );
    Ok(md)
}

/// The runs with each one's episodes replaced by `f` of them.
fn with_episodes(
    runs: &[summary::Run],
    f: impl Fn(&summary::Episodes) -> summary::Episodes,
) -> Vec<summary::Run> {
    runs.iter()
        .map(|r| summary::Run {
            episodes: f(&r.episodes),
            ..r.clone()
        })
        .collect()
}

/// Writes the curves of `results` as `csv` and plots them as `STEM.svg` (and `.png`), the y axis
/// naming `what`; returns the plot files written.
fn write_curves(
    ctx: &Ctx,
    results: &[summary::MethodResult],
    csv: &str,
    stem: &str,
    what: &str,
) -> crate::Result<Vec<String>> {
    write(
        ctx.out,
        csv,
        summary::curves_csv(ctx.exp, results).as_bytes(),
    )?;
    let series = summary::training_series(ctx.exp, results);
    write_plot_as(ctx, &series, summary::x_name(ctx.exp.x).1, stem, what)
}

/// The learning curves of greedy evaluation from each method's `runs` (in the order of the
/// experiment's methods): `eval-curves.csv`, `EXPERIMENT-eval.svg` (and `.png`) and their section
/// of `summary.md`.
fn eval_curves(ctx: &Ctx, all_runs: &[Vec<summary::Run>]) -> crate::Result<String> {
    let exp = ctx.exp;
    let mut results = Vec::with_capacity(exp.methods.len());
    for (method, runs) in exp.methods.iter().zip(all_runs) {
        let runs = with_episodes(runs, summary::Episodes::greedy_evaluations);
        if runs.iter().any(|r| r.episodes.returns.is_empty()) {
            crate::error::bail!(
                "`eval_curves`: a run of method `{}` records no greedy evaluation (set \
                 `evaluation.every` in its config)",
                method.name
            );
        }
        results.push(summary::analyse(method, &runs, exp)?);
    }
    let stem = format!("{}-eval", exp.name);
    let plotted = write_curves(
        ctx,
        &results,
        "eval-curves.csv",
        &stem,
        "greedy evaluation return",
    )?;
    Ok(summary::eval_curves_section(exp, &results, &plotted))
}

/// Writes `EXPERIMENT.svg` and, when a font is found, `EXPERIMENT.png`; returns the files written.
fn write_plot(ctx: &Ctx, series: &[plot::Series], x_desc: &str) -> crate::Result<Vec<String>> {
    write_plot_as(ctx, series, x_desc, &ctx.exp.name, "return")
}

/// [`write_plot`] as `STEM.svg` (and `.png`), the y axis naming `what` is averaged.
fn write_plot_as(
    ctx: &Ctx,
    series: &[plot::Series],
    x_desc: &str,
    stem: &str,
    what: &str,
) -> crate::Result<Vec<String>> {
    let exp = ctx.exp;
    let seeds = summary::count(exp.seeds, "seed");
    let (title, y_desc, band) = match exp.kind {
        ExperimentKind::Training => (
            summary::title_with_count(&exp.title, exp.seeds, "seed"),
            if exp.smooth > 1 {
                format!(
                    "{what}: mean of {seeds} ({}-{} moving average)",
                    exp.smooth,
                    summary::smooth_unit(exp.x)
                )
            } else {
                format!("{what}: mean of {seeds}")
            },
            Some("band: 95% bootstrap CI of the mean"),
        ),
        ExperimentKind::DemoModelPolicy => (
            summary::title_with_count(&exp.title, exp.seeds, "run"),
            "return of the model's greedy episode".to_owned(),
            None,
        ),
    };
    let svg = plot::svg(&plot::Plot {
        title: &title,
        x_desc,
        y_desc: &y_desc,
        log_y: exp.log_y,
        y_range: exp.y_range,
        legend: exp.legend,
        band_desc: band,
        series,
    })?;
    let mut files = vec![format!("{stem}.svg")];
    write(ctx.out, &files[0], svg.as_bytes())?;
    let png_name = format!("{stem}.png");
    match png_from_svg(&svg)? {
        Some(png) => {
            write(ctx.out, &png_name, &png)?;
            files.push(png_name);
        }
        // No stale PNG of an earlier sweep next to the new SVG.
        None => match std::fs::remove_file(ctx.out.join(&png_name)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("cannot remove the stale {png_name}"))
            }
            _ => {}
        },
    }
    Ok(files)
}

fn run_policy(ctx: &Ctx) -> crate::Result<()> {
    let exp = ctx.exp;
    let total = exp.seeds * exp.methods.len() as u64;
    let results = play_policies(ctx, total)?;
    write(ctx.out, "returns.csv", returns_csv(&results).as_bytes())?;
    let plotted = write_plot(ctx, &sorted_returns(&results), "run, sorted by return")?;
    let wall = ctx.start.elapsed().as_secs_f64();
    let md = policy_markdown(ctx, &results, wall, &plotted);
    write(ctx.out, "summary.md", md.as_bytes())?;
    let line = format!(
        "sweep {}: {total} runs, {wall:.1} s; see {}",
        exp.name,
        ctx.out.join("summary.md").display()
    );
    let files = ["summary.md", "returns.csv"].map(str::to_owned);
    let n = usize::try_from(total).unwrap_or(usize::MAX);
    sweep_report(ctx, total, n, 0, wall, &files, &plotted, line).print(ctx.output)
}

/// Each method's runs of a demo-model-policy sweep, in the experiment's order.
type PolicyResults<'a> = Vec<(&'a Method, Vec<PolicyRun>)>;

/// Plays every seed of every method, showing progress over the `total` runs.
fn play_policies<'a>(ctx: &Ctx<'a>, total: u64) -> crate::Result<PolicyResults<'a>> {
    let exp = ctx.exp;
    let bar = if ctx.progress {
        indicatif::ProgressBar::new(total)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut results: PolicyResults<'a> = Vec::new();
    for method in &exp.methods {
        let MethodSpec::DemoModelPolicy {
            expert,
            demos,
            model,
            source,
            ..
        } = &method.spec
        else {
            crate::error::bail!("method `{}` is not a demo-model-policy method", method.name);
        };
        let seeds: Vec<u64> = exp.seed_range().collect();
        let runs = parallel_map(&seeds, ctx.jobs, |&seed| {
            let run = policy::play(expert, *demos, *model, seed, source);
            bar.inc(1);
            run
        })?;
        results.push((method, runs));
    }
    bar.finish_and_clear();
    Ok(results)
}

/// `returns.csv`: `method,seed,return,length` of every run.
fn returns_csv(results: &PolicyResults) -> String {
    let mut csv = String::from("method,seed,return,length\n");
    for (m, runs) in results {
        for r in runs {
            let _ = writeln!(csv, "{},{},{},{}", m.name, r.seed, r.ret, r.length);
        }
    }
    csv
}

/// Each method's returns in increasing order, against the run's rank.
fn sorted_returns(results: &PolicyResults) -> Vec<plot::Series> {
    results
        .iter()
        .map(|(m, runs)| {
            let mut y: Vec<f64> = runs.iter().map(|r| r.ret).collect();
            y.sort_by(f64::total_cmp);
            plot::Series {
                label: m.label.clone(),
                x: (0..y.len()).map(|i| i as f64).collect(),
                y,
                lo: Vec::new(),
                hi: Vec::new(),
            }
        })
        .collect()
}

/// The `summary.md` of a demo-model-policy sweep that took `wall` seconds.
fn policy_markdown(ctx: &Ctx, results: &PolicyResults, wall: f64, plotted: &[String]) -> String {
    let exp = ctx.exp;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# {}\n",
        summary::title_with_count(&exp.title, exp.seeds, "run")
    );
    let _ = writeln!(
        md,
        "Experiment `{}`: each run fits a demonstration model on demonstrations (\"demos\": how \
         many, mean over the runs; \"source\": the states they were given in, see \
         `alfd demo-model-policy --help`), then plays one greedy CartPole episode (limit 1000) \
         from a seeded reset; {} runs (seeds {}..{}) per method. Returns are the episodes' \
         (`returns.csv`).\n",
        exp.name,
        exp.seeds,
        exp.first_seed,
        exp.last_seed()
    );
    let _ = writeln!(md, "Command: `{}`\n", ctx.command);
    policy_table(&mut md, results);
    let _ = writeln!(
        md,
        "\n{wall:.1} s wall-clock. Plot: {} (each run's return, sorted).",
        plotted.join(", ")
    );
    md
}

/// The table of `summary.md` of a demo-model-policy sweep: one row per method.
fn policy_table(md: &mut String, results: &PolicyResults) {
    let _ = writeln!(
        md,
        "| method | expert | demos | source | model | runs | median | mean | std | min | max |"
    );
    let _ = writeln!(md, "|---|---|---:|---|---|---:|---:|---:|---:|---:|---:|");
    for (m, runs) in results {
        let MethodSpec::DemoModelPolicy {
            expert,
            model,
            source_desc: source,
            ..
        } = &m.spec
        else {
            continue;
        };
        let demos = stats::mean(&runs.iter().map(|r| r.demos as f64).collect::<Vec<_>>());
        let returns: Vec<f64> = runs.iter().map(|r| r.ret).collect();
        let s = ReturnStats::of(&returns);
        let min = returns.iter().copied().fold(f64::INFINITY, f64::min);
        let max = returns.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let _ = writeln!(
            md,
            "| {} | {expert} | {demos} | {source} | {model} | {} | {:.1} | {:.1} | {:.1} | {min} | {max} |",
            m.name,
            runs.len(),
            s.median,
            s.mean,
            s.std
        );
    }
}
