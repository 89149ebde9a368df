//! CartPole-v1 with Gymnasium's dynamics (placeholder: being written).

/// CartPole environment.
#[derive(Debug, Clone)]
pub struct CartPole;
