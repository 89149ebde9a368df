//! `alfd-learner`: the learner process (started by `alfd run`). Logs to `RUN_DIR/learner.log`.

use clap::Parser as _;

fn main() {
    let args = alfd_learner::Args::parse();
    alfd_harness::init_process_logging(
        "alfd-learner",
        &args.run_dir,
        &alfd_learner::log_name(&args),
    );
    let schema = alfd_harness::schema_version_from_env().unwrap_or_else(|e| {
        eprintln!("alfd-learner: {e}");
        std::process::exit(2)
    });
    if let Err(err) = alfd_learner::run(&args, schema) {
        tracing::error!("{err:#}");
        eprintln!("alfd-learner: error: {err:#}");
        std::process::exit(1);
    }
}
