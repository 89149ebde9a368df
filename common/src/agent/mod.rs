//! The agents, split the way actor-learner systems are (Acme's `Actor` / `Learner`): the part that
//! acts (picks actions, measures the divergence, decides to query, shapes the reward) and the part
//! that learns (replay, K heads, targets, optimizer), plus the expert's side (budget,
//! demonstrations, demonstration model). The single-process runner and the processes of the
//! multi-process runtime both drive these same types.

pub mod expert;
pub mod neural;
pub mod tabular;

pub use expert::{
    BalancingController, DemoRecord, Demonstrator, ExpertCore, NetworkDemonstrator, TablePolicy,
};
pub use neural::{Decision, NeuralActor, NeuralLearner};
pub use tabular::TabularAgent;

use crate::config::QueryMode;
use crate::query::QueryRule;

/// Algorithm 1 lines 3-8 for one state: given the divergence `u`, whether to query the expert.
/// The divergence is pushed to the queue only while budget remains, as in the paper.
pub fn query_decision(mode: QueryMode, rule: &mut QueryRule, u: f64, budget_left: bool) -> bool {
    if !budget_left {
        return false;
    }
    match mode {
        QueryMode::Never => false,
        QueryMode::First => true,
        QueryMode::Active => rule.observe(u),
    }
}
