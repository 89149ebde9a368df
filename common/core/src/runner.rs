//! The single-process runner: one experiment config, Algorithm 1 in one process, deterministic
//! from the config's seed. It builds the pieces and hands them to the one
//! [`environment_loop::run`] with in-memory transports; it returns the episode records (writing
//! them is the caller's business: [`crate::record::episodes_csv`]).

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use crate::agent::build;
use crate::agent::{
    ActorSnapshot, Demonstrator, ExpertCore, ExpertSnapshot, LearnerSnapshot, PriorDemo,
    TabularAgent, TabularSnapshot,
};
use crate::checkpoint::StateMismatch;
use crate::config::ExperimentConfig;
use crate::demo_model::DemoModel;
use crate::env::{vector_env, EnvState, TabularEnv, VectorEnv};
use crate::environment_loop::in_process::{LearnerHandle, LocalExpert};
use crate::environment_loop::panel_expert::{PanelAsk, PanelLog};
use crate::environment_loop::{self, ExpertClient, GenericActor, Progress, Schedule};
use crate::evaluate::evaluate_greedy_advised;
use crate::nn::Mlp;
use crate::record::EpisodeRecord;

/// What a tabular run leaves behind.
#[derive(Debug, Clone)]
pub struct TabularRun {
    pub records: Vec<EpisodeRecord>,
    /// The greedy policy learned (mean over heads).
    pub greedy_policy: Vec<usize>,
    pub agent: TabularAgent,
    /// The demonstrations of the run, in the order they were given.
    pub demos: Vec<crate::agent::DemoRecord>,
    /// With several experts: who answered, at what cost, and their qualities over the run.
    pub panel: Option<PanelLog>,
}

/// What a neural run leaves behind.
#[derive(Debug, Clone)]
pub struct NeuralRun {
    pub records: Vec<EpisodeRecord>,
    pub network: Mlp,
    pub expert: ExpertCore,
    /// With several experts: who answered, at what cost, and their qualities over the run.
    pub panel: Option<PanelLog>,
    /// Environment steps taken, the episode cut short by a step limit included.
    pub env_steps: u64,
    /// The learner's updates.
    pub updates: u64,
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

    /// After `done` episodes (the last one recorded): `stop` if the caller's observer says so,
    /// else what `save` says of `state()` when a checkpoint is due (every `every` episodes, not
    /// after the run's last, `limit`).
    fn after_episode(
        &self,
        stop: ControlFlow<()>,
        done: u32,
        limit: Option<u32>,
        save: &mut impl FnMut(&S) -> ControlFlow<()>,
        state: impl FnOnce() -> S,
    ) -> ControlFlow<()> {
        let due = self.every.is_some_and(|n| done.is_multiple_of(n.max(1)))
            && limit.is_none_or(|l| done < l);
        if stop.is_break() || !due {
            return stop;
        }
        save(&state())
    }
}

/// The schedule of the single-process run (actor 0, the `env` seed stream).
fn schedule(cfg: &ExperimentConfig) -> Schedule {
    Schedule {
        env_seed: build::env_seed(cfg, 0, 1),
        episodes: cfg.episode_limit(),
        steps: cfg.step_limit(),
        actor_id: 0,
    }
}

/// Runs a tabular experiment (CliffWalk, DeepSea's cells) on `env` with `demonstrator` as the
/// expert. `on_episode` sees each record and the agent as each episode completes (progress,
/// evaluation) and may stop the run early with `ControlFlow::Break`.
///
/// # Panics
/// If the config's gate is `oracle` ([`run_tabular_checkpointed`] takes the oracle).
pub fn run_tabular<E: TabularEnv>(
    cfg: &ExperimentConfig,
    env: E,
    demonstrator: &mut dyn Demonstrator<usize>,
    on_episode: impl FnMut(&EpisodeRecord, &TabularAgent) -> ControlFlow<()>,
) -> TabularRun {
    run_tabular_checkpointed(
        cfg,
        env,
        (demonstrator, Vec::new()),
        None,
        Checkpoints::none(),
        |_| ControlFlow::Continue(()),
        on_episode,
    )
    .expect("a run from scratch restores nothing")
}

/// [`run_tabular`] with the `[[experts]]` of `cfg` (`experts`: the demonstrator, and the
/// experts' demonstrators in order, none when the one expert answers), checkpoints (see
/// [`Checkpoints`]) and the expert gate `oracle` consults (needed by that gate only). With
/// `evaluation.every`, each evaluation plays the greedy policy of the heads' mean on a copy of
/// `env`.
///
/// # Panics
/// If the config's gate is `oracle` and `oracle` is `None`.
pub fn run_tabular_checkpointed<E: TabularEnv>(
    cfg: &ExperimentConfig,
    mut env: E,
    (demonstrator, panel): (&mut dyn Demonstrator<usize>, TabularPanel),
    oracle: Option<crate::query::Oracle<usize>>,
    checkpoints: Checkpoints<'_, TabularRunState>,
    mut save: impl FnMut(&TabularRunState) -> ControlFlow<()>,
    mut on_episode: impl FnMut(&EpisodeRecord, &TabularAgent) -> ControlFlow<()>,
) -> Result<TabularRun, StateMismatch> {
    let mut agent = build::tabular_agent(cfg, env.num_states(), env.num_actions());
    if agent.needs_oracle() {
        agent.set_oracle(oracle.expect("gate `oracle` is given its oracle"));
    }
    let mut eval_env = env.clone();
    let eval_seed = build::eval_seed(cfg);
    let core = ExpertCore::for_config(cfg, env.num_actions());
    // Tabular runs shape no reward.
    let mut expert = local_expert(cfg, core, demonstrator, panel, false);
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
    let limit = cfg.episode_limit();
    environment_loop::run_from(
        &mut env,
        &mut agent,
        &mut expert,
        schedule(cfg),
        progress,
        |e| {
            if cfg.evaluation.due(e.record.episode) {
                let policy = e.actor.greedy_policy();
                let returns = crate::evaluate::evaluate(
                    &mut eval_env,
                    cfg.evaluation.episodes as usize,
                    eval_seed,
                    |&s| policy[s],
                )?;
                e.record.eval_return = returns.iter().sum::<f64>() / returns.len().max(1) as f64;
            }
            records.push(*e.record);
            let stop = on_episode(e.record, e.actor);
            Ok(
                checkpoints.after_episode(stop, e.progress.episodes, limit, &mut save, || {
                    TabularRunState {
                        progress: e.progress,
                        records: records.clone(),
                        agent: e.actor.snapshot(),
                        env: e.env.snapshot(),
                        expert: e.expert.core.snapshot(),
                    }
                }),
            )
        },
    )
    .expect("an in-process tabular run cannot fail");
    let (core, panel) = expert.into_parts();
    Ok(TabularRun {
        records,
        greedy_policy: agent.greedy_policy(),
        agent,
        demos: core.snapshot().demos,
        panel,
    })
}

/// The demonstration model and λ a greedy evaluation adds to the action values under look-ahead
/// advice (`shaping.kind = "advice"`), as the actor does at `step`; `None` otherwise.
pub fn advice<'e, E: ExpertClient<Vec<f32>> + ?Sized>(
    cfg: &ExperimentConfig,
    expert: &'e E,
    step: u64,
) -> Option<(&'e DemoModel, f64)> {
    cfg.shaping.kind.advice(expert.shaping(step))
}

/// The demonstrators of a tabular run's `[[experts]]`, in order.
pub type TabularPanel = Vec<Box<dyn Demonstrator<usize>>>;

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
    let env = vector_env(cfg).expect("a neural agent runs on a vector environment");
    let eval_env = vector_env(cfg).expect("the same environment");
    let envs = NeuralEnvs {
        env,
        eval_env,
        oracle: None,
        panel: Vec::new(),
    };
    let prior = &[];
    run_neural_on(
        cfg,
        envs,
        demonstrator,
        prior,
        checkpoints,
        save,
        on_episode,
    )
    .map_err(|e| match e {
        RunError::Mismatch(m) => m,
        RunError::Loop(e) => unreachable!("an in-process neural run cannot fail: {e}"),
        RunError::Prior(e) => unreachable!("a run without prior demonstrations fits none: {e}"),
        RunError::NoOracle => unreachable!("run_neural_checkpointed is not given gate `oracle`"),
    })
}

/// The environments of a neural run built outside the core (a Gymnasium environment in another
/// process): the one trained on and the one evaluated on.
pub struct NeuralEnvs {
    pub env: Box<VectorEnv>,
    pub eval_env: Box<VectorEnv>,
    /// The expert gate `oracle` consults (needed by that gate only).
    pub oracle: Option<crate::query::Oracle<[f32]>>,
    /// The demonstrators of `[[experts]]`, in order (empty: the one expert answers).
    pub panel: Vec<Box<dyn Demonstrator<[f32]>>>,
}

/// Why a run on environments of [`NeuralEnvs`] stopped short.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Mismatch(#[from] StateMismatch),
    /// The environment or the expert (in another process) failed.
    #[error("{0}")]
    Loop(#[from] environment_loop::LoopError),
    /// No demonstration model fits the prior demonstrations.
    #[error("the prior demonstrations (demos.prior): {0}")]
    Prior(crate::demo_model::DemoModelError),
    /// Gate `oracle` without an expert to consult in this process.
    #[error("gate `oracle` needs an expert it can consult at every step in this process (a built-in one)")]
    NoOracle,
}

/// The in-process expert of a run: `demonstrator`, or the `panel` of `[[experts]]`; `shaping`
/// says whether its model shapes the reward.
fn local_expert<'d, S: ?Sized>(
    cfg: &ExperimentConfig,
    core: ExpertCore,
    demonstrator: &'d mut dyn Demonstrator<S>,
    panel: Vec<Box<dyn Demonstrator<S>>>,
    shaping: bool,
) -> LocalExpert<'d, S> {
    let actions = core.num_actions();
    let expert = LocalExpert::new(core, demonstrator, &cfg.expert.name, shaping);
    if panel.is_empty() {
        return expert;
    }
    expert.with_panel(PanelAsk::new(cfg, panel, actions))
}

/// Where a neural run starts: its agent, expert and records, fresh (the `prior`
/// demonstrations in the replay buffer) or as the checkpoint `from` left them.
struct NeuralStart {
    learner: crate::agent::NeuralLearner,
    core: crate::agent::NeuralActor,
    expert_core: ExpertCore,
    records: Vec<EpisodeRecord>,
    progress: Progress,
}

/// The agent, expert and records of a neural run on `env` (restored into `from`'s state if
/// given), the `prior` demonstrations in its demonstration model.
fn neural_start(
    cfg: &ExperimentConfig,
    env: &mut VectorEnv,
    oracle: Option<crate::query::Oracle<[f32]>>,
    prior: &[PriorDemo],
    from: Option<&NeuralRunState>,
) -> Result<NeuralStart, RunError> {
    let (obs_dim, actions) = (env.observation_dim(), env.num_actions());
    let mut learner = build::neural_learner(cfg, obs_dim, actions);
    let mut core = build::neural_actor(cfg, obs_dim, actions, 0, 1);
    if core.needs_oracle() {
        core.set_oracle(oracle.ok_or(RunError::NoOracle)?);
    }
    let mut expert_core = ExpertCore::for_config(cfg, actions);
    if !prior.is_empty() {
        let records = prior.iter().enumerate().map(|(i, p)| p.record(i)).collect();
        expert_core.set_prior(records).map_err(RunError::Prior)?;
    }
    let Some(s) = from else {
        for p in prior {
            learner.insert(&p.transition(cfg.agent.heads()));
        }
        return Ok(NeuralStart {
            learner,
            core,
            expert_core,
            records: Vec::new(),
            progress: Progress::default(),
        });
    };
    learner.restore(&s.learner)?;
    core.restore(&s.actor)?;
    env.restore(&s.env)
        .map_err(|e| StateMismatch(e.to_string()))?;
    expert_core.restore_snapshot(&s.expert)?;
    Ok(NeuralStart {
        learner,
        core,
        expert_core,
        records: s.records.clone(),
        progress: s.progress,
    })
}

/// [`run_neural_checkpointed`] on the environments `envs` (the config's environment, made by
/// the caller), starting from the `prior` demonstrations (in the demonstration model, and in
/// the replay buffer of a run from scratch: a restored one holds them already); an environment
/// or expert that fails stops the run with [`RunError::Loop`].
pub fn run_neural_on(
    cfg: &ExperimentConfig,
    envs: NeuralEnvs,
    demonstrator: &mut dyn Demonstrator<[f32]>,
    prior: &[PriorDemo],
    checkpoints: Checkpoints<'_, NeuralRunState>,
    mut save: impl FnMut(&NeuralRunState) -> ControlFlow<()>,
    mut on_episode: impl FnMut(&EpisodeRecord, &Mlp) -> ControlFlow<()>,
) -> Result<NeuralRun, RunError> {
    let NeuralEnvs {
        mut env,
        mut eval_env,
        oracle,
        panel,
    } = envs;
    let NeuralStart {
        learner,
        core,
        expert_core,
        mut records,
        progress,
    } = neural_start(cfg, env.as_mut(), oracle, prior, checkpoints.from)?;
    let handle = LearnerHandle::new(learner);
    let mut actor = GenericActor::new(core, handle.adder(), handle.variables());
    let shaping = cfg.shaping_enabled();
    let mut expert = local_expert(cfg, expert_core, demonstrator, panel, shaping);
    let eval_seed = build::eval_seed(cfg);
    let limit = cfg.episode_limit();
    let end = environment_loop::run_from(
        env.as_mut(),
        &mut actor,
        &mut expert,
        schedule(cfg),
        progress,
        |e| {
            if cfg.evaluation.due(e.record.episode) {
                e.record.eval_return = evaluate_greedy_advised(
                    e.actor.core.network(),
                    advice(cfg, e.expert, e.record.total_steps),
                    eval_env.as_mut(),
                    cfg.evaluation.episodes,
                    eval_seed,
                )?;
            }
            records.push(*e.record);
            let stop = on_episode(e.record, handle.learner().network());
            Ok(
                checkpoints.after_episode(stop, e.progress.episodes, limit, &mut save, || {
                    NeuralRunState {
                        progress: e.progress,
                        records: records.clone(),
                        learner: handle.learner().snapshot(),
                        actor: e.actor.core.snapshot(),
                        env: e.env.snapshot(),
                        expert: e.expert.core.snapshot(),
                    }
                }),
            )
        },
    )?;
    drop(actor);
    let learner = handle.into_inner();
    let (expert, panel) = expert.into_parts();
    Ok(NeuralRun {
        records,
        network: learner.network().clone(),
        expert,
        panel,
        env_steps: end.progress.steps,
        updates: learner.updates(),
    })
}
