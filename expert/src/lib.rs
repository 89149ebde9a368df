//! The expert process of alfd (it answers the actors' queries within the global budget, keeps
//! `demos.jsonl`, and publishes the demonstration model), and the registry of demonstrators it
//! (and the single-process runner) loads by name.

pub mod demo_log;
pub mod human;
pub mod machine;
mod process;
pub mod registry;
pub mod scripted;

pub use process::{log_name, run, Args, ANSWER_DELAY_VAR};
