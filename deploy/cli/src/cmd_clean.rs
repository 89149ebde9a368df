//! `alfd clean`: removes what dead runs left in iceoryx2's directories (`/dev/shm`,
//! `/tmp/iceoryx2`) — a run whose launcher was killed with SIGKILL, say — and never touches a
//! live run's files: a run with any live process is listed and left alone.

use alfd_wire::{self as wire, Cleaned};

#[derive(Debug, clap::Args)]
pub struct CleanArgs {
    /// Only list what would be removed.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(args: CleanArgs) -> anyhow::Result<()> {
    let runs = wire::runs_with_files();
    let (mut cleaned, mut files, mut live) = (0usize, 0usize, 0usize);
    for run_id in &runs {
        if args.dry_run {
            let mut alive = wire::alive_nodes(run_id)?;
            if let Some(pid) = wire::owner_alive(run_id) {
                alive.push(format!("its launcher, pid {pid}"));
            }
            if alive.is_empty() {
                let left = wire::leftover_files(run_id);
                println!("{run_id}: dead, {} files would be removed", left.len());
                files += left.len();
                cleaned += 1;
            } else {
                println!("{run_id}: live ({}), left alone", alive.join(", "));
                live += 1;
            }
            continue;
        }
        match wire::clean_run(run_id)? {
            Cleaned::Live(nodes) => {
                println!("{run_id}: live ({}), left alone", nodes.join(", "));
                live += 1;
            }
            Cleaned::Removed(removed) => {
                println!("{run_id}: dead, {} files removed", removed.len());
                files += removed.len();
                cleaned += 1;
            }
        }
    }
    let verb = if args.dry_run {
        "would remove"
    } else {
        "removed"
    };
    println!(
        "{} runs with iceoryx2 files: {cleaned} dead ({verb} {files} files), {live} live (left alone)",
        runs.len()
    );
    Ok(())
}
