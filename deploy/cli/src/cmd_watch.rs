//! `alfd watch RUN_DIR` and `alfd run --watch`: a page on `127.0.0.1` that shows a run while it
//! learns. The page asks for `data` every second; the server reads the run directory each time:
//! `episodes.csv` (training returns, greedy evaluations, the episodes in which the expert acted,
//! demonstrations), the TensorBoard event files in `tb/` (each actor's throughput, the learner's
//! update rate and loss, with their wall-clock times), `config.toml` (the budget) and
//! `summary.json` (whether the run ended). Nothing is kept between requests, so a page opened on
//! a finished run shows it whole.
//!
//! The same rule as the human expert's page: every path lives under a secret token (128 random
//! bits), written to `RUN_DIR/watch-page.txt` readable by its owner only; any other request gets
//! 403.

use std::path::PathBuf;

// The page's server (axum), behind the `pages` feature; without it, serving says how to build it.
#[cfg(feature = "pages")]
mod page;
#[cfg(not(feature = "pages"))]
#[path = "cmd_watch/page_off.rs"]
mod page;
pub use page::serve;

#[derive(Debug, clap::Args)]
pub struct WatchArgs {
    /// The run directory (`alfd run --out`, `alfd local --out`), running or finished.
    pub run_dir: PathBuf,
    /// The port on 127.0.0.1 (0: a free one).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
}

/// `alfd watch`: serves the page until interrupted.
pub fn run(args: WatchArgs) -> anyhow::Result<()> {
    if !args.run_dir.is_dir() {
        return Err(crate::usage::usage(format!(
            "{} is not a directory (the run directory of `alfd run` or `alfd local`)",
            args.run_dir.display()
        )));
    }
    let page = serve(&args.run_dir, args.port)?;
    eprintln!("watch the run at {}  (Ctrl-C stops the page)", page.url());
    loop {
        std::thread::park();
    }
}
