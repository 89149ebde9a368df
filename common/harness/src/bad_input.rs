//! Bad input and the exit codes: every binary exits with 2 when the user gave it something it
//! cannot use (a config, a file, a flag, a name), and 1 on anything else.

/// Bad input (a config, a file, a flag, a name), already phrased for the user: every binary
/// exits with code 2 on it (see [`exit_code`]), and 1 on anything else.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// Shorthand for `anyhow::Error::new(BadInput(msg))`: `Err(bad_input(format!(..)))?`.
pub fn bad_input(msg: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(BadInput(msg.into()))
}

/// The exit code of every binary for an error: 2 when the user's input caused it ([`BadInput`],
/// or the core's errors about a config, a map or CliffWalk's parameters anywhere in its chain),
/// 1 otherwise.
pub fn exit_code(err: &anyhow::Error) -> i32 {
    let user_fault = |e: &(dyn std::error::Error + 'static)| {
        e.is::<BadInput>()
            || e.is::<alfd_common::config::ConfigError>()
            || e.is::<alfd_common::env::cliffwalk::MapError>()
            || e.is::<alfd_common::env::cliffwalk::CliffWalkError>()
    };
    if err.chain().any(user_fault) {
        2
    } else {
        1
    }
}
