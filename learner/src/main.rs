//! `alfd-learner`: the learner process (started by `alfd run`). Logs to `RUN_DIR/learner.log`; exits 2 on
//! bad input (a run directory's config), 1 on any other failure.

use clap::Parser as _;

fn main() {
    let args = alfd_learner::Args::parse();
    let log = alfd_learner::log_name(&args);
    alfd_harness::main(
        "alfd-learner",
        &args,
        &args.process,
        &log,
        alfd_learner::run,
    )
}
