//! The expert process of alfd, and the registry of demonstrators it (and the single-process
//! runner) loads by name.

pub mod registry;
