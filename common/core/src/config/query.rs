//! `[query]`: when the agent asks the expert.

use serde::{Deserialize, Serialize};

use super::RuleKind;

/// When the agent asks the expert (`[query]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct QueryConfig {
    /// The query rule (`active` is read as `js`; the older key `query.mode` as `query.rule`).
    #[serde(default = "default_query_rule")]
    pub rule: RuleKind,
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
    /// Rule `js-spread`: the steps H over which budget B is spread (0: the run's `steps`; needed
    /// when the run is limited by `episodes` only).
    #[serde(default, skip_serializing_if = "super::is_zero_u64")]
    pub horizon: u64,
    /// Rule `random`: the global steps read from `schedule` by
    /// [`ExperimentConfig::load_schedule`] (not part of the TOML).
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
        }
    }
}
