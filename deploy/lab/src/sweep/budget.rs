//! A sweep's methods seen as query rules × budgets (the query-rule study): per rule (each
//! method's `query.rule`) and budget B (its `budget.total`), the final greedy evaluation, the
//! demonstrations used when greedy evaluation first reaches the experiment's `eval_threshold`,
//! and the expert's share of the actions; a table of each and plots against B.
//!
//! Only the learner's own play is measured: greedy evaluation episodes never ask the expert.

use std::collections::BTreeMap;
use std::fmt::Write as _;

pub use super::stats::bootstrap::Estimate;
use super::stats::bootstrap::Resamples;
use super::stats::{self};
use super::summary::{Episodes, Run};

/// The row of a method in the tables against B: its query rule, and its prior scale when the
/// heads have randomized prior functions (`js + prior 30`). A `random` control that replays the
/// steps of another rule than `js` in the same sweep (`{out}/runs/METHOD/SEED/demos.jsonl`, the
/// method named `RULE-bB`) is named after it: `random (js-spread's steps)`.
pub fn row_name(cfg: &alfd_common::config::ExperimentConfig) -> String {
    let rule = cfg.query.rule_name();
    if cfg.query.rule == alfd_common::query::RuleKind::Random {
        if let Some(other) = cfg.query.schedule.as_deref().and_then(replayed_rule) {
            if other != "js" {
                return format!("random ({other}'s steps)");
            }
        }
    }
    match cfg.agent.prior_scale {
        s if s > 0.0 => format!("{rule} + prior {s}"),
        _ => rule.to_owned(),
    }
}

/// The rule of the method whose runs a schedule path replays: `js-spread` in
/// `…/runs/js-spread-b25/{other_seed}/demos.jsonl`.
fn replayed_rule(schedule: &str) -> Option<&str> {
    let method = schedule.split("/runs/").nth(1)?.split('/').next()?;
    let (rule, budget) = method.rsplit_once("-b")?;
    budget.chars().all(|c| c.is_ascii_digit()).then_some(rule)
}

/// The demonstrations used by the end of the first episode after which greedy evaluation reached
/// `threshold`; infinite when it never did (or the run records no evaluation).
pub fn demos_to_threshold(e: &Episodes, threshold: f64) -> f64 {
    let Some(eval) = &e.eval_return else {
        return f64::INFINITY;
    };
    eval.iter()
        .zip(&e.demos)
        .find(|(v, _)| **v >= threshold)
        .map_or(f64::INFINITY, |(_, &d)| d)
}

/// The expert's share of the run's actions: demonstrations over environment steps (0 when the
/// run records no steps).
pub fn expert_share(e: &Episodes) -> f64 {
    match e.total_steps.as_ref().and_then(|s| s.last()) {
        Some(&steps) if steps > 0.0 => e.demos_used / steps,
        _ => 0.0,
    }
}

/// A run's final greedy score: its last evaluation return, or (CliffWalk) the value at S of its
/// final greedy policy.
pub fn final_score(run: &Run) -> Option<f64> {
    let last_eval = run
        .episodes
        .eval_return
        .as_ref()
        .and_then(|v| v.iter().rev().copied().find(|x| x.is_finite()));
    last_eval.or(run.greedy_value)
}

/// The median, infinite values included (a run that never reached the threshold counts as
/// needing more than any budget).
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n == 0 {
        return f64::NAN;
    }
    let upper_middle_is_enough = n % 2 == 1 || s[n / 2 - 1].is_infinite() || s[n / 2].is_infinite();
    if upper_middle_is_enough {
        s[n / 2]
    } else {
        (s[n / 2 - 1] + s[n / 2]) / 2.0
    }
}

/// One rule at one budget.
#[derive(Debug, Clone)]
pub struct Cell {
    pub seeds: usize,
    /// Mean final greedy score, with its 95% interval.
    pub score: Option<Estimate>,
    /// Median demonstrations to the threshold, with its 95% interval (infinite: never).
    pub demos_to: Option<Estimate>,
    /// Seeds that reached the threshold.
    pub reached: usize,
    /// Mean expert share of actions.
    pub expert_share: f64,
}

/// The cells of a sweep: rule name → budget → cell.
pub type Table = BTreeMap<String, BTreeMap<u32, Cell>>;

/// The cell of one method's runs.
pub fn cell(runs: &[Run], threshold: Option<f64>, stream: &str) -> Cell {
    let resamples = Resamples::new(runs.len(), stream);
    let scores: Vec<f64> = runs.iter().filter_map(final_score).collect();
    let score = (scores.len() == runs.len() && !runs.is_empty()).then(|| {
        Resamples::new(runs.len(), super::summary::FINAL_EVAL_STREAM).estimate(&scores, stats::mean)
    });
    let (demos_to, reached) = match threshold {
        Some(t) if runs.iter().any(|r| r.episodes.eval_return.is_some()) => {
            let d: Vec<f64> = runs
                .iter()
                .map(|r| demos_to_threshold(&r.episodes, t))
                .collect();
            let reached = d.iter().filter(|x| x.is_finite()).count();
            let mut e = resamples.estimate(&d, median);
            // A bound interpolated next to a "never" (infinite) value is never too.
            for x in [&mut e.ci.low, &mut e.ci.high] {
                if x.is_nan() {
                    *x = f64::INFINITY;
                }
            }
            (Some(e), reached)
        }
        _ => (None, 0),
    };
    let shares: Vec<f64> = runs.iter().map(|r| expert_share(&r.episodes)).collect();
    Cell {
        seeds: runs.len(),
        score,
        demos_to,
        reached,
        expert_share: stats::mean(&shares),
    }
}

fn number(x: f64) -> String {
    if x.is_infinite() {
        "never".to_owned()
    } else if x.abs() >= 100.0 || x == x.round() {
        format!("{x:.0}")
    } else {
        format!("{x:.2}")
    }
}

fn est(e: &Estimate) -> String {
    format!(
        "{} [{}, {}]",
        number(e.value),
        number(e.ci.low),
        number(e.ci.high)
    )
}

/// The Markdown section of the table: final score, demonstrations to the threshold and expert
/// share, rule by budget.
pub fn markdown(table: &Table, threshold: Option<f64>, score_desc: &str) -> String {
    let budgets: Vec<u32> = table
        .values()
        .flat_map(|m| m.keys().copied())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut md = String::from("\n## Query rules by budget\n\n");
    let head = |md: &mut String| {
        let cols: Vec<String> = budgets.iter().map(|b| format!("B = {b}")).collect();
        let _ = writeln!(md, "| rule | {} |", cols.join(" | "));
        let _ = writeln!(md, "|---|{}", "---:|".repeat(budgets.len()));
    };
    let rows = |md: &mut String, f: &dyn Fn(&Cell) -> String| {
        for (rule, cells) in table {
            let row: Vec<String> = budgets
                .iter()
                .map(|b| cells.get(b).map_or_else(|| "".to_owned(), f))
                .collect();
            let _ = writeln!(md, "| {rule} | {} |", row.join(" | "));
        }
    };
    let _ = writeln!(
        md,
        "{score_desc}: mean over the seeds with its 95% bootstrap interval (greedy play of the \
         learned agent only; the expert never acts in it).\n"
    );
    head(&mut md);
    rows(&mut md, &|c| c.score.as_ref().map_or("—".to_owned(), est));
    if let Some(t) = threshold {
        let _ = writeln!(
            md,
            "\nDemonstrations used when greedy evaluation first reaches {}: median over the \
             seeds with its 95% bootstrap interval, a seed that never reaches it counting as \
             \"never\" (more than any budget); then how many seeds reached it.\n",
            number(t)
        );
        head(&mut md);
        rows(&mut md, &|c| {
            c.demos_to.as_ref().map_or("—".to_owned(), |e| {
                format!("{} ({}/{})", est(e), c.reached, c.seeds)
            })
        });
    }
    let _ = writeln!(
        md,
        "\nThe expert's share of the actions (demonstrations over environment steps), mean over \
         the seeds.\n"
    );
    head(&mut md);
    rows(&mut md, &|c| format!("{:.4}", c.expert_share));
    md
}

/// The lines of a plot against B: one per rule, `value` of each cell (infinite values and missing
/// cells left out). The rule with only B = 0 (`never`) is drawn flat across the budgets.
pub fn series(
    table: &Table,
    value: impl Fn(&Cell) -> Option<Estimate>,
) -> Vec<super::plot::Series> {
    let budgets: Vec<u32> = table
        .values()
        .flat_map(|m| m.keys().copied())
        .filter(|&b| b > 0)
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    table
        .iter()
        .map(|(rule, cells)| {
            let points: Vec<(f64, Estimate)> = match cells.get(&0) {
                Some(c) if cells.len() == 1 => value(c)
                    .map(|e| budgets.iter().map(|&b| (f64::from(b), e)).collect())
                    .unwrap_or_default(),
                _ => cells
                    .iter()
                    .filter_map(|(&b, c)| value(c).map(|e| (f64::from(b), e)))
                    .collect(),
            };
            let points: Vec<(f64, Estimate)> = points
                .into_iter()
                .filter(|(_, e)| e.value.is_finite())
                .collect();
            super::plot::Series {
                label: rule.clone(),
                x: points.iter().map(|p| p.0).collect(),
                y: points.iter().map(|p| p.1.value).collect(),
                lo: points.iter().map(|p| p.1.ci.low).collect(),
                hi: points.iter().map(|p| p.1.ci.high).collect(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn episodes(eval: Vec<f64>, demos: Vec<f64>, steps: Vec<f64>) -> Episodes {
        Episodes {
            returns: vec![0.0; eval.len()],
            demos_used: *demos.last().unwrap(),
            demos,
            total_steps: Some(steps),
            eval_return: Some(eval),
            queries: None,
        }
    }

    #[test]
    fn demonstrations_to_threshold_are_those_known_at_the_first_evaluation_reaching_it() {
        let nan = f64::NAN;
        let e = episodes(
            vec![nan, -150.0, nan, -129.0, -120.0],
            vec![3.0, 10.0, 12.0, 17.0, 20.0],
            vec![200.0, 400.0, 600.0, 800.0, 1000.0],
        );
        assert_eq!(demos_to_threshold(&e, -130.0), 17.0);
        assert_eq!(demos_to_threshold(&e, -150.0), 10.0);
        assert_eq!(demos_to_threshold(&e, -100.0), f64::INFINITY);
        // 20 demonstrations over 1000 steps.
        assert_eq!(expert_share(&e), 0.02);
    }

    #[test]
    fn a_final_greedy_mean_has_one_interval_in_the_budget_table_and_the_summary() {
        let runs: Vec<Run> = (0..12)
            .map(|i| Run {
                episodes: episodes(
                    vec![f64::NAN, -200.0 + 7.0 * f64::from(i), f64::NAN],
                    vec![1.0, 2.0, 3.0],
                    vec![10.0, 20.0, 30.0],
                ),
                wall_clock_s: 1.0,
                greedy_value: None,
                optimal_value: None,
                costs: None,
            })
            .collect();
        let in_budget = cell(&runs, None, "some-method").score.unwrap();
        let in_summary = super::super::summary::final_eval(&runs).unwrap().mean;
        assert_eq!(in_budget, in_summary);
        assert!(in_budget.ci.low < in_budget.value && in_budget.value < in_budget.ci.high);
    }

    #[test]
    fn a_random_control_is_named_after_the_rule_whose_steps_it_replays() {
        let cfg = |rule: &str, schedule: &str| {
            alfd_common::config::ExperimentConfig::from_toml_with_overrides(
                "seed = 0\nsteps = 100\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n",
                &[
                    format!("query.rule={rule}"),
                    format!("query.schedule={schedule}"),
                ],
            )
            .unwrap()
        };
        let out = "/tmp/sweep/runs";
        for (schedule, want) in [
            (format!("{out}/js-b10/{{other_seed}}/demos.jsonl"), "random"),
            (
                format!("{out}/js-spread-b200/{{other_seed}}/demos.jsonl"),
                "random (js-spread's steps)",
            ),
            ("recorded/demos.jsonl".to_owned(), "random"),
            (format!("{out}/js-bx/1/demos.jsonl"), "random"),
        ] {
            assert_eq!(row_name(&cfg("random", &schedule)), want, "{schedule}");
        }
        assert_eq!(row_name(&cfg("js-spread", "x")), "js-spread");
    }

    #[test]
    fn median_counts_never_as_more_than_any_budget() {
        let inf = f64::INFINITY;
        assert_eq!(median(&[5.0, 1.0, 3.0]), 3.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&[1.0, inf, inf]), inf);
        assert_eq!(median(&[1.0, 2.0, inf]), 2.0);
        assert_eq!(median(&[1.0, 2.0, inf, inf]), inf);
    }

    #[test]
    fn the_never_rule_is_drawn_flat_across_the_budgets() {
        let c = |v: f64| Cell {
            seeds: 1,
            score: Some(Estimate {
                value: v,
                ci: super::super::stats::bootstrap::Interval { low: v, high: v },
            }),
            demos_to: None,
            reached: 0,
            expert_share: 0.0,
        };
        let mut table = Table::new();
        table.insert("never".into(), [(0, c(-200.0))].into());
        table.insert("js".into(), [(10, c(-150.0)), (50, c(-120.0))].into());
        let s = series(&table, |c| c.score);
        let js = s.iter().find(|s| s.label == "js").unwrap();
        let never = s.iter().find(|s| s.label == "never").unwrap();
        assert_eq!(
            (js.x.clone(), js.y.clone()),
            (vec![10.0, 50.0], vec![-150.0, -120.0])
        );
        assert_eq!(
            (never.x.clone(), never.y.clone()),
            (vec![10.0, 50.0], vec![-200.0, -200.0])
        );
        let md = markdown(&table, None, "final");
        assert!(md.contains("| rule | B = 0 | B = 10 | B = 50 |"), "{md}");
        assert!(
            md.contains("| js |  | -150 [-150, -150] | -120 [-120, -120] |"),
            "{md}"
        );
    }
}
