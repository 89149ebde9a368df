//! [`Wire`]: a process's connection to its run (an iceoryx2 node with the run's own config, who
//! it is, the schema it speaks), run ids and their iceoryx2 prefix, and the check for a request to stop.

use std::fmt;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use iceoryx2::node::NodeWaitFailure;
use iceoryx2::prelude::*;

use crate::error::{transport, Result, WireError};
use crate::messages::{Header, Process};

/// The iceoryx2 transport used by every process.
pub(crate) type Transport = ipc::Service;

/// Set once a process received SIGINT or SIGTERM (iceoryx2 reports a signal only once).
pub(crate) static TERMINATION_REQUESTED: AtomicBool = AtomicBool::new(false);

/// How many signals in a row a check for termination looks through before it gives up and
/// reports none (a storm of stray signals must not hang a process).
pub(crate) const MAX_INTERRUPTED_CHECKS: usize = 16;

/// Routes iceoryx2's own log output: only its warnings and errors (or `IOX2_LOG_LEVEL`).
pub fn quiet_transport_logs() {
    set_log_level_from_env_or(LogLevel::Warn);
}

/// Checks a run id: 1 to 64 ASCII letters, digits, `-` or `_`.
pub fn validate_run_id(run_id: &str) -> Result<()> {
    let ok = !run_id.is_empty()
        && run_id.len() <= 64
        && run_id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    if ok {
        Ok(())
    } else {
        Err(WireError::InvalidRunId(run_id.to_owned()))
    }
}

/// The iceoryx2 file prefix of a run: every file it creates starts with this.
pub fn run_prefix(run_id: &str) -> String {
    format!("alfd_{run_id}_")
}

/// The iceoryx2 config of a run: the defaults (no config file is read), with the run's prefix.
pub(crate) fn run_config(run_id: &str) -> Result<Config> {
    validate_run_id(run_id)?;
    let mut cfg = Config::default();
    cfg.global.prefix = FileName::new(run_prefix(run_id).as_bytes())
        .map_err(transport("name the prefix of", run_id))?;
    Ok(cfg)
}

/// A process's connection to its run: an iceoryx2 node with the run's config, and who we are.
pub struct Wire {
    pub(crate) node: Node<Transport>,
    run_id: String,
    me: Process,
    schema: u32,
}

impl fmt::Debug for Wire {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Wire")
            .field("run_id", &self.run_id)
            .field("me", &self.me)
            .field("schema", &self.schema)
            .finish()
    }
}

impl Wire {
    /// Joins run `run_id` as `me`, speaking schema version `schema` (normally
    /// [`SCHEMA_VERSION`](crate::SCHEMA_VERSION)). SIGINT and SIGTERM are caught from here on: see
    /// [`Wire::termination_requested`].
    pub fn connect(run_id: &str, me: Process, schema: u32) -> Result<Self> {
        let cfg = run_config(run_id)?;
        let name =
            NodeName::new(&me.to_string()).map_err(transport("name node", me.to_string()))?;
        let node = NodeBuilder::new()
            .name(&name)
            .config(&cfg)
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Transport>()
            .map_err(transport("create node", me.to_string()))?;
        let wire = Self {
            node,
            run_id: run_id.to_owned(),
            me,
            schema,
        };
        // Installs iceoryx2's signal handler now rather than at the first wait.
        wire.termination_requested();
        Ok(wire)
    }

    /// Whether SIGINT or SIGTERM arrived (sticky). Any other signal iceoryx2 catches (SIGCONT,
    /// SIGTSTP, SIGUSR1, ...) is not a request to stop.
    pub fn termination_requested(&self) -> bool {
        termination_requested(&self.node)
    }

    /// Removes what crashed processes of this run left behind; returns how many nodes it removed.
    #[cfg(test)]
    pub(crate) fn cleanup_dead_nodes(&self) -> usize {
        let state = self.node.try_cleanup_dead_nodes();
        state.cleanups as usize
    }

    pub(crate) fn service_name(&self, topic: &str) -> Result<ServiceName> {
        let name = format!("alfd/{}/{}", self.run_id, topic);
        ServiceName::new(&name).map_err(transport("name service", name.clone()))
    }

    /// The run this wire belongs to.
    pub fn run_id(&self) -> &str {
        &self.run_id
    }

    /// The schema version this process speaks.
    pub fn schema(&self) -> u32 {
        self.schema
    }

    pub(crate) fn header(&self, seq: u64) -> Header {
        Header {
            schema: self.schema,
            role: self.me.role as u16,
            id: self.me.id,
            seq,
        }
    }

    pub(crate) fn check(&self, service: &'static str, h: &Header) -> Result<()> {
        if h.schema == self.schema {
            Ok(())
        } else {
            Err(WireError::SchemaMismatch {
                service,
                ours: self.schema,
                theirs: h.schema,
                sender: h.sender(),
            })
        }
    }
}

/// Whether SIGINT or SIGTERM arrived at this process (sticky), asked through `node`, created
/// with [`SignalHandlingMode::HandleTerminationRequests`].
pub(crate) fn termination_requested(node: &Node<Transport>) -> bool {
    // iceoryx2 keeps only the last signal caught, and `node.wait` takes it: a
    // `TerminationRequest` is SIGINT or SIGTERM; an `Interrupt` says only that some signal
    // cut the (zero-length) sleep short, so the check is made again to learn which.
    for _ in 0..MAX_INTERRUPTED_CHECKS {
        if TERMINATION_REQUESTED.load(Ordering::Relaxed) {
            return true;
        }
        match node.wait(Duration::ZERO) {
            Ok(()) => return false,
            Err(NodeWaitFailure::TerminationRequest) => {
                TERMINATION_REQUESTED.store(true, Ordering::Relaxed);
            }
            Err(NodeWaitFailure::Interrupt) => {}
        }
    }
    TERMINATION_REQUESTED.load(Ordering::Relaxed)
}
