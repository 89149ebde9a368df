//! The lab's typed error: what failed, with the error that says why as its source, so that
//! `alfd_harness::exit_code` finds the user's mistakes ([`alfd_harness::BadInput`], a bad config)
//! anywhere in the chain and `alfd_harness::describe` prints it whole.

use std::error::Error;
use std::fmt::Display;

/// Why a sweep, a report or a plot failed.
#[derive(Debug, thiserror::Error)]
pub enum LabError {
    /// The user's to fix (exit code 2).
    #[error("{0}")]
    BadInput(#[from] alfd_harness::BadInput),
    /// `what` failed; the source says why.
    #[error("{what}")]
    Failed {
        what: String,
        #[source]
        source: Box<dyn Error + Send + Sync>,
    },
    /// A failure the message says whole.
    #[error("{0}")]
    Msg(String),
}

impl AsRef<dyn Error + 'static> for LabError {
    fn as_ref(&self) -> &(dyn Error + 'static) {
        self
    }
}

/// The lab's `Result`.
pub type Result<T, E = LabError> = std::result::Result<T, E>;

macro_rules! impl_from {
    ($($t:ty => $what:literal),* $(,)?) => {$(
        impl From<$t> for LabError {
            fn from(e: $t) -> Self {
                LabError::Failed { what: $what.into(), source: Box::new(e) }
            }
        }
    )*};
}

impl_from!(
    std::io::Error => "input/output",
    std::fmt::Error => "formatting",
    serde_json::Error => "JSON",
    alfd_common::config::ConfigError => "config",
    alfd_common::env::EnvError => "environment",
    alfd_common::demo_model::DemoModelError => "demonstration model",
    alfd_harness::HarnessError => "run directory",
);

/// Bad input (exit code 2): `Err(usage(format!(..)))?`.
pub fn usage(msg: impl Into<String>) -> LabError {
    LabError::BadInput(alfd_harness::BadInput(msg.into()))
}

/// `.context(..)` and `.with_context(|| ..)`: names what failed, keeping the error as its source
/// (on an `Option`, `None` becomes the message).
pub trait Context<T> {
    fn with_context<D: Display>(self, what: impl FnOnce() -> D) -> Result<T>;

    fn context<D: Display>(self, what: D) -> Result<T>
    where
        Self: Sized,
    {
        self.with_context(|| what)
    }
}

impl<T, E: Error + Send + Sync + 'static> Context<T> for std::result::Result<T, E> {
    fn with_context<D: Display>(self, what: impl FnOnce() -> D) -> Result<T> {
        self.map_err(|e| LabError::Failed {
            what: what().to_string(),
            source: Box::new(e),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn with_context<D: Display>(self, what: impl FnOnce() -> D) -> Result<T> {
        self.ok_or_else(|| LabError::Msg(what().to_string()))
    }
}

/// `bail!`: returns a [`LabError::Msg`] with the formatted message.
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::error::LabError::Msg(format!($($arg)*)))
    };
}

/// `ensure!`: [`bail!`] unless the condition holds.
macro_rules! ensure {
    ($cond:expr, $($arg:tt)*) => {
        if !$cond {
            $crate::error::bail!($($arg)*);
        }
    };
}

/// `msg!`: a [`LabError::Msg`] with the formatted message.
macro_rules! msg {
    ($($arg:tt)*) => {
        $crate::error::LabError::Msg(format!($($arg)*))
    };
}

pub(crate) use {bail, ensure, msg};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_input_anywhere_in_the_chain_exits_2_and_the_chain_reads_whole() {
        let inner: Result<()> = Err(usage("--seeds must be at least 1"));
        let outer = inner.context("experiment file e.toml").unwrap_err();
        assert_eq!(alfd_harness::exit_code(&outer), 2);
        assert_eq!(
            alfd_harness::describe(&outer),
            "experiment file e.toml: --seeds must be at least 1"
        );
        let io = std::io::Error::other("disk on fire");
        let failed: Result<()> = Err(io).context("cannot write summary.md");
        let e = failed.unwrap_err();
        assert_eq!(alfd_harness::exit_code(&e), 1);
        assert_eq!(
            alfd_harness::describe(&e),
            "cannot write summary.md: disk on fire"
        );
        assert_eq!(
            None::<u8>
                .context("`config` is missing")
                .unwrap_err()
                .to_string(),
            "`config` is missing"
        );
    }
}
