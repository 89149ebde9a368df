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

/// `alfd scaling`: writes the scaling table, CSV and plots, and prints the table.
pub fn scaling(args: alfd_lab::sweep::scaling::ScalingArgs) -> anyhow::Result<()> {
    let md = alfd_lab::sweep::scaling::run(&args)?;
    print!("{md}");
    Ok(())
}
