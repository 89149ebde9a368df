//! What a run says at its end: the human summary on stderr, the JSON line on stdout (`--json`, or
//! a stdout that is not a terminal), no ANSI codes off a terminal, and the learning curve
//! (`curve.svg`) in the run directory, for `alfd local` and `alfd run`.

use std::path::Path;
use std::process::Output;

use crate::support::{alfd, text, timed, tmp};

const CONFIG: &str = "deploy/configs/cartpole-bdqn.toml";

fn local(out: &Path, flags: &[&str]) -> Output {
    let o = alfd()
        .args(["local", "--config", CONFIG, "--set", "episodes=30", "--out"])
        .arg(out)
        .args(flags)
        .output()
        .expect("alfd runs");
    assert!(o.status.success(), "{}", text(&o));
    o
}

/// `curve.svg` exists, is an SVG document and carries the run's title.
fn check_curve(dir: &Path, title: &str) {
    let svg = std::fs::read_to_string(dir.join("curve.svg")).expect("curve.svg written");
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert!(
        svg.contains(title),
        "title {title:?} missing from curve.svg"
    );
    assert!(svg.contains("demonstrations used") && svg.contains("budget B = "));
}

#[test]
fn local_ends_with_a_summary_naming_the_run_directory_and_draws_the_curve() {
    let _time = timed!();
    let dir = tmp("report-local");
    let out = dir.join("run");
    let o = local(&out, &[]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    let last: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout: the JSON line");
    let demos = last["demos_used"].as_u64().unwrap();
    for needle in [
        "Run finished (cartpole, bdqn, seed 0)".to_owned(),
        format!("run directory    {}", out.display()),
        "episodes         30 (".to_owned(),
        format!("demonstrations   {demos} used of the budget of 100"),
        "1000.0, the mean return of cartpole-1000".to_owned(),
        "curve.svg".to_owned(),
        "episodes.csv".to_owned(),
        // The learned network's Q-values, against CartPole-1000's range at the config's γ.
        "on 3 greedy episodes; every true value lies in [0, ".to_owned(),
    ] {
        assert!(
            err.contains(&needle),
            "{needle:?} missing from stderr:\n{err}"
        );
    }
    assert!(
        !err.contains('\x1b'),
        "ANSI codes on a stderr that is no terminal:\n{err}"
    );
    check_curve(&out, "cartpole, bdqn (seed 0): run");
    // The summary's files are those in the directory.
    for f in [
        "config.toml",
        "demos.jsonl",
        "weights.safetensors",
        "summary.json",
    ] {
        assert!(out.join(f).is_file() && err.contains(f), "{f}");
    }
    assert_eq!(out.join("curve.png").is_file(), err.contains("curve.png"));
}

#[test]
fn json_prints_only_the_machine_readable_line() {
    let _time = timed!();
    let dir = tmp("report-json");
    let json = local(&dir.join("json"), &["--json"]);
    let line: serde_json::Value = serde_json::from_slice(&json.stdout).expect("one JSON line");
    assert_eq!(line["episodes"], 30);
    assert_eq!(String::from_utf8_lossy(&json.stdout).lines().count(), 1);
    let err = String::from_utf8_lossy(&json.stderr);
    assert!(
        !err.contains("Run finished") && !err.contains("run directory"),
        "a summary with --json:\n{err}"
    );
    check_curve(&dir.join("json"), "(seed 0): json");
    // --quiet keeps the line on a piped stdout, and says nothing else.
    let quiet = local(&dir.join("quiet"), &["--quiet"]);
    let mut quiet_line: serde_json::Value = serde_json::from_slice(&quiet.stdout).unwrap();
    let mut line = line;
    for l in [&mut quiet_line, &mut line] {
        l.as_object_mut().unwrap().remove("wall_clock_s");
    }
    assert_eq!(quiet_line, line, "the same run, the same line");
    assert!(!String::from_utf8_lossy(&quiet.stderr).contains("Run finished"));
}

#[test]
fn a_multi_process_run_draws_its_curve_too() {
    let _time = timed!();
    let dir = tmp("report-run");
    let out = dir.join("mp");
    let o = alfd()
        .args(["run", "--actors", "1", "--set", "episodes=10", "--out"])
        .arg(&out)
        .output()
        .expect("alfd runs");
    assert!(o.status.success(), "{}", text(&o));
    let line: serde_json::Value = serde_json::from_slice(&o.stdout).expect("the JSON line");
    assert_eq!(line["episodes"], 10);
    let err = String::from_utf8_lossy(&o.stderr);
    for needle in ["Run finished", "run directory", "processes", "learner.log"] {
        assert!(
            err.contains(needle),
            "{needle:?} missing from stderr:\n{err}"
        );
    }
    check_curve(&out, "(seed 0): mp");
}
