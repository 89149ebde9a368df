//! The harness of the alfd process binaries (`alfd-actor`, `alfd-learner`, `alfd-expert`): what
//! all three share, in one place. Their common arguments and reading the run directory
//! (`process`), the runtime settings every process reads from `runtime.toml` (`runtime`),
//! joining the run and the one `should_stop` (`session`), the Python adapters of Gymnasium
//! environments and external experts (`python`), start-up (logging, the schema-version
//! hook: `startup`), durable file writes (`fs`), a run directory's ownership (`run_dir`:
//! one run per directory, held by a `flock`), and the demonstration model's lanes on the
//! machine's cores (`threads`).

mod bad_input;
mod fs;
mod prior;
mod process;
pub mod python;
pub mod run_dir;
mod runtime;
mod sched;
mod session;
mod startup;
pub mod tensorboard;
mod threads;

pub use bad_input::{chain, describe, exit_code, BadInput, HarnessError, Result, What};
#[cfg(any(test, feature = "testing"))]
pub use fs::test_dir;
pub use fs::{
    append_whole, disk_full, load_checkpoint, save_checkpoint, write_atomically,
    write_atomically_patiently, write_private, DISK_FULL_PATIENCE,
};
pub use prior::{read_prior, write_prior, PRIOR_FILE};
pub use process::{check_wire_limits, main, read_text, ProcessArgs, Setup};
pub use runtime::{
    Refit, RuntimeConfig, RuntimeConfigError, DEFAULT_CHECKPOINT_EVERY,
    DEFAULT_HUMAN_QUERY_TIMEOUT_MS, DEFAULT_MAX_RESTARTS, HUMAN_EXPERT, RUNTIME_FILE,
};
pub use sched::{micros_var, set_timer_slack, Sched, QUERY_SLICE};
pub use session::{Session, SessionError, LAUNCHER_SILENCE, STOP_REQUESTED, TERMINATION_SIGNAL};
pub use startup::{
    init_process_logging, log_filter, portable_kernels_from_env, schema_version_from_env,
};
pub use threads::Threads;
