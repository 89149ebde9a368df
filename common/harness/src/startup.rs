//! Process start-up: where a process binary logs (`RUN_DIR/NAME.log`) and which schema version
//! it speaks (the `ALFD_SCHEMA_VERSION_OVERRIDE` test hook).

use std::fs::OpenOptions;
use std::path::Path;
use std::sync::Mutex;

use tracing_subscriber::filter::Targets;
use tracing_subscriber::prelude::*;

/// Start-up shared by the process binaries (`alfd-actor`, `alfd-learner`, `alfd-expert`): quiets
/// iceoryx2, logs to `RUN_DIR/NAME.log` (appended to; `RUST_LOG` sets the filter, default `info`),
/// or to stderr if that file cannot be opened.
pub fn init_process_logging(process: &str, run_dir: &Path, name: &str) {
    alfd_wire::quiet_transport_logs();
    let filter = log_filter("info");
    let path = run_dir.join(format!("{name}.log"));
    match OpenOptions::new().create(true).append(true).open(&path) {
        Ok(file) => {
            let _ = tracing_subscriber::registry()
                .with(
                    tracing_subscriber::fmt::layer()
                        .with_ansi(false)
                        .with_writer(Mutex::new(file)),
                )
                .with(filter)
                .try_init();
        }
        Err(e) => {
            eprintln!(
                "{process}: cannot open log {}: {e}; logging to stderr",
                path.display()
            );
            let _ = tracing_subscriber::registry()
                .with(
                    tracing_subscriber::fmt::layer()
                        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
                        .with_writer(std::io::stderr),
                )
                .with(filter)
                .try_init();
        }
    }
}

/// The log filter from `RUST_LOG` (`LEVEL`, `TARGET=LEVEL`, comma-separated), or `default` when it
/// is unset or unreadable. tracing-subscriber's `Targets`, not its `EnvFilter`: the same
/// directives without span and field matching, and without compiling `regex` into every binary
/// (BENCHMARKS.md, "Build and CI").
pub fn log_filter(default: &str) -> Targets {
    std::env::var("RUST_LOG")
        .ok()
        .and_then(|v| v.parse::<Targets>().ok())
        .unwrap_or_else(|| default.parse().unwrap_or_default())
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

/// `ALFD_PORTABLE_KERNELS=1`: this process computes with the core's portable kernels (no AVX2, a
/// software FMA per element), which must give the same numbers as the fast ones (the golden-run
/// test checks it).
pub fn portable_kernels_from_env() {
    if std::env::var_os("ALFD_PORTABLE_KERNELS").is_some_and(|v| v == "1") {
        alfd_common::nn::use_portable_kernels(true);
        tracing::info!("ALFD_PORTABLE_KERNELS=1: the portable kernels (slow)");
    }
}
