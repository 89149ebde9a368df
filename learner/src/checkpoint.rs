//! `RUN_DIR/learner.ckpt`: the learner process's whole state (the core's [`LearnerSnapshot`]:
//! online and target weights, Adam's moments and step, the replay buffer with masks and
//! demonstration flags, the learner's generator, its counters) and the run's global step, in the
//! core's checkpoint format (versioned, checksummed, tied to the run's `config.toml`). Written
//! whole (temporary file, fsync, rename, fsync of the directory), so a learner killed while
//! writing leaves the previous good checkpoint. A learner restarted in a live run, or by
//! `alfd resume`, continues from it.

use std::path::{Path, PathBuf};

use alfd_common::agent::LearnerSnapshot;
use alfd_common::checkpoint::{config_hash, decode, encode};
use alfd_harness::{write_atomically, BadInput};
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
pub fn config_text(run_dir: &Path) -> anyhow::Result<String> {
    let p = run_dir.join("config.toml");
    std::fs::read_to_string(&p)
        .map_err(|e| BadInput(format!("cannot read {}: {e}", p.display())).into())
}

/// Writes the checkpoint whole; returns its size in bytes.
pub fn save(run_dir: &Path, ckpt: &LearnerCheckpoint, config_toml: &str) -> anyhow::Result<usize> {
    let bytes = encode(ckpt, config_hash(config_toml));
    write_atomically(&path(run_dir), &bytes)?;
    Ok(bytes.len())
}

/// Reads the checkpoint, if there is one; one that cannot be trusted (truncated, corrupt, of
/// another version or another config) is [`BadInput`] saying which, and is left as it is.
pub fn load(run_dir: &Path, config_toml: &str) -> anyhow::Result<Option<LearnerCheckpoint>> {
    let p = path(run_dir);
    let bytes = match std::fs::read(&p) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(BadInput(format!("cannot read {}: {e}", p.display())).into()),
    };
    decode(&bytes, config_hash(config_toml))
        .map(Some)
        .map_err(|e| {
            BadInput(format!(
                "{}: {e}; the learner was not restored and the file was left as it is",
                p.display()
            ))
            .into()
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_common::agent::NeuralLearner;
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
            });
        }
        l
    }

    /// A unit test's scratch directory `alfd-NAME-XXXXXX` in the system's temporary
    /// directory, removed with everything in it when dropped (also while a failed test unwinds);
    /// kept, and named on stderr, when `ALFD_KEEP_TEST_DIRS=1`.
    fn test_dir(name: &str) -> tempfile::TempDir {
        use std::io::Write as _;
        let keep = std::env::var_os("ALFD_KEEP_TEST_DIRS").is_some_and(|v| v == "1");
        let dir = tempfile::Builder::new()
            .prefix(&format!("alfd-{name}-"))
            .disable_cleanup(keep)
            .tempdir()
            .expect("a temporary directory");
        if keep {
            // Straight to stderr: libtest's capture would hide it for a test that passes.
            let _ = writeln!(
                std::io::stderr(),
                "ALFD_KEEP_TEST_DIRS: keeping {}",
                dir.path().display()
            );
        }
        dir
    }

    #[test]
    fn a_checkpoint_restores_the_learner_exactly_and_bad_ones_are_refused_saying_why() {
        let tmp = test_dir("learner-ckpt");
        let d = tmp.path();
        assert!(load(&d, CONFIG).unwrap().is_none());
        let l = learner();
        let ckpt = LearnerCheckpoint {
            learner: l.snapshot(),
            env_steps: 1234,
        };
        let size = save(&d, &ckpt, CONFIG).unwrap();
        assert_eq!(std::fs::metadata(path(&d)).unwrap().len(), size as u64);
        let back = load(&d, CONFIG).unwrap().unwrap();
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
        };
        for _ in 0..5 {
            assert_eq!(a.learn(&t), b.learn(&t));
        }
        assert_eq!(a.snapshot(), b.snapshot());

        // Another config, a truncated file, a flipped byte: refused, the file kept.
        let other = CONFIG.replace("seed = 3", "seed = 4");
        let e = load(&d, &other).unwrap_err().to_string();
        assert!(e.contains("learner.ckpt") && e.contains("config"), "{e}");
        let good = std::fs::read(path(&d)).unwrap();
        std::fs::write(path(&d), &good[..good.len() / 2]).unwrap();
        let e = load(&d, CONFIG).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        let mut flipped = good.clone();
        let n = flipped.len() - 10;
        flipped[n] ^= 0x40;
        std::fs::write(path(&d), &flipped).unwrap();
        let e = load(&d, CONFIG).unwrap_err().to_string();
        assert!(e.contains("corrupt") || e.contains("checksum"), "{e}");
        assert_eq!(std::fs::read(path(&d)).unwrap(), flipped);
    }
}
