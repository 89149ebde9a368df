//! The launcher's errors.

use std::error::Error;

/// Why a launch (or reading a run directory) failed.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    #[error(transparent)]
    Harness(#[from] alfd_harness::HarnessError),
    #[error(transparent)]
    Wire(#[from] alfd_wire::WireError),
    #[error(transparent)]
    Bridge(#[from] alfd_bridge::BridgeError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// `what` failed; the source says why.
    #[error("{what}")]
    Failed {
        what: String,
        #[source]
        source: Box<dyn Error + Send + Sync>,
    },
    /// The run went wrong in a way the message says (a child that keeps failing, episodes
    /// missing at the end, a run directory that is not one).
    #[error("{0}")]
    Run(String),
}

/// The launcher's `Result`.
pub type Result<T, E = LaunchError> = std::result::Result<T, E>;

/// `.what(|| ..)`: names what failed, keeping the error as its source.
pub(crate) trait What<T> {
    fn what(self, what: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Error + Send + Sync + 'static> What<T> for std::result::Result<T, E> {
    fn what(self, what: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| LaunchError::Failed {
            what: what(),
            source: Box::new(e),
        })
    }
}

impl<T> What<T> for Option<T> {
    fn what(self, what: impl FnOnce() -> String) -> Result<T> {
        self.ok_or_else(|| LaunchError::Run(what()))
    }
}

/// `bail!`: returns a [`LaunchError::Run`] with the formatted message.
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::error::LaunchError::Run(format!($($arg)*)))
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

pub(crate) use {bail, ensure};
