//! When to ask the expert (paper section 3.3, Algorithm 1 lines 3-8), and the other query rules
//! the paper's is compared with. A rule sees the [`Signals`] of the current state and answers
//! whether to ask; it is consulted only while budget remains.
//!
//! The paper's rule ([`RuleKind::Js`]) compares the heads' Jensen-Shannon divergence with the
//! `p_r` percentile of the last `L_q` divergences ([`PercentileGate`]). The same gate thresholds
//! the other disagreement signals (the heads' Q-value spread, the novelty of the state), so that
//! they ask at the same rate and differ only in *where* they ask.

use rand::Rng as _;
use serde::{Deserialize, Serialize};

use crate::rng::{Rng, RngState};

mod composed;
mod gate;
pub use composed::{Allowance, AllowanceKind, Composed, Gate, GateKind, Oracle};
pub use gate::{percentile, PercentileGate};

/// Which rule decides when to ask (`query.rule`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum RuleKind {
    /// Never: pure RL.
    Never,
    /// On every step until the budget is spent (the paper's "all the budget at the beginning").
    First,
    /// The paper's rule: the JS divergence of the heads' softmax policies (eq. 3) above the `p_r`
    /// percentile of the last `L_q` values.
    #[serde(alias = "active")]
    Js,
    /// A matched control: asks at the global steps at which a recorded run asked
    /// (`query.schedule`, that run's `demos.jsonl`), whatever the state.
    Random,
    /// Asks with probability `query.probability` at every step.
    Uniform,
    /// The spread (standard deviation) of the heads' Q-values at the greedy action of their mean,
    /// above the `p_r` percentile of the last `L_q` values (EnsembleDAgger, RCMP).
    QStd,
    /// The state's distance to the nearest demonstration held, in the demonstration model's RBF
    /// kernel (`1 − max_i k(s, x_i)`), above the `p_r` percentile of the last `L_q` values; asks
    /// whenever no demonstration is held yet (ThriftyDAgger's novelty).
    Novelty,
    /// The paper's rule, but when it fires the expert drives the next `query.burst` steps: the
    /// demonstrations come as short trajectories instead of isolated states.
    JsBurst,
    /// The paper's rule, but at most one query in any `query.gap` consecutive steps: the heads'
    /// disagreement picks the states, the gap spreads the budget over the run as `uniform` does.
    JsPaced,
    /// The paper's rule, with the budget spread over the run: with `n` demonstrations used it
    /// asks at global step `t` only if `n·H ≤ B·t` (`H` = `query.horizon`, the run's `steps` by
    /// default), so the `(n+1)`-th is allowed from step `n·H/B`. The disagreement picks the
    /// states, the budget and the horizon set the pace; an allowance not spent carries over.
    JsSpread,
}

impl RuleKind {
    /// Every rule, in the order the documents list them.
    pub const ALL: [RuleKind; 10] = [
        RuleKind::Never,
        RuleKind::First,
        RuleKind::Js,
        RuleKind::Random,
        RuleKind::Uniform,
        RuleKind::QStd,
        RuleKind::Novelty,
        RuleKind::JsBurst,
        RuleKind::JsPaced,
        RuleKind::JsSpread,
    ];

    /// The name in configs (`query.rule`).
    pub fn name(self) -> &'static str {
        match self {
            RuleKind::Never => "never",
            RuleKind::First => "first",
            RuleKind::Js => "js",
            RuleKind::Random => "random",
            RuleKind::Uniform => "uniform",
            RuleKind::QStd => "q-std",
            RuleKind::Novelty => "novelty",
            RuleKind::JsBurst => "js-burst",
            RuleKind::JsPaced => "js-paced",
            RuleKind::JsSpread => "js-spread",
        }
    }
}

/// What a rule sees at one state. [`Rule::decide_at`] computes `q_std` and `novelty` only for the
/// rules that read them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Signals {
    /// The run's global step of this state.
    pub step: u64,
    /// The Jensen-Shannon divergence of the heads' softmax policies (eq. 3; 0 with one head).
    pub js: f64,
    /// The standard deviation over the heads of `Q_k(s, a*)`, `a*` the greedy action of the
    /// heads' mean Q-values (0 with one head).
    pub q_std: f64,
    /// `1 − max_i k(s, x_i)` over the demonstrations held; `None` when none is held.
    pub novelty: Option<f64>,
    /// Demonstrations used in the run so far, as far as the acting agent knows.
    pub used: u64,
    /// Whether the learner's greedy action differs from the expert's (gate `oracle` only;
    /// `None` when not computed).
    pub disagrees: Option<bool>,
}

/// Budget B as the acting agent sees it at a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BudgetView {
    /// Whether any demonstration is left.
    pub left: bool,
    /// Demonstrations used in the run so far.
    pub used: u64,
}

impl BudgetView {
    /// Budget left, none used yet.
    pub const FRESH: BudgetView = BudgetView {
        left: true,
        used: 0,
    };
}

/// A query rule: whether to ask the expert at a state, given its [`Signals`]. Called once per
/// step, and only while budget remains.
pub trait QueryRule {
    fn ask(&mut self, signals: &Signals) -> bool;
}

/// What a [`Rule`] is built from: `query.*` with the schedule of [`RuleKind::Random`] loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct RuleSpec {
    pub kind: RuleKind,
    pub queue_len: usize,
    pub percentile: f64,
    pub probability: f64,
    pub burst: u32,
    pub gap: u64,
    /// The global steps to ask at (rule `random`), in any order.
    pub schedule: Vec<u64>,
    /// B, the run's budget (rule `js-spread`).
    pub total: u64,
    /// H, the steps over which rule `js-spread` spreads B (the config requires ≥ 1 for it).
    pub horizon: u64,
    /// `query.allowance` and `query.gate`: a rule in two parts, in place of `kind`.
    pub parts: Option<(AllowanceKind, GateKind)>,
    /// W, gate `record`'s window in allowed steps.
    pub window: u64,
}

/// Never asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Never;

impl QueryRule for Never {
    fn ask(&mut self, _: &Signals) -> bool {
        false
    }
}

/// Asks at every step (while budget remains).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct First;

impl QueryRule for First {
    fn ask(&mut self, _: &Signals) -> bool {
        true
    }
}

/// Which signal a [`Disagreement`] rule thresholds (and [`Signal::Oracle`], which only gate
/// `oracle` reads).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Signal {
    Js,
    QStd,
    Novelty,
    Oracle,
}

/// A signal above the `p_r` percentile of its last `L_q` values (Algorithm 1 lines 4-7 with the
/// signal in place of the divergence). With [`Signal::Novelty`] the rule asks, and pushes
/// nothing, while no demonstration is held.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Disagreement {
    pub signal: Signal,
    pub gate: PercentileGate,
}

impl QueryRule for Disagreement {
    fn ask(&mut self, s: &Signals) -> bool {
        let u = match self.signal {
            Signal::Js => s.js,
            Signal::QStd => s.q_std,
            Signal::Novelty => match s.novelty {
                Some(u) => u,
                None => return true,
            },
            Signal::Oracle => unreachable!("the oracle is a gate of its own"),
        };
        self.gate.observe(u)
    }
}

/// Asks at the global steps of a recorded run's queries: at the first state whose step is at or
/// past the next scheduled one (one query per state; a late start catches up one at a time).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scheduled {
    /// Sorted, ascending.
    steps: Vec<u64>,
    next: usize,
}

impl Scheduled {
    pub fn new(mut steps: Vec<u64>) -> Self {
        steps.sort_unstable();
        Self { steps, next: 0 }
    }
}

impl QueryRule for Scheduled {
    fn ask(&mut self, s: &Signals) -> bool {
        match self.steps.get(self.next) {
            Some(&due) if due <= s.step => {
                self.next += 1;
                true
            }
            _ => false,
        }
    }
}

/// Asks with a fixed probability at every step, from its own generator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uniform {
    probability: f64,
    rng: RngState,
}

impl Uniform {
    pub fn new(probability: f64, rng: &Rng) -> Self {
        Self {
            probability,
            rng: RngState::of(rng),
        }
    }
}

impl QueryRule for Uniform {
    fn ask(&mut self, _: &Signals) -> bool {
        let mut rng = self.rng.to_rng();
        let u: f64 = rng.random();
        self.rng = RngState::of(&rng);
        u < self.probability
    }
}

/// The paper's rule, and when it fires the next `len − 1` steps ask too (a burst of `len`
/// consecutive demonstrations). The divergence is pushed to the queue on every step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Burst {
    pub gate: PercentileGate,
    pub len: u32,
    /// Steps of the current burst still to ask at.
    pub left: u32,
}

impl QueryRule for Burst {
    fn ask(&mut self, s: &Signals) -> bool {
        let fired = self.gate.observe(s.js);
        if self.left > 0 {
            self.left -= 1;
            return true;
        }
        if fired {
            self.left = self.len.saturating_sub(1);
        }
        fired
    }
}

/// The paper's rule, asking only when at least `gap` steps have passed since its last query. The
/// divergence is pushed to the queue on every step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Paced {
    pub gate: PercentileGate,
    pub gap: u64,
    /// The global step of the last query.
    pub last: Option<u64>,
}

impl QueryRule for Paced {
    fn ask(&mut self, s: &Signals) -> bool {
        let fired = self.gate.observe(s.js);
        let ready = self
            .last
            .is_none_or(|t| s.step >= t.saturating_add(self.gap));
        if fired && ready {
            self.last = Some(s.step);
        }
        fired && ready
    }
}

/// The paper's rule, asking only while `used·horizon ≤ total·step`: B spread evenly over H steps,
/// the first demonstration allowed from the start, the `(n+1)`-th from step `n·H/B`. The
/// divergence is pushed to the queue on every step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Spread {
    pub gate: PercentileGate,
    pub total: u64,
    pub horizon: u64,
}

impl Spread {
    /// Whether one more demonstration is allowed at `step` with `used` spent: `used·H ≤ B·step`.
    pub fn allows(&self, used: u64, step: u64) -> bool {
        u128::from(used) * u128::from(self.horizon) <= u128::from(self.total) * u128::from(step)
    }
}

impl QueryRule for Spread {
    fn ask(&mut self, s: &Signals) -> bool {
        let fired = self.gate.observe(s.js);
        fired && self.allows(s.used, s.step)
    }
}

/// Every rule, with its state (what a checkpoint keeps).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Rule {
    Never(Never),
    First(First),
    Disagreement(Disagreement),
    Scheduled(Scheduled),
    Uniform(Uniform),
    Burst(Burst),
    Paced(Paced),
    Spread(Spread),
    Composed(Composed),
}

impl Rule {
    /// The rule of `spec`; `rng` seeds [`Uniform`]'s generator (and is read, not advanced).
    pub fn new(spec: &RuleSpec, rng: &Rng) -> Self {
        let gate = || PercentileGate::new(spec.queue_len, spec.percentile);
        let disagreement = |signal| {
            Rule::Disagreement(Disagreement {
                signal,
                gate: gate(),
            })
        };
        if let Some((allowance, g)) = spec.parts {
            return Rule::Composed(Composed {
                allowance: Allowance::new(allowance, spec.total, spec.horizon),
                gate: Gate::new(g, spec.queue_len, spec.percentile, spec.window, rng),
            });
        }
        match spec.kind {
            RuleKind::Never => Rule::Never(Never),
            RuleKind::First => Rule::First(First),
            RuleKind::Js => disagreement(Signal::Js),
            RuleKind::QStd => disagreement(Signal::QStd),
            RuleKind::Novelty => disagreement(Signal::Novelty),
            RuleKind::Random => Rule::Scheduled(Scheduled::new(spec.schedule.clone())),
            RuleKind::Uniform => {
                let mut seeder = rng.clone();
                Rule::Uniform(Uniform::new(
                    spec.probability,
                    &crate::rng::seeded(seeder.random()),
                ))
            }
            RuleKind::JsBurst => Rule::Burst(Burst {
                gate: gate(),
                len: spec.burst.max(1),
                left: 0,
            }),
            RuleKind::JsPaced => Rule::Paced(Paced {
                gate: gate(),
                gap: spec.gap,
                last: None,
            }),
            RuleKind::JsSpread => Rule::Spread(Spread {
                gate: gate(),
                total: spec.total,
                horizon: spec.horizon,
            }),
        }
    }

    /// Algorithm 1 lines 3-8 for one state: whether to ask, given its signals. Nothing is asked,
    /// and no signal pushed to a queue, once the budget is spent (as in the paper).
    pub fn decide(&mut self, signals: &Signals, budget_left: bool) -> bool {
        budget_left && self.ask(signals)
    }

    /// [`Rule::decide`] at the run's global step `step` with divergence `js`, calling the lazy
    /// signals only when the budget is left and the rule reads them (the act step's hot path).
    pub fn decide_at(
        &mut self,
        budget: BudgetView,
        step: u64,
        js: f64,
        q_std: impl FnOnce() -> f64,
        novelty: impl FnOnce() -> Option<f64>,
        disagrees: impl FnOnce() -> Option<bool>,
    ) -> bool {
        if !budget.left {
            return false;
        }
        let signals = Signals {
            step,
            js,
            used: budget.used,
            q_std: if self.reads(Signal::QStd) {
                q_std()
            } else {
                0.0
            },
            novelty: if self.reads(Signal::Novelty) {
                novelty()
            } else {
                None
            },
            disagrees: if self.reads(Signal::Oracle) {
                disagrees()
            } else {
                None
            },
        };
        self.ask(&signals)
    }

    /// Whether the rule reads `signal` beyond the divergence (the agents keep the demonstrated
    /// states only for a rule that reads the novelty, and consult the expert only for gate
    /// `oracle`).
    pub fn reads(&self, signal: Signal) -> bool {
        match self {
            Rule::Disagreement(d) => d.signal == signal,
            Rule::Composed(c) => c.gate.reads(signal),
            _ => false,
        }
    }
}

impl QueryRule for Rule {
    fn ask(&mut self, s: &Signals) -> bool {
        match self {
            Rule::Never(r) => r.ask(s),
            Rule::First(r) => r.ask(s),
            Rule::Disagreement(r) => r.ask(s),
            Rule::Scheduled(r) => r.ask(s),
            Rule::Uniform(r) => r.ask(s),
            Rule::Burst(r) => r.ask(s),
            Rule::Paced(r) => r.ask(s),
            Rule::Spread(r) => r.ask(s),
            Rule::Composed(r) => r.ask(s),
        }
    }
}

/// The global steps of the queries recorded in a run's `demos.jsonl` (one JSON object a line,
/// each with a `step`), the schedule of [`RuleKind::Random`].
pub fn schedule_from_demos(text: &str) -> Result<Vec<u64>, String> {
    #[derive(Deserialize)]
    struct Line {
        step: u64,
    }
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str::<Line>(l)
                .map(|d| d.step)
                .map_err(|e| format!("line {}: {e}", i + 1))
        })
        .collect()
}

/// The standard deviation over `heads` heads of `Q_k(s, a*)`, `a*` the greedy action of the
/// heads' mean (`q` holds `heads × actions` values, head-major; population standard deviation).
pub fn q_spread(q: &[f64], heads: usize) -> f64 {
    let actions = q.len() / heads;
    let mean_q = |a: usize| (0..heads).map(|k| q[k * actions + a]).sum::<f64>() / heads as f64;
    let best = mean_greedy(q, heads);
    let mean = mean_q(best);
    let var = (0..heads)
        .map(|k| (q[k * actions + best] - mean).powi(2))
        .sum::<f64>()
        / heads as f64;
    var.sqrt()
}

/// The greedy action of the heads' mean Q-values (`q`: `heads × actions`, head-major; the
/// first of equal values).
pub fn mean_greedy(q: &[f64], heads: usize) -> usize {
    let actions = q.len() / heads;
    let mean_q = |a: usize| (0..heads).map(|k| q[k * actions + a]).sum::<f64>() / heads as f64;
    (0..actions)
        .map(mean_q)
        .enumerate()
        .fold((0, f64::NEG_INFINITY), |(bi, bv), (i, v)| {
            if v > bv {
                (i, v)
            } else {
                (bi, bv)
            }
        })
        .0
}

/// The RBF kernel width of the demonstration models (`k(x, y) = exp(−γ|x − y|²)`).
pub const NOVELTY_KERNEL_GAMMA: f64 = 0.1;

/// `1 − max_i exp(−γ|s − x_i|²)` over `held` (γ = [`NOVELTY_KERNEL_GAMMA`]); `None` when
/// `held` is empty.
pub fn novelty<'a>(s: &[f64], held: impl IntoIterator<Item = &'a [f64]>) -> Option<f64> {
    let nearest = held
        .into_iter()
        .map(|x| s.iter().zip(x).map(|(a, b)| (a - b) * (a - b)).sum::<f64>())
        .reduce(f64::min)?;
    Some(1.0 - crate::math::exp(-NOVELTY_KERNEL_GAMMA * nearest))
}

/// The demonstration budget `B`: how many expert queries may still be answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Budget {
    total: u32,
    used: u32,
}

impl Budget {
    pub fn new(total: u32) -> Self {
        Self { total, used: 0 }
    }

    /// A budget of which `used` queries are already spent (an expert restarted on a run).
    pub fn with_used(total: u32, used: u32) -> Self {
        Self {
            total,
            used: used.min(total),
        }
    }

    /// Spends one query if any remains (Algorithm 1 line 8); `false` when the budget is exhausted.
    pub fn try_spend(&mut self) -> bool {
        if self.used < self.total {
            self.used += 1;
            true
        } else {
            false
        }
    }

    pub fn remaining(&self) -> u32 {
        self.total - self.used
    }

    pub fn used(&self) -> u32 {
        self.used
    }

    pub fn total(&self) -> u32 {
        self.total
    }

    pub fn is_exhausted(&self) -> bool {
        self.used >= self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(step: u64) -> Signals {
        Signals {
            step,
            ..Signals::default()
        }
    }

    fn spec(kind: RuleKind) -> RuleSpec {
        RuleSpec {
            kind,
            queue_len: 3,
            percentile: 50.0,
            probability: 0.25,
            burst: 3,
            gap: 2,
            schedule: vec![9, 3, 5],
            total: 4,
            horizon: 20,
            parts: None,
            window: 8,
        }
    }

    #[test]
    fn never_and_first() {
        let rng = crate::rng::seeded(0);
        let mut never = Rule::new(&spec(RuleKind::Never), &rng);
        let mut first = Rule::new(&spec(RuleKind::First), &rng);
        for step in 0..5 {
            assert!(!never.decide(&at(step), true));
            assert!(first.decide(&at(step), true));
            assert!(
                !first.decide(&at(step), false),
                "nothing asked without budget"
            );
        }
    }

    #[test]
    fn each_disagreement_rule_reads_its_own_signal() {
        let rng = crate::rng::seeded(0);
        // The same gate (L_q = 3, median) over js, q_std or novelty; the other signals are noise.
        let values = [1.0, 2.0, 1.5, 1.6, 1.55];
        let fired = [false, true, false, true, false]; // rule_compares_with_queue_before_push
        for kind in [RuleKind::Js, RuleKind::QStd, RuleKind::Novelty] {
            let mut rule = Rule::new(&spec(kind), &rng);
            for (i, (&u, &want)) in values.iter().zip(&fired).enumerate() {
                let noise = 100.0 - i as f64; // would fire differently if read
                let s = match kind {
                    RuleKind::Js => Signals {
                        js: u,
                        q_std: noise,
                        novelty: Some(noise),
                        ..Signals::default()
                    },
                    RuleKind::QStd => Signals {
                        js: noise,
                        q_std: u,
                        novelty: Some(noise),
                        ..Signals::default()
                    },
                    _ => Signals {
                        js: noise,
                        q_std: noise,
                        novelty: Some(u),
                        ..Signals::default()
                    },
                };
                assert_eq!(rule.decide(&s, true), want, "{kind:?} step {i}");
            }
        }
    }

    #[test]
    fn decide_at_computes_only_the_signals_the_rule_reads_and_nothing_without_budget() {
        let rng = crate::rng::seeded(0);
        let mut js = Rule::new(&spec(RuleKind::Js), &rng);
        let never_called = || -> f64 { panic!("q_std computed for the js rule") };
        assert!(!js.decide_at(
            BudgetView::FRESH,
            0,
            1.0,
            never_called,
            || panic!("novelty computed"),
            || None
        ));
        assert!(js.decide_at(
            BudgetView::FRESH,
            1,
            2.0,
            never_called,
            || panic!("novelty computed"),
            || None
        ));
        let mut q = Rule::new(&spec(RuleKind::QStd), &rng);
        assert!(!q.decide_at(
            BudgetView::FRESH,
            0,
            9.0,
            || 1.0,
            || panic!("novelty computed"),
            || None
        ));
        assert!(q.decide_at(
            BudgetView::FRESH,
            1,
            0.0,
            || 2.0,
            || panic!("novelty computed"),
            || None
        ));
        assert!(!q.decide_at(
            BudgetView::default(),
            2,
            0.0,
            || panic!("computed without budget"),
            || None,
            || None
        ));
        let mut n = Rule::new(&spec(RuleKind::Novelty), &rng);
        assert!(
            n.decide_at(BudgetView::FRESH, 0, 0.0, never_called, || None, || None),
            "nothing held: ask"
        );
        // The budget's use reaches the rule: js-spread (B = 4, H = 20) with 1 used at step 1.
        let mut spread = Rule::new(&spec(RuleKind::JsSpread), &rng);
        let used = |used| BudgetView { left: true, used };
        assert!(!spread.decide_at(used(0), 0, 1.0, never_called, || None, || None));
        assert!(!spread.decide_at(used(1), 1, 2.0, never_called, || None, || None));
        assert!(spread.decide_at(used(0), 2, 3.0, never_called, || None, || None));
        assert!(n.reads(Signal::Novelty) && !n.reads(Signal::QStd) && !js.reads(Signal::Novelty));
    }

    #[test]
    fn the_old_rule_names_are_an_allowance_and_a_gate_with_the_same_decisions() {
        let rng = crate::rng::seeded(0);
        let pairs = [
            (RuleKind::Js, AllowanceKind::First, GateKind::Js),
            (RuleKind::QStd, AllowanceKind::First, GateKind::QStd),
            (RuleKind::Novelty, AllowanceKind::First, GateKind::Novelty),
            (RuleKind::JsSpread, AllowanceKind::Spread, GateKind::Js),
        ];
        let mut draw = crate::rng::seeded(5);
        let stream: Vec<Signals> = (0..400)
            .map(|t| Signals {
                step: t,
                js: draw.random(),
                q_std: draw.random(),
                novelty: (t > 3).then(|| draw.random()),
                used: t / 7,
                disagrees: None,
            })
            .collect();
        for (kind, allowance, gate) in pairs {
            let mut old = Rule::new(&spec(kind), &rng);
            let parts = RuleSpec {
                parts: Some((allowance, gate)),
                ..spec(RuleKind::Never)
            };
            let mut new = Rule::new(&parts, &rng);
            for s in &stream {
                assert_eq!(
                    old.decide(s, true),
                    new.decide(s, true),
                    "{kind:?} at {}",
                    s.step
                );
            }
        }
    }

    #[test]
    fn novelty_asks_while_nothing_is_held_and_pushes_nothing_then() {
        let mut rule = Rule::new(&spec(RuleKind::Novelty), &crate::rng::seeded(0));
        assert!(rule.decide(&Signals::default(), true));
        assert!(rule.decide(&Signals::default(), true));
        let held = |u| Signals {
            novelty: Some(u),
            ..Signals::default()
        };
        // The queue is still empty: the first value held never fires, the next above it does.
        assert!(!rule.decide(&held(0.5), true));
        assert!(rule.decide(&held(0.6), true));
        // Without budget nothing is pushed: 0.55 is compared with median([0.5, 0.6]) = 0.55.
        assert!(!rule.decide(&held(9.0), false));
        assert!(!rule.decide(&held(0.55), true));
    }

    #[test]
    fn scheduled_asks_at_the_recorded_steps_and_catches_up_one_at_a_time() {
        let mut rule = Rule::new(&spec(RuleKind::Random), &crate::rng::seeded(0));
        // Schedule [9, 3, 5] sorted to [3, 5, 9]; step 9 is skipped over and asked at 11.
        let asked: Vec<u64> = [0, 3, 4, 5, 6, 11, 12, 13]
            .into_iter()
            .filter(|&t| rule.decide(&at(t), true))
            .collect();
        assert_eq!(asked, vec![3, 5, 11]);
        // A late start (steps 3 and 5 both past at step 7) asks once per state.
        let mut late = Rule::new(&spec(RuleKind::Random), &crate::rng::seeded(0));
        let asked: Vec<bool> = (7..10).map(|t| late.decide(&at(t), true)).collect();
        assert_eq!(asked, vec![true, true, true]);
        assert!(!late.decide(&at(10), true));
    }

    #[test]
    fn uniform_asks_with_its_probability_from_its_own_generator() {
        let rng = crate::rng::seeded(7);
        let mut a = Rule::new(&spec(RuleKind::Uniform), &rng);
        let mut b = Rule::new(&spec(RuleKind::Uniform), &rng);
        let n = 20_000;
        let asked_a: Vec<bool> = (0..n).map(|t| a.decide(&at(t), true)).collect();
        let asked_b: Vec<bool> = (0..n).map(|t| b.decide(&at(t), true)).collect();
        assert_eq!(asked_a, asked_b, "the same generator gives the same draws");
        let rate = asked_a.iter().filter(|&&x| x).count() as f64 / n as f64;
        // Binomial(20000, 0.25): standard deviation 0.0031; 5 of them either side.
        assert!((rate - 0.25).abs() < 0.016, "{rate}");
        for (p, want) in [(0.0, false), (1.0, true)] {
            let mut r = Rule::new(
                &RuleSpec {
                    probability: p,
                    ..spec(RuleKind::Uniform)
                },
                &rng,
            );
            assert!((0..100).all(|t| r.decide(&at(t), true) == want), "p = {p}");
        }
    }

    #[test]
    fn burst_asks_for_the_next_steps_after_the_gate_fires() {
        let mut rule = Rule::new(&spec(RuleKind::JsBurst), &crate::rng::seeded(0));
        let js = |js| Signals {
            js,
            ..Signals::default()
        };
        // Gate alone: [no (empty), yes (2 > 1), no, yes, no]. Burst of 3: the yes at step 1 also
        // asks at steps 2 and 3 (the gate's yes at 3 is inside that burst and starts none).
        let asked: Vec<bool> = [1.0, 2.0, 1.5, 1.6, 1.55, 0.0, 5.0]
            .into_iter()
            .map(|u| rule.decide(&js(u), true))
            .collect();
        assert_eq!(asked, vec![false, true, true, true, false, false, true]);
    }

    #[test]
    fn paced_asks_when_the_gate_fires_and_the_gap_has_passed() {
        let mut rule = Rule::new(&spec(RuleKind::JsPaced), &crate::rng::seeded(0));
        let s = |step, js| Signals {
            step,
            js,
            ..Signals::default()
        };
        // Gate alone: [no (empty), yes, no, yes, no, no, yes] at steps 0..7; with gap 2 each yes
        // is at least 2 steps after the one before (1, 3 >= 1 + 2, 6 >= 3 + 2): all asked.
        let asked: Vec<bool> = [1.0, 2.0, 1.5, 1.6, 1.55, 0.0, 5.0]
            .into_iter()
            .enumerate()
            .map(|(t, u)| rule.decide(&s(t as u64, u), true))
            .collect();
        assert_eq!(asked, vec![false, true, false, true, false, false, true]);
        // Queue [1.55, 0, 5] (median 1.55): 9 fires at step 7 but only 1 step after the last query.
        assert!(!rule.decide(&s(7, 9.0), true));
        // Queue [0, 5, 9] (median 5): 9.5 fires at step 8, 2 steps after: asked.
        assert!(rule.decide(&s(8, 9.5), true));
    }

    #[test]
    fn spread_asks_when_the_gate_fires_within_the_allowance() {
        // B = 4 over H = 20 steps: one more demonstration is allowed while used·20 ≤ 4t, that
        // is used ≤ t/5: the first from step 0, the second from 5, the third from 10, ...
        let mut rule = Rule::new(&spec(RuleKind::JsSpread), &crate::rng::seeded(0));
        let s = |step, js, used| Signals {
            step,
            js,
            used,
            ..Signals::default()
        };
        // Gate alone at steps 0..7: [no (empty), yes, no, yes, no, no, yes]. Step 1: 0 ≤ 1/5:
        // asked. Step 3: 1 used, 1 > 3/5: not asked. Step 6: 1 ≤ 6/5: asked.
        let used = [0, 0, 1, 1, 1, 1, 1];
        let asked: Vec<bool> = [1.0, 2.0, 1.5, 1.6, 1.55, 0.0, 5.0]
            .into_iter()
            .zip(used)
            .enumerate()
            .map(|(t, (u, n))| rule.decide(&s(t as u64, u, n), true))
            .collect();
        assert_eq!(asked, vec![false, true, false, false, false, false, true]);
        // An allowance not spent carries over: from step 15 on, up to 3 used allow one more;
        // with 2 used a firing gate asks twice in a row, and not a third time with 4 used.
        assert!(rule.decide(&s(15, 9.0, 2), true));
        assert!(rule.decide(&s(16, 9.5, 3), true));
        assert!(!rule.decide(&s(17, 9.9, 4), true));
        let Rule::Spread(spread) = rule else {
            panic!("js-spread builds a Spread")
        };
        // The edges: 1·20 ≤ 4·5 but not ≤ 4·4; 2·20 ≤ 4·10 but not ≤ 4·9.
        assert!(spread.allows(1, 5) && !spread.allows(1, 4));
        assert!(spread.allows(2, 10) && !spread.allows(2, 9));
        // No overflow near u64::MAX: (MAX/5)·20 ≤ 4·MAX, (MAX/4 + 1)·20 > 4·MAX.
        assert!(spread.allows(u64::MAX / 5, u64::MAX));
        assert!(!spread.allows(u64::MAX / 4 + 1, u64::MAX));
    }

    #[test]
    fn q_spread_is_the_heads_standard_deviation_at_the_greedy_action_of_their_mean() {
        // Heads [1, 4] and [3, 2]: mean [2, 3], greedy action 1, values 4 and 2: std 1.
        assert_eq!(q_spread(&[1.0, 4.0, 3.0, 2.0], 2), 1.0);
        // Three heads agreeing: 0.
        assert_eq!(q_spread(&[1.0, 2.0, 1.0, 2.0, 1.0, 2.0], 3), 0.0);
        // One head of three actions: 0.
        assert_eq!(q_spread(&[5.0, 1.0, 2.0], 1), 0.0);
    }

    #[test]
    fn novelty_is_one_minus_the_kernel_of_the_nearest_demonstration() {
        let held = [vec![1.0, 0.0], vec![3.0, 4.0]];
        let u = novelty(&[0.0, 0.0], held.iter().map(Vec::as_slice)).unwrap();
        // Nearest squared distance 1: 1 − exp(−0.1) = 0.095162581964040...
        assert!((u - 0.095_162_581_964_040_43).abs() < 1e-15, "{u}");
        assert_eq!(
            novelty(&[3.0, 4.0], held.iter().map(Vec::as_slice)),
            Some(0.0)
        );
        assert_eq!(novelty(&[0.0, 0.0], std::iter::empty()), None);
    }

    #[test]
    fn schedule_reads_the_steps_of_demos_jsonl() {
        let text = "{\"index\":0,\"state\":[0.5],\"action\":1,\"step\":6,\"expert\":\"e\"}\n\n{\"index\":1,\"state\":[0.2],\"action\":0,\"step\":40,\"expert\":\"e\"}\n";
        assert_eq!(schedule_from_demos(text), Ok(vec![6, 40]));
        let err = schedule_from_demos("{\"step\":1}\n{\"index\":2}\n").unwrap_err();
        assert!(err.starts_with("line 2:"), "{err}");
    }

    #[test]
    fn rules_survive_a_snapshot_exactly() {
        let rng = crate::rng::seeded(3);
        let parts = AllowanceKind::ALL
            .into_iter()
            .flat_map(|a| GateKind::ALL.into_iter().map(move |g| Some((a, g))));
        let specs = RuleKind::ALL
            .into_iter()
            .map(spec)
            .chain(parts.map(|parts| RuleSpec {
                parts,
                ..spec(RuleKind::Never)
            }));
        for spec in specs {
            let kind = spec.clone();
            let mut rule = Rule::new(&spec, &rng);
            let s = |t: u64| Signals {
                step: t,
                js: (t as f64 * 0.7).sin(),
                q_std: (t as f64 * 1.3).cos(),
                novelty: Some((t as f64 * 0.4).sin().abs()),
                used: t / 4,
                disagrees: Some(t.is_multiple_of(3)),
            };
            for t in 0..20 {
                rule.decide(&s(t), true);
            }
            let bytes = postcard::to_stdvec(&rule).unwrap();
            let mut copy: Rule = postcard::from_bytes(&bytes).unwrap();
            for t in 20..60 {
                assert_eq!(
                    rule.decide(&s(t), true),
                    copy.decide(&s(t), true),
                    "{kind:?}"
                );
            }
        }
    }

    #[test]
    fn budget_never_goes_below_zero() {
        let mut b = Budget::new(2);
        assert!(b.try_spend());
        assert!(b.try_spend());
        assert!(!b.try_spend());
        assert_eq!(b.remaining(), 0);
        assert_eq!(b.used(), 2);
        assert!(b.is_exhausted());
        assert_eq!(Budget::with_used(5, 9).remaining(), 0);
        assert_eq!(Budget::with_used(5, 3).remaining(), 2);
    }
}
