//! What can go wrong across hosts ([`BridgeError`]).

/// What can go wrong across hosts.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BridgeError {
    #[error(
        "schema version mismatch across hosts: this alfd speaks schema version {ours}, the other \
         host {theirs}; build alfd from the same sources on both hosts"
    )]
    SchemaMismatch { ours: u32, theirs: u32 },
    #[error("malformed frame from the other host: {0}")]
    Malformed(String),
    #[error(
        "invalid endpoint `{0}`: expected quic/HOST:PORT or tcp/HOST:PORT (for example \
         quic/192.168.1.10:7447 or tcp/0.0.0.0:7447)"
    )]
    InvalidEndpoint(String),
    /// Certificates: a file missing or of the wrong kind, or a security setting that does not
    /// fit the endpoint.
    #[error("{0}")]
    Tls(String),
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error(
        "no run answered at {endpoint} within {waited_ms} ms ({why}; is `alfd run --listen \
         {endpoint}` running, and are this host's certificates of its CA?)"
    )]
    NoRun {
        endpoint: String,
        waited_ms: u64,
        why: String,
    },
    #[error("the run refused to be joined: {0}")]
    Refused(String),
    #[error("{0}")]
    Demos(String),
    #[error(transparent)]
    Wire(#[from] alfd_wire::WireError),
}

impl BridgeError {
    /// Bad input from the user or the other host (exit code 2), not a failure of this host.
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Self::SchemaMismatch { .. }
                | Self::InvalidEndpoint(_)
                | Self::Refused(_)
                | Self::Tls(_)
        )
    }
}

pub(crate) fn zenoh_error(e: impl std::fmt::Display) -> BridgeError {
    BridgeError::Zenoh(e.to_string())
}

/// The result of everything across hosts.
pub type Result<T, E = BridgeError> = std::result::Result<T, E>;
