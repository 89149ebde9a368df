//! The demonstrators of alfd, by name, and the demonstration log: what the expert process and the
//! single-process runner both load, in a crate of their own so that neither the runner nor the
//! lab comes with the expert process's page server.
//!
//! - `registry`: every demonstrator by name (the shipped networks and Q-tables in `shipped/`,
//!   compiled in, with their measured quality in `shipped/manifest.json`; the scripted ones;
//!   external ones, `python:` and `sb3:`, checked by name).
//! - `scripted`: the scripted experts of graded quality for MountainCar and Acrobot, and
//!   DeepSea's noisy one.
//! - `demo_log`: `demos.jsonl`, read and appended to (each line whole, fsync'd).
//! - `added`: `experts-added.jsonl`, the experts `alfd expert add` gave a live run.

pub mod added;
pub mod demo_log;
pub mod registry;
pub mod scripted;
