//! The learner process of alfd: receives the actors' transitions, makes `U` updates of the K heads
//! per environment step (the core's [`NeuralLearner`]), publishes versioned weights, and returns
//! credits to the actors so that none runs more than a window of steps ahead.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use alfd_common::agent::NeuralLearner;
use alfd_common::config::ExperimentConfig;
use alfd_common::replay::Transition;
use alfd_common::rng::{derive_seed, seeded};
use alfd_wire::{
    self as wire, process_state, progress_kind, ActorBells, ControlWatch, Credits, Doorbell,
    Process, Progress, Role, TransitionBatch, Wake, Wire, WireError, MAX_ACTORS, MAX_CREDIT_WINDOW,
};
use anyhow::Context as _;
use tracing::{debug, info, warn};

/// CartPole's observation size and number of actions.
const OBS_DIM: usize = 4;
const ACTIONS: usize = 2;

/// `alfd-learner`: the learner process of a run (started by `alfd run`).
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "alfd-learner", version)]
pub struct Args {
    /// The run directory (config, logs, weights).
    #[arg(long)]
    pub run_dir: PathBuf,
    /// The run id (names the run's iceoryx2 services).
    #[arg(long)]
    pub run_id: String,
    /// The experiment config; default `RUN_DIR/config.toml`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Credit window: how many steps an actor may run ahead of the learner's updates.
    #[arg(long, default_value_t = 32)]
    pub window: u64,
    /// Publish the weights every this many updates.
    #[arg(long, default_value_t = 1)]
    pub weights_every: u64,
    /// Seconds to wait for the launcher's first word.
    #[arg(long, default_value_t = 20)]
    pub handshake_timeout: u64,
}

/// The name of the process's log file (without `.log`).
pub fn log_name(_args: &Args) -> String {
    "learner".to_owned()
}

/// Reads the experiment config of a run and checks the runtime can run it.
pub fn load_config(path: &Path) -> anyhow::Result<ExperimentConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read config {}", path.display()))?;
    ExperimentConfig::for_multi_process(&text)
        .with_context(|| format!("in config {}", path.display()))
}

/// Where the credits of each actor stand.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct ActorBook {
    incarnation: u64,
    /// One past the highest sequence number received (lost steps count as received).
    received: u64,
    /// Steps received and not yet learned from.
    queued: u64,
    lost: u64,
    /// The actor is blocked until its grant exceeds this sequence number.
    blocked_until: Option<u64>,
}

/// The learner's accounts: what each actor sent, what is learned from, and the grants.
#[derive(Debug, Clone)]
pub struct CreditBook {
    window: u64,
    actors: [ActorBook; MAX_ACTORS],
    env_steps: u64,
}

/// One step waiting in the learner's queue.
#[derive(Debug, Clone)]
pub struct Queued {
    pub actor: u16,
    pub incarnation: u64,
    /// The last step of its batch: its processing frees a batch worth of credit.
    pub last_of_batch: bool,
    pub transition: Transition,
}

impl CreditBook {
    pub fn new(window: u64) -> Self {
        Self {
            window,
            actors: [ActorBook::default(); MAX_ACTORS],
            env_steps: 0,
        }
    }

    /// Environment steps received from all actors: the run's global step.
    pub fn env_steps(&self) -> u64 {
        self.env_steps
    }

    /// Steps of `actor` lost on the way (never expected; logged).
    pub fn lost(&self, actor: u16) -> u64 {
        self.actors.get(actor as usize).map_or(0, |a| a.lost)
    }

    /// Takes in a batch, appending its steps to `queue`; returns how many it appended.
    pub fn accept(&mut self, b: &TransitionBatch, queue: &mut VecDeque<Queued>) -> usize {
        let a = b.actor as usize;
        if a >= MAX_ACTORS {
            warn!(
                actor = a,
                "transitions from an actor id beyond the credit table; dropped"
            );
            return 0;
        }
        let book = &mut self.actors[a];
        let current = b.incarnation >= book.incarnation;
        if b.incarnation > book.incarnation {
            if book.incarnation != 0 {
                info!(
                    actor = a,
                    old = book.incarnation,
                    new = b.incarnation,
                    "actor restarted"
                );
            }
            *book = ActorBook {
                incarnation: b.incarnation,
                ..ActorBook::default()
            };
        }
        if current {
            if b.first_seq > book.received {
                let gap = b.first_seq - book.received;
                warn!(
                    actor = a,
                    gap, "transitions lost on the way; counted as received"
                );
                book.lost += gap;
            }
            book.received = book.received.max(b.end_seq());
            book.queued += b.len() as u64;
            if b.blocked != 0 {
                book.blocked_until = Some(b.end_seq());
            }
        }
        let n = b.len().min(wire::TRANSITIONS_PER_BATCH);
        for (i, transition) in b.transitions().enumerate() {
            queue.push_back(Queued {
                actor: b.actor as u16,
                incarnation: b.incarnation,
                last_of_batch: i + 1 == n,
                transition,
            });
        }
        self.env_steps += n as u64;
        n
    }

    /// Records that a queued step of `actor` has been learned from.
    pub fn learned(&mut self, actor: u16, incarnation: u64) {
        if let Some(book) = self.actors.get_mut(actor as usize) {
            if book.incarnation == incarnation {
                book.queued = book.queued.saturating_sub(1);
            }
        }
    }

    /// Whether an actor waits for credits.
    pub fn any_blocked(&self) -> bool {
        self.actors.iter().any(|a| a.blocked_until.is_some())
    }

    /// The grants to publish now, and the actors to wake: those blocked for want of credits
    /// that the new grants let go on.
    pub fn grant(&mut self, updates: u64) -> (Credits, Vec<u16>) {
        let c = self.credits(updates);
        let mut wake = Vec::new();
        for (i, b) in self.actors.iter_mut().enumerate() {
            if let Some(until) = b.blocked_until {
                if c.granted[i] > until {
                    wake.push(i as u16);
                    b.blocked_until = None;
                }
            }
        }
        (c, wake)
    }

    /// The grants: each actor may send up to `window` steps beyond those learned from.
    pub fn credits(&self, updates: u64) -> Credits {
        let mut c = Credits {
            env_steps: self.env_steps,
            updates,
            ..Credits::default()
        };
        for (i, b) in self.actors.iter().enumerate() {
            c.incarnation[i] = b.incarnation;
            c.received[i] = b.received;
            c.granted[i] = b.received - b.queued + self.window;
        }
        c
    }
}

/// Runs the learner until the launcher says stop or a termination signal arrives; saves the final
/// weights to `RUN_DIR/weights.safetensors`.
pub fn run(args: &Args, schema: u32) -> anyhow::Result<()> {
    anyhow::ensure!(
        (1..=MAX_CREDIT_WINDOW).contains(&args.window),
        "--window must be in 1..={MAX_CREDIT_WINDOW}, got {}",
        args.window
    );
    let config_path = args
        .config
        .clone()
        .unwrap_or_else(|| args.run_dir.join("config.toml"));
    let cfg = load_config(&config_path)?;
    let wire = Wire::connect(&args.run_id, Process::new(Role::Learner, 0), schema)
        .context("cannot join the run")?;
    let waiter = wire.waiter(Doorbell::Learner)?;
    let mut control = ControlWatch::new(&wire)?;
    control
        .handshake(&waiter, Duration::from_secs(args.handshake_timeout))
        .context("no handshake with the launcher")?;
    let rx = wire.transitions_receiver()?;
    let mut credits_tx = wire.credits_sender()?;
    let mut actors = ActorBells::new(&wire);
    let mut progress = wire.progress_sender()?;

    let mut learner = NeuralLearner::new(
        &cfg.agent,
        OBS_DIM,
        ACTIONS,
        seeded(derive_seed(cfg.seed, "learner")),
    );
    let mut params = vec![0.0f32; learner.network().num_params()];
    let mut weights_tx = wire.weights_sender(params.len())?;
    let mut book = CreditBook::new(args.window);
    let updates_per_step = cfg.agent.updates_per_step;

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
        window = args.window,
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
            learner.insert(&q.transition);
            for _ in 0..updates_per_step {
                if let Some(loss) = learner.update() {
                    status.loss = f64::from(loss);
                }
            }
            book.learned(q.actor, q.incarnation);
            if learner.updates() >= published_version + args.weights_every {
                let t = Instant::now();
                publish_weights(&learner, &mut params, &mut weights_tx, book.env_steps())?;
                publish_time += t.elapsed();
                published_version = learner.updates();
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
        control.poll()?;
        if control.shutdown_requested() {
            stop_reason = "the launcher said stop";
            break;
        }
        if wire.termination_requested() {
            stop_reason = "termination signal";
            break;
        }
        anyhow::ensure!(
            control.silence() < LAUNCHER_SILENCE,
            "no word from the launcher for {:?}: giving up",
            control.silence()
        );
        if queue.is_empty() {
            let idle_since = Instant::now();
            idle_waits += 1;
            let wake = waiter.wait(Duration::from_millis(100))?;
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
    let path = args.run_dir.join("weights.safetensors");
    write_atomically(&path, &learner.network().to_safetensors_bytes())?;
    info!(path = %path.display(), "final weights saved");
    status.send(&mut progress, process_state::EXITING, &book, &learner)?;
    debug!(
        lost = (0..MAX_ACTORS as u16).map(|a| book.lost(a)).sum::<u64>(),
        "lost steps"
    );
    Ok(())
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

/// How long the launcher may stay silent before a process gives up on the run.
pub const LAUNCHER_SILENCE: Duration = Duration::from_secs(10);

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

/// Writes a file whole: a temporary file, fsync, rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    use std::io::Write as _;
    let tmp = path.with_extension("tmp");
    let mut f =
        std::fs::File::create(&tmp).with_context(|| format!("cannot write {}", tmp.display()))?;
    f.write_all(bytes)
        .and_then(|()| f.sync_all())
        .with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch(actor: u16, incarnation: u64, first_seq: u64, len: usize) -> TransitionBatch {
        let mut b = TransitionBatch::new(actor, incarnation, 4, 2, first_seq).unwrap();
        for i in 0..len {
            let t = Transition {
                state: vec![i as f32; 4],
                action: 0,
                reward: 1.0,
                next_state: vec![i as f32 + 1.0; 4],
                terminated: false,
                mask: vec![1.0, 1.0],
                demo: false,
            };
            b.push(&t, 0, false).unwrap();
        }
        b
    }

    #[test]
    fn grants_follow_what_is_learned_from() {
        let mut book = CreditBook::new(64);
        let mut q = VecDeque::new();
        // Before anything: nobody has a grant (actors start with an implicit one of `window`).
        assert_eq!(book.credits(0).granted_for(0, 1), None);

        assert_eq!(book.accept(&batch(0, 1, 0, 32), &mut q), 32);
        assert_eq!(book.accept(&batch(1, 1, 0, 10), &mut q), 10);
        assert_eq!(book.env_steps(), 42);
        let c = book.credits(0);
        assert_eq!(
            c.granted_for(0, 1),
            Some(64),
            "nothing learned yet: window only"
        );
        assert_eq!(c.received[0], 32);
        assert_eq!(c.global_step_for(0, 1, 40), 42 + 8);

        for _ in 0..20 {
            let s = q.pop_front().unwrap();
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.credits(0).granted_for(0, 1), Some(20 + 64));
        // The 32nd step of actor 0 ends its batch.
        let mut last = None;
        for _ in 0..12 {
            let s = q.pop_front().unwrap();
            book.learned(s.actor, s.incarnation);
            last = Some(s);
        }
        let last = last.unwrap();
        assert!(last.last_of_batch && last.actor == 0);
        assert_eq!(book.credits(0).granted_for(0, 1), Some(96));
        assert_eq!(book.credits(0).granted_for(1, 1), Some(64));
    }

    #[test]
    fn a_blocked_actor_is_woken_once_its_grant_lets_it_go_on() {
        let mut book = CreditBook::new(4);
        let mut q = VecDeque::new();
        let mut b = batch(1, 1, 0, 4);
        b.blocked = 1; // sent steps 0..4 with a grant of 4: blocked
        book.accept(&b, &mut q);
        book.accept(&batch(0, 1, 0, 2), &mut q);
        assert!(book.any_blocked());
        let (c, wake) = book.grant(0);
        assert_eq!(
            (c.granted_for(1, 1), wake),
            (Some(4), vec![]),
            "nothing learned yet"
        );
        let s = q.pop_front().unwrap();
        book.learned(s.actor, s.incarnation);
        let (c, wake) = book.grant(1);
        assert_eq!((c.granted_for(1, 1), wake), (Some(5), vec![1]));
        assert!(!book.any_blocked(), "woken once");
        let s = q.pop_front().unwrap();
        book.learned(s.actor, s.incarnation);
        assert_eq!(book.grant(2).1, Vec::<u16>::new());
        // Actor 0 uses its grant of 4, then blocks with nothing batched: an empty flagged batch.
        book.accept(&batch(0, 1, 2, 2), &mut q);
        let mut empty = batch(0, 1, 4, 0);
        empty.blocked = 1;
        book.accept(&empty, &mut q);
        assert_eq!(
            book.grant(2).1,
            Vec::<u16>::new(),
            "granted 4, blocked at 4: not yet"
        );
        while let Some(s) = q.pop_front() {
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.grant(8).1, vec![0]);
        // One that blocked on stale news (its grant is already beyond) is woken at once.
        let mut stale = batch(0, 1, 4, 1);
        stale.blocked = 1;
        book.accept(&stale, &mut q);
        assert_eq!(book.grant(8).1, vec![0]);
    }

    #[test]
    fn a_restarted_actor_starts_a_new_account_and_old_steps_still_count() {
        let mut book = CreditBook::new(8);
        let mut q = VecDeque::new();
        book.accept(&batch(2, 1, 0, 5), &mut q);
        book.accept(&batch(2, 2, 0, 3), &mut q);
        let c = book.credits(0);
        assert_eq!(c.granted_for(2, 1), None);
        assert_eq!(c.granted_for(2, 2), Some(8));
        // A late batch of the dead incarnation is learned from but does not touch the account.
        book.accept(&batch(2, 1, 5, 4), &mut q);
        assert_eq!(q.len(), 12);
        assert_eq!(book.env_steps(), 12);
        while let Some(s) = q.pop_front() {
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.credits(0).granted_for(2, 2), Some(3 + 8));
    }

    #[test]
    fn lost_steps_count_as_received_so_credits_keep_flowing() {
        let mut book = CreditBook::new(4);
        let mut q = VecDeque::new();
        book.accept(&batch(0, 1, 0, 2), &mut q);
        book.accept(&batch(0, 1, 5, 2), &mut q); // steps 2..5 lost
        assert_eq!(book.lost(0), 3);
        while let Some(s) = q.pop_front() {
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.credits(0).granted_for(0, 1), Some(7 + 4));
        let mut q2 = VecDeque::new();
        let mut out_of_range = batch(0, 1, 0, 1);
        out_of_range.actor = MAX_ACTORS as u32;
        assert_eq!(book.accept(&out_of_range, &mut q2), 0);
    }
}
