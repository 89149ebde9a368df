//! The step of Algorithm 1, written once: [`run`] plays episodes of an environment with an
//! [`Actor`] and an [`ExpertClient`], whatever connects them to the learner and to the expert.
//!
//! This is Acme's `EnvironmentLoop` driving a `GenericActor(actor_core, variable_client, adder)`,
//! in the paper's words. What differs between one process and many is only what is passed in:
//! - the [`ExpertClient`] (ask for a demonstration, the budget left, the shaping model): an
//!   in-memory [`ExpertCore`](crate::agent::ExpertCore) in one process
//!   ([`in_process::LocalExpert`]), a query over the wire in the actor process;
//! - for the neural agents, the [`Adder`] (where transitions go: Acme's adder) and the
//!   [`VariableSource`] (where the newest weights come from: Acme's variable client), combined
//!   with the pure [`NeuralActor`] by [`GenericActor`]: the learner in the same process
//!   ([`in_process::LearnerHandle`]) or the learner process over the wire.
//!
//! The tabular agents learn where they act: [`TabularAgent`] is an
//! [`Actor`] by itself.
//!
//! Nothing here does I/O; a transport's errors reach the caller as [`LoopError::Link`].

pub mod in_process;
pub mod panel_expert;

use std::ops::ControlFlow;

use crate::agent::{Decision, NeuralActor, TabularAgent};
use crate::demo_model::DemoModel;
use crate::env::{Env, EnvError, Step};
use crate::n_step::NStep;
use crate::query::BudgetView;
use crate::record::EpisodeRecord;
use crate::replay::Transition;
use crate::shaping::potential_bonus;

/// Why a run stopped before its last episode (the launcher said so, a signal arrived, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stop(pub &'static str);

/// What can go wrong in the loop: the environment refused a step, or a transport failed.
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// Its message is the environment's (not also given as the source, so that `{:#}` does not
    /// print it twice).
    #[error("environment: {0}")]
    Env(EnvError),
    #[error(transparent)]
    Link(Box<dyn std::error::Error + Send + Sync>),
    /// An observer of an episode's end failed (a checkpoint that could not be written).
    #[error("{0}")]
    Observer(Box<dyn std::error::Error + Send + Sync>),
}

impl From<EnvError> for LoopError {
    fn from(e: EnvError) -> Self {
        Self::Env(e)
    }
}

impl LoopError {
    /// Wraps a transport's error.
    pub fn link(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        Self::Link(e.into())
    }

    /// Wraps the error of an episode's observer.
    pub fn observer(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> Self {
        Self::Observer(e.into())
    }
}

pub type Result<T, E = LoopError> = std::result::Result<T, E>;

/// The acting agent's side of the expert (Algorithm 1 lines 8-10 and 18).
pub trait ExpertClient<O: ?Sized> {
    /// Takes in what changed on the expert's side since the last step (a refitted model, the
    /// budget); called once before every step.
    fn update(&mut self) -> Result<()> {
        Ok(())
    }
    /// Whether budget B has demonstrations left, as far as this actor knows.
    fn budget_left(&self) -> bool;
    /// Budget B as this actor knows it: whether any is left, how much is used.
    fn budget(&self) -> BudgetView {
        BudgetView {
            left: self.budget_left(),
            used: u64::from(self.demos_used()),
        }
    }
    /// Asks for a demonstration at `obs`, the run's global step `step`: `Some(action)` if the
    /// expert gave one (and spent one unit of budget on it), `None` if it did not (budget
    /// exhausted, no expert, no answer in time): the agent then acts on its own.
    fn ask(&mut self, obs: &O, step: u64) -> Result<Option<usize>>;
    /// The demonstration model and λ to shape the reward of global step `step` with (eq. 4),
    /// or `None` when shaping is off then.
    fn shaping(&self, step: u64) -> Option<(&DemoModel, f64)>;
    /// Demonstrations used in the run so far, as far as this actor knows.
    fn demos_used(&self) -> u32;
    /// This actor's episode ended with the (unshaped) return `ret`; with several experts, the
    /// next query tells the experts (`expert.quality_from_returns`).
    fn episode_ended(&mut self, _ret: f64) {}
}

/// An agent that acts in an environment (Acme's `Actor`: `select_action` / `observe` / `update`).
pub trait Actor<O> {
    /// Before every step: take in the newest weights, wait for flow control. `Break` stops the
    /// run (in the middle of an episode if need be).
    fn update(&mut self) -> Result<ControlFlow<Stop>> {
        Ok(ControlFlow::Continue(()))
    }
    /// The run's global step of this actor's next step, given the steps it took itself (the same
    /// number when it is the only actor).
    fn global_step(&self, own_steps: u64) -> u64 {
        own_steps
    }
    /// Algorithm 1 line 1: sample the head to follow this episode.
    fn begin_episode(&mut self);
    /// Algorithm 1 lines 3-16 but the asking: the divergence of the heads at `obs` (the run's
    /// global step `step`), whether the query rule fires (only while budget is left), and the
    /// agent's own action.
    ///
    /// `advice` is the demonstration model and λ that shape this step's reward, which an agent
    /// with look-ahead advice (`shaping.kind = "advice"`) adds to its action values.
    fn select(
        &mut self,
        obs: &O,
        step: u64,
        budget: BudgetView,
        advice: Option<(&DemoModel, f64)>,
    ) -> Decision;
    /// Algorithm 1 lines 17-20: learn from (or hand on) the step taken with `action` from `obs`,
    /// with the reward shaped when `shaping` is given. Returns whether the reward was shaped.
    fn observe(
        &mut self,
        obs: &O,
        action: usize,
        step: &Step<O>,
        demo: bool,
        shaping: Option<(&DemoModel, f64)>,
    ) -> Result<bool>;
    /// The episode is over (a transport flushes what it batched).
    fn end_episode(&mut self) -> Result<()> {
        Ok(())
    }
}

/// Where an actor's transitions go (Acme's adder).
pub trait Adder {
    /// Before every step: wait, if the learner is too far behind, until one more transition may
    /// be added. `Break` stops the run.
    fn reserve(&mut self) -> Result<ControlFlow<Stop>> {
        Ok(ControlFlow::Continue(()))
    }
    /// Hands one transition on (`episode_end`: the last of its episode, which ended there,
    /// terminated or truncated).
    fn add(&mut self, transition: Transition, episode_end: bool) -> Result<()>;
    /// The episode is over.
    fn end_episode(&mut self) -> Result<()> {
        Ok(())
    }
    /// The run's global step of the next transition, given the transitions this actor added.
    fn global_step(&self, own_steps: u64) -> u64 {
        own_steps
    }
}

/// Where an actor's weights come from (Acme's variable client).
pub trait VariableSource {
    /// Puts the newest weights into `actor` if there are newer ones than it has.
    fn update(&mut self, actor: &mut NeuralActor) -> Result<()>;
}

/// The neural agent of Algorithm 1 as an [`Actor`]: the pure [`NeuralActor`] (divergence, query
/// rule, exploration, shaping, masks), an [`Adder`] and a [`VariableSource`].
///
/// With potential-based shaping a transition's bonus `γΦ(s',a') − Φ(s,a)` needs the next action
/// `a'`, so each transition waits for the next step before it goes to the adder (the last one of
/// an episode goes at once, with `Φ = 0` after it). With `agent.n_step > 1` the transitions then
/// pass through [`NStep`] on their way to the adder.
#[derive(Debug)]
pub struct GenericActor<A, V> {
    pub core: NeuralActor,
    pub adder: A,
    pub variables: V,
    /// Potential shaping: the last transition and its potential `Φ(s,a)`.
    pending: Option<(Transition, f64)>,
    /// n-step returns (`None`: one-step transitions go to the adder as they are).
    n_step: Option<NStep>,
}

impl<A: Adder, V: VariableSource> GenericActor<A, V> {
    pub fn new(core: NeuralActor, adder: A, variables: V) -> Self {
        let n_step = (core.n_step() > 1).then(|| NStep::new(core.n_step(), core.gamma()));
        Self {
            core,
            adder,
            variables,
            pending: None,
            n_step,
        }
    }

    /// Hands `t` on to the adder, through the n-step window if there is one (`episode_end`: the
    /// last transition of its episode).
    fn emit(&mut self, t: Transition, episode_end: bool) -> Result<()> {
        match &mut self.n_step {
            None => self.adder.add(t, episode_end),
            Some(window) => {
                let adder = &mut self.adder;
                window.push(t, episode_end, |t, end| adder.add(t, end))
            }
        }
    }

    /// Potential-based shaping (see the type's docs): `t`, the transition of the step from `obs`
    /// with `action` (unshaped), waits for the next action; the one before it goes out now with
    /// its bonus.
    fn add_with_potential(
        &mut self,
        mut t: Transition,
        obs: &[f32],
        action: usize,
        step: &Step<Vec<f32>>,
        shaping: Option<(&DemoModel, f64)>,
    ) -> Result<()> {
        let gamma = self.core.gamma();
        let phi = shaping.map_or(0.0, |(m, lambda)| {
            NeuralActor::potential(obs, action, m, lambda)
        });
        if let Some((mut prev, phi_prev)) = self.pending.take() {
            prev.reward = (f64::from(prev.reward) + potential_bonus(gamma, phi, phi_prev)) as f32;
            self.emit(prev, false)?;
        }
        if step.done() {
            t.reward = (f64::from(t.reward) + potential_bonus(gamma, 0.0, phi)) as f32;
            self.emit(t, true)
        } else {
            self.pending = Some((t, phi));
            Ok(())
        }
    }
}

impl<A: Adder, V: VariableSource> Actor<Vec<f32>> for GenericActor<A, V> {
    fn update(&mut self) -> Result<ControlFlow<Stop>> {
        if let ControlFlow::Break(stop) = self.adder.reserve()? {
            return Ok(ControlFlow::Break(stop));
        }
        self.variables.update(&mut self.core)?;
        Ok(ControlFlow::Continue(()))
    }

    fn global_step(&self, own_steps: u64) -> u64 {
        self.adder.global_step(own_steps)
    }

    fn begin_episode(&mut self) {
        self.core.begin_episode();
    }

    fn select(
        &mut self,
        obs: &Vec<f32>,
        step: u64,
        budget: BudgetView,
        advice: Option<(&DemoModel, f64)>,
    ) -> Decision {
        let advice = self.core.shaping_kind().advice(advice);
        self.core.decide_advised(obs, step, budget, advice)
    }

    fn observe(
        &mut self,
        obs: &Vec<f32>,
        action: usize,
        step: &Step<Vec<f32>>,
        demo: bool,
        shaping: Option<(&DemoModel, f64)>,
    ) -> Result<bool> {
        let potential = self.core.shaping_kind().is_potential();
        // Eq. 4 shapes the transition itself; potential shaping adds its bonus afterwards.
        let t = self.core.transition(
            obs,
            action,
            step.reward,
            &step.observation,
            step.terminated,
            demo,
            if potential { None } else { shaping },
        );
        if potential {
            self.add_with_potential(t, obs, action, step, shaping)?;
        } else {
            self.emit(t, step.done())?;
        }
        Ok(shaping.is_some())
    }

    fn end_episode(&mut self) -> Result<()> {
        // Nothing waits here: the episode's last step flushed the potential and n-step windows.
        self.adder.end_episode()
    }
}

/// The tabular agents learn from each step as they take it
/// ([`TabularAgent::observe_step`]). The tabular study does not shape the reward (section
/// 5.1.1).
impl Actor<usize> for TabularAgent {
    fn begin_episode(&mut self) {
        TabularAgent::begin_episode(self);
    }

    fn select(
        &mut self,
        obs: &usize,
        step: u64,
        budget: BudgetView,
        _advice: Option<(&DemoModel, f64)>,
    ) -> Decision {
        self.decide(*obs, step, budget)
    }

    fn observe(
        &mut self,
        obs: &usize,
        action: usize,
        step: &Step<usize>,
        demo: bool,
        _shaping: Option<(&DemoModel, f64)>,
    ) -> Result<bool> {
        self.observe_step(*obs, action, step, demo);
        Ok(false)
    }
}

/// Which episodes [`run`] plays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Schedule {
    /// The seed of the first reset (later resets continue the environment's generator).
    pub env_seed: u64,
    /// Stop after this many episodes (`None`: until the actor or `on_episode` says stop).
    pub episodes: Option<u32>,
    /// Stop when this actor has taken this many steps; the episode running then is not recorded
    /// (`None`: no limit).
    pub steps: Option<u64>,
    /// The actor's id, recorded in every [`EpisodeRecord`].
    pub actor_id: u16,
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunEnd {
    /// Episodes played to their end, and environment steps this actor took (including those of
    /// an unfinished last episode): where a continued run starts.
    pub progress: Progress,
    /// Why the run stopped before its episode limit, if it did (the step limit, the transport;
    /// `None`: all episodes played, or `on_episode` said stop).
    pub stopped: Option<Stop>,
}

/// What the observers of an episode's end see: its record (they may fill in its `eval_return`),
/// where the run stands (the start of a run continued from here), and the environment, actor and
/// expert as they are between this episode and the next (what a checkpoint saves).
pub struct EpisodeEnd<'a, E: ?Sized, Ac, X> {
    pub record: &'a mut EpisodeRecord,
    pub progress: Progress,
    pub env: &'a E,
    pub actor: &'a Ac,
    pub expert: &'a X,
}

/// Plays episodes of `env` with `actor`, asking `expert` where the query rule fires: Algorithm 1,
/// one step at a time. `on_episode` sees every episode's end ([`EpisodeEnd`]: evaluation,
/// progress, checkpoints) and may stop the run with `Break`.
pub fn run<E, Ac, X>(
    env: &mut E,
    actor: &mut Ac,
    expert: &mut X,
    schedule: Schedule,
    on_episode: impl FnMut(EpisodeEnd<'_, E, Ac, X>) -> Result<ControlFlow<()>>,
) -> Result<RunEnd>
where
    E: Env + ?Sized,
    Ac: Actor<E::Observation>,
    X: ExpertClient<E::Observation>,
{
    run_from(
        env,
        actor,
        expert,
        schedule,
        Progress::default(),
        on_episode,
    )
}

/// Where a run stands between two episodes: episodes played, steps taken by this actor.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Progress {
    pub episodes: u32,
    pub steps: u64,
}

/// [`run`] continued from `start` (a restored checkpoint, or the end of an earlier call): the
/// environment, the actor and the expert are as they were then, and only episode 0 reseeds the
/// environment.
pub fn run_from<E, Ac, X>(
    env: &mut E,
    actor: &mut Ac,
    expert: &mut X,
    schedule: Schedule,
    start: Progress,
    mut on_episode: impl FnMut(EpisodeEnd<'_, E, Ac, X>) -> Result<ControlFlow<()>>,
) -> Result<RunEnd>
where
    E: Env + ?Sized,
    Ac: Actor<E::Observation>,
    X: ExpertClient<E::Observation>,
{
    let mut steps = start.steps;
    let mut episode = start.episodes;
    while schedule.episodes.is_none_or(|n| episode < n) {
        let seed = (episode == 0).then_some(schedule.env_seed);
        let limit = schedule.steps;
        let mut record = match run_episode(env, actor, expert, seed, &mut steps, limit)? {
            ControlFlow::Continue(mut record) => {
                record.episode = episode;
                record.actor = schedule.actor_id;
                record
            }
            ControlFlow::Break(stop) => {
                return Ok(RunEnd {
                    progress: Progress {
                        episodes: episode,
                        steps,
                    },
                    stopped: Some(stop),
                })
            }
        };
        episode += 1;
        let end = EpisodeEnd {
            record: &mut record,
            progress: Progress {
                episodes: episode,
                steps,
            },
            env: &*env,
            actor: &*actor,
            expert: &*expert,
        };
        if on_episode(end)?.is_break() {
            break;
        }
    }
    Ok(RunEnd {
        progress: Progress {
            episodes: episode,
            steps,
        },
        stopped: None,
    })
}

/// Why [`run`] stops when the step limit is reached.
pub const STEP_LIMIT: Stop = Stop("the step limit was reached");

/// One episode of Algorithm 1. `steps` counts this actor's steps across episodes; the episode is
/// abandoned (`Break(STEP_LIMIT)`) when it reaches `limit`. The record's `episode` and `actor`
/// are left for the caller.
pub fn run_episode<E, Ac, X>(
    env: &mut E,
    actor: &mut Ac,
    expert: &mut X,
    seed: Option<u64>,
    steps: &mut u64,
    limit: Option<u64>,
) -> Result<ControlFlow<Stop, EpisodeRecord>>
where
    E: Env + ?Sized,
    Ac: Actor<E::Observation>,
    X: ExpertClient<E::Observation>,
{
    let mut obs = env.reset(seed);
    actor.begin_episode();
    let (mut ret, mut length, mut js_sum) = (0.0, 0u32, 0.0);
    let (mut queries, mut shaped_steps) = (0u32, 0u32);
    loop {
        if limit.is_some_and(|n| *steps >= n) {
            return Ok(ControlFlow::Break(STEP_LIMIT));
        }
        if let ControlFlow::Break(stop) = actor.update()? {
            return Ok(ControlFlow::Break(stop));
        }
        expert.update()?;
        let global_step = actor.global_step(*steps);
        // Lines 3-16: the divergence, the query rule, the action.
        let decision = actor.select(
            &obs,
            global_step,
            expert.budget(),
            expert.shaping(global_step),
        );
        js_sum += decision.js;
        let (action, demo) = match decision.query {
            true => match expert.ask(&obs, global_step)? {
                Some(a) => (a, true),
                None => (decision.action, false),
            },
            false => (decision.action, false),
        };
        queries += u32::from(demo);
        // Lines 17-20: act, shape, store, learn.
        let step = env.step(action)?;
        let shaped = actor.observe(&obs, action, &step, demo, expert.shaping(global_step))?;
        shaped_steps += u32::from(shaped);
        ret += step.reward;
        length += 1;
        *steps += 1;
        let done = step.done();
        obs = step.observation;
        if done {
            break;
        }
    }
    actor.end_episode()?;
    expert.episode_ended(ret);
    // The record counts every demonstration of the run known at the episode's end (another
    // actor's included, in a run of many).
    expert.update()?;
    Ok(ControlFlow::Continue(EpisodeRecord {
        ret,
        length,
        demos_used: expert.demos_used(),
        mean_js: js_sum / f64::from(length),
        queries,
        shaped_steps,
        total_steps: actor.global_step(*steps),
        ..EpisodeRecord::default()
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ExperimentConfig;
    use crate::demo_model::DemoModelKind;

    #[derive(Default)]
    struct Recorder(Vec<(Transition, bool)>);

    impl Adder for &mut Recorder {
        fn add(&mut self, t: Transition, truncated: bool) -> Result<()> {
            self.0.push((t, truncated));
            Ok(())
        }
    }

    struct Fixed;

    impl VariableSource for Fixed {
        fn update(&mut self, _: &mut NeuralActor) -> Result<()> {
            Ok(())
        }
    }

    fn actor(kind: &str) -> NeuralActor {
        actor_with(kind, "")
    }

    fn actor_with(kind: &str, agent: &str) -> NeuralActor {
        let text = format!(
            "seed = 0\nepisodes = 1\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"dqn\"\ngamma = 0.9\n{agent}[shaping]\nkind = \"{kind}\"\n"
        );
        let cfg = ExperimentConfig::from_toml(&text).unwrap();
        NeuralActor::new(
            &cfg.agent,
            &cfg.rule_spec(),
            cfg.shaping.kind,
            4,
            2,
            crate::rng::seeded(1),
        )
    }

    fn step(x: f32, terminated: bool) -> Step<Vec<f32>> {
        Step {
            observation: vec![x; 4],
            reward: 1.0,
            terminated,
            truncated: false,
        }
    }

    #[test]
    fn an_actor_with_look_ahead_advice_acts_on_q_plus_the_potential_and_no_other_does() {
        let states = [vec![0.0; 4], vec![1.0; 4]];
        let model = DemoModel::fit(DemoModelKind::Krr, &states, &[0, 1], 2).unwrap();
        // So large a λ that the potential decides: the model's action at each state.
        let advice = Some((&model, 1e6));
        let greedy = "exploration = \"epsilon-greedy\"\nepsilon_start = 0.0\nepsilon_end = 0.0\n";
        let budget = BudgetView::FRESH;
        let mut out = Recorder::default();
        let mut plain = GenericActor::new(actor_with("potential", greedy), &mut out, Fixed);
        let mut sink = Recorder::default();
        let mut advised = GenericActor::new(actor_with("advice", greedy), &mut sink, Fixed);
        let (s0, s1) = (vec![0.0f32; 4], vec![1.0f32; 4]);
        let own: Vec<usize> = [&s0, &s1]
            .map(|s| plain.select(s, 0, budget, None).action)
            .to_vec();
        assert_ne!(
            own,
            [0, 1],
            "the network alone disagrees with the model somewhere"
        );
        for (s, want) in [(&s0, 0), (&s1, 1)] {
            assert_eq!(advised.select(s, 0, budget, advice).action, want);
        }
        // `potential` shapes the reward alone: its actions are the network's.
        let shaped: Vec<usize> = [&s0, &s1]
            .map(|s| plain.select(s, 0, budget, advice).action)
            .to_vec();
        assert_eq!(shaped, own);
    }

    #[test]
    fn potential_shaping_adds_gamma_phi_next_minus_phi_once_the_next_action_is_known() {
        let states = [vec![0.0; 4], vec![1.0; 4]];
        let model = DemoModel::fit(DemoModelKind::Krr, &states, &[0, 1], 2).unwrap();
        let shaping = Some((&model, 0.5));
        let mut out = Recorder::default();
        let mut a = GenericActor::new(actor("potential"), &mut out, Fixed);
        let (s0, s1) = (vec![0.2f32; 4], vec![0.7f32; 4]);
        assert!(a
            .observe(&s0, 0, &step(0.7, false), false, shaping)
            .unwrap());
        assert!(a.adder.0.is_empty(), "waits for the next action");
        a.observe(&s1, 1, &step(1.3, true), false, shaping).unwrap();
        let phi0 = NeuralActor::potential(&s0, 0, &model, 0.5);
        let phi1 = NeuralActor::potential(&s1, 1, &model, 0.5);
        assert!(phi0 > 0.0 && phi1 > 0.0);
        let got: Vec<f32> = a.adder.0.iter().map(|(t, _)| t.reward).collect();
        let want = [(1.0 + 0.9 * phi1 - phi0) as f32, (1.0 - phi1) as f32];
        assert_eq!(
            got, want,
            "F = γΦ(s',a') − Φ(s,a), Φ = 0 after the terminal step"
        );
        assert_eq!(a.adder.0[0].0.state, s0);

        // The paper's shaping goes to the adder at once, with eq. 4.
        let mut out = Recorder::default();
        let mut p = GenericActor::new(actor("paper"), &mut out, Fixed);
        p.observe(&s0, 0, &step(0.7, false), false, shaping)
            .unwrap();
        assert_eq!(p.adder.0.len(), 1);
        assert!(p.adder.0[0].0.reward > 1.0, "eq. 4 adds a positive bonus");
    }

    #[test]
    fn with_n_step_the_adder_gets_n_step_transitions_and_the_tail_at_the_end() {
        // Four steps of reward 1, the fourth terminal, n = 3, γ = 0.9.
        let mut out = Recorder::default();
        let mut a = GenericActor::new(actor_with("paper", "n_step = 3\n"), &mut out, Fixed);
        for x in 0..4 {
            let s = vec![x as f32; 4];
            a.observe(&s, 0, &step(x as f32 + 1.0, x == 3), false, None)
                .unwrap();
            let waited = if x == 3 {
                4
            } else {
                (x as usize).saturating_sub(1)
            };
            assert_eq!(a.adder.0.len(), waited, "after step {x}");
        }
        let got: Vec<(f32, f32, u8, bool, bool)> = a
            .adder
            .0
            .iter()
            .map(|(t, end)| (t.state[0], t.reward, t.horizon, t.terminated, *end))
            .collect();
        let r3 = (1.0 + 0.9 + 0.81f64) as f32;
        assert_eq!(
            got,
            vec![
                (0.0, r3, 3, false, false),
                (1.0, r3, 3, true, false),
                (2.0, 1.9, 2, true, false),
                (3.0, 1.0, 1, true, true),
            ]
        );
        assert_eq!(a.adder.0[0].0.next_state, vec![3.0; 4]);
    }
}
