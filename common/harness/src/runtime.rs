//! The runtime settings of a multi-process run ([`RuntimeConfig`]): one validated file,
//! `RUN_DIR/runtime.toml`, that the launcher writes and every process reads, so that actors and
//! learner can never disagree on the credit window.

use std::time::Duration;

use alfd_wire::MAX_CREDIT_WINDOW;
use serde::{Deserialize, Serialize};

/// The file in a run directory.
pub const RUNTIME_FILE: &str = "runtime.toml";

/// Largest `query_timeout_ms`: one hour.
pub const MAX_QUERY_TIMEOUT_MS: u64 = 3_600_000;
/// Largest `handshake_timeout_s`: one day.
pub const MAX_HANDSHAKE_TIMEOUT_S: u64 = 86_400;
/// Largest `weights_every`.
pub const MAX_WEIGHTS_EVERY: u64 = 1_000_000_000;

/// Settings of the runtime (not of the experiment: they change speed and robustness, never what
/// an experiment means).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RuntimeConfig {
    /// Credit window: how many steps an actor may run ahead of the learner's updates
    /// (1 = lockstep: the actor always acts on the newest weights), `1..=64`.
    pub window: u64,
    /// Milliseconds an actor waits for the expert's answer before acting on its own.
    pub query_timeout_ms: u64,
    /// Milliseconds an actor waits for the answer when a person is the expert (`human`): a
    /// person needs minutes, not a second. Default 5 minutes.
    #[serde(default = "default_human_query_timeout_ms")]
    pub human_query_timeout_ms: u64,
    /// The port of the human expert's page on 127.0.0.1 (0: any free port; the address is in
    /// the expert's log and in `RUN_DIR/human-page.txt`).
    #[serde(default)]
    pub human_port: u16,
    /// Seconds a process waits for the launcher's first word and for the learner's first weights.
    pub handshake_timeout_s: u64,
    /// The learner publishes its weights every this many updates.
    pub weights_every: u64,
    /// The learner writes its whole state to `RUN_DIR/learner.ckpt`, and each actor to
    /// `RUN_DIR/actor-<id>.ckpt`, at the first episode end after every this many updates' worth
    /// of environment steps (`alfd_common::checkpoint::Cadence`), and the learner when it stops;
    /// 0: only when it stops. A learner that dies is restarted from it.
    #[serde(default = "default_checkpoint_every")]
    pub checkpoint_every: u64,
    /// When the expert refits its demonstration model: `inline` (before it answers the query
    /// that brought the demonstration, so that the actor shapes that very step with it) or
    /// `background` (on a thread of its own while it answers; the model is published when it
    /// is ready: queries never wait for a refit, and runs no longer repeat to the byte).
    #[serde(default)]
    pub refit: Refit,
    /// Restarts allowed per actor, of the expert, of the learner (the launcher's), and of each
    /// of several experts' processes (the expert process's), before it gives up on it.
    #[serde(default = "default_max_restarts")]
    pub max_restarts: u32,
    /// A Gymnasium environment's spaces and limit, as its adapter reported them when the run
    /// started (absent for the built-in environments).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub env_spec: Option<crate::python::EnvSpec>,
}

/// When the expert refits its demonstration model ([`RuntimeConfig::refit`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Refit {
    /// Before answering the query that brought the demonstration.
    #[default]
    Inline,
    /// On a thread of its own, while the expert answers.
    Background,
}

/// The default of [`RuntimeConfig::checkpoint_every`] (see BENCHMARKS.md: a CartPole checkpoint
/// with a full 10,000-transition buffer costs well under 5% of the learner's time at this period).
pub const DEFAULT_CHECKPOINT_EVERY: u64 = 10_000;

/// `alfd run`'s default `--max-restarts` ([`RuntimeConfig::max_restarts`]).
pub const DEFAULT_MAX_RESTARTS: u32 = 5;

fn default_max_restarts() -> u32 {
    DEFAULT_MAX_RESTARTS
}

/// The name of the human expert (`--expert human`).
pub const HUMAN_EXPERT: &str = "human";

/// The default of [`RuntimeConfig::human_query_timeout_ms`]: 5 minutes.
pub const DEFAULT_HUMAN_QUERY_TIMEOUT_MS: u64 = 300_000;

fn default_human_query_timeout_ms() -> u64 {
    DEFAULT_HUMAN_QUERY_TIMEOUT_MS
}

fn default_checkpoint_every() -> u64 {
    DEFAULT_CHECKPOINT_EVERY
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            window: 32,
            query_timeout_ms: 1000,
            human_query_timeout_ms: DEFAULT_HUMAN_QUERY_TIMEOUT_MS,
            human_port: 0,
            handshake_timeout_s: 20,
            weights_every: 1,
            checkpoint_every: DEFAULT_CHECKPOINT_EVERY,
            refit: Refit::Inline,
            max_restarts: DEFAULT_MAX_RESTARTS,
            env_spec: None,
        }
    }
}

/// A runtime config that cannot be used, naming the field at fault.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RuntimeConfigError {
    #[error("invalid runtime config: {0}")]
    Parse(String),
    #[error("invalid runtime config: `{field}` {message}")]
    Invalid {
        field: &'static str,
        message: String,
    },
}

impl RuntimeConfig {
    /// Parses and validates `runtime.toml`.
    pub fn from_toml(text: &str) -> Result<Self, RuntimeConfigError> {
        let cfg: Self = toml::from_str(text)
            .map_err(|e| RuntimeConfigError::Parse(e.message().trim().to_owned()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a RuntimeConfig always serialises")
    }

    /// Checks every value; the error names the field.
    pub fn validate(&self) -> Result<(), RuntimeConfigError> {
        let invalid = |field, message: String| Err(RuntimeConfigError::Invalid { field, message });
        if !(1..=MAX_CREDIT_WINDOW).contains(&self.window) {
            return invalid(
                "window",
                format!("must be in 1..={MAX_CREDIT_WINDOW}, got {}", self.window),
            );
        }
        // Upper limits: a deadline `now + timeout` must exist (u64::MAX ms panicked there).
        for (field, value, max) in [
            (
                "query_timeout_ms",
                self.query_timeout_ms,
                MAX_QUERY_TIMEOUT_MS,
            ),
            (
                "human_query_timeout_ms",
                self.human_query_timeout_ms,
                MAX_QUERY_TIMEOUT_MS,
            ),
            (
                "handshake_timeout_s",
                self.handshake_timeout_s,
                MAX_HANDSHAKE_TIMEOUT_S,
            ),
            ("weights_every", self.weights_every, MAX_WEIGHTS_EVERY),
        ] {
            if value == 0 {
                return invalid(field, "must be at least 1".to_owned());
            }
            if value > max {
                return invalid(field, format!("must be at most {max}, got {value}"));
            }
        }
        if self.checkpoint_every > MAX_WEIGHTS_EVERY {
            return invalid(
                "checkpoint_every",
                format!(
                    "must be at most {MAX_WEIGHTS_EVERY}, got {}",
                    self.checkpoint_every
                ),
            );
        }
        Ok(())
    }

    pub fn query_timeout(&self) -> Duration {
        Duration::from_millis(self.query_timeout_ms)
    }

    /// How long an actor waits for the answer of the expert named `expert` (a person gets
    /// [`RuntimeConfig::human_query_timeout_ms`]).
    pub fn query_timeout_for(&self, expert: &str) -> Duration {
        if expert == HUMAN_EXPERT {
            Duration::from_millis(self.human_query_timeout_ms)
        } else {
            self.query_timeout()
        }
    }

    pub fn handshake_timeout(&self) -> Duration {
        Duration::from_secs(self.handshake_timeout_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_round_trips_and_bad_values_name_their_field() {
        let d = RuntimeConfig::default();
        assert_eq!(RuntimeConfig::from_toml(&d.to_toml()).unwrap(), d);
        let with = |field: &str, value: &str| {
            let text = d
                .to_toml()
                .lines()
                .map(|l| {
                    if l.starts_with(&format!("{field} ")) {
                        format!("{field} = {value}")
                    } else {
                        l.to_owned()
                    }
                })
                .collect::<Vec<_>>()
                .join("\n");
            RuntimeConfig::from_toml(&text)
        };
        assert_eq!(with("window", "1").unwrap().window, 1);
        assert_eq!(
            with("window", "0").unwrap_err().to_string(),
            "invalid runtime config: `window` must be in 1..=64, got 0"
        );
        assert!(with("window", "65")
            .unwrap_err()
            .to_string()
            .contains("`window`"));
        for field in ["query_timeout_ms", "handshake_timeout_s", "weights_every"] {
            let e = with(field, "0").unwrap_err().to_string();
            assert!(e.contains(&format!("`{field}` must be at least 1")), "{e}");
        }
        // A person gets minutes; a file of before that field gets the default.
        assert_eq!(d.query_timeout_for("human"), Duration::from_secs(300));
        assert_eq!(
            d.query_timeout_for("cartpole-perfect"),
            Duration::from_secs(1)
        );
        let e = with("human_query_timeout_ms", "0").unwrap_err().to_string();
        assert!(
            e.contains("`human_query_timeout_ms` must be at least 1"),
            "{e}"
        );
        let older: String = d
            .to_toml()
            .lines()
            .filter(|l| !l.starts_with("human_"))
            .map(|l| format!("{l}\n"))
            .collect();
        assert_eq!(RuntimeConfig::from_toml(&older).unwrap(), d);
        let e = RuntimeConfig::from_toml("window = 4\nwindows = 3").unwrap_err();
        assert!(e.to_string().contains("windows"), "{e}");
        let e = RuntimeConfig::from_toml("window = \"big\"").unwrap_err();
        assert!(matches!(e, RuntimeConfigError::Parse(_)), "{e}");
    }

    // Regression (fuzz): `query_timeout_ms = 18446744073709551615` was accepted, and the
    // actor's `Instant::now() + timeout` panicked at its first query.
    #[test]
    fn timeouts_beyond_their_limits_are_refused_naming_the_field() {
        for (text, field) in [
            (
                "query_timeout_ms = 18446744073709551615",
                "query_timeout_ms",
            ),
            (
                "handshake_timeout_s = 18446744073709551615",
                "handshake_timeout_s",
            ),
            ("weights_every = 18446744073709551615", "weights_every"),
        ] {
            let toml = [
                "window = 4",
                "query_timeout_ms = 10",
                "handshake_timeout_s = 1",
            ]
            .into_iter()
            .chain(["weights_every = 1"])
            .filter(|l| !l.starts_with(field))
            .chain([text])
            .collect::<Vec<_>>()
            .join("\n");
            let e = RuntimeConfig::from_toml(&toml).unwrap_err();
            assert!(
                matches!(e, RuntimeConfigError::Invalid { field: f, .. } if f == field),
                "{e}"
            );
        }
    }

    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        fn field() -> impl Strategy<Value = String> {
            let key = prop_oneof![
                Just("window"),
                Just("query_timeout_ms"),
                Just("handshake_timeout_s"),
                Just("weights_every"),
                Just("other"),
            ];
            let value = prop_oneof![
                any::<u64>().prop_map(|v| v.to_string()),
                any::<i64>().prop_map(|v| v.to_string()),
                Just("0".to_owned()),
                Just("65".to_owned()),
                Just("1.5".to_owned()),
                Just("\"x\"".to_owned()),
                "[ -~]{0,8}",
            ];
            (key, value).prop_map(|(k, v)| format!("{k} = {v}\n"))
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            /// Arbitrary text and arbitrary fields: never a panic; what parses is valid and
            /// round-trips.
            #[test]
            fn fuzz_runtime_config(
                text in "[ -~\n]{0,120}",
                fields in proptest::collection::vec(field(), 0..6),
            ) {
                for t in [text, fields.concat()] {
                    if let Ok(cfg) = RuntimeConfig::from_toml(&t) {
                        prop_assert!(cfg.validate().is_ok());
                        let now = std::time::Instant::now();
                        prop_assert!(now.checked_add(cfg.query_timeout()).is_some());
                        prop_assert!(now.checked_add(cfg.handshake_timeout()).is_some());
                        prop_assert_eq!(RuntimeConfig::from_toml(&cfg.to_toml()), Ok(cfg));
                    }
                }
            }
        }
    }
}
