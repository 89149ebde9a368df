//! `alfd-actor`: an actor process (started by `alfd run`). Logs to `RUN_DIR/actor-<id>.log`.

use std::path::Path;

use clap::Parser as _;

fn main() {
    let args = alfd_actor::Args::parse();
    init_logging(&args.run_dir, &alfd_actor::log_name(&args));
    if let Err(err) = alfd_actor::run(&args, schema_version()) {
        tracing::error!("{err:#}");
        eprintln!("alfd-actor: error: {err:#}");
        std::process::exit(1);
    }
}

/// The schema version this process speaks: [`SCHEMA_VERSION`](alfd_common::wire::SCHEMA_VERSION),
/// unless the hidden test hook `ALFD_SCHEMA_VERSION_OVERRIDE` says otherwise.
fn schema_version() -> u32 {
    match std::env::var("ALFD_SCHEMA_VERSION_OVERRIDE") {
        Ok(v) => v.parse().unwrap_or_else(|_| {
            eprintln!("alfd-actor: ALFD_SCHEMA_VERSION_OVERRIDE must be a number, got {v:?}");
            std::process::exit(2)
        }),
        Err(_) => alfd_common::wire::SCHEMA_VERSION,
    }
}

/// Logs to `RUN_DIR/NAME.log` (appended to); `RUST_LOG` sets the filter (default `info`).
fn init_logging(run_dir: &Path, name: &str) {
    alfd_common::wire::quiet_transport_logs();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let path = run_dir.join(format!("{name}.log"));
    match std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
    {
        Ok(file) => {
            let _ = tracing_subscriber::fmt()
                .with_env_filter(filter)
                .with_ansi(false)
                .with_writer(std::sync::Mutex::new(file))
                .try_init();
        }
        Err(e) => {
            eprintln!(
                "alfd-actor: cannot open log {}: {e}; logging to stderr",
                path.display()
            );
            let _ = tracing_subscriber::fmt()
                .with_env_filter(filter)
                .with_writer(std::io::stderr)
                .try_init();
        }
    }
}
