//! `alfd sweep` end to end on a tiny experiment (2 methods × 2 seeds × 20 episodes): every output
//! file, the curves, their bootstrap intervals and the summary's numbers recomputed from the runs'
//! `episodes.csv` (over episodes and over environment steps), resuming, determinism, and bad
//! experiment files refused before anything runs.
//!
//! With two seeds a and b, a bootstrap resample is (a, a), (a, b), (b, a) or (b, b), each a
//! quarter of the 2000 resamples give or take: a 95% interval of any statistic is the smallest and
//! the largest of its values on a alone, on b alone and (for crossings) on their mean.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::SystemTime;

use crate::support::{timed, tmp, TestDir};

const METHODS: [&str; 2] = ["qlearning", "bdqn-krr"];
const SEEDS: u64 = 2;
const EPISODES: usize = 20;
const LAST: usize = 5;
const THRESHOLDS: [f64; 3] = [-40.0, 15.0, 1000.0];

fn alfd(args: &[&str]) -> Output {
    alfd_with_env(args, &[])
}

fn alfd_with_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_alfd"));
    cmd.args(args).env("RUST_LOG", "warn");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().expect("the alfd binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A fresh scratch directory for one test, removed when dropped.
fn scratch(name: &str) -> TestDir {
    tmp(&format!("sweep-{name}"))
}

fn config(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../configs")
        .join(name)
        .display()
        .to_string()
}

/// The tiny experiment: tabular Q-learning on CliffWalk and BDQN+KRR on CartPole; the configs are
/// given by absolute path, `extra` is appended to the second method.
fn write_experiment(dir: &Path, extra: &str) -> PathBuf {
    let path = dir.join("tiny.toml");
    let body = format!(
        r#"title = "Tiny sweep"
seeds = {SEEDS}
episodes = {EPISODES}
log_y = true
thresholds = [-40, 15, 1000]
last = {LAST}

[[method]]
name = "qlearning"
config = "{q}"

[[method]]
name = "bdqn-krr"
label = "BDQN+KRR"
config = "{b}"
{extra}
"#,
        q = config("cliffwalk-qlearning.toml"),
        b = config("cartpole-bdqn-krr.toml"),
    );
    std::fs::write(&path, body).unwrap();
    path
}

fn sweep(experiment: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "sweep",
        "--config",
        experiment.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    alfd(&args)
}

fn assert_ok(out: &Output) {
    assert!(
        out.status.success(),
        "alfd failed: {}\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
}

/// `curves.csv` (its text, and its rows split into cells), after checking its header names the
/// x axis `x`.
fn read_curves(out: &Path, x: &str) -> (String, Vec<Vec<String>>) {
    let curves = std::fs::read_to_string(out.join("curves.csv")).unwrap();
    let mut lines = curves.lines();
    let header = format!("method,{x},mean,std,median,count,ci_low,ci_high");
    assert_eq!(lines.next(), Some(header.as_str()));
    let rows = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    (curves, rows)
}

/// What the test reads of a run's `episodes.csv`.
struct RunCsv {
    returns: Vec<f64>,
    /// demos_used of the last episode.
    demos: f64,
    total_steps: Vec<f64>,
    /// The `eval_return` column, when there is one (NaN where empty).
    eval: Option<Vec<f64>>,
}

fn read_run(dir: &Path) -> RunCsv {
    let csv = std::fs::read_to_string(dir.join("episodes.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|v| {
                    if v.is_empty() {
                        f64::NAN
                    } else {
                        v.parse().unwrap()
                    }
                })
                .collect()
        })
        .collect();
    let column = |c: usize| rows.iter().map(|r| r[c]).collect::<Vec<f64>>();
    RunCsv {
        returns: column(col("return").unwrap()),
        demos: rows.last().unwrap()[col("demos_used").unwrap()],
        total_steps: column(col("total_steps").unwrap()),
        eval: col("eval_return").map(column),
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

/// Mean, population std and median of `v`.
fn stats(v: &[f64]) -> (f64, f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let median = if s.len() % 2 == 1 {
        s[s.len() / 2]
    } else {
        (s[s.len() / 2 - 1] + s[s.len() / 2]) / 2.0
    };
    (mean, std, median)
}

/// The rows of the summary's tables, by method: column name -> cell, over all its tables.
fn summary_table(md: &str) -> BTreeMap<String, BTreeMap<String, String>> {
    let mut table: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    let mut header: Option<Vec<String>> = None;
    for line in md.lines() {
        if !line.starts_with('|') {
            header = None;
            continue;
        }
        if line.starts_with("|---") {
            continue;
        }
        let cells: Vec<String> = line
            .trim_matches('|')
            .split('|')
            .map(|c| c.trim().to_owned())
            .collect();
        match &header {
            None => header = Some(cells),
            Some(h) => table
                .entry(cells[0].clone())
                .or_default()
                .extend(h.iter().cloned().zip(cells.iter().cloned())),
        }
    }
    table
}

/// A summary cell `value [low, high]` (a bound may be "not reached", kept as `None`), and what
/// follows it.
fn parse_cell(cell: &str) -> (String, Option<f64>, Option<f64>, String) {
    let Some((value, rest)) = cell.split_once(" [") else {
        return (cell.to_owned(), None, None, String::new());
    };
    let (ci, after) = rest.split_once(']').unwrap();
    let bound = |b: &str| b.trim().parse::<f64>().ok();
    let (lo, hi) = match ci.split_once(", ") {
        Some((lo, hi)) => (bound(lo), bound(hi)),
        None => (None, None),
    };
    (value.to_owned(), lo, hi, after.trim().to_owned())
}

/// Checks a cell `value [low, high]` of a statistic whose value over both seeds is `both` and
/// whose values over each seed alone are `one`: the interval is their extent.
fn assert_estimate(cell: &str, both: f64, one: [f64; 2], what: &str) {
    let (value, lo, hi, _) = parse_cell(cell);
    let value: f64 = value.parse().unwrap();
    let tol = 0.005 + 1e-9;
    assert!((value - both).abs() <= tol, "{what}: {cell} vs {both}");
    let (min, max) = (one[0].min(one[1]), one[0].max(one[1]));
    assert!(
        (lo.unwrap() - min).abs() <= tol,
        "{what}: {cell} vs low {min}"
    );
    assert!(
        (hi.unwrap() - max).abs() <= tol,
        "{what}: {cell} vs high {max}"
    );
}

/// The first x at which `v` is at least `t`.
fn first_crossing(xs: &[f64], v: &[f64], t: f64) -> Option<f64> {
    xs.iter().zip(v).find(|(_, v)| **v >= t).map(|(x, _)| *x)
}

/// The area under `v` along `xs`, divided by the x range.
fn area(xs: &[f64], v: &[f64]) -> f64 {
    let a: f64 = (1..xs.len())
        .map(|k| (xs[k] - xs[k - 1]) * (v[k] + v[k - 1]) / 2.0)
        .sum();
    a / (xs[xs.len() - 1] - xs[0])
}

/// Checks the summary's row of a method against its two seeds' curves `a` and `b` along `xs`:
/// final, IQM final, AUC and the crossings, each with its interval.
fn assert_row(row: &BTreeMap<String, String>, xs: &[f64], a: &[f64], b: &[f64], what: &str) {
    let both: Vec<f64> = a.iter().zip(b).map(|(a, b)| (a + b) / 2.0).collect();
    let last = xs.len().div_ceil(10);
    let fin = |v: &[f64]| v[v.len() - last..].iter().sum::<f64>() / last as f64;
    let finals = [fin(a), fin(b)];
    let mean_final = (finals[0] + finals[1]) / 2.0;
    assert_estimate(&row["final"], mean_final, finals, &format!("{what} final"));
    // Two seeds: the IQM cuts none and is the mean.
    assert_estimate(
        &row["IQM final"],
        mean_final,
        finals,
        &format!("{what} IQM"),
    );
    let areas = [area(xs, a), area(xs, b)];
    assert_estimate(&row["AUC"], area(xs, &both), areas, &format!("{what} AUC"));
    for t in THRESHOLDS {
        let cell = &row[&format!("crosses {t}")];
        let (value, lo, hi, after) = parse_cell(cell);
        let expected = first_crossing(xs, &both, t).map_or("never".to_owned(), |x| x.to_string());
        assert_eq!(value, expected, "{what} crossing {t}: {cell}");
        // The resampled curves are a, b and their mean; the interval spans their crossings, a
        // curve that never crosses making the upper bound "not reached".
        let crossings: Vec<f64> = [a, b, &both]
            .iter()
            .map(|v| first_crossing(xs, v, t).unwrap_or(f64::INFINITY))
            .collect();
        let min = crossings.iter().copied().fold(f64::INFINITY, f64::min);
        let max = crossings.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if min.is_infinite() {
            assert_eq!(cell, "never", "{what} {t}: no resample crosses");
            continue;
        }
        assert_eq!(
            lo,
            Some(min).filter(|m| m.is_finite()),
            "{what} {t}: {cell}"
        );
        assert_eq!(
            hi,
            Some(max).filter(|m| m.is_finite()),
            "{what} {t}: {cell}"
        );
        assert_eq!(after.is_empty(), max.is_finite(), "{what} {t}: {cell}");
    }
}

/// The steps grid of runs given as (total_steps, returns), and each run's return on it (the
/// return of its last episode finished by each step), as the summary documents it.
fn step_curves(runs: &[(&[f64], &[f64])]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let lo = runs
        .iter()
        .map(|r| r.0[0])
        .fold(f64::NEG_INFINITY, f64::max);
    let hi = runs
        .iter()
        .map(|r| r.0[r.0.len() - 1])
        .fold(f64::INFINITY, f64::min);
    let mut grid: Vec<f64> = (0..100)
        .map(|k| (lo + (hi - lo) * k as f64 / 99.0).round())
        .collect();
    grid.dedup();
    let values = runs
        .iter()
        .map(|(steps, rets)| {
            grid.iter()
                .map(|s| rets[steps.iter().rposition(|t| t <= s).unwrap()])
                .collect()
        })
        .collect();
    (grid, values)
}

fn mtimes(out: &Path) -> Vec<SystemTime> {
    let mut v = Vec::new();
    for m in METHODS {
        for s in 0..SEEDS {
            let p = out
                .join("runs")
                .join(m)
                .join(s.to_string())
                .join("summary.json");
            v.push(std::fs::metadata(p).unwrap().modified().unwrap());
        }
    }
    v
}

#[test]
fn tiny_sweep_writes_curves_and_summary_that_match_the_runs() {
    let _time = timed!();
    let dir = scratch("tiny");
    // BDQN+KRR evaluates its greedy policy after episodes 7 and 15; Q-learning never does.
    let experiment = write_experiment(
        &dir,
        r#"set = ["evaluation.every=8", "evaluation.episodes=2"]"#,
    );
    let out = dir.join("out");
    let first = sweep(&experiment, &out, &["--jobs", "2"]);
    assert_ok(&first);
    assert!(
        text(&first.stdout).contains("4 runs, 4 run now, 0 resumed"),
        "{}",
        text(&first.stdout)
    );

    // Every run's files, with its seed and the experiment's episodes.
    let mut runs: BTreeMap<&str, Vec<RunCsv>> = BTreeMap::new();
    for m in METHODS {
        for s in 0..SEEDS {
            let run = out.join("runs").join(m).join(s.to_string());
            for f in ["config.toml", "episodes.csv", "demos.jsonl", "summary.json"] {
                assert!(run.join(f).is_file(), "{} missing", run.join(f).display());
            }
            let cfg = std::fs::read_to_string(run.join("config.toml")).unwrap();
            assert!(cfg.contains(&format!("seed = {s}\n")), "{cfg}");
            assert!(cfg.contains(&format!("episodes = {EPISODES}\n")), "{cfg}");
            let csv = read_run(&run);
            assert_eq!(csv.returns.len(), EPISODES);
            runs.entry(m).or_default().push(csv);
        }
    }
    // The two seeds of a method are different runs.
    assert_ne!(runs["bdqn-krr"][0].returns, runs["bdqn-krr"][1].returns);
    assert!(
        runs["bdqn-krr"][0].demos > 0.0,
        "BDQN+KRR asked for demonstrations"
    );

    // runs.csv: one row per run, its final evaluation and the mean of its evaluations
    // recomputed from its episodes.csv (Q-learning never evaluates: empty cells).
    let table = std::fs::read_to_string(out.join("runs.csv")).unwrap();
    let mut lines = table.lines();
    assert!(lines
        .next()
        .unwrap()
        .starts_with("method,seed,budget,demos,final_eval,eval_auc"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), METHODS.len() * SEEDS as usize);
    for r in &rows {
        let run = &runs[r[0]][r[1].parse::<usize>().unwrap()];
        let evals: Vec<f64> = run
            .eval
            .iter()
            .flatten()
            .copied()
            .filter(|v| !v.is_nan())
            .collect();
        assert_eq!(r[3].parse::<f64>().unwrap(), run.demos, "{r:?}");
        if evals.is_empty() {
            assert_eq!((r[4], r[5], r[6]), ("", "", "0"), "{r:?}");
        } else {
            assert_eq!(
                r[4].parse::<f64>().unwrap(),
                *evals.last().unwrap(),
                "{r:?}"
            );
            let mean = evals.iter().sum::<f64>() / evals.len() as f64;
            assert!(close(r[5].parse().unwrap(), mean, 1e-9), "{r:?}");
            assert_eq!(r[6], evals.len().to_string());
        }
    }

    // curves.csv: mean, std, median, count and the mean's interval per method and episode,
    // recomputed.
    let (curves, rows) = read_curves(&out, "episode");
    assert_eq!(rows.len(), METHODS.len() * EPISODES);
    let mut means: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for row in &rows {
        let m = METHODS
            .iter()
            .find(|m| **m == row[0])
            .expect("a known method");
        let e: usize = row[1].parse().unwrap();
        let values: Vec<f64> = runs[m].iter().map(|r| r.returns[e]).collect();
        let (mean, std, median) = stats(&values);
        let got: Vec<f64> = row[2..5].iter().map(|v| v.parse().unwrap()).collect();
        assert!(close(got[0], mean, 1e-12), "{row:?} mean {mean}");
        assert!(close(got[1], std, 1e-12), "{row:?} std {std}");
        assert!(close(got[2], median, 1e-12), "{row:?} median {median}");
        assert_eq!(row[5], SEEDS.to_string());
        // Two seeds: the interval of the mean runs from one seed's return to the other's.
        let ci: Vec<f64> = row[6..8].iter().map(|v| v.parse().unwrap()).collect();
        let (lo, hi) = (values[0].min(values[1]), values[0].max(values[1]));
        assert!(
            close(ci[0], lo, 1e-12) && close(ci[1], hi, 1e-12),
            "{row:?}"
        );
        assert_eq!(means.entry(m).or_default().len(), e, "episodes in order");
        means.get_mut(m).unwrap().push(mean);
    }

    // summary.md: final returns, IQM, AUC and crossings with their intervals, last-LAST means
    // and demonstrations, recomputed.
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.starts_with("# Tiny sweep (2 seeds)\n"), "{md}");
    let table = summary_table(&md);
    let episodes: Vec<f64> = (0..EPISODES).map(|e| e as f64).collect();
    let mut crossed = 0;
    for m in METHODS {
        let row = &table[m];
        let mean = &means[m];
        for t in THRESHOLDS {
            crossed += usize::from(mean.iter().any(|v| *v >= t));
        }
        let (a, b) = (&runs[m][0].returns, &runs[m][1].returns);
        assert_row(row, &episodes, a, b, m);
        let tail = mean[EPISODES - LAST..].iter().sum::<f64>() / LAST as f64;
        let got: f64 = row[&format!("last {LAST}")].parse().unwrap();
        assert!(
            (got - tail).abs() <= 0.005 + 1e-9,
            "{m}: last {got} vs {tail}"
        );
        let demos = runs[m].iter().map(|r| r.demos).sum::<f64>() / SEEDS as f64;
        let got: f64 = row["demos"].parse().unwrap();
        assert!(
            (got - demos).abs() <= 0.005 + 1e-9,
            "{m}: demos {got} vs {demos}"
        );
        let per_run: f64 = row["s/run"].parse().unwrap();
        assert!(per_run >= 0.0);
    }
    // One method is not on CliffWalk: no greedy-value column.
    assert!(!table["qlearning"].contains_key("greedy V(S)"));
    assert!(md.contains("## Greedy evaluation"), "{md}");
    assert_eval(&md, &table, &runs);
    assert!(crossed >= 2, "the thresholds exercise both outcomes:\n{md}");
    assert!(
        (1..THRESHOLDS.len() * METHODS.len()).contains(&crossed),
        "some thresholds are never crossed:\n{md}"
    );

    // The plot: an SVG always; a PNG when a font was found, else a warning saying so.
    let svg = std::fs::read_to_string(out.join("tiny.svg")).unwrap();
    assert!(svg.starts_with("<svg"));
    for label in ["Tiny sweep", "episode", "qlearning", "BDQN+KRR"] {
        assert!(svg.contains(label), "{label} not in the SVG");
    }
    match std::fs::read(out.join("tiny.png")) {
        Ok(png) => assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n"),
        Err(_) => assert!(text(&first.stderr).contains("no font found")),
    }

    // Resume: a second invocation redoes nothing and gives the same curves.
    let before = mtimes(&out);
    let second = sweep(&experiment, &out, &["--jobs", "2"]);
    assert_ok(&second);
    assert!(
        text(&second.stdout).contains("0 run now, 4 resumed"),
        "{}",
        text(&second.stdout)
    );
    assert_eq!(mtimes(&out), before, "complete runs were redone");
    assert_eq!(
        std::fs::read_to_string(out.join("curves.csv")).unwrap(),
        curves
    );

    // An interrupted run (no summary.json) is redone, and only it.
    std::fs::remove_file(out.join("runs/bdqn-krr/1/summary.json")).unwrap();
    let third = sweep(&experiment, &out, &["--jobs", "2"]);
    assert_ok(&third);
    assert!(
        text(&third.stdout).contains("1 run now, 3 resumed"),
        "{}",
        text(&third.stdout)
    );
    assert_eq!(
        std::fs::read_to_string(out.join("curves.csv")).unwrap(),
        curves,
        "the redone run reproduces its numbers"
    );

    // The same sweep on one thread, elsewhere: the same numbers.
    let other = dir.join("out-one-job");
    assert_ok(&sweep(&experiment, &other, &["--jobs", "1"]));
    assert_eq!(
        std::fs::read_to_string(other.join("curves.csv")).unwrap(),
        curves
    );

    // Complete runs of another config are not mixed in.
    let changed = sweep(&experiment, &out, &["--episodes", "7"]);
    assert_eq!(changed.status.code(), Some(2), "{}", text(&changed.stderr));
    assert!(text(&changed.stderr).contains("different config"));

    // Over environment steps (`x = "steps"`), from the same runs: nothing is run again.
    let steps = dir.join("tiny-steps.toml");
    let body = std::fs::read_to_string(&experiment).unwrap();
    std::fs::write(&steps, body.replacen("\n", "\nx = \"steps\"\n", 1)).unwrap();
    let res = sweep(&steps, &out, &["--jobs", "2"]);
    assert_ok(&res);
    assert!(text(&res.stdout).contains("0 run now, 4 resumed"));
    assert_steps(&out, &runs);
}

/// The outputs of the sweep over environment steps, recomputed from the runs' `episodes.csv`.
fn assert_steps(out: &Path, runs: &BTreeMap<&str, Vec<RunCsv>>) {
    let (_, rows) = read_curves(out, "steps");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("x axis: environment steps"), "{md}");
    let table = summary_table(&md);
    for m in METHODS {
        let (a, b) = (&runs[m][0], &runs[m][1]);
        let (grid, values) =
            step_curves(&[(&a.total_steps, &a.returns), (&b.total_steps, &b.returns)]);
        assert!(grid.len() > 50, "{m}: {} grid points", grid.len());
        let mine: Vec<&Vec<String>> = rows.iter().filter(|r| r[0] == m).collect();
        assert_eq!(mine.len(), grid.len(), "{m}");
        for (k, row) in mine.iter().enumerate() {
            let got: Vec<f64> = row[1..].iter().map(|v| v.parse().unwrap()).collect();
            let (va, vb) = (values[0][k], values[1][k]);
            assert_eq!(got[0], grid[k], "{m} {row:?}");
            assert!(close(got[1], (va + vb) / 2.0, 1e-12), "{m} {row:?}");
            assert!(close(got[5], va.min(vb), 1e-12), "{m} {row:?}");
            assert!(close(got[6], va.max(vb), 1e-12), "{m} {row:?}");
        }
        assert_row(&table[m], &grid, &values[0], &values[1], m);
        let range = format!("{}–{}", grid[0], grid[grid.len() - 1]);
        assert_eq!(table[m]["steps"], range, "{m}");
    }
    let svg = std::fs::read_to_string(out.join("tiny-steps.svg")).unwrap();
    assert!(svg.contains("environment steps"));
}

/// The greedy-evaluation table: there when a run records `eval_return`, with each method's mean
/// and IQM of its seeds' last evaluations; absent otherwise.
fn assert_eval(
    md: &str,
    table: &BTreeMap<String, BTreeMap<String, String>>,
    runs: &BTreeMap<&str, Vec<RunCsv>>,
) {
    let last = |r: &RunCsv| {
        r.eval
            .as_ref()
            .and_then(|e| e.iter().rev().copied().find(|v| v.is_finite()))
    };
    let any = runs.values().flatten().any(|r| last(r).is_some());
    assert_eq!(md.contains("## Greedy evaluation"), any, "{md}");
    if !any {
        return;
    }
    for m in METHODS {
        let finals: Vec<f64> = runs[m].iter().filter_map(last).collect();
        let row = &table[m];
        assert_eq!(row["eval seeds"], finals.len().to_string(), "{m}");
        match finals[..] {
            [] => assert_eq!(row["final eval"], "—"),
            [v] => assert_estimate(&row["final eval"], v, [v, v], m),
            [a, b] => {
                assert_estimate(&row["final eval"], (a + b) / 2.0, [a, b], m);
                assert_estimate(&row["IQM final eval"], (a + b) / 2.0, [a, b], m);
            }
            _ => unreachable!("two seeds"),
        }
    }
}

#[test]
fn without_a_font_the_plot_is_svg_only_and_the_sweep_succeeds() {
    let _time = timed!();
    let dir = scratch("no-font");
    let experiment = write_experiment(&dir, "");
    let out = dir.join("out");
    // A PNG of an earlier sweep must not survive as if it were this one's.
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("tiny.png"), b"stale").unwrap();
    let args = [
        "sweep",
        "--config",
        experiment.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
        "--seeds",
        "1",
        "--episodes",
        "3",
    ];
    let res = alfd_with_env(&args, &[("ALFD_FONT", "")]);
    assert_ok(&res);
    assert!(
        text(&res.stderr).contains("no font found"),
        "{}",
        text(&res.stderr)
    );
    assert!(!out.join("tiny.png").exists());
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("Plot: tiny.svg —"), "{md}");
    // One seed: said so in the singular, in the title and on the axis; its intervals are points.
    assert!(md.starts_with("# Tiny sweep (1 seed)\n"), "{md}");
    let svg = std::fs::read_to_string(out.join("tiny.svg")).unwrap();
    for text in ["Tiny sweep (1 seed)", "mean of 1 seed", "95% bootstrap CI"] {
        assert!(svg.contains(text), "{text} not in the SVG");
    }
    assert!(!svg.contains("1 seeds") && !md.contains("1 seeds"));
    for m in METHODS {
        let (value, lo, hi, _) = parse_cell(&summary_table(&md)[m]["final"]);
        let value: f64 = value.parse().unwrap();
        assert_eq!((lo, hi), (Some(value), Some(value)), "{m}");
    }
}

/// Runs `alfd sweep` on an experiment with `extra` appended to its second method (or replacing
/// the whole file when `whole` is given) and checks it is refused with exit code 2, a message
/// containing every one of `needles`, and nothing run.
fn assert_refused(name: &str, extra: &str, whole: Option<&str>, args: &[&str], needles: &[&str]) {
    let dir = scratch(name);
    let experiment = write_experiment(&dir, extra);
    if let Some(body) = whole {
        std::fs::write(&experiment, body).unwrap();
    }
    let out = dir.join("out");
    let res = sweep(&experiment, &out, args);
    let stderr = text(&res.stderr);
    assert_eq!(res.status.code(), Some(2), "{name}: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "{name}: `{n}` not in: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{name}: {stderr}");
    assert!(!out.join("runs").exists(), "{name}: something ran");
}

#[test]
fn bad_experiments_are_refused_before_anything_runs() {
    let _time = timed!();
    // The first method is valid: validation covers every method before any run starts.
    assert_refused(
        "unknown-config",
        "",
        Some("title = \"t\"\nseeds = 2\n[[method]]\nname = \"ok\"\nconfig = \"/no/such/dir/x.toml\"\n"),
        &[],
        &["method `ok`", "/no/such/dir/x.toml"],
    );
    assert_refused(
        "unknown-expert",
        "set = [\"expert.name=cartpole-9000\"]",
        None,
        &[],
        &["method `bdqn-krr`", "cartpole-9000"],
    );
    assert_refused(
        "unknown-set-key",
        "set = [\"agent.flavour=3\"]",
        None,
        &[],
        &["method `bdqn-krr`", "flavour"],
    );
    assert_refused(
        "unknown-x",
        "",
        Some("title = \"t\"\nseeds = 2\nx = \"time\"\n[[method]]\nname = \"ok\"\nconfig = \"x.toml\"\n"),
        &[],
        &["time", "episodes", "steps"],
    );
    assert_refused("zero-seeds", "", None, &["--seeds", "0"], &["seeds", "0"]);
    assert_refused(
        "first-seed-overflow",
        "",
        None,
        &["--first-seed", "18446744073709551615"],
        &["--first-seed 18446744073709551615", "2 seeds"],
    );
    assert_refused("unknown-key", "colour = \"red\"", None, &[], &["colour"]);
    assert_refused(
        "seed-in-set",
        "set = [\"seed=4\"]",
        None,
        &[],
        &["method `bdqn-krr`", "seed=4"],
    );
    assert_refused(
        "duplicate-method",
        &format!(
            "\n[[method]]\nname = \"qlearning\"\nconfig = \"{}\"\n",
            config("cliffwalk-sarsa.toml")
        ),
        None,
        &[],
        &["`qlearning` is listed twice"],
    );
    assert_refused(
        "unknown-baseline",
        "",
        Some(&format!(
            "title = \"t\"\nseeds = 2\nbaseline = \"nobody\"\n[[method]]\nname = \"ok\"\nconfig = \"{}\"\n",
            config("cliffwalk-qlearning.toml")
        )),
        &[],
        &["baseline `nobody`"],
    );
}

/// `--first-seed 1000`: the runs are seeds 1000 and 1001, each the run `alfd local` makes with that
/// seed, and the summary and the command say so.
#[test]
fn first_seed_runs_the_seeds_from_there() {
    let _time = timed!();
    let dir = scratch("first-seed");
    let experiment = write_experiment(&dir, "");
    let out = dir.join("out");
    assert_ok(&sweep(&experiment, &out, &["--first-seed", "1000"]));
    for m in METHODS {
        assert!(
            !out.join("runs").join(m).join("0").exists(),
            "{m}: seed 0 ran"
        );
        for s in 1000..1000 + SEEDS {
            let run = out.join("runs").join(m).join(s.to_string());
            let cfg = std::fs::read_to_string(run.join("config.toml")).unwrap();
            assert!(cfg.contains(&format!("seed = {s}\n")), "{cfg}");
        }
    }
    let local = dir.join("local");
    let res = alfd(&[
        "local",
        "--config",
        &config("cartpole-bdqn-krr.toml"),
        "--set",
        "seed=1001",
        "--set",
        &format!("episodes={EPISODES}"),
        "--out",
        local.to_str().unwrap(),
        "--quiet",
    ]);
    assert_ok(&res);
    let swept = std::fs::read_to_string(out.join("runs/bdqn-krr/1001/episodes.csv")).unwrap();
    let alone = std::fs::read_to_string(local.join("episodes.csv")).unwrap();
    assert_eq!(swept, alone, "the sweep's seed-1001 run is `alfd local`'s");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("× 2 seeds (1000..1001)"), "{md}");
    assert!(md.contains("--first-seed 1000"), "{md}");
}

#[test]
fn demo_model_policy_is_reproducible_and_checks_its_input() {
    let _time = timed!();
    let args = [
        "demo-model-policy",
        "--expert",
        "cartpole-1000",
        "--demos",
        "20",
        "--runs",
        "3",
    ];
    let a = alfd(&args);
    assert_ok(&a);
    let line: serde_json::Value = serde_json::from_slice(&a.stdout).unwrap();
    let returns: Vec<f64> = line["returns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(returns.len(), 3);
    assert!(returns.iter().all(|r| (1.0..=1000.0).contains(r)));
    let (_, _, median) = stats(&returns);
    assert_eq!(line["median"].as_f64().unwrap(), median);
    assert_eq!(alfd(&args).stdout, a.stdout, "same seeds, same returns");

    let bad = alfd(&["demo-model-policy", "--runs", "0"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(text(&bad.stderr).contains("--runs"));
    let bad = alfd(&["demo-model-policy", "--expert", "cartpole-9000"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(text(&bad.stderr).contains("cartpole-9000"));
}
