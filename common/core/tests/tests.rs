//! Integration tests of the core against the reference fixtures (one test binary).

mod conformance_suite;
mod deepsea_reference;
mod dqn_loss;
mod env_conformance;
mod fuzz;
mod gymnasium_reference;
mod js_reference;
mod kernel_reference;
mod learner_options;
mod manual;
mod manual_numbers;
mod mlp_reference;
mod nn_checkpoint;
mod resume;
mod runner;
mod separate_torsos;
mod tidy;
mod tidy_features;
mod tidy_functions;
