//! `alfd join`: actors on this host for a run on another (`alfd run --listen`), and/or the run's
//! expert (`--expert NAME`). It asks the run for actor ids, starts a mirror of the run's
//! services here (see `alfd_bridge`), and the actor processes, unchanged, against the mirror;
//! with `--expert` also an expert host (a second local copy of the run's services), where it
//! starts `alfd-expert` when the run's launcher says so (a make-before-break swap to this
//! host's expert) and reports its exit. It ends when its processes have stopped: at the run's
//! end, on Ctrl-C, when this host's expert was replaced, or when the link is lost. An actor that
//! crashes is restarted with a new incarnation the run gives it (at most the run's
//! `--max-restarts` times), as the launcher restarts its own.

use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct JoinArgs {
    /// The learner's host: the endpoint its `alfd run --listen` listens on.
    #[arg(long, value_name = "quic/ADDR:PORT")]
    pub connect: String,
    #[command(flatten)]
    pub link: crate::link_flags::LinkFlags,
    /// Actor processes to start on this host (0..=16; the run gives them free actor ids).
    /// Default 1, or 0 with `--expert`.
    #[arg(long)]
    pub actors: Option<usize>,
    /// Serve the run's expert from this host: the demonstrator, by name (`alfd expert list`,
    /// or `python:MODULE:FUNCTION`). The run swaps to it, make before break.
    #[arg(long, value_name = "NAME")]
    pub expert: Option<String>,
    /// Where this host keeps its actors' logs and checkpoints; default
    /// `runs/join-<run id>-<pid>`.
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// Seconds to wait for the run to answer.
    #[arg(long, default_value_t = 20)]
    pub wait_s: u64,
}

#[cfg(feature = "hosts")]
mod host;
#[cfg(feature = "hosts")]
pub use host::run;

/// `alfd join` in a build without the `hosts` feature: exit 2, saying how to build it.
#[cfg(not(feature = "hosts"))]
pub fn run(args: JoinArgs) -> anyhow::Result<()> {
    let what = format!("alfd join --connect {}", args.connect);
    Err(crate::usage::without_hosts(&what))
}
