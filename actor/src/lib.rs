//! The actor process of alfd: steps CartPole with the latest weights it has (the core's
//! [`NeuralActor`]), measures the JS divergence and applies the query rule, asks the expert when
//! the rule fires, shapes the reward with the latest demonstration model, and sends its
//! transitions to the learner, never more than its credits allow.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use alfd_common::agent::NeuralActor;
use alfd_common::config::ExperimentConfig;
use alfd_common::demo_model::DemoModel;
use alfd_common::env::{CartPole, Env};
use alfd_common::rng::{derive_seed, seeded};
use alfd_wire::{
    self as wire, outcome, process_state, progress_kind, Bell, ControlWatch, Credits, Doorbell,
    Process, Progress, QueryRequest, QueryResponse, Role, TransitionBatch, Wake, Wire, MAX_ACTORS,
    MAX_CREDIT_WINDOW,
};
use anyhow::Context as _;
use tracing::{debug, info, warn};

const OBS_DIM: usize = 4;
const ACTIONS: usize = 2;
/// How long the launcher may stay silent before the actor gives up on the run.
const LAUNCHER_SILENCE: Duration = Duration::from_secs(10);

/// `alfd-actor`: one actor process of a run (started by `alfd run`).
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "alfd-actor", version)]
pub struct Args {
    /// The run directory (config, logs).
    #[arg(long)]
    pub run_dir: PathBuf,
    /// The run id (names the run's iceoryx2 services).
    #[arg(long)]
    pub run_id: String,
    /// The experiment config; default `RUN_DIR/config.toml`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// This actor's id, `0..16`.
    #[arg(long)]
    pub actor_id: u16,
    /// Which process plays this actor id: 1 for the first, +1 per restart.
    #[arg(long, default_value_t = 1)]
    pub incarnation: u64,
    /// Credit window: steps this actor may run ahead of the learner (as the learner's `--window`).
    #[arg(long, default_value_t = 32)]
    pub window: u64,
    /// Milliseconds to wait for the expert's answer before acting on its own.
    #[arg(long, default_value_t = 1000)]
    pub query_timeout_ms: u64,
    /// Seconds to wait for the launcher's first word and the learner's first weights.
    #[arg(long, default_value_t = 20)]
    pub handshake_timeout: u64,
}

/// The name of the process's log file (without `.log`).
pub fn log_name(args: &Args) -> String {
    format!("actor-{}", args.actor_id)
}

fn load_config(path: &Path) -> anyhow::Result<ExperimentConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read config {}", path.display()))?;
    ExperimentConfig::for_multi_process(&text)
        .with_context(|| format!("in config {}", path.display()))
}

/// The seed streams of an actor. Actor 0's first incarnation uses the single-process runner's
/// streams (`actor-0`, `env`), so a one-actor run starts from the same seeds as `alfd local`.
pub fn seed_streams(actor_id: u16, incarnation: u64) -> (String, String) {
    match (actor_id, incarnation) {
        (0, 1) => ("actor-0".to_owned(), "env".to_owned()),
        (a, 1) => (format!("actor-{a}"), format!("env-{a}")),
        (a, i) => (format!("actor-{a}-r{i}"), format!("env-{a}-r{i}")),
    }
}

/// What the actor knows of the expert's side.
#[derive(Debug)]
struct ExpertView {
    budget_left: u32,
    /// Demonstrations in the run, as far as known.
    demos: u64,
    model: Option<DemoModel>,
    model_demos: usize,
    last_demo_step: u64,
}

impl ExpertView {
    /// Takes in the newest demonstration model, if one arrived.
    fn take_model(
        &mut self,
        rx: &wire::DemoModelReceiver<'_>,
        bytes: &mut Vec<u8>,
    ) -> anyhow::Result<()> {
        if let Some(h) = rx.latest_into(bytes)? {
            self.model = if h.len == 0 {
                None
            } else {
                Some(postcard::from_bytes(bytes).context("malformed demonstration model")?)
            };
            self.model_demos = h.demos as usize;
            self.last_demo_step = h.last_demo_step;
            self.budget_left = h.budget_left;
            self.demos = self.demos.max(u64::from(h.demos));
            debug!(version = h.version, demos = h.demos, "demonstration model");
        }
        Ok(())
    }
}

/// Runs the actor until the launcher says stop or a termination signal arrives.
pub fn run(args: &Args, schema: u32) -> anyhow::Result<()> {
    anyhow::ensure!(
        (args.actor_id as usize) < MAX_ACTORS,
        "--actor-id must be below {MAX_ACTORS}, got {}",
        args.actor_id
    );
    anyhow::ensure!(args.incarnation >= 1, "--incarnation must be at least 1");
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
    let (actor_stream, env_stream) = seed_streams(args.actor_id, args.incarnation);
    let (id, incarnation) = (args.actor_id, args.incarnation);

    let wire = Wire::connect(&args.run_id, Process::new(Role::Actor, id), schema)
        .context("cannot join the run")?;
    let waiter = wire.waiter(Doorbell::Actor(id))?;
    let mut control = ControlWatch::new(&wire)?;
    let handshake = Duration::from_secs(args.handshake_timeout);
    control
        .handshake(&waiter, handshake)
        .context("no handshake with the launcher")?;
    let mut tx = wire.transitions_sender()?;
    let learner = wire.bell(Doorbell::Learner)?;
    let expert = wire.bell(Doorbell::Expert)?;
    let credits_rx = wire.credits_receiver()?;
    let weights_rx = wire.weights_receiver()?;
    let model_rx = wire.demo_model_receiver()?;
    let mut client = wire.query_client()?;
    let mut progress = wire.progress_sender()?;

    let mut actor = NeuralActor::new(
        &cfg.agent,
        &cfg.query,
        OBS_DIM,
        ACTIONS,
        seeded(derive_seed(cfg.seed, &actor_stream)),
    );
    let heads = cfg.agent.heads();
    let mut params = Vec::new();
    // The learner's initial weights, as the single-process runner starts from them.
    let start = Instant::now();
    loop {
        if let Some(h) = weights_rx.latest_into(&mut params)? {
            actor.set_weights(&params, h.version)?;
            break;
        }
        control.poll()?;
        anyhow::ensure!(
            !control.shutdown_requested() && !wire.termination_requested(),
            "stopped before the learner's first weights arrived"
        );
        anyhow::ensure!(
            start.elapsed() < handshake,
            "no weights from the learner within {handshake:?}"
        );
        waiter.wait(Duration::from_millis(50))?;
    }
    info!(
        actor = id,
        incarnation,
        weights = actor.weights_version(),
        "actor running"
    );

    let schedule = cfg.shaping.schedule();
    let mut view = ExpertView {
        budget_left: cfg.budget(),
        demos: 0,
        model: None,
        model_demos: 0,
        last_demo_step: 0,
    };
    let mut model_bytes = Vec::new();
    let mut credits: Option<Credits> = None;
    let mut env = CartPole::new(cfg.env.max_episode_steps());
    let env_seed = derive_seed(cfg.seed, &env_stream);
    let mut next_seq = 0u64;
    let mut batch = TransitionBatch::new(id, incarnation, OBS_DIM, heads, 0)?;
    let pid = std::process::id();
    let query_timeout = Duration::from_millis(args.query_timeout_ms);
    let mut timeouts = 0u64;
    let mut since_check = 0u32;
    let mut last_status = Instant::now();
    let (mut credit_waits, mut credit_wait) = (0u64, Duration::ZERO);

    // Sends the batch (if any) and starts the next one at `next_seq`.
    let flush = |batch: &mut TransitionBatch,
                 tx: &mut wire::Sender<'_, TransitionBatch>,
                 next_seq: u64|
     -> anyhow::Result<()> {
        if !batch.is_empty() {
            tx.send(*batch)?;
            learner.ring()?;
        }
        *batch = TransitionBatch::new(id, incarnation, OBS_DIM, heads, next_seq)?;
        Ok(())
    };

    let mut episode = 0u64;
    let stop_reason = 'run: loop {
        let mut obs = env.reset(if episode == 0 { Some(env_seed) } else { None });
        actor.begin_episode();
        let (mut ret, mut length, mut js_sum) = (0.0f64, 0u64, 0.0f64);
        let (mut queries, mut shaped_steps) = (0u64, 0u64);
        loop {
            // The credit throttle: wait for the learner rather than run ahead of it.
            let granted = |c: &Option<Credits>| {
                c.as_ref()
                    .and_then(|c| c.granted_for(id, incarnation))
                    .unwrap_or(0)
                    .max(args.window)
            };
            if next_seq >= granted(&credits) {
                if let Some(c) = credits_rx.latest()? {
                    credits = Some(c);
                }
            }
            if next_seq >= granted(&credits) {
                // Out of credits: send what is batched, flagged so that the learner rings when
                // new credits are there (an empty batch if need be), and wait.
                batch.blocked = 1;
                tx.send(batch)?;
                learner.ring()?;
                batch = TransitionBatch::new(id, incarnation, OBS_DIM, heads, next_seq)?;
                let blocked = Instant::now();
                credit_waits += 1;
                loop {
                    if let Some(c) = credits_rx.latest()? {
                        credits = Some(c);
                    }
                    if next_seq < granted(&credits) {
                        break;
                    }
                    if waiter.wait(Duration::from_millis(100))? == Wake::Signal {
                        break 'run "termination signal";
                    }
                    control.poll()?;
                    if control.shutdown_requested() {
                        break 'run "the launcher said stop";
                    }
                    anyhow::ensure!(
                        control.silence() < LAUNCHER_SILENCE,
                        "no word from the launcher for {:?}: giving up",
                        control.silence()
                    );
                }
                credit_wait += blocked.elapsed();
                if blocked.elapsed() > Duration::from_millis(5) {
                    debug!(
                        waited_ms = blocked.elapsed().as_millis() as u64,
                        next_seq,
                        granted = granted(&credits),
                        "long credit wait"
                    );
                }
            }
            // Take in the news (after any wait): weights, demonstration model, credits, control.
            if let Some(h) = weights_rx.latest_into(&mut params)? {
                actor.set_weights(&params, h.version)?;
            }
            view.take_model(&model_rx, &mut model_bytes)?;
            if let Some(c) = credits_rx.latest()? {
                credits = Some(c);
            }
            since_check += 1;
            if since_check >= 64 {
                since_check = 0;
                control.poll()?;
                if control.shutdown_requested() {
                    break 'run "the launcher said stop";
                }
                if wire.termination_requested() {
                    break 'run "termination signal";
                }
                anyhow::ensure!(
                    control.silence() < LAUNCHER_SILENCE,
                    "no word from the launcher for {:?}: giving up",
                    control.silence()
                );
                if last_status.elapsed() >= Duration::from_secs(1) {
                    progress.send(status(pid, incarnation, next_seq, &view, &actor))?;
                    last_status = Instant::now();
                }
            }
            let global_step = credits
                .as_ref()
                .map_or(next_seq, |c| c.global_step_for(id, incarnation, next_seq));

            // Algorithm 1 lines 3-16.
            let decision = actor.decide(&obs, view.budget_left > 0);
            js_sum += decision.js;
            let mut action = decision.action;
            let mut demo = false;
            if decision.query {
                let asked = Query {
                    client: &mut client,
                    expert: &expert,
                    waiter: &waiter,
                    active_expert: control.current().active_expert,
                    timeout: query_timeout,
                };
                match asked.ask(QueryRequest::new(id, incarnation, global_step, &obs)?)? {
                    Answer::Demo(r) => {
                        action = r.action as usize;
                        demo = true;
                        queries += 1;
                        // The expert published the model refitted with this demonstration
                        // before answering: shape this very step with it, as Algorithm 1 does.
                        view.take_model(&model_rx, &mut model_bytes)?;
                        view.budget_left = r.budget_left;
                        view.demos = view.demos.max(u64::from(r.demo_index) + 1);
                    }
                    Answer::BudgetExhausted => view.budget_left = 0,
                    Answer::NoExpert => {}
                    Answer::Timeout => {
                        timeouts += 1;
                        warn!(timeouts, "the expert did not answer in time; acting alone");
                    }
                }
            }
            // Lines 17-19: act, shape, store.
            let step = env.step(action)?;
            let shaping = if cfg.shaping_enabled() {
                schedule.model_for(
                    global_step,
                    view.model_demos,
                    view.last_demo_step,
                    view.model.as_ref(),
                )
            } else {
                None
            };
            shaped_steps += u64::from(shaping.is_some());
            let t = actor.transition(
                &obs,
                action,
                step.reward,
                &step.observation,
                step.terminated,
                demo,
                shaping,
            );
            batch.push(&t, episode as u32, step.truncated)?;
            next_seq += 1;
            if batch.is_full() {
                flush(&mut batch, &mut tx, next_seq)?;
            }
            ret += step.reward;
            length += 1;
            obs = step.observation;
            if step.done() {
                break;
            }
        }
        flush(&mut batch, &mut tx, next_seq)?;
        let total_steps = credits
            .as_ref()
            .map_or(next_seq, |c| c.global_step_for(id, incarnation, next_seq));
        progress.send(Progress {
            kind: progress_kind::EPISODE,
            incarnation,
            episode,
            episode_return: ret,
            length,
            demos_used: view.demos,
            mean_js: js_sum / length as f64,
            queries,
            shaped_steps,
            total_steps,
            env_steps: next_seq,
            weights_version: actor.weights_version(),
            ..Progress::default()
        })?;
        episode += 1;
    };
    info!(
        reason = stop_reason,
        episodes = episode,
        steps = next_seq,
        timeouts,
        credit_waits,
        credit_wait_s = credit_wait.as_secs_f64(),
        "actor stopping"
    );
    let mut last = status(pid, incarnation, next_seq, &view, &actor);
    last.state = process_state::EXITING;
    progress.send(last)?;
    Ok(())
}

fn status(
    pid: u32,
    incarnation: u64,
    steps: u64,
    view: &ExpertView,
    actor: &NeuralActor,
) -> Progress {
    Progress {
        kind: progress_kind::STATUS,
        state: process_state::RUNNING,
        pid,
        incarnation,
        env_steps: steps,
        demos: view.demos,
        budget_left: u64::from(view.budget_left),
        weights_version: actor.weights_version(),
        ..Progress::default()
    }
}

/// What came of a query.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Answer {
    Demo(QueryResponse),
    BudgetExhausted,
    /// No expert is active or connected: the actor acts on its own at once.
    NoExpert,
    /// The expert did not answer in time: the actor acted on its own.
    Timeout,
}

/// One query to the expert (Algorithm 1 line 9), with the client-side timeout.
struct Query<'a, 'w> {
    client: &'a mut wire::QueryClient<'w>,
    expert: &'a Bell,
    waiter: &'a wire::Waiter,
    active_expert: u32,
    timeout: Duration,
}

impl Query<'_, '_> {
    fn ask(self, request: QueryRequest) -> anyhow::Result<Answer> {
        if self.active_expert == 0 {
            return Ok(Answer::NoExpert);
        }
        let mut pending = self.client.ask(request)?;
        if pending.servers() == 0 {
            return Ok(Answer::NoExpert);
        }
        self.expert.ring()?;
        let deadline = Instant::now() + self.timeout;
        loop {
            if let Some(r) = pending.poll()? {
                return Ok(match r.outcome {
                    outcome::ANSWERED => Answer::Demo(r),
                    _ => Answer::BudgetExhausted,
                });
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(Answer::Timeout);
            }
            if self
                .waiter
                .wait((deadline - now).min(Duration::from_millis(50)))?
                == Wake::Signal
            {
                return Ok(Answer::Timeout);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn actor_zero_uses_the_single_process_streams_and_restarts_new_ones() {
        assert_eq!(seed_streams(0, 1), ("actor-0".to_owned(), "env".to_owned()));
        assert_eq!(
            seed_streams(3, 1),
            ("actor-3".to_owned(), "env-3".to_owned())
        );
        assert_eq!(
            seed_streams(0, 2),
            ("actor-0-r2".to_owned(), "env-0-r2".to_owned())
        );
        let all: std::collections::HashSet<_> = (0..4u16)
            .flat_map(|a| (1..4u64).map(move |i| seed_streams(a, i)))
            .collect();
        assert_eq!(
            all.len(),
            12,
            "every actor and incarnation has its own streams"
        );
    }
}
