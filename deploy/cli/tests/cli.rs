//! The `alfd` command line as a user meets it: outputs of `local`, `env`, `expert`, and clear
//! errors with exit code 2 on bad input.

use std::path::Path;
use std::process::{Command, Output};

use crate::support::{repo, text, timed, tmp};

pub(crate) fn alfd(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_alfd"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("alfd runs")
}

pub(crate) fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn local_writes_a_byte_identical_episodes_csv_for_the_same_seed() {
    let _time = timed!();
    let (a, b) = (tmp("local-a"), tmp("local-b"));
    for out in [&a, &b] {
        let o = alfd(&[
            "local",
            "--config",
            "deploy/configs/cliffwalk-bootstrapped.toml",
            "--set",
            "episodes=100",
            "--out",
            out.to_str().unwrap(),
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(summary["episodes"], 100);
    }
    let csv_a = std::fs::read(a.join("episodes.csv")).unwrap();
    assert_eq!(csv_a, std::fs::read(b.join("episodes.csv")).unwrap());
    let text = String::from_utf8(csv_a).unwrap();
    assert_eq!(text.lines().count(), 101);
    for f in ["config.toml", "summary.json", "policy.json", "demos.jsonl"] {
        assert!(a.join(f).exists(), "{f} missing");
    }
    // The recorded config runs again as it is.
    let c = tmp("local-c");
    let o = alfd(&[
        "local",
        "--config",
        a.join("config.toml").to_str().unwrap(),
        "--out",
        c.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read(c.join("episodes.csv")).unwrap(),
        text.as_bytes()
    );
}

#[test]
fn local_cartpole_saves_weights_and_demos() {
    let _time = timed!();
    let out = tmp("local-cartpole");
    let o = alfd(&[
        "local",
        "--config",
        "deploy/configs/cartpole-bdqn-krr.toml",
        "--set",
        "episodes=20",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let weights = std::fs::read(out.join("weights.safetensors")).unwrap();
    let net = alfd_common::nn::Mlp::from_safetensors_bytes(&weights).unwrap();
    assert_eq!((net.heads(), net.actions()), (2, 2));
    let demos = std::fs::read_to_string(out.join("demos.jsonl")).unwrap();
    let csv = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    let last_used: usize = csv
        .lines()
        .last()
        .unwrap()
        .split(',')
        .nth(3)
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(demos.lines().count(), last_used);
    for line in demos.lines() {
        let d: serde_json::Value = serde_json::from_str(line).unwrap();
        assert_eq!(d["expert"], "cartpole-1000");
        assert_eq!(d["state"].as_array().unwrap().len(), 4);
    }
}

pub(crate) fn assert_usage_error(args: &[&str], needle: &str) {
    let o = alfd(args);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
    assert!(
        stderr(&o).contains(needle),
        "{args:?}: expected `{needle}` in: {}",
        stderr(&o)
    );
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
}

#[test]
fn bad_configs_are_refused_with_exit_code_2_naming_the_field() {
    let _time = timed!();
    let out = tmp("bad");
    let o = out.to_str().unwrap();
    let cfg = "deploy/configs/cliffwalk-bootstrapped.toml";
    assert_usage_error(
        &[
            "local",
            "--config",
            cfg,
            "--set",
            "agent.heads=0",
            "--out",
            o,
        ],
        "agent.heads",
    );
    assert_usage_error(
        &[
            "local",
            "--config",
            cfg,
            "--set",
            "query.percentile=120",
            "--out",
            o,
        ],
        "query.percentile",
    );
    assert_usage_error(
        &[
            "local",
            "--config",
            cfg,
            "--set",
            "budget.total=-1",
            "--out",
            o,
        ],
        "budget.total",
    );
    assert_usage_error(
        &[
            "local",
            "--config",
            cfg,
            "--set",
            "env.p_success=1.2",
            "--out",
            o,
        ],
        "env.p_success",
    );
    assert_usage_error(
        &[
            "local",
            "--config",
            cfg,
            "--set",
            "agent.colour=3",
            "--out",
            o,
        ],
        "colour",
    );
    assert_usage_error(
        &[
            "local",
            "--config",
            cfg,
            "--set",
            "expert.name=nobody",
            "--out",
            o,
        ],
        "nobody",
    );
    assert_usage_error(
        &["local", "--config", "no/such.toml", "--out", o],
        "no/such.toml",
    );
    let map = out.join("ragged.txt");
    std::fs::write(&map, "S..\n..\n..G\n").unwrap();
    assert_usage_error(
        &[
            "local",
            "--config",
            cfg,
            "--set",
            &format!("env.map=\"{}\"", map.display()),
            "--out",
            o,
        ],
        "line 2",
    );
    let nomap = out.join("nogoal.txt");
    std::fs::write(&nomap, "S..\n...\n").unwrap();
    assert_usage_error(
        &[
            "env",
            "show",
            "--env",
            "cliffwalk",
            "--map",
            nomap.to_str().unwrap(),
        ],
        "G",
    );
    assert_usage_error(&["env", "show", "--env", "mountaincar"], "mountaincar");
    assert_usage_error(&["expert", "eval", "cartpole-123"], "cartpole-123");
}

#[test]
fn a_bad_value_is_refused_with_exit_code_2_saying_where_it_came_from() {
    let _time = timed!();
    let out = tmp("bad-source");
    let o = out.to_str().unwrap();
    let cfg = "deploy/configs/cartpole-bdqn-krr.toml";
    // From the command line: `alfd run` (with a config file or the default one) and `alfd local`
    // name the field and the `--set`, not the file.
    let from_file = ["--config", cfg];
    for (cmd, config) in [("run", &from_file[..]), ("run", &[]), ("local", &from_file)] {
        for (set, field) in [
            ("agent.heads=0", "agent.heads"),
            ("agent.gamma=1.5", "agent.gamma"),
        ] {
            let mut args = vec![cmd];
            args.extend_from_slice(config);
            args.extend(["--set", set, "--out", o]);
            let e = stderr(&alfd(&args));
            assert_usage_error(&args, &format!("in `--set {set}` (on the command line)"));
            assert!(
                e.contains(&format!("`{field}`")) && !e.contains("in config"),
                "{e}"
            );
        }
    }
    // From the file: the file is named.
    let text = std::fs::read_to_string(repo().join(cfg))
        .unwrap()
        .replace("gamma = 0.99", "gamma = 1.5");
    let bad = out.join("bad.toml");
    std::fs::write(&bad, text).unwrap();
    let bad = bad.to_str().unwrap();
    for cmd in ["run", "local"] {
        let args = [cmd, "--config", bad, "--set", "episodes=5", "--out", o];
        assert_usage_error(&args, &format!("in config {bad}"));
        assert_usage_error(&args, "agent.gamma");
    }
    // Nothing ran: the output directory holds only the bad config.
    let names: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("bad.toml")]);
}

#[test]
fn local_refuses_an_output_directory_holding_a_run_and_leaves_it_untouched() {
    let _time = timed!();
    let out = tmp("local-reused");
    let o = out.to_str().unwrap();
    let args = [
        "local",
        "--config",
        "deploy/configs/cliffwalk-bootstrapped.toml",
        "--set",
        "episodes=10",
        "--out",
        o,
        "--quiet",
    ];
    let first = alfd(&args);
    assert!(first.status.success(), "{}", stderr(&first));
    let snapshot = || crate::support::dir_snapshot(&out);
    let before = snapshot();
    assert_usage_error(&args, "already holds a run");
    assert_usage_error(&args, &format!("--out {o}-2"));
    assert_eq!(snapshot(), before);
    // Any one of a run's files is enough.
    let partial = tmp("local-partial");
    std::fs::write(partial.join("demos.jsonl"), "").unwrap();
    let p = partial.to_str().unwrap();
    let args = [
        "local",
        "--config",
        "deploy/configs/cliffwalk-bootstrapped.toml",
        "--out",
        p,
    ];
    assert_usage_error(&args, "demos.jsonl");
    assert!(!partial.join("config.toml").exists());
}

#[test]
fn env_rollout_prints_one_json_object_per_step() {
    let _time = timed!();
    let o = alfd(&[
        "env",
        "rollout",
        "--env",
        "cartpole",
        "--initial-state",
        "0,0,0.01,0",
        "--actions",
        "1,0,1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let lines: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    // After pushing right from rest, the cart moves right: x_dot = 0.02 * a, a > 0.
    assert!(lines[0]["state"][1].as_f64().unwrap() > 0.19);
    assert_eq!(lines[2]["reward"], 1.0);
    assert_eq!(lines[2]["terminated"], false);
}

#[test]
fn env_rollout_steps_mountaincar_and_acrobot_from_a_given_state() {
    let _time = timed!();
    // MountainCar pushed right from just below the flag reaches it on the first step.
    let o = alfd(&[
        "env",
        "rollout",
        "--env",
        "mountaincar",
        "--initial-state",
        "0.49,0.03",
        "--actions",
        "2,2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("1 remaining action(s) were ignored"));
    let out = String::from_utf8(o.stdout).unwrap();
    let line: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert!(line["state"][0].as_f64().unwrap() >= 0.5, "{out}");
    assert_eq!(line["reward"], -1.0);
    assert_eq!(line["terminated"], true);

    let o = alfd(&[
        "env",
        "rollout",
        "--env",
        "acrobot",
        "--initial-state",
        "-0.05,0.02,0,0",
        "--actions",
        "2,2,2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let lines: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[2]["state"].as_array().unwrap().len(), 4);
    // Torque +1 bends the second link forward.
    assert!(lines[2]["state"][3].as_f64().unwrap() > 0.0);
    assert_eq!(lines[2]["reward"], -1.0);
    assert_usage_error(
        &[
            "env",
            "rollout",
            "--env",
            "acrobot",
            "--initial-state",
            "0,0",
            "--actions",
            "1",
        ],
        "expected 4 comma-separated numbers THETA1,THETA2,DTHETA1,DTHETA2",
    );
}

#[test]
fn expert_eval_prints_mean_median_std() {
    let _time = timed!();
    let o = alfd(&["expert", "eval", "cartpole-perfect", "--episodes", "5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["mean"], 1000.0);
    assert_eq!(v["median"], 1000.0);
    assert_eq!(v["std"], 0.0);
    let list = alfd(&["expert", "list"]);
    let text = String::from_utf8(list.stdout).unwrap();
    for name in [
        "cartpole-50",
        "cartpole-100",
        "cartpole-200",
        "cartpole-500",
        "cartpole-1000",
        "cartpole-perfect",
        "cliffwalk-optimal",
        "mountaincar-energy",
        "mountaincar-poor",
        "acrobot-energy",
        "acrobot-poor",
    ] {
        assert!(text.contains(name), "{name} not listed");
    }
    // The scripted experts score in `expert eval` what `expert list` says they do.
    let o = alfd(&["expert", "eval", "mountaincar-energy", "--episodes", "100"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let mean = v["mean"].as_f64().unwrap();
    let row = text
        .lines()
        .find(|l| l.starts_with("mountaincar-energy "))
        .expect("listed");
    assert!(row.contains(&format!("{mean:.1}")), "{row} vs {mean}");
}

#[test]
fn deepseas_experts_are_evaluated_on_deepsea_of_the_size_asked_and_rank_by_their_noise() {
    let _time = timed!();
    let mean = |name: &str, size: &str| {
        let o = alfd(&["expert", "eval", name, "--size", size, "--episodes", "2000"]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["mean"].as_f64().unwrap()
    };
    // Every move right: the treasure (1) less the moves' cost (0.01 in all).
    assert!((mean("deepsea-optimal", "20") - 0.99).abs() < 1e-9);
    // A move right with probability 1 - epsilon / 2 at each row: the treasure with that to the
    // power N, so at N = 20 about 0.36, 0.07 and 0.003 of the episodes.
    let (good, fair, poor) = (
        mean("deepsea-good", "20"),
        mean("deepsea-fair", "20"),
        mean("deepsea-poor", "20"),
    );
    assert!(good > fair && fair > poor, "{good} {fair} {poor}");
    assert!((good - 0.95f64.powi(20)).abs() < 0.05, "{good}");
    assert_usage_error(
        &["expert", "eval", "deepsea-good", "--size", "0"],
        "--size 0",
    );
    assert_usage_error(
        &["expert", "eval", "mountaincar-good", "--size", "20"],
        "`mountaincar-good` demonstrates mountaincar",
    );
}

/// `alfd local` of `config` (40 episodes) into `out`, with `extra` arguments.
fn local_40(config: &str, out: &Path, extra: &[&str]) -> Output {
    let out = out.to_str().unwrap();
    let mut args = vec![
        "local",
        "--config",
        config,
        "--set",
        "episodes=40",
        "--out",
        out,
        "--quiet",
    ];
    args.extend_from_slice(extra);
    alfd(&args)
}

/// Stop at episode 25 (checkpoints every 10), resume: the uninterrupted run's files, to the byte.
fn assert_stop_and_resume_is_the_uninterrupted_run(config: &str, name: &str) {
    let dir = tmp(name);
    let (whole, cut) = (dir.join("whole"), dir.join("cut"));
    let o = local_40(config, &whole, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = local_40(
        config,
        &cut,
        &["--checkpoint-every", "10", "--stop-after-episodes", "25"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("alfd resume"), "{}", stderr(&o));
    let csv = std::fs::read_to_string(cut.join("episodes.csv")).unwrap();
    assert_eq!(csv.lines().count(), 21, "the rows of the checkpoint at 20");
    assert!(!cut.join("summary.json").exists());
    // Rows written after the checkpoint (as a crash may leave) are dropped and played again.
    std::fs::write(cut.join("episodes.csv"), format!("{csv}20,1,2,3\n")).unwrap();
    let again = local_40(config, &cut, &[]);
    assert_eq!(again.status.code(), Some(2), "a new run is refused");
    let o = alfd(&["resume", cut.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in ["episodes.csv", "demos.jsonl"] {
        let (a, b) = (
            std::fs::read(whole.join(f)).unwrap(),
            std::fs::read(cut.join(f)).unwrap(),
        );
        assert!(a == b, "{name}: {f} differs from the uninterrupted run's");
    }
    assert_eq!(
        std::fs::read_to_string(cut.join("episodes.csv"))
            .unwrap()
            .lines()
            .count(),
        41
    );
    let o = alfd(&["resume", cut.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("finished"), "{}", stderr(&o));
}

#[test]
fn a_cartpole_run_stopped_and_resumed_is_the_uninterrupted_run_to_the_byte() {
    let _time = timed!();
    assert_stop_and_resume_is_the_uninterrupted_run(
        "deploy/configs/cartpole-bdqn-krr.toml",
        "resume-cartpole",
    );
}

#[test]
fn a_cliffwalk_run_stopped_and_resumed_is_the_uninterrupted_run_to_the_byte() {
    let _time = timed!();
    assert_stop_and_resume_is_the_uninterrupted_run(
        "deploy/configs/cliffwalk-bootstrapped.toml",
        "resume-cliffwalk",
    );
}

#[test]
fn resume_refuses_a_bad_checkpoint_saying_why_and_keeps_it() {
    let _time = timed!();
    let dir = tmp("resume-bad");
    let run = dir.join("run");
    let o = local_40(
        "deploy/configs/cliffwalk-bootstrapped.toml",
        &run,
        &["--checkpoint-every", "10", "--stop-after-episodes", "15"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let path = run.join("checkpoint.bin");
    let good = std::fs::read(&path).unwrap();
    let mut flipped = good.clone();
    *flipped.last_mut().unwrap() ^= 0x40;
    let mut version = good.clone();
    version[8] = version[8].wrapping_add(1);
    let cases: [(&[u8], &str); 3] = [
        (&good[..good.len() - 10], "truncated"),
        (&flipped, "corrupt"),
        (&version, "another format version"),
    ];
    for (bytes, reason) in cases {
        std::fs::write(&path, bytes).unwrap();
        let o = alfd(&["resume", run.to_str().unwrap(), "--quiet"]);
        assert_eq!(o.status.code(), Some(2), "{reason}: {}", stderr(&o));
        assert!(stderr(&o).contains(reason), "{reason}: {}", stderr(&o));
        assert_eq!(std::fs::read(&path).unwrap(), bytes, "{reason}: kept");
    }
    std::fs::write(&path, &good).unwrap();
    let config = run.join("config.toml");
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, text.replace("seed = 0", "seed = 1")).unwrap();
    let o = alfd(&["resume", run.to_str().unwrap(), "--quiet"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("another config"), "{}", stderr(&o));
    std::fs::write(&config, text).unwrap();
    let o = alfd(&["resume", run.to_str().unwrap(), "--quiet"]);
    assert!(
        o.status.success(),
        "the good checkpoint resumes: {}",
        stderr(&o)
    );
    let o = alfd(&["resume", dir.join("none").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
}

/// A `width`×`height` CliffWalk map: plates, S at the bottom left, G at the bottom right.
fn open_map(width: usize, height: usize) -> String {
    let mut rows = vec![".".repeat(width); height];
    let last = &mut rows[height - 1];
    last.replace_range(0..1, "S");
    last.replace_range(width - 1..width, "G");
    rows.join("\n") + "\n"
}

#[test]
fn a_map_over_the_size_limit_is_refused_wherever_a_map_is_read() {
    let _time = timed!();
    let dir = tmp("big-map");
    let big = dir.join("big.txt");
    std::fs::write(&big, open_map(129, 3)).unwrap();
    let big = big.to_str().unwrap();
    let too_large =
        "map is too large: 129x3 tiles (width x height, the width of line 1); at most 128x128 are allowed";
    assert_usage_error(
        &["env", "show", "--env", "cliffwalk", "--map", big],
        too_large,
    );
    // In a config: refused before anything runs (no output directory).
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    let set = format!("env.map=\"{big}\"");
    let cfg = "deploy/configs/cliffwalk-qlearning.toml";
    assert_usage_error(
        &["local", "--config", cfg, "--set", &set, "--out", o],
        too_large,
    );
    let experiment = dir.join("exp.toml");
    let qlearning = repo().join("deploy/configs/cliffwalk-qlearning.toml");
    std::fs::write(
        &experiment,
        format!(
            "title = \"t\"\nseeds = 1\n[[method]]\nname = \"q\"\nconfig = \"{}\"\nset = [{set:?}]\n",
            qlearning.display()
        ),
    )
    .unwrap();
    assert_usage_error(
        &[
            "sweep",
            "--config",
            experiment.to_str().unwrap(),
            "--out",
            o,
        ],
        too_large,
    );
    assert!(!out.exists(), "nothing ran");
    // A file far larger than any map is not read whole.
    let huge = dir.join("huge.txt");
    std::fs::write(&huge, ".".repeat(2 << 20)).unwrap();
    let huge = huge.to_str().unwrap();
    assert_usage_error(
        &["env", "show", "--env", "cliffwalk", "--map", huge],
        "the file is larger than 1048576 bytes",
    );
    // The largest map is shown, and trained on, quickly.
    let largest = dir.join("largest.txt");
    std::fs::write(&largest, open_map(128, 128)).unwrap();
    let largest = largest.to_str().unwrap();
    let o = alfd(&["env", "show", "--env", "cliffwalk", "--map", largest]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("128x128 (width x height), 0 pits"));
    let run = dir.join("run");
    let set = format!("env.map=\"{largest}\"");
    let o = alfd(&[
        "local",
        "--config",
        "deploy/configs/cliffwalk-qlearning.toml",
        "--set",
        &set,
        "--set",
        "episodes=5",
        "--out",
        run.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(summary["greedy_value_at_start"].is_f64(), "{summary}");
}

#[test]
fn a_rollout_whose_state_overflows_is_refused_naming_the_step() {
    let _time = timed!();
    for (env, state, component) in [
        ("cartpole", "0,0,0,1e308", "XDOT"),
        ("mountaincar", "1e308,1e308", "POSITION"),
        ("acrobot", "0,0,1e308,1e308", "THETA1"),
    ] {
        let args = [
            "env",
            "rollout",
            "--env",
            env,
            "--initial-state",
            state,
            "--actions",
            "0,1",
        ];
        assert_usage_error(
            &args,
            &format!(
                "--initial-state {state}: the state stopped being finite at step 1 (action 0): {component} became NaN"
            ),
        );
        let o = alfd(&args);
        assert!(o.stdout.is_empty(), "{env}: no null printed: {}", text(&o));
    }
}

#[test]
fn config_values_accepted_silently_before_are_refused_naming_the_field() {
    let _time = timed!();
    let out = tmp("bad-config-values");
    let o = out.join("run");
    let o = o.to_str().unwrap();
    let tabular = "deploy/configs/cliffwalk-qlearning.toml";
    let neural = "deploy/configs/cartpole-bdqn-krr.toml";
    for (config, set, message) in [
        (
            tabular,
            "agent.gamma=1.0",
            "`agent.gamma` must be in [0, 1) for the tabular agents",
        ),
        (
            neural,
            "agent.hidden=100000000",
            "`agent.hidden` must be at most 1024, got 100000000",
        ),
        (
            neural,
            "agent.replay_capacity=100000000000",
            "`agent.replay_capacity` must be at most 1000000",
        ),
        (
            neural,
            "agent.batch_size=100000",
            "`agent.batch_size` must be at most 8192",
        ),
        (
            neural,
            "query.queue_len=100000000000",
            "`query.queue_len` must be at most 100000",
        ),
        (
            neural,
            "budget.total=100000",
            "`budget.total` is 100000, but the demonstration model (`expert.model`) is refitted on every demonstration and takes at most 10000",
        ),
        (
            neural,
            "agent.epsilon_decay_steps=nan",
            "`agent.epsilon_decay_steps` must be > 0 and finite, got NaN",
        ),
    ] {
        let args = ["local", "--config", config, "--set", set, "--out", o];
        assert_usage_error(&args, &format!("in `--set {set}` (on the command line)"));
        assert_usage_error(&args, message);
    }
    assert!(!out.join("run").exists(), "nothing ran");
}

#[test]
fn size_like_arguments_have_limits_naming_the_argument() {
    let _time = timed!();
    let out = tmp("size-arguments");
    let o = out.join("sweep");
    let o = o.to_str().unwrap();
    assert_usage_error(
        &[
            "expert",
            "eval",
            "cartpole-1000",
            "--episodes",
            "100000000000",
        ],
        "--episodes 100000000000: at most 1000000 episodes are evaluated",
    );
    let experiment = "deploy/experiments/fig3-cliffwalk.toml";
    assert_usage_error(
        &[
            "sweep",
            "--config",
            experiment,
            "--seeds",
            "100000000000",
            "--out",
            o,
        ],
        "`seeds` (or --seeds) is 100000000000; at most 10000 are allowed",
    );
    assert_usage_error(
        &[
            "sweep", "--config", experiment, "--jobs", "100000", "--out", o,
        ],
        "--jobs 100000: at most 256 runs at a time",
    );
    assert_usage_error(
        &[
            "demo-model-policy",
            "--seed",
            "18446744073709551615",
            "--runs",
            "2",
        ],
        "the last run's seed would be beyond 18446744073709551615",
    );
    assert!(!out.join("sweep").exists(), "nothing ran");
}

/// `alfd q-range` on a short CartPole run: one line with the range [0, 200] and a verdict; a
/// tabular run's directory and a directory without a run are refused with exit code 2.
#[test]
fn q_range_checks_a_run_and_refuses_what_is_not_one() {
    let _time = timed!();
    let dir = tmp("q-range");
    let (run, table) = (dir.join("cartpole"), dir.join("cliffwalk"));
    for (config, out) in [
        ("deploy/configs/recommended/cartpole.toml", &run),
        ("deploy/configs/cliffwalk-bootstrapped.toml", &table),
    ] {
        let o = local_40(config, out, &[]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let o = alfd(&["q-range", run.to_str().unwrap(), "--episodes", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    let row = out
        .lines()
        .find(|l| l.starts_with(run.to_str().unwrap()))
        .unwrap_or_else(|| panic!("no row for the run: {out}"));
    let cells: Vec<&str> = row.split('\t').collect();
    assert_eq!(cells.len(), 6, "{row}");
    let (min, max): (f64, f64) = (cells[1].parse().unwrap(), cells[2].parse().unwrap());
    assert!(min <= max && min.is_finite() && max.is_finite(), "{row}");
    assert_eq!(cells[4], "[0, 200]", "CartPole-1000 at γ = 0.995: {row}");
    let verdict = if max > 250.0 || min < -50.0 {
        "DIVERGED"
    } else {
        "ok"
    };
    assert_eq!(cells[5], verdict, "{row}");
    assert!(out.contains("of 1 diverged"), "{out}");

    let o = alfd(&["q-range", table.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("weights.safetensors") || stderr(&o).contains("cliffwalk"));
    let o = alfd(&["q-range", dir.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("config.toml"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"));
}

#[test]
fn the_manual_documents_every_output_column_and_summary_field() {
    use alfd_common::record::{RunSummary, RuntimeSummary, CSV_HEADER};
    let readme =
        std::fs::read_to_string(crate::support::repo().join("docs/src/outputs.md")).unwrap();
    let documented = |name: &str| {
        readme.lines().any(|l| {
            l.starts_with('|')
                && l.split('|')
                    .nth(1)
                    .is_some_and(|c| c.contains(&format!("`{name}`")))
        })
    };
    for column in CSV_HEADER.split(',') {
        assert!(
            documented(column),
            "episodes.csv column `{column}` is not in docs/src/outputs.md"
        );
    }
    let summary = RunSummary {
        episodes: 1,
        mean_return_last_50: 0.0,
        demos_used: 0,
        wall_clock_s: 0.0,
        greedy_value_at_start: Some(0.0),
        optimal_value_at_start: Some(0.0),
        env_steps: Some(0),
        updates: Some(0),
        env_steps_per_s: Some(0.0),
        updates_per_s: Some(0.0),
        runtime: Some(RuntimeSummary {
            run_id: String::new(),
            demos: 0,
            actor_restarts: 0,
            expert_swaps: 0,
            expert_restarts: 0,
            learner_restarts: 0,
            interrupted: false,
            demos_refused: 0,
            answers_late: 0,
            demos_experts_wrote: 0,
            episodes_lost: 0,
        }),
    };
    let json = serde_json::to_value(&summary).unwrap();
    let fields = json.as_object().unwrap();
    assert!(fields.len() >= 17, "{fields:?}");
    for field in fields.keys() {
        assert!(
            documented(field),
            "summary.json field `{field}` is not in docs/src/outputs.md"
        );
    }
}

#[test]
fn the_documents_generated_tables_match_the_committed_results() {
    let _time = timed!();
    let experiments =
        std::fs::read_to_string(crate::support::repo().join("EXPERIMENTS.md")).unwrap();
    let parts = experiments.matches("<!-- generated from ").count();
    assert!(parts >= 6, "EXPERIMENTS.md has {parts} generated parts");
    let o = alfd(&["docs", "--check"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // A part edited by hand is found.
    let dir = tmp("docs-check");
    let root = crate::support::repo();
    std::fs::create_dir_all(dir.join("docs/src")).unwrap();
    let chapters = std::fs::read_dir(root.join("docs/src")).unwrap();
    let chapters =
        chapters.map(|e| format!("docs/src/{}", e.unwrap().file_name().to_str().unwrap()));
    for doc in ["README.md", "EXPERIMENTS.md", "BENCHMARKS.md"]
        .map(String::from)
        .into_iter()
        .chain(chapters)
    {
        std::fs::copy(root.join(&doc), dir.join(&doc)).unwrap();
    }
    std::fs::create_dir_all(dir.join("results")).unwrap();
    let copy = Command::new("cp")
        .args(["-r", "results", dir.to_str().unwrap()])
        .current_dir(crate::support::repo())
        .status()
        .unwrap();
    assert!(copy.success());
    let edited = experiments.replacen("<!-- end generated -->", "| 1 |\n<!-- end generated -->", 1);
    std::fs::write(dir.join("EXPERIMENTS.md"), edited).unwrap();
    let o = alfd(&["docs", "--check", "--root", dir.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("EXPERIMENTS.md: line"),
        "{}",
        stderr(&o)
    );
    // `alfd docs` mends it.
    let o = alfd(&["docs", "--root", dir.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(dir.join("EXPERIMENTS.md")).unwrap(),
        experiments
    );
}
