//! `alfd demos export RUN_DIR --out DATASET_DIR`: a run's episodes, every transition with the
//! demonstrated ones marked, as a Minari dataset (`arrow` data format) that
//! `minari.load_dataset` reads. The run must have recorded its transitions
//! (`alfd local --transitions`); `demos.jsonl` marks the demonstrated steps.

use std::path::PathBuf;

use alfd_lab::{minari, transitions};

use crate::usage::usage;

#[derive(Debug, clap::Args)]
pub struct DemosArgs {
    #[command(subcommand)]
    pub command: DemosCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum DemosCommand {
    /// Write a run's episodes as a Minari dataset (every transition; the expert's steps marked
    /// in `infos["demonstrated"]`).
    Export(ExportArgs),
}

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The run directory (`alfd local --transitions --out RUN_DIR`).
    pub run_dir: PathBuf,
    /// The dataset's directory (it must not hold a dataset). With `--out ROOT/NAMESPACE/NAME-vN`
    /// and `MINARI_DATASETS_PATH=ROOT`, `minari.load_dataset("NAMESPACE/NAME-vN")` finds it.
    #[arg(long)]
    pub out: PathBuf,
    /// The dataset's id, `NAMESPACE/NAME-vN`; default: the last two parts of `--out`.
    #[arg(long)]
    pub id: Option<String>,
}

pub fn run(args: DemosArgs) -> anyhow::Result<()> {
    match args.command {
        DemosCommand::Export(a) => export(a),
    }
}

fn export(args: ExportArgs) -> anyhow::Result<()> {
    let id = match args.id {
        Some(id) => id,
        None => default_id(&args.out)?,
    };
    let (header, episodes) = transitions::read(&args.run_dir)?;
    let demos_path = args.run_dir.join("demos.jsonl");
    let demos = alfd_demonstrators::demo_log::read(&demos_path)
        .map_err(|e| usage(format!("{}: {e}", demos_path.display())))?;
    let ds = transitions::dataset(&header, episodes, &demos, &id);
    minari::write(&args.out, &ds)?;
    let marked: usize = ds
        .episodes
        .iter()
        .filter_map(|e| e.demonstrated.as_ref())
        .map(|m| m.iter().filter(|&&d| d).count())
        .sum();
    eprintln!(
        "wrote Minari dataset {id} to {}: {} episodes, {} steps, {marked} demonstrated",
        args.out.display(),
        ds.episodes.len(),
        ds.total_steps()
    );
    Ok(())
}

/// `NAMESPACE/NAME-vN` from the last two parts of `out`.
fn default_id(out: &std::path::Path) -> anyhow::Result<String> {
    let parts: Vec<String> = out
        .components()
        .rev()
        .take(2)
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let id = parts.iter().rev().cloned().collect::<Vec<_>>().join("/");
    if minari::valid_id(&id) {
        Ok(id)
    } else {
        Err(usage(format!(
            "--out {}: its last two parts are not a Minari id NAMESPACE/NAME-vN; name the \
             dataset with --id",
            out.display()
        )))
    }
}
