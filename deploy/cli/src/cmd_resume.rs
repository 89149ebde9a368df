//! `alfd resume RUN_DIR`: continues a stopped or crashed run to its configured end.
//! - An `alfd local --checkpoint-every N` run, from its `checkpoint.bin`. The episodes after the
//!   checkpoint are played again (the rows the stopped run wrote after it are replaced), so
//!   `episodes.csv` and `demos.jsonl` come out as the uninterrupted run's, to the byte.
//! - An `alfd run` (multi-process) run, with a new launcher: the learner from its
//!   `learner.ckpt`, the expert from `demos.jsonl` (budget and demonstrations carry over), each
//!   actor from its `actor-<id>.ckpt` (ε position, divergence queue, generators, environment,
//!   what it knew of the expert), `episodes.csv` appended to (numbering goes on; no row is
//!   repeated). With one actor in lockstep (window 1) the learner's checkpoint pairs with one of
//!   the actor's (both are written at the same episode end): the rows and demonstrations after
//!   it are dropped and played again, and the run is the uninterrupted one to the byte.
//!   Otherwise what the learner learned after its last checkpoint is lost, and the actors go on
//!   from their own newest states.

use std::path::PathBuf;

use crate::checkpoint_file;
use crate::cmd_local::{finish, run_pieces, Pieces, Resumable};
use crate::setup;
use crate::usage::usage;
use alfd_harness::run_dir;
use alfd_lab::report::Output;

#[derive(Debug, clap::Args)]
pub struct ResumeArgs {
    /// The run directory of the run to continue.
    pub run_dir: PathBuf,
    /// Print no progress and no summary at the end.
    #[arg(long)]
    pub quiet: bool,
    /// Print only the machine-readable line: the run's summary as JSON on stdout (printed also
    /// without this flag when stdout is not a terminal).
    #[arg(long)]
    pub json: bool,
    /// Testing: stop (as a crash would, without the final files) after this many episodes.
    #[arg(long, hide = true, value_name = "N")]
    pub stop_after_episodes: Option<u32>,
}

impl ResumeArgs {
    fn output(&self) -> Output {
        Output {
            json: self.json,
            quiet: self.quiet,
        }
    }
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
    if dir.join("summary.json").exists() && !interrupted(dir) {
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
    if cfg.env.name.is_remote() {
        // Say so rather than pretend: the environment's generator and state are in Python.
        return Err(usage(format!(
            "the run in {} plays a gymnasium environment, whose state lives in its Python \
             adapter: checkpointing it is not supported, so the run cannot be resumed",
            dir.display()
        )));
    }
    if dir.join("run.json").is_file() {
        return resume_multi_process(&args, cfg, &config_toml);
    }
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
    let output = args.output();
    let transitions = dir.join(alfd_lab::transitions::FILE).is_file();
    let summary = run_pieces(&cfg, pieces, dir, output.progress(), resumable, transitions)?;
    finish(&cfg, dir, summary, output)
}

/// Continues an `alfd run` run in `args.run_dir` (its lock is held by the caller).
fn resume_multi_process(
    args: &ResumeArgs,
    cfg: alfd_common::config::ExperimentConfig,
    config_toml: &str,
) -> anyhow::Result<()> {
    let dir = &args.run_dir;
    let info = alfd_launcher::read_run_info(dir).map_err(|e| usage(alfd_harness::describe(&e)))?;
    // The processes of the stopped launch may still be saving (a launcher killed a moment ago):
    // wait for them to leave, then for the files they leave to go.
    let alive = alfd_wire::wait_for_run_end(&info.run_id, std::time::Duration::from_secs(30))
        .unwrap_or_default();
    if !alive.is_empty() {
        return Err(usage(format!(
            "processes of run {} are still alive ({}): stop them before resuming",
            info.run_id,
            alive.join(", ")
        )));
    }
    if alfd_wire::is_launcher_run_id(&info.run_id) {
        if let Err(e) = alfd_wire::clean_run(&info.run_id) {
            tracing::warn!("cannot remove what run {} left: {e}", info.run_id);
        }
    }
    // The learner must be able to continue: a checkpoint that cannot be trusted is refused now.
    let learner = match alfd_learner::checkpoint::load(dir, config_toml) {
        Ok(Some(c)) => c,
        Ok(None) => {
            return Err(usage(format!(
                "{} has no learner.ckpt: the run's learner never checkpointed, so there is \
                 nothing to continue from",
                dir.display()
            )))
        }
        Err(e) => return Err(usage(alfd_harness::describe(&e))),
    };
    let runtime_path = dir.join(alfd_harness::RUNTIME_FILE);
    let runtime = std::fs::read_to_string(&runtime_path)
        .map_err(|e| usage(format!("cannot read {}: {e}", runtime_path.display())))
        .and_then(|t| {
            alfd_harness::RuntimeConfig::from_toml(&t)
                .map_err(|e| usage(format!("in {}: {e}", runtime_path.display())))
        })?;
    let restore_actors = actor_states(dir, config_toml, info.actors, &runtime, learner.env_steps)?;
    let plan = alfd_launcher::Plan {
        cfg,
        actors: info.actors,
        run_dir: dir.clone(),
        run_id: alfd_launcher::new_run_id(),
        runtime,
        max_restarts: info.max_restarts,
        progress: args.output().progress(),
        pin: false,
        bin_dir: alfd_launcher::bin_dir()?,
        resume: true,
        launches: info.launches.saturating_add(1),
        earlier_run_ids: [info.earlier_run_ids.clone(), vec![info.run_id.clone()]].concat(),
        restore_actors,
        listen: None,
    };
    tracing::info!(
        previous_run_id = %info.run_id,
        run_id = %plan.run_id,
        launches = plan.launches,
        "resuming a multi-process run"
    );
    crate::cmd_run::finish(&plan, args.output())
}

/// The state each actor continues from (see the module doc); in lockstep with one actor, when its
/// checkpoint pairs with the learner's, the run's files are cut back to that pair.
fn actor_states(
    dir: &std::path::Path,
    config_toml: &str,
    actors: usize,
    runtime: &alfd_harness::RuntimeConfig,
    learner_step: u64,
) -> anyhow::Result<Vec<Option<u64>>> {
    let mut files = Vec::with_capacity(actors);
    for id in 0..actors as u16 {
        files.push(
            alfd_actor::checkpoint::load(dir, id, config_toml)
                .map_err(|e| usage(alfd_harness::describe(&e)))?,
        );
    }
    if let [Some(file)] = &files[..] {
        if runtime.window == 1 {
            if let Some(c) = file.at(learner_step) {
                let rows = c.progress.episodes as usize;
                let demos = c.expert.demos as usize;
                if cut_lines(&dir.join("episodes.csv"), 1 + rows)?
                    && cut_lines(&dir.join("demos.jsonl"), demos)?
                {
                    tracing::info!(
                        step = learner_step,
                        episodes = rows,
                        demos,
                        "the learner's and the actor's checkpoints pair up: continuing from there"
                    );
                    return Ok(vec![Some(c.global_step)]);
                }
            }
            tracing::warn!(
                step = learner_step,
                "the actor's checkpoint does not pair with the learner's: the run goes on, \
                 not as the uninterrupted run"
            );
        }
    }
    Ok(files
        .iter()
        .map(|f| f.as_ref().and_then(|f| f.newest()).map(|c| c.global_step))
        .collect())
}

/// Keeps the first `lines` lines of the file at `path` (written whole); `false` (and the file as
/// it is) if it has fewer.
fn cut_lines(path: &std::path::Path, lines: usize) -> anyhow::Result<bool> {
    let text = match std::fs::read(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(lines == 0),
        Err(e) => return Err(usage(format!("cannot read {}: {e}", path.display()))),
    };
    let ends: Vec<usize> = text
        .iter()
        .enumerate()
        .filter(|(_, &b)| b == b'\n')
        .map(|(i, _)| i + 1)
        .collect();
    let keep = match lines {
        0 => 0,
        n => match ends.get(n - 1) {
            Some(&end) => end,
            None => return Ok(false),
        },
    };
    if keep < text.len() {
        // Waiting out a full disk: a resume must not fail on a disk filled for a moment.
        alfd_harness::write_atomically_patiently(
            path,
            &text[..keep],
            alfd_harness::DISK_FULL_PATIENCE,
        )?;
    }
    Ok(true)
}

/// Whether the run in `dir` was stopped with Ctrl-C (its `summary.json` says so): such a run is
/// resumed like a crashed one.
fn interrupted(dir: &std::path::Path) -> bool {
    std::fs::read_to_string(dir.join("summary.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<alfd_common::record::RunSummary>(&t).ok())
        .and_then(|s| s.runtime)
        .is_some_and(|r| r.interrupted)
}
