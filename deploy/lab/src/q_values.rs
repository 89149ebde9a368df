//! The Q-values a run's learned network takes on its own greedy episodes, against the range every
//! true value lies in: a check for divergence (EXPERIMENTS.md, the CartPole Q-value divergence: a
//! CartPole-1000 network whose Q-values reached 40,000 where no return exceeds 200 had learned to
//! seek failure). `alfd q-range` prints it for run directories; every run's summary says it.

use std::path::Path;

use alfd_common::config::ExperimentConfig;
use alfd_common::env::vector_env;
use alfd_common::evaluate::{q_range, value_bounds, QRange};
use alfd_common::nn::Mlp;

use crate::error::{usage, Result};

/// Greedy episodes and the first one's reset seed, of `alfd q-range` and of the end-of-run summary.
pub const EPISODES: u32 = 3;
pub const SEED: u64 = 100;

/// One run's verdict.
pub struct Checked {
    pub range: QRange,
    pub bounds: (f64, f64),
    pub diverged: bool,
}

/// A run diverged when its Q-values leave the true range by more than a quarter of its width
/// (shaping moves values a little past the range; a diverged network is off by multiples of it).
pub fn check(dir: &Path, episodes: u32, seed: u64) -> Result<Checked> {
    let read = |name: &str| {
        let path = dir.join(name);
        std::fs::read(&path).map_err(|e| {
            usage(format!(
                "{}: cannot read {name} ({e}); q-range needs a neural run's directory",
                dir.display()
            ))
        })
    };
    let text = String::from_utf8(read("config.toml")?)
        .map_err(|_| usage(format!("{}: config.toml is not UTF-8", dir.display())))?;
    let cfg = ExperimentConfig::from_toml(&text)
        .map_err(|e| usage(format!("{}: config.toml: {e}", dir.display())))?;
    check_with(dir, &cfg, &read("weights.safetensors")?, episodes, seed)
}

/// [`check`] with the config read and the weights' bytes.
fn check_with(
    dir: &Path,
    cfg: &ExperimentConfig,
    weights: &[u8],
    episodes: u32,
    seed: u64,
) -> Result<Checked> {
    let name = cfg.env.name;
    let (Some(rewards), Some(mut env)) = (name.reward_range(), vector_env(cfg)) else {
        return Err(usage(format!(
            "{}: environment `{name}`; q-range knows the reward range of cartpole, mountaincar \
             and acrobot",
            dir.display()
        )));
    };
    let net = Mlp::from_safetensors_bytes(weights)
        .map_err(|e| usage(format!("{}: weights.safetensors: {e}", dir.display())))?;
    if net.obs_dim() != env.observation_dim() || net.actions() != env.num_actions() {
        return Err(usage(format!(
            "{}: the network takes {} inputs and gives {} actions; `{name}` has {} and {}",
            dir.display(),
            net.obs_dim(),
            net.actions(),
            env.observation_dim(),
            env.num_actions()
        )));
    }
    let range = q_range(&net, env.as_mut(), episodes, seed)?;
    let bounds = value_bounds(rewards, cfg.agent.gamma);
    let slack = 0.25 * (bounds.1 - bounds.0);
    let diverged = range.max > bounds.1 + slack || range.min < bounds.0 - slack;
    Ok(Checked {
        range,
        bounds,
        diverged,
    })
}

/// The end-of-run summary's line on the learned network's Q-values (3 greedy episodes), or `None`
/// where there is nothing to check (a tabular run, an environment of unknown reward range, no
/// weights) or the check fails: the summary reports, it does not fail.
pub fn summary_text(dir: &Path, cfg: &ExperimentConfig) -> Option<String> {
    cfg.env.name.reward_range()?;
    let weights = std::fs::read(dir.join("weights.safetensors")).ok()?;
    let c = check_with(dir, cfg, &weights, EPISODES, SEED).ok()?;
    let mut text = format!(
        "{:.1} to {:.1} on {EPISODES} greedy episodes; every true value lies in [{:.0}, {:.0}] \
         (γ = {})",
        c.range.min, c.range.max, c.bounds.0, c.bounds.1, cfg.agent.gamma
    );
    if c.diverged {
        text.push_str(
            " — DIVERGED: the network values states beyond any return (EXPERIMENTS.md, \
             the CartPole Q-value divergence; `agent.target_bounds` clamps the targets)",
        );
    }
    Some(text)
}
