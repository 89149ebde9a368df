//! Integration tests of the core against the reference fixtures (one test binary).
mod mlp_reference;
mod nn_checkpoint;
mod dqn_loss;
