//! The query rules (`query.rule`) as a user runs them: each one in `alfd local` and `alfd run`,
//! the matched `random` control replaying a recorded run's query steps, in one process and in a
//! sweep, and a missing schedule refused with exit code 2.

use std::path::Path;

use alfd_common::query::RuleKind;

use crate::runtime::summary;
use crate::support::{alfd, text, timed, tmp};

/// The global steps of a run's demonstrations, in order.
fn demo_steps(dir: &Path) -> Vec<u64> {
    alfd_demonstrators::demo_log::read(&dir.join("demos.jsonl"))
        .expect("demos.jsonl valid")
        .iter()
        .map(|d| d.step)
        .collect()
}

/// `alfd local` on the shipped BDQN + KRR CartPole config, 30 episodes, B = 12.
fn local(out: &Path, sets: &[&str]) -> std::process::Output {
    let mut c = alfd();
    c.args([
        "local",
        "--config",
        "deploy/configs/cartpole-bdqn-krr.toml",
        "--quiet",
        "--set",
        "episodes=30",
        "--set",
        "budget.total=12",
        "--set",
        "expert.name=cartpole-perfect",
    ])
    .arg(format!("--out={}", out.display()));
    for s in sets {
        c.args(["--set", s]);
    }
    c.output().expect("alfd runs")
}

#[test]
fn every_rule_runs_in_alfd_local_within_the_budget_and_random_replays_js_s_steps() {
    let _time = timed!();
    let js = tmp("rule-js");
    let o = local(&js, &["query.rule=js"]);
    assert!(o.status.success(), "{}", text(&o));
    let asked = demo_steps(&js);
    assert!(asked.len() >= 2, "the js run asked {asked:?}");
    let schedule = js.join("demos.jsonl");
    for kind in RuleKind::ALL {
        let out = tmp(&format!("rule-{}", kind.name()));
        let rule = format!("query.rule={}", kind.name());
        let sched = format!("query.schedule={}", schedule.display());
        // `random` on another seed: other states, the recorded run's steps.
        let seed = if kind == RuleKind::Random {
            "seed=5"
        } else {
            "seed=0"
        };
        // js-spread: B = 12 over H = 3,000 steps, the k-th (from 0) at step 250·k or later.
        let o = local(
            &out,
            &[
                &rule,
                &sched,
                "query.probability=0.05",
                "query.horizon=3000",
                seed,
            ],
        );
        assert!(o.status.success(), "{}: {}", kind.name(), text(&o));
        let steps = demo_steps(&out);
        assert!(
            steps.len() <= 12,
            "{}: {} demonstrations",
            kind.name(),
            steps.len()
        );
        assert_eq!(summary(&out)["demos_used"], steps.len(), "{}", kind.name());
        match kind {
            RuleKind::Never => assert!(steps.is_empty()),
            // The whole budget on the first steps.
            RuleKind::First => assert_eq!(steps, (0..12).collect::<Vec<u64>>()),
            RuleKind::Random => assert_eq!(steps, asked),
            RuleKind::JsSpread => {
                assert!(!steps.is_empty(), "js-spread asked nothing");
                for (k, &t) in steps.iter().enumerate() {
                    assert!(
                        t >= 250 * k as u64,
                        "demonstration {k} at step {t}: {steps:?}"
                    );
                }
            }
            // 600+ steps: every rule that asks at all spends some of its budget.
            _ => assert!(!steps.is_empty(), "{} asked nothing", kind.name()),
        }
    }
}

#[test]
fn a_random_rule_without_a_readable_schedule_is_refused_with_exit_code_2() {
    let _time = timed!();
    let out = tmp("no-schedule");
    let o = local(&out, &["query.rule=random"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("query.schedule"), "{}", text(&o));
    let o = local(
        &out,
        &[
            "query.rule=random",
            "query.schedule=/nonexistent/{seed}/demos.jsonl",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("/nonexistent/0/demos.jsonl"), "{t}");
    assert!(!out.join("episodes.csv").exists(), "nothing ran");
}

#[test]
fn alfd_run_accepts_the_rules_that_read_the_actor_s_own_signals() {
    let _time = timed!();
    for rule in ["js-burst", "novelty", "q-std", "uniform", "js-spread"] {
        let out = tmp(&format!("run-{rule}"));
        let o = crate::runtime::run(
            &out,
            2,
            &[
                "episodes=40",
                "budget.total=15",
                &format!("query.rule={rule}"),
                "query.probability=0.05",
                "query.horizon=4000",
            ],
        );
        assert!(o.status.success(), "{rule}: {}", text(&o));
        let demos = crate::runtime::check_run_dir(&out, 15);
        assert!(!demos.is_empty(), "{rule} asked nothing");
    }
}

/// A rule in two parts, an allowance and a gate, runs in `alfd run` as in `alfd local`: every
/// demonstration in both files, within the budget, none after the run's end.
#[test]
fn alfd_run_accepts_a_rule_given_as_an_allowance_and_a_gate() {
    let _time = timed!();
    for (allowance, gate) in [
        ("spread", "chance"),
        ("uniform", "record"),
        ("first", "novelty"),
    ] {
        let out = tmp(&format!("run-{allowance}-{gate}"));
        let o = crate::runtime::run(
            &out,
            2,
            &[
                "episodes=40",
                "budget.total=15",
                "query.rule=never",
                &format!("query.allowance={allowance}"),
                &format!("query.gate={gate}"),
                "query.horizon=4000",
            ],
        );
        assert!(o.status.success(), "{allowance}+{gate}: {}", text(&o));
        let demos = crate::runtime::check_run_dir(&out, 15);
        assert!(!demos.is_empty(), "{allowance}+{gate} asked nothing");
    }
}

#[test]
fn a_sweep_replays_another_seed_s_js_steps_in_its_random_method() {
    let _time = timed!();
    let dir = tmp("rule-sweep");
    let exp = dir.join("rules.toml");
    let config = crate::support::repo().join("deploy/configs/cliffwalk-bootstrapped.toml");
    std::fs::write(
        &exp,
        format!(
            "title = \"rules\"\nseeds = 2\nepisodes = 60\nby_budget = true\n\
             learner_episodes_only = true\n\
             [[method]]\nname = \"random-b10\"\nlabel = \"random\"\nconfig = \"{c}\"\n\
             set = [\"query.rule=random\", \"budget.total=10\", \
             \"query.schedule={{out}}/runs/js-b10/{{other_seed}}/demos.jsonl\"]\n\
             [[method]]\nname = \"js-b10\"\nlabel = \"js\"\nconfig = \"{c}\"\n\
             set = [\"query.rule=js\", \"budget.total=10\"]\n\
             [[method]]\nname = \"never\"\nlabel = \"never\"\nconfig = \"{c}\"\n\
             set = [\"query.rule=never\", \"budget.total=0\"]\n",
            c = config.display()
        ),
    )
    .unwrap();
    let out = dir.join("out");
    let o = alfd()
        .args(["sweep", "--jobs", "2", "--config"])
        .arg(&exp)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    // Each seed replays the other seed's js steps (the last seed's "next" is the first).
    for (seed, other) in [("0", "1"), ("1", "0")] {
        let js = demo_steps(&out.join("runs/js-b10").join(other));
        assert!(!js.is_empty());
        let run = out.join("runs/random-b10").join(seed);
        // The steps of the other run this run reached.
        let steps: u64 = crate::runtime::rows(&run).last().unwrap()[7]
            .parse()
            .unwrap();
        let reached: Vec<u64> = js.into_iter().filter(|&t| t < steps).collect();
        assert!(!reached.is_empty());
        assert_eq!(demo_steps(&run), reached, "seed {seed}");
    }
    let csv = std::fs::read_to_string(out.join("by-budget.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 3, "{csv}");
    assert!(rows.iter().any(|r| r.starts_with("never,0,2,")), "{csv}");
    assert!(rows.iter().any(|r| r.starts_with("random,10,2,")), "{csv}");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("## Query rules by budget"), "{md}");
    // The runs table says what its learner-only columns leave out.
    assert!(
        md.contains("With `learner_episodes_only`, \"last 50\" count only the episodes"),
        "{md}"
    );
    assert!(out.join("rules-by-budget-eval.svg").exists());
}
