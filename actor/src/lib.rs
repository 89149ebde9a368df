//! The actor process of alfd: plays the config's environment with the core's [`NeuralActor`]
//! through the one environment loop ([`alfd_common::environment_loop`]), connected to the
//! learner and the expert processes by the wire transports of [`links`]: transitions go to the
//! learner under its credits, the newest weights and demonstration model come back, queries go
//! to the expert. Every finished episode goes to the launcher as a progress message.

pub mod checkpoint;
pub mod links;
pub mod machine;

use std::ops::ControlFlow;
use std::time::Duration;

use alfd_common::agent::{build, NeuralActor};
use alfd_common::checkpoint::Cadence;
use alfd_common::env::VectorEnv;
use alfd_common::environment_loop::{
    self, Actor as _, EpisodeEnd, GenericActor, LoopError, Schedule,
};
use alfd_common::evaluate::evaluate_greedy_advised;
use alfd_harness::{BadInput, ProcessArgs, Session};
use alfd_wire::{Doorbell, Process, Progress, Role, MAX_ACTORS};
use tracing::info;

use crate::links::{WireAdder, WireExpert, WireVariables};
use crate::machine::{CreditPoll, Identity};

/// `alfd-actor`: one actor process of a run (started by `alfd run`).
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "alfd-actor", version)]
pub struct Args {
    #[command(flatten)]
    pub process: ProcessArgs,
    /// This actor's id, `0..16`.
    #[arg(long)]
    pub actor_id: u16,
    /// Which process plays this actor id: 1 for the first, +1 per restart.
    #[arg(long, default_value_t = 1)]
    pub incarnation: u64,
    /// Episodes this actor plays before it exits (its share of a run with an episode limit, not
    /// counting those of a restored state); default: until the launcher says stop.
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Continue from the state `RUN_DIR/actor-<id>.ckpt` holds for this global step (`alfd
    /// resume` chooses it).
    #[arg(long, value_name = "STEP")]
    pub restore_step: Option<u64>,
    /// Steps this actor id has played before this process (its earlier incarnations' recorded
    /// episodes): ε's clock starts there, so an actor that takes over does not explore from
    /// ε's start again (the launcher passes it).
    #[arg(long, value_name = "STEPS", default_value_t = 0)]
    pub explored_steps: u64,
}

/// The name of the process's log file (without `.log`).
pub fn log_name(args: &Args) -> String {
    format!("actor-{}", args.actor_id)
}

/// Runs the actor until the launcher says stop or a termination signal arrives.
pub fn run(args: &Args, schema: u32) -> alfd_harness::Result<()> {
    // Woken by its answer, the actor runs before a busy learner or refit.
    alfd_harness::Sched::query_path().apply();
    let me = identity(args)?;
    let setup = args.process.load()?;
    let (cfg, runtime) = (&setup.config, &setup.runtime);
    // A Gymnasium environment is served by this actor's adapter (started here, stopped with it).
    let mut adapter = None;
    let mut env = setup.actor_env(&mut adapter, &args.process, args.actor_id, schema)?;
    let (obs_dim, actions) = (env.observation_dim(), env.num_actions());

    let wire = args
        .process
        .connect(Process::new(Role::Actor, me.id), schema)?;
    let session = Session::join(&wire, Doorbell::Actor(me.id), runtime.handshake_timeout())?;
    let mut core = build::neural_actor(cfg, obs_dim, actions, me.id, me.incarnation);
    core.continue_exploration(args.explored_steps);
    let mut variables = WireVariables::new(&session)?;
    let mut adder = wire_adder(&session, me, runtime.window, obs_dim, cfg.agent.heads())?;
    let mut expert = wire_expert(&session, me, &setup, &args.process.run_dir)?;
    // A restored actor continues where its checkpoint stands.
    let run_dir = &args.process.run_dir;
    let (config_toml, restored) = restored(args, me.id)?;
    let mut start = environment_loop::Progress::default();
    if let Some(c) = &restored {
        start = continue_from(c, &mut core, env.as_mut(), &mut adder, &mut expert)?;
    }
    if !first_weights(
        &mut variables,
        &session,
        &mut core,
        me,
        runtime.handshake_timeout(),
    )? {
        return Ok(());
    }
    let mut progress = wire.episode_sender()?;
    let mut actor = GenericActor::new(core, adder, variables);
    let mut eval_env = setup.actor_env(&mut adapter, &args.process, args.actor_id, schema)?;
    let eval_seed = build::eval_seed(cfg);
    let quota = args.episodes.map(|n| n.saturating_add(start.episodes));
    let every = Cadence::steps_for_updates(runtime.checkpoint_every, cfg.agent.updates_per_step);
    let mut checkpoints = Checkpoints::new(run_dir, me.id, &config_toml, every, quota, restored);
    let mut waits = AnswerWaits {
        board: alfd_harness::tensorboard::Board::open(run_dir, &format!("actor-{}", me.id), cfg),
        seen: 0,
    };
    let end = environment_loop::run_from(
        env.as_mut(),
        &mut actor,
        &mut expert,
        schedule(cfg, me, quota),
        start,
        |e| {
            // Actor 0 evaluates, with the weights it acts on (as the single-process run does).
            if me.id == 0 && cfg.evaluation.due(e.record.episode) {
                e.record.eval_return = evaluate_greedy_advised(
                    e.actor.core.network(),
                    alfd_common::runner::advice(cfg, e.expert, e.record.total_steps),
                    eval_env.as_mut(),
                    cfg.evaluation.episodes,
                    eval_seed,
                )?;
            }
            progress
                .send(Progress::episode(me.incarnation, *e.record))
                .map_err(LoopError::link)?;
            waits.episode_end(&e.expert.answer_waits, e.record.total_steps);
            checkpoints.episode_end(&e);
            Ok(ControlFlow::Continue(()))
        },
    )?;
    log_end(&end, &actor, &expert, &checkpoints);
    if end.stopped.is_none() {
        expert.leave()?;
        stay_until_stop(&session, &mut progress, me.incarnation)?;
    }
    Ok(())
}

/// This actor's episodes: its own seed stream, up to `quota` episodes (none: until the run
/// stops), no step limit of its own.
fn schedule(
    cfg: &alfd_common::config::ExperimentConfig,
    me: Identity,
    quota: Option<u32>,
) -> Schedule {
    Schedule {
        env_seed: build::env_seed(cfg, me.id, me.incarnation),
        episodes: quota,
        steps: None,
        actor_id: me.id,
    }
}

/// Waits for the learner's first weights; `false` when the run's end overtook a restarted actor
/// first (nothing to play, nothing lost).
fn first_weights(
    variables: &mut WireVariables<'_>,
    session: &Session<'_>,
    core: &mut NeuralActor,
    me: Identity,
    timeout: Duration,
) -> alfd_harness::Result<bool> {
    if let Some(stop) = variables.first(session, core, timeout)? {
        info!(
            reason = stop.0,
            "stopped before the learner's first weights arrived"
        );
        return Ok(false);
    }
    info!(
        actor = me.id,
        incarnation = me.incarnation,
        weights = core.weights_version(),
        "actor running"
    );
    Ok(true)
}

/// Its share played, the actor stays until the launcher says stop, since messages of a process
/// that has exited may never reach their receiver (its episodes, its last transitions). Every
/// second it says so on its episodes' publisher, with the number of records it sent
/// (`progress_kind::SHARE_PLAYED`): the launcher then knows of a last record lost on the way.
fn stay_until_stop(
    session: &Session<'_>,
    progress: &mut alfd_wire::Sender<'_, Progress>,
    incarnation: u64,
) -> alfd_harness::Result<()> {
    info!("played its share of the episodes; waiting for the run to end");
    let sent = progress.sent();
    let reason = loop {
        progress.send(Progress::share_played(incarnation, sent))?;
        if let Some(reason) = wait_for_stop(session, Duration::from_secs(1))? {
            break reason;
        }
    };
    info!(reason, "actor leaving");
    Ok(())
}

/// This actor's TensorBoard file: at each episode's end, the mean time it waited for the
/// expert's answers of that episode (`expert/answer_wait_ms`).
struct AnswerWaits {
    board: alfd_harness::tensorboard::Board,
    /// The answers already reported.
    seen: usize,
}

impl AnswerWaits {
    fn episode_end(&mut self, all: &[std::time::Duration], step: u64) {
        let new = &all[self.seen.min(all.len())..];
        self.seen = all.len();
        if new.is_empty() {
            return;
        }
        let ms = new.iter().map(|w| w.as_secs_f64() * 1e3).sum::<f64>() / new.len() as f64;
        let tag = "expert/answer_wait_ms".to_owned();
        self.board.scalars(step, &[(tag, ms as f32)]);
    }
}

/// How the actor's run ended, with what waiting and checkpoints cost it.
fn log_end(
    end: &environment_loop::RunEnd,
    actor: &GenericActor<WireAdder<'_, '_>, WireVariables<'_>>,
    expert: &WireExpert<'_, '_>,
    checkpoints: &Checkpoints<'_>,
) {
    let waits = &expert.answer_waits;
    info!(
        reason = end.stopped.map_or("done", |s| s.0),
        episodes = end.progress.episodes,
        steps = end.progress.steps,
        timeouts = expert.timeouts,
        answers = waits.len(),
        answer_wait_p50_ms = quantile_ms(waits, 0.5),
        answer_wait_p99_ms = quantile_ms(waits, 0.99),
        answer_wait_max_ms = quantile_ms(waits, 1.0),
        credit_waits = actor.adder.credit_waits,
        credit_wait_s = actor.adder.credit_wait.as_secs_f64(),
        checkpoints = checkpoints.written,
        checkpoint_write_s = checkpoints.time.as_secs_f64(),
        "actor stopping"
    );
}

/// The `q` quantile of `waits` in milliseconds (the nearest rank: the smallest wait with at least
/// a share `q` of them at or below it); 0 without any.
fn quantile_ms(waits: &[Duration], q: f64) -> f64 {
    if waits.is_empty() {
        return 0.0;
    }
    let mut sorted = waits.to_vec();
    sorted.sort_unstable();
    let rank = (q * sorted.len() as f64).ceil().max(1.0) as usize;
    sorted[rank.min(sorted.len()) - 1].as_secs_f64() * 1e3
}

/// This actor's id and incarnation, checked.
fn identity(args: &Args) -> alfd_harness::Result<Identity> {
    if args.actor_id as usize >= MAX_ACTORS {
        let id = args.actor_id;
        return Err(BadInput(format!("--actor-id must be below {MAX_ACTORS}, got {id}")).into());
    }
    if args.incarnation < 1 {
        return Err(BadInput("--incarnation must be at least 1".into()).into());
    }
    Ok(Identity {
        id: args.actor_id,
        incarnation: args.incarnation,
    })
}

/// The expert as this actor's client: budget, shaping schedule and timeouts of the run, and the
/// run's prior demonstrations (`RUN_DIR/prior-demos.jsonl`), which its model counts too.
/// Where the actor's transitions go: batches under the learner's credits, polled as
/// `ALFD_CREDIT_POLL_US` says (waiting on the doorbell by default).
fn wire_adder<'s, 'w>(
    session: &'s Session<'w>,
    me: Identity,
    window: u64,
    obs_dim: usize,
    heads: usize,
) -> alfd_harness::Result<WireAdder<'s, 'w>> {
    let poll = machine::credit_poll(std::env::var(machine::CREDIT_POLL_VAR).ok().as_deref());
    if !poll.is_zero() {
        // Polls of the doorbell sleep 200 µs, not up to 250 µs as with the default slack.
        alfd_harness::set_timer_slack(Duration::from_micros(1));
    }
    WireAdder::new(session, me, window, CreditPoll::new(poll), obs_dim, heads)
}

fn wire_expert<'s, 'w>(
    session: &'s Session<'w>,
    me: Identity,
    setup: &alfd_harness::Setup,
    run_dir: &std::path::Path,
) -> alfd_harness::Result<WireExpert<'s, 'w>> {
    let (cfg, runtime) = (&setup.config, &setup.runtime);
    let schedule = cfg.shaping_enabled().then(|| cfg.shaping.schedule());
    let (obs_dim, actions) = setup.env_dims()?;
    let prior = alfd_harness::read_prior(run_dir, obs_dim, actions)?.len();
    Ok(WireExpert::new(
        session,
        me,
        (cfg.budget(), obs_dim),
        schedule,
        runtime.query_timeout(),
    )?
    .with_human_timeout(runtime.query_timeout_for(alfd_harness::HUMAN_EXPERT))
    .with_person_among_experts(
        cfg.experts
            .iter()
            .any(|e| e.name == alfd_harness::HUMAN_EXPERT),
    )
    .with_prior_demos(prior))
}

/// The actor's checkpoints: every `checkpoint_every` updates' worth of global steps, between two
/// episodes, each appended to `RUN_DIR/actor-<id>.ckpt` with the earlier ones it keeps.
struct Checkpoints<'a> {
    cadence: Cadence,
    saved: checkpoint::ActorCheckpoints,
    /// The episodes this actor plays (none is saved after its last).
    quota: Option<u32>,
    run_dir: &'a std::path::Path,
    id: u16,
    config_toml: &'a str,
    written: u32,
    time: Duration,
}

type ActorEnd<'e, 's, 'w> = EpisodeEnd<
    'e,
    VectorEnv,
    GenericActor<WireAdder<'s, 'w>, WireVariables<'w>>,
    WireExpert<'s, 'w>,
>;

impl<'a> Checkpoints<'a> {
    /// Every `every` global steps, continuing from the checkpoint `restored` from.
    fn new(
        run_dir: &'a std::path::Path,
        id: u16,
        config_toml: &'a str,
        every: u64,
        quota: Option<u32>,
        restored: Option<checkpoint::ActorCheckpoint>,
    ) -> Self {
        Self {
            cadence: Cadence::new(every, restored.as_ref().map_or(0, |c| c.global_step)),
            saved: checkpoint::ActorCheckpoints {
                slots: restored.into_iter().collect(),
            },
            quota,
            run_dir,
            id,
            config_toml,
            written: 0,
            time: Duration::ZERO,
        }
    }

    /// An episode ended: saves the state between it and the next if the cadence says so. A
    /// checkpoint that cannot be written (a full disk) is said in the log and the actor goes
    /// on: the file keeps its earlier states whole, and the next one is tried at the cadence.
    fn episode_end(&mut self, e: &ActorEnd<'_, '_, '_>) {
        if self.quota.is_some_and(|q| e.progress.episodes >= q) {
            return;
        }
        let global_step = e.actor.global_step(e.progress.steps);
        if !self.cadence.episode_end(global_step) {
            return;
        }
        self.saved.push(checkpoint::ActorCheckpoint {
            progress: e.progress,
            global_step,
            core: e.actor.core.snapshot(),
            env: e.env.snapshot(),
            expert: e.expert.view().clone(),
        });
        let t = std::time::Instant::now();
        if let Err(e) = checkpoint::save(self.run_dir, self.id, &self.saved, self.config_toml) {
            tracing::warn!(
                "checkpoint not written ({}); the earlier states stay, the next is tried at the \
                 cadence",
                alfd_harness::describe(&e)
            );
            return;
        }
        self.time += t.elapsed();
        self.written += 1;
    }
}

/// Puts a checkpoint's state into the actor's pieces; the progress it continues from.
/// The run's `config.toml` and, for an actor restarted from a checkpoint, that checkpoint.
fn restored(
    args: &Args,
    id: u16,
) -> alfd_harness::Result<(String, Option<checkpoint::ActorCheckpoint>)> {
    let run_dir = &args.process.run_dir;
    let config_toml = std::fs::read_to_string(run_dir.join("config.toml"))
        .map_err(|e| BadInput(format!("cannot read the run's config.toml: {e}")))?;
    let restored = (args.restore_step)
        .map(|step| restore(run_dir, id, step, &config_toml))
        .transpose()?;
    Ok((config_toml, restored))
}

fn continue_from(
    c: &checkpoint::ActorCheckpoint,
    core: &mut NeuralActor,
    env: &mut VectorEnv,
    adder: &mut WireAdder<'_, '_>,
    expert: &mut WireExpert<'_, '_>,
) -> Result<environment_loop::Progress, BadInput> {
    let bad = |e: &dyn std::fmt::Display| BadInput(format!("actor checkpoint: {e}"));
    core.restore(&c.core).map_err(|e| bad(&e))?;
    env.restore(&c.env).map_err(|e| bad(&e))?;
    adder.restored(c.progress.steps);
    expert.restore_view(c.expert.clone());
    Ok(c.progress)
}

/// The state `RUN_DIR/actor-<id>.ckpt` holds for global step `step` (the weights come from the
/// learner, restored from the checkpoint that pairs with this one).
fn restore(
    run_dir: &std::path::Path,
    id: u16,
    step: u64,
    config_toml: &str,
) -> alfd_harness::Result<checkpoint::ActorCheckpoint> {
    let path = checkpoint::path(run_dir, id);
    let file = checkpoint::load(run_dir, id, config_toml)?.ok_or_else(|| {
        BadInput(format!(
            "--restore-step {step}: {} does not exist",
            path.display()
        ))
    })?;
    let c = file.at(step).ok_or_else(|| {
        BadInput(format!(
            "--restore-step {step}: {} holds no state at that step",
            path.display()
        ))
    })?;
    info!(
        episodes = c.progress.episodes,
        steps = c.progress.steps,
        global_step = step,
        "restored from the checkpoint"
    );
    Ok(c.clone())
}

/// Waits until the launcher says stop or a termination signal arrives, for at most `patience`;
/// the reason, `None` if neither came.
fn wait_for_stop(
    session: &Session<'_>,
    patience: Duration,
) -> alfd_harness::Result<Option<&'static str>> {
    let deadline = std::time::Instant::now() + patience;
    while std::time::Instant::now() < deadline {
        if let Some(stop) = session.should_stop()? {
            return Ok(Some(stop.0));
        }
        if let Some(stop) = session.wait(Duration::from_millis(100))? {
            return Ok(Some(stop.0));
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answer_wait_quantiles_take_the_nearest_rank() {
        let ms = |v: &[u64]| {
            v.iter()
                .map(|&m| Duration::from_millis(m))
                .collect::<Vec<_>>()
        };
        assert_eq!(quantile_ms(&[], 0.99), 0.0);
        let waits = ms(&[5, 1, 4, 2, 3]);
        assert_eq!(quantile_ms(&waits, 0.5), 3.0);
        assert_eq!(quantile_ms(&waits, 0.99), 5.0);
        assert_eq!(quantile_ms(&waits, 0.0), 1.0);
        // 100 waits, one slow: the 99th percentile is the 99th smallest, not the slow one.
        let mut many = ms(&[1; 99]);
        many.push(Duration::from_millis(500));
        assert_eq!(quantile_ms(&many, 0.99), 1.0);
        assert_eq!(quantile_ms(&many, 1.0), 500.0);
    }
}
