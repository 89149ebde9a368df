//! `RUN_DIR/actor-<id>.ckpt`: an actor's whole state at an episode end — its episodes and steps,
//! the core's [`ActorSnapshot`] (ε position, the query rule's divergence queue, its generator, the
//! episode's head), the environment's state with its generator, and what it knew of the expert
//! (budget left, demonstrations used, the demonstration model) — with the run's global step then.
//! The file keeps the last two such states: in lockstep with one actor, the learner's
//! `learner.ckpt` pairs with one of them (the learner may be one episode behind the actor), and
//! `alfd resume` continues from that pair to the byte. Same format and guarantees as
//! `learner.ckpt` (versioned, checksummed, tied to `config.toml`, written whole).

use std::path::{Path, PathBuf};

use alfd_common::agent::ActorSnapshot;
use alfd_common::env::EnvState;
use alfd_common::environment_loop::Progress;
use alfd_harness::{load_checkpoint, save_checkpoint};
use serde::{Deserialize, Serialize};

use crate::links::ExpertView;

/// How many states the file keeps.
pub const SLOTS: usize = 2;

/// One actor state at an episode end.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ActorCheckpoint {
    /// Episodes this actor finished and steps it took.
    pub progress: Progress,
    /// The run's global step at that episode end (the learner's count once it has them all).
    pub global_step: u64,
    pub core: ActorSnapshot,
    pub env: EnvState,
    pub expert: ExpertView,
}

/// The file's content: the last [`SLOTS`] states, oldest first.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ActorCheckpoints {
    pub slots: Vec<ActorCheckpoint>,
}

impl ActorCheckpoints {
    /// Adds the newest state, dropping the oldest beyond [`SLOTS`].
    pub fn push(&mut self, c: ActorCheckpoint) {
        self.slots.push(c);
        let extra = self.slots.len().saturating_sub(SLOTS);
        self.slots.drain(..extra);
    }

    /// The state saved at global step `step`.
    pub fn at(&self, step: u64) -> Option<&ActorCheckpoint> {
        self.slots.iter().find(|c| c.global_step == step)
    }

    pub fn newest(&self) -> Option<&ActorCheckpoint> {
        self.slots.last()
    }
}

pub fn path(run_dir: &Path, actor: u16) -> PathBuf {
    run_dir.join(format!("actor-{actor}.ckpt"))
}

/// Writes the file whole.
pub fn save(
    run_dir: &Path,
    actor: u16,
    ckpts: &ActorCheckpoints,
    config_toml: &str,
) -> alfd_harness::Result<()> {
    save_checkpoint(&path(run_dir, actor), ckpts, config_toml).map(drop)
}

/// Reads actor `actor`'s file, if there is one; one that cannot be trusted is
/// [`BadInput`](alfd_harness::BadInput) saying which, and is left as it is.
pub fn load(
    run_dir: &Path,
    actor: u16,
    config_toml: &str,
) -> alfd_harness::Result<Option<ActorCheckpoints>> {
    load_checkpoint(
        &path(run_dir, actor),
        config_toml,
        "the actor was not restored (remove the file to resume without its state)",
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_common::agent::NeuralActor;
    use alfd_common::config::ExperimentConfig;
    use alfd_common::env::{CartPole, Env};
    use alfd_common::rng::seeded;

    const CONFIG: &str =
        "seed = 3\nepisodes = 2\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n";

    fn state(step: u64) -> ActorCheckpoint {
        let cfg = ExperimentConfig::from_toml(CONFIG).unwrap();
        let core = NeuralActor::new(
            &cfg.agent,
            &cfg.rule_spec(),
            cfg.shaping.kind,
            4,
            2,
            seeded(1),
        );
        let mut env = CartPole::new(1000);
        env.reset(Some(step));
        ActorCheckpoint {
            progress: Progress {
                episodes: step as u32,
                steps: step,
            },
            global_step: step,
            core: core.snapshot(),
            env: env.snapshot(),
            expert: ExpertView {
                budget_left: 7,
                demos: 3,
                model: None,
                model_demos: 3,
                last_demo_step: step,
            },
        }
    }

    #[test]
    fn the_file_keeps_the_last_two_states_and_refuses_a_damaged_one() {
        let mut c = ActorCheckpoints::default();
        for step in [10, 20, 30] {
            c.push(state(step));
        }
        let steps: Vec<u64> = c.slots.iter().map(|s| s.global_step).collect();
        assert_eq!(steps, [20, 30]);
        assert_eq!(c.at(20).unwrap().progress.episodes, 20);
        assert!(c.at(10).is_none());
        assert_eq!(c.newest().unwrap().global_step, 30);

        let dir = tempfile::tempdir().unwrap();
        save(dir.path(), 1, &c, CONFIG).unwrap();
        assert_eq!(load(dir.path(), 1, CONFIG).unwrap().unwrap(), c);
        assert!(load(dir.path(), 0, CONFIG).unwrap().is_none());
        let other = load(dir.path(), 1, "seed = 4\n").unwrap_err().to_string();
        assert!(
            other.contains("actor-1.ckpt") && other.contains("another config"),
            "{other}"
        );
        let p = path(dir.path(), 1);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
        let cut = load(dir.path(), 1, CONFIG).unwrap_err().to_string();
        assert!(cut.contains("truncated"), "{cut}");
        assert_eq!(
            std::fs::read(&p).unwrap().len(),
            bytes.len() / 2,
            "left as it is"
        );
    }
}
