//! Demonstrations as records: one answered query ([`DemoRecord`], a line of `demos.jsonl`) and
//! one step of an expert given before the run ([`PriorDemo`], `demos.prior`). The expert's core
//! and its refits both read them; neither depends on the other for them.

use serde::{Deserialize, Serialize};

use crate::replay::Transition;

/// One answered query, as `demos.jsonl` records it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DemoRecord {
    /// 0-based index of the demonstration in the run (the budget spent before it).
    pub index: u32,
    pub state: Vec<f64>,
    pub action: usize,
    /// The global environment step at which it was asked for.
    pub step: u64,
    /// The demonstrator that answered.
    pub expert: String,
    /// Its weight in the demonstration model (KRR): with several experts and
    /// `demos.weighting = "quality"`, its expert's estimated quality when it answered; else 1.
    /// Always written: checkpoints store records in postcard, which has no optional fields.
    #[serde(default = "one")]
    pub weight: f64,
}

fn one() -> f64 {
    1.0
}

/// A step of an expert given before the run (`demos.prior`): a demonstration for the
/// demonstration model and a transition for the replay buffer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PriorDemo {
    pub state: Vec<f32>,
    pub action: usize,
    /// The environment's reward (unshaped).
    pub reward: f64,
    pub next_state: Vec<f32>,
    pub terminated: bool,
}

impl PriorDemo {
    /// Its demonstration record (`index`: its place among the prior ones).
    pub fn record(&self, index: usize) -> DemoRecord {
        DemoRecord {
            index: index as u32,
            state: self.state.iter().map(|&x| f64::from(x)).collect(),
            action: self.action,
            step: 0,
            expert: "prior".to_owned(),
            weight: 1.0,
        }
    }

    /// Its transition: a demonstration, so every head trains on it (as on the run's own).
    pub fn transition(&self, heads: usize) -> Transition {
        Transition {
            state: self.state.clone(),
            action: self.action as u32,
            reward: self.reward as f32,
            next_state: self.next_state.clone(),
            terminated: self.terminated,
            mask: vec![1.0; heads],
            demo: true,
            horizon: 1,
        }
    }
}
