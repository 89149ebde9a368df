//! The learner process of alfd: receives the actors' transitions, learns from each (the core's
//! [`NeuralLearner::learn`]: insert, then `U` updates), publishes versioned weights, and returns
//! credits to the actors (the pure [`CreditBook`]) so that none runs more than a window of steps
//! ahead.

pub mod checkpoint;
pub mod credit_book;
pub mod machine;

use std::time::{Duration, Instant};

use alfd_common::agent::NeuralLearner;
use alfd_common::checkpoint::Cadence;
use alfd_harness::{write_atomically_patiently, BadInput, ProcessArgs, Session, Setup};
use alfd_wire::{
    self as wire, process_state, progress_kind, ActorBells, Credits, Doorbell, Process, Progress,
    Role, Wake, WireError, MAX_ACTORS,
};
use tracing::{debug, info, warn};

use crate::checkpoint::LearnerCheckpoint;

pub use credit_book::{BatchShape, CreditBook, Queued};
pub use machine::{LearnerMachine, Learns, Todo, CREDITS_EVERY};

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
pub fn run(args: &Args, schema: u32) -> alfd_harness::Result<()> {
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
) -> alfd_harness::Result<End> {
    let runtime = &setup.runtime;
    let run_dir = &args.process.run_dir;
    let session = Session::join(wire, Doorbell::Learner, runtime.handshake_timeout())?;
    let mut m = machine(setup, restored.as_ref(), run_dir)?;
    let params = m.learner().network().num_params();
    let mut shell = Shell {
        rx: wire.transitions_receiver()?,
        credits_tx: wire.credits_sender()?,
        actors: ActorBells::new(wire),
        progress: wire.progress_sender()?,
        weights_tx: wire.weights_sender(params)?,
        run_dir,
        config_toml,
        clock: Instant::now(),
        stats: Stats::default(),
        board: alfd_harness::tensorboard::Board::open(run_dir, "learner", &setup.config),
    };
    shell.publish(&m)?;
    shell.credits_tx.send(m.book().credits(0))?;
    info!(params, window = runtime.window, "learner running");
    shell.status(&mut m, process_state::RUNNING)?;
    let (stop_reason, end) = shell.serve(&mut m, &session)?;
    shell.stats.log(stop_reason, &m);
    let path = run_dir.join("weights.safetensors");
    // A disk full for a moment (being freed) does not cost the run its weights.
    let weights = m.learner().network().to_safetensors_bytes();
    write_atomically_patiently(&path, &weights, alfd_harness::DISK_FULL_PATIENCE)?;
    info!(path = %path.display(), "final weights saved");
    if m.final_checkpoint(runtime.window) {
        // The run's learning is done and its weights are saved: a final checkpoint that cannot
        // be written (a full disk) leaves the last one in place rather than failing the run.
        if let Err(e) = shell.checkpoint(&m) {
            let path = checkpoint::path(run_dir);
            let kept = if path.exists() {
                "keeps the last one"
            } else {
                "does not exist: `alfd resume` cannot continue this run"
            };
            tracing::error!(
                "the final checkpoint could not be written: {e:#}; {} {kept}",
                path.display()
            );
        }
    } else {
        info!("lockstep with one actor: the last checkpoint (at an episode end) is kept");
    }
    let s = &shell.stats;
    info!(
        checkpoints = s.checkpoints,
        bytes = s.checkpoint_bytes,
        write_s = s.checkpoint_time.as_secs_f64(),
        share_of_learner_time =
            s.checkpoint_time.as_secs_f64() / shell.clock.elapsed().as_secs_f64(),
        "learner state checkpointed"
    );
    shell.status(&mut m, process_state::EXITING)?;
    debug!(
        lost = (0..MAX_ACTORS as u16)
            .map(|a| m.book().lost(a))
            .sum::<u64>(),
        "lost steps"
    );
    Ok(end)
}

/// The learner's state machine for this run, restored from `restored` when given.
fn machine(
    setup: &Setup,
    restored: Option<&LearnerCheckpoint>,
    run_dir: &std::path::Path,
) -> alfd_harness::Result<LearnerMachine<NeuralLearner>> {
    let (cfg, runtime) = (&setup.config, &setup.runtime);
    let (obs_dim, num_actions) = setup.env_dims()?;
    let mut learner = alfd_common::agent::build::neural_learner(cfg, obs_dim, num_actions);
    let mut book = CreditBook::new(
        runtime.window,
        BatchShape {
            obs_dim,
            heads: cfg.agent.heads(),
            actions: num_actions,
        },
    );
    if restored.is_none() {
        // A run from scratch starts from its prior demonstrations (`demos.prior`), if any.
        let prior = alfd_harness::read_prior(run_dir, obs_dim, num_actions)?;
        for p in &prior {
            learner.insert(&p.transition(cfg.agent.heads()));
        }
        if !prior.is_empty() {
            info!(
                transitions = prior.len(),
                "prior demonstrations in the replay buffer"
            );
        }
    }
    if let Some(ckpt) = restored {
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
    Ok(LearnerMachine::new(
        learner,
        book,
        runtime.weights_every,
        Cadence::steps_for_updates(runtime.checkpoint_every, cfg.agent.updates_per_step),
        restored.map_or(0, |c| c.env_steps),
    ))
}

/// What the learner measures of itself (logged when it stops).
#[derive(Debug, Default)]
struct Stats {
    idle_waits: u64,
    idle: Duration,
    idle_running: Duration,
    publish: Duration,
    /// Actors woken, and the time their doorbells took (a sleeping actor's costs the wake-up
    /// of its core).
    rings: u64,
    ring: Duration,
    first_step: Option<Instant>,
    checkpoints: u64,
    checkpoint_time: Duration,
    checkpoint_bytes: usize,
}

impl Stats {
    fn log(&self, reason: &str, m: &LearnerMachine<NeuralLearner>) {
        let updates = m.learner().updates();
        info!(
            reason,
            updates,
            env_steps = m.book().env_steps(),
            idle_waits = self.idle_waits,
            idle_s = self.idle.as_secs_f64(),
            idle_running_s = self.idle_running.as_secs_f64(),
            publish_s = self.publish.as_secs_f64(),
            rings = self.rings,
            ring_s = self.ring.as_secs_f64(),
            updates_per_s = updates as f64
                / self
                    .first_step
                    .map_or(f64::INFINITY, |t| t.elapsed().as_secs_f64()),
            "learner stopping"
        );
    }
}

/// The learner's I/O: the wire's ports and the run directory.
struct Shell<'w, 'a> {
    rx: wire::TransitionReceiver<'w>,
    credits_tx: wire::Sender<'w, Credits>,
    actors: ActorBells<'w>,
    progress: wire::Sender<'w, Progress>,
    weights_tx: wire::WeightsSender<'w>,
    run_dir: &'a std::path::Path,
    config_toml: &'a str,
    clock: Instant,
    stats: Stats,
    /// The learner's TensorBoard scalars (`RUN_DIR/tb/`).
    board: alfd_harness::tensorboard::Board,
}

type Machine = LearnerMachine<NeuralLearner>;

impl Shell<'_, '_> {
    /// The loop: take in the batches, learn one step (checking the session every 32 steps),
    /// publish and grant when the queue drains, wait when there is nothing to do.
    fn serve(
        &mut self,
        m: &mut Machine,
        session: &Session<'_>,
    ) -> alfd_harness::Result<(&'static str, End)> {
        let mut since_check = 0u32;
        loop {
            self.receive(m)?;
            if m.any_wake_due() {
                // A blocked actor's grant is there (the steps just learned, or it blocked on
                // stale news): wake it at once.
                self.send_credits(m)?;
            }
            if let Some(todo) = m.step() {
                self.stats.first_step.get_or_insert_with(Instant::now);
                self.carry_out(m, todo)?;
                since_check += 1;
                if since_check < 32 {
                    continue;
                }
            }
            since_check = 0;
            let todo = m.drained();
            self.carry_out(m, todo)?;
            if m.tick(self.clock.elapsed()) {
                self.status(m, process_state::RUNNING)?;
            }
            // A process that subscribed since the last publication gets the history sample now.
            self.weights_tx.update_connections()?;
            self.credits_tx.update_connections()?;
            match session.should_stop() {
                Ok(Some(stop)) => return Ok((stop.0, End::Stopped)),
                Ok(None) => {}
                Err(e) if e.orphaned() => {
                    warn!("{e}: saving the learner's state and leaving");
                    return Ok(("the launcher is gone", End::Orphaned));
                }
                Err(e) => return Err(e.into()),
            }
            if m.queue_is_empty() && self.idle(m, session)? == Wake::Signal {
                return Ok(("termination signal", End::Stopped));
            }
        }
    }

    /// Takes in whatever arrived.
    fn receive(&mut self, m: &mut Machine) -> alfd_harness::Result<()> {
        loop {
            match self.rx.receive() {
                Ok(Some(batch)) => m.accept(&batch),
                Ok(None) => return Ok(()),
                Err(e @ WireError::SchemaMismatch { .. }) => {
                    tracing::error!("{e}; batch dropped");
                }
                Err(e) => return Err(e.into()),
            }
        }
    }

    fn idle(&mut self, m: &Machine, session: &Session<'_>) -> alfd_harness::Result<Wake> {
        let since = Instant::now();
        self.stats.idle_waits += 1;
        let wake = session.wait_for(Duration::from_millis(100))?;
        let waited = since.elapsed();
        self.stats.idle += waited;
        if self.stats.first_step.is_some() {
            self.stats.idle_running += waited;
        }
        if waited > Duration::from_millis(5) {
            debug!(
                waited_ms = waited.as_millis() as u64,
                ?wake,
                env_steps = m.book().env_steps(),
                "long idle wait"
            );
        }
        Ok(wake)
    }

    fn carry_out(&mut self, m: &mut Machine, todo: Todo) -> alfd_harness::Result<()> {
        if todo.publish {
            let t = Instant::now();
            self.publish(m)?;
            self.stats.publish += t.elapsed();
        }
        if todo.checkpoint {
            if let Err(e) = self.checkpoint(m) {
                // A full disk, say: the previous checkpoint stays whole (written atomically),
                // and the next one is tried at the cadence; the run goes on.
                tracing::warn!(
                    "checkpoint not written ({e:#}); the previous one stays, the next is tried \
                     at the cadence"
                );
            }
        }
        if todo.credits {
            self.send_credits(m)?;
        }
        Ok(())
    }

    fn publish(&mut self, m: &Machine) -> alfd_harness::Result<()> {
        let learner = m.learner();
        let v = learner.updates();
        self.weights_tx.publish(
            v,
            v,
            m.book().env_steps(),
            &learner.network().params().tensors(),
        )?;
        Ok(())
    }

    /// Publishes the grants, and wakes the actors that wait for them.
    fn send_credits(&mut self, m: &mut Machine) -> alfd_harness::Result<()> {
        let (credits, wake) = m.grant();
        self.credits_tx.send(credits)?;
        if wake.is_empty() {
            return Ok(());
        }
        let t = Instant::now();
        for id in &wake {
            self.actors.ring(*id)?;
        }
        self.stats.rings += wake.len() as u64;
        self.stats.ring += t.elapsed();
        Ok(())
    }

    fn checkpoint(&mut self, m: &Machine) -> alfd_harness::Result<()> {
        let t = Instant::now();
        let ckpt = LearnerCheckpoint {
            learner: m.learner().snapshot(),
            env_steps: m.book().env_steps(),
        };
        self.stats.checkpoint_bytes = checkpoint::save(self.run_dir, &ckpt, self.config_toml)?;
        let took = t.elapsed();
        self.stats.checkpoint_time += took;
        self.stats.checkpoints += 1;
        debug!(
            updates = m.learner().updates(),
            env_steps = m.book().env_steps(),
            bytes = self.stats.checkpoint_bytes,
            ms = took.as_secs_f64() * 1e3,
            "checkpoint written"
        );
        Ok(())
    }

    fn status(&mut self, m: &mut Machine, state: u32) -> alfd_harness::Result<()> {
        let l = m.learner();
        self.board.learner(
            m.book().env_steps(),
            l.updates(),
            m.loss(),
            f64::from(l.q_mean()),
        );
        self.progress.send(Progress {
            kind: progress_kind::STATUS,
            state,
            pid: std::process::id(),
            env_steps: m.book().env_steps(),
            updates: m.learner().updates(),
            weights_version: m.learner().updates(),
            loss: m.loss(),
            ..Progress::default()
        })?;
        Ok(())
    }
}
