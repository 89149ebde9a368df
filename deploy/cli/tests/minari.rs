//! Minari datasets both ways, checked with the pinned `minari` package of the project's
//! `.venv/`: a run's episodes exported by `alfd demos export` load with `minari.load_dataset`
//! (every transition, the demonstrated ones marked, the environment recoverable), and a
//! dataset written by `minari` seeds a run through `demos.prior`.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

use crate::support::{alfd, repo, text, timed, tmp};

const CONFIG: &str = "deploy/configs/cartpole-bdqn-krr.toml";

/// The project's Python, with `MINARI_DATASETS_PATH=root`, running `minari_check.py args`.
fn minari(root: &Path, args: &[&str]) -> Value {
    let o = Command::new(crate::support::project_python())
        .arg(repo().join("deploy/cli/tests/minari_check.py"))
        .args(args)
        .env("MINARI_DATASETS_PATH", root)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn local(out: &Path, sets: &[&str], extra: &[&str]) -> std::process::Output {
    let mut c = alfd();
    c.args([
        "local",
        "--config",
        CONFIG,
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    for s in sets {
        c.args(["--set", s]);
    }
    c.args(extra).output().unwrap()
}

/// `alfd demos export RUN --out OUT`.
fn export(run: &Path, out: &Path) -> std::process::Output {
    let (run, out) = (run.to_str().unwrap(), out.to_str().unwrap());
    alfd()
        .args(["demos", "export", run, "--out", out])
        .output()
        .unwrap()
}

fn json_lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn a_run_exported_loads_in_minari_and_a_minari_dataset_seeds_a_run() {
    let _time = timed!();
    let dir = tmp("minari");
    let root = dir.join("datasets");
    // A run that records its transitions, exported.
    let run = dir.join("run");
    let sets = [
        "episodes=12",
        "budget.total=15",
        "env.max_episode_steps=150",
    ];
    let o = local(&run, &sets, &["--transitions"]);
    assert!(o.status.success(), "{}", text(&o));
    let out = root.join("alfd/cartpole-run-v0");
    let o = export(&run, &out);
    assert!(o.status.success(), "{}", text(&o));
    let m = minari(&root, &["load", "alfd/cartpole-run-v0"]);
    let recorded = json_lines(&run.join("transitions.jsonl"));
    let episodes = &recorded[1..];
    let demos = json_lines(&run.join("demos.jsonl"));
    assert_eq!(m["total_episodes"], 12);
    let lengths: Vec<u64> = episodes
        .iter()
        .map(|e| e["actions"].as_array().unwrap().len() as u64)
        .collect();
    assert_eq!(m["lengths"], serde_json::json!(lengths));
    assert_eq!(m["total_steps"], lengths.iter().sum::<u64>());
    let csv = std::fs::read_to_string(run.join("episodes.csv")).unwrap();
    let csv_lengths: Vec<u64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    assert_eq!(csv_lengths, lengths, "the same episodes as episodes.csv");
    // Every demonstration of the run is marked, at its step.
    let marked: u64 = m["demonstrated"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert!(!demos.is_empty());
    assert_eq!(marked, demos.len() as u64);
    let as_f32 = |v: &Value| -> Vec<f32> {
        let values = v.as_array().unwrap().iter();
        values.map(|x| x.as_f64().unwrap() as f32).collect()
    };
    let first = as_f32(&episodes[0]["observations"][1]);
    let loaded = as_f32(&m["first_observations"][1]);
    assert_eq!(first, loaded, "observations to the bit (f32)");
    assert_eq!(
        m["first_actions"],
        serde_json::json!(episodes[0]["actions"].as_array().unwrap()[..3])
    );
    assert_eq!(
        (m["env_id"].as_str(), m["max_episode_steps"].as_u64()),
        (Some("CartPole-v1"), Some(150))
    );
    assert_eq!(
        (m["observation_shape"].clone(), m["actions"].clone()),
        (serde_json::json!([4]), serde_json::json!(2))
    );
    // A run stopped and resumed records the same transitions as the run without a stop.
    let stopped = dir.join("stopped");
    let extra = [
        "--transitions",
        "--checkpoint-every",
        "3",
        "--stop-after-episodes",
        "7",
    ];
    let o = local(&stopped, &sets, &extra);
    assert!(o.status.success(), "{}", text(&o));
    let o = alfd()
        .args(["resume", stopped.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let read = |d: &Path| std::fs::read_to_string(d.join("transitions.jsonl")).unwrap();
    assert_eq!(read(&stopped), read(&run));
    // Exporting again into the same directory is refused, the dataset kept.
    let again = export(&run, &out);
    assert_eq!(again.status.code(), Some(2), "{}", text(&again));
    assert!(text(&again).contains("holds a dataset already"));

    // A dataset written by minari seeds a run: with potential shaping and no budget, only the
    // prior demonstrations can make a demonstration model, so shaped steps show it was read.
    let w = minari(&root, &["write", "test/cartpole-weak-v0", "6"]);
    let prior_steps = w["total_steps"].as_u64().unwrap();
    let seeded = |out: &Path, prior: Option<&Path>| {
        let mut sets = vec![
            "episodes=4".to_owned(),
            "budget.total=0".to_owned(),
            "shaping.kind=\"potential\"".to_owned(),
            "shaping.min_demos=1".to_owned(),
        ];
        if let Some(p) = prior {
            sets.push(format!("demos.prior=\"{}\"", p.display()));
        }
        let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
        let o = local(out, &sets, &[]);
        assert!(o.status.success(), "{}", text(&o));
        let csv = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
        let shaped: u64 = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(6).unwrap().parse::<u64>().unwrap())
            .sum();
        let summary: Value =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
        (shaped, summary["demos_used"].as_u64().unwrap())
    };
    let weak = root.join("test/cartpole-weak-v0");
    let (with, used) = seeded(&dir.join("seeded"), Some(&weak));
    let (without, _) = seeded(&dir.join("unseeded"), None);
    assert!(
        prior_steps > 6 && with > 0 && without == 0,
        "{prior_steps} {with} {without}"
    );
    assert_eq!(used, 0, "the prior spends no budget");
    // Our own export as a prior: its marked steps only.
    let (from_export, _) = seeded(&dir.join("from-export"), Some(&out));
    assert!(from_export > 0);

    // What cannot seed a run is refused before anything is written.
    let missing = dir.join("no-such-dataset");
    let bad = local(
        &dir.join("bad"),
        &[&format!("demos.prior=\"{}\"", missing.display())],
        &[],
    );
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad));
    assert!(
        text(&bad).contains("is not a Minari dataset"),
        "{}",
        text(&bad)
    );
    assert!(!dir.join("bad/config.toml").exists());
    let weak_prior = format!("demos.prior=\"{}\"", weak.display());
    let too_many = local(&dir.join("bad"), &["budget.total=9900", &weak_prior], &[]);
    assert_eq!(too_many.status.code(), Some(2), "{}", text(&too_many));
    assert!(text(&too_many).contains("more than the demonstration model"));
    let acrobot = local(
        &dir.join("bad"),
        &[
            "env.name=\"acrobot\"",
            &format!("demos.prior=\"{}\"", weak.display()),
        ],
        &[],
    );
    assert_eq!(acrobot.status.code(), Some(2), "{}", text(&acrobot));
    assert!(
        text(&acrobot).contains("the config's environment has 6 and 3"),
        "{}",
        text(&acrobot)
    );
    // `alfd run` seeds its learner and its expert from the same dataset.
    let multi = dir.join("multi");
    let o = alfd()
        .args(["run", "--config", CONFIG, "--actors", "1", "--quiet"])
        .args(["--out", multi.to_str().unwrap()])
        .args(["--set", "episodes=4", "--set", "budget.total=0"])
        .args([
            "--set",
            "shaping.kind=\"potential\"",
            "--set",
            "shaping.min_demos=1",
        ])
        .args(["--set", &format!("demos.prior=\"{}\"", weak.display())])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let lines = std::fs::read_to_string(multi.join("prior-demos.jsonl")).unwrap();
    assert_eq!(lines.lines().count() as u64, prior_steps);
    let log = |name: &str| std::fs::read_to_string(multi.join(name)).unwrap();
    assert!(log("learner.log").contains("prior demonstrations in the replay buffer"));
    assert!(log("expert-1.log").contains("prior demonstrations in the demonstration model"));
    let csv = std::fs::read_to_string(multi.join("episodes.csv")).unwrap();
    let shaped = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(6).unwrap().parse::<u64>().unwrap());
    assert!(shaped.sum::<u64>() > 0, "{csv}");
    // A run without recorded transitions cannot be exported.
    let plain = alfd()
        .args([
            "demos",
            "export",
            dir.join("seeded").to_str().unwrap(),
            "--out",
        ])
        .arg(root.join("alfd/plain-v0"))
        .output()
        .unwrap();
    assert_eq!(plain.status.code(), Some(2), "{}", text(&plain));
    assert!(
        text(&plain).contains("alfd local --transitions"),
        "{}",
        text(&plain)
    );
}
