//! The multi-process runtime with real processes (`alfd run`: learner, expert and actors over
//! iceoryx2), asserting on the run directory: a small run, equivalence with the single-process
//! runner, an expert swap, kill -9 of an actor and of the expert, stray signals,
//! two concurrent runs, a run directory reused, concurrent swaps, and a refused schema version.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use alfd_wire as wire;

use crate::support::{alfd, bin_dir, text, timed, tmp, Background, TestDir};

/// The expert every test uses (the registry's perfect CartPole controller).
pub(crate) const EXPERT: &str = "cartpole-perfect";

/// An endless run with the 200 expert asked on every step (a budget that lasts the whole test) and
/// no model to refit: demonstrations flow whenever a test looks.
const ASKING_ALL_ALONG: [&str; 5] = [
    "episodes=1000000",
    "expert.name=cartpole-200",
    "expert.model=none",
    "query.rule=first",
    "budget.total=100000",
];

/// `alfd run` on the shipped BDQN + KRR config with the perfect expert, to the end.
pub(crate) fn run(out: &Path, actors: usize, sets: &[&str]) -> Output {
    let mut c = alfd();
    c.args([
        "run",
        "--config",
        "deploy/configs/cartpole-bdqn-krr.toml",
        "--quiet",
    ])
    .arg(format!("--actors={actors}"))
    .arg(format!("--out={}", out.display()))
    .args(["--set", &format!("expert.name={EXPERT}")]);
    for s in sets {
        // A flag of `alfd run` as it is, anything else a config override.
        if s.starts_with("--") {
            c.arg(s);
        } else {
            c.args(["--set", s]);
        }
    }
    c.output().expect("alfd runs")
}

/// The same, in the background (the caller stops it with [`interrupt`]).
pub(crate) fn spawn_run(out: &Path, actors: usize, sets: &[&str]) -> Background {
    spawn(run_command(out, actors, sets))
}

/// The command [`spawn_run`] starts: `alfd run` of the shipped BDQN + KRR config with the
/// perfect expert, `sets` a flag of `alfd run` when it starts with `--`, else a config override.
pub(crate) fn run_command(out: &Path, actors: usize, sets: &[&str]) -> Command {
    let mut c = alfd();
    c.args([
        "run",
        "--config",
        "deploy/configs/cartpole-bdqn-krr.toml",
        "--quiet",
    ])
    .arg(format!("--actors={actors}"))
    .arg(format!("--out={}", out.display()))
    .args(["--set", &format!("expert.name={EXPERT}")]);
    for s in sets {
        if s.starts_with("--") {
            c.arg(s);
        } else {
            c.args(["--set", s]);
        }
    }
    c
}

/// Starts `c` in the background with its output piped.
pub(crate) fn spawn(mut c: Command) -> Background {
    Background(Some(
        c.stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("alfd runs"),
    ))
}

/// Rows of `episodes.csv` (without the header), each split on commas.
pub(crate) fn rows(dir: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(dir.join("episodes.csv"))
        .unwrap_or_default()
        .lines()
        .skip(1)
        // Whole rows only (the file may be read while a row is being written).
        .filter(|l| l.split(',').count() == alfd_common::record::CSV_HEADER.split(',').count())
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

/// Waits until `episodes.csv` has at least `n` rows.
pub(crate) fn wait_rows(dir: &Path, n: usize, run: &mut Background) {
    let child = run.child();
    let start = Instant::now();
    while rows(dir).len() < n {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the run ended ({status}) before {n} episodes");
        }
        assert!(
            start.elapsed() < Duration::from_secs(90),
            "fewer than {n} episodes in 90 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Stops a background run with SIGINT (Ctrl-C) and returns its output.
pub(crate) fn interrupt(mut run: Background) -> Output {
    let child = run.0.take().expect("running");
    let ok = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
    child.wait_with_output().unwrap()
}

pub(crate) fn run_id(dir: &Path) -> String {
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    info["run_id"].as_str().unwrap().to_owned()
}

pub(crate) fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// What every finished run must satisfy: a valid `demos.jsonl` within the budget and counted in
/// the summary, weights saved, one log per process, nothing left in iceoryx2's directories.
pub(crate) fn check_run_dir(dir: &Path, budget: usize) -> Vec<alfd_common::agent::DemoRecord> {
    let demos =
        alfd_demonstrators::demo_log::read(&dir.join("demos.jsonl")).expect("demos.jsonl valid");
    assert!(
        demos.len() <= budget,
        "{} demos for a budget of {budget}",
        demos.len()
    );
    assert_eq!(summary(dir)["demos"], demos.len());
    let weights = std::fs::read(dir.join("weights.safetensors")).expect("weights saved");
    let net = alfd_common::nn::Mlp::from_safetensors_bytes(&weights).unwrap();
    assert_eq!((net.heads(), net.actions(), net.num_params()), (2, 2, 4740));
    for log in ["learner.log", "expert-1.log", "actor-0.log"] {
        assert!(dir.join(log).is_file(), "{log} missing");
    }
    let id = run_id(dir);
    assert_eq!(
        wire::leftover_files(&id),
        Vec::<PathBuf>::new(),
        "stale iceoryx2 files"
    );
    assert_eq!(wire::alive_nodes(&id).unwrap(), Vec::<String>::new());
    demos
}

#[test]
fn a_small_run_with_two_actors_fills_its_run_directory() {
    let _time = timed!();
    let out = tmp("small");
    // `first`: the budget goes on the first steps, so exactly B demonstrations are made. Enough
    // episodes (about a second of play) that an actor starting a little later still gets some.
    let o = run(
        &out,
        2,
        &["episodes=300", "budget.total=10", "query.rule=first"],
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = summary(&out);
    assert_eq!(s["episodes"], 300);
    assert_eq!(s["interrupted"], false);
    let rows = rows(&out);
    assert_eq!(rows.len(), 300);
    let header = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    assert_eq!(
        header.lines().next().unwrap(),
        alfd_common::record::CSV_HEADER
    );
    for (i, r) in rows.iter().enumerate() {
        assert_eq!(
            r[0],
            i.to_string(),
            "episodes are numbered in order of arrival"
        );
        assert!(r[8] == "0" || r[8] == "1", "actor {}", r[8]);
        let ret: f64 = r[1].parse().unwrap();
        assert!(
            ret >= 1.0 && r[1] == r[2],
            "CartPole's return is its length"
        );
    }
    assert!(rows.iter().any(|r| r[8] == "0") && rows.iter().any(|r| r[8] == "1"));
    let demos = check_run_dir(&out, 10);
    assert_eq!(demos.len(), 10);
    assert!(demos.iter().all(|d| d.expert == EXPERT));
    let queries: u32 = rows.iter().map(|r| r[5].parse::<u32>().unwrap()).sum();
    assert_eq!(queries, 10, "every demonstration was used by an actor");
    assert_eq!(rows.last().unwrap()[3], "10", "demos_used");
    assert!(out.join("actor-1.log").is_file());
    let config = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(
        config.contains("cartpole-perfect"),
        "the config used is recorded"
    );
}

#[test]
fn refits_in_the_background_answer_every_query_and_the_models_still_shape() {
    let _time = timed!();
    let out = tmp("background-refits");
    // The budget is spent in the first 20 steps, and a background refit (at nice 10) may wait
    // for a core while other tests run. Eq. 4's shaping stops at twice the last
    // demonstration's step by default, before a late model comes; at 1000 times it goes on
    // through the whole run (300 episodes, a few thousand steps), so that a model published
    // late still shapes.
    let o = run(
        &out,
        1,
        &[
            "--refit=background",
            "episodes=300",
            "budget.total=20",
            "shaping.stop_multiple=1000",
            "query.rule=first",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let demos = check_run_dir(&out, 20);
    assert_eq!(demos.len(), 20);
    let runtime = std::fs::read_to_string(out.join("runtime.toml")).unwrap();
    assert!(runtime.contains("refit = \"background\""), "{runtime}");
    let actor = std::fs::read_to_string(out.join("actor-0.log")).unwrap();
    assert!(actor.contains("answers=20"), "{actor}");
    assert!(actor.contains("answer_wait_p99_ms="), "{actor}");
    // The models refitted in the background were published: steps were shaped with them.
    let shaped: u64 = rows(&out)
        .iter()
        .map(|r| r[6].parse::<u64>().unwrap())
        .sum();
    assert!(shaped > 0, "no shaped step");
}

/// `alfd local` and `alfd run --actors=1 --window=1` on the KRR config with `sets`: the
/// directories of both runs.
fn local_and_lockstep(name: &str, sets: &[&str]) -> (TestDir, TestDir) {
    let (local, multi) = (tmp(&format!("{name}-local")), tmp(&format!("{name}-multi")));
    let expert = format!("expert.name={EXPERT}");
    for (dir, how) in [
        (&local, &["local"][..]),
        (&multi, &["run", "--actors=1", "--window=1"][..]),
    ] {
        let mut c = alfd();
        c.args(how)
            .args([
                "--config",
                "deploy/configs/cartpole-bdqn-krr.toml",
                "--quiet",
            ])
            .arg(format!("--out={}", dir.display()))
            .args(["--set", &expert]);
        for s in sets {
            c.args(["--set", s]);
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", text(&o));
    }
    (local, multi)
}

#[test]
fn one_actor_in_lockstep_reproduces_the_single_process_run() {
    let _time = timed!();
    // With one actor and a credit window of 1 the actor always acts on the newest weights, as in
    // one process: one loop, the same seeds, the same episodes, to the byte.
    let (local, multi) = local_and_lockstep("equiv", &["episodes=60"]);
    // The same file, byte for byte (the actor column included: actor 0 in both).
    let single = std::fs::read_to_string(local.join("episodes.csv")).unwrap();
    let many = std::fs::read_to_string(multi.join("episodes.csv")).unwrap();
    assert_eq!(single.lines().count(), 61);
    assert_eq!(many, single);
    // The demonstrations too (the multi-process run may have a few more, asked in the episode
    // that was still running when the run stopped).
    let d1 = alfd_demonstrators::demo_log::read(&local.join("demos.jsonl")).unwrap();
    let d2 = check_run_dir(&multi, 100);
    assert!(!d1.is_empty());
    assert_eq!(d2[..d1.len()], d1[..]);
}

#[test]
fn lockstep_equivalence_holds_with_every_learner_option_evaluation_and_a_step_budget() {
    let _time = timed!();
    let (local, multi) = local_and_lockstep(
        "equiv-options",
        &[
            "episodes=0",
            "steps=2500",
            "evaluation.every=5",
            "evaluation.episodes=2",
            "shaping.kind=potential",
            "agent.demo_fraction=0.1",
            "agent.margin_loss_weight=1.0",
            "agent.double_dqn=true",
            "agent.loss=mse",
            "agent.tau=0.05",
            "agent.target_update_every=1",
            "agent.max_grad_norm=10",
            "agent.heads=12",
        ],
    );
    let single = std::fs::read_to_string(local.join("episodes.csv")).unwrap();
    let many = std::fs::read_to_string(multi.join("episodes.csv")).unwrap();
    assert_eq!(many, single);
    let rows: Vec<Vec<&str>> = single
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert!(rows.len() > 20, "{} episodes", rows.len());
    // Every 5th episode carries an evaluation, the others none; no episode ends past the budget.
    for (i, r) in rows.iter().enumerate() {
        assert_eq!(r[9].is_empty(), (i + 1) % 5 != 0, "row {i}: {r:?}");
        assert!(r[7].parse::<u64>().unwrap() <= 2500);
    }
}

#[test]
fn the_expert_is_swapped_in_a_live_run_without_losing_or_repeating_a_demonstration() {
    let _time = timed!();
    let out = tmp("swap");
    // Demonstrations flow before, during and after the swap from the 200 expert to the 1000 one.
    let mut child = spawn_run(&out, 2, &ASKING_ALL_ALONG);
    wait_rows(&out, 10, &mut child);
    let before = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl"))
        .unwrap()
        .len();
    let o = alfd()
        .args(["swap-expert", "--run"])
        .arg(&out)
        .args(["--expert", "cartpole-1000"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let response: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(response["ok"], true);
    assert_eq!(response["generation"], 2);
    assert_eq!(
        (response["from"].as_str(), response["to"].as_str()),
        (Some("cartpole-200"), Some("cartpole-1000"))
    );
    let at = response["at_episode"].as_u64().unwrap() as usize;
    wait_rows(&out, at + 10, &mut child);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let s = summary(&out);
    assert_eq!(
        (s["interrupted"].as_bool(), s["expert_swaps"].as_u64()),
        (Some(true), Some(1))
    );
    // Read back whole: indices 0.. in order, none missing or repeated.
    let demos = check_run_dir(&out, 100_000);
    // Every demonstration names its expert: the 200 one until the swap, the 1000 one after.
    let switch = demos
        .iter()
        .position(|d| d.expert == "cartpole-1000")
        .expect("demonstrations after the swap");
    assert!(switch >= before && switch > 0, "{switch} < {before}");
    assert!(demos[..switch].iter().all(|d| d.expert == "cartpole-200"));
    assert!(demos[switch..].iter().all(|d| d.expert == "cartpole-1000"));
    let old = std::fs::read_to_string(out.join("expert-1.log")).unwrap();
    assert!(old.contains("replaced by a newer expert"), "{old}");
    // The new expert restored everything the old one recorded: its first index follows.
    let new = std::fs::read_to_string(out.join("expert-2.log")).unwrap();
    assert!(
        new.contains(&format!("active: answering queries demos={switch} ")),
        "{new}"
    );
    assert!(rows(&out).len() > at, "episodes went on after the swap");
}

#[test]
fn an_actor_killed_with_sigkill_is_restarted_and_the_run_goes_on() {
    let _time = timed!();
    let out = tmp("kill");
    let mut child = spawn_run(&out, 2, &["episodes=1000000"]);
    wait_rows(&out, 10, &mut child);
    // Actor 1 recorded episodes of its first incarnation (on a loaded machine actor 0 may have
    // played the first ten alone).
    wait_until(&mut child, "episodes of actor 1", || {
        rows(&out).iter().filter(|r| r[8] == "1").count() >= 2
    });
    let id = run_id(&out);
    let pid = find_process("alfd-actor", &[&format!("--run-id={id}"), "--actor-id=1"])
        .expect("actor 1 is running");
    assert!(Command::new("kill")
        .args(["-9", &pid.to_string()])
        .status()
        .unwrap()
        .success());
    // The launcher starts a second incarnation of actor 1.
    let start = Instant::now();
    loop {
        if find_process(
            "alfd-actor",
            &[&format!("--run-id={id}"), "--actor-id=1", "--incarnation=2"],
        )
        .is_some()
        {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "actor 1 was not restarted"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // The new incarnation finishes episodes of its own: rows of actor 1 keep coming, and the
    // launcher saw an episode of incarnation 2 (below, in its log).
    let killed_at = rows(&out).len();
    let start = Instant::now();
    while rows(&out)[killed_at..]
        .iter()
        .filter(|r| r[8] == "1")
        .count()
        < 5
    {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no episodes of the restarted actor 1"
        );
        assert!(child.child().try_wait().unwrap().is_none(), "the run ended");
        std::thread::sleep(Duration::from_millis(50));
    }
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    assert_eq!(summary(&out)["actor_restarts"], 1);
    check_run_dir(&out, 100);
    let launcher_log = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        launcher_log.contains("killed by signal 9"),
        "{launcher_log}"
    );
    assert!(
        launcher_log.contains("first episode of a restarted actor actor=1 incarnation=2"),
        "{launcher_log}"
    );
}

#[test]
fn two_concurrent_runs_do_not_see_each_other() {
    let _time = timed!();
    let (a, b) = (tmp("iso-a"), tmp("iso-b"));
    let run_a = std::thread::spawn({
        let a = a.to_path_buf();
        move || {
            run(
                &a,
                1,
                &[
                    "episodes=30",
                    "budget.total=5",
                    "query.rule=first",
                    "seed=1",
                ],
            )
        }
    });
    let ob = run(
        &b,
        2,
        &[
            "episodes=30",
            "budget.total=7",
            "query.rule=first",
            "seed=2",
        ],
    );
    let oa = run_a.join().unwrap();
    assert!(oa.status.success(), "{}", text(&oa));
    assert!(ob.status.success(), "{}", text(&ob));
    assert_ne!(run_id(&a), run_id(&b));
    // Each expert spent its own run's budget, and each launcher saw only its own actors.
    assert_eq!(check_run_dir(&a, 5).len(), 5);
    assert_eq!(check_run_dir(&b, 7).len(), 7);
    assert!(rows(&a).iter().all(|r| r[8] == "0"));
    assert_eq!(rows(&a).len(), 30);
    assert_eq!(rows(&b).len(), 30);
}

#[test]
fn a_process_of_another_schema_version_is_refused() {
    let _time = timed!();
    let out = tmp("schema");
    let mut child = spawn_run(&out, 1, &["episodes=1000000"]);
    wait_rows(&out, 5, &mut child);
    let id = run_id(&out);
    let o = Command::new(bin_dir().join("alfd-actor"))
        .args([
            "--run-dir",
            out.to_str().unwrap(),
            "--run-id",
            &id,
            "--actor-id",
            "5",
        ])
        .env("ALFD_SCHEMA_VERSION_OVERRIDE", "999")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("schema version 999")
            && err.contains(&format!("schema version {}", wire::SCHEMA_VERSION)),
        "{err}"
    );
    // The run did not notice.
    let n = rows(&out).len();
    wait_rows(&out, n + 5, &mut child);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    assert!(rows(&out).iter().all(|r| r[8] == "0"));
    check_run_dir(&out, 100);
}

#[test]
fn stray_signals_stop_no_process_and_the_run_finishes() {
    let _time = timed!();
    let out = tmp("stray-signals");
    // Many short episodes (at most 50 steps: a run of a few seconds whether or not it learns), and
    // a budget that lasts, so that queries meet the stopped expert.
    let episodes = 3000;
    let mut child = spawn_run(
        &out,
        2,
        &[
            &format!("episodes={episodes}"),
            "env.max_episode_steps=50",
            "budget.total=1000",
        ],
    );
    wait_rows(&out, 30, &mut child);
    let id = run_id(&out);
    let run = format!("--run-id={id}");
    let expert = find_process("alfd-expert", &[&run]).expect("expert");
    let learner = find_process("alfd-learner", &[&run]).expect("learner");
    let actor = find_process("alfd-actor", &[&run, "--actor-id=0"]).expect("actor 0");
    let launcher = child.child().id();
    // The expert is stopped, as by a debugger or `kill -STOP`, then resumed; the others get a
    // bare SIGCONT, the launcher and the expert Ctrl-Z's SIGTSTP.
    signal("STOP", expert);
    std::thread::sleep(Duration::from_millis(1500));
    signal("CONT", expert);
    signal("CONT", learner);
    signal("CONT", actor);
    signal("TSTP", launcher);
    signal("TSTP", expert);
    signal("URG", learner);
    std::thread::sleep(Duration::from_millis(100));
    signal("CONT", expert);
    let sent_at = rows(&out).len();
    assert!(
        sent_at < episodes,
        "the run ended before the signals were sent"
    );
    let (_, s) = finished(child, &out, episodes);
    assert_eq!(
        (s["actor_restarts"].as_u64(), s["expert_restarts"].as_u64()),
        (Some(0), Some(0))
    );
    assert!(
        !out.join("expert-2.log").exists(),
        "the expert was restarted"
    );
    for log in ["expert-1.log", "learner.log", "actor-0.log", "actor-1.log"] {
        let t = std::fs::read_to_string(out.join(log)).unwrap();
        assert!(!t.contains("termination signal"), "{log}: {t}");
        assert!(t.contains("the launcher said stop"), "{log}: {t}");
    }
    check_run_dir(&out, 1000);
}

#[test]
fn an_expert_killed_with_sigkill_is_restarted_and_the_run_completes() {
    let _time = timed!();
    let out = tmp("expert-killed");
    // Every step asks until the budget is spent (no model to refit, so answers are quick): the
    // expert dies with demonstrations flowing, and its successor spends the rest of the budget.
    let (episodes, budget) = (300, 3000);
    let mut child = spawn_run(
        &out,
        2,
        &[
            &format!("episodes={episodes}"),
            "env.max_episode_steps=200",
            "expert.model=none",
            "query.rule=first",
            &format!("budget.total={budget}"),
        ],
    );
    let demos = || {
        std::fs::read_to_string(out.join("demos.jsonl"))
            .unwrap_or_default()
            .lines()
            .count()
    };
    wait_until(&mut child, "100 demonstrations", || demos() >= 100);
    let id = run_id(&out);
    let run = format!("--run-id={id}");
    let pid = find_process("alfd-expert", &[&run, "--generation=1"]).expect("expert 1");
    signal("KILL", pid);
    let killed = Instant::now();
    let at_kill = demos();
    assert!(at_kill < budget, "the budget was spent before the kill");
    // The launcher starts generation 2, which reads demos.jsonl back and answers.
    wait_until(&mut child, "expert 2 started", || {
        find_process("alfd-expert", &[&run, "--generation=2"]).is_some()
    });
    let respawned = killed.elapsed();
    let (o, s) = finished(child, &out, episodes);
    assert_eq!(
        (s["expert_restarts"].as_u64(), s["actor_restarts"].as_u64()),
        (Some(1), Some(0))
    );
    // demos.jsonl reads back whole (indices 0..n in order, none repeated), within the budget,
    // and the restarted expert carried on from where its predecessor stopped.
    let demos = check_run_dir(&out, budget);
    assert!(demos.len() > at_kill, "{} <= {at_kill}", demos.len());
    let new = std::fs::read_to_string(out.join("expert-2.log")).unwrap();
    let restored = number_after(&new, "active: answering queries demos=") as usize;
    assert!(
        (at_kill..demos.len()).contains(&restored),
        "restored {restored}"
    );
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(err.contains("killed by signal 9"), "{err}");
    let recovered_ms = number_after(&err, "expert-2 answers again, ");
    eprintln!(
        "expert restart: generation 2 started {} ms after the kill, answering {recovered_ms} ms \
         after the launcher saw the death; {at_kill} demos at the kill, {restored} restored, {} at \
         the end",
        respawned.as_millis(),
        demos.len()
    );
}

#[test]
fn a_run_directory_belongs_to_one_run() {
    let _time = timed!();
    let out = tmp("one-run");
    // A second launcher on a live run's directory is refused, as is `alfd local`.
    let mut child = spawn_run(&out, 1, &["episodes=1000000"]);
    wait_rows(&out, 3, &mut child);
    let run_json = std::fs::read(out.join("run.json")).unwrap();
    let refused = |o: &Output| {
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(2), "{}", text(o));
        assert!(
            err.contains(&out.display().to_string()) && err.contains("--out"),
            "{err}"
        );
        err
    };
    refused(&run(&out, 1, &["episodes=5"]));
    let local = alfd()
        .args(["local", "--config", "deploy/configs/cartpole-bdqn-krr.toml"])
        .arg(format!("--out={}", out.display()))
        .output()
        .unwrap();
    refused(&local);
    assert_eq!(std::fs::read(out.join("run.json")).unwrap(), run_json);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));

    // A finished run's directory: refused, and nothing in it changes.
    let snapshot = crate::support::dir_snapshot;
    let before = snapshot(&out);
    let err = refused(&run(&out, 1, &["episodes=5"]));
    assert!(err.contains("already holds a run"), "{err}");
    assert_eq!(snapshot(&out), before, "the run directory was touched");
    check_run_dir(&out, 100);

    // Two launchers started together on a new directory: one runs, the other is refused.
    let fresh = tmp("one-run-race");
    let _ = std::fs::remove_dir(&fresh);
    let a = spawn_run(&fresh, 1, &["episodes=5"]);
    let b = spawn_run(&fresh, 1, &["episodes=5"]);
    let (oa, ob) = (
        wait_output(a, Duration::from_secs(120)),
        wait_output(b, Duration::from_secs(120)),
    );
    let mut codes = [oa.status.code(), ob.status.code()];
    codes.sort();
    assert_eq!(codes, [Some(0), Some(2)], "{}\n{}", text(&oa), text(&ob));
    assert_eq!(rows(&fresh).len(), 5);
    check_run_dir(&fresh, 100);
}

#[test]
fn concurrent_swaps_are_refused_at_once_and_a_refused_swap_says_why() {
    let _time = timed!();
    let out = tmp("swaps");
    let mut child = spawn_run(&out, 1, &ASKING_ALL_ALONG);
    wait_rows(&out, 5, &mut child);
    let launcher = child.child().id();
    let swap = |expert: &str| {
        let mut c = alfd();
        c.args(["swap-expert", "--run"])
            .arg(&out)
            .args(["--expert", expert]);
        c
    };
    // The launcher is stopped, so the first swap waits (holding the swap lock) for its answer.
    signal("STOP", launcher);
    let first = swap("cartpole-1000")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lock = out.join(".swap.lock");
    let start = Instant::now();
    while std::fs::read_to_string(&lock).unwrap_or_default().trim() != first.id().to_string() {
        assert!(start.elapsed() < Duration::from_secs(30), "no swap lock");
        std::thread::sleep(Duration::from_millis(10));
    }
    let start = Instant::now();
    let second = swap("cartpole-500").output().unwrap();
    let refused_in = start.elapsed();
    signal("CONT", launcher);
    let err = String::from_utf8_lossy(&second.stderr).into_owned();
    assert_eq!(second.status.code(), Some(2), "{}", text(&second));
    assert!(
        err.contains("another `alfd swap-expert`")
            && err.contains(&format!("(pid {})", first.id()))
            && err.contains("one at a time"),
        "{err}"
    );
    assert!(
        refused_in < Duration::from_secs(5),
        "refused after {refused_in:?}"
    );
    let first = first.wait_with_output().unwrap();
    assert!(first.status.success(), "{}", text(&first));
    let response: serde_json::Value = serde_json::from_slice(&first.stdout).unwrap();
    assert_eq!(
        (response["ok"].as_bool(), response["generation"].as_u64()),
        (Some(true), Some(2))
    );

    // A bad line in demos.jsonl: the new expert refuses it, and the swap says so itself.
    let mut demos = std::fs::OpenOptions::new()
        .append(true)
        .open(out.join("demos.jsonl"))
        .unwrap();
    std::io::Write::write_all(&mut demos, b"not json\n").unwrap();
    drop(demos);
    let bad = swap("cartpole-500").output().unwrap();
    let err = String::from_utf8_lossy(&bad.stderr).into_owned();
    assert_eq!(bad.status.code(), Some(1), "{}", text(&bad));
    assert!(
        err.contains("the new expert exited with status 2")
            && err.contains("demos.jsonl line ")
            && err.contains("not a demonstration record"),
        "{err}"
    );
    // The run went on with the expert it had.
    let n = rows(&out).len();
    wait_rows(&out, n + 5, &mut child);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let s = summary(&out);
    assert_eq!(
        (s["expert_swaps"].as_u64(), s["expert_restarts"].as_u64()),
        (Some(1), Some(0))
    );
}

/// Waits (at most 90 s, polling) until `done` while the run goes on.
pub(crate) fn wait_until(run: &mut Background, what: &str, mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(
            start.elapsed() < Duration::from_secs(90),
            "not within 90 s: {what}"
        );
        assert!(
            run.child().try_wait().unwrap().is_none(),
            "the run ended before: {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Waits for a background run to end by itself, and checks that it finished: exit code 0, every
/// one of its `episodes` recorded, not interrupted. Returns its output and summary.
pub(crate) fn finished(
    run: Background,
    dir: &Path,
    episodes: usize,
) -> (Output, serde_json::Value) {
    let o = wait_output(run, Duration::from_secs(180));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let s = summary(dir);
    assert_eq!(
        (s["episodes"].as_u64(), s["interrupted"].as_bool()),
        (Some(episodes as u64), Some(false))
    );
    assert_eq!(rows(dir).len(), episodes);
    (o, s)
}

/// The number that follows the first `marker` in `text`.
fn number_after(text: &str, marker: &str) -> u64 {
    text.split(marker)
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after {marker:?} in {text}"))
}

/// Sends `signal` (a name: KILL, STOP, CONT, ...) to `pid`.
pub(crate) fn signal(signal: &str, pid: u32) {
    let ok = Command::new("kill")
        .args([&format!("-{signal}"), &pid.to_string()])
        .status()
        .unwrap();
    assert!(ok.success(), "kill -{signal} {pid}");
}

/// Waits (at most `timeout`) for a background run to end by itself, and returns its output.
pub(crate) fn wait_output(mut run: Background, timeout: Duration) -> Output {
    let child = run.0.take().expect("running");
    let pid = child.id();
    let (tx, rx) = std::sync::mpsc::channel();
    // Reads its output as it comes (a full pipe would stall it).
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(timeout) {
        Ok(output) => output.unwrap(),
        Err(_) => {
            // Stopped (as `Background` would) before the test's directory goes: SIGINT, then
            // SIGKILL if it is still there 30 s later.
            for (signal, grace) in [("-INT", 30), ("-KILL", 5)] {
                let _ = Command::new("kill")
                    .args([signal, &pid.to_string()])
                    .status();
                if rx.recv_timeout(Duration::from_secs(grace)).is_ok() {
                    break;
                }
            }
            panic!("the run did not end within {timeout:?}");
        }
    }
}

pub(crate) use alfd_launcher::find_process;
