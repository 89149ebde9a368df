//! Shared set-up of the CLI: logging, reading configs and maps, building environments and
//! demonstrators from a config.

use std::path::Path;

use alfd_common::config::{ConfigError, EnvName, ExperimentConfig};
use alfd_common::env::cliffwalk::{CliffMap, CliffWalk};
use alfd_demonstrators::registry::People;
use anyhow::Context as _;

use crate::usage::usage;

/// Logs to stderr; `RUST_LOG` sets the filter (default `warn`).
pub fn init_logging() {
    use tracing_subscriber::prelude::*;
    let _ = tracing_subscriber::registry()
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
                .with_filter(tracing_subscriber::filter::filter_fn(|m| {
                    !tls_refusals::is_zenoh_tls(m)
                })),
        )
        .with(tls_refusals::TlsRefusals(Default::default()))
        // zenoh warns of every failed connection attempt; its errors are enough.
        .with(alfd_harness::log_filter(
            "warn,zenoh=error,zenoh_transport=error,zenoh_link_tcp=error,zenoh_link_commons::quic=warn",
        ))
        .try_init();
}

/// Reads and validates an experiment config, with `--set` overrides.
pub fn load_config(path: &Path, overrides: &[String]) -> anyhow::Result<ExperimentConfig> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| usage(format!("cannot read config {}: {e}", path.display())))?;
    parse_config(&text, overrides, &format!("config {}", path.display()))
}

/// Validates the config `text` (called `source` in messages) with `--set` overrides. An error
/// says where the bad value came from: the file, or the command line (naming the `--set`).
pub fn parse_config(
    text: &str,
    overrides: &[String],
    source: &str,
) -> anyhow::Result<ExperimentConfig> {
    let mut cfg = ExperimentConfig::from_toml_with_overrides(text, overrides).map_err(|e| {
        let file_alone = if overrides.is_empty() {
            None
        } else {
            ExperimentConfig::from_toml(text).err()
        };
        let context = match blame(&e, overrides, file_alone.as_ref()) {
            Culprit::File => format!("in {source}"),
            Culprit::Override(item) => format!("in `--set {item}` (on the command line)"),
            Culprit::CommandLine => format!(
                "in the --set values given on the command line ({})",
                overrides.join(" ")
            ),
        };
        anyhow::Error::new(e).context(context)
    })?;
    cfg.load_schedule(alfd_harness::read_text)?;
    Ok(cfg)
}

/// Where a bad config value came from.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Culprit {
    /// The config file (or the default config).
    File,
    /// This `--set KEY=VALUE`.
    Override(String),
    /// Some `--set`, which one is not known.
    CommandLine,
}

/// Blames the error `err` of a config read with `overrides` on the file or on the command line:
/// the file is at fault if it fails alone (`file_alone`) with the same error.
fn blame(err: &ConfigError, overrides: &[String], file_alone: Option<&ConfigError>) -> Culprit {
    if overrides.is_empty() {
        return Culprit::File;
    }
    let key = |item: &String| item.split_once('=').map_or("", |kv| kv.0).trim().to_owned();
    let the_one = |found: Option<&String>| match (found, overrides) {
        (Some(item), _) => Culprit::Override(item.clone()),
        (None, [only]) => Culprit::Override(only.clone()),
        (None, _) => Culprit::CommandLine,
    };
    match err {
        ConfigError::BadOverride(_) => Culprit::CommandLine,
        _ if file_alone.is_some_and(|f| f.to_string() == err.to_string()) => Culprit::File,
        ConfigError::Invalid { field, .. } => {
            the_one(overrides.iter().rev().find(|o| key(o) == *field))
        }
        ConfigError::Parse(message) => the_one(overrides.iter().rev().find(|o| {
            let k = key(o);
            let last = k.rsplit('.').next().unwrap_or_default();
            message.contains(&format!("`{k}`")) || message.contains(&format!("`{last}`"))
        })),
    }
}

/// The most bytes read from a map file: the largest map (`MAX_MAP_SIDE` = 128 rows of 128 tiles)
/// takes 16.5 kB, so this leaves room for trailing whitespace and blank lines, and a larger file
/// (or `/dev/zero`) is refused rather than read whole.
pub const MAX_MAP_FILE_BYTES: u64 = 1 << 20;

/// The text of a map file, at most [`MAX_MAP_FILE_BYTES`]; the error says why not (without the
/// path, which the caller names).
pub fn read_map_text(path: &Path) -> Result<String, String> {
    use std::io::Read as _;
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read: {e}"))?;
    let mut text = String::new();
    file.take(MAX_MAP_FILE_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(|e| format!("cannot read: {e}"))?;
    if text.len() as u64 > MAX_MAP_FILE_BYTES {
        return Err(format!(
            "the file is larger than {MAX_MAP_FILE_BYTES} bytes; a map has at most {side}x{side} tiles",
            side = alfd_common::env::cliffwalk::MAX_MAP_SIDE
        ));
    }
    Ok(text)
}

/// Reads a CliffWalk map file, or the built-in map.
pub fn load_map(path: Option<&str>) -> anyhow::Result<CliffMap> {
    match path {
        None => Ok(CliffMap::default_map()),
        Some(p) => {
            let text = read_map_text(Path::new(p)).map_err(|e| usage(format!("map {p}: {e}")))?;
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

/// The DeepSea of a config, as state ids: N = `env.size`, the mapping seed `env.mapping_seed`
/// or else the run's seed (its low 32 bits).
pub fn deepsea(cfg: &ExperimentConfig) -> anyhow::Result<alfd_common::env::DeepSeaCells> {
    anyhow::ensure!(cfg.env.name == EnvName::Deepsea, "not a deepsea config");
    let sea = alfd_common::env::DeepSea::with_max_episode_steps(
        cfg.env.deepsea_size(),
        cfg.deepsea_mapping_seed(),
        cfg.env.max_episode_steps(),
    )
    .map_err(|e| usage(e.to_string()))?;
    Ok(alfd_common::env::DeepSeaCells(sea))
}

/// The environment of a tabular config.
pub enum TabularEnvs {
    CliffWalk(Box<CliffWalk>),
    DeepSea(Box<alfd_common::env::DeepSeaCells>),
}

impl TabularEnvs {
    /// The environment of a tabular config (CliffWalk, DeepSea).
    pub fn of(cfg: &ExperimentConfig) -> anyhow::Result<Self> {
        Ok(match cfg.env.name {
            EnvName::Deepsea => Self::DeepSea(Box::new(deepsea(cfg)?)),
            _ => Self::CliffWalk(Box::new(cliffwalk(cfg)?)),
        })
    }

    /// The demonstrators of `cfg`'s `[[experts]]` for this environment, in order.
    pub fn panel(
        &self,
        cfg: &ExperimentConfig,
    ) -> anyhow::Result<alfd_common::runner::TabularPanel> {
        let mut members = Vec::with_capacity(cfg.experts.len());
        for i in 0..cfg.experts.len() {
            members.push(alfd_demonstrators::registry::member_of(cfg, i, |name| {
                self.built(name)
            })?);
        }
        Ok(members)
    }

    /// The demonstrator `name` for this environment (CliffWalk's for its map, DeepSea's for its
    /// instance).
    pub fn demonstrator(
        &self,
        name: &str,
    ) -> anyhow::Result<Box<dyn alfd_common::agent::Demonstrator<usize> + Send>> {
        Ok(self.built(name)?)
    }

    fn built(
        &self,
        name: &str,
    ) -> Result<Box<dyn alfd_common::agent::Demonstrator<usize> + Send>, alfd_harness::BadInput>
    {
        match self {
            Self::DeepSea(env) => alfd_demonstrators::registry::deepsea(name, env),
            Self::CliffWalk(env) => alfd_demonstrators::registry::cliffwalk(name, env),
        }
    }
}

/// The expert gate `oracle` consults, for a config whose gate is `oracle` (none otherwise): a
/// second copy of the config's built-in demonstrator, consulted for the gate alone.
pub fn oracle<S: ?Sized + 'static>(
    cfg: &ExperimentConfig,
    make: impl FnOnce() -> anyhow::Result<Box<dyn alfd_common::agent::Demonstrator<S> + Send>>,
) -> anyhow::Result<Option<alfd_common::query::Oracle<S>>> {
    if cfg.query.gate != Some(alfd_common::query::GateKind::Oracle) {
        return Ok(None);
    }
    let mut d = make().map_err(|e| usage(format!("gate `oracle` consults the expert: {e:#}")))?;
    Ok(Some(alfd_common::query::Oracle::new(move |s: &S| d.act(s))))
}

/// The config's demonstrator exists: a built-in one for its environment (CliffWalk's for its
/// map), or a well-formed external one (`python:MODULE:FUNCTION`, `sb3:ALGO:PATH`), which the
/// expert process starts.
pub fn check_demonstrator(cfg: &ExperimentConfig) -> anyhow::Result<()> {
    check_demonstrator_where(cfg, People::Refused)
}

/// [`check_demonstrator`] for `alfd run`, where a person may be among several experts.
pub fn check_run_demonstrator(cfg: &ExperimentConfig) -> anyhow::Result<()> {
    check_demonstrator_where(cfg, People::Allowed)
}

fn check_demonstrator_where(cfg: &ExperimentConfig, people: People) -> anyhow::Result<()> {
    if !cfg.experts.is_empty() && cfg.agent.kind.is_tabular() {
        TabularEnvs::of(cfg)?.panel(cfg)?;
        return Ok(());
    }
    if !cfg.experts.is_empty() {
        return check_panel(cfg, people);
    }
    if !cfg.needs_expert() {
        // No expert to check; a map is still read now, so that a bad one is refused first.
        if cfg.agent.kind.is_tabular() {
            TabularEnvs::of(cfg)?;
        }
        return Ok(());
    }
    if cfg.expert.name == alfd_expert::human::HUMAN {
        // A person answers on a web page: any environment, any number of actions.
        return Ok(());
    }
    if alfd_demonstrators::registry::external_policy(&cfg.expert.name).is_some() {
        return Ok(alfd_demonstrators::registry::check_external(
            &cfg.expert.name,
        )?);
    }
    if cfg.agent.kind.is_tabular() {
        return TabularEnvs::of(cfg)?
            .demonstrator(&cfg.expert.name)
            .map(|_| ());
    }
    neural_demonstrator(cfg).map(|_| ())
}

/// The demonstrators of `[[experts]]`, in order, when each is a built-in one of the config's
/// environment (none without `[[experts]]`); external ones are started by `local_remote`.
pub fn panel(
    cfg: &ExperimentConfig,
) -> anyhow::Result<Vec<Box<dyn alfd_common::agent::Demonstrator<[f32]>>>> {
    Ok(alfd_demonstrators::registry::panel(
        cfg,
        People::Refused,
        |_, name| {
            Err(alfd_harness::BadInput(format!(
                "[[experts]]: the external expert `{name}` is started with the run's adapters"
            ))
            .into())
        },
    )?)
}

/// Checks `[[experts]]` without starting anyone: each name known for the environment, each
/// external name well formed, a person only where `people` allows.
fn check_panel(cfg: &ExperimentConfig, people: People) -> anyhow::Result<()> {
    let none = |_: usize,
                _: &str|
     -> alfd_harness::Result<Box<dyn alfd_common::agent::Demonstrator<[f32]>>> {
        Ok(Box::new(alfd_common::agent::NoExpert))
    };
    alfd_demonstrators::registry::panel(cfg, people, none)?;
    Ok(())
}

/// The demonstrator named by a neural config, for its environment.
pub fn neural_demonstrator(
    cfg: &ExperimentConfig,
) -> anyhow::Result<Box<dyn alfd_common::agent::Demonstrator<[f32]> + Send>> {
    if !cfg.needs_expert() {
        return Ok(Box::new(alfd_common::agent::NoExpert));
    }
    if cfg.expert.name == alfd_expert::human::HUMAN {
        return Err(usage(
            "the human expert (a person on a web page) answers in `alfd run` and `alfd \
             swap-expert` only: its page is served by the expert process",
        ));
    }
    Ok(alfd_demonstrators::registry::for_config(
        cfg,
        &cfg.expert.name,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str =
        "seed = 1\nepisodes = 10\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n";

    fn error(text: &str, sets: &[&str]) -> String {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        format!(
            "{:#}",
            parse_config(text, &sets, "config c.toml").unwrap_err()
        )
    }

    #[test]
    fn a_bad_value_is_blamed_on_where_it_came_from() {
        // From the command line: the `--set` is named, not the file.
        let e = error(FILE, &["episodes=20", "agent.heads=0"]);
        assert!(
            e.starts_with("in `--set agent.heads=0` (on the command line): ")
                && e.contains("agent.heads"),
            "{e}"
        );
        let e = error(FILE, &["agent.colour=3"]);
        assert!(e.starts_with("in `--set agent.colour=3`"), "{e}");
        let e = error(FILE, &["agent.heads=-x"]);
        assert!(e.starts_with("in `--set agent.heads=-x`"), "{e}");
        let e = error(FILE, &["nonsense"]);
        assert!(
            e.starts_with("in the --set values given on the command line (nonsense)"),
            "{e}"
        );
        // From the file: the file is named, even with unrelated overrides.
        let bad_file = FILE.replace("seed = 1", "seed = 1\nbudget.total = -4");
        let e = error(&bad_file, &["episodes=20"]);
        assert!(e.starts_with("in config c.toml: "), "{e}");
        assert!(error(&bad_file, &[]).starts_with("in config c.toml: "));
        // The command line overriding a bad file value is the command line's fault if still bad.
        let e = error(&bad_file, &["budget.total=-5"]);
        assert!(e.starts_with("in `--set budget.total=-5`"), "{e}");
    }
}

/// A peer refused by the TLS handshake of a `quic/` endpoint (no certificate of the run's CA, an
/// expired one): zenoh warns of it as of a full file table ("… Hint: increase the system open
/// file limit."); these warnings are said again as what they are, under `alfd_bridge`, with the
/// handshake's reason, at the 1st, 2nd, 4th, 8th, ... refusal (a peer retries 4 times a second).
mod tls_refusals {
    use std::sync::atomic::{AtomicU64, Ordering};

    use tracing::field::{Field, Visit};
    use tracing::{Event, Level, Metadata, Subscriber};
    use tracing_subscriber::layer::{Context, Layer};

    const HINT: &str = " Hint: increase the system open file limit.";

    pub(super) fn is_zenoh_tls(m: &Metadata<'_>) -> bool {
        m.target().starts_with("zenoh_link_commons::quic")
    }

    pub(super) struct TlsRefusals(pub(super) AtomicU64);

    impl<S: Subscriber> Layer<S> for TlsRefusals {
        fn on_event(&self, event: &Event<'_>, _: Context<'_, S>) {
            let m = event.metadata();
            if !is_zenoh_tls(m) || *m.level() > Level::WARN {
                return;
            }
            let mut text = Message(String::new());
            event.record(&mut text);
            if !text.0.ends_with(HINT) {
                tracing::warn!(target: "alfd_bridge", "QUIC: {}", text.0);
                return;
            }
            let refused = self.0.fetch_add(1, Ordering::Relaxed) + 1;
            if refused.is_power_of_two() {
                tracing::warn!(
                    target: "alfd_bridge",
                    refused,
                    "refused a peer: {}",
                    reason(&text.0)
                );
            }
        }
    }

    /// The TLS reason in a QUIC connection error, or the whole text without zenoh's hint.
    pub(super) fn reason(text: &str) -> &str {
        #[cfg(feature = "hosts")]
        if let Some(reason) = alfd_bridge::tls_reason(text) {
            return reason;
        }
        text.trim_end_matches(HINT)
    }

    struct Message(String);

    impl Visit for Message {
        fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
            if field.name() == "message" {
                self.0 = format!("{value:?}");
            }
        }
    }

    #[cfg(all(test, feature = "hosts"))]
    mod tests {
        #[test]
        fn the_reason_is_taken_from_either_form_of_the_error() {
            let a = "QUIC acceptor failed: TransportError(Error { code: Code::crypto(33), \
                     frame: None, reason: \"invalid peer certificate: Expired\" }) at x.rs:1. \
                     Hint: increase the system open file limit.";
            assert_eq!(super::reason(a), "invalid peer certificate: Expired");
            let b = "QUIC acceptor failed: ConnectionClosed(ConnectionClose { reason: \
                     b\"peer sent no certificates\" }) Hint: increase the system open file limit.";
            assert_eq!(super::reason(b), "peer sent no certificates");
            assert_eq!(
                super::reason("other Hint: increase the system open file limit."),
                "other"
            );
        }
    }
}
