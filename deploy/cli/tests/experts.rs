//! Several experts at once (`[[experts]]`) from the command line: `alfd local` routes each query,
//! records who answered at what cost in `demos.jsonl` and the experts' qualities in
//! `experts.csv`; the same config twice gives the same files; `alfd run` hosts them in its expert
//! process, one actor in lockstep giving `alfd local`'s files to the byte.

use serde_json::Value;

use crate::support::{alfd, text, timed, tmp};

const CONFIG: &str = "seed = 3\nsteps = 6000\n[env]\nname = \"mountaincar\"\n\
    [agent]\nkind = \"bdqn\"\nheads = 2\n[query]\nallowance = \"spread\"\ngate = \"chance\"\n\
    horizon = 6000\n[budget]\ntotal = 30\n[expert]\nroute = \"round-robin\"\ndouble_ask = 0.5\n\
    [[experts]]\nname = \"mountaincar-energy\"\ncost = 10\n\
    [[experts]]\nname = \"mountaincar-fair\"\ncost = 2\n\
    [[experts]]\nname = \"mountaincar-poor\"\ncost = 1\n";

#[test]
fn alfd_local_asks_several_experts_and_records_who_answered_at_what_cost() {
    let _time = timed!();
    let dir = tmp("experts");
    let config = dir.join("three.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let run = |name: &str| {
        let out = dir.join(name);
        let o = alfd()
            .args(["local", "--config"])
            .arg(&config)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        out
    };
    let (a, b) = (run("a"), run("b"));
    let demos = std::fs::read_to_string(a.join("demos.jsonl")).unwrap();
    let lines: Vec<Value> = demos
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 30, "the whole budget is spent");
    let cost = |name: &str| match name {
        "mountaincar-energy" => 10.0,
        "mountaincar-fair" => 2.0,
        "mountaincar-poor" => 1.0,
        other => panic!("an expert outside the panel: {other}"),
    };
    for l in &lines {
        assert_eq!(
            l["cost"].as_f64().unwrap(),
            cost(l["expert"].as_str().unwrap()),
            "{l}"
        );
    }
    // Round-robin: every expert answers, and some states were asked twice.
    for name in ["mountaincar-energy", "mountaincar-fair", "mountaincar-poor"] {
        assert!(
            lines.iter().any(|l| l["expert"] == name),
            "{name} never answered"
        );
    }
    let doubles = lines.iter().filter(|l| l["double_asked"] == true).count();
    assert!(doubles >= 2, "{doubles} answers of double asks");
    let csv = std::fs::read_to_string(a.join("experts.csv")).unwrap();
    assert!(
        csv.starts_with("step,expert,answers,quality,low,high\n"),
        "{csv}"
    );
    assert_eq!(csv.lines().count(), 31, "one row per answer");
    // The same config, the same files.
    for f in ["demos.jsonl", "experts.csv", "episodes.csv"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}"
        );
    }
}

#[test]
fn several_experts_are_refused_where_they_cannot_run() {
    let _time = timed!();
    let dir = tmp("experts-refused");
    let config = dir.join("three.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let o = alfd()
        .args([
            "run",
            "--actors",
            "1",
            "--expert",
            "mountaincar-poor",
            "--config",
        ])
        .arg(&config)
        .arg("--out")
        .arg(dir.join("run"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("leave --expert out"), "{}", text(&o));
    assert!(!dir.join("run").exists(), "nothing written");
    let o = alfd()
        .args(["local", "--checkpoint-every", "2", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(dir.join("ckpt"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("several experts"), "{}", text(&o));
    let both = CONFIG.replace("[expert]\n", "[expert]\nname = \"mountaincar-poor\"\n");
    std::fs::write(&config, both).unwrap();
    let o = alfd()
        .args(["local", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(dir.join("both"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("leave `expert.name` out"), "{}", text(&o));
    assert!(!dir.join("both").exists(), "nothing written");
}

#[test]
fn alfd_run_hosts_several_experts_as_alfd_local_does_to_the_byte() {
    let _time = timed!();
    let dir = tmp("experts-run");
    let config = dir.join("three.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let run = |name: &str, how: &[&str]| {
        let out = dir.join(name);
        let o = alfd()
            .args(how)
            .args(["--quiet", "--config"])
            .arg(&config)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{how:?}: {}", text(&o));
        out
    };
    let local = run("local", &["local"]);
    let lockstep = run("lockstep", &["run", "--actors=1", "--window=1"]);
    for f in ["episodes.csv", "demos.jsonl", "experts.csv"] {
        assert_eq!(
            std::fs::read_to_string(lockstep.join(f)).unwrap(),
            std::fs::read_to_string(local.join(f)).unwrap(),
            "{f}"
        );
    }
    // Two actors: the whole budget spent, by every expert at its cost, a quality row per answer.
    let two = run("two", &["run", "--actors=2"]);
    let lines: Vec<Value> = std::fs::read_to_string(two.join("demos.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 30, "the whole budget is spent");
    for (name, cost) in [
        ("mountaincar-energy", 10.0),
        ("mountaincar-fair", 2.0),
        ("mountaincar-poor", 1.0),
    ] {
        let mine: Vec<&Value> = lines.iter().filter(|l| l["expert"] == name).collect();
        assert!(!mine.is_empty(), "{name} never answered");
        assert!(
            mine.iter().all(|l| l["cost"].as_f64() == Some(cost)),
            "{name}"
        );
    }
    let csv = std::fs::read_to_string(two.join("experts.csv")).unwrap();
    assert_eq!(csv.lines().count(), 31, "one row per answer: {csv}");
    assert!(two.join("experts.svg").exists(), "the qualities are drawn");
}
