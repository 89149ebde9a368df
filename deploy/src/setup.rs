//! Shared set-up of the CLI: logging, reading configs and maps, building environments and
//! demonstrators from a config.

use std::path::Path;

use alfd_common::config::{EnvName, ExperimentConfig};
use alfd_common::env::cliffwalk::{CliffMap, CliffWalk};
use anyhow::Context as _;

use crate::usage::usage;

/// Logs to stderr; `RUST_LOG` sets the filter (default `warn`).
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// Reads and validates an experiment config, with `--set` overrides.
pub fn load_config(path: &Path, overrides: &[String]) -> anyhow::Result<ExperimentConfig> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| usage(format!("cannot read config {}: {e}", path.display())))?;
    ExperimentConfig::from_toml_with_overrides(&text, overrides)
        .with_context(|| format!("in config {}", path.display()))
}

/// Reads a CliffWalk map file, or the built-in map.
pub fn load_map(path: Option<&str>) -> anyhow::Result<CliffMap> {
    match path {
        None => Ok(CliffMap::default_map()),
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| usage(format!("cannot read map {p}: {e}")))?;
            CliffMap::parse(&text).with_context(|| format!("in map {p}"))
        }
    }
}

/// The CliffWalk environment of a config.
pub fn cliffwalk(cfg: &ExperimentConfig) -> anyhow::Result<CliffWalk> {
    anyhow::ensure!(cfg.env.name == EnvName::Cliffwalk, "not a cliffwalk config");
    let map = load_map(cfg.env.map.as_deref())?;
    Ok(CliffWalk::new(
        map,
        cfg.env.p_success,
        cfg.env.max_episode_steps(),
    )?)
}

/// The demonstrator named by a neural config, for its environment.
pub fn neural_demonstrator(
    cfg: &ExperimentConfig,
) -> anyhow::Result<Box<dyn alfd_common::agent::Demonstrator<[f32]> + Send>> {
    alfd_expert::registry::for_env(cfg.env.name, &cfg.expert.name).map_err(|e| usage(e.to_string()))
}
