//! The wire of alfd: the one crate that knows iceoryx2. Message types, the schema version, and
//! one builder function per service, so that every process builds a service with the same
//! settings.
//!
//! # Services of one run
//! Every run has its own iceoryx2 `global.prefix` (`alfd_<run id>_`) and its service names start
//! with `alfd/<run id>/`, so two runs on one host never see each other.
//!
//! | service             | pattern           | from → to               | payload                      |
//! |---------------------|-------------------|-------------------------|------------------------------|
//! | `transitions`       | pub/sub           | actors → learner        | `[f32]` + [`TransitionHeader`] ([`TransitionBatch`]) |
//! | `credits`           | pub/sub, hist. 1  | learner → actors        | [`Credits`]                  |
//! | `weights`           | pub/sub, hist. 1  | learner → actors        | `[f32]` + [`WeightsHeader`]  |
//! | `demo-model`        | pub/sub, hist. 1  | expert → actors         | `[u8]` + [`DemoModelHeader`] |
//! | `query`             | request/response  | actors → expert → actor | `[f32]` + [`QueryHeader`] ([`QueryRequest`]) → [`QueryResponse`] |
//! | `progress`          | pub/sub           | every process → launcher| [`Progress`]                 |
//! | `control`           | pub/sub, hist. 1  | launcher → every process| [`Control`]                  |
//! | `doorbell/<who>`    | event             | anyone → one process    | (wakes a blocked process)    |
//! | `remote/<name>`     | request/response  | actor or expert → Python adapter | [`RemoteRequest`] → [`RemoteResponse`] (see `remote`) |
//!
//! Data services never wake anybody: a sender rings the receiver's doorbell (`learner`, `expert`,
//! `launcher`, `actor-<id>`), and a process with nothing to do blocks on its own doorbell in a
//! WaitSet, so nothing spins when idle.
//!
//! Across hosts (`alfd-bridge`), a bridge stands in for the processes of the other host: it waits
//! on several doorbells at once ([`Wire::waiter_on`], its own `doorbell/bridge` among them) and
//! passes messages on under their sender's header ([`Sender::forward`]).
//!
//! # Credits (the replay-ratio throttle)
//! The learner makes `U` updates per environment step it receives. Every transition an actor
//! sends carries a per-actor sequence number; the learner processes transitions in order and
//! publishes, per actor, `granted = paid + window`, where `paid` counts the actor's transitions
//! whose `U` updates are done. An actor may send transition `seq` only while `seq < granted`, so
//! it never runs more than `window` steps ahead of the learner (the idea of Reverb's
//! `SampleToInsertRatio`). Grants are cumulative and all actors' grants travel in one message, so
//! a lost or overwritten message loses nothing. A new actor process (after a crash) has a new
//! incarnation and starts with an implicit grant of `window`. An actor out of credits flags its
//! last batch `blocked` (an empty one if need be) and sleeps on its doorbell; the learner rings it
//! as soon as a grant lets it take half its window (one step with a window of one), and never
//! otherwise, so that an actor ahead of a slower learner runs several steps a wake-up.
//!
//! # Schema version
//! Every message carries a [`Header`] with the sender's schema version. A receiver meeting another
//! version gets [`WireError::SchemaMismatch`], which names both versions.
//!
//! # Where things are
//! - `messages`: limits, [`Role`] and [`Process`], the [`Header`] and every message type.
//! - `error`: [`WireError`] and [`Result`].
//! - `connection`: [`Wire`] (joining a run as a process, run ids, the request to stop).
//! - `services`: the channel table [`CHANNELS`], one builder per service, the port constructors.
//! - `ports`: [`Sender`], [`Receiver`], the weights and demonstration-model slices, and both
//!   sides of a query.
//! - `stream`: the weights' copy into shared memory, with stores that bypass the cache.
//! - `remote`: services to Python adapters: [`RemoteEnv`] (an environment in another process)
//!   and [`RemoteDemonstrator`] (an external expert).
//! - `remote_server`: [`RemoteServer`], the serving side of `remote/<name>` for a demonstrator
//!   of this workspace in a process of its own (one of several experts).
//! - `wakeups`: doorbells ([`Doorbell`], [`Bell`], [`ActorBells`]) and the [`Waiter`].
//! - `control`: [`ControlWatch`], a process's view of the launcher.
//! - `housekeeping`: the files a run leaves, and their removal
//!   ([`cleanup_dead_nodes`], [`close_run`]).
//!
//! Processes start up through `alfd-harness` (logging, the schema hook), not through this crate.

mod connection;
mod control;
mod error;
mod housekeeping;
mod messages;
mod ports;
mod remote;
mod remote_server;
mod services;
mod stream;
mod wakeups;

#[cfg(test)]
mod progress_tests;
#[cfg(test)]
mod test_support;

pub use connection::{quiet_transport_logs, run_prefix, validate_run_id, Wire};
pub use control::{ControlWatch, CONTROL_PERIOD};
pub use error::{Result, WireError};
pub use housekeeping::{
    alive_nodes, clean_run, cleanup_dead_nodes, close_dead_run, close_run, is_alfd_run_id,
    is_launcher_run_id, leftover_files, owner_alive, runs_with_files, wait_for_run_end, Cleaned,
};
pub use messages::{
    command, flags, name_from_bytes, name_to_bytes, outcome, process_state, progress_kind, Control,
    Credits, DemoModelHeader, Header, Message, Process, Progress, QueryHeader, QueryRequest,
    QueryResponse, Role, TransitionBatch, TransitionHeader, TransitionRecord, WeightsHeader,
    MAX_ACTORS, MAX_CREDIT_WINDOW, MAX_HEADS, MAX_OBS_DIM, NAME_LEN, SCHEMA_VERSION,
    TRANSITIONS_BUFFER, TRANSITIONS_PER_BATCH,
};
pub use ports::{
    DemoModelReceiver, DemoModelSender, IncomingQuery, PendingQuery, QueryClient, QueryServer,
    Receiver, Sender, TransitionReceiver, TransitionSender, WeightsReceiver, WeightsSender,
};
pub use remote::{
    remote_kind, remote_limits, remote_status, Liveness, RemoteClient, RemoteDemonstrator,
    RemoteEnv, RemoteRequest, RemoteResponse, RemoteSpec, MAX_REMOTE_VALUES, REMOTE_MESSAGE_LEN,
};
pub use remote_server::RemoteServer;
pub use services::{
    transitions_bytes, weights_bytes, Channel, CHANNELS, CONTROL, CREDITS, DEMO_MODEL, PROGRESS,
    PROGRESS_PATIENCE, TRANSITIONS, WEIGHTS,
};
pub use wakeups::{ActorBells, Bell, Doorbell, Waiter, Wake};
