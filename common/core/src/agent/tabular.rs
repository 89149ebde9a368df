//! The tabular agents of section 5.1.1: Q-learning and SARSA with softmax exploration, and
//! bootstrapped Q-learning (K Q-tables, randomized masked updates, one greedy head per episode).
//! A tabular agent learns where it acts: it is an `Actor` of the environment loop by itself.

use rand::Rng as _;

use serde::{Deserialize, Serialize};

use crate::agent::{Decision, Explorer};
use crate::checkpoint::StateMismatch;
use crate::config::{AgentConfig, AgentKind};
use crate::env::Step;
use crate::math;
use crate::policy::argmax;
use crate::qfunction::{QFunction, TabularQ};
use crate::query::{mean_greedy, q_spread, BudgetView, Oracle, Rule, RuleSpec, Signal};
use crate::rng::{Rng, RngState};

/// A tabular agent over `states` states and `actions` actions.
#[derive(Debug, Clone)]
pub struct TabularAgent {
    kind: AgentKind,
    explorer: Explorer,
    q: TabularQ,
    temperature: f64,
    lr: f64,
    lr_decay: f64,
    /// Updates of each (state, head, action), for the decaying step size.
    visits: Vec<u32>,
    gamma: f64,
    bootstrap_probability: f64,
    rng: Rng,
    /// The head followed this episode (Algorithm 1 line 1).
    arm: usize,
    rule: Rule,
    /// The states demonstrated so far, sorted (the novelty rule's reference set: a state is novel,
    /// 1, until it is demonstrated, 0).
    demo_states: Vec<usize>,
    /// SARSA's last transition `(s, a, r, s')`, learned from once the action at `s'` is known.
    pending: Option<(usize, usize, f64, usize)>,
    /// The expert gate `oracle` consults (none for the other gates).
    oracle: Option<Oracle<usize>>,
    /// With `agent.margin_loss_weight` > 0, the margin by which a demonstrated action stays
    /// above the others at its state in every head (DQfD's large margin as a hard constraint).
    margin: Option<f64>,
    /// The last action demonstrated at each demonstrated state (with a margin only).
    demo_actions: std::collections::BTreeMap<usize, usize>,
}

/// The Q-tables' start: zeros, or with `agent.prior_scale` β > 0, β times standard normal
/// draws (Box-Muller) from a generator seeded with `agent.prior_seed`.
fn prior_tables(cfg: &AgentConfig, states: usize, heads: usize, actions: usize) -> TabularQ {
    let mut q = TabularQ::new(states, heads, actions, 0.0);
    if cfg.prior_scale <= 0.0 {
        return q;
    }
    let mut rng = crate::rng::seeded(crate::rng::derive_seed(
        cfg.prior_seed.unwrap_or(0),
        "tabular-prior",
    ));
    for s in 0..states {
        for k in 0..heads {
            for a in 0..actions {
                let (u1, u2): (f64, f64) = (rng.random(), rng.random());
                let z = (-2.0 * math::ln(1.0 - u1)).sqrt() * math::cos(std::f64::consts::TAU * u2);
                q.set(s, k, a, cfg.prior_scale * z);
            }
        }
    }
    q
}

/// What a [`TabularAgent`] must remember to continue exactly: the Q-tables, the visit counts,
/// ε's clock, its generator, the head followed, the divergence queue and SARSA's pending step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TabularSnapshot {
    pub q: TabularQ,
    pub visits: Vec<u32>,
    pub explorer_steps: u64,
    pub rng: RngState,
    pub arm: usize,
    pub rule: Rule,
    pub demo_states: Vec<usize>,
    pub pending: Option<(usize, usize, f64, usize)>,
    /// The demonstrated actions the margin holds to, by state.
    #[serde(default)]
    pub demo_actions: std::collections::BTreeMap<usize, usize>,
}

impl TabularAgent {
    pub fn snapshot(&self) -> TabularSnapshot {
        TabularSnapshot {
            q: self.q.clone(),
            visits: self.visits.clone(),
            explorer_steps: self.explorer.steps(),
            rng: RngState::of(&self.rng),
            arm: self.arm,
            rule: self.rule.clone(),
            demo_states: self.demo_states.clone(),
            pending: self.pending,
            demo_actions: self.demo_actions.clone(),
        }
    }

    /// Restores [`TabularAgent::snapshot`] into an agent built from the same config and map.
    pub fn restore(&mut self, s: &TabularSnapshot) -> Result<(), StateMismatch> {
        let shape = |q: &TabularQ| (q.states(), q.heads(), q.actions());
        if shape(&s.q) != shape(&self.q) || s.visits.len() != self.visits.len() {
            return Err(StateMismatch(format!(
                "Q-tables of shape {:?} where the run has {:?}",
                shape(&s.q),
                shape(&self.q)
            )));
        }
        if s.arm >= self.q.heads() {
            return Err(StateMismatch(format!(
                "head {} of {}",
                s.arm,
                self.q.heads()
            )));
        }
        self.q = s.q.clone();
        self.visits = s.visits.clone();
        self.explorer.restore_steps(s.explorer_steps);
        self.rng = s.rng.to_rng();
        self.arm = s.arm;
        self.rule = s.rule.clone();
        self.demo_states = s.demo_states.clone();
        self.pending = s.pending;
        self.demo_actions = s.demo_actions.clone();
        Ok(())
    }

    pub fn new(
        cfg: &AgentConfig,
        rule: &RuleSpec,
        states: usize,
        actions: usize,
        rng: Rng,
    ) -> Self {
        let heads = cfg.heads();
        let rule = Rule::new(rule, &rng);
        Self {
            kind: cfg.kind,
            explorer: Explorer::new(cfg, actions),
            q: prior_tables(cfg, states, heads, actions),
            temperature: cfg.temperature,
            lr: cfg.learning_rate(),
            lr_decay: cfg.learning_rate_decay,
            visits: vec![0; states * heads * actions],
            gamma: cfg.gamma,
            bootstrap_probability: cfg.bootstrap_probability,
            rng,
            arm: 0,
            rule,
            demo_states: Vec::new(),
            pending: None,
            oracle: None,
            margin: (cfg.margin_loss_weight > 0.0).then_some(cfg.margin),
            demo_actions: std::collections::BTreeMap::new(),
        }
    }

    /// The expert gate `oracle` consults at every step (for the gate alone).
    pub fn set_oracle(&mut self, oracle: Oracle<usize>) {
        self.oracle = Some(oracle);
    }

    /// Whether the rule needs an oracle ([`TabularAgent::set_oracle`]).
    pub fn needs_oracle(&self) -> bool {
        self.rule.reads(Signal::Oracle)
    }

    pub fn q(&self) -> &TabularQ {
        &self.q
    }

    pub fn arm(&self) -> usize {
        self.arm
    }

    /// Algorithm 1 line 1: sample the head to follow this episode.
    pub fn begin_episode(&mut self) {
        self.arm = self.rng.random_range(0..self.q.heads());
    }

    /// The Jensen-Shannon divergence of the K heads' softmax policies at `s` (0 for one head).
    pub fn js_divergence(&mut self, s: usize) -> f64 {
        if self.q.heads() == 1 {
            return 0.0;
        }
        self.q.js_divergence(&s, self.temperature)
    }

    /// The agent's own action at `s` on the episode's head.
    pub fn act(&mut self, s: usize) -> usize {
        self.explorer
            .act(self.q.head_values(s, self.arm), &mut self.rng)
    }

    /// Algorithm 1 lines 3-16 at `s`, the run's global step `step`: the divergence, the agent's
    /// own action, and the query rule's decision.
    pub fn decide(&mut self, s: usize, step: u64, budget: BudgetView) -> Decision {
        let js = self.js_divergence(s);
        let action = self.act(s);
        let (q, held, oracle) = (&self.q, &self.demo_states, &self.oracle);
        let heads = q.heads();
        let query = self.rule.decide_at(
            budget,
            step,
            js,
            || {
                let values: Vec<f64> = (0..heads)
                    .flat_map(|k| q.head_values(s, k).iter().copied())
                    .collect();
                q_spread(&values, heads)
            },
            // A state is novel (1) until it is demonstrated (0).
            || (!held.is_empty()).then(|| f64::from(held.binary_search(&s).is_err())),
            || {
                let oracle = oracle.as_ref()?;
                let values: Vec<f64> = (0..heads)
                    .flat_map(|k| q.head_values(s, k).iter().copied())
                    .collect();
                Some(oracle.action(&s) != mean_greedy(&values, heads))
            },
        );
        Decision { action, js, query }
    }

    /// Remembers that `s` was demonstrated (the novelty rule's reference set).
    fn note_demo(&mut self, s: usize) {
        if let Err(i) = self.demo_states.binary_search(&s) {
            self.demo_states.insert(i, s);
        }
    }

    /// Learns from one transition. `next_action` is the action taken at `s_next` (SARSA's target;
    /// ignored by Q-learning). A terminal transition does not bootstrap; a truncated one does.
    pub fn learn(
        &mut self,
        s: usize,
        a: usize,
        r: f64,
        s_next: usize,
        terminated: bool,
        next_action: Option<usize>,
    ) {
        for k in 0..self.q.heads() {
            // Randomized update keeping the heads diverse: head k learns with probability p.
            if self.q.heads() > 1 && self.rng.random::<f64>() >= self.bootstrap_probability {
                continue;
            }
            let next = if terminated {
                0.0
            } else {
                match (self.kind, next_action) {
                    (AgentKind::Sarsa, Some(a_next)) => self.q.get(s_next, k, a_next),
                    _ => self.q.max_value(s_next, k),
                }
            };
            let i = (s * self.q.heads() + k) * self.q.actions() + a;
            self.visits[i] = self.visits[i].saturating_add(1);
            let lr = if self.lr_decay == 0.0 {
                self.lr
            } else {
                self.lr / math::powf(f64::from(self.visits[i]), self.lr_decay)
            };
            self.q.update_towards(s, k, a, r + self.gamma * next, lr);
        }
        self.hold_margin(s);
    }

    /// At a demonstrated state, raises every head's value of the demonstrated action to at least
    /// the margin above its best other action (nothing without a margin or a demonstration).
    fn hold_margin(&mut self, s: usize) {
        let Some(margin) = self.margin else { return };
        let Some(&a_e) = self.demo_actions.get(&s) else {
            return;
        };
        for k in 0..self.q.heads() {
            let others = (0..self.q.actions())
                .filter(|&a| a != a_e)
                .map(|a| self.q.get(s, k, a))
                .fold(f64::NEG_INFINITY, f64::max);
            if self.q.get(s, k, a_e) < others + margin {
                self.q.set(s, k, a_e, others + margin);
            }
        }
    }

    /// The greedy policy of the agent (of head 0, or of the mean over heads when K > 1).
    pub fn greedy_policy(&self) -> Vec<usize> {
        let heads = self.q.heads();
        let actions = self.q.actions();
        (0..self.q.states())
            .map(|s| {
                let mut mean = vec![0.0; actions];
                for k in 0..heads {
                    for (m, v) in mean.iter_mut().zip(self.q.head_values(s, k)) {
                        *m += v / heads as f64;
                    }
                }
                argmax(&mean)
            })
            .collect()
    }
}

impl TabularAgent {
    /// Learns from a step as it is taken. SARSA's target needs the action taken at `s'`, so
    /// SARSA learns from a step when the next one is observed (or at once when the episode ends
    /// there).
    pub fn observe_step(&mut self, obs: usize, action: usize, step: &Step<usize>, demo: bool) {
        if demo && self.rule.reads(Signal::Novelty) {
            self.note_demo(obs);
        }
        if demo && self.margin.is_some() {
            self.demo_actions.insert(obs, action);
            self.hold_margin(obs);
        }
        if let Some((s, a, r, s_next)) = self.pending.take() {
            self.learn(s, a, r, s_next, false, Some(action));
        }
        if step.done() {
            self.learn(
                obs,
                action,
                step.reward,
                step.observation,
                step.terminated,
                None,
            );
        } else if self.kind == AgentKind::Sarsa {
            self.pending = Some((obs, action, step.reward, step.observation));
        } else {
            self.learn(obs, action, step.reward, step.observation, false, None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ExperimentConfig, QueryConfig};

    fn cfg(kind: &str, extra: &str) -> AgentConfig {
        let text = format!("seed = 0\nepisodes = 1\n[env]\nname = \"cliffwalk\"\n[agent]\nkind = \"{kind}\"\n{extra}");
        ExperimentConfig::from_toml(&text).unwrap().agent
    }

    #[test]
    fn a_prior_starts_each_head_from_its_own_draws_and_none_starts_from_zero() {
        let spec = QueryConfig::default().spec(0, 0);
        let make = |extra: &str| {
            let c = cfg("bootstrapped-q", &format!("heads = 4\n{extra}"));
            TabularAgent::new(&c, &spec, 50, 2, crate::rng::seeded(0))
        };
        let plain = make("");
        assert!((0..50).all(|s| (0..4).all(|k| plain.q.head_values(s, k) == [0.0, 0.0])));
        let a = make("prior_scale = 2.0");
        let values: Vec<f64> = (0..50)
            .flat_map(|s| (0..4).flat_map(move |k| [(s, k, 0), (s, k, 1)]))
            .map(|(s, k, x)| a.q.get(s, k, x))
            .collect();
        // 400 draws of 2·N(0, 1): mean near 0, standard deviation near 2.
        let mean = values.iter().sum::<f64>() / 400.0;
        let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 400.0).sqrt();
        assert!(mean.abs() < 0.4 && (sd - 2.0).abs() < 0.3, "{mean} {sd}");
        assert_ne!(a.q.head_values(7, 0), a.q.head_values(7, 1), "heads differ");
        // The same seed, the same prior; another prior_seed, another.
        assert_eq!(make("prior_scale = 2.0").q, a.q);
        assert_ne!(make("prior_scale = 2.0\nprior_seed = 9").q, a.q);
    }

    #[test]
    fn a_margin_keeps_the_demonstrated_action_ahead_in_every_head() {
        let spec = QueryConfig::default().spec(0, 0);
        let c = cfg(
            "bootstrapped-q",
            "heads = 3\nlearning_rate = 1.0\nmargin_loss_weight = 1.0\nmargin = 0.5",
        );
        let mut a = TabularAgent::new(&c, &spec, 4, 2, crate::rng::seeded(0));
        for k in 0..3 {
            a.q.set(2, k, 0, 1.0);
        }
        let step = |r| Step {
            observation: 3,
            reward: r,
            terminated: false,
            truncated: false,
        };
        // The expert moved with action 1 at state 2: ahead of action 0 by the margin everywhere.
        a.observe_step(2, 1, &step(0.0), true);
        for k in 0..3 {
            assert!(a.q.get(2, k, 1) >= a.q.get(2, k, 0) + 0.5, "head {k}");
        }
        // Learning that raises action 0 keeps action 1 ahead.
        a.observe_step(2, 0, &step(5.0), false);
        for k in 0..3 {
            assert!(a.q.get(2, k, 1) >= a.q.get(2, k, 0) + 0.5, "head {k}");
        }
        assert_eq!(a.greedy_policy()[2], 1);
        // Without the margin a demonstration is one more step to learn from.
        let plain = cfg("bootstrapped-q", "heads = 3\nlearning_rate = 1.0");
        let mut b = TabularAgent::new(&plain, &spec, 4, 2, crate::rng::seeded(0));
        b.observe_step(2, 1, &step(0.0), true);
        assert!(b.demo_actions.is_empty());
    }

    #[test]
    fn qlearning_and_sarsa_targets_differ_as_they_should() {
        let mut ql = TabularAgent::new(
            &cfg("qlearning", "learning_rate = 1.0\ngamma = 0.5"),
            &QueryConfig::default().spec(0, 0),
            2,
            2,
            crate::rng::seeded(0),
        );
        let mut sa = TabularAgent::new(
            &cfg("sarsa", "learning_rate = 1.0\ngamma = 0.5"),
            &QueryConfig::default().spec(0, 0),
            2,
            2,
            crate::rng::seeded(0),
        );
        for agent in [&mut ql, &mut sa] {
            agent.q.set(1, 0, 0, 4.0);
            agent.q.set(1, 0, 1, -2.0);
            agent.learn(0, 1, 1.0, 1, false, Some(1));
        }
        assert_eq!(
            ql.q.get(0, 0, 1),
            1.0 + 0.5 * 4.0,
            "Q-learning bootstraps from the max"
        );
        assert_eq!(
            sa.q.get(0, 0, 1),
            1.0 + 0.5 * -2.0,
            "SARSA bootstraps from the action taken"
        );
        ql.learn(0, 0, 3.0, 1, true, None);
        assert_eq!(
            ql.q.get(0, 0, 0),
            3.0,
            "a terminal transition does not bootstrap"
        );
    }

    #[test]
    fn masked_updates_train_each_head_about_half_the_time() {
        let mut agent = TabularAgent::new(
            &cfg("bootstrapped-q", "heads = 4\nlearning_rate = 1.0"),
            &QueryConfig::default().spec(0, 0),
            1000,
            2,
            crate::rng::seeded(1),
        );
        for s in 0..1000 {
            agent.learn(s, 0, 1.0, s, true, None);
        }
        for k in 0..4 {
            let trained = (0..1000).filter(|&s| agent.q.get(s, k, 0) == 1.0).count();
            assert!(
                (400..600).contains(&trained),
                "head {k} trained on {trained} of 1000"
            );
        }
        // The heads now disagree, so the divergence is positive somewhere.
        let max_js = (0..1000)
            .map(|s| agent.js_divergence(s))
            .fold(0.0, f64::max);
        assert!(max_js > 0.01, "{max_js}");
    }

    #[test]
    fn softmax_exploration_follows_the_policy() {
        let mut agent = TabularAgent::new(
            &cfg("qlearning", "temperature = 1.0"),
            &QueryConfig::default().spec(0, 0),
            1,
            2,
            crate::rng::seeded(2),
        );
        agent.q.set(0, 0, 1, 2f64.ln()); // pi = (1/3, 2/3)
        let ones = (0..30_000).filter(|_| agent.act(0) == 1).count();
        assert!((ones as f64 / 30_000.0 - 2.0 / 3.0).abs() < 0.01, "{ones}");
    }
}
