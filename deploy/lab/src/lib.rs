//! The experiment tooling of alfd, apart from the command line: sweeps of many seeds over the
//! methods of an experiment file (`sweep`: running them, sharding, statistics with bootstrap
//! intervals, summaries, plots, the query-rule study's tables against the budget), how a run
//! ends and reports (`report`: the summary, the learning curve), files and PNGs (`output`), the
//! demonstration model alone as a policy (`policy`), the Q-value check of a run directory
//! (`q_values`) and Minari datasets read and written (`minari`).
//!
//! The lab trains nothing itself: a sweep's runs are trained by the [`Trainer`] its caller passes
//! in (the `alfd` binary's single-process runner), so this crate holds no copy of a run.

pub mod error;
pub mod minari;
pub mod output;
pub mod policy;
pub mod q_values;
pub mod report;
pub mod sweep;
pub mod transitions;

pub use error::{LabError, Result};

use std::error::Error;
use std::path::Path;

use alfd_common::config::ExperimentConfig;
use alfd_common::record::RunSummary;

/// An error from the caller's side of a [`Trainer`].
pub type BoxError = Box<dyn Error + Send + Sync>;

/// How a sweep trains its runs and checks its methods: the single-process runner of the `alfd`
/// binary, passed in.
pub trait Trainer: Sync {
    /// Whether a method's config can run (its demonstrator exists); the reason if not.
    fn check(&self, cfg: &ExperimentConfig) -> std::result::Result<(), BoxError>;
    /// Trains the run of `cfg` into `dir`, as `alfd local` does (the directory is the sweep's
    /// and locked by it); the run's summary.
    fn train(
        &self,
        cfg: &ExperimentConfig,
        dir: &Path,
    ) -> std::result::Result<RunSummary, BoxError>;
}

/// What the lab's own tests pass for a [`Trainer`].
#[cfg(test)]
pub(crate) mod testing {
    use super::*;

    /// Takes every demonstrator name; trains nothing.
    pub struct AnyDemonstrator;

    impl Trainer for AnyDemonstrator {
        fn check(&self, _: &ExperimentConfig) -> std::result::Result<(), BoxError> {
            Ok(())
        }

        fn train(
            &self,
            _: &ExperimentConfig,
            _: &Path,
        ) -> std::result::Result<RunSummary, BoxError> {
            Err("the lab's unit tests train nothing".into())
        }
    }
}
