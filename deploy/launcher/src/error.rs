//! The launcher's errors.

/// Why a launch (or reading a run directory) failed.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    /// Also what `.what(..)` (`alfd_harness::What`) names: `HarnessError::Failed`.
    #[error(transparent)]
    Harness(#[from] alfd_harness::HarnessError),
    #[error(transparent)]
    Wire(#[from] alfd_wire::WireError),
    #[cfg(feature = "hosts")]
    #[error(transparent)]
    Bridge(#[from] alfd_bridge::BridgeError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The run went wrong in a way the message says (a child that keeps failing, episodes
    /// missing at the end, a run directory that is not one).
    #[error("{0}")]
    Run(String),
}

/// The launcher's `Result`.
pub type Result<T, E = LaunchError> = std::result::Result<T, E>;

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
