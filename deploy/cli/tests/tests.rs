//! Integration tests of the `alfd` command line and of the multi-process runtime (one binary).

mod chaos;
mod cli;
mod deepsea;
mod demo_model;
mod experts;
mod faults;
mod golden;
mod gymnasium;
mod human;
mod late;
mod minari;
mod query_rules;
mod remote;
mod report;
mod runtime;
mod shards;
mod support;
mod sweep;
mod tensorboard;
mod watch;
