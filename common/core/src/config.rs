//! The experiment config: raw TOML (plus `--set key=value` overrides) becomes a validated
//! [`ExperimentConfig`]; an unknown key or a value out of range is refused with a message naming
//! the field.
//!
//! The same config runs in one process (`alfd local`) or in many (`alfd run`).

use serde::{Deserialize, Serialize};

mod env;
mod expert;
mod logging;
mod normalize;
mod query;
pub mod reference;
mod shaping;
mod validate;

pub use shaping::ShapingConfig;
pub use validate::{
    MAX_BATCH_SIZE, MAX_HIDDEN, MAX_N_STEP, MAX_QUEUE_LEN, MAX_REPLAY_CAPACITY, MAX_SEPARATE_WIDTH,
};

/// A config that cannot be used, with the field (or TOML line) at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("invalid config: {0}")]
    Parse(String),
    #[error("invalid config: `{field}` {message}")]
    Invalid {
        field: &'static str,
        message: String,
    },
    #[error("invalid --set `{0}`: expected key=value, e.g. agent.heads=3")]
    BadOverride(String),
}

pub type Result<T, E = ConfigError> = std::result::Result<T, E>;

fn invalid(field: &'static str, message: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        field,
        message: message.into(),
    }
}

/// One experiment: an environment, an agent, its query rule, budget, expert and shaping.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// Seed of everything random in the run (environment, initialisation, exploration, masks).
    pub seed: u64,
    /// Number of training episodes (0 or absent: no limit; then `steps` must be set).
    #[serde(default, skip_serializing_if = "is_zero_u32")]
    pub episodes: u32,
    /// Number of environment steps to train for, as Stable-Baselines3's `total_timesteps`; the
    /// episode running when the limit is reached is not recorded (0 or absent: no limit).
    #[serde(default, skip_serializing_if = "is_zero_u64")]
    pub steps: u64,
    /// Periodic evaluation of the greedy policy (off by default).
    #[serde(default, skip_serializing_if = "EvalConfig::is_default")]
    pub evaluation: EvalConfig,
    pub env: EnvConfig,
    pub agent: AgentConfig,
    #[serde(default)]
    pub query: QueryConfig,
    #[serde(default)]
    pub budget: BudgetConfig,
    #[serde(default)]
    pub expert: ExpertConfig,
    #[serde(default)]
    pub shaping: ShapingConfig,
    #[serde(default, skip_serializing_if = "DemosConfig::is_default")]
    pub demos: DemosConfig,
    /// Several experts at once (`[[experts]]`, one table each), asked as `expert.route` says;
    /// `[expert]` keeps the run's demonstration model. In `alfd run` each but a person answers
    /// from its own process; Q-table agents take built-in experts only. Empty: `expert.name`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub experts: Vec<PanelEntry>,
    #[serde(default, skip_serializing_if = "LoggingConfig::is_default")]
    pub logging: LoggingConfig,
}

/// Demonstrations the run starts with, besides the ones it asks for.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DemosConfig {
    /// A Minari dataset (`arrow` data format: its directory, or the `data` directory in it) of
    /// the config's environment whose expert steps seed the run: every step, or only the steps
    /// its `infos.demonstrated` marks when it has that field (as `alfd demos export` writes).
    /// They go to the replay buffer as demonstrations and into the demonstration model before
    /// the first step; budget B counts only the demonstrations the run asks for. Neural agents;
    /// relative to the working directory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<String>,
    /// With several experts: `quality` weighs each demonstration in the KRR model by its
    /// expert's estimated quality when it answered (scikit-learn's `sample_weight`; `weight` in
    /// `demos.jsonl`), `none` weighs them alike. SVM and Nyström weigh every one alike.
    #[serde(default, skip_serializing_if = "Weighting::is_quality")]
    pub weighting: Weighting,
}

/// How demonstrations of several experts are weighted in the demonstration model.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// By the estimated quality of the expert that answered.
    #[default]
    Quality,
    /// Every demonstration alike.
    None,
}

impl Weighting {
    fn is_quality(&self) -> bool {
        *self == Weighting::Quality
    }
}

impl DemosConfig {
    fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

fn is_zero_u32(v: &u32) -> bool {
    *v == 0
}
fn is_zero_u64(v: &u64) -> bool {
    *v == 0
}

/// Evaluation: every `every` training episodes, `episodes` episodes of the greedy policy of the
/// learned network (the mean of the heads' Q-values; no queries, no learning, no exploration) on
/// a separate copy of the environment, the same seed every time. Their mean return is the
/// `eval_return` of that training episode's record.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EvalConfig {
    /// Evaluate after every this many training episodes (0: never).
    #[serde(default)]
    pub every: u32,
    /// Greedy episodes per evaluation (at least 1 when `every` > 0).
    #[serde(default = "default_eval_episodes")]
    pub episodes: u32,
}

fn default_eval_episodes() -> u32 {
    10
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            every: 0,
            episodes: default_eval_episodes(),
        }
    }
}

impl EvalConfig {
    pub fn is_off(&self) -> bool {
        self.every == 0
    }

    /// Whether this is the default (left out of a written config, so the config reads back equal).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Whether training episode `episode` (0-based) is followed by an evaluation.
    pub fn due(&self, episode: u32) -> bool {
        self.every > 0 && (episode + 1).is_multiple_of(self.every)
    }
}

impl ExperimentConfig {
    /// The episode limit, if any.
    pub fn episode_limit(&self) -> Option<u32> {
        (self.episodes > 0).then_some(self.episodes)
    }

    /// The step limit, if any.
    pub fn step_limit(&self) -> Option<u64> {
        (self.steps > 0).then_some(self.steps)
    }
}

/// The learning algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum AgentKind {
    /// Tabular Q-learning.
    Qlearning,
    /// Tabular SARSA.
    Sarsa,
    /// Tabular bootstrapped Q-learning: K Q-tables with randomized (masked) updates.
    BootstrappedQ,
    /// DQN (section 5.3), one head.
    Dqn,
    /// Bootstrapped DQN (section 3.2), K heads in one network.
    Bdqn,
}

impl AgentKind {
    pub fn is_tabular(self) -> bool {
        matches!(self, Self::Qlearning | Self::Sarsa | Self::BootstrappedQ)
    }
}

/// How the agent picks its own actions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Exploration {
    /// Sample from the softmax policy (eq. 2) of the acting head.
    Softmax,
    /// ε-greedy on the acting head, ε decaying exponentially.
    EpsilonGreedy,
    /// Greedy on the head sampled for the episode (Algorithm 1, lines 1 and 12).
    GreedyHead,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AgentConfig {
    /// The learning algorithm.
    pub kind: AgentKind,
    /// K, the number of heads, 1 to 8 (default 1 for qlearning/sarsa/dqn, 2 for
    /// bootstrapped-q/bdqn).
    #[serde(default)]
    pub heads: Option<usize>,
    /// Discount factor γ, in [0, 1] (below 1 for the tabular agents).
    #[serde(default = "default_gamma")]
    pub gamma: f64,
    /// Temperature of the softmax policies of eq. 2 (JS divergence, shaping, softmax exploration);
    /// > 0.
    #[serde(default = "default_temperature")]
    pub temperature: f64,
    /// Step size, > 0: α of the tabular update (default 0.1), or Adam's learning rate (default
    /// 1e-3).
    #[serde(default)]
    pub learning_rate: Option<f64>,
    /// Tabular: the step size of the n-th update of a state-action pair is
    /// `learning_rate / n^learning_rate_decay` (0 keeps it constant; in (0.5, 1] it meets the
    /// Robbins-Monro conditions under which Q-learning converges).
    #[serde(default)]
    pub learning_rate_decay: f64,
    /// Exploration (default: softmax for tabular Q-learning/SARSA, epsilon-greedy for dqn,
    /// greedy-head for the bootstrapped agents).
    #[serde(default)]
    pub exploration: Option<Exploration>,
    /// ε at the first step, in [0, 1].
    #[serde(default = "default_epsilon_start")]
    pub epsilon_start: f64,
    /// ε reached asymptotically, in [0, 1].
    #[serde(default = "default_epsilon_end")]
    pub epsilon_end: f64,
    /// Time constant of the exponential decay of ε, in environment steps (> 0).
    #[serde(default = "default_epsilon_decay_steps")]
    pub epsilon_decay_steps: f64,
    /// Probability that a transition trains a given head (the Bernoulli bootstrap mask), in
    /// (0, 1].
    #[serde(default = "default_bootstrap_probability")]
    pub bootstrap_probability: f64,
    /// Neural: replay buffer capacity (at least `batch_size`, at most [`MAX_REPLAY_CAPACITY`]).
    #[serde(default = "default_replay_capacity")]
    pub replay_capacity: usize,
    /// Neural: mini-batch size (1 to [`MAX_BATCH_SIZE`], and at most the replay capacity).
    #[serde(default = "default_batch_size")]
    pub batch_size: usize,
    /// Neural: the target networks are copied from the online one every this many updates (≥ 1).
    #[serde(default = "default_target_update_every")]
    pub target_update_every: u64,
    /// Neural: updates per environment step (the replay ratio U; ≥ 1).
    #[serde(default = "default_updates_per_step")]
    pub updates_per_step: u32,
    /// Neural: width of the two hidden layers (1 to [`MAX_HIDDEN`]); of each head's own when the
    /// torsos are separate.
    #[serde(default = "default_hidden")]
    pub hidden: usize,
    /// Neural: the K heads share one torso (the paper's Bootstrapped DQN); `false` gives each head
    /// its own two hidden layers, K networks that share nothing (Osband et al.'s ensemble on
    /// DeepSea), at K times the arithmetic of the second hidden layer. `heads × hidden` is then at
    /// most [`MAX_SEPARATE_WIDTH`].
    #[serde(default = "default_true", skip_serializing_if = "is_true")]
    #[schemars(extend("default" = true))]
    pub shared_torso: bool,
    /// Neural: the loss on TD errors, `huber` (SmoothL1, the paper's) or `mse`.
    #[serde(default)]
    pub loss: LossKind,
    /// Neural: δ of the Huber loss, > 0 (PyTorch's `HuberLoss(delta)`; 1 is SmoothL1, the
    /// paper's).
    #[serde(default = "default_huber_delta")]
    pub huber_delta: f64,
    /// Neural: Double DQN targets (the online head picks the next action, the target evaluates).
    #[serde(default)]
    pub double_dqn: bool,
    /// Neural: every `target_update_every` updates, `target <- tau * online + (1 - tau) *
    /// target` (Polyak), τ in (0, 1]; 1 copies (the paper's hard update).
    #[serde(default = "default_tau")]
    pub tau: f64,
    /// Neural: the gradient is scaled to at most this global L2 norm, > 0 (absent: no clipping).
    #[serde(default)]
    pub max_grad_norm: Option<f64>,
    /// Neural: `[lo, hi]` every TD target is clamped to, the range of the true values (CartPole-1000
    /// at γ = 0.995: `[0, 200]`); absent: unclamped.
    #[serde(default)]
    pub target_bounds: Option<[f64; 2]>,
    /// Neural: no update before this many transitions were stored (nor before a full batch).
    #[serde(default)]
    pub learning_starts: u64,
    /// Neural: the fraction of every batch drawn from the demonstrations in the replay buffer,
    /// in [0, 1] (0: uniform, the paper's).
    #[serde(default)]
    pub demo_fraction: f64,
    /// λ_E of DQfD's large-margin loss on demonstrated transitions, ≥ 0 (0: off). Neural: the
    /// loss's weight. Tabular: any value > 0 makes the margin a hard constraint: at every
    /// demonstrated state each head's value of the demonstrated action stays at least `margin`
    /// above its others.
    #[serde(default)]
    pub margin_loss_weight: f64,
    /// The margin `l` of that loss, ≥ 0 (Hester et al. use 0.8).
    #[serde(default = "default_margin")]
    pub margin: f64,
    /// Neural: Adam's learning rate goes linearly from `learning_rate` to this over the first
    /// `learning_rate_anneal_steps` stored transitions, then stays there (absent: constant; as
    /// Stable-Baselines3's linear schedule, on the transition count instead of the run's fraction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learning_rate_end: Option<f64>,
    /// Neural: the length of that anneal, in stored transitions (environment steps).
    #[serde(default, skip_serializing_if = "is_zero_u64")]
    pub learning_rate_anneal_steps: u64,
    /// Neural: n-step returns (Rainbow's, and DQfD's n-step loss): a stored transition carries
    /// the discounted sum of up to `n_step` rewards and the state after them, and its target
    /// bootstraps with `gamma^n`; fewer at an episode's end (1 to [`MAX_N_STEP`]; 1: one-step TD,
    /// the paper's).
    #[serde(default = "default_n_step", skip_serializing_if = "is_one_u32")]
    #[schemars(extend("default" = 1))]
    pub n_step: u32,
    /// β of randomized prior functions (Osband et al. 2018), so that the heads disagree where no
    /// data has pulled them together (0: none, the paper's). Neural: each head's Q-values add β
    /// times the output of a fixed random network of the same shape that is never trained.
    /// Tabular: each head's Q-table starts from β times standard normal draws (the tabular
    /// prior of Osband et al.: a random start that learning washes out where data comes).
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub prior_scale: f64,
    /// The seed the prior (network or Q-tables) is drawn from (absent: the run's `seed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior_seed: Option<u64>,
}

fn is_zero_f64(v: &f64) -> bool {
    *v == 0.0
}

fn default_n_step() -> u32 {
    1
}
fn default_true() -> bool {
    true
}

fn is_true(v: &bool) -> bool {
    *v
}

fn is_one_u32(v: &u32) -> bool {
    *v == 1
}

/// A linear learning-rate anneal: `start` at 0 stored transitions, `end` from `steps` on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LrSchedule {
    pub start: f64,
    pub end: f64,
    pub steps: u64,
}

impl LrSchedule {
    /// The learning rate once `inserted` transitions were stored.
    pub fn at(&self, inserted: u64) -> f64 {
        if inserted >= self.steps {
            return self.end;
        }
        let f = inserted as f64 / self.steps as f64;
        self.start + (self.end - self.start) * f
    }
}

/// The loss on TD errors.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum LossKind {
    /// PyTorch's `HuberLoss(delta)` on the TD errors.
    #[default]
    Huber,
    /// The mean squared TD error.
    Mse,
}

fn default_huber_delta() -> f64 {
    1.0
}
fn default_tau() -> f64 {
    1.0
}
fn default_margin() -> f64 {
    0.8
}

fn default_gamma() -> f64 {
    0.99
}
fn default_temperature() -> f64 {
    1.0
}
fn default_epsilon_start() -> f64 {
    1.0
}
fn default_epsilon_end() -> f64 {
    0.05
}
fn default_epsilon_decay_steps() -> f64 {
    1000.0
}
fn default_bootstrap_probability() -> f64 {
    0.5
}
fn default_replay_capacity() -> usize {
    10_000
}
fn default_batch_size() -> usize {
    64
}
fn default_target_update_every() -> u64 {
    50
}
fn default_updates_per_step() -> u32 {
    1
}
fn default_hidden() -> usize {
    64
}

impl AgentConfig {
    pub fn heads(&self) -> usize {
        self.heads.unwrap_or(match self.kind {
            AgentKind::BootstrappedQ | AgentKind::Bdqn => 2,
            _ => 1,
        })
    }

    pub fn learning_rate(&self) -> f64 {
        self.learning_rate
            .unwrap_or(if self.kind.is_tabular() { 0.1 } else { 1e-3 })
    }

    /// The neural agents' learning-rate anneal (`learning_rate_end`), `None` if constant.
    pub fn learning_rate_schedule(&self) -> Option<LrSchedule> {
        self.learning_rate_end.map(|end| LrSchedule {
            start: self.learning_rate(),
            end,
            steps: self.learning_rate_anneal_steps,
        })
    }

    pub fn exploration(&self) -> Exploration {
        self.exploration.unwrap_or(match self.kind {
            AgentKind::Qlearning | AgentKind::Sarsa => Exploration::Softmax,
            AgentKind::Dqn => Exploration::EpsilonGreedy,
            AgentKind::BootstrappedQ | AgentKind::Bdqn => Exploration::GreedyHead,
        })
    }

    /// The width of the network's hidden layers: `hidden`, or `heads × hidden` with separate
    /// torsos (held block-diagonally, see [`crate::nn::Mlp`]).
    pub fn network_width(&self) -> usize {
        if self.shared_torso {
            self.hidden
        } else {
            self.hidden * self.heads()
        }
    }

    /// A freshly initialised Q-network of this agent (weights drawn from `rng`), with its
    /// randomized prior function when `prior_scale` > 0: actors, learner and target networks of
    /// one run all carry the same prior.
    pub fn network(
        &self,
        obs_dim: usize,
        actions: usize,
        rng: &mut crate::rng::Rng,
    ) -> crate::nn::Mlp {
        let (h, k) = (self.hidden, self.heads());
        let net = if self.shared_torso {
            crate::nn::Mlp::new(obs_dim, h, k, actions, rng)
        } else {
            crate::nn::Mlp::separate(obs_dim, h, k, actions, rng)
        };
        net.with_prior(self.prior_scale as f32, self.prior_seed.unwrap_or(0))
    }

    /// ε after `step` environment steps: `end + (start − end) · exp(−step / decay)`.
    pub fn epsilon(&self, step: u64) -> f64 {
        self.epsilon_end
            + (self.epsilon_start - self.epsilon_end)
                * crate::math::exp(-(step as f64) / self.epsilon_decay_steps)
    }
}

pub use crate::query::RuleKind;
pub use crate::shaping::ShapingKind;
pub use env::{EnvConfig, EnvName, MAX_DEEPSEA_SIZE, MAX_HEADS};
pub use expert::{changed_roster, BudgetConfig, ExpertConfig, PanelEntry, RosterChange};
pub use logging::LoggingConfig;
pub use query::QueryConfig;

/// Which model of the demonstrations shapes the reward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum DemoModelChoice {
    /// No model: no shaping.
    None,
    /// Kernel Ridge Regression (α = 0.1, RBF γ = 0.1).
    Krr,
    /// Kernel SVM (C = 10, RBF γ = 0.1) with Platt scaling.
    Svm,
    /// KRR on the first 512 demonstrations as Nyström landmarks (α = 0.1, RBF γ = 0.1): for
    /// budgets beyond the exact models' 10,000, up to 1,000,000.
    Nystrom,
}

impl ExperimentConfig {
    /// Parses TOML, applies `key=value` overrides (dotted keys, TOML values; bare words are
    /// strings), and validates.
    pub fn from_toml_with_overrides(text: &str, overrides: &[String]) -> Result<Self> {
        let mut value: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| ConfigError::Parse(e.to_string()))?;
        normalize::rename_query_mode(&mut value)?;
        expert::check_named_once(&value, overrides)?;
        normalize::default_expert_of_env(&mut value);
        for o in overrides {
            apply_override(&mut value, o)?;
        }
        let mut config: Self = toml::Value::Table(value)
            .try_into()
            .map_err(|e: toml::de::Error| ConfigError::Parse(e.to_string().trim().to_owned()))?;
        config.validate()?;
        if config.agent.prior_scale > 0.0 && config.agent.prior_seed.is_none() {
            config.agent.prior_seed = Some(config.seed);
        }
        Ok(config)
    }

    pub fn from_toml(text: &str) -> Result<Self> {
        Self::from_toml_with_overrides(text, &[])
    }

    /// Parses a config for the multi-process runtime, which runs the neural agents (on any
    /// environment with vector observations).
    pub fn for_multi_process(text: &str) -> Result<Self> {
        let cfg = Self::from_toml(text)?;
        cfg.check_multi_process()?;
        Ok(cfg)
    }

    /// What the multi-process runtime cannot run: tabular agents, gate `oracle` (it consults
    /// the expert at every step), several experts.
    pub fn check_multi_process(&self) -> Result<()> {
        if self.agent.kind.is_tabular() {
            return Err(invalid(
                "agent.kind",
                "the multi-process runtime runs neural agents (dqn, bdqn); run tabular configs with `alfd local`",
            ));
        }
        if self.query.gate == Some(crate::query::GateKind::Oracle) {
            return Err(invalid(
                "query.gate",
                "gate `oracle` consults the expert at every step, in the actor's process: run it \
                 with `alfd local` or `alfd sweep`",
            ));
        }
        Ok(())
    }

    /// Reads rule `random`'s schedule (`query.schedule`, `{seed}` replaced by the run's seed)
    /// into `query.schedule_steps` with `read` (a file's text, or why it cannot be read);
    /// nothing to do for the other rules. Every entry point that runs a config calls it.
    pub fn load_schedule(
        &mut self,
        read: impl FnOnce(&str) -> std::result::Result<String, String>,
    ) -> Result<()> {
        if self.query.rule != RuleKind::Random {
            return Ok(());
        }
        let path = self
            .query
            .schedule_path(self.seed)
            .ok_or_else(|| invalid("query.schedule", "rule `random` needs a schedule"))?;
        let text = read(&path)
            .map_err(|e| invalid("query.schedule", format!("cannot read {path}: {e}")))?;
        self.query.schedule_steps = crate::query::schedule_from_demos(&text)
            .map_err(|e| invalid("query.schedule", format!("{path}: {e}")))?;
        Ok(())
    }

    /// The config as TOML (what a run directory records as `config.toml`).
    pub fn to_toml(&self) -> String {
        if self.experts.is_empty() {
            return toml::to_string(self).expect("an ExperimentConfig always serialises");
        }
        let mut table = toml::Table::try_from(self).expect("an ExperimentConfig always serialises");
        {
            // With several experts `expert.name` is not the run's (it is the environment's
            // default, unused); written, it could name one of them and be refused on reading.
            if let Some(toml::Value::Table(e)) = table.get_mut("expert") {
                e.remove("name");
            }
        }
        toml::to_string(&table).expect("a config table always serialises")
    }

    /// The budget B, validated non-negative.
    pub fn budget(&self) -> u32 {
        self.budget.total as u32
    }

    /// DeepSea's mapping seed: `env.mapping_seed`, or else the run's seed (its low 32 bits), so
    /// that each seed of a sweep plays its own instance.
    pub fn deepsea_mapping_seed(&self) -> u32 {
        self.env.mapping_seed.unwrap_or(self.seed as u32)
    }

    /// The name the run's expert answers under: `expert.name`, or with several experts
    /// (`[[experts]]`) theirs joined by `+` (the expert process that routes among them).
    pub fn run_expert_name(&self) -> String {
        if self.experts.is_empty() {
            return self.expert.name.clone();
        }
        let names: Vec<&str> = self.experts.iter().map(|e| e.name.as_str()).collect();
        names.join("+")
    }

    /// Whether the run ever consults an expert: a budget to ask it, several experts, or the
    /// `oracle` gate. Without, no expert need exist for the environment (B = 0 anywhere).
    pub fn needs_expert(&self) -> bool {
        self.budget() > 0
            || !self.experts.is_empty()
            || self.query.gate == Some(crate::query::GateKind::Oracle)
    }

    /// The query rule's spec: `[query]` with the run's budget and length.
    pub fn rule_spec(&self) -> crate::query::RuleSpec {
        self.query.spec(u64::from(self.budget()), self.steps)
    }

    /// Whether the reward is shaped (a demonstration model is chosen).
    pub fn shaping_enabled(&self) -> bool {
        self.expert.model != DemoModelChoice::None
    }
}

/// Applies one `a.b.c=value` override to a TOML table.
fn apply_override(table: &mut toml::Table, item: &str) -> Result<()> {
    let (key, raw) = item
        .split_once('=')
        .ok_or_else(|| ConfigError::BadOverride(item.to_owned()))?;
    // `query.mode` is the older name of `query.rule`.
    let key = match key.trim() {
        "query.mode" => "query.rule",
        k => k,
    };
    if key.is_empty() || key.split('.').any(str::is_empty) {
        return Err(ConfigError::BadOverride(item.to_owned()));
    }
    let raw = raw.trim();
    // A TOML value when it parses as one, else a bare string (so `--set expert.name=cartpole-200` works).
    let value = format!("v = {raw}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_owned()));
    let parts: Vec<&str> = key.split('.').collect();
    let mut cur = table;
    for p in &parts[..parts.len() - 1] {
        let entry = cur
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = match entry {
            toml::Value::Table(t) => t,
            _ => {
                return Err(ConfigError::BadOverride(format!(
                    "{item} (`{p}` is not a section)"
                )))
            }
        };
    }
    cur.insert(parts[parts.len() - 1].to_owned(), value);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = r#"
seed = 1
episodes = 10
[env]
name = "cartpole"
[agent]
kind = "bdqn"
[expert]
model = "krr"
"#;

    #[test]
    fn defaults_follow_the_paper() {
        let c = ExperimentConfig::from_toml(BASE).unwrap();
        assert_eq!(c.agent.heads(), 2);
        assert_eq!(c.agent.learning_rate(), 1e-3);
        assert_eq!(c.agent.batch_size, 64);
        assert_eq!(c.agent.replay_capacity, 10_000);
        assert_eq!(c.agent.target_update_every, 50);
        assert_eq!(c.env.max_episode_steps(), 1000);
        assert_eq!(c.shaping.lambda, 0.75);
        assert_eq!(c.budget(), 100);
        assert_eq!(c.agent.exploration(), Exploration::GreedyHead);
        assert!((c.agent.epsilon(0) - 1.0).abs() < 1e-12);
        assert!((c.agent.epsilon(1_000_000) - 0.05).abs() < 1e-9);
    }

    #[test]
    fn overrides_apply_and_round_trip() {
        let c = ExperimentConfig::from_toml_with_overrides(
            BASE,
            &[
                "agent.heads=3".into(),
                "expert.name=cartpole-200".into(),
                "query.percentile=95.5".into(),
            ],
        )
        .unwrap();
        assert_eq!(c.agent.heads(), 3);
        assert_eq!(c.expert.name, "cartpole-200");
        assert_eq!(c.query.percentile, 95.5);
        assert_eq!(ExperimentConfig::from_toml(&c.to_toml()).unwrap(), c);
    }

    #[test]
    fn query_rule_keys_and_the_older_query_mode() {
        let rule = |text: &str, o: &[&str]| {
            let o: Vec<String> = o.iter().map(|s| s.to_string()).collect();
            ExperimentConfig::from_toml_with_overrides(&format!("{BASE}{text}"), &o)
                .map(|c| c.query.rule)
        };
        assert_eq!(rule("", &[]), Ok(RuleKind::Never));
        assert_eq!(rule("[query]\nmode = \"active\"\n", &[]), Ok(RuleKind::Js));
        assert_eq!(rule("[query]\nrule = \"q-std\"\n", &[]), Ok(RuleKind::QStd));
        // `--set query.mode=...` and `--set query.rule=...` both replace the file's rule.
        let js = "[query]\nrule = \"js\"\n";
        assert_eq!(rule(js, &["query.mode=first"]), Ok(RuleKind::First));
        assert_eq!(rule(js, &["query.rule=js-burst"]), Ok(RuleKind::JsBurst));
        let both = rule("[query]\nrule = \"js\"\nmode = \"first\"\n", &[]).unwrap_err();
        assert!(both.to_string().contains("query.mode"), "{both}");
        for kind in RuleKind::ALL {
            let c = ExperimentConfig::from_toml_with_overrides(
                BASE,
                &[
                    format!("query.rule={}", kind.name()),
                    "query.schedule=run/{seed}/demos.jsonl".into(),
                    "query.horizon=500".into(),
                ],
            )
            .unwrap();
            assert_eq!(c.query.rule, kind);
            assert_eq!(ExperimentConfig::from_toml(&c.to_toml()).unwrap(), c);
            assert_eq!(c.query.schedule_path(7).unwrap(), "run/7/demos.jsonl");
        }
        assert!(err(&["query.rule=random"]).contains("query.schedule"));
        assert!(err(&["query.probability=1.5"]).contains("query.probability"));
        assert!(err(&["query.burst=0"]).contains("query.burst"));
        assert!(err(&["query.gap=0"]).contains("query.gap"));
        assert!(err(&["query.rule=sometimes"]).contains("sometimes"));
        // js-spread spreads B over `steps`, or `query.horizon` in a run limited by episodes.
        assert!(err(&["query.rule=js-spread"]).contains("query.horizon"));
        let spread = |sets: &[&str]| {
            let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
            ExperimentConfig::from_toml_with_overrides(BASE, &sets)
                .unwrap()
                .rule_spec()
        };
        let s = spread(&["query.rule=js-spread", "steps=6000", "budget.total=30"]);
        assert_eq!((s.kind, s.total, s.horizon), (RuleKind::JsSpread, 30, 6000));
        let s = spread(&["query.rule=js-spread", "steps=6000", "query.horizon=900"]);
        assert_eq!(s.horizon, 900);
    }

    #[test]
    fn the_expert_defaults_to_the_environment_s_reference_expert() {
        let expert = |env: &str| {
            ExperimentConfig::from_toml(&format!(
                "seed = 0\nepisodes = 1\n[env]\nname = \"{env}\"\n[agent]\nkind = \"{}\"\n",
                if env == "cliffwalk" {
                    "qlearning"
                } else {
                    "bdqn"
                }
            ))
            .unwrap()
            .expert
            .name
        };
        assert_eq!(expert("cartpole"), "cartpole-1000");
        assert_eq!(expert("cliffwalk"), "cliffwalk-optimal");
        assert_eq!(expert("mountaincar"), "mountaincar-energy");
        assert_eq!(expert("acrobot"), "acrobot-energy");
        // A name given stays.
        let c = ExperimentConfig::from_toml_with_overrides(
            "seed = 0\nepisodes = 1\n[env]\nname = \"acrobot\"\n[agent]\nkind = \"bdqn\"\n",
            &["expert.name=acrobot-poor".into()],
        )
        .unwrap();
        assert_eq!(c.expert.name, "acrobot-poor");
    }

    #[test]
    fn the_random_rule_loads_its_schedule_from_a_run() {
        let mut c = ExperimentConfig::from_toml_with_overrides(
            BASE,
            &[
                "seed=3".into(),
                "query.rule=random".into(),
                "query.schedule=runs/{seed}/demos.jsonl".into(),
            ],
        )
        .unwrap();
        c.load_schedule(|p| {
            assert_eq!(p, "runs/3/demos.jsonl");
            Ok("{\"step\":4}\n{\"step\":2}\n".into())
        })
        .unwrap();
        assert_eq!(c.query.schedule_steps, vec![4, 2]);
        let e = c.load_schedule(|_| Err("no such file".into())).unwrap_err();
        let e = e.to_string();
        assert!(
            e.contains("query.schedule")
                && e.contains("cannot read runs/3/demos.jsonl: no such file"),
            "{e}"
        );
        let e = c
            .load_schedule(|_| Ok("{\"index\":0}\n".into()))
            .unwrap_err();
        assert!(e.to_string().contains("line 1"), "{e}");
    }

    fn err(overrides: &[&str]) -> String {
        let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        ExperimentConfig::from_toml_with_overrides(BASE, &o)
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn bad_values_name_the_field() {
        assert!(err(&["agent.heads=0"]).contains("agent.heads"));
        assert!(err(&["query.percentile=101"]).contains("query.percentile"));
        assert!(err(&["query.percentile=-1"]).contains("query.percentile"));
        assert!(err(&["budget.total=-5"]).contains("budget.total"));
        assert!(err(&["env.p_success=0"]).contains("env.p_success"));
        assert!(err(&["env.p_success=1.5"]).contains("env.p_success"));
        assert!(err(&["agent.kind=qlearning"]).contains("agent.kind"));
        assert!(err(&["episodes=0"]).contains("episodes"));
        let unknown = err(&["agent.hedas=2"]);
        assert!(unknown.contains("hedas"), "{unknown}");
        let unknown_env = err(&["env.name=pendulum"]);
        assert!(unknown_env.contains("pendulum"), "{unknown_env}");
        assert!(err(&["nonsense"]).contains("expected key=value"));
    }

    #[test]
    fn p_success_of_one_is_allowed() {
        let text = "seed = 0\nepisodes = 1\n[env]\nname = \"cliffwalk\"\np_success = 1.0\n[agent]\nkind = \"qlearning\"\n";
        let c = ExperimentConfig::from_toml(text).unwrap();
        assert_eq!(c.env.max_episode_steps(), 500);
        assert_eq!(c.agent.learning_rate(), 0.1);
    }

    #[test]
    fn sparse_reward_envs_take_neural_agents_and_their_own_limits() {
        for (name, limit) in [("mountaincar", 200), ("acrobot", 500)] {
            let c = ExperimentConfig::from_toml_with_overrides(BASE, &[format!("env.name={name}")])
                .unwrap();
            assert_eq!(c.env.max_episode_steps(), limit, "{name}");
            assert_eq!(c.env.name.to_string(), name);
            assert_eq!(name.parse::<EnvName>(), Ok(c.env.name));
            let tabular = err(&[&format!("env.name={name}"), "agent.kind=qlearning"]);
            assert!(
                tabular.contains("agent.kind")
                    && tabular.contains(&format!("does not run on {name}"))
                    && tabular.contains(
                        "neural ones on cartpole, mountaincar, acrobot, deepsea and gymnasium"
                    ),
                "{tabular}"
            );
            let map = err(&[&format!("env.name={name}"), "env.map=m.txt"]);
            assert!(map.contains("env.map"), "{map}");
        }
        let e = "pendulum".parse::<EnvName>().unwrap_err();
        assert_eq!(
            e,
            "unknown environment `pendulum` (known: cartpole, cliffwalk, mountaincar, acrobot, gymnasium, deepsea)"
        );
    }

    #[test]
    fn a_gymnasium_env_needs_an_id_and_keeps_its_kwargs() {
        let gym = |extra: &str| {
            ExperimentConfig::from_toml(&format!(
                "seed = 1\nepisodes = 2\n[env]\nname = \"gymnasium\"\n{extra}\n[agent]\nkind = \"bdqn\"\n"
            ))
        };
        let c = gym("id = \"Acrobot-v1\"\nkwargs = { render_mode = \"rgb_array\" }").unwrap();
        assert_eq!(c.env.id.as_deref(), Some("Acrobot-v1"));
        assert_eq!(c.env.max_episode_steps(), 0, "the registration's own limit");
        assert!(c.env.name.is_remote());
        assert_eq!(ExperimentConfig::from_toml(&c.to_toml()).unwrap(), c);
        let e = gym("").unwrap_err().to_string();
        assert!(e.contains("env.id") && e.contains("gymnasium.make"), "{e}");
        let e = gym("id = \"Bad id;rm\"").unwrap_err().to_string();
        assert!(e.contains("env.id"), "{e}");
        let e = gym("id = \"CartPole-v1\"\nmax_episode_steps = 0")
            .unwrap_err()
            .to_string();
        assert!(e.contains("env.max_episode_steps"), "{e}");
        assert!(err(&["env.id=CartPole-v1"]).contains("applies to gymnasium only"));
        let e = gym("id = \"CartPole-v1\"\n[agent2]")
            .unwrap_err()
            .to_string();
        assert!(!e.is_empty());
        let tab = ExperimentConfig::from_toml(
            "seed = 1\nepisodes = 2\n[env]\nname = \"gymnasium\"\nid = \"CartPole-v1\"\n[agent]\nkind = \"qlearning\"\n",
        )
        .unwrap_err()
        .to_string();
        assert!(tab.contains("agent.kind"), "{tab}");
    }

    #[test]
    fn a_prior_is_drawn_from_the_run_s_seed_unless_given() {
        let cfg = |set: &[&str]| {
            let set: Vec<String> = set.iter().map(|s| (*s).to_owned()).collect();
            ExperimentConfig::from_toml_with_overrides(BASE, &set)
        };
        let plain = cfg(&[]).unwrap();
        assert_eq!(
            (plain.agent.prior_scale, plain.agent.prior_seed),
            (0.0, None)
        );
        let with = cfg(&["seed=7", "agent.prior_scale=3.0"]).unwrap();
        assert_eq!(with.agent.prior_seed, Some(7));
        assert_eq!(ExperimentConfig::from_toml(&with.to_toml()).unwrap(), with);
        let given = cfg(&["agent.prior_scale=3.0", "agent.prior_seed=11"]).unwrap();
        assert_eq!(given.agent.prior_seed, Some(11));
        // Two runs of one seed build the same prior; the networks carry it.
        let mut rng = crate::rng::seeded(1);
        let net = with.agent.network(4, 2, &mut rng);
        let prior = net.prior().unwrap();
        assert_eq!((prior.scale(), prior.seed()), (3.0, 7));
        assert!(plain.agent.network(4, 2, &mut rng).prior().is_none());
        for bad in ["-1.0", "nan", "inf"] {
            let e = cfg(&[&format!("agent.prior_scale={bad}")]).unwrap_err();
            assert!(e.to_string().contains("agent.prior_scale"), "{e}");
        }
        // The Q-tables take a prior too: their start (see `agent::tabular`).
        let t = cfg(&[
            "agent.kind=qlearning",
            "env.name=cliffwalk",
            "agent.prior_scale=1.0",
            "expert.model=none",
        ])
        .unwrap();
        assert_eq!(
            (t.agent.prior_scale, t.agent.prior_seed),
            (1.0, Some(t.seed))
        );
    }

    #[test]
    fn a_written_config_reads_back_equal_even_with_evaluation_off_and_its_size_set() {
        // Found by the fuzz pass: `evaluation` was left out whenever it was off, losing `episodes`.
        let text = "seed = 0\nepisodes = 3\n[evaluation]\nepisodes = 5\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n";
        let cfg = ExperimentConfig::from_toml(text).unwrap();
        assert_eq!(ExperimentConfig::from_toml(&cfg.to_toml()).unwrap(), cfg);
    }
}
