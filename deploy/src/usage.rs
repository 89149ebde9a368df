//! Errors that are the user's to fix (bad config, map, file, name): the CLI exits with code 2 on
//! them, and 1 on anything else.

/// A problem with what the user gave us, already phrased for them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// Shorthand: `Err(usage(format!(..)))?`.
pub fn usage(msg: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(UsageError(msg.into()))
}

/// The exit code for an error: 2 when the user's input is at fault.
pub fn exit_code(err: &anyhow::Error) -> i32 {
    for cause in err.chain() {
        if cause.is::<UsageError>()
            || cause.is::<alfd_common::config::ConfigError>()
            || cause.is::<alfd_common::env::cliffwalk::MapError>()
            || cause.is::<alfd_common::env::cliffwalk::CliffWalkError>()
            || cause.is::<alfd_expert::registry::RegistryError>()
        {
            return 2;
        }
    }
    1
}

/// Whether `err` is the user's to fix (exit code 2).
#[cfg(test)]
pub fn is_usage_error(err: &anyhow::Error) -> bool {
    exit_code(err) == 2
}
