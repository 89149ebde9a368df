//! Every run of a training sweep as one row (`runs.csv`), so that any comparison can be redone
//! from the committed results: its final greedy evaluation, the area under its greedy-evaluation
//! curve, and when greedy evaluation first reached the experiment's `eval_threshold`. From the
//! rows: paired differences by seed against a baseline method with paired bootstrap intervals,
//! and the time to the threshold as Kaplan-Meier medians (runs that never reach it censored at
//! their end) with the share reached. Pure functions, tested here.

use super::stats::bootstrap::{Estimate, Resamples};
use super::summary::Run;

/// One run's row of `runs.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct RunRow {
    pub method: String,
    pub seed: u64,
    pub budget: u32,
    /// Demonstrations the run used in all.
    pub demos: f64,
    /// With several experts: what the run spent on answers in all (NaN: one expert, no costs).
    pub cost: f64,
    /// The last greedy evaluation's return (NaN: none).
    pub final_eval: f64,
    /// The mean of the greedy evaluations: the area under the evaluation curve over its length.
    pub eval_auc: f64,
    pub evaluations: usize,
    /// When greedy evaluation first reached the threshold: training episodes (1-based),
    /// environment steps and demonstrations used by then; else the run's end (censored).
    pub to_threshold: Option<ToThreshold>,
}

/// The time to the threshold, or to the run's end when it was never reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToThreshold {
    pub reached: bool,
    pub episodes: f64,
    pub steps: f64,
    pub demos: f64,
    /// What the first `demos` answers cost (NaN: no costs).
    pub cost: f64,
}

impl RunRow {
    /// The row of `run`; `threshold` is the experiment's `eval_threshold`.
    pub fn of(method: &str, seed: u64, budget: u32, run: &Run, threshold: Option<f64>) -> Self {
        let e = &run.episodes;
        let evals: Vec<(usize, f64)> = e
            .eval_return
            .iter()
            .flatten()
            .copied()
            .enumerate()
            .filter(|(_, v)| !v.is_nan())
            .collect();
        let values: Vec<f64> = evals.iter().map(|&(_, v)| v).collect();
        let steps = |i: usize| e.total_steps.as_ref().map_or(f64::NAN, |s| s[i]);
        let cost_of = |demos: f64| cost_of_first(run.costs.as_deref(), demos);
        let to_threshold = threshold.map(|t| {
            let hit = evals.iter().find(|&&(_, v)| v >= t).map(|&(i, _)| i);
            let i = hit.unwrap_or(e.returns.len().saturating_sub(1));
            let demos = e.demos.get(i).copied().unwrap_or(f64::NAN);
            ToThreshold {
                reached: hit.is_some(),
                episodes: (i + 1) as f64,
                steps: steps(i),
                demos,
                cost: cost_of(demos),
            }
        });
        Self {
            method: method.to_owned(),
            seed,
            budget,
            demos: e.demos_used,
            cost: cost_of(e.demos_used),
            final_eval: values.last().copied().unwrap_or(f64::NAN),
            eval_auc: if values.is_empty() {
                f64::NAN
            } else {
                values.iter().sum::<f64>() / values.len() as f64
            },
            evaluations: values.len(),
            to_threshold,
        }
    }
}

/// What the first `demos` demonstrations cost, from each one's cost in order; NaN without costs.
fn cost_of_first(costs: Option<&[f64]>, demos: f64) -> f64 {
    match costs {
        // A fold from +0: an empty sum is 0, not the -0 of `Sum`.
        Some(c) if !demos.is_nan() => c.iter().take(demos as usize).fold(0.0, |a, b| a + b),
        _ => f64::NAN,
    }
}

/// `runs.csv`: a header and one line per row (`cost` and `cost_to_threshold` empty for a run
/// of one expert).
pub fn runs_csv(rows: &[RunRow]) -> String {
    let mut out = String::from(
        "method,seed,budget,demos,final_eval,eval_auc,evaluations,reached,\
         episodes_to_threshold,steps_to_threshold,demos_to_threshold,cost,cost_to_threshold\n",
    );
    let num = |x: f64| {
        if x.is_nan() {
            String::new()
        } else {
            format!("{x}")
        }
    };
    for r in rows {
        let t = r.to_threshold;
        out.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            r.method,
            r.seed,
            r.budget,
            num(r.demos),
            num(r.final_eval),
            num(r.eval_auc),
            r.evaluations,
            t.map_or(String::new(), |t| t.reached.to_string()),
            t.filter(|t| t.reached)
                .map_or(String::new(), |t| num(t.episodes)),
            t.filter(|t| t.reached)
                .map_or(String::new(), |t| num(t.steps)),
            t.filter(|t| t.reached)
                .map_or(String::new(), |t| num(t.demos)),
            num(r.cost),
            t.filter(|t| t.reached)
                .map_or(String::new(), |t| num(t.cost)),
        ));
    }
    out
}

/// The Kaplan-Meier median of times to an event, `(time, reached)` per run (a run not reached is
/// censored at its time): the first time at which the estimated share still waiting is at most
/// one half; `None` when it never falls that far.
pub fn km_median(runs: &[(f64, bool)]) -> Option<f64> {
    let mut sorted: Vec<(f64, bool)> = runs.iter().copied().filter(|(t, _)| !t.is_nan()).collect();
    // At equal times, events before censorings (the usual convention).
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
    let mut at_risk = sorted.len() as f64;
    let mut surviving = 1.0;
    let mut i = 0;
    while i < sorted.len() {
        let t = sorted[i].0;
        let same: Vec<&(f64, bool)> = sorted[i..].iter().take_while(|r| r.0 == t).collect();
        let events = same.iter().filter(|r| r.1).count() as f64;
        if events > 0.0 {
            surviving *= 1.0 - events / at_risk;
            if surviving <= 0.5 {
                return Some(t);
            }
        }
        at_risk -= same.len() as f64;
        i += same.len();
    }
    None
}

/// A method's paired difference against the baseline over the seeds both ran: the mean of the
/// per-seed differences of `value` and its 95% paired bootstrap interval (the seeds resampled,
/// each keeping its pair); `None` without a common seed with a value.
pub fn paired(
    rows: &[RunRow],
    method: &str,
    baseline: &str,
    value: impl Fn(&RunRow) -> f64,
    stream: &str,
) -> Option<(usize, Estimate)> {
    let diffs: Vec<f64> = rows
        .iter()
        .filter(|r| r.method == method)
        .filter_map(|r| {
            let b = rows
                .iter()
                .find(|b| b.method == baseline && b.seed == r.seed)?;
            let d = value(r) - value(b);
            (!d.is_nan()).then_some(d)
        })
        .collect();
    if diffs.is_empty() {
        return None;
    }
    let resamples = Resamples::new(diffs.len(), stream);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    Some((diffs.len(), resamples.estimate(&diffs, mean)))
}

/// `summary.md`'s section on the rows: per method, the share of runs whose greedy evaluation
/// reached the threshold and the Kaplan-Meier medians of the time to it; against the baseline,
/// paired differences by seed of the area under the evaluation curve and of the final
/// evaluation.
pub fn section(exp: &super::experiment::Experiment, rows: &[RunRow]) -> String {
    let mut md = format!(
        "\n## Per run\n\n`runs.csv` holds every run ({} rows): its final greedy evaluation, the \
         mean of its greedy evaluations (the area under the evaluation curve over its length)",
        rows.len()
    );
    md.push_str(match exp.eval_threshold {
        Some(_) => ", and when greedy evaluation first reached the threshold.\n",
        None => ".\n",
    });
    let costed = rows.iter().any(|r| !r.cost.is_nan());
    if let Some(t) = exp.eval_threshold {
        md.push_str(&format!(
            "\nTime until greedy evaluation first reaches {t}: Kaplan-Meier medians over the seeds, \
             a run that never reaches it counted as still waiting at its end (\"not reached\": \
             fewer than half reach it).\n\n\
             | method | reached | median episodes | median demonstrations |{}\n|---|---:|---:|---:|{}\n",
            if costed { " median cost |" } else { "" },
            if costed { "---:|" } else { "" },
        ));
        for m in &exp.methods {
            md.push_str(&threshold_row(&m.name, rows, costed));
        }
    }
    if let Some(b) = &exp.baseline {
        md.push_str(&format!(
            "\nPaired by seed against `{b}`: the mean difference and its 95% paired bootstrap \
             interval (an interval of one point: every seed's difference the same).\n\n\
             | method | seeds | area difference | final difference |\n|---|---:|---:|---:|\n"
        ));
        for m in exp.methods.iter().filter(|m| &m.name != b) {
            let area = paired(
                rows,
                &m.name,
                b,
                |r| r.eval_auc,
                &format!("{}-area", m.name),
            );
            let last = paired(
                rows,
                &m.name,
                b,
                |r| r.final_eval,
                &format!("{}-final", m.name),
            );
            let n = area.map_or(0, |(n, _)| n);
            md.push_str(&format!(
                "| {} | {n} | {} | {} |\n",
                m.name,
                estimate(area.map(|(_, e)| e)),
                estimate(last.map(|(_, e)| e))
            ));
        }
    }
    md
}

/// A method's row of the threshold table.
fn threshold_row(method: &str, rows: &[RunRow], costed: bool) -> String {
    let times: Vec<ToThreshold> = rows
        .iter()
        .filter(|r| r.method == method)
        .filter_map(|r| r.to_threshold)
        .collect();
    let reached = times.iter().filter(|t| t.reached).count();
    let median = |f: fn(&ToThreshold) -> f64| {
        let pairs: Vec<(f64, bool)> = times.iter().map(|t| (f(t), t.reached)).collect();
        km_median(&pairs).map_or("not reached".to_owned(), |m| format!("{m}"))
    };
    let cost = if costed {
        format!(" {} |", median(|t| t.cost))
    } else {
        String::new()
    };
    format!(
        "| {method} | {reached} of {} | {} | {} |{cost}\n",
        times.len(),
        median(|t| t.episodes),
        median(|t| t.demos)
    )
}

/// `value [low, high]` to three decimals; `–` for none.
fn estimate(e: Option<Estimate>) -> String {
    e.map_or("–".to_owned(), |e| {
        format!("{:+.3} [{:+.3}, {:+.3}]", e.value, e.ci.low, e.ci.high)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::summary::Episodes;

    fn run(evals: &[f64], demos: &[f64]) -> Run {
        let n = evals.len();
        Run {
            episodes: Episodes {
                returns: vec![0.0; n],
                demos_used: *demos.last().unwrap(),
                demos: demos.to_vec(),
                total_steps: Some((1..=n).map(|i| 10.0 * i as f64).collect()),
                eval_return: Some(evals.to_vec()),
                queries: None,
            },
            wall_clock_s: 0.0,
            greedy_value: None,
            optimal_value: None,
            costs: None,
        }
    }

    #[test]
    fn a_row_has_the_last_evaluation_the_mean_of_them_and_the_first_reach() {
        let nan = f64::NAN;
        let r = run(&[nan, 0.0, nan, 1.0, nan, 0.5], &[1., 2., 3., 4., 5., 6.]);
        let row = RunRow::of("m", 7, 10, &r, Some(0.9));
        assert_eq!(row.final_eval, 0.5);
        assert_eq!(row.eval_auc, 0.5);
        assert_eq!(row.evaluations, 3);
        let t = row.to_threshold.unwrap();
        assert!(t.reached);
        assert_eq!((t.episodes, t.steps, t.demos), (4.0, 40.0, 4.0));
        // Never reached: censored at the run's end, the columns left empty in runs.csv.
        let never = RunRow::of("m", 8, 10, &r, Some(2.0));
        assert_eq!(never.to_threshold.unwrap().episodes, 6.0);
        let csv = runs_csv(&[row, never]);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[1], "m,7,10,6,0.5,0.5,3,true,4,40,4,,");
        assert_eq!(lines[2], "m,8,10,6,0.5,0.5,3,false,,,,,");
    }

    #[test]
    fn with_costs_a_row_sums_what_the_demonstrations_up_to_the_threshold_cost() {
        let nan = f64::NAN;
        let mut r = run(&[nan, 0.0, nan, 1.0], &[1., 2., 2., 3.]);
        r.costs = Some(vec![10.0, 1.0, 2.0]);
        let row = RunRow::of("m", 7, 10, &r, Some(0.9));
        assert_eq!(row.cost, 13.0);
        let t = row.to_threshold.unwrap();
        assert_eq!((t.demos, t.cost), (3.0, 13.0));
        let early = RunRow::of("m", 7, 10, &r, Some(0.0));
        assert_eq!(
            early.to_threshold.unwrap().cost,
            11.0,
            "two demonstrations by episode 2"
        );
        let csv = runs_csv(&[early]);
        assert!(csv.lines().nth(1).unwrap().ends_with(",2,13,11"), "{csv}");
    }

    #[test]
    fn kaplan_meier_medians_count_censored_runs_as_still_waiting() {
        // Hand-computed: times 2, 3, 5 reached, 4 and 6 censored. S(2) = 4/5, S(3) = 3/5,
        // at 5 two are at risk: S(5) = 3/5 · 1/2 = 0.3 ≤ 0.5, so the median is 5.
        let runs = [
            (2.0, true),
            (3.0, true),
            (4.0, false),
            (5.0, true),
            (6.0, false),
        ];
        assert_eq!(km_median(&runs), Some(5.0));
        // One of three reached, the rest censored later: S stays at 2/3.
        assert_eq!(km_median(&[(1.0, true), (9.0, false), (9.0, false)]), None);
        // Two of four at time 3: S(3) = 1/2.
        let half = [(3.0, true), (3.0, true), (8.0, false), (9.0, false)];
        assert_eq!(km_median(&half), Some(3.0));
        assert_eq!(km_median(&[]), None);
    }

    #[test]
    fn paired_differences_pair_by_seed_and_skip_unpaired_seeds() {
        let row = |method: &str, seed, auc| RunRow {
            method: method.into(),
            seed,
            budget: 5,
            demos: 5.0,
            cost: f64::NAN,
            final_eval: 0.0,
            eval_auc: auc,
            evaluations: 1,
            to_threshold: None,
        };
        let rows = [
            row("a", 0, 3.0),
            row("a", 1, 5.0),
            row("a", 2, 9.0),
            row("b", 0, 1.0),
            row("b", 1, 4.0),
        ];
        let (n, e) = paired(&rows, "a", "b", |r| r.eval_auc, "t").unwrap();
        // Seeds 0 and 1: differences 2 and 1.
        assert_eq!(n, 2);
        assert_eq!(e.value, 1.5);
        assert!(e.ci.low >= 1.0 && e.ci.high <= 2.0, "{e:?}");
        assert!(paired(&rows, "a", "c", |r| r.eval_auc, "t").is_none());
    }
}
