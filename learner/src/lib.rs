//! The learner process of alfd: receives the actors' transitions, learns from each (the core's
//! [`NeuralLearner::learn`]: insert, then `U` updates), publishes versioned weights, and returns
//! credits to the actors (the pure [`CreditBook`]) so that none runs more than a window of steps
//! ahead.

pub mod checkpoint;
pub mod credit_book;

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use alfd_common::agent::NeuralLearner;
use alfd_common::checkpoint::Cadence;
use alfd_common::rng::{derive_seed, seeded};
use alfd_harness::{write_atomically, BadInput, ProcessArgs, Session, Setup};
use alfd_wire::{
    self as wire, process_state, progress_kind, ActorBells, Credits, Doorbell, Process, Progress,
    Role, Wake, WireError, MAX_ACTORS,
};
use tracing::{debug, info, warn};

use crate::checkpoint::LearnerCheckpoint;

pub use credit_book::{BatchShape, CreditBook, Queued};

/// `alfd-learner`: the learner process of a run (started by `alfd run`).
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "alfd-learner", version)]
pub struct Args {
    #[command(flatten)]
    pub process: ProcessArgs,
    /// Continue from `RUN_DIR/learner.ckpt` when there is one (a learner restarted in a live
    /// run, or a run resumed with `alfd resume`).
    #[arg(long)]
    pub restore: bool,
}

/// The name of the process's log file (without `.log`).
pub fn log_name(_args: &Args) -> String {
    "learner".to_owned()
}

/// How the learner's run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// The launcher said stop, or a termination signal.
    Stopped,
    /// The launcher is gone: the learner saved its state, and closes the run once the other
    /// processes have left.
    Orphaned,
}

/// Runs the learner until the launcher says stop or a termination signal arrives (or the launcher
/// is gone); checkpoints its whole state to `RUN_DIR/learner.ckpt` every `checkpoint_every`
/// updates and at the end, and saves the final weights to `RUN_DIR/weights.safetensors`.
pub fn run(args: &Args, schema: u32) -> anyhow::Result<()> {
    let setup = args.process.load()?;
    let run_dir = &args.process.run_dir;
    let config_toml = checkpoint::config_text(run_dir)?;
    let restored = if args.restore {
        checkpoint::load(run_dir, &config_toml)?
    } else {
        None
    };
    let end = {
        let wire = args
            .process
            .connect(Process::new(Role::Learner, 0), schema)?;
        serve(args, &setup, &config_toml, restored, &wire)?
    };
    if end == End::Orphaned {
        close_orphaned_run(&args.process.run_id);
    }
    Ok(())
}

/// The last process of a run whose launcher died: waits (up to 10 s) for the actors and the
/// expert to leave, then removes the run's iceoryx2 files, as the launcher would have.
fn close_orphaned_run(run_id: &str) {
    match wire::wait_for_run_end(run_id, Duration::from_secs(10)) {
        Ok(alive) if alive.is_empty() => {}
        Ok(alive) => {
            warn!(?alive, "processes of the run are still alive; its files are left (`alfd clean` removes them later)");
            return;
        }
        Err(e) => {
            warn!("cannot list the run's processes: {e}");
            return;
        }
    }
    match wire::close_run(run_id) {
        Ok(()) => info!("the launcher is gone; the run's iceoryx2 files were removed"),
        Err(e) => warn!("cannot close the run: {e} (`alfd clean` removes what is left)"),
    }
}

fn serve(
    args: &Args,
    setup: &Setup,
    config_toml: &str,
    restored: Option<LearnerCheckpoint>,
    wire: &wire::Wire,
) -> anyhow::Result<End> {
    let (cfg, runtime) = (&setup.config, &setup.runtime);
    let run_dir = &args.process.run_dir;
    let (obs_dim, num_actions) = setup.env_dims()?;
    let session = Session::join(wire, Doorbell::Learner, runtime.handshake_timeout())?;
    let rx = wire.transitions_receiver()?;
    let mut credits_tx = wire.credits_sender()?;
    let mut actors = ActorBells::new(wire);
    let mut progress = wire.progress_sender()?;

    let mut learner = NeuralLearner::new(
        &cfg.agent,
        obs_dim,
        num_actions,
        seeded(derive_seed(cfg.seed, "learner")),
    );
    let mut params = vec![0.0f32; learner.network().num_params()];
    let mut weights_tx = wire.weights_sender(params.len())?;
    let mut book = CreditBook::new(
        runtime.window,
        BatchShape {
            obs_dim,
            heads: cfg.agent.heads(),
            actions: num_actions,
        },
    );

    if let Some(ckpt) = &restored {
        learner
            .restore(&ckpt.learner)
            .map_err(|e| BadInput(format!("{}: {e}", checkpoint::path(run_dir).display())))?;
        book.restore_env_steps(ckpt.env_steps);
        info!(
            updates = learner.updates(),
            env_steps = ckpt.env_steps,
            "restored from the checkpoint"
        );
    }
    let started = Instant::now();
    let restored_step = restored.as_ref().map_or(0, |c| c.env_steps);
    let mut checkpoints = Checkpoints {
        cadence: Cadence::new(
            Cadence::steps_for_updates(runtime.checkpoint_every, cfg.agent.updates_per_step),
            restored_step,
        ),
        written: 0,
        time: Duration::ZERO,
        bytes: 0,
    };

    let publish_weights = |learner: &NeuralLearner,
                           params: &mut Vec<f32>,
                           tx: &mut wire::WeightsSender<'_>,
                           env_steps: u64|
     -> anyhow::Result<()> {
        learner.network().copy_params_into(params)?;
        tx.publish(learner.updates(), learner.updates(), env_steps, params)?;
        Ok(())
    };
    publish_weights(&learner, &mut params, &mut weights_tx, 0)?;
    credits_tx.send(book.credits(0))?;
    info!(
        params = params.len(),
        window = runtime.window,
        "learner running"
    );

    let mut status = Status::new(std::process::id());
    status.send(&mut progress, process_state::RUNNING, &book, &learner)?;
    let mut queue: VecDeque<Queued> = VecDeque::new();
    let mut published_version = 0u64;
    let mut credits_dirty = false;
    let mut learned_since_credits = 0u64;
    let mut since_check = 0u32;
    let (mut idle_waits, mut idle) = (0u64, Duration::ZERO);
    let mut first_step: Option<Instant> = None;
    let mut idle_running = Duration::ZERO;
    let mut publish_time = Duration::ZERO;
    let stop_reason;
    let mut end = End::Stopped;
    loop {
        // Take in whatever arrived.
        loop {
            match rx.receive() {
                Ok(Some(batch)) => {
                    book.accept(&batch, &mut queue);
                }
                Ok(None) => break,
                Err(e @ WireError::SchemaMismatch { .. }) => {
                    tracing::error!("{e}; batch dropped");
                }
                Err(e) => return Err(e.into()),
            }
        }
        if book.any_blocked() {
            // Its grant may already be there (it blocked on stale news): wake it at once.
            send_credits(&mut book, &mut credits_tx, &mut actors, learner.updates())?;
        }
        if let Some(q) = queue.pop_front() {
            first_step.get_or_insert_with(Instant::now);
            // Algorithm 1 lines 19-20, U times per step.
            if let Some(loss) = learner.learn(&q.transition) {
                status.loss = f64::from(loss);
            }
            book.learned(q.actor, q.incarnation);
            if learner.updates() >= published_version.saturating_add(runtime.weights_every) {
                let t = Instant::now();
                publish_weights(&learner, &mut params, &mut weights_tx, book.env_steps())?;
                publish_time += t.elapsed();
                published_version = learner.updates();
            }
            // At an actor's episode end, every `checkpoint_every` updates' worth of steps: in
            // lockstep with one actor, where that actor checkpoints too.
            if q.episode_end && checkpoints.cadence.episode_end(book.env_steps()) {
                checkpoints.write(run_dir, &learner, &book, config_toml)?;
            }
            credits_dirty = true;
            learned_since_credits += 1;
            // Credits go back every few steps (so an actor refills its batch while the learner
            // works through the rest of the queue) and at the end of every batch.
            if q.last_of_batch || learned_since_credits >= CREDITS_EVERY {
                send_credits(&mut book, &mut credits_tx, &mut actors, learner.updates())?;
                credits_dirty = false;
                learned_since_credits = 0;
            }
            since_check += 1;
            if since_check < 32 {
                continue;
            }
        }
        since_check = 0;
        if queue.is_empty() {
            if learner.updates() > published_version {
                publish_weights(&learner, &mut params, &mut weights_tx, book.env_steps())?;
                published_version = learner.updates();
            }
            if credits_dirty {
                send_credits(&mut book, &mut credits_tx, &mut actors, learner.updates())?;
                credits_dirty = false;
            }
        }
        if status.due() {
            status.send(&mut progress, process_state::RUNNING, &book, &learner)?;
        }
        // A process that subscribed since the last publication gets the history sample now.
        weights_tx.update_connections()?;
        credits_tx.update_connections()?;
        match session.should_stop() {
            Ok(Some(stop)) => {
                stop_reason = stop.0;
                break;
            }
            Ok(None) => {}
            Err(e) if e.orphaned() => {
                warn!("{e}: saving the learner's state and leaving");
                stop_reason = "the launcher is gone";
                end = End::Orphaned;
                break;
            }
            Err(e) => return Err(e.into()),
        }
        if queue.is_empty() {
            let idle_since = Instant::now();
            idle_waits += 1;
            let wake = session.wait_for(Duration::from_millis(100))?;
            idle += idle_since.elapsed();
            if first_step.is_some() {
                idle_running += idle_since.elapsed();
            }
            if idle_since.elapsed() > Duration::from_millis(5) {
                debug!(
                    waited_ms = idle_since.elapsed().as_millis() as u64,
                    ?wake,
                    env_steps = book.env_steps(),
                    "long idle wait"
                );
            }
            if wake == Wake::Signal {
                stop_reason = "termination signal";
                break;
            }
        }
    }
    info!(
        reason = stop_reason,
        updates = learner.updates(),
        env_steps = book.env_steps(),
        idle_waits,
        idle_s = idle.as_secs_f64(),
        idle_running_s = idle_running.as_secs_f64(),
        publish_s = publish_time.as_secs_f64(),
        updates_per_s = learner.updates() as f64
            / first_step.map_or(f64::INFINITY, |t| t.elapsed().as_secs_f64()),
        "learner stopping"
    );
    let path = run_dir.join("weights.safetensors");
    write_atomically(&path, &learner.network().to_safetensors_bytes())?;
    info!(path = %path.display(), "final weights saved");
    // One actor in lockstep: the last checkpoint pairs with the actor's at an episode end, from
    // which `alfd resume` continues as the uninterrupted run; a final one would not pair.
    if runtime.window == 1 && book.senders() <= 1 && (checkpoints.written > 0 || restored_step > 0)
    {
        info!("lockstep with one actor: the last checkpoint (at an episode end) is kept");
    } else {
        checkpoints.write(run_dir, &learner, &book, config_toml)?;
    }
    info!(
        checkpoints = checkpoints.written,
        bytes = checkpoints.bytes,
        write_s = checkpoints.time.as_secs_f64(),
        share_of_learner_time = checkpoints.time.as_secs_f64() / started.elapsed().as_secs_f64(),
        "learner state checkpointed"
    );
    status.send(&mut progress, process_state::EXITING, &book, &learner)?;
    debug!(
        lost = (0..MAX_ACTORS as u16).map(|a| book.lost(a)).sum::<u64>(),
        "lost steps"
    );
    Ok(end)
}

/// When the learner checkpoints, and what its checkpoints cost.
struct Checkpoints {
    cadence: Cadence,
    written: u64,
    time: Duration,
    bytes: usize,
}

impl Checkpoints {
    fn write(
        &mut self,
        run_dir: &std::path::Path,
        learner: &NeuralLearner,
        book: &CreditBook,
        config_toml: &str,
    ) -> anyhow::Result<()> {
        let t = Instant::now();
        let ckpt = LearnerCheckpoint {
            learner: learner.snapshot(),
            env_steps: book.env_steps(),
        };
        self.bytes = checkpoint::save(run_dir, &ckpt, config_toml)?;
        let took = t.elapsed();
        self.time += took;
        self.written += 1;
        debug!(
            updates = learner.updates(),
            env_steps = book.env_steps(),
            bytes = self.bytes,
            ms = took.as_secs_f64() * 1e3,
            "checkpoint written"
        );
        Ok(())
    }
}

/// Publishes the grants, and wakes the actors that wait for them.
fn send_credits(
    book: &mut CreditBook,
    tx: &mut wire::Sender<'_, Credits>,
    actors: &mut ActorBells<'_>,
    updates: u64,
) -> anyhow::Result<()> {
    let (credits, wake) = book.grant(updates);
    tx.send(credits)?;
    for id in wake {
        actors.ring(id)?;
    }
    Ok(())
}

/// Credits are returned after at most this many learned steps.
pub const CREDITS_EVERY: u64 = 8;

/// The learner's periodic status message.
struct Status {
    pid: u32,
    loss: f64,
    last: Instant,
}

impl Status {
    fn new(pid: u32) -> Self {
        Self {
            pid,
            loss: f64::NAN,
            last: Instant::now(),
        }
    }

    fn due(&self) -> bool {
        self.last.elapsed() >= Duration::from_millis(500)
    }

    fn send(
        &mut self,
        tx: &mut wire::Sender<'_, Progress>,
        state: u32,
        book: &CreditBook,
        learner: &NeuralLearner,
    ) -> anyhow::Result<()> {
        tx.send(Progress {
            kind: progress_kind::STATUS,
            state,
            pid: self.pid,
            env_steps: book.env_steps(),
            updates: learner.updates(),
            weights_version: learner.updates(),
            loss: self.loss,
            ..Progress::default()
        })?;
        self.last = Instant::now();
        Ok(())
    }
}
