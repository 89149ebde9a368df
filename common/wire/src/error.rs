//! What can go wrong on the wire ([`WireError`]), and the helper that turns an iceoryx2 error
//! into one.

use std::fmt;

/// What can go wrong on the wire.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    #[error(
        "schema version mismatch on `{service}`: this process speaks schema version {ours}, \
         but {sender} sent schema version {theirs}; rebuild all processes from the same sources"
    )]
    SchemaMismatch {
        service: &'static str,
        ours: u32,
        theirs: u32,
        sender: String,
    },
    #[error("invalid run id `{0}`: use 1 to 64 ASCII letters, digits, `-` or `_`")]
    InvalidRunId(String),
    #[error("{what} has {got} values, more than the wire carries ({max})")]
    TooLarge {
        what: &'static str,
        got: usize,
        max: usize,
    },
    #[error("{what}: {value} is out of range ({expected})")]
    OutOfRange {
        what: &'static str,
        value: u64,
        expected: &'static str,
    },
    #[error("no word from the launcher of this run within {waited_ms} ms (is the run id right, is the run alive?)")]
    NoLauncher { waited_ms: u64 },
    #[error("interrupted by a termination signal")]
    Interrupted,
    #[error("run `{run_id}` still has live processes: {nodes}")]
    RunAlive { run_id: String, nodes: String },
    #[error("`{service}` failed: {message}")]
    Remote { service: String, message: String },
    #[error(
        "no answer on `{service}` within {waited_ms} ms (is its adapter running? see its log)"
    )]
    NoAnswer { service: String, waited_ms: u64 },
    #[error("iceoryx2 failed to {op} `{service}`: {detail}")]
    Transport {
        op: &'static str,
        service: String,
        detail: String,
    },
}

/// The result of everything on the wire.
pub type Result<T, E = WireError> = std::result::Result<T, E>;

/// Turns an iceoryx2 error into [`WireError::Transport`], naming what was done (`op`) to which
/// `service`.
pub(crate) fn transport<E: fmt::Debug>(
    op: &'static str,
    service: impl Into<String>,
) -> impl FnOnce(E) -> WireError {
    let service = service.into();
    move |e| WireError::Transport {
        op,
        service,
        detail: format!("{e:?}"),
    }
}
