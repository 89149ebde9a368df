//! `alfd-expert`: the expert process (started by `alfd run`). Logs to `RUN_DIR/expert-<generation>.log`.

use clap::Parser as _;

fn main() {
    let args = alfd_expert::Args::parse();
    alfd_harness::init_process_logging("alfd-expert", &args.run_dir, &alfd_expert::log_name(&args));
    let schema = alfd_harness::schema_version_from_env().unwrap_or_else(|e| {
        eprintln!("alfd-expert: {e}");
        std::process::exit(2)
    });
    if let Err(err) = alfd_expert::run(&args, schema) {
        tracing::error!("{err:#}");
        eprintln!("alfd-expert: error: {err:#}");
        std::process::exit(1);
    }
}
