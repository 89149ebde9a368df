//! DeepSea from the command line: `alfd env rollout --env deepsea` step for step as bsuite 0.3.6
//! (the fixtures of `common/core/tests/data/deepsea`, made with bsuite), and `alfd local` on
//! DeepSea's cells with every gate of a rule in two parts (`query.allowance`, `query.gate`).

use std::path::Path;

use serde_json::Value;

use crate::support::{alfd, repo, text, timed, tmp};

fn fixtures() -> Vec<Value> {
    let dir = repo().join("common/core/tests/data/deepsea");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .contains("_mapping_seed")
        })
        .collect();
    files.sort();
    assert!(files.len() >= 12, "{files:?}");
    files
        .iter()
        .map(|p| serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap())
        .collect()
}

#[test]
fn rollout_gives_bsuites_positions_and_rewards_bit_for_bit() {
    let _time = timed!();
    let mut checked = 0;
    for f in fixtures() {
        let (size, seed) = (
            f["size"].as_u64().unwrap(),
            f["mapping_seed"].as_u64().unwrap(),
        );
        for (name, episode) in f["episodes"].as_object().unwrap() {
            let actions: Vec<String> = episode["actions"]
                .as_array()
                .unwrap()
                .iter()
                .map(|a| a.to_string())
                .collect();
            let o = alfd()
                .args(["env", "rollout", "--env", "deepsea"])
                .args([
                    "--size",
                    &size.to_string(),
                    "--mapping-seed",
                    &seed.to_string(),
                ])
                .args(["--actions", &actions.join(",")])
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", text(&o));
            let lines: Vec<Value> = String::from_utf8(o.stdout)
                .unwrap()
                .lines()
                .map(|l| serde_json::from_str(l).unwrap())
                .collect();
            let want_pos = episode["positions"].as_array().unwrap();
            let want_bits = episode["reward_bits"].as_array().unwrap();
            assert_eq!(lines.len(), want_pos.len(), "N={size} seed {seed} {name}");
            for (i, l) in lines.iter().enumerate() {
                assert_eq!(
                    l["position"], want_pos[i],
                    "N={size} seed {seed} {name} step {i}"
                );
                let bits = l["reward"].as_f64().unwrap().to_bits();
                assert_eq!(bits, want_bits[i].as_u64().unwrap(), "{name} step {i}");
            }
            assert_eq!(lines.last().unwrap()["terminated"], true);
            checked += 1;
        }
    }
    assert!(checked >= 24, "{checked} episodes");
}

#[test]
fn rollout_refuses_what_deepsea_does_not_take_with_exit_code_2() {
    for (args, says) in [
        (&["--mapping-seed", "1", "--actions", "0"][..], "--size"),
        (&["--size", "5", "--actions", "0"][..], "--mapping-seed"),
        (
            &["--size", "0", "--mapping-seed", "1", "--actions", "0"][..],
            "size",
        ),
        (
            &["--size", "5", "--mapping-seed", "1", "--actions", "2"][..],
            "2",
        ),
        (
            &[
                "--size",
                "5",
                "--mapping-seed",
                "1",
                "--actions",
                "0",
                "--initial-state",
                "0",
            ][..],
            "--initial-state",
        ),
    ] {
        let o = alfd()
            .args(["env", "rollout", "--env", "deepsea"])
            .args(args)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains(says),
            "{args:?}: {}",
            text(&o)
        );
    }
}

/// `alfd local` of DeepSea(8) with bootstrapped Q-tables, a budget of 12 spread over the run,
/// and `query.gate = gate`; the summary.
fn local(dir: &Path, gate: &str) -> Value {
    let out = dir.join(gate);
    let config = dir.join(format!("{gate}.toml"));
    std::fs::write(
        &config,
        format!(
            "seed = 3\nepisodes = 200\n[env]\nname = \"deepsea\"\nsize = 8\n\
             [agent]\nkind = \"bootstrapped-q\"\nheads = 10\nprior_scale = 1.0\n\
             [query]\nallowance = \"spread\"\ngate = \"{gate}\"\nhorizon = 1600\n\
             [budget]\ntotal = 12\n[expert]\nmodel = \"none\"\n\
             [evaluation]\nevery = 20\nepisodes = 1\n"
        ),
    )
    .unwrap();
    let o = alfd()
        .args(["local", "--quiet", "--out", out.to_str().unwrap()])
        .arg(format!("--config={}", config.display()))
        .output()
        .unwrap();
    assert!(o.status.success(), "{gate}: {}", text(&o));
    serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn every_gate_runs_on_deepsea_within_its_allowance() {
    let _time = timed!();
    let dir = tmp("deepsea-gates");
    for gate in ["chance", "js", "q-std", "novelty", "oracle", "record"] {
        let s = local(&dir, gate);
        let used = s["demos_used"].as_u64().unwrap();
        assert!(used <= 12, "{gate}: {used}");
        let demos =
            alfd_demonstrators::demo_log::read(&dir.join(gate).join("demos.jsonl")).unwrap();
        // Spread over 1,600 steps: the (n+1)-th not before step 133·n.
        for (n, d) in demos.iter().enumerate() {
            assert!(
                d.step * 12 >= n as u64 * 1600,
                "{gate}: demonstration {n} at step {}",
                d.step
            );
            assert_eq!(d.expert, "deepsea-optimal");
        }
        let rows = std::fs::read_to_string(dir.join(gate).join("episodes.csv")).unwrap();
        let evaluated = rows.lines().skip(1).filter(|l| !l.ends_with(',')).count();
        assert_eq!(
            evaluated, 10,
            "{gate}: one greedy evaluation every 20 episodes"
        );
    }
    // The same run twice is the same run.
    let again = tmp("deepsea-again");
    local(&again, "record");
    assert_eq!(
        std::fs::read(again.join("record/demos.jsonl")).unwrap(),
        std::fs::read(dir.join("record/demos.jsonl")).unwrap()
    );
}

#[test]
fn gate_oracle_is_refused_by_alfd_run_with_exit_code_2() {
    let out = tmp("oracle-run");
    let o = alfd()
        .args([
            "run",
            "--quiet",
            "--actors",
            "1",
            "--out",
            out.to_str().unwrap(),
        ])
        .args(["--set", "query.rule=never", "--set", "query.gate=oracle"])
        .args(["--set", "episodes=2"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("alfd local"),
        "{}",
        text(&o)
    );
}

/// `alfd local`, `alfd run` with one actor in lockstep and `alfd run` with two actors of a
/// network of `heads` heads on DeepSea(`size`), in `dir`; `false` when `alfd run` refused the
/// run because the machine's shared memory cannot hold it (exit 2, saying so).
fn neural_deepsea(dir: &Path, size: usize, heads: usize) -> bool {
    let config = dir.join("deepsea.toml");
    std::fs::write(
        &config,
        format!(
            "seed = 3\nepisodes = 20\n[env]\nname = \"deepsea\"\nsize = {size}\n\
             [agent]\nkind = \"bdqn\"\nheads = {heads}\nbatch_size = 16\n\
             [query]\nrule = \"first\"\n[budget]\ntotal = 100\n\
             [expert]\nname = \"deepsea-optimal\"\n"
        ),
    )
    .unwrap();
    let (local, lockstep, two) = (dir.join("local"), dir.join("lockstep"), dir.join("two"));
    for (out, how) in [
        (&local, &["local"][..]),
        (&lockstep, &["run", "--actors=1", "--window=1"][..]),
        (&two, &["run", "--actors=2"][..]),
    ] {
        let o = alfd()
            .args(how)
            .args(["--quiet", "--out", out.to_str().unwrap()])
            .arg(format!("--config={}", config.display()))
            .output()
            .unwrap();
        if how[0] == "run" && o.status.code() == Some(2) {
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(
                err.contains("MiB of shared memory") && err.contains("/dev/shm has"),
                "{err}"
            );
            eprintln!("DeepSea({size}), K = {heads}: refused here for want of shared memory");
            return false;
        }
        assert!(o.status.success(), "{how:?}: {}", text(&o));
    }
    let episodes = |dir: &Path| std::fs::read_to_string(dir.join("episodes.csv")).unwrap();
    assert_eq!(episodes(&lockstep), episodes(&local));
    assert_eq!(episodes(&two).lines().count(), 21);
    let demos = alfd_demonstrators::demo_log::read(&two.join("demos.jsonl")).unwrap();
    assert_eq!(demos.len(), 100);
    // Each demonstration is a cell of the grid, answered with the move right there.
    let sea = alfd_common::env::DeepSea::new(size, 3).unwrap();
    for d in &demos {
        assert_eq!(d.state.len(), size * size);
        let state: Vec<f32> = d.state.iter().map(|&v| v as f32).collect();
        assert_eq!(Some(d.action), sea.optimal_action_for(&state));
    }
    true
}

/// A network plays DeepSea's one-hot grid in `alfd run` as in `alfd local`, to the byte with one
/// actor in lockstep: DeepSea(12) with 12 heads (144 values a state, 29 MiB of shared memory,
/// so it runs everywhere), and DeepSea(50) with 20 heads (2,500 values a state, 419 MiB), which
/// a machine whose `/dev/shm` cannot hold it must refuse with exit code 2.
#[test]
fn a_network_of_20_heads_plays_deepsea_50_in_alfd_run_as_in_alfd_local_to_the_byte() {
    let _time = timed!();
    let dir = tmp("deepsea-neural");
    std::fs::create_dir_all(dir.join("n12")).unwrap();
    std::fs::create_dir_all(dir.join("n50")).unwrap();
    assert!(
        neural_deepsea(&dir.join("n12"), 12, 12),
        "DeepSea(12) fits any machine"
    );
    neural_deepsea(&dir.join("n50"), 50, 20);
}
