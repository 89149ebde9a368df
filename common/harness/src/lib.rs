//! The harness of the alfd process binaries (`alfd-actor`, `alfd-learner`, `alfd-expert`): what
//! every one of them does before it joins a run (logging, the schema version it speaks).

mod startup;

pub use startup::{init_process_logging, schema_version_from_env};
