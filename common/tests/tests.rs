//! Integration tests of the core against the reference fixtures (one test binary).
mod dqn_loss;
mod mlp_reference;
mod nn_checkpoint;
