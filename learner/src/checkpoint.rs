//! `RUN_DIR/learner.ckpt`: the learner process's whole state (the core's [`LearnerSnapshot`]:
//! online and target weights, Adam's moments and step, the replay buffer with masks and
//! demonstration flags, the learner's generator, its counters) and the run's global step, in the
//! core's checkpoint format (versioned, checksummed, tied to the run's `config.toml`). Written
//! whole (temporary file, fsync, rename, fsync of the directory), so a learner killed while
//! writing leaves the previous good checkpoint. A learner restarted in a live run, or by
//! `alfd resume`, continues from it.

use std::path::{Path, PathBuf};

use alfd_common::agent::LearnerSnapshot;
use alfd_harness::{load_checkpoint, save_checkpoint, BadInput};
use serde::{Deserialize, Serialize};

/// The checkpoint's name in a run directory.
pub const LEARNER_CHECKPOINT: &str = "learner.ckpt";

/// What the learner writes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LearnerCheckpoint {
    pub learner: LearnerSnapshot,
    /// Environment steps the learner had received from all actors (the run's global step).
    pub env_steps: u64,
}

pub fn path(run_dir: &Path) -> PathBuf {
    run_dir.join(LEARNER_CHECKPOINT)
}

/// The text of `RUN_DIR/config.toml`, to which a checkpoint belongs.
pub fn config_text(run_dir: &Path) -> alfd_harness::Result<String> {
    let p = run_dir.join("config.toml");
    std::fs::read_to_string(&p)
        .map_err(|e| BadInput(format!("cannot read {}: {e}", p.display())).into())
}

/// Writes the checkpoint whole; returns its size in bytes.
pub fn save(
    run_dir: &Path,
    ckpt: &LearnerCheckpoint,
    config_toml: &str,
) -> alfd_harness::Result<usize> {
    save_checkpoint(&path(run_dir), ckpt, config_toml)
}

/// Reads the checkpoint, if there is one; one that cannot be trusted (truncated, corrupt, of
/// another version or another config) is [`BadInput`] saying which, and
/// is left as it is.
pub fn load(run_dir: &Path, config_toml: &str) -> alfd_harness::Result<Option<LearnerCheckpoint>> {
    load_checkpoint(&path(run_dir), config_toml, "the learner was not restored")
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_common::agent::NeuralLearner;
    use alfd_common::checkpoint::{config_hash, decode, encode};
    use alfd_common::config::ExperimentConfig;
    use alfd_common::replay::Transition;
    use alfd_common::rng::seeded;

    const CONFIG: &str = "seed = 3\nepisodes = 2\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\nheads = 2\nreplay_capacity = 64\nbatch_size = 4\n";

    fn learner() -> NeuralLearner {
        let cfg = ExperimentConfig::from_toml(CONFIG).unwrap();
        let mut l = NeuralLearner::new(&cfg.agent, 4, 2, seeded(7));
        for i in 0..20 {
            l.learn(&Transition {
                state: vec![i as f32 * 0.01; 4],
                action: i % 2,
                reward: 1.0,
                next_state: vec![i as f32 * 0.01 + 0.01; 4],
                terminated: i == 19,
                mask: vec![1.0, 0.0],
                demo: i == 3,
                horizon: 1,
            });
        }
        l
    }

    use alfd_harness::test_dir;

    #[test]
    fn a_checkpoint_restores_the_learner_exactly_and_bad_ones_are_refused_saying_why() {
        let tmp = test_dir("learner-ckpt");
        let d = tmp.path();
        assert!(load(d, CONFIG).unwrap().is_none());
        let l = learner();
        let ckpt = LearnerCheckpoint {
            learner: l.snapshot(),
            env_steps: 1234,
        };
        let size = save(d, &ckpt, CONFIG).unwrap();
        assert_eq!(std::fs::metadata(path(d)).unwrap().len(), size as u64);
        let back = load(d, CONFIG).unwrap().unwrap();
        assert_eq!(back, ckpt);
        // Restored, the learner goes on exactly as the original does.
        let cfg = ExperimentConfig::from_toml(CONFIG).unwrap();
        let mut a = l.clone();
        let mut b = NeuralLearner::new(&cfg.agent, 4, 2, seeded(99));
        b.restore(&back.learner).unwrap();
        let t = Transition {
            state: vec![0.5; 4],
            action: 1,
            reward: 0.0,
            next_state: vec![0.6; 4],
            terminated: false,
            mask: vec![1.0, 1.0],
            demo: false,
            horizon: 1,
        };
        for _ in 0..5 {
            assert_eq!(a.learn(&t), b.learn(&t));
        }
        assert_eq!(a.snapshot(), b.snapshot());

        // Another config, a truncated file, a flipped byte: refused, the file kept.
        let other = CONFIG.replace("seed = 3", "seed = 4");
        let e = load(d, &other).unwrap_err().to_string();
        assert!(e.contains("learner.ckpt") && e.contains("config"), "{e}");
        let good = std::fs::read(path(d)).unwrap();
        std::fs::write(path(d), &good[..good.len() / 2]).unwrap();
        let e = load(d, CONFIG).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        let mut flipped = good.clone();
        let n = flipped.len() - 10;
        flipped[n] ^= 0x40;
        std::fs::write(path(d), &flipped).unwrap();
        let e = load(d, CONFIG).unwrap_err().to_string();
        assert!(e.contains("corrupt") || e.contains("checksum"), "{e}");
        assert_eq!(std::fs::read(path(d)).unwrap(), flipped);
    }

    /// The size and write time of `learner.ckpt` with a full replay buffer of the recommended
    /// CartPole preset's learner, as one `BENCH {json}` line that
    /// `deploy/bench/runtime.sh` reads. Run with
    /// `cargo test --release -p alfd-learner -- --ignored --nocapture learner_checkpoint_cost`.
    #[test]
    #[ignore = "a measurement, not a test"]
    fn learner_checkpoint_cost() {
        let text = include_str!("../../deploy/configs/recommended/cartpole.toml");
        let cfg = ExperimentConfig::from_toml(text).unwrap();
        let mut l = NeuralLearner::new(&cfg.agent, 4, 2, seeded(1));
        let mut rng = seeded(2);
        for i in 0..cfg.agent.replay_capacity {
            let s: Vec<f32> = (0..4)
                .map(|_| rand::Rng::random_range(&mut rng, -1.0..1.0))
                .collect();
            l.learn(&Transition {
                next_state: s.iter().map(|x| x + 0.01).collect(),
                state: s,
                action: (i % 2) as u32,
                reward: 1.0,
                terminated: i % 200 == 199,
                mask: (0..cfg.agent.heads())
                    .map(|k| ((i + k) % 2) as f32)
                    .collect(),
                demo: i < 100,
                horizon: 1,
            });
        }
        let tmp = test_dir("learner-ckpt-cost");
        let d = tmp.path();
        let mut times = Vec::new();
        let mut size = 0;
        for _ in 0..10 {
            let t = std::time::Instant::now();
            size = save(
                d,
                &LearnerCheckpoint {
                    learner: l.snapshot(),
                    env_steps: 10_000,
                },
                text,
            )
            .unwrap();
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let mut loads = Vec::new();
        for _ in 0..10 {
            let t = std::time::Instant::now();
            load(d, text).unwrap().unwrap();
            loads.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        loads.sort_by(f64::total_cmp);
        // One line for deploy/bench/runtime.py.
        println!(
            "BENCH {}",
            serde_json::json!({
                "bench": "learner_ckpt", "bytes": size, "transitions": cfg.agent.replay_capacity,
                "write_ms_median": times[5], "write_ms_min": times[0], "write_ms_max": times[9],
                "read_ms_median": loads[5],
            })
        );
    }

    // The fuzz pass: a damaged learner.ckpt (truncated, bytes changed, bytes
    // appended) is refused with an error and never panics; nothing else decodes it.
    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        #[test]
        fn fuzz_a_damaged_learner_checkpoint_is_refused_never_a_panic(
            cut in proptest::option::of(0usize..200_000),
            flips in proptest::collection::vec((0usize..200_000, 1u8..=255), 0..4),
            tail in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..8),
        ) {
            use std::sync::OnceLock;
            static GOOD: OnceLock<Vec<u8>> = OnceLock::new();
            let good = GOOD.get_or_init(|| {
                encode(
                    &LearnerCheckpoint { learner: learner().snapshot(), env_steps: 20 },
                    config_hash(CONFIG),
                )
            });
            let mut bytes = good.clone();
            if let Some(c) = cut {
                bytes.truncate(c % (good.len() + 1));
            }
            for (at, x) in flips {
                if !bytes.is_empty() {
                    let i = at % bytes.len();
                    bytes[i] ^= x;
                }
            }
            bytes.extend_from_slice(&tail);
            let decoded = decode::<LearnerCheckpoint>(&bytes, config_hash(CONFIG));
            if bytes != *good {
                proptest::prop_assert!(decoded.is_err());
            }
        }
    }
}
