//! `alfd chaos`, short and seeded: a two-actor run under at least 30 faults of every kind (SIGKILL
//! and SIGSTOP of actors, learner and expert, expert swaps, the launcher killed and the run
//! resumed, and, as root, the run directory's file system filled and freed) keeps every
//! invariant: it finishes, every episode is in `episodes.csv` once, `demos.jsonl` is gap-free
//! within the budget and as counted, every checkpoint loads, nothing is left running. Two more
//! variants: Python environment adapters among the targets, a joined host (`alfd join` on
//! 127.0.0.1) among them, and the expert on a joined host behind a link slowed below what the
//! actors wait (its `demos.jsonl` must end as the start of the run's), and three experts in one
//! expert process under kills, pauses and swaps.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::support::{alfd, text, timed, tmp, Tmpfs};

/// The chaos run's report, once every invariant held and it exited 0 (else the test fails with
/// the broken ones and the run's output).
fn held(out: &Path, o: &std::process::Output) -> serde_json::Value {
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("chaos.json")).unwrap()).unwrap();
    let broken: Vec<&serde_json::Value> = report["invariants"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|v| v["ok"] != true)
        .collect();
    assert!(broken.is_empty(), "{broken:#?}\n{}", text(o));
    assert_eq!(o.status.code(), Some(0), "{}", text(o));
    report
}

/// `alfd chaos --out DIR/run --seed SEED ARGS` with a checkpoint every 300 updates, 300 s of
/// grace and 200-step episodes, `--set`ting `episodes`; the run directory and the output.
fn chaos(dir: &Path, seed: &str, episodes: u32, args: &[&str]) -> (PathBuf, Output) {
    let out = dir.join("run");
    let o = alfd()
        .args(["chaos", "--out", out.to_str().unwrap(), "--seed", seed])
        .args(["--checkpoint-every", "300", "--grace", "300"])
        .args(["--set", &format!("episodes={episodes}")])
        .args(["--set", "env.max_episode_steps=200"])
        .args(args)
        .output()
        .unwrap();
    (out, o)
}

/// The kind of a fault of `chaos.json` (`kill`, `pause`, `swap-expert`, `kill-launcher`,
/// `fill-disk`).
fn kind(event: &serde_json::Value) -> String {
    match &event["fault"] {
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Object(o) => o.keys().next().cloned().unwrap_or_default(),
        other => other.to_string(),
    }
}

/// At least 30 faults of every kind carried out, a fault every 0.2 s for 90 s of a run of 20,000
/// steps (the run directory on a tmpfs when run as root, for the disk faults).
#[test]
fn a_seeded_chaos_run_keeps_every_invariant() {
    let _time = timed!();
    let dir = tmp("chaos");
    let disk = Tmpfs::mount(&dir, 96);
    let (faults, kinds) = if disk.is_some() {
        (
            "kill=1,pause=1,swap=1,launcher=1,disk=1",
            &["kill", "pause", "swap-expert", "kill-launcher", "fill-disk"][..],
        )
    } else {
        eprintln!("chaos: no tmpfs (not root, or mount refused): the run goes without disk faults");
        (
            "kill=1,pause=1,swap=1,launcher=1",
            &["kill", "pause", "swap-expert", "kill-launcher"][..],
        )
    };
    let args = [
        "--duration",
        "90",
        "--every",
        "0.2",
        "--faults",
        faults,
        "--set",
        "steps=20000",
    ];
    let (out, o) = chaos(&dir, "13", 100_000, &args);
    let report = held(&out, &o);
    let events = report["events"].as_array().unwrap();
    for k in kinds {
        let carried_out = events
            .iter()
            .filter(|e| kind(e) == *k && e["carried_out"] == true)
            .count();
        assert!(carried_out >= 30, "{carried_out} {k} faults: {events:#?}");
    }
    assert!(report["launches"].as_u64().unwrap() >= 30);
    // The filler is gone with the faults.
    assert!(!out.join(".chaos-filler").exists());
}

#[test]
fn a_seeded_chaos_run_with_python_adapters_keeps_every_invariant() {
    let _time = timed!();
    let dir = tmp("chaos-gym");
    let args = [
        "--duration",
        "40",
        "--every",
        "1.2",
        // A Gymnasium run cannot be resumed (`alfd chaos` drops launcher kills on its own).
        "--faults",
        "kill=4,pause=3,launcher=1",
        "--set",
        "env.name=gymnasium",
        "--set",
        "env.id=CartPole-v1",
        "--set",
        "expert.name=python:alfd_examples:cartpole_balance",
    ];
    let (out, o) = chaos(&dir, "4", 200, &args);
    let report = held(&out, &o);
    let events = report["events"].as_array().unwrap();
    let adapters_hit = events
        .iter()
        .filter(|e| e["fault"].to_string().contains("adapter"))
        .filter(|e| e["carried_out"] == true)
        .count();
    assert!(events.len() >= 10, "{} faults", events.len());
    assert!(adapters_hit >= 1, "no adapter was hit: {events:#?}");
}

#[test]
fn a_seeded_chaos_run_with_a_joined_host_keeps_every_invariant() {
    let _time = timed!();
    let dir = tmp("chaos-remote");
    let args = [
        "--actors",
        "1",
        "--join-actors",
        "1",
        "--duration",
        "40",
        "--every",
        "1.2",
        // A resumed run listens on no port (`alfd chaos` drops launcher kills on its own).
        "--faults",
        "kill=4,pause=3,swap=1",
    ];
    let (out, o) = chaos(&dir, "5", 400, &args);
    let report = held(&out, &o);
    let events = report["events"].as_array().unwrap();
    let host_hit = events
        .iter()
        .filter(|e| e["fault"].to_string().contains("host"))
        .filter(|e| e["carried_out"] == true)
        .count();
    assert!(events.len() >= 10, "{} faults", events.len());
    assert!(host_hit >= 1, "the joined host was not hit: {events:#?}");
    // A killed host was started again (seed 5 kills it several times).
    assert!(
        report["joined_host"]["starts"].as_u64().unwrap() >= 2,
        "{report:#}"
    );
    // The joined host's actor (id 1, above the local actor 0) played episodes of the run.
    let episodes = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    let remote = episodes
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(8) == Some("1"))
        .count();
    assert!(remote >= 1, "no episode of the joined host's actor");
}

#[test]
fn a_seeded_chaos_run_with_its_expert_behind_a_slow_link_loses_no_demonstration() {
    let _time = timed!();
    let dir = tmp("chaos-slow-link");
    let args = [
        "--join-expert",
        "cartpole-200",
        "--duration",
        "40",
        "--every",
        "1.5",
        "--faults",
        "delay=3,swap=1,kill=1",
        "--set",
        "budget.total=2000",
        "--set",
        "query.rule=js-spread",
    ];
    let (out, o) = chaos(&dir, "3", 200, &args);
    let report = held(&out, &o);
    let host_file = report["invariants"]
        .as_array()
        .unwrap()
        .iter()
        .find(|v| v["name"] == "expert host's file");
    assert!(host_file.is_some_and(|v| v["ok"] == true), "{report:#}");
    let delays = report["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| kind(e) == "delay-link" && e["carried_out"] == true)
        .count();
    assert!(delays >= 5, "{delays} delays: {report:#}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    // The link was slower than the actors wait: answers came late, and none was refused.
    assert!(
        summary["answers_late"].as_u64().unwrap() >= 1,
        "{summary:#}"
    );
    assert_eq!(summary["demos_refused"], 0);
    let records = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    let remote = records
        .iter()
        .filter(|d| d.expert == "cartpole-200")
        .count();
    assert!(remote >= 50, "{remote} demonstrations of the remote expert");
}

/// Three experts (`[[experts]]`), each answering from a process of its own (two built-in ones'
/// `alfd-expert --member`, one Python adapter); the expert process killed, paused and swapped
/// (for one of them alone, and back to all three), the experts' processes killed and paused,
/// while the budget is spent across the run: every invariant holds, and every answer the panel gave is in `demos.jsonl` with its cost
/// and in `experts.csv`.
#[test]
fn a_seeded_chaos_run_with_several_experts_keeps_every_invariant() {
    let _time = timed!();
    let dir = tmp("chaos-experts");
    let config = dir.join("three.toml");
    // Each expert answers from a process of its own: kills and pauses aim at them too.
    let pump = "python:alfd_examples:acrobot_pump";
    let three = format!("acrobot-good+{pump}+acrobot-poor");
    std::fs::write(
        &config,
        format!(
            "seed = 2\nsteps = 90000\n[env]\nname = \"acrobot\"\n\
             [agent]\nkind = \"bdqn\"\nheads = 2\n\
             [query]\nallowance = \"spread\"\ngate = \"chance\"\nhorizon = 90000\n\
             [budget]\ntotal = 150\n[expert]\nmodel = \"krr\"\nroute = \"round-robin\"\n\
             double_ask = 0.2\n\
             [[experts]]\nname = \"acrobot-good\"\ncost = 10\n\
             [[experts]]\nname = \"{pump}\"\ncost = 2\n\
             [[experts]]\nname = \"acrobot-poor\"\ncost = 1\n"
        ),
    )
    .unwrap();
    let experts = format!("{three},acrobot-poor");
    let args = [
        "--config",
        config.to_str().unwrap(),
        "--duration",
        "30",
        "--every",
        "0.8",
        "--faults",
        "kill=3,pause=2,swap=1,launcher=1",
        "--experts",
        &experts,
    ];
    let (out, o) = chaos(&dir, "6", 100_000, &args);
    let report = held(&out, &o);
    let events = report["events"].as_array().unwrap();
    let expert_hit = events
        .iter()
        .filter(|e| e["carried_out"] == true)
        .filter(|e| e["fault"].to_string().contains("expert"))
        .count();
    assert!(
        expert_hit >= 1,
        "the experts' process was never hit: {events:#?}"
    );
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(out.join("demos.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let by_panel = lines.iter().filter(|l| l.get("cost").is_some()).count();
    let csv = std::fs::read_to_string(out.join("experts.csv")).unwrap();
    assert_eq!(
        csv.lines().count(),
        by_panel + 1,
        "a quality row per panel answer"
    );
    for name in ["acrobot-good", pump, "acrobot-poor"] {
        assert!(
            lines
                .iter()
                .any(|l| l["expert"] == name && l.get("cost").is_some()),
            "{name} never answered in the panel"
        );
    }
    let member_hit = events
        .iter()
        .filter(|e| e["carried_out"] == true)
        .filter(|e| e["fault"].to_string().contains("member"))
        .count();
    assert!(
        member_hit >= 1,
        "no expert's process was ever hit: {events:#?}"
    );
}
