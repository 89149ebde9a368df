//! The neural agents of sections 3.2-3.5 and 5.3, split into the part that acts and the part that
//! learns: DQN (one head, ε-greedy), Bootstrapped DQN (K heads, one followed greedily per episode),
//! the single-head greedy ablation, all with active queries and eq. 4 shaping.

use rand::Rng as _;

use serde::{Deserialize, Serialize};

use crate::agent::{Decision, Explorer};
use crate::checkpoint::StateMismatch;
use crate::config::LossKind;
use crate::config::{AgentConfig, LrSchedule};
use crate::demo_model::DemoModel;
use crate::nn::{Adam, AdamConfig, AdamState, Mlp, NnError, TdConfig, TdLoss, TrainScratch};
use crate::policy::{js_divergence, softmax_into};
use crate::query::{mean_greedy, novelty, q_spread, BudgetView, Oracle, Rule, RuleSpec, Signal};
use crate::replay::{Batch, ReplayBuffer, Transition};
use crate::rng::{Rng, RngState};
use crate::shaping::{shaped_reward, ShapingKind};

/// The acting side: the latest weights, exploration, the divergence queue and shaping.
#[derive(Debug, Clone)]
pub struct NeuralActor {
    net: Mlp,
    heads: usize,
    actions: usize,
    explorer: Explorer,
    temperature: f64,
    bootstrap_probability: f64,
    rule: Rule,
    /// The states of the demonstrations this actor was given (the novelty rule's reference set).
    demo_states: Vec<Vec<f64>>,
    rng: Rng,
    arm: usize,
    q32: Vec<f32>,
    /// Q-values of the last state passed to [`NeuralActor::decide`].
    q: Vec<f64>,
    probs: Vec<f64>,
    weights_version: u64,
    gamma: f64,
    n_step: u32,
    shaping_kind: ShapingKind,
    /// The expert gate `oracle` consults (none for the other gates).
    oracle: Option<Oracle<[f32]>>,
}

impl NeuralActor {
    /// An actor whose network has the architecture of `cfg`; it acts on whatever weights it is
    /// given with [`NeuralActor::set_weights`] (a fresh initialisation until then).
    pub fn new(
        agent: &AgentConfig,
        rule: &RuleSpec,
        shaping_kind: ShapingKind,
        obs_dim: usize,
        actions: usize,
        mut rng: Rng,
    ) -> Self {
        let heads = agent.heads();
        let net = agent.network(obs_dim, actions, &mut rng);
        Self {
            net,
            heads,
            actions,
            explorer: Explorer::new(agent, actions),
            temperature: agent.temperature,
            bootstrap_probability: agent.bootstrap_probability,
            rule: Rule::new(rule, &rng),
            demo_states: Vec::new(),
            rng,
            arm: 0,
            q32: vec![0.0; heads * actions],
            q: vec![0.0; heads * actions],
            probs: vec![0.0; actions],
            weights_version: 0,
            gamma: agent.gamma,
            n_step: agent.n_step,
            shaping_kind,
            oracle: None,
        }
    }

    /// The expert gate `oracle` consults at every step (for the gate alone).
    pub fn set_oracle(&mut self, oracle: Oracle<[f32]>) {
        self.oracle = Some(oracle);
    }

    /// Whether the rule needs an oracle ([`NeuralActor::set_oracle`]).
    pub fn needs_oracle(&self) -> bool {
        self.rule.reads(Signal::Oracle)
    }

    /// Replaces the acting weights (the flat parameter order of [`Mlp::params_flat`]).
    pub fn set_weights(&mut self, params: &[f32], version: u64) -> Result<(), NnError> {
        self.net.load_params_flat(params)?;
        self.weights_version = version;
        Ok(())
    }

    /// Copies the weights of `net` (same architecture) without going through a flat buffer.
    pub fn copy_weights_from(&mut self, net: &Mlp, version: u64) {
        self.net
            .copy_params_from(net)
            .expect("actor and learner networks share one architecture");
        self.weights_version = version;
    }

    pub fn weights_version(&self) -> u64 {
        self.weights_version
    }

    pub fn network(&self) -> &Mlp {
        &self.net
    }

    /// The head followed this episode.
    pub fn arm(&self) -> usize {
        self.arm
    }

    /// Environment steps taken by this actor (drives ε).
    pub fn steps(&self) -> u64 {
        self.explorer.steps()
    }

    /// Puts ε's clock at `steps`: an actor that takes over from one that died goes on
    /// exploring where its predecessor was, not from ε's start.
    pub fn continue_exploration(&mut self, steps: u64) {
        self.explorer.restore_steps(steps);
    }

    /// Algorithm 1 line 1: sample the head to follow this episode.
    pub fn begin_episode(&mut self) {
        self.arm = self.rng.random_range(0..self.heads);
    }

    /// Algorithm 1 lines 3-16 at state `obs`, the run's global step `step`: the divergence, the
    /// query rule's decision, and the agent's own action (greedy on the episode's head, or
    /// ε-greedy / softmax as configured).
    pub fn decide(&mut self, obs: &[f32], step: u64, budget: BudgetView) -> Decision {
        self.decide_advised(obs, step, budget, None)
    }

    /// [`NeuralActor::decide`] on every head's `Q(s,a) + λ p(a|s)` when `advice` gives the
    /// demonstration model and λ (look-ahead advice): the divergence, the query rule and the
    /// action all see the advised values.
    pub fn decide_advised(
        &mut self,
        obs: &[f32],
        step: u64,
        budget: BudgetView,
        advice: Option<(&DemoModel, f64)>,
    ) -> Decision {
        self.net.forward_one(obs, &mut self.q32);
        for (q, &v) in self.q.iter_mut().zip(&self.q32) {
            *q = f64::from(v);
        }
        if let Some((model, lambda)) = advice {
            add_advice(&mut self.q, self.actions, obs, model, lambda);
        }
        let js = if self.heads > 1 {
            js_divergence(&self.q, self.heads, self.temperature)
        } else {
            0.0
        };
        let (q, heads, held, oracle) = (&self.q, self.heads, &self.demo_states, &self.oracle);
        let query = self.rule.decide_at(
            budget,
            step,
            js,
            || q_spread(q, heads),
            || {
                let s: Vec<f64> = obs.iter().map(|&x| f64::from(x)).collect();
                novelty(&s, held.iter().map(Vec::as_slice))
            },
            || {
                oracle
                    .as_ref()
                    .map(|o| o.action(obs) != mean_greedy(q, heads))
            },
        );
        let a = self.actions;
        let action = self
            .explorer
            .act(&self.q[self.arm * a..(self.arm + 1) * a], &mut self.rng);
        Decision { action, js, query }
    }

    /// `π(a|s)` of the episode's head at the state last passed to [`NeuralActor::decide`] (eq. 2).
    pub fn policy_prob(&mut self, action: usize) -> f64 {
        let a = self.actions;
        softmax_into(
            &self.q[self.arm * a..(self.arm + 1) * a],
            self.temperature,
            &mut self.probs,
        );
        self.probs[action]
    }

    /// Which shaping this actor applies.
    pub fn shaping_kind(&self) -> ShapingKind {
        self.shaping_kind
    }

    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The n of the n-step transitions this actor hands on (`agent.n_step`).
    pub fn n_step(&self) -> u32 {
        self.n_step
    }

    /// The potential `Φ(s, a) = λ p(a|s)` of potential-based shaping.
    pub fn potential(obs: &[f32], action: usize, model: &DemoModel, lambda: f64) -> f64 {
        let s: Vec<f64> = obs.iter().map(|&x| f64::from(x)).collect();
        lambda * model.prob(&s, action)
    }

    /// Algorithm 1 lines 17-19: the transition to store, with the reward shaped by eq. 4 when a
    /// demonstration model is given (`shaping = Some((model, λ))`), and its bootstrap mask.
    /// Demonstrations train every head; other transitions train head k with probability p.
    #[allow(clippy::too_many_arguments)]
    pub fn transition(
        &mut self,
        obs: &[f32],
        action: usize,
        reward: f64,
        next_obs: &[f32],
        terminated: bool,
        demo: bool,
        shaping: Option<(&DemoModel, f64)>,
    ) -> Transition {
        if demo && self.rule.reads(Signal::Novelty) {
            self.demo_states
                .push(obs.iter().map(|&x| f64::from(x)).collect());
        }
        let reward = match shaping {
            Some((model, lambda)) => {
                let s: Vec<f64> = obs.iter().map(|&x| f64::from(x)).collect();
                let p_demo = model.prob(&s, action);
                let pi = self.policy_prob(action);
                shaped_reward(reward, lambda, p_demo, pi)
            }
            None => reward,
        };
        let mask = (0..self.heads)
            .map(|_| {
                if demo || self.heads == 1 || self.rng.random::<f64>() < self.bootstrap_probability
                {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        Transition {
            state: obs.to_vec(),
            action: action as u32,
            reward: reward as f32,
            next_state: next_obs.to_vec(),
            terminated,
            mask,
            demo,
            horizon: 1,
        }
    }
}

/// Adds `λ p(a|s)` to every head's value of action `a` in `q` (heads × `actions`, head-major):
/// look-ahead advice's potential, which the values learned under it lack.
pub fn add_advice(q: &mut [f64], actions: usize, obs: &[f32], model: &DemoModel, lambda: f64) {
    let s: Vec<f64> = obs.iter().map(|&x| f64::from(x)).collect();
    let p = model.probs(&s);
    for head in q.chunks_mut(actions) {
        for (v, pa) in head.iter_mut().zip(&p) {
            *v += lambda * pa;
        }
    }
}

/// What a [`NeuralActor`] must remember to continue exactly (its hyper-parameters come from the
/// config): the weights it acts on, ε's clock, the divergence queue, its generator and the head
/// it follows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ActorSnapshot {
    pub weights: Vec<f32>,
    pub weights_version: u64,
    pub explorer_steps: u64,
    pub rule: Rule,
    /// The demonstrations' states the novelty rule measures against.
    pub demo_states: Vec<Vec<f64>>,
    pub rng: RngState,
    pub arm: usize,
}

impl NeuralActor {
    pub fn snapshot(&self) -> ActorSnapshot {
        ActorSnapshot {
            weights: self.net.params_flat(),
            weights_version: self.weights_version,
            explorer_steps: self.explorer.steps(),
            rule: self.rule.clone(),
            demo_states: self.demo_states.clone(),
            rng: RngState::of(&self.rng),
            arm: self.arm,
        }
    }

    /// Restores [`NeuralActor::snapshot`] into an actor built from the same config.
    pub fn restore(&mut self, s: &ActorSnapshot) -> Result<(), StateMismatch> {
        if s.arm >= self.heads {
            return Err(StateMismatch(format!("head {} of {}", s.arm, self.heads)));
        }
        self.set_weights(&s.weights, s.weights_version)
            .map_err(|e| StateMismatch(format!("actor weights: {e}")))?;
        self.explorer.restore_steps(s.explorer_steps);
        self.rule = s.rule.clone();
        self.demo_states = s.demo_states.clone();
        self.rng = s.rng.to_rng();
        self.arm = s.arm;
        Ok(())
    }
}

/// What a [`NeuralLearner`] must remember to continue exactly: online and target weights, Adam,
/// the replay buffer (masks, demonstration flags, ring position), its generator and counters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LearnerSnapshot {
    pub online: Vec<f32>,
    pub target: Vec<f32>,
    pub adam: AdamState,
    pub replay: ReplayBuffer,
    pub rng: RngState,
    pub inserted: u64,
    pub updates: u64,
}

impl NeuralLearner {
    pub fn snapshot(&self) -> LearnerSnapshot {
        LearnerSnapshot {
            online: self.online.params_flat(),
            target: self.target.params_flat(),
            adam: self.adam.state(),
            replay: self.replay.clone(),
            rng: RngState::of(&self.rng),
            inserted: self.inserted,
            updates: self.updates,
        }
    }

    /// Restores [`NeuralLearner::snapshot`] into a learner built from the same config.
    pub fn restore(&mut self, s: &LearnerSnapshot) -> Result<(), StateMismatch> {
        let r = &s.replay;
        if !self.replay.same_shape(r) {
            return Err(StateMismatch(
                "the replay buffer has another capacity or layout".into(),
            ));
        }
        let (mut online, mut target) = (self.online.clone(), self.target.clone());
        online
            .load_params_flat(&s.online)
            .and_then(|()| target.load_params_flat(&s.target))
            .map_err(|e| StateMismatch(format!("learner weights: {e}")))?;
        if !self.adam.restore(&s.adam) {
            return Err(StateMismatch("Adam's moments have other sizes".into()));
        }
        (self.online, self.target) = (online, target);
        self.replay = s.replay.clone();
        self.rng = s.rng.to_rng();
        self.inserted = s.inserted;
        self.updates = s.updates;
        Ok(())
    }
}

/// The learning side: replay, the K heads, their targets and Adam (Algorithm 1 line 20).
#[derive(Debug, Clone)]
pub struct NeuralLearner {
    online: Mlp,
    target: Mlp,
    adam: Adam,
    replay: ReplayBuffer,
    rng: Rng,
    batch: Batch,
    scratch: TrainScratch,
    td: TdConfig,
    batch_size: usize,
    target_update_every: u64,
    tau: f32,
    learning_starts: u64,
    demo_fraction: f64,
    updates_per_step: u32,
    /// Adam's learning rate at a transition count (`agent.learning_rate_end`); `None`: constant.
    lr_schedule: Option<LrSchedule>,
    /// Transitions stored so far.
    inserted: u64,
    updates: u64,
}

impl NeuralLearner {
    pub fn new(agent: &AgentConfig, obs_dim: usize, actions: usize, mut rng: Rng) -> Self {
        let heads = agent.heads();
        let online = agent.network(obs_dim, actions, &mut rng);
        let target = online.clone();
        let adam = Adam::with_config(
            &online,
            AdamConfig {
                lr: agent.learning_rate(),
                ..AdamConfig::default()
            },
        );
        let scratch = TrainScratch::default();
        Self {
            online,
            target,
            adam,
            replay: ReplayBuffer::new(agent.replay_capacity, obs_dim, heads),
            rng,
            batch: Batch::default(),
            scratch,
            td: TdConfig {
                gamma: agent.gamma as f32,
                loss: match agent.loss {
                    LossKind::Huber => TdLoss::Huber,
                    LossKind::Mse => TdLoss::Mse,
                },
                huber_delta: agent.huber_delta as f32,
                double: agent.double_dqn,
                margin_weight: agent.margin_loss_weight as f32,
                margin: agent.margin as f32,
                max_grad_norm: agent.max_grad_norm.map(|g| g as f32),
                target_bounds: agent.target_bounds.map(|[lo, hi]| (lo as f32, hi as f32)),
            },
            batch_size: agent.batch_size,
            target_update_every: agent.target_update_every,
            tau: agent.tau as f32,
            learning_starts: agent.learning_starts,
            demo_fraction: agent.demo_fraction,
            updates_per_step: agent.updates_per_step,
            lr_schedule: agent.learning_rate_schedule(),
            inserted: 0,
            updates: 0,
        }
    }

    /// Algorithm 1 line 19.
    pub fn insert(&mut self, t: &Transition) {
        self.replay.push(t);
        self.inserted += 1;
    }

    /// Algorithm 1 lines 19-20 for one environment step: stores `t`, then makes `U` updates
    /// (`agent.updates_per_step`). Returns the loss of the last update, `None` if none was made.
    pub fn learn(&mut self, t: &Transition) -> Option<f32> {
        self.insert(t);
        let mut loss = None;
        for _ in 0..self.updates_per_step {
            if let Some(l) = self.update() {
                loss = Some(l);
            }
        }
        loss
    }

    /// One update of the K heads on a batch from the replay buffer, and the target update every
    /// `target_update_every` updates (a copy, or Polyak averaging with `tau < 1`). `None` (no
    /// update) until the buffer holds a full batch and `learning_starts` transitions.
    pub fn update(&mut self) -> Option<f32> {
        if self.replay.len() < self.batch_size || self.inserted < self.learning_starts {
            return None;
        }
        self.replay.sample_with_demos_into(
            self.batch_size,
            self.demo_fraction,
            &mut self.rng,
            &mut self.batch,
        );
        if let Some(schedule) = &self.lr_schedule {
            self.adam.set_lr(schedule.at(self.inserted));
        }
        let loss = crate::nn::train_step_with(
            &mut self.online,
            &self.target,
            &mut self.adam,
            &self.batch,
            &self.td,
            &mut self.scratch,
        );
        self.updates += 1;
        if self.updates.is_multiple_of(self.target_update_every) {
            self.target
                .polyak_from(&self.online, self.tau)
                .expect("online and target networks share one architecture");
        }
        Some(loss)
    }

    /// Updates made so far (also the version of the weights).
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// The mean Q-value of the online network over the last batch it learned from (NaN before
    /// the first update).
    pub fn q_mean(&self) -> f32 {
        self.scratch.q_mean()
    }

    pub fn network(&self) -> &Mlp {
        &self.online
    }

    pub fn replay(&self) -> &ReplayBuffer {
        &self.replay
    }
}
