//! `alfd demo-model`: the same numbers on any number of threads, and the limits it refuses.

use crate::cli::{alfd, assert_usage_error, stderr};
use crate::support::{timed, tmp};

#[test]
fn demo_model_gives_the_same_numbers_on_any_number_of_threads() {
    let _time = timed!();
    let dir = tmp("demo-model-threads");
    let (demos, query) = (dir.join("demos.jsonl"), dir.join("query.jsonl"));
    // 2,400 demonstrations: KRR's factorisation shares its blocks' updates among the threads
    // from `LANES_FROM` (2,048) demonstrations on.
    let line = |i: usize| {
        let t = i as f64;
        let s = [
            (t * 0.37).sin() * 2.0,
            (t * 0.11).cos() * 3.0,
            (t * 0.05).sin() * 0.2,
        ];
        format!(
            "{{\"state\":{s:?},\"action\":{}}}\n",
            u8::from(s[2] + 0.05 * s[1] > 0.0)
        )
    };
    std::fs::write(&demos, (0..2400).map(line).collect::<String>()).unwrap();
    std::fs::write(
        &query,
        "{\"state\":[0.1,-0.5,0.02]}\n{\"state\":[1,2,-0.1]}\n",
    )
    .unwrap();
    let (d, q) = (demos.to_str().unwrap(), query.to_str().unwrap());
    for kind in ["krr", "svm"] {
        let out = |threads: &str| {
            let args = [
                "demo-model",
                "--kind",
                kind,
                "--demos",
                d,
                "--query",
                q,
                "--threads",
                threads,
            ];
            let o = alfd(&args);
            assert!(o.status.success(), "{args:?}: {}", stderr(&o));
            String::from_utf8(o.stdout).unwrap()
        };
        let one = out("1");
        assert_eq!(one.lines().count(), 2, "{one}");
        assert_eq!(out("3"), one, "{kind}");
    }
    let args = [
        "demo-model",
        "--kind",
        "krr",
        "--demos",
        d,
        "--query",
        q,
        "--threads",
        "0",
    ];
    assert_usage_error(&args, "--threads");
}

#[test]
fn demo_model_refuses_an_absurd_number_of_actions_or_demonstrations() {
    let _time = timed!();
    let dir = tmp("demo-model-limits");
    let (demos, query) = (dir.join("demos.jsonl"), dir.join("query.jsonl"));
    std::fs::write(
        &demos,
        "{\"state\":[0,1],\"action\":1}\n{\"state\":[1,0],\"action\":0}\n",
    )
    .unwrap();
    std::fs::write(&query, "{\"state\":[0.5,0.5]}\n").unwrap();
    let (d, q) = (demos.to_str().unwrap(), query.to_str().unwrap());
    let fit = |extra: &[&str]| {
        let mut args = vec!["demo-model", "--kind", "krr", "--demos", d, "--query", q];
        args.extend_from_slice(extra);
        args.into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    let args = fit(&["--actions", "100000000000"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert_usage_error(
        &args,
        "--actions 100000000000: a demonstration model handles at most 1024 actions",
    );
    // The largest number of actions still fits.
    let args = fit(&["--actions", "1024"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = alfd(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    // Without --actions, the largest demonstrated action sets it.
    std::fs::write(&demos, "{\"state\":[0,1],\"action\":100000000000}\n").unwrap();
    let args = fit(&[]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert_usage_error(
        &args,
        &format!("{d}:1: action 100000000000 is too large: a demonstration model handles at most 1024 actions"),
    );
    std::fs::write(&demos, "{\"state\":[0,1],\"action\":1}\n".repeat(10_001)).unwrap();
    assert_usage_error(
        &args,
        &format!("{d}: 10001 demonstrations, but a demonstration model is fitted on at most 10000"),
    );
    // The Nyström model takes them (20,000 demonstrations of two states with their actions): at
    // the demonstrated states, each action's probability.
    let half = "{\"state\":[0,1],\"action\":1}\n{\"state\":[1,0],\"action\":0}\n";
    std::fs::write(&demos, half.repeat(10_000)).unwrap();
    std::fs::write(&query, "{\"state\":[0,1]}\n{\"state\":[1,0]}\n").unwrap();
    let o = alfd(&[
        "demo-model",
        "--kind",
        "nystrom",
        "--demos",
        d,
        "--query",
        q,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let p1 = |i: usize| lines[i]["probs"][1].as_f64().unwrap();
    assert!(lines.len() == 2 && p1(0) > 0.9 && p1(1) < 0.1, "{lines:?}");
    assert_usage_error(
        &["demo-model-policy", "--demos", "100000", "--runs", "1"],
        "--demos 100000: a demonstration model is fitted on at most 10000 demonstrations",
    );
}

#[test]
fn demo_model_weighs_each_demonstration_by_its_weight_as_a_run_does() {
    let _time = timed!();
    let dir = tmp("demo-model-weights");
    let (demos, query) = (dir.join("demos.jsonl"), dir.join("query.jsonl"));
    std::fs::write(&query, "{\"state\":[0,0]}\n").unwrap();
    let (d, q) = (demos.to_str().unwrap(), query.to_str().unwrap());
    let args = ["demo-model", "--kind", "krr", "--demos", d, "--query", q];
    // Two answers at one state that contradict each other.
    let probs = |second: &str| {
        let lines =
            format!("{{\"state\":[0,0],\"action\":0}}\n{{\"state\":[0,0],\"action\":1{second}}}\n");
        std::fs::write(&demos, lines).unwrap();
        let o = alfd(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let line: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let p: Vec<f64> = serde_json::from_value(line["probs"].clone()).unwrap();
        p
    };
    let even = probs("");
    assert!(
        (even[0] - even[1]).abs() < 1e-12,
        "no weight: 1 each, {even:?}"
    );
    assert_eq!(probs(",\"weight\":1.0"), even, "weight 1 is no weight");
    // Weight 0 leaves the second answer out: the first one's action wins.
    let first = probs(",\"weight\":0.0");
    assert!(first[0] > first[1], "{first:?}");
    let half = probs(",\"weight\":0.5");
    assert!(first[0] > half[0] && half[0] > even[0], "{half:?}");
    std::fs::write(&demos, "{\"state\":[0,0],\"action\":0,\"weight\":-1}\n").unwrap();
    assert_usage_error(
        &args,
        &format!("{d}:1: weight -1 is not a finite number ≥ 0"),
    );
}
