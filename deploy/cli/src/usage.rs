//! Errors that are the user's to fix (bad config, map, file, name): every binary exits with code
//! 2 on them and 1 on anything else, through the harness's one mechanism ([`alfd_harness::BadInput`]
//! and [`alfd_harness::exit_code`]).

pub use alfd_harness::exit_code;

/// Bad input as an `anyhow::Error`: `Err(usage(format!(..)))?`.
pub fn usage(msg: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(alfd_harness::BadInput(msg.into()))
}

/// A command or flag of runs across hosts in a build without the `hosts` feature (as
/// `deploy/run.sh` builds the main job): exit 2, saying how to build it.
#[cfg(not(feature = "hosts"))]
pub fn without_hosts(what: &str) -> anyhow::Error {
    usage(format!(
        "{what} runs across hosts, and this alfd was built without them (the `hosts` \
         feature; deploy/run.sh builds the main job so): build every feature with \
         `cargo build --release --workspace`"
    ))
}

/// Whether `err` is the user's to fix (exit code 2).
#[cfg(test)]
pub fn is_usage_error(err: &anyhow::Error) -> bool {
    exit_code(err) == 2
}
