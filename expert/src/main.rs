//! `alfd-expert`: the expert process (started by `alfd run`). Logs to `RUN_DIR/expert-<generation>.log`; exits 2 on
//! bad input (a run directory's config), 1 on any other failure.

use clap::Parser as _;

/// Blocks the products read start on a cache line (see `alfd_common::alloc`).
#[global_allocator]
static ALLOC: alfd_common::alloc::CacheAligned = alfd_common::alloc::CacheAligned;

fn main() {
    let args = alfd_expert::Args::parse();
    let log = alfd_expert::log_name(&args);
    alfd_harness::main("alfd-expert", &args, &args.process, &log, alfd_expert::run)
}
