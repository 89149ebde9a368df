//! `alfd sweep` end to end on a tiny experiment (2 methods × 2 seeds × 20 episodes): every output
//! file, the curves and the summary's numbers recomputed from the runs' `episodes.csv`, resuming,
//! determinism, and bad experiment files refused before anything runs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::SystemTime;

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

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("sweep")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn config(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs")
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

/// (returns, final demos_used) of a run's `episodes.csv`.
fn read_run(dir: &Path) -> (Vec<f64>, f64) {
    let csv = std::fs::read_to_string(dir.join("episodes.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let ret = header.iter().position(|h| *h == "return").unwrap();
    let demos = header.iter().position(|h| *h == "demos_used").unwrap();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (
        rows.iter().map(|r| r[ret]).collect(),
        rows.last().unwrap()[demos],
    )
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

/// The rows of the summary's table, by method: column name -> cell.
fn summary_table(md: &str) -> BTreeMap<String, BTreeMap<String, String>> {
    let rows: Vec<Vec<String>> = md
        .lines()
        .filter(|l| l.starts_with('|') && !l.starts_with("|---"))
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_owned())
                .collect()
        })
        .collect();
    let header = &rows[0];
    rows[1..]
        .iter()
        .map(|r| {
            (
                r[0].clone(),
                header.iter().cloned().zip(r.iter().cloned()).collect(),
            )
        })
        .collect()
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
    let dir = scratch("tiny");
    let experiment = write_experiment(&dir, "");
    let out = dir.join("out");
    let first = sweep(&experiment, &out, &["--jobs", "2"]);
    assert_ok(&first);
    assert!(
        text(&first.stdout).contains("4 runs, 4 run now, 0 resumed"),
        "{}",
        text(&first.stdout)
    );

    // Every run's files, with its seed and the experiment's episodes.
    let mut runs: BTreeMap<&str, Vec<(Vec<f64>, f64)>> = BTreeMap::new();
    for m in METHODS {
        for s in 0..SEEDS {
            let run = out.join("runs").join(m).join(s.to_string());
            for f in ["config.toml", "episodes.csv", "demos.jsonl", "summary.json"] {
                assert!(run.join(f).is_file(), "{} missing", run.join(f).display());
            }
            let cfg = std::fs::read_to_string(run.join("config.toml")).unwrap();
            assert!(cfg.contains(&format!("seed = {s}\n")), "{cfg}");
            assert!(cfg.contains(&format!("episodes = {EPISODES}\n")), "{cfg}");
            let (returns, demos) = read_run(&run);
            assert_eq!(returns.len(), EPISODES);
            runs.entry(m).or_default().push((returns, demos));
        }
    }
    // The two seeds of a method are different runs.
    assert_ne!(runs["bdqn-krr"][0].0, runs["bdqn-krr"][1].0);
    assert!(
        runs["bdqn-krr"][0].1 > 0.0,
        "BDQN+KRR asked for demonstrations"
    );

    // curves.csv: mean, std, median and count per method and episode, recomputed.
    let curves = std::fs::read_to_string(out.join("curves.csv")).unwrap();
    let mut lines = curves.lines();
    assert_eq!(lines.next(), Some("method,episode,mean,std,median,count"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), METHODS.len() * EPISODES);
    let mut means: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for row in &rows {
        let m = METHODS
            .iter()
            .find(|m| **m == row[0])
            .expect("a known method");
        let e: usize = row[1].parse().unwrap();
        let values: Vec<f64> = runs[m].iter().map(|(r, _)| r[e]).collect();
        let (mean, std, median) = stats(&values);
        let got: Vec<f64> = row[2..5].iter().map(|v| v.parse().unwrap()).collect();
        assert!(close(got[0], mean, 1e-12), "{row:?} mean {mean}");
        assert!(close(got[1], std, 1e-12), "{row:?} std {std}");
        assert!(close(got[2], median, 1e-12), "{row:?} median {median}");
        assert_eq!(row[5], SEEDS.to_string());
        assert_eq!(means.entry(m).or_default().len(), e, "episodes in order");
        means.get_mut(m).unwrap().push(mean);
    }

    // summary.md: crossings, last-LAST means and demonstrations, recomputed.
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    let table = summary_table(&md);
    let mut crossed = 0;
    for m in METHODS {
        let row = &table[m];
        let mean = &means[m];
        for t in THRESHOLDS {
            let expected = mean
                .iter()
                .position(|v| *v >= t)
                .map_or("never".to_owned(), |e| e.to_string());
            crossed += usize::from(expected != "never");
            assert_eq!(row[&format!("crosses {t}")], expected, "{m} crossing {t}");
        }
        let tail = mean[EPISODES - LAST..].iter().sum::<f64>() / LAST as f64;
        let got: f64 = row[&format!("last {LAST}")].parse().unwrap();
        assert!(
            (got - tail).abs() <= 0.005 + 1e-9,
            "{m}: last {got} vs {tail}"
        );
        let demos = runs[m].iter().map(|(_, d)| d).sum::<f64>() / SEEDS as f64;
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
}

#[test]
fn without_a_font_the_plot_is_svg_only_and_the_sweep_succeeds() {
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
    assert!(out.join("tiny.svg").is_file());
    assert!(!out.join("tiny.png").exists());
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("Plot: tiny.svg —"), "{md}");
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
    assert_refused("zero-seeds", "", None, &["--seeds", "0"], &["seeds", "0"]);
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
}

#[test]
fn demo_model_policy_is_reproducible_and_checks_its_input() {
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
