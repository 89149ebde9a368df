//! `alfd-actor`: an actor process (started by `alfd run`). Logs to `RUN_DIR/actor-<id>.log`.

use clap::Parser as _;

fn main() {
    let args = alfd_actor::Args::parse();
    alfd_harness::init_process_logging("alfd-actor", &args.run_dir, &alfd_actor::log_name(&args));
    let schema = alfd_harness::schema_version_from_env().unwrap_or_else(|e| {
        eprintln!("alfd-actor: {e}");
        std::process::exit(2)
    });
    if let Err(err) = alfd_actor::run(&args, schema) {
        tracing::error!("{err:#}");
        eprintln!("alfd-actor: error: {err:#}");
        std::process::exit(1);
    }
}
