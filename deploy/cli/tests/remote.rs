//! Runs across hosts over zenoh on 127.0.0.1: the learner, the launcher and the expert as one
//! "host" (`alfd run --listen`), actors as another (`alfd join`), sharing nothing but the zenoh
//! link: their own run ids (so iceoryx2 prefixes), working directories and homes.

use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use alfd_wire as wire;

use crate::runtime::{rows, run_id, spawn_run, summary};
use crate::support::{alfd, text, timed, tmp, Background};

/// A port free on 127.0.0.1 for TCP and UDP, below Linux's ephemeral range (32768 and up): a
/// port the kernel handed out and this test released could be handed at once to a client socket
/// of a concurrent test (zenoh's QUIC clients bind one per connection) before its listener binds
/// it. The tests of this binary take turns through one counter; other binaries start elsewhere.
pub(crate) fn free_port() -> u16 {
    use std::sync::atomic::{AtomicU32, Ordering};
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let start = std::process::id().wrapping_mul(97);
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = 20_000 + (start.wrapping_add(n) % 12_000) as u16;
        let tcp = std::net::TcpListener::bind(("127.0.0.1", port));
        let udp = std::net::UdpSocket::bind(("127.0.0.1", port));
        if tcp.is_ok() && udp.is_ok() {
            return port;
        }
    }
}

/// `alfd join` as another host (its own working directory and home) with `link` (`--connect`
/// and how it proves who it is) and `role` (`--actors=N` or `--expert=NAME`).
fn spawn_host(link: &[String], role: &str, dir: &Path) -> Background {
    Background(Some(
        alfd()
            .arg("join")
            .args(link)
            .arg(role)
            .arg(format!("--dir={}", dir.join("join").display()))
            .current_dir(dir)
            .env("HOME", dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("alfd join runs"),
    ))
}

/// The link of a host joining the run on `port` of 127.0.0.1 over plain TCP.
pub(crate) fn insecure(port: u16) -> Vec<String> {
    vec![
        "--insecure".to_owned(),
        format!("--connect=tcp/127.0.0.1:{port}"),
    ]
}

/// `alfd join` with `actors` actors, as another host.
pub(crate) fn spawn_join(port: u16, actors: usize, dir: &Path) -> Background {
    spawn_host(&insecure(port), &format!("--actors={actors}"), dir)
}

/// `alfd join` serving the run's expert `name` (no actors), as another host.
fn spawn_expert_join(port: u16, name: &str, dir: &Path) -> Background {
    spawn_host(&insecure(port), &format!("--expert={name}"), dir)
}

/// Waits (at most `secs`) for a background process to end, and returns its output.
pub(crate) fn finish(mut p: Background, secs: u64) -> Output {
    let start = Instant::now();
    while p.child().try_wait().unwrap().is_none() {
        assert!(
            start.elapsed() < Duration::from_secs(secs),
            "still running after {secs} s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let child: Child = p.0.take().unwrap();
    child.wait_with_output().unwrap()
}

/// The mirror's run id recorded by `alfd join` in `join.json`.
pub(crate) fn mirror_id(join_dir: &Path) -> String {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(join_dir.join("join.json")).unwrap())
            .unwrap();
    v["mirror_run_id"].as_str().unwrap().to_owned()
}

#[test]
fn two_remote_actors_over_zenoh_play_a_run_to_its_end_within_the_budget() {
    let _time = timed!();
    let (out, remote) = (tmp("remote-run"), tmp("remote-host"));
    let port = free_port();
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    let run = spawn_run(
        &out,
        0,
        &[
            &listen,
            "--insecure",
            "episodes=150",
            "budget.total=10",
            "query.rule=first",
        ],
    );
    // A host built from other sources is refused by name, with exit code 2, and joins nothing.
    let other = alfd()
        .arg("join")
        .args(insecure(port))
        .arg("--actors=1")
        .arg(format!("--dir={}", remote.join("other").display()))
        .env("ALFD_SCHEMA_VERSION_OVERRIDE", "999")
        .output()
        .unwrap();
    assert_eq!(other.status.code(), Some(2), "{}", text(&other));
    assert!(
        String::from_utf8_lossy(&other.stderr).contains("schema version"),
        "{}",
        text(&other)
    );
    let join = spawn_join(port, 2, &remote);
    let o = finish(run, 120);
    assert!(o.status.success(), "{}", text(&o));
    let j = finish(join, 60);
    assert!(j.status.success(), "{}", text(&j));

    let s = summary(&out);
    assert_eq!(s["episodes"], 150);
    let rows = rows(&out);
    assert_eq!(rows.len(), 150);
    // With no local actor, the remote ones got ids 0 and 1, and both played.
    assert!(rows.iter().all(|r| r[8] == "0" || r[8] == "1"));
    assert!(rows.iter().any(|r| r[8] == "0") && rows.iter().any(|r| r[8] == "1"));
    // The budget holds across hosts, and every demonstration written was used by an actor.
    let demos = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 10);
    assert_eq!(s["demos"], 10);
    let queries: u32 = rows.iter().map(|r| r[5].parse::<u32>().unwrap()).sum();
    assert_eq!(
        queries, 10,
        "every demonstration was used by a remote actor"
    );
    assert_eq!(rows.last().unwrap()[3], "10", "demos_used");
    // The actors' logs are on their host, not on the learner's.
    let join_dir = remote.join("join");
    for log in ["actor-0.log", "actor-1.log"] {
        assert!(join_dir.join(log).is_file(), "{log} missing");
        assert!(!out.join(log).exists(), "{log} on the learner's host");
    }
    // Both hosts cleaned up their iceoryx2 files.
    for id in [run_id(&out), mirror_id(&join_dir)] {
        assert_eq!(
            wire::leftover_files(&id),
            Vec::<std::path::PathBuf>::new(),
            "{id}"
        );
    }
}

#[test]
fn an_expert_on_another_host_answers_every_query_and_its_demonstrations_are_written_here() {
    let _time = timed!();
    let (out, expert_host, actor_host) = (
        tmp("remote-expert"),
        tmp("remote-expert-host"),
        tmp("remote-actor-host"),
    );
    let port = free_port();
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    let run = spawn_run(
        &out,
        0,
        &[
            &listen,
            "--insecure",
            // Every answer is used however slow the loaded machine is: the test is of what is
            // written, not of the wait.
            "--query-timeout-ms=30000",
            "episodes=120",
            "budget.total=12",
            "query.rule=first",
        ],
    );
    // The run starts with its own expert (cartpole-perfect, local); a host joins as its expert,
    // and the run swaps to it (make before break) before any actor plays.
    let expert = spawn_expert_join(port, "cartpole-200", &expert_host);
    let log = expert_host.join("join").join("expert-2.log");
    let start = Instant::now();
    while !std::fs::read_to_string(&log).is_ok_and(|t| t.contains("answering queries")) {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the remote expert is not active after 60 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let actors = spawn_join(port, 2, &actor_host);
    let o = finish(run, 120);
    assert!(o.status.success(), "{}", text(&o));
    let a = finish(actors, 60);
    assert!(a.status.success(), "{}", text(&a));
    let e = finish(expert, 60);
    assert!(e.status.success(), "{}", text(&e));

    let s = summary(&out);
    assert_eq!(s["episodes"], 120);
    assert_eq!(s["expert_swaps"], 1);
    let rows = rows(&out);
    // Every demonstration is on the learner's host, each from the remote expert, within the
    // budget, and each was used by an actor (none lost, none counted twice).
    let demos = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 12);
    assert!(
        demos.iter().all(|d| d.expert == "cartpole-200"),
        "{:?}",
        demos.iter().map(|d| &d.expert).collect::<Vec<_>>()
    );
    assert_eq!(s["demos"], 12);
    let queries: u32 = rows.iter().map(|r| r[5].parse::<u32>().unwrap()).sum();
    assert_eq!(queries, 12, "every demonstration was used by an actor");
    assert_eq!(rows.last().unwrap()[3], "12", "demos_used");
    // The remote expert's own copy holds the same demonstrations.
    let there =
        alfd_demonstrators::demo_log::read(&expert_host.join("join").join("demos.jsonl")).unwrap();
    assert_eq!(there, demos);
    for id in [
        run_id(&out),
        mirror_id(&actor_host.join("join")),
        expert_host_id(&expert_host.join("join")),
    ] {
        assert_eq!(
            wire::leftover_files(&id),
            Vec::<std::path::PathBuf>::new(),
            "{id}"
        );
    }
}

#[test]
fn alfd_swap_expert_swaps_away_from_a_remote_expert_and_its_host_leaves() {
    let _time = timed!();
    let (out, expert_host) = (tmp("remote-swap"), tmp("remote-swap-host"));
    let port = free_port();
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    let run = spawn_run(
        &out,
        1,
        &[
            &listen,
            "--insecure",
            "episodes=100000",
            "budget.total=1000",
            "query.rule=first",
        ],
    );
    let expert = spawn_expert_join(port, "cartpole-200", &expert_host);
    let log = expert_host.join("join").join("expert-2.log");
    let start = Instant::now();
    while !std::fs::read_to_string(&log).is_ok_and(|t| t.contains("answering queries")) {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no remote expert"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // Back to an expert on the learner's host, make before break.
    let swap = alfd()
        .args(["swap-expert", "--run"])
        .arg(&out)
        .args(["--expert", "cartpole-perfect"])
        .output()
        .unwrap();
    assert!(swap.status.success(), "{}", text(&swap));
    // The remote host's expert was replaced: `alfd join --expert` ends, successfully.
    let e = finish(expert, 60);
    assert!(e.status.success(), "{}", text(&e));
    let o = crate::runtime::interrupt(run);
    let s = summary(&out);
    assert_eq!(s["expert_swaps"], 2, "{}", text(&o));
    // Every demonstration on the learner's host, in order (read checks the indices): the run's
    // first expert's, then the remote expert's, then only the local one's again.
    let demos = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    let names: Vec<&str> = demos.iter().map(|d| d.expert.as_str()).collect();
    let mut runs: Vec<&str> = names.clone();
    runs.dedup();
    assert!(
        matches!(
            runs.as_slice(),
            ["cartpole-200"]
                | ["cartpole-perfect", "cartpole-200"]
                | ["cartpole-200", "cartpole-perfect"]
                | ["cartpole-perfect", "cartpole-200", "cartpole-perfect"]
        ),
        "{runs:?}"
    );
    assert!(demos.len() <= 1000);
}

#[test]
fn a_remote_host_lost_mid_run_is_a_crash_and_a_rejoin_plays_on() {
    let _time = timed!();
    let (out, first, second) = (tmp("remote-drop"), tmp("remote-a"), tmp("remote-b"));
    let port = free_port();
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    let mut run = spawn_run(
        &out,
        1,
        &[
            &listen,
            "--insecure",
            "episodes=100000",
            "budget.total=20",
            "query.rule=first",
        ],
    );
    let remote_rows = |out: &Path| rows(out).iter().filter(|r| r[8] == "1").count();
    let wait_until = |what: &str, run: &mut Background, ok: &dyn Fn() -> bool| {
        let start = Instant::now();
        while !ok() {
            if let Some(status) = run.child().try_wait().unwrap() {
                panic!("the run ended ({status}) before {what}");
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "no {what} in 60 s"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    // A remote actor (id 1, above the local actor 0) plays...
    let mut join = spawn_join(port, 1, &first);
    wait_until("remote episodes", &mut run, &|| remote_rows(&out) >= 5);
    // ...until its host dies at once (its process and the link with it).
    let pid = join.child().id().to_string();
    assert!(Command::new("kill")
        .args(["-KILL", &pid])
        .status()
        .unwrap()
        .success());
    let _ = join.0.take().expect("running").wait();
    // The run goes on with its local actor.
    let at_kill = rows(&out).len();
    wait_until("local episodes after the loss", &mut run, &|| {
        rows(&out).len() >= at_kill + 20
    });
    // A host joining again gets the free id 1 (a new incarnation) and plays on.
    let remote_before = remote_rows(&out);
    let rejoin = spawn_join(port, 1, &second);
    wait_until("episodes of the rejoined host", &mut run, &|| {
        remote_rows(&out) >= remote_before + 5
    });
    let o = crate::runtime::interrupt(run);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("link dropped"),
        "the launcher reports the lost host: {}",
        text(&o)
    );
    let j = finish(rejoin, 60);
    assert!(j.status.success(), "{}", text(&j));
    let s = summary(&out);
    assert_eq!(s["interrupted"], true);
    let demos = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert!(
        demos.len() <= 20,
        "{} demonstrations, budget 20",
        demos.len()
    );
    assert_eq!(
        wire::leftover_files(&run_id(&out)),
        Vec::<std::path::PathBuf>::new()
    );
    // The killed host left its mirror's files behind (nobody was there to remove them): the
    // next `alfd clean` removes them, as it does for any dead run.
    // Its orphaned actor exits on its own first (it sees its parent gone).
    let dead = mirror_id(&first.join("join"));
    let start = Instant::now();
    while !wire::leftover_files(&dead).is_empty() && start.elapsed() < Duration::from_secs(30) {
        let _ = wire::clean_run(&dead);
        std::thread::sleep(Duration::from_millis(200));
    }
    assert_eq!(
        wire::leftover_files(&dead),
        Vec::<std::path::PathBuf>::new()
    );
}

/// `alfd ARGS` with its run or host directory under `out`, which must end with exit code 2.
fn refused_with_2(args: &[&str], out: &Path) -> Output {
    let o = alfd()
        .args(args)
        .arg(format!(
            "--{}={}",
            if args[0] == "run" { "out" } else { "dir" },
            out.join("x").display()
        ))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
    o
}

#[test]
fn bad_endpoints_and_actor_counts_are_refused_with_exit_code_2() {
    let _time = timed!();
    let out = tmp("remote-bad");
    for args in [
        vec!["join", "--insecure", "--connect", "127.0.0.1:7447"],
        vec!["join", "--insecure", "--connect", "udp/127.0.0.1:7447"],
        vec!["join", "--insecure", "--connect", "tcp/127.0.0.1:0"],
        vec![
            "join",
            "--insecure",
            "--connect",
            "tcp/127.0.0.1:7447",
            "--actors=0",
        ],
        vec!["run", "--actors=0"],
        vec![
            "run",
            "--insecure",
            "--listen",
            "tcp/no-such-host.invalid:7447",
        ],
    ] {
        let o = refused_with_2(&args, &out);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("--connect") || err.contains("--listen") || err.contains("--actors"),
            "{args:?}: the error names the flag: {err}"
        );
    }
}

/// The iceoryx2 run id of the expert's copy of the run, as `alfd join --expert` recorded it in
/// its `join.json`.
pub(crate) fn expert_host_id(join_dir: &Path) -> String {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(join_dir.join("join.json")).unwrap())
            .unwrap();
    v["expert_host_run_id"].as_str().unwrap().to_owned()
}

/// Lines of a `demos.jsonl` (0 while it does not exist).
fn lines(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .count()
}

/// Waits until `expert-<generation>.log` in `dir` says the expert answers.
pub(crate) fn wait_answering(dir: &Path, generation: u16) {
    let log = dir.join(format!("expert-{generation}.log"));
    let start = Instant::now();
    while !std::fs::read_to_string(&log).is_ok_and(|t| t.contains("answering queries")) {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{} does not answer after 60 s",
            log.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The dead remote host left its expert's iceoryx2 files behind (nobody was there to remove
/// them); its orphaned `alfd-expert` exits on its own (it sees its parent gone), then the next
/// `alfd clean` removes them, as for any dead run.
fn clean_dead_host(id: &str) {
    let start = Instant::now();
    while !wire::leftover_files(id).is_empty() && start.elapsed() < Duration::from_secs(30) {
        let _ = wire::clean_run(id);
        std::thread::sleep(Duration::from_millis(200));
    }
    assert_eq!(wire::leftover_files(id), Vec::<std::path::PathBuf>::new());
}

#[test]
fn a_remote_expert_killed_mid_run_is_restarted_here_and_no_demonstration_is_lost() {
    let _time = timed!();
    let (out, expert_host, actor_host) = (
        tmp("remote-expert-kill"),
        tmp("remote-expert-kill-host"),
        tmp("remote-expert-kill-actors"),
    );
    let port = free_port();
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    // Every step asks until the budget is spent (no model to refit, so answers are quick): the
    // remote expert dies with demonstrations flowing, and its successor spends the rest.
    let (episodes, budget) = (120, 2000);
    let mut run = spawn_run(
        &out,
        0,
        &[
            &listen,
            "--insecure",
            &format!("episodes={episodes}"),
            "env.max_episode_steps=200",
            "expert.model=none",
            "query.rule=first",
            &format!("budget.total={budget}"),
        ],
    );
    let mut expert = spawn_expert_join(port, "cartpole-200", &expert_host);
    wait_answering(&expert_host.join("join"), 2);
    let actors = spawn_join(port, 2, &actor_host);
    let demos_here = out.join("demos.jsonl");
    crate::runtime::wait_until(&mut run, "50 demonstrations of the remote expert", || {
        lines(&demos_here) >= 50
    });
    // Its host dies at once: `alfd join --expert` and the link with it.
    crate::runtime::signal("KILL", expert.child().id());
    let _ = expert.0.take().expect("running").wait();
    let there = expert_host.join("join").join("demos.jsonl");
    let remote_demos = alfd_demonstrators::demo_log::read(&there).unwrap();
    assert!(
        remote_demos.len() < budget,
        "the budget was spent before the kill"
    );
    // The run goes on (the actors act on their own meanwhile), restarts the expert here under
    // the same name, and finishes.
    let (o, s) = crate::runtime::finished(run, &out, episodes);
    let a = finish(actors, 60);
    assert!(a.status.success(), "{}", text(&a));
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(err.contains("link dropped"), "the loss is reported: {err}");
    assert!(err.contains("expert-3 answers again"), "{err}");
    assert_eq!(
        (s["expert_swaps"].as_u64(), s["expert_restarts"].as_u64()),
        (Some(1), Some(1))
    );
    assert!(std::fs::read_to_string(out.join("expert-3.log"))
        .unwrap()
        .contains("answering queries"));
    // Every demonstration is on the learner's host, in order, within the budget, and each is
    // counted once: the file, the summary and the last episode agree.
    let demos = alfd_demonstrators::demo_log::read(&demos_here).unwrap();
    for (i, d) in demos.iter().enumerate() {
        assert_eq!(d.index as usize, i);
        assert_eq!(d.expert, "cartpole-200");
    }
    assert!(demos.len() <= budget, "{} > {budget}", demos.len());
    assert_eq!(s["demos"].as_u64(), Some(demos.len() as u64));
    assert_eq!(s["demos_used"].as_u64(), Some(demos.len() as u64));
    let rows = rows(&out);
    assert_eq!(
        rows.last().unwrap()[3],
        demos.len().to_string(),
        "demos_used"
    );
    // The remote expert's demonstrations are all here, but for answers in flight when it died
    // (at most one per actor): the remote copy may hold those, never fewer.
    let same = demos
        .iter()
        .zip(&remote_demos)
        .take_while(|(a, b)| a == b)
        .count();
    assert!(
        same + 2 >= remote_demos.len(),
        "{same} of the remote expert's {} demonstrations here",
        remote_demos.len()
    );
    // Its successor here carried on from them.
    assert!(demos.len() > same, "{} <= {same}", demos.len());
    assert_eq!(
        wire::leftover_files(&run_id(&out)),
        Vec::<std::path::PathBuf>::new()
    );
    clean_dead_host(&expert_host_id(&expert_host.join("join")));
}

#[test]
fn a_remote_python_expert_lost_with_its_host_leaves_the_run_going_without_an_expert() {
    let _time = timed!();
    let (out, expert_host) = (tmp("remote-python-kill"), tmp("remote-python-host"));
    // A demonstrator only the other host has: a module in its working directory.
    std::fs::write(
        expert_host.join("only_there.py"),
        "def balance(obs):\n    return 1 if obs[2] + 0.5 * obs[3] > 0.0 else 0\n",
    )
    .unwrap();
    let port = free_port();
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    let mut run = spawn_run(
        &out,
        1,
        &[
            &listen,
            "--insecure",
            "episodes=100000",
            "env.max_episode_steps=200",
            "expert.model=none",
            "query.rule=first",
            "budget.total=100000",
        ],
    );
    let name = "python:only_there:balance";
    let mut expert = spawn_expert_join(port, name, &expert_host);
    wait_answering(&expert_host.join("join"), 2);
    let demos_here = out.join("demos.jsonl");
    let remote = || {
        alfd_demonstrators::demo_log::read(&demos_here)
            .unwrap_or_default()
            .iter()
            .filter(|d| d.expert == name)
            .count()
    };
    crate::runtime::wait_until(&mut run, "demonstrations of the remote expert", || {
        remote() >= 20
    });
    crate::runtime::signal("KILL", expert.child().id());
    let _ = expert.0.take().expect("running").wait();
    // The learner's host cannot start that name: the run goes on without an expert, its actor
    // acting on its own, instead of failing.
    let log = out.join("expert-3.log");
    let generation_3 = [
        format!("--run-id={}", run_id(&out)),
        "--generation=3".into(),
    ];
    let generation_3: Vec<&str> = generation_3.iter().map(String::as_str).collect();
    crate::runtime::wait_until(&mut run, "the replacement tried here and gone", || {
        std::fs::metadata(&log).is_ok_and(|m| m.len() > 0)
            && crate::runtime::find_process("alfd-expert", &generation_3).is_none()
    });
    let at_loss = lines(&demos_here);
    let n = rows(&out).len();
    crate::runtime::wait_until(&mut run, "episodes without an expert", || {
        rows(&out).len() >= n + 20
    });
    let o = crate::runtime::interrupt(run);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(err.contains("link dropped"), "{err}");
    assert!(err.contains("goes on without an expert"), "{err}");
    let s = summary(&out);
    assert_eq!(s["expert_restarts"].as_u64(), Some(1), "{s}");
    // Nothing was written after the loss, and every line before it is in order: the run's
    // first expert's, then the remote one's.
    let demos = alfd_demonstrators::demo_log::read(&demos_here).unwrap();
    assert_eq!(demos.len(), at_loss);
    assert!(
        demos
            .iter()
            .all(|d| d.expert == name || d.expert == crate::runtime::EXPERT),
        "{:?}",
        demos.iter().map(|d| &d.expert).collect::<Vec<_>>()
    );
    assert!(demos.iter().filter(|d| d.expert == name).count() >= 20);
    assert_eq!(s["demos"].as_u64(), Some(demos.len() as u64));
    assert_eq!(
        wire::leftover_files(&run_id(&out)),
        Vec::<std::path::PathBuf>::new()
    );
    clean_dead_host(&expert_host_id(&expert_host.join("join")));
}

#[test]
fn a_remote_actor_killed_with_sigkill_is_restarted_by_its_host_with_a_new_incarnation() {
    let _time = timed!();
    let (out, remote) = (tmp("remote-actor-kill"), tmp("remote-actor-kill-host"));
    let port = free_port();
    let listen = format!("--listen=tcp/127.0.0.1:{port}");
    // The run's only actor is remote (id 0): once it is killed, nobody plays until its host
    // restarts it, so the run can end only with the restarted actor's episodes.
    let episodes = 300;
    let mut run = spawn_run(
        &out,
        0,
        &[
            &listen,
            "--insecure",
            &format!("episodes={episodes}"),
            "env.max_episode_steps=100",
            "budget.total=20",
            "query.rule=first",
        ],
    );
    let join = spawn_join(port, 1, &remote);
    crate::runtime::wait_until(&mut run, "5 remote episodes", || rows(&out).len() >= 5);
    let mirror = format!("--run-id={}", mirror_id(&remote.join("join")));
    let pid = crate::runtime::find_process("alfd-actor", &[&mirror, "--actor-id=0"])
        .expect("the remote actor runs");
    crate::runtime::signal("KILL", pid);
    let at_kill = rows(&out).len();
    assert!(at_kill < episodes, "the run ended before the kill");
    // Its host restarts it with a new incarnation; it plays the run to its end.
    let (o, s) = crate::runtime::finished(run, &out, episodes);
    let j = finish(join, 60);
    assert!(j.status.success(), "{}", text(&j));
    assert_eq!(s["actor_restarts"].as_u64(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("its host restarts it"), "{err}");
    let log = std::fs::read_to_string(remote.join("join").join("actor-0.log")).unwrap();
    assert!(
        log.contains("incarnation=1") && log.contains("incarnation=2"),
        "the restarted actor is incarnation 2: {log}"
    );
    let rows = rows(&out);
    assert!(
        rows[at_kill..].iter().all(|r| r[8] == "0"),
        "every episode after the kill is the restarted actor's"
    );
    assert!(rows.len() - at_kill >= 1);
    // The budget holds, and every demonstration written was used.
    let demos = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert!(
        demos.len() <= 20,
        "{} demonstrations, budget 20",
        demos.len()
    );
    assert_eq!(s["demos"].as_u64(), Some(demos.len() as u64));
    assert_eq!(s["demos_used"].as_u64(), Some(demos.len() as u64));
    for id in [run_id(&out), mirror_id(&remote.join("join"))] {
        assert_eq!(
            wire::leftover_files(&id),
            Vec::<std::path::PathBuf>::new(),
            "{id}"
        );
    }
}

/// `alfd certs DIR --host …` (the CLI), checked.
fn certs(dir: &Path, hosts: &[&str]) {
    let mut c = alfd();
    c.arg("certs").arg(dir);
    for h in hosts {
        c.args(["--host", h]);
    }
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
}

/// The --tls-* flags for host `name`'s files in `dir`, with the CA of `ca_dir`.
fn tls_flags(ca_dir: &Path, dir: &Path, name: &str) -> Vec<String> {
    vec![
        format!("--tls-ca={}", ca_dir.join("ca.pem").display()),
        format!("--tls-cert={}", dir.join(format!("{name}.pem")).display()),
        format!("--tls-key={}", dir.join(format!("{name}.key")).display()),
    ]
}

#[test]
fn tls_a_run_across_hosts_takes_hosts_of_its_ca_and_refuses_strangers() {
    let _time = timed!();
    let (out, remote, ca, other) = (
        tmp("tls-run"),
        tmp("tls-host"),
        tmp("tls-ca"),
        tmp("tls-other-ca"),
    );
    certs(&ca, &["127.0.0.1", "remote"]);
    certs(&other, &["stranger"]);
    let port = free_port();
    let endpoint = format!("quic/127.0.0.1:{port}");
    let mut sets = vec![format!("--listen={endpoint}")];
    sets.extend(tls_flags(&ca, &ca, "127.0.0.1"));
    sets.extend(["episodes=60", "budget.total=10", "query.rule=first"].map(String::from));
    let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
    let run = spawn_run(&out, 0, &sets);
    // Strangers first: a host showing another CA's certificate, and one without TLS.
    let stranger = alfd()
        .args(["join", "--connect", &endpoint, "--wait-s=3"])
        .args(tls_flags(&ca, &other, "stranger"))
        .arg(format!("--dir={}", remote.join("stranger").display()))
        .output()
        .unwrap();
    let plain = alfd()
        .args(["join", "--wait-s=2"])
        .args(insecure(port))
        .arg(format!("--dir={}", remote.join("plain").display()))
        .output()
        .unwrap();
    for (who, o) in [
        ("another CA's host", &stranger),
        ("a plain TCP host", &plain),
    ] {
        assert_eq!(o.status.code(), Some(1), "{who}: {}", text(o));
        assert!(text(o).contains("no run answered"), "{who}: {}", text(o));
    }
    // The run's own host plays it to the end, unaffected.
    let mut link = vec![format!("--connect={endpoint}")];
    link.extend(tls_flags(&ca, &ca, "remote"));
    let join = spawn_host(&link, "--actors=2", &remote);
    let o = finish(run, 120);
    assert!(o.status.success(), "{}", text(&o));
    let j = finish(join, 60);
    assert!(j.status.success(), "{}", text(&j));
    let s = summary(&out);
    assert_eq!(s["episodes"], 60);
    assert_eq!(rows(&out).len(), 60);
    assert_eq!(s["demos"], 10);
    // The run said whom it refused, and why.
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("refused a peer: invalid peer certificate"),
        "{err}"
    );
}

#[test]
fn plain_tcp_without_insecure_and_tls_over_tcp_are_refused_with_exit_code_2() {
    let _time = timed!();
    let out = tmp("tls-plain");
    for (args, says) in [
        (vec!["run", "--listen", "tcp/127.0.0.1:7447"], "--insecure"),
        (
            vec!["join", "--connect", "tcp/127.0.0.1:7447"],
            "--insecure",
        ),
        (
            vec!["run", "--listen", "tls/127.0.0.1:7447"],
            "quic/127.0.0.1:7447",
        ),
        (vec!["run", "--listen", "quic/127.0.0.1:7447"], "--tls-ca"),
        (
            vec![
                "join",
                "--connect",
                "quic/127.0.0.1:7447",
                "--tls-ca=/nonexistent/ca.pem",
            ],
            "all three",
        ),
    ] {
        let o = refused_with_2(&args, &out);
        assert!(text(&o).contains(says), "{args:?}: {}", text(&o));
        assert!(!out.join("x").exists(), "{args:?} made its directory");
    }
}

#[test]
fn tls_alfd_certs_refuses_bad_names_and_days_with_exit_code_2_and_keeps_what_it_made() {
    let _time = timed!();
    let dir = tmp("tls-certs-bad");
    certs(&dir, &["h1"]);
    let ca = std::fs::read(dir.join("ca.pem")).unwrap();
    for (args, says) in [
        (vec!["--days", "0"], "--days"),
        (vec!["--host", "a b"], "a b"),
        (vec!["--host", "h1"], "h1.key"),
    ] {
        let o = alfd().arg("certs").arg(&dir).args(&args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
        assert!(text(&o).contains(says), "{args:?}: {}", text(&o));
    }
    // The CA and the host's files made first are as they were.
    assert_eq!(std::fs::read(dir.join("ca.pem")).unwrap(), ca);
    assert!(dir.join("h1.pem").is_file() && dir.join("h1.key").is_file());
}
