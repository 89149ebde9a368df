//! Process start-up: where a process binary logs (`RUN_DIR/NAME.log`) and which schema version
//! it speaks (the `ALFD_SCHEMA_VERSION_OVERRIDE` test hook).

use std::fs::OpenOptions;
use std::path::Path;
use std::sync::Mutex;

/// Start-up shared by the process binaries (`alfd-actor`, `alfd-learner`, `alfd-expert`): quiets
/// iceoryx2, logs to `RUN_DIR/NAME.log` (appended to; `RUST_LOG` sets the filter, default `info`),
/// or to stderr if that file cannot be opened.
pub fn init_process_logging(process: &str, run_dir: &Path, name: &str) {
    alfd_wire::quiet_transport_logs();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let path = run_dir.join(format!("{name}.log"));
    match OpenOptions::new().create(true).append(true).open(&path) {
        Ok(file) => {
            let _ = tracing_subscriber::fmt()
                .with_env_filter(filter)
                .with_ansi(false)
                .with_writer(Mutex::new(file))
                .try_init();
        }
        Err(e) => {
            eprintln!(
                "{process}: cannot open log {}: {e}; logging to stderr",
                path.display()
            );
            let _ = tracing_subscriber::fmt()
                .with_env_filter(filter)
                .with_writer(std::io::stderr)
                .try_init();
        }
    }
}

/// The schema version a process speaks: [`SCHEMA_VERSION`](alfd_wire::SCHEMA_VERSION), unless the hidden test hook
/// `ALFD_SCHEMA_VERSION_OVERRIDE` says otherwise (the integration test of a mismatched process).
pub fn schema_version_from_env() -> Result<u32, String> {
    match std::env::var("ALFD_SCHEMA_VERSION_OVERRIDE") {
        Ok(v) => v
            .parse()
            .map_err(|_| format!("ALFD_SCHEMA_VERSION_OVERRIDE must be a number, got {v:?}")),
        Err(_) => Ok(alfd_wire::SCHEMA_VERSION),
    }
}
