//! The pure, seeded core of alfd (active learning from demonstrations).
//!
//! Nothing in this crate opens a file, takes a lock or talks to another process: everything is
//! exactly reproducible from a seed, so the same experiment runs in one process or in many. The
//! processes of a multi-process run talk through `alfd-wire` (the one crate that knows
//! iceoryx2) and start up through `alfd-harness`.

pub mod agent;
pub mod alloc;
pub mod checkpoint;
pub mod config;
pub mod cpu;
pub mod demo_model;
pub mod env;
pub mod environment_loop;
pub mod evaluate;
pub mod math;
pub mod n_step;
pub mod nn;
pub mod panel;
pub mod policy;
pub mod qfunction;
pub mod query;
pub mod record;
pub mod replay;
pub mod restarts;
pub mod rng;
pub mod runner;
pub mod shaping;
pub mod tensorboard;
