//! `[logging]`: what a run writes for watching it besides its own files.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LoggingConfig {
    /// TensorBoard event files in `RUN_DIR/tb/` (`tensorboard --logdir RUN_DIR`), written as the
    /// run goes: Stable-Baselines3's tags (`rollout/ep_rew_mean`, `eval/mean_reward`,
    /// `time/fps`, ...) and this project's (`query/js`, `demos/used`, `learner/td_loss`, ...).
    #[serde(default = "yes")]
    pub tensorboard: bool,
}

fn yes() -> bool {
    true
}

impl Default for LoggingConfig {
    fn default() -> Self {
        Self { tensorboard: true }
    }
}

impl LoggingConfig {
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}
