//! `alfd sweep`: runs every method of an experiment file over many seeds in the single-process
//! mode, several runs at a time, and writes the learning curves (`curves.csv`), a plot (SVG, and
//! PNG when a font is available) and a summary table (`summary.md`).
//!
//! Layout of the output directory `DIR`:
//! - `DIR/runs/METHOD/SEED/`: each run's outputs, as `alfd local` writes them (`config.toml`,
//!   `episodes.csv`, `demos.jsonl`, weights or policy, and `summary.json`, written last);
//! - `DIR/curves.csv`: `method,episode,mean,std,median,count` of the return across seeds;
//! - `DIR/EXPERIMENT.svg`, `DIR/EXPERIMENT.png`: mean ± 1 standard deviation per method;
//! - `DIR/summary.md`: per method, the first episode at which the mean return reaches each
//!   threshold, the mean over the last episodes, the demonstrations used and the wall-clock time.
//!
//! Runs are deterministic, so a sweep re-run gives the same numbers. A run whose `summary.json`
//! exists is complete and is not redone: an interrupted sweep resumes where it stopped. A complete
//! run of a different config (say, other episodes) is refused rather than mixed in.

mod experiment;
mod plot;
mod stats;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use alfd_common::config::ExperimentConfig;
use alfd_common::record::ReturnStats;
use anyhow::Context as _;

use crate::cmd_demo_model_policy::{self, PolicyRun};
use crate::cmd_local::{self, write, RunSummary};
use crate::usage::usage;
use experiment::{Experiment, ExperimentKind, Method, MethodSpec};
use stats::CurvePoint;

#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// The experiment file (TOML; see `deploy/experiments/`). Method configs are found relative
    /// to its directory.
    #[arg(long)]
    pub config: PathBuf,
    /// Number of seeds (runs use seeds 0..N); overrides the experiment file's `seeds`.
    #[arg(long)]
    pub seeds: Option<u64>,
    /// Runs at a time (default: the number of cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Output directory (created if missing; complete runs in it are kept).
    #[arg(long)]
    pub out: PathBuf,
    /// Training episodes of every run; overrides the experiment file's and the configs'.
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Print no progress bar.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(args: SweepArgs) -> anyhow::Result<()> {
    let exp = Experiment::load(&args.config, args.seeds, args.episodes)?;
    let jobs = match args.jobs {
        Some(0) => return Err(usage("--jobs must be at least 1")),
        Some(j) => j,
        None => std::thread::available_parallelism().map_or(1, usize::from),
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create output directory {}", args.out.display()))?;
    let mut command = format!(
        "alfd sweep --config {} --seeds {} --jobs {jobs}",
        args.config.display(),
        exp.seeds
    );
    if let Some(e) = args.episodes {
        write!(command, " --episodes {e}")?;
    }
    write!(command, " --out {}", args.out.display())?;
    let ctx = Ctx {
        exp: &exp,
        out: &args.out,
        jobs,
        progress: !args.quiet,
        command,
        start: Instant::now(),
    };
    match exp.kind {
        ExperimentKind::Training => run_training(&ctx),
        ExperimentKind::DemoModelPolicy => run_policy(&ctx),
    }
}

struct Ctx<'a> {
    exp: &'a Experiment,
    out: &'a Path,
    jobs: usize,
    progress: bool,
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

fn run_training(ctx: &Ctx) -> anyhow::Result<()> {
    let exp = ctx.exp;
    // Every run's config first, seed-major so that an interrupted sweep has whole seeds done.
    let mut pending = Vec::new();
    let mut resumed = 0u64;
    for seed in 0..exp.seeds {
        for method in &exp.methods {
            let cfg = method.config(seed, exp.episodes)?;
            let dir = run_dir(ctx.out, &method.name, seed);
            if is_complete(&dir, &cfg)? {
                resumed += 1;
            } else {
                pending.push(Job {
                    method,
                    seed,
                    dir,
                    cfg,
                });
            }
        }
    }
    let total = exp.seeds * exp.methods.len() as u64;
    tracing::info!(total, resumed, jobs = ctx.jobs, "sweep {}", exp.name);
    run_jobs(&pending, ctx.jobs, total, resumed, ctx.progress)?;

    let mut results = Vec::with_capacity(exp.methods.len());
    for method in &exp.methods {
        results.push(method_result(ctx.out, method, exp.seeds)?);
    }
    write(ctx.out, "curves.csv", curves_csv(&results).as_bytes())?;
    let plotted = write_plot(ctx, &training_series(exp, &results), "episode")?;
    let wall = ctx.start.elapsed().as_secs_f64();
    let md = training_summary(ctx, &results, pending.len(), resumed, wall, &plotted);
    write(ctx.out, "summary.md", md.as_bytes())?;
    println!(
        "sweep {}: {} runs, {} run now, {} resumed (complete already), {:.1} s; see {}",
        exp.name,
        total,
        pending.len(),
        resumed,
        wall,
        ctx.out.join("summary.md").display()
    );
    Ok(())
}

fn run_dir(out: &Path, method: &str, seed: u64) -> PathBuf {
    out.join("runs").join(method).join(seed.to_string())
}

/// Whether `dir` holds a complete run of `cfg`. A complete run of another config is an error.
fn is_complete(dir: &Path, cfg: &ExperimentConfig) -> anyhow::Result<bool> {
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
    pending: &[Job],
    jobs: usize,
    total: u64,
    done: u64,
    progress: bool,
) -> anyhow::Result<()> {
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
    let failure: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(pending.len()) {
            scope.spawn(|| {
                while !stop.load(Ordering::Relaxed) {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(job) = pending.get(i) else { break };
                    match cmd_local::run_config(&job.cfg, &job.dir, false) {
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
                            let e = e.context(format!(
                                "run of method `{}` with seed {} ({})",
                                job.method.name,
                                job.seed,
                                job.dir.display()
                            ));
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

/// `f` over `items` on `jobs` threads, results in the order of `items`; the first error wins.
fn parallel_map<T: Sync, R: Send>(
    items: &[T],
    jobs: usize,
    f: impl Fn(&T) -> anyhow::Result<R> + Sync,
) -> anyhow::Result<Vec<R>> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<anyhow::Result<R>>>> =
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

/// What a method's runs gave, read back from their directories.
struct MethodResult<'a> {
    method: &'a Method,
    curve: Vec<CurvePoint>,
    /// Demonstrations used by the end of each run.
    demos_used: Vec<f64>,
    /// Each run's wall-clock time, from its `summary.json`.
    wall_clock_s: Vec<f64>,
    /// CliffWalk: each run's value at S of its learned greedy policy, and the optimal value.
    greedy_value: Vec<f64>,
    optimal_value: Option<f64>,
}

fn method_result<'a>(
    out: &Path,
    method: &'a Method,
    seeds: u64,
) -> anyhow::Result<MethodResult<'a>> {
    let mut returns = Vec::with_capacity(seeds as usize);
    let mut demos_used = Vec::with_capacity(seeds as usize);
    let mut wall_clock_s = Vec::with_capacity(seeds as usize);
    let mut greedy_value = Vec::new();
    let mut optimal_value = None;
    for seed in 0..seeds {
        let dir = run_dir(out, &method.name, seed);
        let path = dir.join("episodes.csv");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let (rets, demos) =
            parse_episodes(&text).with_context(|| format!("in {}", path.display()))?;
        returns.push(rets);
        demos_used.push(demos);
        let path = dir.join("summary.json");
        let summary: RunSummary = serde_json::from_str(
            &std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read {}", path.display()))?,
        )
        .with_context(|| format!("in {}", path.display()))?;
        wall_clock_s.push(summary.wall_clock_s);
        greedy_value.extend(summary.greedy_value_at_start);
        optimal_value = optimal_value.or(summary.optimal_value_at_start);
    }
    Ok(MethodResult {
        method,
        curve: stats::curve(&returns),
        demos_used,
        wall_clock_s,
        greedy_value,
        optimal_value,
    })
}

/// The returns of `episodes.csv`, and the demonstrations used by its last episode.
fn parse_episodes(text: &str) -> anyhow::Result<(Vec<f64>, f64)> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .with_context(|| format!("no `{name}` column"))
    };
    let (ret_col, demos_col) = (col("return")?, col("demos_used")?);
    let mut returns = Vec::new();
    let mut demos = 0.0;
    for (i, line) in lines.enumerate().filter(|(_, l)| !l.is_empty()) {
        let fields: Vec<&str> = line.split(',').collect();
        let field = |c: usize| -> anyhow::Result<f64> {
            fields
                .get(c)
                .and_then(|v| v.parse().ok())
                .with_context(|| format!("line {}: no number in column {}", i + 2, c + 1))
        };
        returns.push(field(ret_col)?);
        demos = field(demos_col)?;
    }
    anyhow::ensure!(!returns.is_empty(), "no episodes");
    Ok((returns, demos))
}

fn curves_csv(results: &[MethodResult]) -> String {
    let mut out = String::from("method,episode,mean,std,median,count\n");
    for r in results {
        for p in &r.curve {
            let _ = writeln!(
                out,
                "{},{},{},{},{},{}",
                r.method.name, p.episode, p.mean, p.std, p.median, p.count
            );
        }
    }
    out
}

fn training_series(exp: &Experiment, results: &[MethodResult]) -> Vec<plot::Series> {
    results
        .iter()
        .map(|r| {
            let mean: Vec<f64> = r.curve.iter().map(|p| p.mean).collect();
            let std: Vec<f64> = r.curve.iter().map(|p| p.std).collect();
            let mean = stats::smooth(&mean, exp.smooth);
            let std = stats::smooth(&std, exp.smooth);
            plot::Series {
                label: r.method.label.clone(),
                x: r.curve.iter().map(|p| f64::from(p.episode)).collect(),
                lo: mean.iter().zip(&std).map(|(m, s)| m - s).collect(),
                hi: mean.iter().zip(&std).map(|(m, s)| m + s).collect(),
                y: mean,
            }
        })
        .collect()
}

/// Writes `EXPERIMENT.svg` and, when a font is found, `EXPERIMENT.png`; returns the files written.
fn write_plot(ctx: &Ctx, series: &[plot::Series], x_desc: &str) -> anyhow::Result<Vec<String>> {
    let exp = ctx.exp;
    let y_desc = match exp.kind {
        ExperimentKind::Training if exp.smooth > 1 => format!(
            "return: mean of {} seeds ± 1 std ({}-episode moving average)",
            exp.seeds, exp.smooth
        ),
        ExperimentKind::Training => format!("return: mean of {} seeds ± 1 std", exp.seeds),
        ExperimentKind::DemoModelPolicy => "return of the model's greedy episode".to_owned(),
    };
    let svg = plot::svg(&plot::Plot {
        title: &exp.title,
        x_desc,
        y_desc: &y_desc,
        log_y: exp.log_y,
        y_range: exp.y_range,
        legend: exp.legend,
        series,
    })?;
    let mut files = vec![format!("{}.svg", exp.name)];
    write(ctx.out, &files[0], svg.as_bytes())?;
    let png_name = format!("{}.png", exp.name);
    match plot::png_from_svg(&svg)? {
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

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn training_summary(
    ctx: &Ctx,
    results: &[MethodResult],
    ran: usize,
    resumed: u64,
    wall: f64,
    plotted: &[String],
) -> String {
    let exp = ctx.exp;
    let episodes = results
        .iter()
        .map(|r| r.curve.len())
        .max()
        .unwrap_or_default();
    let mut md = String::new();
    let _ = writeln!(md, "# {}\n", exp.title);
    let _ = writeln!(
        md,
        "Experiment `{}`: {} methods × {} seeds (0..{}), {} episodes.\n",
        exp.name,
        results.len(),
        exp.seeds,
        exp.seeds - 1,
        episodes
    );
    let _ = writeln!(md, "Command: `{}`\n", ctx.command);
    let _ = writeln!(
        md,
        "\"crosses T\": the first episode (0-based, as in `curves.csv`) at which the mean return \
         over the seeds is ≥ T; \"never\" if it never is. \"last {last}\": the mean return over the \
         last {last} episodes and the seeds. \"demos\": demonstrations used by the end of a run, \
         mean over the seeds. \"s/run\": mean wall-clock time of one run; \"run-s\": their sum. \
         CliffWalk: \"greedy V(S)\": the value at S (γ = 0.99) of each run's final greedy policy, \
         mean over the seeds, next to the optimal one (value iteration).\n",
        last = exp.last
    );
    let mut header = String::from("| method |");
    let mut rule = String::from("|---|");
    for t in &exp.thresholds {
        let _ = write!(header, " crosses {t} |");
        rule.push_str("---:|");
    }
    let _ = write!(header, " last {} | demos | s/run | run-s |", exp.last);
    rule.push_str("---:|---:|---:|---:|");
    // CliffWalk runs also report the value at S of their greedy policy.
    let greedy = results
        .iter()
        .all(|r| r.greedy_value.len() == r.wall_clock_s.len() && r.optimal_value.is_some());
    if greedy {
        header.push_str(" greedy V(S) | optimal V(S) |");
        rule.push_str("---:|---:|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
    for r in results {
        let mut row = format!("| {} |", r.method.name);
        for &t in &exp.thresholds {
            match stats::crossing(&r.curve, t) {
                Some(e) => write!(row, " {e} |"),
                None => write!(row, " never |"),
            }
            .expect("writing to a String");
        }
        let _ = write!(
            row,
            " {:.2} | {:.2} | {:.2} | {:.1} |",
            stats::tail_mean(&r.curve, exp.last as usize),
            mean(&r.demos_used),
            mean(&r.wall_clock_s),
            r.wall_clock_s.iter().sum::<f64>()
        );
        if greedy {
            let _ = write!(
                row,
                " {:.3} | {:.3} |",
                mean(&r.greedy_value),
                r.optimal_value.unwrap_or(f64::NAN)
            );
        }
        let _ = writeln!(md, "{row}");
    }
    let _ = writeln!(
        md,
        "\nSweep: {} runs ({ran} run now, {resumed} resumed), {} jobs, {wall:.1} s wall-clock.\n",
        results.len() as u64 * exp.seeds,
        ctx.jobs
    );
    let _ =
        writeln!(
        md,
        "Plot: {} — the line is the mean return over the seeds, the band ± 1 standard deviation \
         (what the paper calls \"variance\"){}.",
        plotted.join(", "),
        if exp.smooth > 1 {
            format!(", both smoothed by a centred {}-episode moving average", exp.smooth)
        } else {
            String::new()
        }
    );
    md
}

fn run_policy(ctx: &Ctx) -> anyhow::Result<()> {
    let exp = ctx.exp;
    let total = exp.seeds * exp.methods.len() as u64;
    let bar = if ctx.progress {
        indicatif::ProgressBar::new(total)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut results: Vec<(&Method, Vec<PolicyRun>)> = Vec::new();
    for method in &exp.methods {
        let MethodSpec::DemoModelPolicy {
            expert,
            demos,
            model,
            source,
            ..
        } = &method.spec
        else {
            anyhow::bail!("method `{}` is not a demo-model-policy method", method.name);
        };
        let seeds: Vec<u64> = (0..exp.seeds).collect();
        let runs = parallel_map(&seeds, ctx.jobs, |&seed| {
            let run = cmd_demo_model_policy::play(expert, *demos, *model, seed, source);
            bar.inc(1);
            run
        })?;
        results.push((method, runs));
    }
    bar.finish_and_clear();
    let mut csv = String::from("method,seed,return,length\n");
    for (m, runs) in &results {
        for r in runs {
            let _ = writeln!(csv, "{},{},{},{}", m.name, r.seed, r.ret, r.length);
        }
    }
    write(ctx.out, "returns.csv", csv.as_bytes())?;
    let series: Vec<plot::Series> = results
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
        .collect();
    let plotted = write_plot(ctx, &series, "run, sorted by return")?;
    let wall = ctx.start.elapsed().as_secs_f64();
    let mut md = String::new();
    let _ = writeln!(md, "# {}\n", exp.title);
    let _ = writeln!(
        md,
        "Experiment `{}`: each run fits a demonstration model on demonstrations (\"demos\": how \
         many, mean over the runs; \"source\": the states they were given in, see \
         `alfd demo-model-policy --help`), then plays one greedy CartPole episode (limit 1000) \
         from a seeded reset; {} runs (seeds 0..{}) per method. Returns are the episodes' \
         (`returns.csv`).\n",
        exp.name,
        exp.seeds,
        exp.seeds - 1
    );
    let _ = writeln!(md, "Command: `{}`\n", ctx.command);
    let _ = writeln!(
        md,
        "| method | expert | demos | source | model | runs | median | mean | std | min | max |"
    );
    let _ = writeln!(md, "|---|---|---:|---|---|---:|---:|---:|---:|---:|---:|");
    for (m, runs) in &results {
        let MethodSpec::DemoModelPolicy {
            expert,
            model,
            source_desc: source,
            ..
        } = &m.spec
        else {
            continue;
        };
        let demos = mean(&runs.iter().map(|r| r.demos as f64).collect::<Vec<_>>());
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
    let _ = writeln!(
        md,
        "\n{wall:.1} s wall-clock. Plot: {} (each run's return, sorted).",
        plotted.join(", ")
    );
    write(ctx.out, "summary.md", md.as_bytes())?;
    println!(
        "sweep {}: {total} runs, {wall:.1} s; see {}",
        exp.name,
        ctx.out.join("summary.md").display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episodes_csv_is_read_by_column_name() {
        let text = "episode,return,length,demos_used,mean_js\n0,12.5,12,3,0\n1,-4,9,7,0.1\n";
        let (rets, demos) = parse_episodes(text).unwrap();
        assert_eq!(rets, vec![12.5, -4.0]);
        assert_eq!(demos, 7.0);
        assert!(parse_episodes("episode,length\n0,1\n").is_err());
        assert!(parse_episodes("episode,return,demos_used\n0,x,1\n").is_err());
        assert!(parse_episodes("episode,return,demos_used\n").is_err());
    }
}
