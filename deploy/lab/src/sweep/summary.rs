//! What a training sweep reports: each method's runs (read from their `episodes.csv` by column
//! name) turned into curves with 95% bootstrap bands, crossings, areas, final returns and their
//! interquartile means, and written as `curves.csv`, plot series and `summary.md`.
//!
//! The x axis is the experiment's `x`: episodes (0-based), or environment steps. Over steps, each
//! seed's return at step s is the return of its last episode finished by step s (no moving
//! window), evaluated on a grid of [`GRID_POINTS`] steps common to the method's seeds: from the
//! first step at which every seed has finished an episode to the smallest of the seeds' final
//! steps, so that every seed counts at every point and none is extrapolated past its end.

use std::fmt::Write as _;

use crate::error::Context as _;

use super::experiment::{Experiment, Method, XAxis};
use super::stats::bootstrap::{CrossingCi, Estimate, Interval, Resamples};
use super::stats::{self, CurvePoint};
use super::Ctx;

/// Points of the step grid.
pub const GRID_POINTS: usize = 100;

/// The columns of a run's `episodes.csv` the sweep reads.
#[derive(Debug, Clone, PartialEq)]
pub struct Episodes {
    pub returns: Vec<f64>,
    /// Demonstrations used by the last episode.
    pub demos_used: f64,
    /// `demos_used` of each episode (the run's demonstrations known at its end).
    pub demos: Vec<f64>,
    /// `total_steps` of each episode, when the column is there.
    pub total_steps: Option<Vec<f64>>,
    /// `eval_return` of each episode, when the column is there (NaN where it is empty or NaN:
    /// no evaluation after that episode).
    pub eval_return: Option<Vec<f64>>,
    /// `queries` of each episode (the steps the expert acted in), when the column is there.
    pub queries: Option<Vec<f64>>,
}

impl Episodes {
    /// The episodes in which the expert never acted (`queries` 0; all of them without the
    /// column): the learner's own training returns. The demonstrations and evaluations are kept
    /// as they are (an evaluation never asks the expert).
    pub fn without_expert(&self) -> Episodes {
        let Some(q) = &self.queries else {
            return self.clone();
        };
        let keep: Vec<bool> = q.iter().map(|&n| n == 0.0).collect();
        Episodes {
            returns: kept(&self.returns, &keep),
            total_steps: self.total_steps.as_ref().map(|v| kept(v, &keep)),
            ..self.clone()
        }
    }

    /// The episodes after which the learner was evaluated, with their evaluation return as the
    /// return: the greedy-evaluation learning curve. Empty without the `eval_return` column.
    pub fn greedy_evaluations(&self) -> Episodes {
        let eval = self.eval_return.as_deref().unwrap_or(&[]);
        let keep: Vec<bool> = eval.iter().map(|v| v.is_finite()).collect();
        Episodes {
            returns: kept(eval, &keep),
            demos: kept(&self.demos, &keep),
            total_steps: self.total_steps.as_ref().map(|v| kept(v, &keep)),
            queries: self.queries.as_ref().map(|v| kept(v, &keep)),
            ..self.clone()
        }
    }
}

/// The values of `v` whose episode `keep` says to keep (none past the end of `keep`).
fn kept(v: &[f64], keep: &[bool]) -> Vec<f64> {
    v.iter()
        .zip(keep)
        .filter(|(_, &k)| k)
        .map(|(&x, _)| x)
        .collect()
}

/// What one run left: its episodes and the numbers of its `summary.json`.
#[derive(Debug, Clone)]
pub struct Run {
    pub episodes: Episodes,
    pub wall_clock_s: f64,
    /// CliffWalk: the value at S of the run's greedy policy, and the optimal one.
    pub greedy_value: Option<f64>,
    pub optimal_value: Option<f64>,
    /// With several experts: what each demonstration cost, in order (`demos.jsonl`'s `cost`).
    pub costs: Option<Vec<f64>>,
}

/// The first crossing of a threshold by the mean curve, and its interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    pub x: Option<f64>,
    pub ci: CrossingCi,
}

/// The final greedy-evaluation return of the seeds that have one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalResult {
    pub seeds: usize,
    pub mean: Estimate,
    pub iqm: Estimate,
}

/// A method's statistics.
pub struct MethodResult<'a> {
    pub method: &'a Method,
    pub seeds: usize,
    /// Episodes of the longest run.
    pub episodes: usize,
    /// The curve over the experiment's x axis.
    pub curve: Vec<CurvePoint>,
    /// The 95% interval of the mean at the first `band.len()` points of the curve: those every
    /// seed reached.
    pub band: Vec<Interval>,
    /// Per threshold of the experiment.
    pub crossings: Vec<Crossing>,
    pub auc: Estimate,
    /// Each seed's mean return over its last 10% of x: their mean and their IQM.
    pub final_mean: Estimate,
    pub final_iqm: Estimate,
    /// The mean return over the last `last` episodes and the seeds.
    pub tail: f64,
    pub eval: Option<EvalResult>,
    /// Over steps: the grid's first and last step.
    pub steps: Option<(f64, f64)>,
    pub demos_used: Vec<f64>,
    pub wall_clock_s: Vec<f64>,
    pub greedy_value: Vec<f64>,
    pub optimal_value: Option<f64>,
}

/// The statistics of a method's runs (seeds in order).
pub fn analyse<'a>(
    method: &'a Method,
    runs: &[Run],
    exp: &Experiment,
) -> crate::Result<MethodResult<'a>> {
    crate::error::ensure!(!runs.is_empty(), "method `{}` has no runs", method.name);
    let returns: Vec<Vec<f64>> = runs.iter().map(|r| r.episodes.returns.clone()).collect();
    let longest = returns.iter().map(Vec::len).max().unwrap_or(0);
    let tail = stats::runs_tail_mean(&returns, exp.last as usize);
    // Each seed's values along the x axis, the curve, and the points every seed reached.
    let (xs, series, steps) = match exp.x {
        XAxis::Episodes => (stats::episodes(longest), returns, None),
        XAxis::Steps => {
            let mut step_runs = Vec::with_capacity(runs.len());
            for (seed, r) in runs.iter().enumerate() {
                let steps = r.episodes.total_steps.as_ref().with_context(|| {
                    format!(
                        "method `{}` seed {seed}: episodes.csv has no `total_steps` column, which \
                         x = \"steps\" needs",
                        method.name
                    )
                })?;
                step_runs.push(
                    steps
                        .iter()
                        .copied()
                        .zip(r.episodes.returns.iter().copied())
                        .collect::<Vec<_>>(),
                );
            }
            let refs: Vec<&stats::StepRun> = step_runs.iter().map(Vec::as_slice).collect();
            let grid = stats::step_grid(&refs, GRID_POINTS);
            let series = refs.iter().map(|r| stats::on_grid(r, &grid)).collect();
            let range = grid.first().zip(grid.last()).map(|(lo, hi)| (*lo, *hi));
            (grid, series, range)
        }
    };
    let curve = stats::curve(&xs, &series);
    let common = series.iter().map(Vec::len).min().unwrap_or(0);
    let common_xs = &xs[..common];
    let common_runs: Vec<Vec<f64>> = series.iter().map(|s| s[..common].to_vec()).collect();
    let means: Vec<f64> = curve[..common].iter().map(|p| p.mean).collect();

    let resamples = Resamples::new(runs.len(), "seeds");
    let ci = resamples.curve(common_xs, &common_runs, &exp.thresholds);
    let crossings = exp
        .thresholds
        .iter()
        .zip(&ci.crossings)
        .map(|(&t, &ci)| Crossing {
            x: stats::crossing(common_xs, &means, t),
            ci,
        })
        .collect();
    let finals = stats::final_values(&series);
    Ok(MethodResult {
        method,
        seeds: runs.len(),
        episodes: longest,
        curve,
        band: ci.band,
        crossings,
        auc: Estimate {
            value: stats::auc(common_xs, &means),
            ci: ci.auc,
        },
        final_mean: resamples.estimate(&finals, stats::mean),
        final_iqm: resamples.estimate(&finals, stats::iqm),
        tail,
        eval: final_eval(runs),
        steps,
        demos_used: runs.iter().map(|r| r.episodes.demos_used).collect(),
        wall_clock_s: runs.iter().map(|r| r.wall_clock_s).collect(),
        greedy_value: runs.iter().filter_map(|r| r.greedy_value).collect(),
        optimal_value: runs.iter().find_map(|r| r.optimal_value),
    })
}

/// The bootstrap stream of the seeds' final greedy evaluations: every table that gives their
/// mean (the summary's "final eval", the budget table's "final greedy") resamples them alike,
/// so one mean has one interval.
pub const FINAL_EVAL_STREAM: &str = "eval";

/// The mean and IQM of the seeds' last evaluation returns (`None` when no seed has one).
pub(super) fn final_eval(runs: &[Run]) -> Option<EvalResult> {
    let last: Vec<f64> = runs
        .iter()
        .filter_map(|r| {
            r.episodes
                .eval_return
                .as_ref()?
                .iter()
                .rev()
                .copied()
                .find(|v| v.is_finite())
        })
        .collect();
    if last.is_empty() {
        return None;
    }
    let resamples = Resamples::new(last.len(), FINAL_EVAL_STREAM);
    Some(EvalResult {
        seeds: last.len(),
        mean: resamples.estimate(&last, stats::mean),
        iqm: resamples.estimate(&last, stats::iqm),
    })
}

/// Reads `episodes.csv` by column name: `return` and `demos_used` are required; `total_steps` and
/// `eval_return` are read when present (an empty `eval_return` is NaN).
pub fn parse_episodes(text: &str) -> crate::Result<Episodes> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let need = |name: &str| col(name).with_context(|| format!("no `{name}` column"));
    let (ret_col, demos_col) = (need("return")?, need("demos_used")?);
    let (steps_col, eval_col) = (col("total_steps"), col("eval_return"));
    let queries_col = col("queries");
    let mut queries = queries_col.map(|_| Vec::new());
    let mut returns = Vec::new();
    let mut demos_used = 0.0;
    let mut demos = Vec::new();
    let mut total_steps = steps_col.map(|_| Vec::new());
    let mut eval_return = eval_col.map(|_| Vec::new());
    for (i, line) in lines.enumerate().filter(|(_, l)| !l.is_empty()) {
        let fields: Vec<&str> = line.split(',').collect();
        let field = |c: usize| -> crate::Result<f64> {
            fields
                .get(c)
                .and_then(|v| v.trim().parse().ok())
                .with_context(|| format!("line {}: no number in column {}", i + 2, c + 1))
        };
        returns.push(field(ret_col)?);
        demos_used = field(demos_col)?;
        demos.push(demos_used);
        if let (Some(c), Some(v)) = (steps_col, total_steps.as_mut()) {
            v.push(field(c)?);
        }
        if let (Some(c), Some(v)) = (queries_col, queries.as_mut()) {
            v.push(field(c)?);
        }
        if let (Some(c), Some(v)) = (eval_col, eval_return.as_mut()) {
            let empty = fields.get(c).is_some_and(|f| f.trim().is_empty());
            v.push(if empty { f64::NAN } else { field(c)? });
        }
    }
    crate::error::ensure!(!returns.is_empty(), "no episodes");
    Ok(Episodes {
        returns,
        demos_used,
        demos,
        total_steps,
        eval_return,
        queries,
    })
}

/// The x axis's name: in `curves.csv` and in the plot.
pub fn x_name(x: XAxis) -> (&'static str, &'static str) {
    match x {
        XAxis::Episodes => ("episode", "episode"),
        XAxis::Steps => ("steps", "environment steps"),
    }
}

/// What the plot's moving average counts: episodes, or points of the step grid.
pub fn smooth_unit(x: XAxis) -> &'static str {
    match x {
        XAxis::Episodes => "episode",
        XAxis::Steps => "grid-point",
    }
}

/// `curves.csv`: per method and x, the mean, std, median and count of the return across seeds,
/// and the 95% bootstrap interval of the mean (empty where not every seed reached the x).
pub fn curves_csv(exp: &Experiment, results: &[MethodResult]) -> String {
    let mut out = format!(
        "method,{},mean,std,median,count,ci_low,ci_high\n",
        x_name(exp.x).0
    );
    for r in results {
        for (k, p) in r.curve.iter().enumerate() {
            let (lo, hi) = r.band.get(k).map_or((String::new(), String::new()), |b| {
                (b.low.to_string(), b.high.to_string())
            });
            let _ = writeln!(
                out,
                "{},{},{},{},{},{},{lo},{hi}",
                r.method.name, p.x, p.mean, p.std, p.median, p.count
            );
        }
    }
    out
}

/// The plot's lines (the mean) and bands (its 95% interval), smoothed by the experiment's
/// `smooth` points.
pub fn training_series(exp: &Experiment, results: &[MethodResult]) -> Vec<super::plot::Series> {
    results
        .iter()
        .map(|r| {
            let mean: Vec<f64> = r.curve.iter().map(|p| p.mean).collect();
            let lo: Vec<f64> = r.band.iter().map(|b| b.low).collect();
            let hi: Vec<f64> = r.band.iter().map(|b| b.high).collect();
            super::plot::Series {
                label: r.method.label.clone(),
                x: r.curve.iter().map(|p| p.x).collect(),
                y: stats::smooth(&mean, exp.smooth),
                lo: stats::smooth(&lo, exp.smooth),
                hi: stats::smooth(&hi, exp.smooth),
            }
        })
        .collect()
}

/// `n seeds`, or `1 seed`.
pub fn count(n: u64, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// The title with the actual number of seeds (or runs): a parenthesis `(N seeds)` (or `(N runs)`)
/// written in the experiment file is replaced, so that `--seeds` never leaves a stale count.
pub fn title_with_count(title: &str, n: u64, noun: &str) -> String {
    let mut kept = String::new();
    let mut rest = title;
    while let Some(open) = rest.find('(') {
        let close = rest[open..].find(')').map(|c| open + c);
        let Some(close) = close else { break };
        let inner = &rest[open + 1..close];
        let is_count = inner.split_once(' ').is_some_and(|(num, word)| {
            num.parse::<u64>().is_ok() && (word == noun || word == format!("{noun}s"))
        });
        kept.push_str(if is_count {
            rest[..open].trim_end()
        } else {
            &rest[..=close]
        });
        rest = &rest[close + 1..];
    }
    kept.push_str(rest);
    format!("{} ({})", kept.trim_end(), count(n, noun))
}

fn estimate(e: &Estimate) -> String {
    format!("{:.2} [{:.2}, {:.2}]", e.value, e.ci.low, e.ci.high)
}

fn crossing(c: &Crossing) -> String {
    if c.x.is_none() && c.ci.never >= 1.0 {
        return "never".to_owned();
    }
    let bound = |b: Option<f64>| b.map_or("not reached".to_owned(), |x| x.to_string());
    let ci = match (c.ci.low, c.ci.high) {
        (None, None) => "[not reached]".to_owned(),
        (lo, hi) => format!("[{}, {}]", bound(lo), bound(hi)),
    };
    let x = c.x.map_or("never".to_owned(), |x| x.to_string());
    if c.ci.high.is_none() {
        format!("{x} {ci} (never in {:.0}%)", 100.0 * c.ci.never)
    } else {
        format!("{x} {ci}")
    }
}

/// `summary.md` of a training sweep.
pub fn training_summary(
    ctx: &Ctx,
    results: &[MethodResult],
    ran: usize,
    resumed: u64,
    wall: f64,
    plotted: &[String],
) -> String {
    let exp = ctx.exp;
    let episodes = results.iter().map(|r| r.episodes).max().unwrap_or_default();
    let (x_word, x_desc) = match exp.x {
        XAxis::Episodes => ("episode", "episodes"),
        XAxis::Steps => ("step", "environment steps"),
    };
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# {}\n",
        title_with_count(&exp.title, exp.seeds, "seed")
    );
    let _ = writeln!(
        md,
        "Experiment `{}`: {} methods × {} ({}..{}), {} episodes; x axis: {x_desc}.\n",
        exp.name,
        results.len(),
        count(exp.seeds, "seed"),
        exp.first_seed,
        exp.last_seed(),
        episodes
    );
    let _ = writeln!(md, "Command: `{}`\n", ctx.command);
    curves_explanation(&mut md, exp, x_word, x_desc);
    curves_table(&mut md, exp, results);
    eval_table(&mut md, results);
    runs_table(&mut md, exp, results);
    let _ = writeln!(
        md,
        "\nSweep: {} runs ({ran} run now, {resumed} resumed), {} jobs, {wall:.1} s wall-clock.\n",
        results.len() as u64 * exp.seeds,
        ctx.jobs
    );
    let _ = writeln!(
        md,
        "Plot: {} — the line is the mean return over the seeds, the band its 95% bootstrap \
         confidence interval{}.",
        plotted.join(", "),
        if exp.smooth > 1 {
            format!(
                ", both smoothed by a centred {}-{} moving average",
                exp.smooth,
                smooth_unit(exp.x)
            )
        } else {
            String::new()
        }
    );
    md
}

/// The "Learning curves" heading and what its table's numbers are, the x axis being `x_desc`
/// counted in `x_word`s.
fn curves_explanation(md: &mut String, exp: &Experiment, x_word: &str, x_desc: &str) {
    let _ = writeln!(md, "## Learning curves\n");
    let _ = writeln!(
        md,
        "Each number is followed by its 95% confidence interval [low, high]: a percentile \
         bootstrap over the seeds ({} resamples, a fixed random seed, so a re-run gives the same \
         intervals; with one seed an interval is a point). \"final\": each seed's mean return \
         over its last 10% of {x_desc}, then their mean over the seeds; \"IQM final\": their \
         interquartile mean (rliable's: the mean after cutting ⌊n/4⌋ seeds at each end). \"AUC\": \
         the area under the mean curve divided by the x range (the curve's average height). \
         \"crosses T\": the first {x_word} (as in `curves.csv`) at which the mean return over the \
         seeds is ≥ T, \"never\" if it never is (alone: nor does any resampled mean curve); \
         the interval is that of the first crossing of \
         the resampled mean curves, and a bound is \"not reached\" when too many of them never \
         cross (the upper bound: more than 2.5%; their share is given).{}\n",
        super::stats::bootstrap::RESAMPLES,
        match exp.x {
            XAxis::Episodes => String::new(),
            XAxis::Steps => format!(
                " Over steps, a seed's return at step s is the return of its last episode \
                 finished by s, on a grid of {GRID_POINTS} steps per method from the first step \
                 at which every seed has finished an episode to the smallest of the seeds' final \
                 steps (\"steps\" in the runs table)."
            ),
        }
    );
}

/// The "Greedy evaluation" section, when a method's runs record an evaluation.
fn eval_table(md: &mut String, results: &[MethodResult]) {
    if !results.iter().any(|r| r.eval.is_some()) {
        return;
    }
    let _ = writeln!(
        md,
        "\n## Greedy evaluation\n\n\"eval seeds\": the seeds whose `episodes.csv` records an \
         evaluation (`eval_return`); for each, its last one; \"final eval\": their mean, \
         \"IQM final eval\": their interquartile mean, with 95% bootstrap intervals.\n"
    );
    let _ = writeln!(
        md,
        "| method | eval seeds | final eval | IQM final eval |\n|---|---:|---:|---:|"
    );
    for r in results {
        let _ = match &r.eval {
            Some(e) => writeln!(
                md,
                "| {} | {} | {} | {} |",
                r.method.name,
                e.seeds,
                estimate(&e.mean),
                estimate(&e.iqm)
            ),
            None => writeln!(md, "| {} | 0 | — | — |", r.method.name),
        };
    }
}

/// The learning-curve table: final, IQM final, AUC and the crossings of each method.
fn curves_table(md: &mut String, exp: &Experiment, results: &[MethodResult]) {
    let mut header = String::from("| method | final | IQM final | AUC |");
    let mut rule = String::from("|---|---:|---:|---:|");
    for t in &exp.thresholds {
        let _ = write!(header, " crosses {t} |");
        rule.push_str("---:|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
    for r in results {
        let mut row = format!(
            "| {} | {} | {} | {} |",
            r.method.name,
            estimate(&r.final_mean),
            estimate(&r.final_iqm),
            estimate(&r.auc)
        );
        for c in &r.crossings {
            let _ = write!(row, " {} |", crossing(c));
        }
        let _ = writeln!(md, "{row}");
    }
}

/// The section of the learning curves of greedy evaluation (`eval_return` against the same x):
/// the table of [`curves_table`] over them, and the plots written.
pub fn eval_curves_section(
    exp: &Experiment,
    results: &[MethodResult],
    plotted: &[String],
) -> String {
    let mut md = String::from(
        "\n## Greedy-evaluation curves\n\nThe same statistics over the greedy evaluations \
         instead of the training returns: a seed's value at x is its last `eval_return` recorded \
         by x (the learner's own greedy play; the expert never acts in an evaluation).\n\n",
    );
    curves_table(&mut md, exp, results);
    let _ = writeln!(
        md,
        "\nPlot: {}; table: eval-curves.csv.",
        plotted.join(", ")
    );
    md
}

/// The table of what the runs used: the mean over their last episodes, demonstrations, time.
fn runs_table(md: &mut String, exp: &Experiment, results: &[MethodResult]) {
    let _ = writeln!(
        md,
        "\n## Runs\n\n\"last {last}\": the mean return over each seed's last {last} episodes, \
         then over the seeds. \"demos\": demonstrations used by the end of a run, mean over the seeds. \
         \"s/run\": mean wall-clock time of one run; \"run-s\": their sum. CliffWalk: \"greedy \
         V(S)\": the value at S (γ = 0.99) of each run's final greedy policy, mean over the \
         seeds, next to the optimal one (value iteration).\n",
        last = exp.last
    );
    if exp.learner_episodes_only {
        let steps = if exp.x == XAxis::Steps {
            " and \"steps\""
        } else {
            ""
        };
        let _ = writeln!(
            md,
            "With `learner_episodes_only`, \"last {last}\"{steps} count only the episodes the \
             expert did not act in: for a rule that asks in the late episodes too, they are \
             early ones, so its final greedy evaluation is the number to read.\n",
            last = exp.last
        );
    }
    let mut header = format!("| method | last {} | demos | s/run | run-s |", exp.last);
    let mut rule = String::from("|---|---:|---:|---:|---:|");
    if exp.x == XAxis::Steps {
        header.push_str(" steps |");
        rule.push_str("---|");
    }
    // CliffWalk runs also report the value at S of their greedy policy.
    let greedy = results
        .iter()
        .all(|r| r.greedy_value.len() == r.seeds && r.optimal_value.is_some());
    if greedy {
        header.push_str(" greedy V(S) | optimal V(S) |");
        rule.push_str("---:|---:|");
    }
    let _ = writeln!(md, "{header}\n{rule}");
    for r in results {
        let mut row = format!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.1} |",
            r.method.name,
            r.tail,
            stats::mean(&r.demos_used),
            stats::mean(&r.wall_clock_s),
            r.wall_clock_s.iter().sum::<f64>()
        );
        if let Some((lo, hi)) = r.steps {
            let _ = write!(row, " {lo}–{hi} |");
        }
        if greedy {
            let _ = write!(
                row,
                " {:.3} | {:.3} |",
                stats::mean(&r.greedy_value),
                r.optimal_value.unwrap_or(f64::NAN)
            );
        }
        let _ = writeln!(md, "{row}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episodes_csv_is_read_by_column_name() {
        let text = "episode,return,length,demos_used,mean_js\n0,12.5,12,3,0\n1,-4,9,7,0.1\n";
        let e = parse_episodes(text).unwrap();
        assert_eq!(e.returns, vec![12.5, -4.0]);
        assert_eq!(e.demos_used, 7.0);
        assert_eq!((e.total_steps, e.eval_return), (None, None));
        assert!(parse_episodes("episode,length\n0,1\n").is_err());
        assert!(parse_episodes("episode,return,demos_used\n0,x,1\n").is_err());
        assert!(parse_episodes("episode,return,demos_used\n").is_err());
    }

    #[test]
    fn the_greedy_evaluation_curve_is_the_evaluated_episodes_with_their_eval_return() {
        let text = "return,demos_used,queries,total_steps,eval_return\n-200,5,5,200,\n-150,5,0,350,-140\n-120,9,4,470,\n-110,9,0,580,-100\n";
        let e = parse_episodes(text).unwrap().greedy_evaluations();
        assert_eq!(e.returns, vec![-140.0, -100.0]);
        assert_eq!(e.total_steps, Some(vec![350.0, 580.0]));
        assert_eq!(e.demos, vec![5.0, 9.0]);
        assert_eq!(e.queries, Some(vec![0.0, 0.0]));
        let none = parse_episodes("return,demos_used\n-200,5\n").unwrap();
        assert!(none.greedy_evaluations().returns.is_empty());
    }

    #[test]
    fn episodes_the_expert_acted_in_can_be_left_out() {
        let text = "return,demos_used,queries,total_steps,eval_return\n-200,5,5,200,\n-150,5,0,350,-140\n-120,9,4,470,\n-110,9,0,580,-100\n";
        let e = parse_episodes(text).unwrap();
        let own = e.without_expert();
        assert_eq!(own.returns, vec![-150.0, -110.0]);
        assert_eq!(own.total_steps, Some(vec![350.0, 580.0]));
        assert_eq!((own.demos.len(), own.demos_used), (4, 9.0));
        assert_eq!(
            own.eval_return.unwrap().len(),
            4,
            "evaluations are all kept"
        );
        let no_column = parse_episodes("return,demos_used\n1,0\n").unwrap();
        assert_eq!(no_column.without_expert(), no_column);
    }

    #[test]
    fn steps_and_evaluations_are_read_when_present() {
        let text = "return,demos_used,total_steps,eval_return\n1,0,10,\n2,1,25,NaN\n3,1,40,7.5\n";
        let e = parse_episodes(text).unwrap();
        assert_eq!(e.total_steps, Some(vec![10.0, 25.0, 40.0]));
        let eval = e.eval_return.unwrap();
        assert!(eval[0].is_nan() && eval[1].is_nan());
        assert_eq!(eval[2], 7.5);
        assert!(parse_episodes("return,demos_used,eval_return\n1,0,x\n").is_err());
    }

    #[test]
    fn the_last_evaluation_of_each_seed_is_summarised() {
        let run = |eval: Option<Vec<f64>>| Run {
            episodes: Episodes {
                returns: vec![0.0; 3],
                demos_used: 0.0,
                demos: vec![0.0; 3],
                total_steps: None,
                eval_return: eval,
                queries: None,
            },
            wall_clock_s: 0.0,
            greedy_value: None,
            optimal_value: None,
            costs: None,
        };
        assert_eq!(final_eval(&[run(None)]), None);
        assert_eq!(final_eval(&[run(Some(vec![f64::NAN; 3]))]), None);
        let e = final_eval(&[
            run(Some(vec![1.0, 4.0, f64::NAN])),
            run(None),
            run(Some(vec![f64::NAN, f64::NAN, 8.0])),
        ])
        .unwrap();
        assert_eq!((e.seeds, e.mean.value, e.iqm.value), (2, 6.0, 6.0));
        assert!(e.mean.ci.low >= 4.0 && e.mean.ci.high <= 8.0);
    }

    #[test]
    fn titles_carry_the_actual_number_of_seeds() {
        let t = "Figure 4: CartPole, B = 100 (50 seeds)";
        assert_eq!(title_with_count(t, 50, "seed"), t);
        assert_eq!(
            title_with_count(t, 1, "seed"),
            "Figure 4: CartPole, B = 100 (1 seed)"
        );
        assert_eq!(
            title_with_count("Budget (B = 50) (20 seeds) in CartPole", 3, "seed"),
            "Budget (B = 50) in CartPole (3 seeds)"
        );
        assert_eq!(title_with_count("Tiny", 2, "seed"), "Tiny (2 seeds)");
        assert_eq!(
            title_with_count("Model (50 runs)", 5, "run"),
            "Model (5 runs)"
        );
    }

    #[test]
    fn crossings_say_not_reached_with_the_share() {
        let c = |x, low, high, never| Crossing {
            x,
            ci: CrossingCi { low, high, never },
        };
        assert_eq!(
            crossing(&c(Some(7.0), Some(5.0), Some(9.0), 0.0)),
            "7 [5, 9]"
        );
        assert_eq!(
            crossing(&c(Some(7.0), Some(5.0), None, 0.31)),
            "7 [5, not reached] (never in 31%)"
        );
        assert_eq!(
            crossing(&c(None, Some(30.0), None, 0.6)),
            "never [30, not reached] (never in 60%)"
        );
        assert_eq!(
            crossing(&c(None, None, None, 0.99)),
            "never [not reached] (never in 99%)"
        );
        assert_eq!(crossing(&c(None, None, None, 1.0)), "never");
    }
}
