//! TensorBoard event files, read back with TensorBoard's own reader (the pinned `tensorboard`
//! package of the project's `.venv/`): `alfd local` and a 2-actor `alfd run` (the launcher's,
//! the learner's and each actor's file under one `tb/`) write every tag the manual names, at the
//! run's environment steps, with the values of `episodes.csv`; and `logging.tensorboard = false`
//! writes none. (`faults` reads a resumed run's files with [`read`] too.)

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use crate::support::{alfd, repo, text, timed, tmp};

const CONFIG: &str = "deploy/configs/cartpole-bdqn-krr.toml";

type Scalars = BTreeMap<String, Vec<(u64, f64)>>;

/// Every scalar under `logdir`, as TensorBoard reads it.
pub(crate) fn read(logdir: &Path) -> Scalars {
    let o = Command::new(crate::support::project_python())
        .arg(repo().join("deploy/cli/tests/tb_read.py"))
        .arg(logdir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Column `name` of `episodes.csv` in `dir`, with `total_steps`.
pub(crate) fn column(dir: &Path, name: &str) -> Vec<(u64, String)> {
    let csv = std::fs::read_to_string(dir.join("episodes.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at = |n: &str| head.iter().position(|h| *h == n).unwrap();
    let (i, steps) = (at(name), at("total_steps"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[steps].parse().unwrap(), f[i].to_owned())
        })
        .collect()
}

const EPISODE_TAGS: [&str; 9] = [
    "rollout/ep_rew_mean",
    "rollout/ep_len_mean",
    "eval/mean_reward",
    "time/fps",
    "query/js",
    "query/gate_fired",
    "demos/used",
    "demos/budget_left",
    "actor/0/sps",
];

#[test]
fn alfd_local_writes_sb3_s_tags_and_its_own_with_the_values_of_episodes_csv() {
    let _time = timed!();
    let dir = tmp("tb-local");
    let out = dir.join("run");
    let o = alfd()
        .args(["local", "--config", CONFIG, "--quiet", "--out"])
        .arg(&out)
        .args(["--set", "episodes=12", "--set", "budget.total=20"])
        .args([
            "--set",
            "evaluation.every=4",
            "--set",
            "evaluation.episodes=2",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let s = read(&out.join("tb"));
    for tag in EPISODE_TAGS {
        assert!(s.contains_key(tag), "no `{tag}` in {:?}", s.keys());
    }
    // One value per episode, at its total steps; the demonstrations as episodes.csv has them.
    let demos = column(&out, "demos_used");
    let got: Vec<(u64, f64)> = s["demos/used"].clone();
    let want: Vec<(u64, f64)> = demos
        .iter()
        .map(|(t, v)| (*t, v.parse().unwrap()))
        .collect();
    assert_eq!(got, want);
    let left: Vec<f64> = s["demos/budget_left"].iter().map(|p| p.1).collect();
    assert_eq!(left, want.iter().map(|p| 20.0 - p.1).collect::<Vec<_>>());
    // The first rolling mean is the first return; the evaluations are the non-empty ones.
    let returns = column(&out, "return");
    assert_eq!(
        s["rollout/ep_rew_mean"][0].1,
        returns[0].1.parse::<f64>().unwrap()
    );
    let evals: Vec<(u64, f64)> = column(&out, "eval_return")
        .into_iter()
        .filter(|(_, v)| !v.is_empty())
        .map(|(t, v)| (t, v.parse().unwrap()))
        .collect();
    assert_eq!(evals.len(), 3);
    let read_evals: Vec<(u64, f64)> = s["eval/mean_reward"].clone();
    assert_eq!(read_evals.len(), evals.len());
    for (a, b) in read_evals.iter().zip(&evals) {
        assert_eq!(a.0, b.0);
        assert!((a.1 - b.1).abs() < 1e-3, "{a:?} {b:?} (a float32 of it)");
    }
    // Turned off: no tb/ at all.
    let off = dir.join("off");
    let o = alfd()
        .args(["local", "--config", CONFIG, "--quiet", "--out"])
        .arg(&off)
        .args(["--set", "episodes=2", "--set", "logging.tensorboard=false"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(!off.join("tb").exists());
}

#[test]
fn a_two_actor_alfd_run_shows_each_actor_and_the_learner() {
    let _time = timed!();
    let dir = tmp("tb-run");
    let out = dir.join("run");
    let o = alfd()
        .args([
            "run", "--config", CONFIG, "--actors", "2", "--quiet", "--out",
        ])
        .arg(&out)
        .args(["--set", "episodes=30", "--set", "evaluation.every=10"])
        .args(["--set", "evaluation.episodes=1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let s = read(&out.join("tb"));
    for tag in EPISODE_TAGS.iter().chain(&[
        "actor/1/sps",
        "learner/td_loss",
        "learner/updates_per_s",
        "learner/q_mean",
        "expert/answer_wait_ms",
    ]) {
        assert!(s.contains_key(*tag), "no `{tag}` in {:?}", s.keys());
    }
    assert_eq!(s["demos/used"].len(), column(&out, "demos_used").len());
    // The learner's updates never go down, and its loss is a number.
    let updates: Vec<f64> = s["learner/updates"].iter().map(|p| p.1).collect();
    assert!(updates.windows(2).all(|w| w[0] <= w[1]), "{updates:?}");
    assert!(s["learner/td_loss"].iter().all(|p| p.1.is_finite()));
    assert!(s["learner/q_mean"].iter().all(|p| p.1.is_finite()));
    // Each actor's waits for the expert, in milliseconds: never negative.
    assert!(s["expert/answer_wait_ms"].iter().all(|p| p.1 >= 0.0));
    // The launcher's counts of restarts and swaps: written at the start, none happened.
    for tag in [
        "run/actor_restarts",
        "run/learner_restarts",
        "run/expert_restarts",
        "run/expert_swaps",
    ] {
        assert!(
            s.get(tag)
                .is_some_and(|v| !v.is_empty() && v.iter().all(|p| p.1 == 0.0)),
            "{tag}: {:?}",
            s.get(tag)
        );
    }
}
