//! Bring your own environment and your own expert: Gymnasium environments served by
//! the Python adapter (`deploy/python/alfd_adapter.py`) pass the same conformance suite as the
//! built-in ones and give our CartPole's trajectories, and a multi-process run plays one with
//! an external Python expert.
//!
//! The adapter's Python comes from `.venv/`, installed on first use by
//! `deploy/python/setup-venv.sh` (as `alfd` itself does).

use std::path::Path;
use std::sync::Arc;

use alfd_common::config::{EnvConfig, EnvName};
use alfd_common::env::{CartPole, Env, EnvError};
use alfd_harness::python::{Adapter, AdapterEnv};
use alfd_wire::{self as wire, Process, Role, SCHEMA_VERSION};

#[path = "../../../common/core/tests/conformance_suite.rs"]
mod conformance_suite;

use crate::support::{alfd, text, timed, tmp};

fn gym(id: &str, max_episode_steps: Option<usize>) -> EnvConfig {
    EnvConfig {
        name: EnvName::Gymnasium,
        max_episode_steps,
        p_success: 0.9,
        map: None,
        id: Some(id.to_owned()),
        kwargs: None,
        size: None,
        mapping_seed: None,
    }
}

/// Sessions on one adapter of run `run_id`; the run's iceoryx2 files are removed when dropped.
struct Served {
    adapter: Option<Arc<Adapter>>,
    run_id: String,
}

impl Served {
    fn new(id: &str, dir: &Path, tag: &str) -> Self {
        let run_id = format!("gymtest-{tag}-{}", std::process::id());
        let adapter = Adapter::env(
            &gym(id, None),
            &run_id,
            "env-0",
            SCHEMA_VERSION,
            &dir.join("adapter.log"),
        )
        .expect("the adapter starts");
        Self {
            adapter: Some(Arc::new(adapter)),
            run_id,
        }
    }

    fn open(&self, id: &str, limit: usize) -> AdapterEnv {
        AdapterEnv::open(
            self.adapter.clone().expect("running"),
            &gym(id, Some(limit)),
            &self.run_id,
            Process::new(Role::Tool, 0),
            SCHEMA_VERSION,
        )
        .expect("a session opens")
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        self.adapter = None;
        let _ = wire::close_run(&self.run_id);
    }
}

#[test]
fn gymnasium_cartpole_through_the_adapter_conforms_and_follows_the_native_cartpole() {
    let _time = timed!();
    let dir = tmp("gym-cartpole");
    let served = Served::new("CartPole-v1", &dir, "cp");
    // The same suite as the built-in environments.
    conformance_suite::conformance(
        "gymnasium:CartPole-v1",
        |limit| served.open("CartPole-v1", limit),
        2,
        |i| i % 2,
        |_| 0,
    );

    // From the same internal state and actions, Gymnasium's CartPole through the adapter and our
    // native one give the same trajectory: every float64 state to 1e-9, observations, rewards
    // and both flags.
    let mut remote = served.open("CartPole-v1", 200);
    let mut native = CartPole::new(200);
    let starts = [
        [0.0, 0.0, 0.0, 0.0],
        [0.01, -0.02, 0.03, 0.04],
        [-0.5, 0.3, -0.1, -0.2],
        [1.0, 1.0, 0.15, 0.5],
    ];
    let (mut steps, mut terminated) = (0, 0);
    for (k, s0) in starts.iter().enumerate() {
        remote.reset(Some(k as u64));
        native.reset(Some(k as u64));
        remote.env.set_internal_state(s0).unwrap();
        native.set_state(*s0);
        assert_eq!(remote.env.internal_state().unwrap(), s0.to_vec());
        for i in 0..200 {
            // A fixed sequence that keeps the pole up a while, then lets it fall.
            let a = if i < 20 { (i + k) % 2 } else { 1 };
            let r = remote.step(a).unwrap();
            let n = native.step(a).unwrap();
            for (x, y) in r.observation.iter().zip(n.observation.iter()) {
                assert!(
                    (f64::from(*x) - f64::from(*y)).abs() <= 1e-9,
                    "start {k} step {i}"
                );
            }
            assert_eq!(
                (r.reward, r.terminated, r.truncated),
                (n.reward, n.terminated, n.truncated),
                "start {k} step {i}"
            );
            let (rs, ns) = (remote.env.internal_state().unwrap(), native.state());
            for (x, y) in rs.iter().zip(ns.iter()) {
                assert!(
                    (x - y).abs() <= 1e-9,
                    "start {k} step {i}: {rs:?} vs {ns:?}"
                );
            }
            steps += 1;
            if r.done() {
                terminated += usize::from(r.terminated);
                break;
            }
        }
    }
    assert!(
        steps > 40 && terminated == starts.len(),
        "{steps} {terminated}"
    );
    // What a remote environment cannot do, it says.
    let e = remote.restore(&native.snapshot()).unwrap_err();
    assert!(
        matches!(&e, EnvError::Unsupported(m) if m.contains("gymnasium:CartPole-v1")),
        "{e}"
    );
    drop((remote, served));
}

#[test]
fn a_gymnasium_environment_with_a_wrong_space_is_refused_naming_it() {
    let _time = timed!();
    let out = tmp("gym-wrong");
    for (id, kwargs, says) in [
        (
            "Pendulum-v1",
            "{}",
            "the action space Box(-2.0, 2.0, (1,), float32) is not Discrete",
        ),
        (
            "Taxi-v4",
            "{}",
            "the observation space Discrete(500) has 500 states; one-hot, the wire carries 1 to \
             MAX_OBS_DIM = 64",
        ),
        (
            "alfd_examples:AlfdCorridor-v0",
            "{width = 70}",
            "has 70 values; the wire carries 1 to MAX_OBS_DIM = 64",
        ),
    ] {
        let o = alfd()
            .args(["run", "--quiet", "--actors=1"])
            .arg(format!(
                "--out={}",
                out.join(id.replace(':', "_")).display()
            ))
            .args(["--set", "env.name=gymnasium", "--set"])
            .arg(format!("env.id={id}"))
            .arg("--set")
            .arg(format!("env.kwargs={kwargs}"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(stderr.contains(says), "{id}: {stderr}");
    }
}

#[test]
fn an_environment_of_ones_own_module_runs_with_its_kwargs() {
    let _time = timed!();
    let out = tmp("gym-own");
    // deploy/python/examples/alfd_examples.py registers AlfdCorridor-v0; `width` is its kwarg.
    let o = alfd()
        .args(["local", "--quiet"])
        .args(["--config", "deploy/configs/cartpole-bdqn-krr.toml"])
        .arg(format!("--out={}", out.join("run").display()))
        .args(["--set", "env.name=gymnasium"])
        .args(["--set", "env.id=alfd_examples:AlfdCorridor-v0"])
        .args(["--set", "env.kwargs={width = 6}", "--set", "episodes=3"])
        .args(["--set", "env.max_episode_steps=40"])
        .args(["--set", "expert.name=python:alfd_examples:corridor_right"])
        .args(["--set", "query.rule=first", "--set", "budget.total=4"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let demos = alfd_demonstrators::demo_log::read(&out.join("run/demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 4);
    assert!(demos.iter().all(|d| d.action == 1 && d.state.len() == 6));
    // The first state is the start, one-hot in the first of 6 cells.
    assert_eq!(demos[0].state, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let csv = std::fs::read_to_string(out.join("run/episodes.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4);
    for row in csv.lines().skip(1) {
        let f: Vec<&str> = row.split(',').collect();
        // -1 per step; the end is 5 moves away at best, 40 steps at most.
        let (ret, len): (f64, u32) = (f[1].parse().unwrap(), f[2].parse().unwrap());
        assert!((5..=40).contains(&len) && ret == -(len as f64), "{row}");
    }
}

/// The scripted controller of `deploy/python/examples/alfd_examples.py`, `acrobot_pump`.
fn acrobot_pump(obs: &[f64]) -> usize {
    if obs[4] > 0.0 {
        0
    } else {
        2
    }
}

#[test]
fn a_run_on_gymnasium_acrobot_with_an_external_python_expert_completes() {
    let _time = timed!();
    let out = tmp("gym-acrobot");
    let config = out.join("acrobot.toml");
    let expert = "python:alfd_examples:acrobot_pump";
    std::fs::write(
        &config,
        format!(
            "seed = 5\nepisodes = 6\n[env]\nname = \"gymnasium\"\nid = \"Acrobot-v1\"\n\
             max_episode_steps = 60\n[agent]\nkind = \"bdqn\"\nbatch_size = 16\n\
             [query]\nmode = \"first\"\n[budget]\ntotal = 25\n\
             [expert]\nname = \"{expert}\"\nmodel = \"krr\"\n"
        ),
    )
    .unwrap();
    let run_dir = out.join("run");
    let o = alfd()
        .args(["run", "--quiet", "--actors=2", "--query-timeout-ms=5000"])
        .arg(format!("--config={}", config.display()))
        .arg(format!("--out={}", run_dir.display()))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["episodes"], 6);
    let rows: Vec<Vec<String>> = std::fs::read_to_string(run_dir.join("episodes.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    assert_eq!(rows.len(), 6);
    for r in &rows {
        // Acrobot-v1: -1 per step until the tip clears the bar, at most 60 steps here.
        let (ret, len): (f64, u32) = (r[1].parse().unwrap(), r[2].parse().unwrap());
        assert!(
            (1..=60).contains(&len) && ret <= 0.0 && ret >= -(len as f64),
            "{r:?}"
        );
    }
    assert!(rows.iter().any(|r| r[8] == "0") && rows.iter().any(|r| r[8] == "1"));
    // The whole budget, spent on the first steps, each answer the controller's, with its name.
    let demos = alfd_demonstrators::demo_log::read(&run_dir.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 25);
    assert_eq!(summary["demos"], 25);
    for d in &demos {
        assert_eq!(d.expert, expert);
        assert_eq!(d.state.len(), 6);
        assert_eq!(d.action, acrobot_pump(&d.state), "{d:?}");
    }
    let spec = std::fs::read_to_string(run_dir.join("runtime.toml")).unwrap();
    assert!(
        spec.contains("obs_dim = 6") && spec.contains("num_actions = 3"),
        "{spec}"
    );
    for log in [
        "adapter-env-0.log",
        "adapter-env-1.log",
        "adapter-expert-1.log",
    ] {
        assert!(run_dir.join(log).is_file(), "{log} missing");
    }
    let id = crate::runtime::run_id(&run_dir);
    assert_eq!(wire::leftover_files(&id), Vec::<std::path::PathBuf>::new());
}

/// The experts named in `demos.jsonl`, in order, each run of equal names once.
fn expert_segments(demos: &[alfd_common::agent::DemoRecord]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for d in demos {
        if out.last() != Some(&d.expert) {
            out.push(d.expert.clone());
        }
    }
    out
}

#[test]
fn swap_expert_goes_from_a_built_in_expert_to_an_external_one_and_back() {
    let _time = timed!();
    let out = tmp("gym-swap");
    let external = "python:alfd_examples:acrobot_pump";
    let demos_of = |name: &str| {
        alfd_demonstrators::demo_log::read(&out.join("demos.jsonl"))
            .unwrap_or_default()
            .iter()
            .filter(|d| d.expert == name)
            .count()
    };
    // The built-in Acrobot, asking on every step (a budget that lasts), so demonstrations flow
    // before and after each swap.
    let mut run = crate::support::Background(Some(
        alfd()
            .args(["run", "--quiet", "--actors=2", "--query-timeout-ms=5000"])
            .arg(format!("--out={}", out.display()))
            .args(["--config", "deploy/configs/cartpole-bdqn-krr.toml"])
            .args([
                "--set",
                "env.name=acrobot",
                "--set",
                "env.max_episode_steps=50",
            ])
            .args([
                "--set",
                "expert.name=acrobot-energy",
                "--set",
                "query.rule=first",
            ])
            .args(["--set", "budget.total=100000", "--set", "episodes=1000000"])
            .args(["--set", "expert.model=none"])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    let swap = |to: &str, generation: u64| {
        let o = alfd()
            .args(["swap-expert", "--run"])
            .arg(&*out)
            .args(["--expert", to])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(
            (r["ok"].as_bool(), r["generation"].as_u64()),
            (Some(true), Some(generation))
        );
        assert_eq!(r["to"].as_str(), Some(to));
    };
    crate::runtime::wait_until(&mut run, "built-in demonstrations", || {
        demos_of("acrobot-energy") >= 20
    });
    swap(external, 2);
    crate::runtime::wait_until(&mut run, "external demonstrations", || {
        demos_of(external) >= 20
    });
    swap("acrobot-energy", 3);
    let before = demos_of("acrobot-energy");
    crate::runtime::wait_until(&mut run, "built-in demonstrations again", || {
        demos_of("acrobot-energy") >= before + 20
    });
    let o = crate::runtime::interrupt(run);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let demos = alfd_demonstrators::demo_log::read(&out.join("demos.jsonl")).unwrap();
    assert_eq!(crate::runtime::summary(&out)["demos"], demos.len());
    let id = crate::runtime::run_id(&out);
    assert_eq!(wire::leftover_files(&id), Vec::<std::path::PathBuf>::new());
    assert_eq!(wire::alive_nodes(&id).unwrap(), Vec::<String>::new());
    assert_eq!(
        expert_segments(&demos),
        ["acrobot-energy", external, "acrobot-energy"],
        "one block per generation, in order"
    );
    for (i, d) in demos.iter().enumerate() {
        assert_eq!(d.index as usize, i, "no demonstration lost or repeated");
        if d.expert == external {
            assert_eq!(d.action, acrobot_pump(&d.state), "{d:?}");
        }
    }
    assert!(out.join("adapter-expert-2.log").is_file());
}

/// The controller of `alfd_examples.cartpole_balance`.
fn cartpole_balance(obs: &[f64]) -> usize {
    usize::from(obs[2] as f32 + 0.5 * obs[3] as f32 > 0.0)
}

#[test]
fn alfd_local_plays_a_gymnasium_environment_with_an_external_expert_reproducibly() {
    let _time = timed!();
    let out = tmp("gym-local");
    let expert = "python:alfd_examples:cartpole_balance";
    let config = out.join("cartpole.toml");
    std::fs::write(
        &config,
        format!(
            "seed = 2\nepisodes = 5\n[env]\nname = \"gymnasium\"\nid = \"CartPole-v1\"\n\
             [agent]\nkind = \"bdqn\"\nbatch_size = 16\n[query]\nmode = \"first\"\n\
             [budget]\ntotal = 15\n[expert]\nname = \"{expert}\"\nmodel = \"krr\"\n"
        ),
    )
    .unwrap();
    let run = |name: &str| {
        let dir = out.join(name);
        let o = alfd()
            .args(["local", "--quiet"])
            .arg(format!("--config={}", config.display()))
            .arg(format!("--out={}", dir.display()))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        dir
    };
    let (a, b) = (run("a"), run("b"));
    let csv = |d: &Path| std::fs::read_to_string(d.join("episodes.csv")).unwrap();
    assert_eq!(csv(&a), csv(&b), "one config and seed, one result");
    assert_eq!(csv(&a).lines().count(), 6);
    let demos = alfd_demonstrators::demo_log::read(&a.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 15);
    for d in &demos {
        assert_eq!(
            (d.expert.as_str(), d.action),
            (expert, cartpole_balance(&d.state))
        );
    }
    // Checkpointing the Python environment is refused, saying why.
    let o = alfd()
        .args(["local", "--quiet", "--checkpoint-every=2"])
        .arg(format!("--config={}", config.display()))
        .arg(format!("--out={}", out.join("c").display()))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("checkpointing it is not supported"));
}

#[test]
fn an_adapter_killed_with_sigkill_takes_its_actor_down_and_both_are_restarted() {
    let _time = timed!();
    let out = tmp("gym-kill");
    let mut run = crate::support::Background(Some(
        alfd()
            .args(["run", "--quiet", "--actors=2"])
            .arg(format!("--out={}", out.display()))
            .args(["--config", "deploy/configs/cartpole-bdqn-krr.toml"])
            .args(["--set", "env.name=gymnasium", "--set", "env.id=CartPole-v1"])
            .args(["--set", "episodes=1000000", "--set", "expert.model=none"])
            .args(["--set", "expert.name=python:alfd_examples:cartpole_balance"])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    crate::runtime::wait_rows(&out, 5, &mut run);
    // This run's adapter, not another test's (they run at the same time, each with an env-0).
    let run_arg = format!("--run-id={}", crate::runtime::run_id(&out));
    let mine = ["env", "--name=env-0", run_arg.as_str()];
    let adapter = crate::runtime::find_process("python", &mine)
        .or_else(|| crate::runtime::find_process("python3", &mine))
        .expect("actor 0's adapter runs");
    crate::runtime::signal("KILL", adapter);
    // Actor 0 stops at its next step, naming the adapter; the launcher restarts it, and the new
    // incarnation starts a new adapter.
    crate::runtime::wait_until(&mut run, "actor 0 restarted", || {
        std::fs::read_to_string(out.join("actor-0.log"))
            .is_ok_and(|l| l.contains("incarnation=2") || l.contains("incarnation: 2"))
    });
    let n = crate::runtime::rows(&out).len();
    crate::runtime::wait_rows(&out, n + 5, &mut run);
    let o = crate::runtime::interrupt(run);
    assert_eq!(o.status.code(), Some(130), "{}", text(&o));
    let s = crate::runtime::summary(&out);
    assert_eq!(s["actor_restarts"].as_u64(), Some(1), "{s}");
    let log = std::fs::read_to_string(out.join("actor-0.log")).unwrap();
    assert!(
        log.contains("remote/env-0") && log.contains("exited"),
        "{log}"
    );
    let id = crate::runtime::run_id(&out);
    assert_eq!(wire::leftover_files(&id), Vec::<std::path::PathBuf>::new());
}

#[test]
fn a_gymnasium_run_with_no_budget_needs_no_expert_and_one_with_a_budget_does() {
    let _time = timed!();
    let out = tmp("gym-no-expert");
    let config = out.join("frozenlake.toml");
    // No expert named: the default one is CartPole's, which cannot play FrozenLake. Its 16
    // states reach the agent one-hot, 16 values, and the agent has 12 heads.
    std::fs::write(
        &config,
        "seed = 3\nepisodes = 3\n[env]\nname = \"gymnasium\"\nid = \"FrozenLake-v1\"\n\
         max_episode_steps = 40\n[agent]\nkind = \"bdqn\"\nheads = 12\nbatch_size = 16\n\
         [query]\nrule = \"never\"\n[budget]\ntotal = 0\n",
    )
    .unwrap();
    for cmd in ["local", "run"] {
        let run_dir = out.join(cmd);
        let o = alfd()
            .args([cmd, "--quiet"])
            .arg(format!("--config={}", config.display()))
            .arg(format!("--out={}", run_dir.display()))
            .output()
            .unwrap();
        assert!(o.status.success(), "{cmd}: {}", text(&o));
        let csv = std::fs::read_to_string(run_dir.join("episodes.csv")).unwrap();
        assert_eq!(csv.lines().count(), 4, "{cmd}: {csv}");
    }
    // With a budget the expert is needed, and the default one is refused, naming it.
    let o = alfd()
        .args([
            "local",
            "--quiet",
            "--set",
            "budget.total=5",
            "--set",
            "query.rule=\"first\"",
        ])
        .arg(format!("--config={}", config.display()))
        .arg(format!("--out={}", out.join("refused").display()))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("cartpole-1000"), "{}", text(&o));
}

/// An adapter whose starter died while it started up (its parent is then another process) stops
/// on its own: it watches the pid it was given, not the parent it finds.
#[test]
fn an_adapter_whose_starter_is_gone_stops_by_itself() {
    let _time = timed!();
    let python = crate::support::project_python();
    let adapter = crate::support::repo().join("deploy/python/alfd_adapter.py");
    let run_id = format!("adapter-orphan-{}", std::process::id());
    // pid 1 is not this test: as if the process that started the adapter had already died.
    let mut adapter_cmd = std::process::Command::new(python);
    adapter_cmd
        .arg(&adapter)
        .args(["expert", "--policy=python:alfd_examples:cartpole_balance"])
        .arg(format!("--run-id={run_id}"))
        .args([
            "--name=orphan",
            &format!("--schema={SCHEMA_VERSION}"),
            "--parent=1",
        ]);
    // Stopped, and the test failed, if it still serves after two minutes.
    let o = crate::runtime::wait_output(
        crate::runtime::spawn(adapter_cmd),
        std::time::Duration::from_secs(120),
    );
    assert!(o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("the process that started it has gone"),
        "{err}"
    );
    let _ = wire::clean_run(&run_id);
}
