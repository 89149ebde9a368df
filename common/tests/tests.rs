//! Integration tests of the core against the reference fixtures (one test binary).

mod cartpole_reference;
mod env_conformance;
mod kernel_reference;
