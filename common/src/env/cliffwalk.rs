//! CliffWalk of the paper, section 4 (placeholder: being written).

/// CliffWalk environment.
#[derive(Debug, Clone)]
pub struct CliffWalk;
