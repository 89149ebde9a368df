//! `alfd resume RUN_DIR`: continues a stopped or crashed `alfd local --checkpoint-every N` run
//! from its `checkpoint.bin` to its configured end. The episodes after the checkpoint are played
//! again (the rows the stopped run wrote after it are replaced), so `episodes.csv` and
//! `demos.jsonl` come out as the uninterrupted run's, to the byte.

use std::path::PathBuf;

use crate::checkpoint_file;
use crate::cmd_local::{finish, run_pieces, Pieces, Resumable};
use crate::usage::usage;
use crate::{run_dir, setup};

#[derive(Debug, clap::Args)]
pub struct ResumeArgs {
    /// The run directory of the run to continue.
    pub run_dir: PathBuf,
    /// Print no progress.
    #[arg(long)]
    pub quiet: bool,
    /// Testing: stop (as a crash would, without the final files) after this many episodes.
    #[arg(long, hide = true, value_name = "N")]
    pub stop_after_episodes: Option<u32>,
}

pub fn run(args: ResumeArgs) -> anyhow::Result<()> {
    let dir = &args.run_dir;
    let config_path = dir.join("config.toml");
    if !config_path.is_file() {
        return Err(usage(format!(
            "{} holds no run (no config.toml) to resume",
            dir.display()
        )));
    }
    // The run's own lock: refused while the run (or another resume) is alive.
    let _lock = run_dir::lock(dir)?;
    if dir.join("summary.json").exists() {
        return Err(usage(format!(
            "the run in {} is finished (it has summary.json): there is nothing to resume",
            dir.display()
        )));
    }
    let config_toml = std::fs::read_to_string(&config_path)
        .map_err(|e| usage(format!("cannot read {}: {e}", config_path.display())))?;
    let cfg = setup::parse_config(
        &config_toml,
        &[],
        &format!("config {}", config_path.display()),
    )?;
    let file = checkpoint_file::load(dir, &config_toml)?;
    let pieces = Pieces::of(&cfg)?;
    tracing::info!(
        episodes = file.state.progress().episodes,
        "resuming from the checkpoint"
    );
    let resumable = Resumable {
        config_toml,
        every: Some(file.every),
        from: Some(file),
        stop_after: args.stop_after_episodes,
    };
    finish(run_pieces(&cfg, pieces, dir, !args.quiet, resumable)?)
}
