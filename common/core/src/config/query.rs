//! `[query]`: when the agent asks the expert.

use serde::{Deserialize, Serialize};

use super::RuleKind;
use crate::query::{AllowanceKind, GateKind};

/// When the agent asks the expert (`[query]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct QueryConfig {
    /// The query rule (`active` is read as `js`; the older key `query.mode` as `query.rule`).
    /// Leave it out (`never`) when the rule is given in two parts, `allowance` and `gate`.
    #[serde(default = "default_query_rule")]
    pub rule: RuleKind,
    /// When the next demonstration may be asked for: `first` (any step while budget remains),
    /// `spread` (B spread over H steps, an unspent allowance carried over), `uniform` (one in
    /// each window of H/B steps, an unspent one lapsing). Default `first`; only with `gate`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub allowance: Option<AllowanceKind>,
    /// Which state is asked once the allowance permits: `chance` (state-blind, probability
    /// 1 − p_r/100), `js`, `q-std`, `novelty` (above the p_r percentile of the last L_q values),
    /// `oracle` (where the greedy action differs from the expert's: a ceiling, `alfd local` and
    /// sweeps only), `record` (the first state more uncertain than all of the first W/e allowed
    /// steps).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gate: Option<GateKind>,
    /// Gate `record`: W, its window in allowed steps (0: `1/(1 − p_r/100)`, the steps a
    /// percentile gate waits on average, at most L_q).
    #[serde(default, skip_serializing_if = "super::is_zero_u64")]
    pub window: u64,
    /// L_q: length of the queue of past signal values (1 to [`super::MAX_QUEUE_LEN`]).
    #[serde(default = "default_queue_len")]
    pub queue_len: usize,
    /// p_r: percentile of the queue the signal must exceed, in [0, 100].
    #[serde(default = "default_percentile")]
    pub percentile: f64,
    /// Rule `random`: the `demos.jsonl` of a recorded run whose query steps are asked at again;
    /// `{seed}` in the path is replaced by the run's seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<String>,
    /// Rule `uniform`: the probability of asking at each step, in [0, 1].
    #[serde(default = "default_probability")]
    pub probability: f64,
    /// Rule `js-burst`: how many consecutive steps the expert drives when the rule fires (≥ 1).
    #[serde(default = "default_burst")]
    pub burst: u32,
    /// Rule `js-paced`: the fewest steps between two queries (≥ 1).
    #[serde(default = "default_gap")]
    pub gap: u64,
    /// Rule `js-spread` and allowances `spread` and `uniform`: the steps H over which budget B is
    /// spread (0: the run's `steps`; needed when the run is limited by `episodes` only).
    #[serde(default, skip_serializing_if = "super::is_zero_u64")]
    pub horizon: u64,
    /// Rule `random`: the global steps read from `schedule` by
    /// [`ExperimentConfig::load_schedule`](crate::config::ExperimentConfig::load_schedule) (not part of the TOML).
    #[serde(skip)]
    pub schedule_steps: Vec<u64>,
}

fn default_query_rule() -> RuleKind {
    RuleKind::Never
}
fn default_queue_len() -> usize {
    1000
}
fn default_percentile() -> f64 {
    99.0
}
fn default_probability() -> f64 {
    0.01
}
fn default_burst() -> u32 {
    10
}
fn default_gap() -> u64 {
    100
}

impl Default for QueryConfig {
    fn default() -> Self {
        Self {
            rule: default_query_rule(),
            allowance: None,
            gate: None,
            window: 0,
            queue_len: default_queue_len(),
            percentile: default_percentile(),
            schedule: None,
            probability: default_probability(),
            burst: default_burst(),
            gap: default_gap(),
            horizon: 0,
            schedule_steps: Vec::new(),
        }
    }
}

impl QueryConfig {
    /// The path of rule `random`'s schedule for the run with `seed` (`{seed}` replaced).
    pub fn schedule_path(&self, seed: u64) -> Option<String> {
        self.schedule
            .as_ref()
            .map(|p| p.replace("{seed}", &seed.to_string()))
    }

    /// The steps rule `js-spread` spreads the budget over in a run of `steps` steps.
    pub fn horizon_for(&self, steps: u64) -> u64 {
        if self.horizon > 0 {
            self.horizon
        } else {
            steps
        }
    }

    /// The rule's spec (with the loaded schedule of rule `random`) for a run with budget `total`
    /// and `steps` steps.
    pub fn spec(&self, total: u64, steps: u64) -> crate::query::RuleSpec {
        crate::query::RuleSpec {
            kind: self.rule,
            queue_len: self.queue_len,
            percentile: self.percentile,
            probability: self.probability,
            burst: self.burst,
            gap: self.gap,
            schedule: self.schedule_steps.clone(),
            total,
            horizon: self.horizon_for(steps),
            parts: self
                .gate
                .map(|g| (self.allowance.unwrap_or(AllowanceKind::First), g)),
            window: self.window_steps(),
        }
    }

    /// W of gate `record`: `query.window`, else `1/(1 − p_r/100)` rounded, between 1 and L_q.
    pub fn window_steps(&self) -> u64 {
        if self.window > 0 {
            return self.window;
        }
        let open = 1.0 - self.percentile / 100.0;
        let w = if open > 0.0 {
            (1.0 / open).round()
        } else {
            f64::INFINITY
        };
        w.clamp(1.0, self.queue_len.max(1) as f64) as u64
    }

    /// Whether the allowance spreads the budget over a horizon (`js-spread`, or allowance
    /// `spread` or `uniform`).
    pub fn spreads(&self) -> bool {
        match self.gate {
            Some(_) => matches!(
                self.allowance,
                Some(AllowanceKind::Spread | AllowanceKind::Uniform)
            ),
            None => self.rule == RuleKind::JsSpread,
        }
    }

    /// Whether the rule ever asks (not `never`).
    pub fn asks(&self) -> bool {
        self.gate.is_some() || self.rule != RuleKind::Never
    }

    /// The rule's name for tables and logs: `query.rule`, or `ALLOWANCE+GATE`.
    pub fn rule_name(&self) -> String {
        match self.gate {
            Some(g) => format!(
                "{}+{}",
                self.allowance.unwrap_or(AllowanceKind::First).name(),
                g.name()
            ),
            None => self.rule.name().to_owned(),
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_rule_in_two_parts_is_an_allowance_and_a_gate_and_mixing_forms_is_refused() {
        use crate::query::{AllowanceKind, GateKind};
        let parse = |sets: &[&str]| {
            let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
            crate::config::ExperimentConfig::from_toml_with_overrides(
                "seed = 1\nsteps = 1000\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n",
                &sets,
            )
        };
        let c = parse(&["query.allowance=uniform", "query.gate=record"]).unwrap();
        let spec = c.rule_spec();
        assert_eq!(spec.parts, Some((AllowanceKind::Uniform, GateKind::Record)));
        assert_eq!(c.query.rule_name(), "uniform+record");
        // W: 1/(1 − 99/100) = 100 allowed steps by default, or query.window.
        assert_eq!(spec.window, 100);
        let c = parse(&["query.gate=chance", "query.window=7"]).unwrap();
        assert_eq!(
            c.rule_spec().parts,
            Some((AllowanceKind::First, GateKind::Chance))
        );
        assert_eq!(c.rule_spec().window, 7);
        assert!(c.query.asks());
        let err = |sets: &[&str]| parse(sets).unwrap_err().to_string();
        assert!(err(&["query.rule=js", "query.gate=js"]).contains("not both"));
        assert!(err(&["query.allowance=spread"]).contains("query.gate"));
        assert!(err(&["query.gate=sometimes"]).contains("sometimes"));
        let no_horizon = crate::config::ExperimentConfig::from_toml_with_overrides(
            "seed = 1\nepisodes = 10\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n",
            &["query.allowance=spread".into(), "query.gate=js".into()],
        )
        .unwrap_err()
        .to_string();
        assert!(no_horizon.contains("query.horizon"), "{no_horizon}");
        let oracle = "seed = 1\nepisodes = 3\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n[query]\ngate = \"oracle\"\n";
        assert!(crate::config::ExperimentConfig::from_toml(oracle).is_ok());
        assert!(crate::config::ExperimentConfig::for_multi_process(oracle)
            .unwrap_err()
            .to_string()
            .contains("alfd local"));
    }
}
