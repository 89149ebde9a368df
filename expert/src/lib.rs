//! The expert process of alfd (it answers the actors' queries within the global budget, keeps
//! `demos.jsonl`, and publishes the demonstration model), and the registry of demonstrators it
//! (and the single-process runner) loads by name.

pub mod human;
mod late;
pub mod machine;
mod member;
mod page_member;
mod process;
mod quality_file;

pub use member::member_name;
pub use process::{log_name, run, Args, ANSWER_DELAY_VAR};
