//! Answers slower than the query timeout, on every path where a query can be asked again or an
//! answer can arrive after its actor stopped waiting: the expert on the learner's host (its
//! actors there and on another host), an expert swapped or restarted while answers are late, an
//! expert on another host, and a Python demonstrator slower than the expert waits (the person's
//! page is in `human.rs`). The expert is made slow with `ALFD_EXPERT_ANSWER_DELAY_MS`, far above
//! `--query-timeout-ms`. Each run must keep its invariant: `demos.jsonl` whole and gap-free,
//! holding every demonstration an expert counted, each late answer counted, nothing refused.

use std::path::Path;
use std::process::Output;
use std::time::Duration;

use crate::remote::{expert_host_id, finish, free_port, insecure, mirror_id, spawn_join};
use crate::runtime::{
    check_run_dir, find_process, finished, interrupt, rows, run_command, run_id, signal, spawn,
    summary, wait_until, EXPERT,
};
use crate::support::{alfd, text, timed, tmp, Background};

/// How much slower the expert answers than the actors wait (2 ms).
const DELAY_MS: &str = "30";
const TIMEOUT: &str = "--query-timeout-ms=2";

/// `alfd run` of the shipped BDQN + KRR config with `actors` actors, its expert answering
/// `DELAY_MS` late, every step asking while the budget lasts (no model to refit).
fn slow_run(out: &Path, actors: usize, sets: &[&str]) -> Background {
    let mut all = vec![
        TIMEOUT,
        "expert.model=none",
        "query.rule=first",
        "env.max_episode_steps=100",
    ];
    all.extend_from_slice(sets);
    let mut c = run_command(out, actors, &all);
    c.env(alfd_expert::ANSWER_DELAY_VAR, DELAY_MS);
    spawn(c)
}

/// Lines of a `demos.jsonl` (0 while it does not exist).
fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .count()
}

/// Answers the actors took (the `queries` column of `episodes.csv`).
fn used(dir: &Path) -> u64 {
    rows(dir).iter().map(|r| r[5].parse::<u64>().unwrap()).sum()
}

/// The summary's numbers of demonstrations: in `demos.jsonl`, counted by the experts, answered
/// late, refused.
fn counts(dir: &Path) -> (u64, u64, u64, u64) {
    let s = summary(dir);
    let n = |k: &str| s[k].as_u64().unwrap_or_else(|| panic!("{k} in {s}"));
    (
        n("demos"),
        n("demos_experts_wrote"),
        n("answers_late"),
        n("demos_refused"),
    )
}

/// Every demonstration an expert counted is in `demos.jsonl`, none refused, and each was either
/// taken by its actor or counted late (all of them late unless an actor was descheduled past
/// the expert's delay).
fn check_late(dir: &Path, budget: u64) -> u64 {
    let (demos, wrote, late, refused) = counts(dir);
    assert_eq!((demos, refused), (wrote, 0));
    assert!(
        demos > 0 && demos <= budget,
        "{demos} demonstrations, budget {budget}"
    );
    assert_eq!(late + used(dir), demos, "late {late}");
    assert!(late * 2 >= demos, "only {late} of {demos} late");
    late
}

#[test]
fn answers_after_the_actors_timeout_keep_their_demonstrations_and_are_counted_late() {
    let _time = timed!();
    let out = tmp("late-local");
    let run = slow_run(&out, 2, &["episodes=30", "budget.total=12"]);
    finished(run, &out, 30);
    check_run_dir(&out, 12);
    check_late(&out, 12);
    let actor = std::fs::read_to_string(out.join("actor-0.log")).unwrap();
    assert!(actor.contains("did not answer in time"), "{actor}");
}

#[test]
fn a_swap_while_answers_are_late_keeps_the_file_whole_and_in_the_experts_order() {
    let _time = timed!();
    let out = tmp("late-swap");
    let mut run = slow_run(&out, 2, &["episodes=1000000", "budget.total=100000"]);
    let demos = out.join("demos.jsonl");
    wait_until(&mut run, "5 demonstrations", || lines(&demos) >= 5);
    let o = alfd()
        .args(["swap-expert", "--run"])
        .arg(&out)
        .args(["--expert", "cartpole-1000"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let at = lines(&demos);
    wait_until(&mut run, "5 demonstrations after the swap", || {
        lines(&demos) >= at + 5
    });
    // Exit code 130, not 1: the run's demos.jsonl holds all its experts counted.
    let o = interrupt(run);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let records = check_run_dir(&out, 100_000);
    let switch = records
        .iter()
        .position(|d| d.expert == "cartpole-1000")
        .expect("demonstrations after the swap");
    assert!(records[..switch].iter().all(|d| d.expert == EXPERT));
    assert!(records[switch..]
        .iter()
        .all(|d| d.expert == "cartpole-1000"));
    let (n, wrote, late, refused) = counts(&out);
    assert_eq!(n, records.len() as u64);
    assert!(n >= wrote && late > 0 && refused == 0, "{n} {wrote} {late}");
}

#[test]
fn an_expert_killed_while_answers_are_late_is_restarted_and_loses_nothing() {
    let _time = timed!();
    let out = tmp("late-restart");
    let budget = 24;
    let mut run = slow_run(
        &out,
        2,
        &["episodes=150", &format!("budget.total={budget}")],
    );
    let demos = out.join("demos.jsonl");
    wait_until(&mut run, "6 demonstrations", || lines(&demos) >= 6);
    let id = run_id(&out);
    let pid = find_process(
        "alfd-expert",
        &[&format!("--run-id={id}"), "--generation=1"],
    )
    .expect("expert 1");
    signal("KILL", pid);
    let (_, s) = finished(run, &out, 150);
    assert_eq!(s["expert_restarts"], 1);
    check_run_dir(&out, budget);
    // Its demonstrations are all in the file; its late answers after its last report are
    // counted by nobody (it reports every 500 ms), so the late count is a lower bound here.
    let (n, wrote, late, refused) = counts(&out);
    assert!(
        n >= wrote && n >= 6 && n <= budget as u64 && refused == 0,
        "{n} {wrote}"
    );
    assert!(late + used(&out) <= n, "{late} of {n}");
}

/// `alfd join` as another host with `role`, its processes' environment given `env`.
fn spawn_host(port: u16, role: &str, dir: &Path, env: &[(&str, &str)]) -> Background {
    let mut c = alfd();
    c.arg("join")
        .args(insecure(port))
        .arg(role)
        .arg(format!("--dir={}", dir.join("join").display()))
        .current_dir(dir)
        .env("HOME", dir);
    for (k, v) in env {
        c.env(k, v);
    }
    spawn(c)
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", text(o));
}

#[test]
fn late_answers_of_an_expert_on_another_host_reach_the_runs_file_in_order() {
    let _time = timed!();
    let (out, expert_host, actor_host) = (
        tmp("late-remote"),
        tmp("late-remote-expert"),
        tmp("late-remote-actors"),
    );
    let port = free_port();
    let budget = 20;
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    let budget_set = format!("budget.total={budget}");
    let run = spawn(run_command(
        &out,
        0,
        &[
            TIMEOUT,
            "--insecure",
            &listen,
            "episodes=40",
            &budget_set,
            "query.rule=first",
            "expert.model=none",
            "env.max_episode_steps=100",
        ],
    ));
    // Only the remote expert is slow: the run's own expert-1 answers at once until the swap.
    let delay = [(alfd_expert::ANSWER_DELAY_VAR, DELAY_MS)];
    let expert = spawn_host(port, "--expert=cartpole-200", &expert_host, &delay);
    crate::remote::wait_answering(&expert_host.join("join"), 2);
    let actors = spawn_join(port, 2, &actor_host);
    ok(&finish(run, 120));
    ok(&finish(actors, 60));
    ok(&finish(expert, 60));
    let here = std::fs::read_to_string(out.join("demos.jsonl")).unwrap();
    let there = std::fs::read_to_string(expert_host.join("join").join("demos.jsonl")).unwrap();
    assert_eq!(here, there, "the two copies of demos.jsonl differ");
    check_late(&out, budget);
    let records = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert!(records.iter().all(|d| d.expert == "cartpole-200"));
    for id in [
        run_id(&out),
        mirror_id(&actor_host.join("join")),
        expert_host_id(&expert_host.join("join")),
    ] {
        assert!(alfd_wire::leftover_files(&id).is_empty(), "{id}");
    }
}

#[test]
fn remote_actors_asking_again_before_the_local_expert_answers_lose_nothing() {
    let _time = timed!();
    let (out, actor_host) = (
        tmp("late-remote-actors-run"),
        tmp("late-remote-actors-host"),
    );
    let port = free_port();
    let budget = 16;
    let run = slow_run(
        &out,
        0,
        &[
            &format!("--listen=tcp/127.0.0.1:{port}"),
            "--insecure",
            "episodes=30",
            &format!("budget.total={budget}"),
        ],
    );
    let actors = spawn_join(port, 2, &actor_host);
    ok(&finish(run, 120));
    ok(&finish(actors, 60));
    check_late(&out, budget);
}

#[test]
fn a_python_demonstrator_slower_than_the_expert_waits_gives_no_answer_to_another_state() {
    let _time = timed!();
    let out = tmp("late-python");
    // The demonstrator takes 15 ms; the expert waits 20 ms for it and the actors 20 ms for the
    // expert: some answers come in time, some late, some not at all.
    let run = spawn(run_command(
        &out,
        2,
        &[
            "--query-timeout-ms=20",
            "expert.name=python:alfd_examples:cartpole_slow",
            "expert.model=none",
            "query.rule=first",
            "env.max_episode_steps=60",
            "episodes=20",
            "budget.total=40",
        ],
    ));
    let o = crate::runtime::wait_output(run, Duration::from_secs(240));
    ok(&o);
    let records = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert!(
        !records.is_empty(),
        "no demonstration in time: {}",
        text(&o)
    );
    // Each demonstration is the demonstrator's action for its own state (a late answer of the
    // adapter is never taken for the next state).
    for d in &records {
        let balance = usize::from(d.state[2] + 0.5 * d.state[3] > 0.0);
        assert_eq!(d.action, balance, "{d:?}");
    }
    let (n, wrote, late, refused) = counts(&out);
    assert_eq!((n, wrote, refused), (records.len() as u64, n, 0));
    assert_eq!(late + used(&out), n);
}
