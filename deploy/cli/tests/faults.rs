//! Faults of a multi-process run, injected with real signals: the learner killed with SIGKILL
//! is restarted from its checkpoint, and with no restarts left (`--max-restarts 0`) a killed
//! actor or learner ends the run naming the limit; the launcher killed with SIGKILL
//! leaves no process and no iceoryx2 file, and `alfd resume` finishes the run; `episodes = N`
//! with several actors plays and records exactly N episodes, and the run's files agree; records
//! an actor says it sent that never came are counted lost and played; `alfd clean` removes a
//! dead run's files and leaves a live run alone.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use alfd_wire as wire;

use crate::runtime::{
    check_run_dir, find_process, finished, interrupt, rows, run, run_id, signal, spawn_run,
    summary, wait_output, wait_rows, wait_until,
};
use crate::support::{alfd, text, timed, tmp, Background};

/// Every episode of `dir`'s `episodes.csv` once, numbered 0..n in order; the last row's
/// `demos_used` equals the lines of `demos.jsonl` and `summary.json`'s count.
fn check_rows_and_demos(dir: &Path, episodes: usize) {
    let rows = rows(dir);
    let numbers: Vec<usize> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
    assert_eq!(numbers, (0..episodes).collect::<Vec<_>>());
    let demos = std::fs::read_to_string(dir.join("demos.jsonl"))
        .unwrap()
        .lines()
        .count();
    let s = summary(dir);
    assert_eq!(
        (
            rows.last().unwrap()[3].parse::<usize>().unwrap(),
            s["demos_used"].as_u64().unwrap() as usize,
            s["demos"].as_u64().unwrap() as usize,
        ),
        (demos, demos, demos),
        "last row, summary.json and demos.jsonl disagree"
    );
}

/// Processes of run `id` still alive.
fn processes_of(id: &str) -> Vec<(&'static str, u32)> {
    let run = format!("--run-id={id}");
    ["alfd-actor", "alfd-expert", "alfd-learner"]
        .into_iter()
        .filter_map(|bin| find_process(bin, &[&run]).map(|pid| (bin, pid)))
        .collect()
}

/// A run that asks the expert on every step until its budget is spent (no model to refit), with
/// 200-step episodes and a learner checkpointing every 200 updates.
const FAULT_RUN: [&str; 6] = [
    "episodes=300",
    "env.max_episode_steps=200",
    "expert.model=none",
    "query.rule=first",
    "budget.total=1500",
    "--checkpoint-every=200",
];

/// [`FAULT_RUN`] with 2 actors in the background, once its learner has checkpointed and 30
/// episodes are recorded.
fn checkpointed_fault_run(out: &Path) -> Background {
    let mut child = spawn_run(out, 2, &FAULT_RUN);
    wait_until(&mut child, "a learner checkpoint", || {
        out.join("learner.ckpt").is_file()
    });
    wait_rows(out, 30, &mut child);
    child
}

#[test]
fn a_learner_killed_with_sigkill_is_restarted_from_its_checkpoint_and_the_run_completes() {
    let _time = timed!();
    let out = tmp("learner-killed");
    let child = checkpointed_fault_run(&out);
    let id = run_id(&out);
    let pid = find_process("alfd-learner", &[&format!("--run-id={id}")]).expect("learner");
    signal("KILL", pid);
    let (o, s) = finished(child, &out, 300);
    assert_eq!(
        (s["learner_restarts"].as_u64(), s["actor_restarts"].as_u64()),
        (Some(1), Some(0)),
        "{}",
        text(&o)
    );
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        err.contains("alfd-learner was killed by signal 9; restarting it from its last checkpoint"),
        "{err}"
    );
    let log = std::fs::read_to_string(out.join("learner.log")).unwrap();
    assert!(log.contains("restored from the checkpoint"), "{log}");
    check_run_dir(&out, 1500);
    check_rows_and_demos(&out, 300);
    assert_eq!(wire::leftover_files(&id), Vec::<PathBuf>::new());
}

#[test]
fn with_no_restarts_left_a_killed_actor_or_learner_ends_the_run_naming_the_limit() {
    let _time = timed!();
    for (bin, says) in [
        (
            "alfd-actor",
            "alfd-actor actor-0 was killed by signal 9, and was restarted",
        ),
        ("alfd-learner", "alfd-learner was killed by signal 9"),
    ] {
        let out = tmp(&format!("give-up-{bin}"));
        let sets = [
            "episodes=300",
            "env.max_episode_steps=200",
            "--max-restarts=0",
        ];
        let mut child = spawn_run(&out, 1, &sets);
        wait_rows(&out, 5, &mut child);
        let id = run_id(&out);
        let pid = find_process(bin, &[&format!("--run-id={id}")]).expect(bin);
        signal("KILL", pid);
        let o = wait_output(child, Duration::from_secs(60));
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(1), "{bin}: {}", text(&o));
        assert!(
            err.contains(says) && err.contains("0 times already (--max-restarts 0)"),
            "{bin}: {err}"
        );
        // The episodes so far are kept, and the run leaves nothing running or behind.
        assert!(rows(&out).len() >= 5, "{bin}");
        assert_eq!(processes_of(&id), Vec::new(), "{bin}");
        assert_eq!(wire::leftover_files(&id), Vec::<PathBuf>::new(), "{bin}");
    }
}

#[test]
fn a_launcher_killed_with_sigkill_leaves_nothing_running_and_alfd_resume_finishes_the_run() {
    let _time = timed!();
    let out = tmp("launcher-killed");
    let mut child = checkpointed_fault_run(&out);
    let id = run_id(&out);
    let launcher = child.child().id();
    signal("KILL", launcher);
    let killed = Instant::now();
    let _ = child.0.take().unwrap().wait();
    // Every child notices within a few seconds, saves what it must, and the last one out
    // removes the run's iceoryx2 files.
    while !processes_of(&id).is_empty() || !wire::leftover_files(&id).is_empty() {
        assert!(
            killed.elapsed() < Duration::from_secs(8),
            "8 s after the launcher's death: processes {:?}, files {:?}",
            processes_of(&id),
            wire::leftover_files(&id)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    eprintln!(
        "launcher killed: its children were gone and the run's files removed {} ms later",
        killed.elapsed().as_millis()
    );
    assert!(out.join("weights.safetensors").is_file());
    let recorded = rows(&out).len();
    assert!((30..300).contains(&recorded), "{recorded}");

    let o = alfd()
        .args(["resume", out.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let s = summary(&out);
    assert_eq!(
        (s["episodes"].as_u64(), s["interrupted"].as_bool()),
        (Some(300), Some(false))
    );
    let log = std::fs::read_to_string(out.join("learner.log")).unwrap();
    assert!(log.contains("restored from the checkpoint"), "{log}");
    check_run_dir(&out, 1500);
    check_rows_and_demos(&out, 300);
    let resumed = run_id(&out);
    assert_ne!(resumed, id);
    assert_eq!(wire::leftover_files(&resumed), Vec::<PathBuf>::new());
    // A finished run is not resumed again.
    let again = alfd()
        .args(["resume", out.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(2), "{}", text(&again));
}

#[test]
fn episodes_n_with_two_actors_plays_and_records_n_and_the_files_agree() {
    let _time = timed!();
    for (episodes, actors) in [(5usize, 2usize), (7, 3)] {
        let out = tmp(&format!("episodes-{episodes}-{actors}"));
        let o = run(
            &out,
            actors,
            &[
                &format!("episodes={episodes}"),
                "query.rule=first",
                "expert.model=none",
                "budget.total=1000",
            ],
        );
        assert!(o.status.success(), "{}", text(&o));
        assert_eq!(summary(&out)["episodes"], episodes);
        check_rows_and_demos(&out, episodes);
        // Every actor played its share.
        for a in 0..actors {
            let share = episodes / actors + usize::from(a < episodes % actors);
            assert_eq!(
                rows(&out).iter().filter(|r| r[8] == a.to_string()).count(),
                share,
                "actor {a}"
            );
        }
        let log = std::fs::read_to_string(out.join("actor-0.log")).unwrap();
        assert!(log.contains("played its share"), "{log}");
    }
}

/// Records an actor says it sent (its share played) that never reached the launcher are
/// counted lost and played: the episode limit is reached without them, and `summary.json` and
/// the end of the output say how many. The message comes from the test, as actor 7's (no actor
/// of this run) of an incarnation that played nothing here, three times as an actor repeats it.
#[test]
fn records_an_actor_says_it_sent_that_never_came_count_played_and_lost() {
    let _time = timed!();
    let out = tmp("lost-records");
    let sets = [
        "episodes=3000",
        "steps=0",
        "env.max_episode_steps=20",
        "query.rule=never",
        "budget.total=0",
        "expert.model=none",
    ];
    let mut r = spawn_run(&out, 2, &sets);
    wait_rows(&out, 1, &mut r);
    let actor = wire::Process::new(wire::Role::Actor, 7);
    let me = wire::Wire::connect(&run_id(&out), actor, wire::SCHEMA_VERSION).unwrap();
    let mut tx = me.episode_sender().unwrap();
    for _ in 0..3 {
        tx.send(wire::Progress::share_played(99, 3)).unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    // Gone once the launcher has drained its buffer (it does every 100 ms at most).
    let seen = rows(&out).len();
    wait_rows(&out, seen + 20, &mut r);
    drop(tx);
    drop(me);
    let o = wait_output(r, Duration::from_secs(180));
    assert!(o.status.success(), "{}", text(&o));
    let s = summary(&out);
    assert_eq!(
        (s["episodes_lost"].as_u64(), s["episodes"].as_u64()),
        (Some(3), Some(2997))
    );
    check_rows_and_demos(&out, 2997);
    assert!(
        text(&o).contains("3 episode records never reached the launcher"),
        "{}",
        text(&o)
    );
}

#[test]
fn alfd_clean_removes_a_dead_runs_files_and_leaves_a_live_run_alone() {
    let _time = timed!();
    let (dead_dir, live_dir) = (tmp("clean-dead"), tmp("clean-live"));
    let mut dead = spawn_run(&dead_dir, 1, &["episodes=1000000"]);
    let mut live = spawn_run(&live_dir, 1, &["episodes=1000000"]);
    wait_rows(&dead_dir, 3, &mut dead);
    wait_rows(&live_dir, 3, &mut live);
    let (dead_id, live_id) = (run_id(&dead_dir), run_id(&live_dir));
    // Everything of the first run dies at once: nobody is left to remove its files.
    let pids: Vec<u32> = processes_of(&dead_id).into_iter().map(|(_, p)| p).collect();
    assert_eq!(pids.len(), 3);
    signal("KILL", dead.child().id());
    for pid in pids {
        signal("KILL", pid);
    }
    let _ = dead.0.take().unwrap().wait();
    let start = Instant::now();
    while !processes_of(&dead_id).is_empty() {
        assert!(start.elapsed() < Duration::from_secs(5));
        std::thread::sleep(Duration::from_millis(20));
    }
    let left = wire::leftover_files(&dead_id);
    assert!(!left.is_empty(), "a run killed whole leaves files");
    let live_files = wire::leftover_files(&live_id);
    assert!(!live_files.is_empty());

    let dry = alfd().args(["clean", "--dry-run"]).output().unwrap();
    assert!(dry.status.success(), "{}", text(&dry));
    let said = String::from_utf8_lossy(&dry.stdout).into_owned();
    assert!(said.contains(&format!("{dead_id}: dead")), "{said}");
    assert!(said.contains(&format!("{live_id}: live")), "{said}");
    assert_eq!(
        wire::leftover_files(&dead_id),
        left,
        "a dry run removes nothing"
    );

    let o = alfd().arg("clean").output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let said = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        said.contains(&format!("{dead_id}: dead, {} files removed", left.len())),
        "{said}"
    );
    assert!(said.contains(&format!("{live_id}: live")), "{said}");
    assert_eq!(wire::leftover_files(&dead_id), Vec::<PathBuf>::new());
    // The live run kept its files and goes on to a clean end.
    assert!(!wire::leftover_files(&live_id).is_empty());
    let n = rows(&live_dir).len();
    wait_rows(&live_dir, n + 3, &mut live);
    let o = interrupt(live);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    assert_eq!(wire::leftover_files(&live_id), Vec::<PathBuf>::new());
}

#[test]
fn a_run_stopped_with_ctrl_c_is_resumed_to_its_end() {
    let _time = timed!();
    let out = tmp("interrupted");
    let mut child = spawn_run(&out, 2, &FAULT_RUN);
    wait_rows(&out, 30, &mut child);
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    assert_eq!(summary(&out)["interrupted"], true);
    let recorded = rows(&out).len();
    assert!(recorded < 300, "{recorded}");
    let o = alfd()
        .args(["resume", out.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert_eq!(summary(&out)["interrupted"], false);
    check_run_dir(&out, 1500);
    check_rows_and_demos(&out, 300);
    // The TensorBoard scalars of both launches: one `demos/used` per episode, each at its
    // episode's own step (the resumed launch goes on where the first stopped).
    let tb = crate::tensorboard::read(&out.join("tb"));
    let mut at: Vec<u64> = tb["demos/used"].iter().map(|p| p.0).collect();
    let mut steps: Vec<u64> = crate::tensorboard::column(&out, "demos_used")
        .iter()
        .map(|c| c.0)
        .collect();
    at.sort_unstable();
    steps.sort_unstable();
    assert_eq!(at, steps);
}

/// One actor in lockstep, stopped with Ctrl-C after its checkpoints, then `alfd resume`: the
/// learner's and the actor's checkpoints pair up at an episode end, and the run comes out as the
/// uninterrupted one (which is `alfd local`'s) to the byte.
#[test]
fn a_lockstep_run_stopped_and_resumed_is_the_uninterrupted_run_to_the_byte() {
    let _time = timed!();
    let sets = [
        "episodes=120",
        "evaluation.every=5",
        "evaluation.episodes=2",
    ];
    let local = tmp("exact-resume-local");
    let mut c = alfd();
    c.args([
        "local",
        "--config",
        "deploy/configs/cartpole-bdqn-krr.toml",
        "--quiet",
    ])
    .arg(format!("--out={}", local.display()))
    .args(["--set", &format!("expert.name={}", crate::runtime::EXPERT)]);
    for s in sets {
        c.args(["--set", s]);
    }
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", text(&o));

    let out = tmp("exact-resume");
    let mut lockstep = sets.to_vec();
    lockstep.extend(["--window=1", "--checkpoint-every=100"]);
    let mut child = spawn_run(&out, 1, &lockstep);
    wait_until(&mut child, "two actor checkpoints", || {
        alfd_actor::checkpoint::load(
            &out,
            0,
            &std::fs::read_to_string(out.join("config.toml")).unwrap_or_default(),
        )
        .ok()
        .flatten()
        .is_some_and(|f| f.slots.len() == 2)
    });
    let o = interrupt(child);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let stopped_at = rows(&out).len();
    assert!(stopped_at < 120, "{stopped_at}");
    // A damaged actor checkpoint is refused, naming it, and left as it is.
    let ckpt = out.join("actor-0.ckpt");
    let good = std::fs::read(&ckpt).unwrap();
    std::fs::write(&ckpt, &good[..good.len() - 9]).unwrap();
    let o = alfd()
        .args(["resume", out.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("actor-0.ckpt: truncated checkpoint"),
        "{}",
        text(&o)
    );
    assert_eq!(std::fs::read(&ckpt).unwrap().len(), good.len() - 9);
    std::fs::write(&ckpt, &good).unwrap();

    let o = alfd()
        .args(["resume", out.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let actor_log = std::fs::read_to_string(out.join("actor-0.log")).unwrap();
    assert!(
        actor_log.contains("restored from the checkpoint"),
        "{actor_log}"
    );
    let single = std::fs::read_to_string(local.join("episodes.csv")).unwrap();
    let resumed = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    assert_eq!(single.lines().count(), 121);
    assert_eq!(resumed, single, "stopped after {stopped_at} episodes");
    let d1 = alfd_demonstrators::demo_log::read(&local.join("demos.jsonl")).unwrap();
    let d2 = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert!(!d1.is_empty());
    assert_eq!(d2[..d1.len()], d1[..]);
}

/// A run whose launcher was killed is resumed while its disk is full: `alfd resume` waits for
/// room to write the files a launch starts with (the run's lock, `runtime.toml`, `run.json`)
/// instead of failing, and the run then finishes whole.
#[test]
fn alfd_resume_on_a_full_disk_waits_for_room_and_finishes_the_run() {
    let _time = timed!();
    let dir = tmp("resume-disk-full");
    let Some(_disk) = crate::support::tmpfs_or_skip(&dir, 24, "the resume test") else {
        return;
    };
    let out = dir.join("run");
    let mut child = checkpointed_fault_run(&out);
    let id = run_id(&out);
    signal("KILL", child.child().id());
    let _ = child.0.take().unwrap().wait();
    let killed = Instant::now();
    while !processes_of(&id).is_empty() {
        assert!(
            killed.elapsed() < Duration::from_secs(8),
            "{:?}",
            processes_of(&id)
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // The file system full to the last byte while the resume starts, room made 2 s later.
    let filler = dir.join("filler");
    let f = crate::support::fill_up(&filler);
    let resume = alfd()
        .args(["resume", out.to_str().unwrap(), "--quiet"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(2));
    drop(f);
    std::fs::remove_file(&filler).unwrap();
    let o = resume.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let s = summary(&out);
    assert_eq!(
        (s["episodes"].as_u64(), s["interrupted"].as_bool()),
        (Some(300), Some(false))
    );
    check_run_dir(&out, 1500);
    check_rows_and_demos(&out, 300);
}

/// A full disk refuses a demonstration: the expert does not exit (no restart), leaves queries
/// unanswered for a moment, rolls its budget and model back to what `demos.jsonl` holds, and
/// answers again once there is room; `demos.jsonl` stays gap-free and as counted.
#[test]
fn a_full_disk_pauses_the_expert_without_a_restart() {
    let _time = timed!();
    let dir = tmp("expert-disk-full");
    let Some(_disk) = crate::support::tmpfs_or_skip(&dir, 24, "the full-disk test") else {
        return;
    };
    let out = dir.join("run");
    // Long enough to go on well after the disk is freed; stopped with Ctrl-C at the end.
    let mut child = spawn_run(
        &out,
        2,
        &[
            "episodes=1000000",
            "env.max_episode_steps=200",
            "query.rule=uniform",
            "query.probability=0.02",
            "budget.total=10000",
            "--checkpoint-every=1000000",
        ],
    );
    let demos = |out: &Path| {
        std::fs::read_to_string(out.join("demos.jsonl"))
            .map(|t| t.lines().count())
            .unwrap_or(0)
    };
    wait_until(&mut child, "3 demonstrations", || demos(&out) >= 3);
    // Fill the file system to the last byte, hold it full for 2 s (dozens of queries at this
    // rate), then free it.
    let filler = dir.join("filler");
    let f = crate::support::fill_up(&filler);
    std::thread::sleep(Duration::from_secs(2));
    drop(f);
    std::fs::remove_file(&filler).unwrap();
    // The line the expert writes when it records again shows that it refused some meanwhile
    // (its warnings may not have found room in its log while the disk was full).
    let log = out.join("expert-1.log");
    wait_until(&mut child, "the expert recording again", || {
        std::fs::read_to_string(&log)
            .is_ok_and(|t| t.contains("demonstrations are recorded again after a full disk"))
    });
    let o = interrupt(child);
    assert_eq!(
        o.status.code(),
        Some(130),
        "Ctrl-C's exit code: {}",
        text(&o)
    );
    let s = summary(&out);
    assert_eq!(s["expert_restarts"].as_u64(), Some(0), "{}", text(&o));
    let records = check_run_dir(&out, 10_000);
    let indices: Vec<u32> = records.iter().map(|d| d.index).collect();
    assert_eq!(indices, (0..records.len() as u32).collect::<Vec<_>>());
}
