//! A query rule in two parts: an *allowance* says when the next demonstration may be asked for
//! (`query.allowance`), a *gate* which state is asked once it may (`query.gate`). Holding the
//! allowance fixed and changing the gate compares *where* rules ask at the same *times*; gate
//! `chance` is the state-blind control, gate `oracle` the ceiling (it knows where the learner's
//! greedy action is wrong).

use std::sync::{Arc, Mutex};

use rand::Rng as _;
use serde::{Deserialize, Serialize};

use super::{PercentileGate, Signal, Signals};
use crate::rng::Rng;

/// When the `(n+1)`-th demonstration may be asked for (`query.allowance`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum AllowanceKind {
    /// At any step while budget remains.
    First,
    /// From step `n·H/B` on, `n` demonstrations used (`n·H ≤ B·t`): B spread evenly over H
    /// steps, an allowance not spent carrying over (as rule `js-spread`).
    Spread,
    /// One demonstration in each of B windows of `H/B` steps; an allowance not spent in its
    /// window lapses.
    Uniform,
}

impl AllowanceKind {
    pub const ALL: [AllowanceKind; 3] = [
        AllowanceKind::First,
        AllowanceKind::Spread,
        AllowanceKind::Uniform,
    ];

    pub fn name(self) -> &'static str {
        match self {
            AllowanceKind::First => "first",
            AllowanceKind::Spread => "spread",
            AllowanceKind::Uniform => "uniform",
        }
    }
}

/// Which state is asked once the allowance permits (`query.gate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum GateKind {
    /// State-blind: asks with probability `1 − p_r/100` at each allowed step, the rate at which
    /// a percentile gate fires on a steady signal (the matched control).
    Chance,
    /// The heads' JS divergence above the `p_r` percentile of its last `L_q` values (the
    /// paper's).
    Js,
    /// The heads' Q-value spread above its `p_r` percentile.
    QStd,
    /// The state's distance to the demonstrations held above its `p_r` percentile (asks while
    /// none is held).
    Novelty,
    /// Where the learner's greedy action differs from the expert's: the expert consulted at every
    /// step for the gate alone (never a demonstration). A ceiling, not a method.
    Oracle,
    /// The secretary's rule on the divergence: once the allowance opens, watch the first
    /// `W/e` allowed steps, then ask at the first state more uncertain than all of them (at the
    /// `W`-th allowed step at the latest); `W` = `query.window`.
    Record,
}

impl GateKind {
    pub const ALL: [GateKind; 6] = [
        GateKind::Chance,
        GateKind::Js,
        GateKind::QStd,
        GateKind::Novelty,
        GateKind::Oracle,
        GateKind::Record,
    ];

    pub fn name(self) -> &'static str {
        match self {
            GateKind::Chance => "chance",
            GateKind::Js => "js",
            GateKind::QStd => "q-std",
            GateKind::Novelty => "novelty",
            GateKind::Oracle => "oracle",
            GateKind::Record => "record",
        }
    }
}

/// An allowance with its state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Allowance {
    First,
    Spread {
        total: u64,
        horizon: u64,
    },
    Uniform {
        total: u64,
        horizon: u64,
        /// The window of the last demonstration asked for.
        last: Option<u64>,
    },
}

impl Allowance {
    /// `kind` for a budget of `total` over `horizon` steps (≥ 1 for `spread` and `uniform`).
    pub fn new(kind: AllowanceKind, total: u64, horizon: u64) -> Self {
        match kind {
            AllowanceKind::First => Allowance::First,
            AllowanceKind::Spread => Allowance::Spread { total, horizon },
            AllowanceKind::Uniform => Allowance::Uniform {
                total,
                horizon,
                last: None,
            },
        }
    }

    /// The window of step `step`: `⌊step·B/H⌋`.
    fn window(total: u64, horizon: u64, step: u64) -> u64 {
        (u128::from(step) * u128::from(total) / u128::from(horizon.max(1))) as u64
    }

    /// Whether a demonstration may be asked for at `step` with `used` spent.
    pub fn allows(&self, used: u64, step: u64) -> bool {
        match *self {
            Allowance::First => true,
            Allowance::Spread { total, horizon } => {
                u128::from(used) * u128::from(horizon) <= u128::from(total) * u128::from(step)
            }
            Allowance::Uniform {
                total,
                horizon,
                last,
            } => last != Some(Self::window(total, horizon, step)),
        }
    }

    /// A demonstration was asked for at `step`.
    fn asked(&mut self, step: u64) {
        if let Allowance::Uniform {
            total,
            horizon,
            last,
        } = self
        {
            *last = Some(Self::window(*total, *horizon, step));
        }
    }
}

/// The expert as gate `oracle` consults it: the action it would demonstrate at a state (`S`:
/// `[f32]` for the neural agents, `usize` for the tabular ones). Not part of a checkpoint: the
/// runner gives it again.
pub struct Oracle<S: ?Sized>(Arc<Mutex<OracleFn<S>>>);

/// What an [`Oracle`] calls.
type OracleFn<S> = dyn FnMut(&S) -> usize + Send;

impl<S: ?Sized> Clone for Oracle<S> {
    fn clone(&self) -> Self {
        Self(Arc::clone(&self.0))
    }
}

impl<S: ?Sized> Oracle<S> {
    pub fn new(f: impl FnMut(&S) -> usize + Send + 'static) -> Self {
        Self(Arc::new(Mutex::new(f)))
    }

    /// The expert's action at `s`.
    pub fn action(&self, s: &S) -> usize {
        let mut f = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        f(s)
    }
}

impl<S: ?Sized> std::fmt::Debug for Oracle<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Oracle")
    }
}

/// A gate with its state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Gate {
    /// Rule `uniform`'s draw, at the allowed steps only.
    Chance(super::Uniform),
    Threshold {
        signal: Signal,
        gate: PercentileGate,
    },
    Oracle,
    Record {
        /// Allowed steps watched before the gate may fire (`⌈W/e⌉`).
        watch: u64,
        /// Allowed steps after which it fires whatever the state (`W`).
        window: u64,
        /// Allowed steps seen since the allowance opened (none: closed).
        seen: Option<u64>,
        /// The most uncertain state watched.
        best: f64,
    },
}

impl Gate {
    /// `kind` with percentile `p_r`, queue `L_q` and window `W`; `rng` seeds gate `chance` (read,
    /// not advanced).
    pub fn new(kind: GateKind, queue_len: usize, percentile: f64, window: u64, rng: &Rng) -> Self {
        let threshold = |signal| Gate::Threshold {
            signal,
            gate: PercentileGate::new(queue_len, percentile),
        };
        match kind {
            GateKind::Chance => {
                let mut seeder = rng.clone();
                let draws = crate::rng::seeded(seeder.random());
                Gate::Chance(super::Uniform::new(1.0 - percentile / 100.0, &draws))
            }
            GateKind::Js => threshold(Signal::Js),
            GateKind::QStd => threshold(Signal::QStd),
            GateKind::Novelty => threshold(Signal::Novelty),
            GateKind::Oracle => Gate::Oracle,
            GateKind::Record => Gate::Record {
                watch: (window as f64 / std::f64::consts::E).ceil() as u64,
                window: window.max(1),
                seen: None,
                best: f64::NEG_INFINITY,
            },
        }
    }

    /// The signal the gate reads beyond the divergence, if any.
    pub fn reads(&self, signal: Signal) -> bool {
        match self {
            Gate::Threshold { signal: s, .. } => *s == signal,
            Gate::Oracle => signal == Signal::Oracle,
            Gate::Chance(_) | Gate::Record { .. } => false,
        }
    }

    /// Whether the gate asks at the state of `s`, `allowed` by the allowance. A percentile gate
    /// sees every step's signal (its window stays the last `L_q` steps); the others look only at
    /// allowed steps.
    fn fire(&mut self, s: &Signals, allowed: bool) -> bool {
        match self {
            Gate::Threshold { signal, gate } => {
                let u = match signal {
                    Signal::Js => s.js,
                    Signal::QStd => s.q_std,
                    Signal::Novelty => match s.novelty {
                        Some(u) => u,
                        None => return allowed,
                    },
                    Signal::Oracle => unreachable!("no percentile gate reads the oracle"),
                };
                gate.observe(u) && allowed
            }
            _ if !allowed => {
                if let Gate::Record { seen, .. } = self {
                    *seen = None;
                }
                false
            }
            Gate::Chance(draw) => super::QueryRule::ask(draw, s),
            Gate::Oracle => s.disagrees == Some(true),
            Gate::Record {
                watch,
                window,
                seen,
                best,
            } => {
                let n = seen.map_or(0, |n| n + 1);
                if n == 0 {
                    *best = f64::NEG_INFINITY;
                }
                *seen = Some(n);
                let fire = (n >= *watch && s.js > *best) || n + 1 >= *window;
                if fire {
                    *seen = None;
                } else if n < *watch {
                    *best = best.max(s.js);
                }
                fire
            }
        }
    }
}

/// An allowance and a gate: asks when the gate fires at a step the allowance permits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Composed {
    pub allowance: Allowance,
    pub gate: Gate,
}

impl Composed {
    pub fn ask(&mut self, s: &Signals) -> bool {
        let allowed = self.allowance.allows(s.used, s.step);
        let fired = self.gate.fire(s, allowed);
        if fired {
            self.allowance.asked(s.step);
        }
        fired
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(step: u64, used: u64, js: f64) -> Signals {
        Signals {
            step,
            used,
            js,
            ..Signals::default()
        }
    }

    #[test]
    fn spread_allows_the_next_demonstration_from_step_n_h_over_b() {
        // B = 4 over H = 20: the (n+1)-th from step 5n.
        let a = Allowance::new(AllowanceKind::Spread, 4, 20);
        assert!(a.allows(0, 0));
        assert!(!a.allows(1, 4));
        assert!(a.allows(1, 5));
        assert!(!a.allows(2, 9));
        assert!(a.allows(2, 10));
        // Not spent: it carries over (3 used at step 20 is allowed, 4·20 ≤ 4·20).
        assert!(a.allows(3, 20));
    }

    #[test]
    fn uniform_allows_one_per_window_and_an_unspent_one_lapses() {
        // B = 4 over H = 20: windows [0,5), [5,10), [10,15), [15,20).
        let mut a = Allowance::new(AllowanceKind::Uniform, 4, 20);
        assert!(a.allows(0, 3));
        a.asked(3);
        assert!(!a.allows(1, 4), "one per window");
        assert!(a.allows(1, 5));
        // Nothing asked in [5, 15): at step 15 only one is allowed, not three.
        a.asked(15);
        assert!(!a.allows(2, 19));
        assert!(a.allows(2, 20));
    }

    #[test]
    fn chance_asks_at_the_rate_of_the_percentile_and_only_when_allowed() {
        let mut c = Composed {
            allowance: Allowance::First,
            gate: Gate::new(GateKind::Chance, 10, 90.0, 10, &crate::rng::seeded(3)),
        };
        let asked = (0..20_000).filter(|&t| c.ask(&at(t, 0, 0.0))).count();
        // 1 − 90/100 = 0.1 of 20,000: 2,000 ± 4.5 standard deviations (42).
        assert!((1810..2190).contains(&asked), "{asked}");
        let mut closed = Composed {
            allowance: Allowance::new(AllowanceKind::Spread, 0, 100),
            gate: Gate::new(GateKind::Chance, 10, 0.0, 10, &crate::rng::seeded(3)),
        };
        assert!((1..100).all(|t| !closed.ask(&at(t, 1, 0.0))));
    }

    #[test]
    fn the_oracle_asks_where_the_greedy_action_is_the_experts_wrong() {
        let mut c = Composed {
            allowance: Allowance::First,
            gate: Gate::new(GateKind::Oracle, 10, 99.0, 10, &crate::rng::seeded(0)),
        };
        let s = |disagrees| Signals {
            disagrees,
            ..Signals::default()
        };
        assert!(c.ask(&s(Some(true))));
        assert!(!c.ask(&s(Some(false))));
        assert!(!c.ask(&s(None)));
        assert!(c.gate.reads(Signal::Oracle) && !c.gate.reads(Signal::Js));
    }

    #[test]
    fn record_watches_w_over_e_steps_then_takes_the_first_state_above_them_all() {
        // W = 8: watch ⌈8/e⌉ = 3 allowed steps, then ask above their maximum, at the 8th at
        // the latest.
        let mut c = Composed {
            allowance: Allowance::First,
            gate: Gate::new(GateKind::Record, 10, 99.0, 8, &crate::rng::seeded(0)),
        };
        let js = [0.2, 0.5, 0.3, 0.4, 0.5, 0.6];
        let asked: Vec<bool> = js
            .iter()
            .enumerate()
            .map(|(t, &u)| c.ask(&at(t as u64, 0, u)))
            .collect();
        // 0.6 is the first above 0.5, the best of the three watched.
        assert_eq!(asked, [false, false, false, false, false, true]);
        // A new watch starts: 3 watched (max 0.9), then nothing above it until the 8th.
        let later: Vec<bool> = [0.9, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]
            .iter()
            .enumerate()
            .map(|(t, &u)| c.ask(&at(6 + t as u64, 0, u)))
            .collect();
        assert_eq!(
            later,
            [false, false, false, false, false, false, false, true]
        );
    }

    #[test]
    fn record_starts_its_watch_again_when_the_allowance_closes() {
        let mut c = Composed {
            allowance: Allowance::new(AllowanceKind::Spread, 1, 10),
            gate: Gate::new(GateKind::Record, 10, 99.0, 4, &crate::rng::seeded(0)),
        };
        // ⌈4/e⌉ = 2 watched. Allowed at step 0 (0 used).
        assert!(!c.ask(&at(0, 0, 0.5)));
        assert!(!c.ask(&at(1, 0, 0.1)));
        // Closed (1 used before step 10): the watch ends.
        assert!(!c.ask(&at(2, 1, 0.9)));
        assert_eq!(
            c.gate,
            Gate::Record {
                watch: 2,
                window: 4,
                seen: None,
                best: 0.5
            }
        );
    }
}
