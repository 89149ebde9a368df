//! The single-process runner: one experiment config, Algorithm 1 in one process, deterministic
//! from the config's seed. It builds the pieces and hands them to the one
//! [`environment_loop::run`] with in-memory transports; it returns the episode records (writing
//! them is the caller's business: [`crate::record::episodes_csv`]).

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use crate::agent::{
    ActorSnapshot, Demonstrator, ExpertCore, ExpertSnapshot, LearnerSnapshot, NetworkDemonstrator,
    NeuralActor, NeuralLearner, TabularAgent, TabularSnapshot,
};
use crate::checkpoint::StateMismatch;
use crate::config::ExperimentConfig;
use crate::env::{vector_env, CartPole, CliffWalk, Env, EnvError, EnvState, VectorEnv};
use crate::environment_loop::in_process::{LearnerHandle, LocalExpert};
use crate::environment_loop::{self, GenericActor, Progress, Schedule};
use crate::nn::Mlp;
use crate::record::EpisodeRecord;
use crate::rng::{derive_seed, seeded};

/// What a tabular run leaves behind.
#[derive(Debug, Clone)]
pub struct TabularRun {
    pub records: Vec<EpisodeRecord>,
    /// The greedy policy learned (mean over heads).
    pub greedy_policy: Vec<usize>,
    pub agent: TabularAgent,
    /// The demonstrations of the run, in the order they were given.
    pub demos: Vec<crate::agent::DemoRecord>,
}

/// What a neural run leaves behind.
#[derive(Debug, Clone)]
pub struct NeuralRun {
    pub records: Vec<EpisodeRecord>,
    pub network: Mlp,
    pub expert: ExpertCore,
}

/// The whole learning state of a neural single-process run between two episodes, from which
/// it continues exactly as it would have. (The evaluation environment is reseeded at every
/// evaluation, so it carries no state; the shaping schedule is the config's applied to the
/// expert's demonstrations; the actor's potential-shaping transition is always flushed at the
/// end of an episode.)
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NeuralRunState {
    pub progress: Progress,
    /// The records of the episodes played so far.
    pub records: Vec<EpisodeRecord>,
    pub learner: LearnerSnapshot,
    pub actor: ActorSnapshot,
    pub env: EnvState,
    pub expert: ExpertSnapshot,
}

/// The whole learning state of a tabular single-process run between two episodes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TabularRunState {
    pub progress: Progress,
    pub records: Vec<EpisodeRecord>,
    pub agent: TabularSnapshot,
    pub env: EnvState,
    pub expert: ExpertSnapshot,
}

/// A checkpoint's state: either kind of run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum RunState {
    Neural(Box<NeuralRunState>),
    Tabular(Box<TabularRunState>),
}

impl RunState {
    pub fn progress(&self) -> Progress {
        match self {
            Self::Neural(s) => s.progress,
            Self::Tabular(s) => s.progress,
        }
    }

    pub fn records(&self) -> &[EpisodeRecord] {
        match self {
            Self::Neural(s) => &s.records,
            Self::Tabular(s) => &s.records,
        }
    }

    /// The state of a neural run, if it is one.
    pub fn neural(&self) -> Option<&NeuralRunState> {
        match self {
            Self::Neural(s) => Some(s),
            Self::Tabular(_) => None,
        }
    }

    /// The state of a tabular run, if it is one.
    pub fn tabular(&self) -> Option<&TabularRunState> {
        match self {
            Self::Tabular(s) => Some(s),
            Self::Neural(_) => None,
        }
    }

    pub fn demos(&self) -> &[crate::agent::DemoRecord] {
        match self {
            Self::Neural(s) => &s.expert.demos,
            Self::Tabular(s) => &s.expert.demos,
        }
    }
}

/// How a run is checkpointed: it starts from `from` (a state saved by an earlier run of the same
/// config) or from scratch, and hands its state to `save` after every `every` episodes (not
/// after its last one); `save` may stop the run.
#[derive(Debug, Clone, Copy)]
pub struct Checkpoints<'s, S> {
    pub from: Option<&'s S>,
    pub every: Option<u32>,
}

impl<S> Checkpoints<'_, S> {
    /// No checkpoints, from scratch.
    pub fn none() -> Self {
        Self {
            from: None,
            every: None,
        }
    }

    /// The episode limit of the segment that starts after `done` episodes.
    fn segment_end(&self, done: u32, limit: Option<u32>) -> Option<u32> {
        match self.every {
            None => limit,
            Some(n) => {
                let next = (done / n.max(1) + 1) * n.max(1);
                Some(limit.map_or(next, |l| l.min(next)))
            }
        }
    }
}

/// The expert's side of a config: budget B, demonstration model, shaping schedule.
pub fn expert_core(cfg: &ExperimentConfig, num_actions: usize) -> ExpertCore {
    ExpertCore::new(
        cfg.budget(),
        cfg.expert.model,
        num_actions,
        cfg.shaping.schedule(),
    )
}

/// The schedule of the single-process run (actor 0, the `env` seed stream).
fn schedule(cfg: &ExperimentConfig) -> Schedule {
    Schedule {
        env_seed: derive_seed(cfg.seed, "env"),
        episodes: cfg.episode_limit(),
        steps: cfg.step_limit(),
        actor_id: 0,
    }
}

/// Plays `cfg`'s run in segments between checkpoints with [`environment_loop::run_from`]:
/// `segment(schedule, progress, stopped)` plays one, `save(progress)` is called between two.
fn in_segments<S>(
    cfg: &ExperimentConfig,
    checkpoints: &Checkpoints<'_, S>,
    mut progress: Progress,
    mut segment: impl FnMut(Schedule, Progress, &mut bool) -> environment_loop::RunEnd,
    mut save: impl FnMut(Progress) -> ControlFlow<()>,
) {
    loop {
        let schedule = Schedule {
            episodes: checkpoints.segment_end(progress.episodes, cfg.episode_limit()),
            ..schedule(cfg)
        };
        let mut stopped = false;
        let end = segment(schedule, progress, &mut stopped);
        progress = end.progress;
        let over = stopped
            || end.stopped.is_some()
            || checkpoints.every.is_none()
            || cfg.episode_limit().is_some_and(|n| progress.episodes >= n);
        if over || save(progress).is_break() {
            return;
        }
    }
}

fn continue_unless(stop: bool) -> ControlFlow<()> {
    if stop {
        ControlFlow::Break(())
    } else {
        ControlFlow::Continue(())
    }
}

/// Runs a tabular experiment (CliffWalk) on `env` with `demonstrator` as the expert.
/// `on_episode` sees each record and the agent as each episode completes (progress, evaluation)
/// and may stop the run early with `ControlFlow::Break`.
pub fn run_tabular(
    cfg: &ExperimentConfig,
    env: CliffWalk,
    demonstrator: &mut dyn Demonstrator<usize>,
    on_episode: impl FnMut(&EpisodeRecord, &TabularAgent) -> ControlFlow<()>,
) -> TabularRun {
    run_tabular_checkpointed(
        cfg,
        env,
        demonstrator,
        Checkpoints::none(),
        |_| ControlFlow::Continue(()),
        on_episode,
    )
    .expect("a run from scratch restores nothing")
}

/// [`run_tabular`] with checkpoints (see [`Checkpoints`]).
pub fn run_tabular_checkpointed(
    cfg: &ExperimentConfig,
    mut env: CliffWalk,
    demonstrator: &mut dyn Demonstrator<usize>,
    checkpoints: Checkpoints<'_, TabularRunState>,
    mut save: impl FnMut(&TabularRunState) -> ControlFlow<()>,
    mut on_episode: impl FnMut(&EpisodeRecord, &TabularAgent) -> ControlFlow<()>,
) -> Result<TabularRun, StateMismatch> {
    let mut agent = TabularAgent::new(
        &cfg.agent,
        &cfg.query,
        env.num_states(),
        env.num_actions(),
        seeded(derive_seed(cfg.seed, "agent")),
    );
    let core = expert_core(cfg, env.num_actions());
    let mut expert = LocalExpert::new(core, demonstrator, &cfg.expert.name, false);
    let mut records = Vec::new();
    let mut progress = Progress::default();
    if let Some(s) = checkpoints.from {
        agent.restore(&s.agent)?;
        env.restore(&s.env)
            .map_err(|e| StateMismatch(e.to_string()))?;
        expert.core.restore_snapshot(&s.expert)?;
        records.clone_from(&s.records);
        progress = s.progress;
    }
    let records = std::cell::RefCell::new(records);
    let state = std::cell::RefCell::new((env, agent, expert));
    in_segments(
        cfg,
        &checkpoints,
        progress,
        |schedule, progress, stopped| {
            let (env, agent, expert) = &mut *state.borrow_mut();
            environment_loop::run_from(env, agent, expert, schedule, progress, |r, agent| {
                records.borrow_mut().push(*r);
                *stopped |= on_episode(r, agent).is_break();
                Ok(continue_unless(*stopped))
            })
            .expect("an in-process tabular run cannot fail")
        },
        |progress| {
            let (env, agent, expert) = &*state.borrow();
            save(&TabularRunState {
                progress,
                records: records.borrow().clone(),
                agent: agent.snapshot(),
                env: env.snapshot(),
                expert: expert.core.snapshot(),
            })
        },
    );
    let (_, agent, expert) = state.into_inner();
    Ok(TabularRun {
        records: records.into_inner(),
        greedy_policy: agent.greedy_policy(),
        agent,
        demos: expert.core.snapshot().demos,
    })
}

/// Runs a neural experiment (the config's environment, e.g. CartPole): Algorithm 1 with the
/// actor and the learner in one process, the actor acting on the learner's newest weights at
/// every step. `on_episode` sees each record and the learner's network, and may stop the run
/// early.
///
/// # Panics
/// If the config's environment has no vector observations (a tabular config: a validated
/// [`ExperimentConfig`] never pairs it with a neural agent).
pub fn run_neural(
    cfg: &ExperimentConfig,
    demonstrator: &mut dyn Demonstrator<[f32]>,
    on_episode: impl FnMut(&EpisodeRecord, &Mlp) -> ControlFlow<()>,
) -> NeuralRun {
    run_neural_checkpointed(
        cfg,
        demonstrator,
        Checkpoints::none(),
        |_| ControlFlow::Continue(()),
        on_episode,
    )
    .expect("a run from scratch restores nothing")
}

/// [`run_neural`] with checkpoints (see [`Checkpoints`]).
pub fn run_neural_checkpointed(
    cfg: &ExperimentConfig,
    demonstrator: &mut dyn Demonstrator<[f32]>,
    checkpoints: Checkpoints<'_, NeuralRunState>,
    save: impl FnMut(&NeuralRunState) -> ControlFlow<()>,
    on_episode: impl FnMut(&EpisodeRecord, &Mlp) -> ControlFlow<()>,
) -> Result<NeuralRun, StateMismatch> {
    let env = vector_env(&cfg.env).expect("a neural agent runs on a vector environment");
    let eval_env = vector_env(&cfg.env).expect("the same environment");
    let envs = NeuralEnvs { env, eval_env };
    run_neural_on(cfg, envs, demonstrator, checkpoints, save, on_episode).map_err(|e| match e {
        RunError::Mismatch(m) => m,
        RunError::Loop(e) => unreachable!("an in-process neural run cannot fail: {e}"),
    })
}

/// The environments of a neural run built outside the core (a Gymnasium environment in another
/// process): the one trained on and the one evaluated on.
pub struct NeuralEnvs {
    pub env: Box<VectorEnv>,
    pub eval_env: Box<VectorEnv>,
}

/// Why a run on environments of [`NeuralEnvs`] stopped short.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Mismatch(#[from] StateMismatch),
    /// The environment or the expert (in another process) failed.
    #[error("{0}")]
    Loop(#[from] environment_loop::LoopError),
}

/// [`run_neural_checkpointed`] on the environments `envs` (the config's environment, made by
/// the caller); an environment or expert that fails stops the run with [`RunError::Loop`].
pub fn run_neural_on(
    cfg: &ExperimentConfig,
    envs: NeuralEnvs,
    demonstrator: &mut dyn Demonstrator<[f32]>,
    checkpoints: Checkpoints<'_, NeuralRunState>,
    mut save: impl FnMut(&NeuralRunState) -> ControlFlow<()>,
    mut on_episode: impl FnMut(&EpisodeRecord, &Mlp) -> ControlFlow<()>,
) -> Result<NeuralRun, RunError> {
    let NeuralEnvs {
        mut env,
        mut eval_env,
    } = envs;
    let (obs_dim, actions) = (env.observation_dim(), env.num_actions());
    let mut learner = NeuralLearner::new(
        &cfg.agent,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, "learner")),
    );
    let mut core = NeuralActor::new(
        &cfg.agent,
        &cfg.query,
        cfg.shaping.kind,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, "actor-0")),
    );
    let mut expert_core = expert_core(cfg, actions);
    let mut records = Vec::new();
    let mut progress = Progress::default();
    if let Some(s) = checkpoints.from {
        learner.restore(&s.learner)?;
        core.restore(&s.actor)?;
        env.restore(&s.env)
            .map_err(|e| StateMismatch(e.to_string()))?;
        expert_core.restore_snapshot(&s.expert)?;
        records.clone_from(&s.records);
        progress = s.progress;
    }
    let handle = LearnerHandle::new(learner);
    let actor = GenericActor::new(core, handle.adder(), handle.variables());
    let expert = LocalExpert::new(
        expert_core,
        demonstrator,
        &cfg.expert.name,
        cfg.shaping_enabled(),
    );
    let eval_seed = derive_seed(cfg.seed, "eval");
    let records = std::cell::RefCell::new(records);
    let failure = std::cell::RefCell::new(None);
    let state = std::cell::RefCell::new((env, actor, expert));
    in_segments(
        cfg,
        &checkpoints,
        progress,
        |schedule, progress, stopped| {
            let (env, actor, expert) = &mut *state.borrow_mut();
            environment_loop::run_from(
                env.as_mut(),
                actor,
                expert,
                schedule,
                progress,
                |r, actor| {
                    if cfg.evaluation.due(r.episode) {
                        r.eval_return = evaluate_greedy(
                            actor.core.network(),
                            eval_env.as_mut(),
                            cfg.evaluation.episodes,
                            eval_seed,
                        )?;
                    }
                    records.borrow_mut().push(*r);
                    *stopped |= on_episode(r, handle.learner().network()).is_break();
                    Ok(continue_unless(*stopped))
                },
            )
            .unwrap_or_else(|e| {
                // Only an environment or expert in another process fails: the run stops here.
                *failure.borrow_mut() = Some(e);
                environment_loop::RunEnd {
                    progress,
                    stopped: Some(environment_loop::Stop("failed")),
                }
            })
        },
        |progress| {
            let (env, actor, expert) = &*state.borrow();
            save(&NeuralRunState {
                progress,
                records: records.borrow().clone(),
                learner: handle.learner().snapshot(),
                actor: actor.core.snapshot(),
                env: env.snapshot(),
                expert: expert.core.snapshot(),
            })
        },
    );
    if let Some(e) = failure.into_inner() {
        return Err(RunError::Loop(e));
    }
    let (_, actor, expert) = state.into_inner();
    drop(actor);
    Ok(NeuralRun {
        records: records.into_inner(),
        network: handle.into_inner().network().clone(),
        expert: expert.core,
    })
}

/// Mean return of `episodes` episodes of `env` played greedily by `net` (on the mean of its
/// heads' Q-values), the first reset seeded with `seed`: the `eval_return` of a record.
pub fn evaluate_greedy(
    net: &Mlp,
    env: &mut VectorEnv,
    episodes: u32,
    seed: u64,
) -> Result<f64, EnvError> {
    Ok(q_range(net, env, episodes, seed)?.mean_return)
}

/// The Q-values a network takes on its own greedy episodes ([`q_range`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QRange {
    /// The smallest and the largest Q-value of any head and action at any state visited.
    pub min: f64,
    pub max: f64,
    /// The mean return of the episodes.
    pub mean_return: f64,
}

/// Plays `episodes` greedy episodes of `env` with `net` (on the mean of its heads), the first
/// reset seeded with `seed`: their mean return ([`evaluate_greedy`]) and the range of every
/// Q-value computed on the way, a check for divergence against [`value_bounds`].
pub fn q_range(
    net: &Mlp,
    env: &mut VectorEnv,
    episodes: u32,
    seed: u64,
) -> Result<QRange, EnvError> {
    let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut policy = NetworkDemonstrator::new(net.clone());
    let returns = evaluate(env, episodes as usize, seed, |obs| {
        let action = policy.act(obs);
        for &v in policy.last_q() {
            min = min.min(f64::from(v));
            max = max.max(f64::from(v));
        }
        action
    })?;
    Ok(QRange {
        min,
        max,
        mean_return: returns.iter().sum::<f64>() / returns.len().max(1) as f64,
    })
}

/// The range every true value lies in when each step's reward is in `[r_min, r_max]` and the
/// discount is `gamma < 1`: `[min(0, r_min), max(0, r_max)] / (1 - gamma)` (an episode may end
/// at any step, so 0 is always reachable). CartPole-1000 at γ = 0.995: `[0, 200]`.
pub fn value_bounds((r_min, r_max): (f64, f64), gamma: f64) -> (f64, f64) {
    (
        r_min.min(0.0) / (1.0 - gamma),
        r_max.max(0.0) / (1.0 - gamma),
    )
}

/// Returns of `episodes` episodes of `env` played by `act`, the first reset seeded with `seed`;
/// the environment's error if a step fails (one in another process that died, say).
pub fn evaluate<E: Env + ?Sized>(
    env: &mut E,
    episodes: usize,
    seed: u64,
    mut act: impl FnMut(&E::Observation) -> usize,
) -> Result<Vec<f64>, EnvError> {
    (0..episodes)
        .map(|i| {
            let mut obs = env.reset(if i == 0 { Some(seed) } else { None });
            let mut ret = 0.0;
            loop {
                let step = env.step(act(&obs))?;
                ret += step.reward;
                let done = step.done();
                obs = step.observation;
                if done {
                    return Ok(ret);
                }
            }
        })
        .collect()
}

/// Returns of `episodes` CartPole episodes (limit `max_steps`) played by `policy`.
pub fn evaluate_cartpole(
    policy: &mut dyn Demonstrator<[f32]>,
    episodes: usize,
    seed: u64,
    max_steps: usize,
) -> Vec<f64> {
    evaluate(&mut CartPole::new(max_steps), episodes, seed, |obs| {
        policy.act(obs)
    })
    .expect("the native CartPole steps every action of a live episode")
}

/// Returns of `episodes` CliffWalk episodes played by `policy` on a clone of `env`.
pub fn evaluate_cliffwalk(
    policy: &mut dyn Demonstrator<usize>,
    env: &CliffWalk,
    episodes: usize,
    seed: u64,
) -> Vec<f64> {
    evaluate(&mut env.clone(), episodes, seed, |s| policy.act(s))
        .expect("the native CliffWalk steps every action of a live episode")
}
