//! `alfd sweep`: the lab's sweeps (`alfd_lab::sweep`), whose runs this binary's single-process
//! runner trains.

use std::path::Path;

use alfd_common::config::ExperimentConfig;
use alfd_common::record::RunSummary;
use alfd_lab::{BoxError, Trainer};

pub use alfd_lab::sweep::SweepArgs;

use crate::{cmd_local, setup};

/// A sweep's runs, trained as `alfd local` trains one.
struct Local;

impl Trainer for Local {
    fn check(&self, cfg: &ExperimentConfig) -> Result<(), BoxError> {
        Ok(setup::check_demonstrator(cfg)?)
    }

    fn train(&self, cfg: &ExperimentConfig, dir: &Path) -> Result<RunSummary, BoxError> {
        Ok(cmd_local::run_config(cfg, dir, false)?)
    }
}

pub fn run(args: SweepArgs) -> anyhow::Result<()> {
    Ok(alfd_lab::sweep::run(args, &Local)?)
}
