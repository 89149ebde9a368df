//! The harness's errors, and the exit codes: every binary exits with 2 when the user gave it
//! something it cannot use (a config, a file, a flag, a name), and 1 on anything else.

use std::error::Error;

use alfd_wire::WireError;

use crate::session::SessionError;

/// Bad input (a config, a file, a flag, a name), already phrased for the user: every binary
/// exits with code 2 on it (see [`exit_code`]), and 1 on anything else.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// Why a harness operation failed.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    #[error(transparent)]
    BadInput(#[from] BadInput),
    #[error(transparent)]
    Wire(#[from] WireError),
    #[error(transparent)]
    Session(#[from] SessionError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// `what` failed; the source says why.
    #[error("{what}")]
    Failed {
        what: String,
        #[source]
        source: Box<dyn Error + Send + Sync>,
    },
    /// A child process (the Python adapter) failed; its own words.
    #[error("{0}")]
    Child(String),
    /// A process cannot go on, for the reason the message gives (no weights from the learner in
    /// time, an external expert that stopped).
    #[error("{0}")]
    Run(String),
    #[error(transparent)]
    Loop(#[from] alfd_common::environment_loop::LoopError),
}

impl HarnessError {
    /// Whether the user's input caused it (exit code 2).
    pub fn is_bad_input(&self) -> bool {
        matches!(self, Self::BadInput(_))
    }
}

impl AsRef<dyn Error + 'static> for HarnessError {
    fn as_ref(&self) -> &(dyn Error + 'static) {
        self
    }
}

/// The harness's `Result`.
pub type Result<T, E = HarnessError> = std::result::Result<T, E>;

/// `.what(|| ..)`: names what failed, keeping the error as its source (anyhow's `with_context`
/// for typed errors: [`HarnessError::Failed`], which the launcher's errors carry too).
pub trait What<T> {
    fn what(self, what: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Error + Send + Sync + 'static> What<T> for std::result::Result<T, E> {
    fn what(self, what: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| HarnessError::Failed {
            what: what(),
            source: Box::new(e),
        })
    }
}

/// The exit code of every binary for an error: 2 when the user's input caused it ([`BadInput`],
/// or the core's errors about a config, a map or CliffWalk's parameters anywhere in its chain),
/// 1 otherwise.
pub fn exit_code<E: AsRef<dyn Error + 'static> + ?Sized>(err: &E) -> i32 {
    let user_fault = |e: &(dyn Error + 'static)| {
        e.is::<BadInput>()
            || e.downcast_ref::<HarnessError>()
                .is_some_and(HarnessError::is_bad_input)
            || e.is::<alfd_common::config::ConfigError>()
            || e.is::<alfd_common::env::cliffwalk::MapError>()
            || e.is::<alfd_common::env::cliffwalk::CliffWalkError>()
    };
    if chain(err.as_ref()).any(user_fault) {
        2
    } else {
        1
    }
}

/// An error and its sources, outermost first.
pub fn chain<'e>(
    err: &'e (dyn Error + 'static),
) -> impl Iterator<Item = &'e (dyn Error + 'static)> {
    std::iter::successors(Some(err), |&e| e.source())
}

/// An error with its sources, as `outer: inner: innermost` (anyhow's `{:#}`), a message said
/// once where a wrapper repeats its source's (an enum variant that shows the error it holds).
pub fn describe(err: &(dyn Error + 'static)) -> String {
    let mut parts: Vec<String> = Vec::new();
    for e in chain(err) {
        let text = e.to_string();
        if parts.last() != Some(&text) {
            parts.push(text);
        }
    }
    parts.join(": ")
}
