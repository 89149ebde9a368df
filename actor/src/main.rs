//! `alfd-actor`: the actor process (started by `alfd run`). Logs to `RUN_DIR/actor-<id>.log`; exits 2 on
//! bad input (a run directory's config), 1 on any other failure.

use clap::Parser as _;

/// Blocks the products read start on a cache line (see `alfd_common::alloc`).
#[global_allocator]
static ALLOC: alfd_common::alloc::CacheAligned = alfd_common::alloc::CacheAligned;

fn main() {
    let args = alfd_actor::Args::parse();
    let log = alfd_actor::log_name(&args);
    alfd_harness::main("alfd-actor", &args, &args.process, &log, alfd_actor::run)
}
