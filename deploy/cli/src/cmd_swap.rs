//! `alfd swap-expert` and `alfd expert add|remove`: a live run's experts changed, make before
//! break. The command writes a request into the run directory; the launcher's expert lifecycle
//! starts the new expert process, makes it the answering one once it is up, and writes the
//! response this command waits for.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use alfd_common::config::{ExperimentConfig, PanelEntry, RosterChange};
use alfd_harness::run_dir;
use alfd_launcher::{self as launcher, SwapRequest, SwapResponse, SWAP_REQUEST, SWAP_RESPONSE};

use crate::setup;
use crate::usage::usage;

#[derive(Debug, clap::Args)]
pub struct SwapArgs {
    /// The run directory of a live run.
    #[arg(long)]
    pub run: PathBuf,
    /// The new demonstrator, by name (`alfd expert list`); names joined by `+` host several.
    #[arg(long)]
    pub expert: String,
    /// Seconds to wait for the swap to complete.
    #[arg(long, default_value_t = 90)]
    pub timeout: u64,
}

/// Asks the launcher of a live run to replace its expert, and waits for the outcome.
pub fn swap(args: SwapArgs) -> anyhow::Result<()> {
    // The new expert must exist for the run's environment. In a run with several experts, any
    // name (or names joined by `+`) replaces them, each answer still counted at its cost.
    let cfg = run_config(&args.run)?;
    let added = alfd_demonstrators::added::read(&args.run)?;
    let cfg = match args.expert.as_str() {
        alfd_harness::HUMAN_EXPERT => cfg.with_one_expert(&args.expert),
        _ => cfg.with_roster(&args.expert, &added),
    };
    setup::check_demonstrator(&cfg)?;
    ask_launcher(&args.run, args.expert, None, args.timeout)
}

/// `alfd expert add`: `entry` joins the live run's experts.
pub fn add(run: &Path, entry: PanelEntry, timeout: u64) -> anyhow::Result<()> {
    if !(entry.cost.is_finite() && entry.cost > 0.0) {
        return Err(usage(format!("--cost {} must be > 0", entry.cost)));
    }
    if entry.name == alfd_harness::HUMAN_EXPERT {
        return Err(usage(
            "a person joins several experts in the run's config (`[[experts]]`), not live: the \
             actors give every query the person's time only then",
        ));
    }
    let mut cfg = run_config(run)?;
    cfg.experts = vec![entry.clone()];
    setup::check_demonstrator(&cfg)?;
    // Written before the request: the expert process the swap starts reads what it costs.
    alfd_demonstrators::added::append(run, &entry).map_err(|e| {
        usage(format!(
            "cannot write {}: {e}",
            run.join(alfd_demonstrators::added::ADDED_EXPERTS).display()
        ))
    })?;
    ask_launcher(run, entry.name, Some(RosterChange::Add), timeout)
}

/// `alfd expert remove`: `name` leaves the live run's experts.
pub fn remove(run: &Path, name: String, timeout: u64) -> anyhow::Result<()> {
    run_config(run)?;
    ask_launcher(run, name, Some(RosterChange::Remove), timeout)
}

/// The config of the run in `run`.
fn run_config(run: &Path) -> anyhow::Result<ExperimentConfig> {
    setup::load_config(&run.join("config.toml"), &[])
}

/// Writes the request for `expert` (with `change`: added to or removed from the run's experts)
/// and waits for the launcher's response, which it prints; an error if the swap failed.
fn ask_launcher(
    run: &Path,
    expert: String,
    change: Option<RosterChange>,
    timeout: u64,
) -> anyhow::Result<()> {
    let info = launcher::read_run_info(run).map_err(|e| usage(alfd_harness::describe(&e)))?;
    // One swap at a time: a second one is refused at once, not queued.
    let _swap_lock = run_dir::lock_swaps(run)?;
    if !PathBuf::from(format!("/proc/{}", info.launcher_pid)).exists() {
        return Err(usage(format!(
            "run {} is not live (its launcher, pid {}, has exited)",
            info.run_id, info.launcher_pid
        )));
    }
    let id = format!("{}-{}", std::process::id(), launcher::new_run_id());
    let request = SwapRequest {
        id: id.clone(),
        expert,
        change,
    };
    alfd_lab::output::write(
        run,
        SWAP_REQUEST,
        serde_json::to_string(&request)?.as_bytes(),
    )?;
    let start = Instant::now();
    loop {
        if let Ok(text) = std::fs::read_to_string(run.join(SWAP_RESPONSE)) {
            if let Ok(r) = serde_json::from_str::<SwapResponse>(&text) {
                if r.id == id {
                    println!("{}", serde_json::to_string(&r)?);
                    anyhow::ensure!(r.ok, "expert swap failed: {}", r.message);
                    return Ok(());
                }
            }
        }
        anyhow::ensure!(
            start.elapsed() < Duration::from_secs(timeout),
            "no answer from the launcher of run {} within {} s",
            info.run_id,
            timeout
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}
