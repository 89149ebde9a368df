//! The agents, split the way actor-learner systems are (Acme's `Actor` / `Learner`): the part that
//! acts (picks actions, measures the divergence, decides to query, shapes the reward) and the part
//! that learns (replay, K heads, targets, optimizer), plus the expert's side (budget,
//! demonstrations, demonstration model). The single-process runner and the processes of the
//! multi-process runtime both drive these same types.

pub mod build;
pub mod demo;
pub mod expert;
pub mod neural;
pub mod refit;
pub mod tabular;

pub use demo::{DemoRecord, PriorDemo};
pub use expert::{
    BalancingController, Becomes, Demonstrator, ExpertCore, ExpertSnapshot, NetworkDemonstrator,
    NoExpert, TablePolicy,
};
pub use neural::{ActorSnapshot, LearnerSnapshot, NeuralActor, NeuralLearner};
pub use refit::{RefitJob, Refitted};
pub use tabular::{TabularAgent, TabularSnapshot};

use rand::Rng as _;

use crate::config::{AgentConfig, Exploration};
use crate::policy::{argmax, softmax_into};
use crate::rng::Rng;

/// What an agent decided at one state (Algorithm 1 lines 3-16, before any answer of the expert).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The agent's own action (used when no query is made, or when the query goes unanswered).
    pub action: usize,
    /// The Jensen-Shannon divergence of the K heads at the state (0 with one head).
    pub js: f64,
    /// The query rule fired: ask the expert.
    pub query: bool,
}

/// How an agent picks its own action from the Q-values of the head it follows: greedily, ε-greedily
/// with ε decaying over its steps, or by sampling the softmax policy (eq. 2).
#[derive(Debug, Clone)]
pub struct Explorer {
    exploration: Exploration,
    temperature: f64,
    config: AgentConfig,
    steps: u64,
    probs: Vec<f64>,
}

impl Explorer {
    pub fn new(cfg: &AgentConfig, actions: usize) -> Self {
        Self {
            exploration: cfg.exploration(),
            temperature: cfg.temperature,
            config: cfg.clone(),
            steps: 0,
            probs: vec![0.0; actions],
        }
    }

    /// Actions chosen so far (the clock of ε).
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Puts ε's clock at `steps` (a restored checkpoint).
    pub fn restore_steps(&mut self, steps: u64) {
        self.steps = steps;
    }

    /// The agent's own action given the acting head's Q-values.
    pub fn act(&mut self, head: &[f64], rng: &mut Rng) -> usize {
        let action = match self.exploration {
            Exploration::GreedyHead => argmax(head),
            Exploration::EpsilonGreedy => {
                if rng.random::<f64>() < self.config.epsilon(self.steps) {
                    rng.random_range(0..head.len())
                } else {
                    argmax(head)
                }
            }
            Exploration::Softmax => {
                softmax_into(head, self.temperature, &mut self.probs);
                sample(&self.probs, rng)
            }
        };
        self.steps += 1;
        action
    }
}

/// Samples an index from a probability vector.
pub(crate) fn sample(probs: &[f64], rng: &mut Rng) -> usize {
    let u: f64 = rng.random();
    let mut acc = 0.0;
    for (i, p) in probs.iter().enumerate() {
        acc += p;
        if u < acc {
            return i;
        }
    }
    probs.len() - 1
}
