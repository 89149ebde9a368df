//! `RUN_DIR/checkpoint.bin` of a single-process run: the core's [`RunState`] in the core's
//! checkpoint format, written whole (temporary file, fsync, rename), so that a crash while
//! writing leaves the previous good checkpoint; read back and refused (exit code 2, saying why:
//! truncated, corrupt, other version, other config) when it cannot be trusted.

use std::path::{Path, PathBuf};

use alfd_common::checkpoint::{config_hash, decode, encode};
use alfd_common::runner::RunState;
use serde::{Deserialize, Serialize};

use crate::usage::usage;

/// The checkpoint's name in a run directory.
pub const CHECKPOINT: &str = "checkpoint.bin";

/// What a checkpoint holds: the run's state and how often the run checkpoints.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CheckpointFile {
    /// Checkpoint every this many episodes.
    pub every: u32,
    pub state: RunState,
}

pub fn path(dir: &Path) -> PathBuf {
    dir.join(CHECKPOINT)
}

/// The checkpoint's bytes for the run of config `config_toml` (the text of its `config.toml`).
pub fn to_bytes(file: &CheckpointFile, config_toml: &str) -> Vec<u8> {
    encode(file, config_hash(config_toml))
}

/// Writes `RUN_DIR/checkpoint.bin` whole.
pub fn save(dir: &Path, file: &CheckpointFile, config_toml: &str) -> anyhow::Result<()> {
    Ok(alfd_harness::write_atomically(
        &path(dir),
        &to_bytes(file, config_toml),
    )?)
}

/// Reads `RUN_DIR/checkpoint.bin`, which must belong to the run of config `config_toml`.
pub fn load(dir: &Path, config_toml: &str) -> anyhow::Result<CheckpointFile> {
    let p = path(dir);
    let bytes = match std::fs::read(&p) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(usage(format!(
                "{} has no {CHECKPOINT}: only a run started with `alfd local --checkpoint-every N` \
                 can be resumed",
                dir.display()
            )))
        }
        Err(e) => return Err(usage(format!("cannot read {}: {e}", p.display()))),
    };
    decode(&bytes, config_hash(config_toml)).map_err(|e| {
        usage(format!(
            "{}: {e}; nothing was resumed and the file was left as it is",
            p.display()
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::usage::is_usage_error;
    use alfd_common::agent::ExpertSnapshot;
    use alfd_common::agent::TabularSnapshot;
    use alfd_common::env::Env;
    use alfd_common::environment_loop::Progress;
    use alfd_common::runner::TabularRunState;

    fn state() -> CheckpointFile {
        let mut env = alfd_common::env::CliffWalk::default();
        env.reset(Some(1));
        let cfg = alfd_common::config::ExperimentConfig::from_toml(
            "seed = 0\nepisodes = 3\n[env]\nname = \"cliffwalk\"\n[agent]\nkind = \"qlearning\"\ngamma = 0.9\n",
        )
        .unwrap();
        let agent = alfd_common::agent::TabularAgent::new(
            &cfg.agent,
            &cfg.rule_spec(),
            env.num_states(),
            4,
            alfd_common::rng::seeded(0),
        );
        let agent: TabularSnapshot = agent.snapshot();
        CheckpointFile {
            every: 5,
            state: RunState::Tabular(Box::new(TabularRunState {
                progress: Progress {
                    episodes: 5,
                    steps: 77,
                },
                records: Vec::new(),
                agent,
                env: env.snapshot(),
                expert: ExpertSnapshot {
                    demos: Vec::new(),
                    model_version: 0,
                },
            })),
        }
    }

    #[test]
    fn a_saved_checkpoint_loads_back() {
        let tmp = alfd_harness::test_dir("ckpt");
        let d = tmp.path();
        save(d, &state(), "seed = 0\n").unwrap();
        let back = load(d, "seed = 0\n").unwrap();
        assert_eq!(back.every, 5);
        assert_eq!(back.state, state().state);
    }

    #[test]
    fn a_bad_checkpoint_is_refused_with_its_reason_and_left_as_it_is() {
        let tmp = alfd_harness::test_dir("ckpt");
        let d = tmp.path();
        let good = to_bytes(&state(), "seed = 0\n");
        let mut flipped = good.clone();
        *flipped.last_mut().unwrap() ^= 1;
        let mut version = good.clone();
        version[8] ^= 1;
        let cases: [(&[u8], &str, &str); 4] = [
            (
                &good[..good.len() / 2],
                "seed = 0\n",
                "truncated checkpoint",
            ),
            (&flipped, "seed = 0\n", "corrupt checkpoint"),
            (&version, "seed = 0\n", "another format version"),
            (&good, "seed = 1\n", "another config"),
        ];
        for (bytes, config, reason) in cases {
            std::fs::write(path(d), bytes).unwrap();
            let e = load(d, config).unwrap_err();
            assert!(is_usage_error(&e), "{e:#}");
            let msg = format!("{e:#}");
            assert!(msg.contains(reason) && msg.contains(CHECKPOINT), "{msg}");
            assert_eq!(std::fs::read(path(d)).unwrap(), bytes, "left as it is");
        }
        std::fs::remove_file(path(d)).unwrap();
        let e = load(d, "seed = 0\n").unwrap_err();
        assert!(format!("{e:#}").contains("--checkpoint-every"), "{e:#}");
    }

    /// The size and write time of the checkpoint of a CartPole run whose 10,000-transition
    /// replay buffer is full (the run's own state, the records and demonstrations so far).
    /// Prints one `BENCH {json}` line (`deploy/bench/runtime.sh` reads it); asserts no time.
    /// `cargo test --release -p alfd-deploy --bin alfd -- --ignored --nocapture checkpoint_size`.
    #[test]
    #[ignore = "a measurement, run by hand"]
    fn checkpoint_size_and_write_time_of_a_full_cartpole_buffer() {
        use alfd_common::runner::{run_neural_checkpointed, Checkpoints, NeuralRunState};
        use std::ops::ControlFlow;
        use std::time::Instant;
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/cartpole-bdqn-krr.toml"
        ))
        .unwrap();
        let overrides = ["episodes=100000".to_owned()];
        let cfg =
            alfd_common::config::ExperimentConfig::from_toml_with_overrides(&text, &overrides)
                .unwrap();
        assert_eq!(cfg.agent.replay_capacity, 10_000);
        let mut full: Option<NeuralRunState> = None;
        run_neural_checkpointed(
            &cfg,
            &mut alfd_common::agent::BalancingController,
            Checkpoints {
                from: None,
                every: Some(1),
            },
            |s| {
                if s.learner.replay.len() < 10_000 {
                    return ControlFlow::Continue(());
                }
                full = Some(s.clone());
                ControlFlow::Break(())
            },
            |_, _| ControlFlow::Continue(()),
        )
        .unwrap();
        let state = full.expect("the buffer fills");
        let file = CheckpointFile {
            every: 1,
            state: RunState::Neural(Box::new(state)),
        };
        let config_toml = cfg.to_toml();
        let tmp = alfd_harness::test_dir("ckpt");
        let d = tmp.path();
        // Each write: encode (postcard, header, checksum) and the atomic write; then ten reads.
        let mut write_ms = Vec::new();
        let mut size = 0;
        for _ in 0..10 {
            let t = Instant::now();
            let bytes = to_bytes(&file, &config_toml);
            size = bytes.len();
            alfd_harness::write_atomically(&path(d), &bytes).unwrap();
            write_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let mut read_ms = Vec::new();
        for _ in 0..10 {
            let t = Instant::now();
            let back = load(d, &config_toml).unwrap();
            read_ms.push(t.elapsed().as_secs_f64() * 1e3);
            assert_eq!(back.state.progress(), file.state.progress());
        }
        write_ms.sort_by(f64::total_cmp);
        read_ms.sort_by(f64::total_cmp);
        // One line for deploy/bench/runtime.py.
        println!(
            "BENCH {}",
            serde_json::json!({
                "bench": "checkpoint_bin", "bytes": size,
                "transitions": cfg.agent.replay_capacity,
                "episode": file.state.progress().episodes, "demos": file.state.demos().len(),
                "write_ms_median": write_ms[5], "write_ms_min": write_ms[0],
                "write_ms_max": write_ms[9], "read_ms_median": read_ms[5],
            })
        );
    }
}
