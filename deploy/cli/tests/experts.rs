//! Several experts at once (`[[experts]]`) from the command line: `alfd local` routes each query,
//! records who answered at what cost in `demos.jsonl` and the experts' qualities in
//! `experts.csv`; the same config twice gives the same files; `alfd run` hosts them in its expert
//! process, one actor in lockstep giving `alfd local`'s files to the byte.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::support::{alfd, text, timed, tmp};

const CONFIG: &str = "seed = 3\nsteps = 6000\n[env]\nname = \"mountaincar\"\n\
    [agent]\nkind = \"bdqn\"\nheads = 2\n[query]\nallowance = \"spread\"\ngate = \"chance\"\n\
    horizon = 6000\n[budget]\ntotal = 30\n[expert]\nroute = \"round-robin\"\ndouble_ask = 0.5\n\
    quality_from_returns = true\n[[experts]]\nname = \"mountaincar-energy\"\ncost = 10\n\
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

const DEEPSEA_QTABLES: &str = "seed = 5\nepisodes = 300\n[env]\nname = \"deepsea\"\nsize = 12\n\
    [agent]\nkind = \"bootstrapped-q\"\n[query]\nallowance = \"spread\"\ngate = \"chance\"\n\
    horizon = 2400\n[budget]\ntotal = 40\n[expert]\nroute = \"round-robin\"\ndouble_ask = 0.5\n\
    [[experts]]\nname = \"deepsea-good\"\ncost = 10\nbecomes = \"deepsea-poor\"\nafter = 5\n\
    [[experts]]\nname = \"deepsea-optimal\"\ncost = 2\n";

#[test]
fn q_tables_ask_several_experts_in_alfd_local_and_record_who_answered_at_what_cost() {
    let _time = timed!();
    let dir = tmp("experts-qtables");
    let config = dir.join("deepsea.toml");
    std::fs::write(&config, DEEPSEA_QTABLES).unwrap();
    let (a, b) = (
        run_quietly(&dir.join("a"), &config, &["local"]),
        run_quietly(&dir.join("b"), &config, &["local"]),
    );
    let lines: Vec<Value> = std::fs::read_to_string(a.join("demos.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["demos_used"], lines.len(), "{summary}");
    assert!(
        lines.len() > 30,
        "most of the budget of 40 is spent: {}",
        lines.len()
    );
    let (mut spent, mut doubles) = (0.0, 0);
    for l in &lines {
        let cost = match l["expert"].as_str().unwrap() {
            "deepsea-good" => 10.0,
            "deepsea-optimal" => 2.0,
            other => panic!("an expert outside the panel: {other}"),
        };
        assert_eq!(l["cost"].as_f64().unwrap(), cost, "{l}");
        spent += cost;
        doubles += usize::from(l["double_asked"] == true);
    }
    assert!(doubles >= 2, "{doubles} answers of double asks");
    // On a double ask both answer the same state: the optimal expert the move right, the good
    // one, once it answers as the poor one, sometimes not. Two experts share their agreements,
    // so both qualities fall below 1, each within its interval.
    let csv = std::fs::read_to_string(a.join("experts.csv")).unwrap();
    assert_eq!(csv.lines().count(), lines.len() + 1, "one row per answer");
    for row in csv.lines().skip(1) {
        let v: Vec<f64> = row.split(',').skip(3).map(|x| x.parse().unwrap()).collect();
        assert!(v[1] <= v[0] && v[0] <= v[2], "{row}");
    }
    for name in ["deepsea-good", "deepsea-optimal"] {
        let row = csv.lines().rfind(|r| r.contains(name)).unwrap();
        let quality: f64 = row.split(',').nth(3).unwrap().parse().unwrap();
        assert!(quality < 1.0, "{row}");
    }
    assert!(
        spent > 2.0 * lines.len() as f64,
        "the good expert answered too: {spent}"
    );
    for f in ["demos.jsonl", "experts.csv", "episodes.csv", "policy.json"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}"
        );
    }
    // A Q-table agent's experts are built-in ones: a Python policy is refused, nothing written.
    let python = DEEPSEA_QTABLES.replace("\"deepsea-optimal\"", "\"python:m:f\"");
    std::fs::write(&config, python).unwrap();
    let o = alfd()
        .args(["local", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(dir.join("python"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("`python:m:f`: a Q-table agent's experts"),
        "{}",
        text(&o)
    );
    assert!(!dir.join("python").exists(), "nothing written");
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
    // `alfd local` refuses `toml` as a config with exit code 2, saying `says`, writing nothing.
    let refused = |name: &str, toml: String, says: &str| {
        std::fs::write(&config, toml).unwrap();
        let o = alfd()
            .args(["local", "--config"])
            .arg(&config)
            .arg("--out")
            .arg(dir.join(name))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        assert!(text(&o).contains(says), "{}", text(&o));
        assert!(!dir.join(name).exists(), "nothing written");
    };
    let both = CONFIG.replace("[expert]\n", "[expert]\nname = \"mountaincar-poor\"\n");
    refused("both", both, "leave `expert.name` out");
    // A person answers on a page, which only `alfd run`'s expert process serves.
    let person = CONFIG.replace("name = \"mountaincar-poor\"", "name = \"human\"");
    refused("person", person, "in `alfd run` only");
}

/// Runs `alfd HOW --quiet --config CONFIG --out OUT`, which must succeed; `out`.
fn run_quietly(out: &Path, config: &Path, how: &[&str]) -> PathBuf {
    let o = alfd()
        .args(how)
        .args(["--quiet", "--config"])
        .arg(config)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{how:?}: {}", text(&o));
    out.to_path_buf()
}

/// `alfd local` and one actor of `alfd run` in lockstep on `config`, into `DIR/local` and
/// `DIR/lockstep`: their `episodes.csv`, `demos.jsonl` and `experts.csv` are equal to the byte.
fn local_equals_lockstep(dir: &Path, config: &Path) -> (PathBuf, PathBuf) {
    let local = run_quietly(&dir.join("local"), config, &["local"]);
    let lockstep = run_quietly(
        &dir.join("lockstep"),
        config,
        &["run", "--actors=1", "--window=1"],
    );
    for f in ["episodes.csv", "demos.jsonl", "experts.csv"] {
        assert_eq!(
            std::fs::read_to_string(lockstep.join(f)).unwrap(),
            std::fs::read_to_string(local.join(f)).unwrap(),
            "{f}"
        );
    }
    (local, lockstep)
}

#[test]
fn alfd_run_hosts_several_experts_as_alfd_local_does_to_the_byte() {
    let _time = timed!();
    let dir = tmp("experts-run");
    let config = dir.join("three.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let run = |name: &str, how: &[&str]| run_quietly(&dir.join(name), &config, how);
    let (local, _) = local_equals_lockstep(&dir, &config);
    // The episodes' returns reached the experts' qualities, over the wire as in one process.
    let off = ["local", "--set", "expert.quality_from_returns=false"];
    let without = run("without-returns", &off);
    let csv = |d: &Path| std::fs::read_to_string(d.join("experts.csv")).unwrap();
    assert_ne!(csv(&local), csv(&without), "returns change the qualities");
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

/// `alfd run --actors=2` of `config` into `out` with `extra` arguments, in the background.
fn two_actors(config: &Path, out: &Path, extra: &[&str]) -> crate::support::Background {
    crate::support::Background(Some(
        alfd()
            .args(["run", "--quiet", "--actors=2"])
            .args(extra)
            .arg("--config")
            .arg(config)
            .arg("--out")
            .arg(out)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    ))
}

/// Three Acrobot experts, the second one external (`alfd_examples.acrobot_pump`, from an
/// adapter process of its own), round-robin, the budget spread over the run.
fn with_external(steps: u32, budget: u32) -> String {
    format!(
        "seed = 4\nsteps = {steps}\n[env]\nname = \"acrobot\"\n\
         [agent]\nkind = \"bdqn\"\nheads = 2\nbatch_size = 16\n\
         [query]\nallowance = \"spread\"\ngate = \"chance\"\nhorizon = {steps}\n\
         [budget]\ntotal = {budget}\n[expert]\nroute = \"round-robin\"\n\
         [[experts]]\nname = \"acrobot-good\"\ncost = 10\n\
         [[experts]]\nname = \"{PUMP}\"\ncost = 2\n\
         [[experts]]\nname = \"acrobot-poor\"\ncost = 1\n"
    )
}

const PUMP: &str = "python:alfd_examples:acrobot_pump";

/// The pids of the processes whose command line (its words joined by spaces) holds every one of
/// `needles`.
pub(crate) fn processes_with(needles: &[&str]) -> Vec<u32> {
    std::fs::read_dir("/proc")
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            std::fs::read(format!("/proc/{pid}/cmdline")).is_ok_and(|c| {
                let c = String::from_utf8_lossy(&c).replace('\0', " ");
                needles.iter().all(|n| c.contains(n))
            })
        })
        .collect()
}

pub(crate) fn kill(pid: u32) {
    assert!(std::process::Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status()
        .unwrap()
        .success());
}

#[test]
fn an_external_expert_among_three_answers_as_in_alfd_local_and_killed_experts_are_restarted() {
    let _time = timed!();
    let dir = tmp("experts-external");
    // One actor in lockstep and `alfd local`: the same answers, the external ones included.
    let config = dir.join("short.toml");
    std::fs::write(&config, with_external(3000, 12)).unwrap();
    let (local, lockstep) = local_equals_lockstep(&dir, &config);
    let demos = alfd_demonstrators::demo_log::read(&local.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 12);
    let pumped: Vec<_> = demos.iter().filter(|d| d.expert == PUMP).collect();
    assert_eq!(pumped.len(), 4, "round-robin: every third answer");
    for d in pumped {
        assert_eq!(d.action, if d.state[4] > 0.0 { 0 } else { 2 }, "{d:?}");
    }
    assert!(local.join("adapter-expert-1-1.log").is_file());
    // In `alfd run`, every expert answers from a process of its own.
    for i in 0..3 {
        assert!(lockstep.join(format!("adapter-expert-1-{i}.log")).is_file());
    }

    // Two actors; once the external expert has answered three times, its adapter and the
    // built-in `acrobot-poor`'s process are killed: both are started again and answer again.
    let config = dir.join("long.toml");
    std::fs::write(&config, with_external(40_000, 60)).unwrap();
    let (before, later, logs) = kill_during(&dir.join("restarted"), &config, &[1, 2], &[]);
    for name in [PUMP, "acrobot-poor", "acrobot-good"] {
        assert!(
            before.contains(name),
            "{name} did not answer before the kills"
        );
        assert!(
            later.contains(name),
            "{name} did not answer after the kills"
        );
    }
    assert_eq!(
        logs.matches("its process ended: starting it again").count(),
        2,
        "{logs}"
    );
    assert!(
        !logs.contains("its queries go to the other experts"),
        "{logs}"
    );
    // With no restarts allowed, the killed expert is asked no more and the others go on.
    let (_, later, logs) = kill_during(&dir.join("down"), &config, &[2], &["--max-restarts=0"]);
    assert!(later.matches("acrobot-poor").count() <= 1, "{later}");
    for name in [PUMP, "acrobot-good"] {
        assert!(later.contains(name), "{name} did not answer after the kill");
    }
    assert!(
        logs.contains("its queries go to the other experts"),
        "{logs}"
    );
}

/// `alfd run --actors=2` of `config` into `out` (with `extra` arguments), in which the processes
/// of the experts at `places` of `[[experts]]` are killed once the external one has answered
/// three times. Checks that the run finishes, spending its whole budget, with every answer
/// written before the kills kept; returns `demos.jsonl` before the kills and what came after,
/// and the expert processes' logs.
fn kill_during(
    out: &Path,
    config: &Path,
    places: &[usize],
    extra: &[&str],
) -> (String, String, String) {
    let mut args = vec!["--query-timeout-ms=2000"];
    args.extend(extra);
    let mut bg = two_actors(config, out, &args);
    let log = || std::fs::read_to_string(out.join("demos.jsonl")).unwrap_or_default();
    crate::runtime::wait_until(&mut bg, "three answers of the external expert", || {
        log().matches(PUMP).count() >= 3
    });
    let id = crate::runtime::run_id(out);
    let run = format!("--run-id={id} ");
    // Every expert answers from a process of its own: a built-in one's is alfd-expert's.
    let process = |i: usize| {
        let name = format!("--name=expert-1-{i} ");
        let program = if i == 1 {
            "alfd_adapter.py"
        } else {
            "alfd-expert-member "
        };
        let pids = processes_with(&[program, &run, &name]);
        assert_eq!(pids.len(), 1, "one process for expert {i}");
        pids[0]
    };
    assert_ne!(process(0), process(2));
    let before = log();
    for &i in places {
        kill(process(i));
    }
    let o = crate::runtime::wait_output(bg, std::time::Duration::from_secs(180));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let after = log();
    assert!(after.starts_with(&before), "the log was rewritten");
    let demos = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 60, "the whole budget is spent");
    let logs: String = std::fs::read_dir(out)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("expert"))
        .map(|e| std::fs::read_to_string(e.path()).unwrap_or_default())
        .collect();
    assert_eq!(
        alfd_wire::leftover_files(&id),
        Vec::<std::path::PathBuf>::new()
    );
    let later = after[before.len()..].to_owned();
    (before, later, logs)
}

#[test]
fn experts_added_to_and_removed_from_a_live_run_answer_from_then_on_at_their_costs() {
    let _time = timed!();
    let dir = tmp("experts-live");
    let config = dir.join("three.toml");
    let three = "seed = 6\nsteps = 2000000\n[env]\nname = \"acrobot\"\n\
        [agent]\nkind = \"bdqn\"\nheads = 2\nbatch_size = 16\n\
        [query]\nallowance = \"spread\"\ngate = \"chance\"\nhorizon = 1000000\n\
        [budget]\ntotal = 100000\n[expert]\nroute = \"round-robin\"\n\
        [[experts]]\nname = \"acrobot-good\"\ncost = 10\n\
        [[experts]]\nname = \"acrobot-poor\"\ncost = 1\n";
    std::fs::write(&config, three).unwrap();
    let out = dir.join("run");
    let mut bg = two_actors(&config, &out, &[]);
    let log = || std::fs::read_to_string(out.join("demos.jsonl")).unwrap_or_default();
    let lines_after = |before: usize| -> Vec<Value> {
        log()
            .lines()
            .skip(before)
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    };
    crate::runtime::wait_until(&mut bg, "answers of both experts", || {
        log().contains("acrobot-good") && log().contains("acrobot-poor")
    });
    let expert = |how: &[&str]| {
        let o = alfd()
            .arg("expert")
            .args(how)
            .arg("--run")
            .arg(&out)
            .output()
            .unwrap();
        (o.status.code(), text(&o))
    };
    // Removed: from the answer after the swap on, only the good one answers, at its cost.
    let (code, said) = expert(&["remove", "acrobot-poor"]);
    assert_eq!(code, Some(0), "{said}");
    assert!(said.contains("\"to\":\"acrobot-good\""), "{said}");
    let at_removal = log().lines().count();
    crate::runtime::wait_until(&mut bg, "answers after the removal", || {
        lines_after(at_removal).len() >= 10
    });
    // Answers in flight at the swap aside, the poor one is gone.
    assert!(lines_after(at_removal)[2..]
        .iter()
        .all(|l| l["expert"] == "acrobot-good" && l["cost"].as_f64() == Some(10.0)));
    // Added, at its own cost; the same name again, or removing an absent one, is refused.
    let (code, said) = expert(&["add", "acrobot-fair", "--cost", "3"]);
    assert_eq!(code, Some(0), "{said}");
    assert!(
        said.contains("\"to\":\"acrobot-good+acrobot-fair\""),
        "{said}"
    );
    let at_add = log().lines().count();
    crate::runtime::wait_until(&mut bg, "answers of the added expert", || {
        lines_after(at_add)
            .iter()
            .any(|l| l["expert"] == "acrobot-fair")
    });
    let fair: Vec<Value> = lines_after(at_add)
        .into_iter()
        .filter(|l| l["expert"] == "acrobot-fair")
        .collect();
    assert!(
        fair.iter().all(|l| l["cost"].as_f64() == Some(3.0)),
        "{fair:?}"
    );
    let (code, said) = expert(&["add", "acrobot-fair"]);
    assert_eq!(code, Some(1), "{said}");
    assert!(said.contains("already"), "{said}");
    let (code, said) = expert(&["remove", "acrobot-poor"]);
    assert_eq!(code, Some(1), "{said}");
    assert!(said.contains("not one of the run's experts"), "{said}");
    let (code, said) = expert(&["add", "nobody-at-all"]);
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("nobody-at-all"), "{said}");
    let (code, said) = expert(&["add", "human"]);
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("not live"), "{said}");
    let o = crate::runtime::interrupt(bg);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    // Every answer of the run in `experts.csv`, each expert's rows under its name.
    let csv = std::fs::read_to_string(out.join("experts.csv")).unwrap();
    let rows = csv.lines().count() - 1;
    assert_eq!(rows, log().lines().count(), "a quality row per answer");
    assert!(csv.contains(",acrobot-fair,"));
}
