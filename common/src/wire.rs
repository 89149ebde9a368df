//! The wire: the one module that knows iceoryx2. Message types, the schema version, and one
//! builder function per service, so that every process builds a service with the same settings.
//!
//! # Services of one run
//! Every run has its own iceoryx2 `global.prefix` (`alfd_<run id>_`) and its service names start
//! with `alfd/<run id>/`, so two runs on one host never see each other.
//!
//! | service             | pattern           | from → to               | payload                      |
//! |---------------------|-------------------|-------------------------|------------------------------|
//! | `transitions`       | pub/sub           | actors → learner        | [`TransitionBatch`]          |
//! | `credits`           | pub/sub, hist. 1  | learner → actors        | [`Credits`]                  |
//! | `weights`           | pub/sub, hist. 1  | learner → actors        | `[f32]` + [`WeightsHeader`]  |
//! | `demo-model`        | pub/sub, hist. 1  | expert → actors         | `[u8]` + [`DemoModelHeader`] |
//! | `query`             | request/response  | actors → expert → actor | [`QueryRequest`] → [`QueryResponse`] |
//! | `progress`          | pub/sub           | every process → launcher| [`Progress`]                 |
//! | `control`           | pub/sub, hist. 1  | launcher → every process| [`Control`]                  |
//! | `doorbell/<who>`    | event             | anyone → one process    | (wakes a blocked process)    |
//!
//! Data services never wake anybody: a sender rings the receiver's doorbell (`learner`, `expert`,
//! `launcher`, `actor-<id>`), and a process with nothing to do blocks on its own doorbell in a
//! WaitSet, so nothing spins when idle.
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
//! as soon as a grant lets it go on, and never otherwise.
//!
//! # Schema version
//! Every message carries a [`Header`] with the sender's schema version. A receiver meeting another
//! version gets [`WireError::SchemaMismatch`], which names both versions.

use std::fmt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use iceoryx2::active_request::ActiveRequest;
use iceoryx2::node::NodeView;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;

use crate::replay::Transition;

/// The version of the messages below. Bump it whenever a message changes.
pub const SCHEMA_VERSION: u32 = 1;
/// Actors per run (the credit table has one slot per actor id).
pub const MAX_ACTORS: usize = 16;
/// Largest observation a transition or a query can carry.
pub const MAX_OBS_DIM: usize = 8;
/// Largest number of heads (K) a bootstrap mask can carry.
pub const MAX_HEADS: usize = 8;
/// Transitions per [`TransitionBatch`].
pub const TRANSITIONS_PER_BATCH: usize = 32;
/// The learner's subscriber queue per actor, in batches. The credit window may not exceed it:
/// an actor never has more batches in flight than unpaid steps, so no batch is ever dropped.
pub const TRANSITIONS_BUFFER: usize = 64;
/// Largest credit window, in environment steps.
pub const MAX_CREDIT_WINDOW: u64 = TRANSITIONS_BUFFER as u64;
/// Nodes a service may have: launcher, learner, two experts during a swap, the actors, actors
/// killed but not yet cleaned up, and a few tools (benchmarks, monitors).
const MAX_NODES: usize = 2 * MAX_ACTORS + 16;
/// Bytes of an expert name in a message.
pub const NAME_LEN: usize = 32;

// ---------------------------------------------------------------------------------------------
// Identities
// ---------------------------------------------------------------------------------------------

/// What a process is in a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u16)]
pub enum Role {
    Launcher = 1,
    Learner = 2,
    Expert = 3,
    Actor = 4,
    /// Benchmarks, monitors, the `swap-expert` command.
    Tool = 5,
}

impl Role {
    pub fn from_u16(v: u16) -> Option<Role> {
        Some(match v {
            1 => Role::Launcher,
            2 => Role::Learner,
            3 => Role::Expert,
            4 => Role::Actor,
            5 => Role::Tool,
            _ => return None,
        })
    }

    fn as_str(self) -> &'static str {
        match self {
            Role::Launcher => "launcher",
            Role::Learner => "learner",
            Role::Expert => "expert",
            Role::Actor => "actor",
            Role::Tool => "tool",
        }
    }
}

/// One process of a run: its role and its id within the role (actor id, expert generation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Process {
    pub role: Role,
    pub id: u16,
}

impl Process {
    pub fn new(role: Role, id: u16) -> Self {
        Self { role, id }
    }
}

impl fmt::Display for Process {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.role {
            Role::Launcher | Role::Learner => write!(f, "{}", self.role.as_str()),
            _ => write!(f, "{}-{}", self.role.as_str(), self.id),
        }
    }
}

/// Whom a doorbell wakes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Doorbell {
    Learner,
    Expert,
    /// One actor (by id): the learner rings it when credits it waits for arrive, the expert when
    /// its answer is there.
    Actor(u16),
    Launcher,
}

impl Doorbell {
    fn topic(self) -> String {
        match self {
            Doorbell::Learner => "doorbell/learner".to_owned(),
            Doorbell::Expert => "doorbell/expert".to_owned(),
            Doorbell::Actor(id) => format!("doorbell/actor-{id}"),
            Doorbell::Launcher => "doorbell/launcher".to_owned(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// What can go wrong on the wire.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    #[error(
        "schema version mismatch on `{service}`: this process speaks schema version {ours}, \
         but {sender} sent schema version {theirs}; rebuild all processes from the same sources"
    )]
    SchemaMismatch {
        service: &'static str,
        ours: u32,
        theirs: u32,
        sender: String,
    },
    #[error("invalid run id `{0}`: use 1 to 64 ASCII letters, digits, `-` or `_`")]
    InvalidRunId(String),
    #[error("{what} has {got} values, more than the wire carries ({max})")]
    TooLarge {
        what: &'static str,
        got: usize,
        max: usize,
    },
    #[error("{what}: {value} is out of range ({expected})")]
    OutOfRange {
        what: &'static str,
        value: u64,
        expected: &'static str,
    },
    #[error("no word from the launcher of this run within {waited_ms} ms (is the run id right, is the run alive?)")]
    NoLauncher { waited_ms: u64 },
    #[error("interrupted by a termination signal")]
    Interrupted,
    #[error("run `{run_id}` still has live processes: {nodes}")]
    RunAlive { run_id: String, nodes: String },
    #[error("iceoryx2 failed to {op} `{service}`: {detail}")]
    Transport {
        op: &'static str,
        service: String,
        detail: String,
    },
}

pub type Result<T, E = WireError> = std::result::Result<T, E>;

fn transport<E: fmt::Debug>(
    op: &'static str,
    service: impl Into<String>,
) -> impl FnOnce(E) -> WireError {
    let service = service.into();
    move |e| WireError::Transport {
        op,
        service,
        detail: format!("{e:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Messages
// ---------------------------------------------------------------------------------------------

/// What every message starts with: the schema version, the sender, and the sender's sequence
/// number on that service (0, 1, 2, ...).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("alfd.Header")]
pub struct Header {
    pub schema: u32,
    /// [`Role`] of the sender, as `u16`.
    pub role: u16,
    pub id: u16,
    pub seq: u64,
}

impl Header {
    /// The sender, for messages; `"unknown-<role>-<id>"` when the role is not known.
    pub fn sender(&self) -> String {
        match Role::from_u16(self.role) {
            Some(role) => Process::new(role, self.id).to_string(),
            None => format!("unknown-{}-{}", self.role, self.id),
        }
    }
}

/// A message with a [`Header`], sent by value.
pub trait Message: Copy + fmt::Debug + ZeroCopySend + 'static {
    /// The service it travels on (for error messages).
    const SERVICE: &'static str;
    fn header(&self) -> &Header;
    fn header_mut(&mut self) -> &mut Header;
}

macro_rules! message {
    ($t:ty, $service:expr) => {
        impl Message for $t {
            const SERVICE: &'static str = $service;
            fn header(&self) -> &Header {
                &self.header
            }
            fn header_mut(&mut self) -> &mut Header {
                &mut self.header
            }
        }
    };
}

/// `flags` of a [`TransitionRecord`].
pub mod flags {
    pub const TERMINATED: u32 = 1;
    pub const TRUNCATED: u32 = 2;
    pub const DEMO: u32 = 4;
    /// Last step of its episode (terminated or truncated).
    pub const EPISODE_END: u32 = 8;
}

/// One environment step as it travels from an actor to the learner.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("alfd.TransitionRecord")]
pub struct TransitionRecord {
    pub state: [f32; MAX_OBS_DIM],
    pub next_state: [f32; MAX_OBS_DIM],
    /// The Bernoulli bootstrap mask, one value per head.
    pub mask: [f32; MAX_HEADS],
    pub action: u32,
    /// The reward learned from (shaped when shaping was on).
    pub reward: f32,
    /// The actor's episode number.
    pub episode: u32,
    /// See [`flags`].
    pub flags: u32,
}

/// Up to [`TRANSITIONS_PER_BATCH`] consecutive steps of one actor.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("alfd.TransitionBatch")]
pub struct TransitionBatch {
    pub header: Header,
    pub actor: u32,
    pub obs_dim: u16,
    pub heads: u16,
    /// Differs for every process that plays this actor id (a restarted actor is a new incarnation).
    pub incarnation: u64,
    /// Sequence number of `records[0]` among all steps this incarnation sent (the credit count).
    pub first_seq: u64,
    pub len: u32,
    /// 1 when the actor has used up its credits with this batch and blocks until it hears of
    /// new ones (the learner then rings its doorbell); 0 otherwise.
    pub blocked: u32,
    pub records: [TransitionRecord; TRANSITIONS_PER_BATCH],
}
message!(TransitionBatch, "transitions");

impl TransitionBatch {
    /// An empty batch whose first step will have sequence number `first_seq`.
    pub fn new(
        actor: u16,
        incarnation: u64,
        obs_dim: usize,
        heads: usize,
        first_seq: u64,
    ) -> Result<Self> {
        if obs_dim > MAX_OBS_DIM {
            return Err(WireError::TooLarge {
                what: "observation",
                got: obs_dim,
                max: MAX_OBS_DIM,
            });
        }
        if heads > MAX_HEADS {
            return Err(WireError::TooLarge {
                what: "bootstrap mask",
                got: heads,
                max: MAX_HEADS,
            });
        }
        Ok(Self {
            actor: u32::from(actor),
            obs_dim: obs_dim as u16,
            heads: heads as u16,
            incarnation,
            first_seq,
            ..Self::default()
        })
    }

    pub fn len(&self) -> usize {
        self.len as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn is_full(&self) -> bool {
        self.len() == TRANSITIONS_PER_BATCH
    }

    /// Sequence number one past the last step of this batch.
    pub fn end_seq(&self) -> u64 {
        self.first_seq + u64::from(self.len)
    }

    /// Appends a step; `truncated` marks the end of an episode cut by the step limit.
    pub fn push(&mut self, t: &Transition, episode: u32, truncated: bool) -> Result<()> {
        if self.is_full() {
            return Err(WireError::TooLarge {
                what: "transition batch",
                got: TRANSITIONS_PER_BATCH + 1,
                max: TRANSITIONS_PER_BATCH,
            });
        }
        let d = self.obs_dim as usize;
        let h = self.heads as usize;
        if t.state.len() != d || t.next_state.len() != d {
            return Err(WireError::TooLarge {
                what: "transition state (batch obs_dim differs)",
                got: t.state.len().max(t.next_state.len()),
                max: d,
            });
        }
        if t.mask.len() != h {
            return Err(WireError::TooLarge {
                what: "transition mask (batch heads differ)",
                got: t.mask.len(),
                max: h,
            });
        }
        let r = &mut self.records[self.len as usize];
        *r = TransitionRecord::default();
        r.state[..d].copy_from_slice(&t.state);
        r.next_state[..d].copy_from_slice(&t.next_state);
        r.mask[..h].copy_from_slice(&t.mask);
        r.action = t.action;
        r.reward = t.reward;
        r.episode = episode;
        r.flags = (if t.terminated { flags::TERMINATED } else { 0 })
            | (if truncated { flags::TRUNCATED } else { 0 })
            | (if t.demo { flags::DEMO } else { 0 })
            | (if t.terminated || truncated {
                flags::EPISODE_END
            } else {
                0
            });
        self.len += 1;
        Ok(())
    }

    /// Step `i` of the batch as the replay buffer stores it.
    pub fn transition(&self, i: usize) -> Transition {
        let d = (self.obs_dim as usize).min(MAX_OBS_DIM);
        let h = (self.heads as usize).min(MAX_HEADS);
        let r = &self.records[i];
        Transition {
            state: r.state[..d].to_vec(),
            action: r.action,
            reward: r.reward,
            next_state: r.next_state[..d].to_vec(),
            terminated: r.flags & flags::TERMINATED != 0,
            mask: r.mask[..h].to_vec(),
            demo: r.flags & flags::DEMO != 0,
        }
    }

    /// The steps of the batch, in order.
    pub fn transitions(&self) -> impl Iterator<Item = Transition> + '_ {
        (0..self.len().min(TRANSITIONS_PER_BATCH)).map(|i| self.transition(i))
    }
}

/// The learner's grants to all actors, and its global counters.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("alfd.Credits")]
pub struct Credits {
    pub header: Header,
    /// Environment steps the learner has received from all actors: the run's global step.
    pub env_steps: u64,
    /// Updates the learner has made.
    pub updates: u64,
    /// Per actor id: steps of that incarnation received so far.
    pub received: [u64; MAX_ACTORS],
    /// Per actor id: the incarnation the grant is for (0: none yet).
    pub incarnation: [u64; MAX_ACTORS],
    /// Per actor id: the actor may send steps with sequence numbers below this.
    pub granted: [u64; MAX_ACTORS],
}
message!(Credits, "credits");

impl Credits {
    /// The grant for `actor` if it is for this `incarnation`.
    pub fn granted_for(&self, actor: u16, incarnation: u64) -> Option<u64> {
        let a = actor as usize;
        (a < MAX_ACTORS && self.incarnation[a] == incarnation).then(|| self.granted[a])
    }

    /// The global step as `actor` (incarnation `incarnation`) sees it after producing `produced`
    /// steps: the learner's count plus the actor's own steps it has not received yet.
    pub fn global_step_for(&self, actor: u16, incarnation: u64, produced: u64) -> u64 {
        let a = actor as usize;
        let received = if a < MAX_ACTORS && self.incarnation[a] == incarnation {
            self.received[a]
        } else {
            0
        };
        self.env_steps + produced.saturating_sub(received)
    }
}

/// User header of the `weights` slice.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("alfd.WeightsHeader")]
pub struct WeightsHeader {
    pub header: Header,
    /// Increases with every publication.
    pub version: u64,
    pub updates: u64,
    pub env_steps: u64,
    pub len: u64,
}

/// User header of the `demo-model` slice (postcard bytes of the fitted model).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("alfd.DemoModelHeader")]
pub struct DemoModelHeader {
    pub header: Header,
    /// Increases with every publication of the same expert; a new expert starts above the old.
    pub version: u64,
    /// Global step of the last demonstration (shaping stops at a multiple of it).
    pub last_demo_step: u64,
    pub demos: u32,
    pub budget_total: u32,
    pub budget_left: u32,
    /// Generation of the expert that published it.
    pub expert: u32,
    pub expert_name: [u8; NAME_LEN],
    pub len: u64,
}

impl DemoModelHeader {
    pub fn expert_name(&self) -> String {
        name_from_bytes(&self.expert_name)
    }
}

/// An actor asks the expert for the action at `state`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("alfd.QueryRequest")]
pub struct QueryRequest {
    pub header: Header,
    pub actor: u32,
    pub obs_dim: u32,
    pub incarnation: u64,
    /// The global step as the actor knows it.
    pub global_step: u64,
    pub state: [f32; MAX_OBS_DIM],
}
message!(QueryRequest, "query");

impl QueryRequest {
    pub fn new(actor: u16, incarnation: u64, global_step: u64, state: &[f32]) -> Result<Self> {
        if state.len() > MAX_OBS_DIM {
            return Err(WireError::TooLarge {
                what: "query state",
                got: state.len(),
                max: MAX_OBS_DIM,
            });
        }
        let mut s = [0.0; MAX_OBS_DIM];
        s[..state.len()].copy_from_slice(state);
        Ok(Self {
            actor: u32::from(actor),
            obs_dim: state.len() as u32,
            incarnation,
            global_step,
            state: s,
            ..Self::default()
        })
    }

    pub fn state(&self) -> &[f32] {
        &self.state[..(self.obs_dim as usize).min(MAX_OBS_DIM)]
    }
}

/// `outcome` of a [`QueryResponse`].
pub mod outcome {
    /// `action` is the expert's demonstration.
    pub const ANSWERED: u32 = 1;
    /// The budget is spent: no demonstration, act on your own.
    pub const BUDGET_EXHAUSTED: u32 = 2;
}

/// The expert's answer.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("alfd.QueryResponse")]
pub struct QueryResponse {
    pub header: Header,
    /// `header.seq` of the request answered.
    pub request_seq: u64,
    pub actor: u32,
    /// See [`outcome`].
    pub outcome: u32,
    pub action: u32,
    /// Generation of the expert that answered.
    pub expert: u32,
    /// Index of the demonstration in `demos.jsonl` (0-based).
    pub demo_index: u32,
    pub budget_total: u32,
    pub budget_left: u32,
    pub _pad: u32,
    pub expert_name: [u8; NAME_LEN],
}
message!(QueryResponse, "query");

impl QueryResponse {
    pub fn expert_name(&self) -> String {
        name_from_bytes(&self.expert_name)
    }
}

/// `kind` of a [`Progress`] message.
pub mod progress_kind {
    /// An actor finished an episode.
    pub const EPISODE: u32 = 1;
    /// A process reports its state and counters.
    pub const STATUS: u32 = 2;
}

/// `state` of a status [`Progress`] message.
pub mod process_state {
    pub const STARTING: u32 = 1;
    pub const RUNNING: u32 = 2;
    /// An expert that is up but not answering (it waits to be made active).
    pub const STANDBY: u32 = 3;
    pub const EXITING: u32 = 4;
}

/// Progress and metrics, from every process to the launcher. An episode message carries the
/// fields of the single-process runner's `EpisodeRecord`; the sender is `header.id`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("alfd.Progress")]
pub struct Progress {
    pub header: Header,
    /// See [`progress_kind`].
    pub kind: u32,
    /// See [`process_state`] (status messages).
    pub state: u32,
    pub pid: u32,
    pub _pad: u32,
    pub incarnation: u64,
    // --- an episode (kind EPISODE) ---
    /// The actor's own episode number.
    pub episode: u64,
    /// The environment's return (never the shaped one).
    pub episode_return: f64,
    pub length: u64,
    /// Demonstrations used so far in the run, as far as the actor knows.
    pub demos_used: u64,
    /// Mean JS divergence over the episode's steps.
    pub mean_js: f64,
    /// Queries answered during the episode.
    pub queries: u64,
    /// Steps whose reward was shaped during the episode.
    pub shaped_steps: u64,
    /// The global step at the end of the episode, as far as the actor knows.
    pub total_steps: u64,
    // --- counters (status) ---
    /// Environment steps: sent (actor), received (learner).
    pub env_steps: u64,
    pub updates: u64,
    /// Demonstrations answered in the whole run (expert).
    pub demos: u64,
    pub budget_left: u64,
    pub weights_version: u64,
    /// Last training loss (learner), NaN when none.
    pub loss: f64,
}
message!(Progress, "progress");

/// `command` of a [`Control`] message.
pub mod command {
    pub const RUN: u32 = 1;
    pub const SHUTDOWN: u32 = 2;
}

/// The launcher's word to every process. Published with history 1 and republished periodically,
/// so a late process gets it; it doubles as the launcher's heartbeat.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("alfd.Control")]
pub struct Control {
    pub header: Header,
    /// See [`command`].
    pub command: u32,
    /// Generation of the expert allowed to answer queries (0: none).
    pub active_expert: u32,
    /// Generation of the newest expert; an expert older than this stops answering and exits.
    pub newest_expert: u32,
    pub _pad: u32,
}
message!(Control, "control");

/// `name` in the fixed-size form messages carry (truncated to [`NAME_LEN`] bytes).
pub fn name_to_bytes(name: &str) -> [u8; NAME_LEN] {
    let mut out = [0u8; NAME_LEN];
    let mut n = name.len().min(NAME_LEN);
    while !name.is_char_boundary(n) {
        n -= 1;
    }
    out[..n].copy_from_slice(&name.as_bytes()[..n]);
    out
}

/// The inverse of [`name_to_bytes`].
pub fn name_from_bytes(bytes: &[u8; NAME_LEN]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(NAME_LEN);
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

// ---------------------------------------------------------------------------------------------
// Runs
// ---------------------------------------------------------------------------------------------

/// The iceoryx2 transport used by every process.
type Transport = ipc::Service;

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
fn run_config(run_id: &str) -> Result<Config> {
    validate_run_id(run_id)?;
    let mut cfg = Config::default();
    cfg.global.prefix = FileName::new(run_prefix(run_id).as_bytes())
        .map_err(transport("name the prefix of", run_id))?;
    Ok(cfg)
}

/// Set once a process received SIGINT or SIGTERM (iceoryx2 reports a signal only once).
static TERMINATION_REQUESTED: AtomicBool = AtomicBool::new(false);

/// Routes iceoryx2's own log output: only its warnings and errors (or `IOX2_LOG_LEVEL`).
pub fn quiet_transport_logs() {
    set_log_level_from_env_or(LogLevel::Warn);
}

/// Start-up shared by the process binaries (`alfd-actor`, `alfd-learner`, `alfd-expert`): quiets
/// iceoryx2, logs to `RUN_DIR/NAME.log` (appended to; `RUST_LOG` sets the filter, default `info`),
/// or to stderr if that file cannot be opened.
pub fn init_process_logging(process: &str, run_dir: &std::path::Path, name: &str) {
    quiet_transport_logs();
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

/// The schema version a process speaks: [`SCHEMA_VERSION`], unless the hidden test hook
/// `ALFD_SCHEMA_VERSION_OVERRIDE` says otherwise (the integration test of a mismatched process).
pub fn schema_version_from_env() -> Result<u32, String> {
    match std::env::var("ALFD_SCHEMA_VERSION_OVERRIDE") {
        Ok(v) => v
            .parse()
            .map_err(|_| format!("ALFD_SCHEMA_VERSION_OVERRIDE must be a number, got {v:?}")),
        Err(_) => Ok(SCHEMA_VERSION),
    }
}

/// A process's connection to its run: an iceoryx2 node with the run's config, and who we are.
pub struct Wire {
    node: Node<Transport>,
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
    /// [`SCHEMA_VERSION`]). SIGINT and SIGTERM are caught from here on: see
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

    pub fn run_id(&self) -> &str {
        &self.run_id
    }

    pub fn me(&self) -> Process {
        self.me
    }

    pub fn schema(&self) -> u32 {
        self.schema
    }

    /// Whether SIGINT or SIGTERM arrived (sticky).
    pub fn termination_requested(&self) -> bool {
        if TERMINATION_REQUESTED.load(Ordering::Relaxed) {
            return true;
        }
        if self.node.wait(Duration::ZERO).is_err() {
            TERMINATION_REQUESTED.store(true, Ordering::Relaxed);
        }
        TERMINATION_REQUESTED.load(Ordering::Relaxed)
    }

    /// Removes what crashed processes of this run left behind; returns how many nodes it removed.
    pub fn cleanup_dead_nodes(&self) -> usize {
        let state = self.node.try_cleanup_dead_nodes();
        state.cleanups as usize
    }

    fn service_name(&self, topic: &str) -> Result<ServiceName> {
        let name = format!("alfd/{}/{}", self.run_id, topic);
        ServiceName::new(&name).map_err(transport("name service", name.clone()))
    }

    fn header(&self, seq: u64) -> Header {
        Header {
            schema: self.schema,
            role: self.me.role as u16,
            id: self.me.id,
            seq,
        }
    }

    fn check(&self, service: &'static str, h: &Header) -> Result<()> {
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

    // --- one builder per service: every process opens it with these settings ---------------

    fn transitions_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<
            Transport,
            TransitionBatch,
            (),
        >,
    > {
        let name = self.service_name("transitions")?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<TransitionBatch>()
            .max_publishers(2 * MAX_ACTORS + 4)
            .max_subscribers(4)
            .max_nodes(MAX_NODES)
            .history_size(0)
            .subscriber_max_buffer_size(TRANSITIONS_BUFFER)
            .enable_safe_overflow(false)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    fn credits_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, Credits, ()>,
    > {
        let name = self.service_name("credits")?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<Credits>()
            .max_publishers(2)
            .max_subscribers(2 * MAX_ACTORS + 4)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(2)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    fn weights_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<
            Transport,
            [f32],
            WeightsHeader,
        >,
    > {
        let name = self.service_name("weights")?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<[f32]>()
            .user_header::<WeightsHeader>()
            .max_publishers(2)
            .max_subscribers(2 * MAX_ACTORS + 4)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(2)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    fn demo_model_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<
            Transport,
            [u8],
            DemoModelHeader,
        >,
    > {
        let name = self.service_name("demo-model")?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<[u8]>()
            .user_header::<DemoModelHeader>()
            .max_publishers(4)
            .max_subscribers(2 * MAX_ACTORS + 4)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(2)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    fn query_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::request_response::PortFactory<
            Transport,
            QueryRequest,
            (),
            QueryResponse,
            (),
        >,
    > {
        let name = self.service_name("query")?;
        self.node
            .service_builder(&name)
            .request_response::<QueryRequest, QueryResponse>()
            .max_servers(4)
            .max_clients(2 * MAX_ACTORS + 4)
            .max_nodes(MAX_NODES)
            .max_active_requests_per_client(2)
            .max_response_buffer_size(2)
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    fn progress_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, Progress, ()>,
    > {
        let name = self.service_name("progress")?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<Progress>()
            .max_publishers(MAX_NODES)
            .max_subscribers(4)
            .max_nodes(MAX_NODES)
            .history_size(0)
            .subscriber_max_buffer_size(256)
            .enable_safe_overflow(false)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    fn control_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, Control, ()>,
    > {
        let name = self.service_name("control")?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<Control>()
            .max_publishers(2)
            .max_subscribers(MAX_NODES)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(4)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    fn doorbell_service(
        &self,
        bell: Doorbell,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Transport>> {
        let name = self.service_name(&bell.topic())?;
        self.node
            .service_builder(&name)
            .event()
            .max_listeners(MAX_NODES)
            .max_notifiers(MAX_NODES)
            .max_nodes(MAX_NODES)
            .event_id_max_value(255)
            .open_or_create()
            .map_err(transport("open", name.to_string()))
    }

    // --- ports ------------------------------------------------------------------------------

    fn sender<T: Message>(&self, port: Publisher<Transport, T, ()>) -> Sender<'_, T> {
        Sender {
            wire: self,
            port,
            seq: 0,
        }
    }

    fn receiver<T: Message>(&self, port: Subscriber<Transport, T, ()>) -> Receiver<'_, T> {
        Receiver { wire: self, port }
    }

    /// Actor side of `transitions`.
    pub fn transitions_sender(&self) -> Result<Sender<'_, TransitionBatch>> {
        let port = self
            .transitions_service()?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(transport("create a publisher on", "transitions"))?;
        Ok(self.sender(port))
    }

    /// Learner side of `transitions`.
    pub fn transitions_receiver(&self) -> Result<Receiver<'_, TransitionBatch>> {
        let port = self
            .transitions_service()?
            .subscriber_builder()
            .buffer_size(TRANSITIONS_BUFFER)
            .create()
            .map_err(transport("create a subscriber on", "transitions"))?;
        Ok(self.receiver(port))
    }

    /// Learner side of `credits`.
    pub fn credits_sender(&self) -> Result<Sender<'_, Credits>> {
        let port = self
            .credits_service()?
            .publisher_builder()
            .create()
            .map_err(transport("create a publisher on", "credits"))?;
        Ok(self.sender(port))
    }

    /// Actor side of `credits`.
    pub fn credits_receiver(&self) -> Result<Receiver<'_, Credits>> {
        let port = self
            .credits_service()?
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(transport("create a subscriber on", "credits"))?;
        Ok(self.receiver(port))
    }

    /// Learner side of `weights`, for a network of `len` parameters.
    pub fn weights_sender(&self, len: usize) -> Result<WeightsSender<'_>> {
        let port = self
            .weights_service()?
            .publisher_builder()
            .initial_max_slice_len(len.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(transport("create a publisher on", "weights"))?;
        Ok(WeightsSender {
            wire: self,
            port,
            seq: 0,
        })
    }

    /// Actor side of `weights`.
    pub fn weights_receiver(&self) -> Result<WeightsReceiver<'_>> {
        let port = self
            .weights_service()?
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(transport("create a subscriber on", "weights"))?;
        Ok(WeightsReceiver { wire: self, port })
    }

    /// Expert side of `demo-model`.
    pub fn demo_model_sender(&self) -> Result<DemoModelSender<'_>> {
        let port = self
            .demo_model_service()?
            .publisher_builder()
            .initial_max_slice_len(4096)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(transport("create a publisher on", "demo-model"))?;
        Ok(DemoModelSender {
            wire: self,
            port,
            seq: 0,
        })
    }

    /// Actor side of `demo-model`.
    pub fn demo_model_receiver(&self) -> Result<DemoModelReceiver<'_>> {
        let port = self
            .demo_model_service()?
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(transport("create a subscriber on", "demo-model"))?;
        Ok(DemoModelReceiver { wire: self, port })
    }

    /// Actor side of `query`.
    pub fn query_client(&self) -> Result<QueryClient<'_>> {
        let port = self
            .query_service()?
            .client_builder()
            .create()
            .map_err(transport("create a client on", "query"))?;
        Ok(QueryClient {
            wire: self,
            port,
            seq: 0,
        })
    }

    /// Expert side of `query`.
    pub fn query_server(&self) -> Result<QueryServer<'_>> {
        let port = self
            .query_service()?
            .server_builder()
            .create()
            .map_err(transport("create a server on", "query"))?;
        Ok(QueryServer { wire: self, port })
    }

    /// Every process's side of `progress`.
    pub fn progress_sender(&self) -> Result<Sender<'_, Progress>> {
        let port = self
            .progress_service()?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(transport("create a publisher on", "progress"))?;
        Ok(self.sender(port))
    }

    /// The launcher's side of `progress`.
    pub fn progress_receiver(&self) -> Result<Receiver<'_, Progress>> {
        let port = self
            .progress_service()?
            .subscriber_builder()
            .buffer_size(256)
            .create()
            .map_err(transport("create a subscriber on", "progress"))?;
        Ok(self.receiver(port))
    }

    /// The launcher's side of `control`.
    pub fn control_sender(&self) -> Result<Sender<'_, Control>> {
        let port = self
            .control_service()?
            .publisher_builder()
            .create()
            .map_err(transport("create a publisher on", "control"))?;
        Ok(self.sender(port))
    }

    /// Every process's side of `control`.
    pub fn control_receiver(&self) -> Result<Receiver<'_, Control>> {
        let port = self
            .control_service()?
            .subscriber_builder()
            .buffer_size(4)
            .create()
            .map_err(transport("create a subscriber on", "control"))?;
        Ok(self.receiver(port))
    }

    /// Rings `bell` to wake whoever waits on it.
    pub fn bell(&self, bell: Doorbell) -> Result<Bell> {
        let port = self
            .doorbell_service(bell)?
            .notifier_builder()
            .create()
            .map_err(transport("create a notifier on", bell.topic()))?;
        Ok(Bell { port, bell })
    }

    /// Waits on `bell` (the process's own doorbell).
    pub fn waiter(&self, bell: Doorbell) -> Result<Waiter> {
        let listener = self
            .doorbell_service(bell)?
            .listener_builder()
            .create()
            .map_err(transport("create a listener on", bell.topic()))?;
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Transport>()
            .map_err(transport("create a waitset for", bell.topic()))?;
        Ok(Waiter {
            listener,
            waitset,
            bell,
        })
    }

    /// How many expert servers are connected to `query` right now.
    pub fn query_servers(&self) -> Result<usize> {
        Ok(self.query_service()?.dynamic_config().number_of_servers())
    }
}

/// Sends messages of type `T`, stamping each with the schema version, the sender and a sequence
/// number.
pub struct Sender<'w, T: Message> {
    wire: &'w Wire,
    port: Publisher<Transport, T, ()>,
    seq: u64,
}

impl<T: Message> fmt::Debug for Sender<'_, T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Sender<{}>(seq {})", T::SERVICE, self.seq)
    }
}

impl<T: Message> Sender<'_, T> {
    /// Sends `msg`; returns the sequence number it got.
    pub fn send(&mut self, mut msg: T) -> Result<u64> {
        let seq = self.seq;
        *msg.header_mut() = self.wire.header(seq);
        self.port
            .send_copy(msg)
            .map_err(transport("send on", T::SERVICE))?;
        self.seq += 1;
        Ok(seq)
    }

    /// Delivers the history to subscribers that connected since the last send.
    pub fn update_connections(&self) -> Result<()> {
        self.port
            .update_connections()
            .map_err(transport("update connections of", T::SERVICE))
    }
}

/// Receives messages of type `T`, refusing other schema versions.
pub struct Receiver<'w, T: Message> {
    wire: &'w Wire,
    port: Subscriber<Transport, T, ()>,
}

impl<T: Message> fmt::Debug for Receiver<'_, T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Receiver<{}>", T::SERVICE)
    }
}

impl<T: Message> Receiver<'_, T> {
    /// The next message, if any. A message of another schema version is consumed and reported
    /// as [`WireError::SchemaMismatch`]; the next call goes on with the following one.
    pub fn receive(&self) -> Result<Option<T>> {
        match self
            .port
            .receive()
            .map_err(transport("receive on", T::SERVICE))?
        {
            None => Ok(None),
            Some(sample) => {
                let msg = *sample.payload();
                self.wire.check(T::SERVICE, msg.header())?;
                Ok(Some(msg))
            }
        }
    }

    /// The newest message waiting, dropping older ones.
    pub fn latest(&self) -> Result<Option<T>> {
        let mut last = None;
        while let Some(m) = self.receive()? {
            last = Some(m);
        }
        Ok(last)
    }
}

/// Publishes the learner's weights.
pub struct WeightsSender<'w> {
    wire: &'w Wire,
    port: Publisher<Transport, [f32], WeightsHeader>,
    seq: u64,
}

impl fmt::Debug for WeightsSender<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "WeightsSender(seq {})", self.seq)
    }
}

impl WeightsSender<'_> {
    /// Publishes `weights` as version `version`.
    pub fn publish(
        &mut self,
        version: u64,
        updates: u64,
        env_steps: u64,
        weights: &[f32],
    ) -> Result<()> {
        let mut sample = self
            .port
            .loan_slice_uninit(weights.len())
            .map_err(transport("loan on", "weights"))?;
        *sample.user_header_mut() = WeightsHeader {
            header: self.wire.header(self.seq),
            version,
            updates,
            env_steps,
            len: weights.len() as u64,
        };
        sample
            .write_from_slice(weights)
            .send()
            .map_err(transport("send on", "weights"))?;
        self.seq += 1;
        Ok(())
    }

    /// Delivers the history to subscribers that connected since the last publication.
    pub fn update_connections(&self) -> Result<()> {
        self.port
            .update_connections()
            .map_err(transport("update connections of", "weights"))
    }
}

/// Receives the learner's weights.
pub struct WeightsReceiver<'w> {
    wire: &'w Wire,
    port: Subscriber<Transport, [f32], WeightsHeader>,
}

impl fmt::Debug for WeightsReceiver<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "WeightsReceiver")
    }
}

impl WeightsReceiver<'_> {
    /// Copies the newest weights waiting into `out`, if any, and returns their header.
    pub fn latest_into(&self, out: &mut Vec<f32>) -> Result<Option<WeightsHeader>> {
        let mut newest = None;
        while let Some(sample) = self
            .port
            .receive()
            .map_err(transport("receive on", "weights"))?
        {
            newest = Some(sample);
        }
        let Some(sample) = newest else {
            return Ok(None);
        };
        let h = *sample.user_header();
        self.wire.check("weights", &h.header)?;
        out.clear();
        out.extend_from_slice(sample.payload());
        Ok(Some(h))
    }
}

/// Publishes the expert's fitted demonstration model.
pub struct DemoModelSender<'w> {
    wire: &'w Wire,
    port: Publisher<Transport, [u8], DemoModelHeader>,
    seq: u64,
}

impl fmt::Debug for DemoModelSender<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "DemoModelSender(seq {})", self.seq)
    }
}

impl DemoModelSender<'_> {
    /// Publishes `bytes` (the model, serialized) under `header` (whose `header` and `len` are
    /// filled in here).
    pub fn publish(&mut self, mut header: DemoModelHeader, bytes: &[u8]) -> Result<()> {
        header.header = self.wire.header(self.seq);
        header.len = bytes.len() as u64;
        let mut sample = self
            .port
            .loan_slice_uninit(bytes.len().max(1))
            .map_err(transport("loan on", "demo-model"))?;
        *sample.user_header_mut() = header;
        let sample = if bytes.is_empty() {
            sample.write_from_slice(&[0u8])
        } else {
            sample.write_from_slice(bytes)
        };
        sample.send().map_err(transport("send on", "demo-model"))?;
        self.seq += 1;
        Ok(())
    }

    /// Delivers the history to subscribers that connected since the last publication.
    pub fn update_connections(&self) -> Result<()> {
        self.port
            .update_connections()
            .map_err(transport("update connections of", "demo-model"))
    }
}

/// Receives the expert's demonstration model.
pub struct DemoModelReceiver<'w> {
    wire: &'w Wire,
    port: Subscriber<Transport, [u8], DemoModelHeader>,
}

impl fmt::Debug for DemoModelReceiver<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "DemoModelReceiver")
    }
}

impl DemoModelReceiver<'_> {
    /// Copies the newest model waiting into `out`, if any, and returns its header.
    pub fn latest_into(&self, out: &mut Vec<u8>) -> Result<Option<DemoModelHeader>> {
        let mut newest = None;
        while let Some(sample) = self
            .port
            .receive()
            .map_err(transport("receive on", "demo-model"))?
        {
            newest = Some(sample);
        }
        let Some(sample) = newest else {
            return Ok(None);
        };
        let h = *sample.user_header();
        self.wire.check("demo-model", &h.header)?;
        let len = (h.len as usize).min(sample.payload().len());
        out.clear();
        out.extend_from_slice(&sample.payload()[..len]);
        Ok(Some(h))
    }
}

/// An actor's side of `query`.
pub struct QueryClient<'w> {
    wire: &'w Wire,
    port: Client<Transport, QueryRequest, (), QueryResponse, ()>,
    seq: u64,
}

impl fmt::Debug for QueryClient<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "QueryClient(seq {})", self.seq)
    }
}

impl<'w> QueryClient<'w> {
    /// Sends `request`. With no expert connected it still succeeds, and
    /// [`PendingQuery::servers`] is 0: no answer will come.
    pub fn ask(&mut self, mut request: QueryRequest) -> Result<PendingQuery<'w>> {
        let seq = self.seq;
        request.header = self.wire.header(seq);
        let pending = self
            .port
            .send_copy(request)
            .map_err(transport("send on", "query"))?;
        self.seq += 1;
        Ok(PendingQuery {
            wire: self.wire,
            pending,
            seq,
            duplicates: 0,
            answered: false,
        })
    }
}

/// A query on its way; poll it for the answer.
pub struct PendingQuery<'w> {
    wire: &'w Wire,
    pending: PendingResponse<Transport, QueryRequest, (), QueryResponse, ()>,
    seq: u64,
    duplicates: u32,
    answered: bool,
}

impl fmt::Debug for PendingQuery<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PendingQuery(seq {})", self.seq)
    }
}

impl PendingQuery<'_> {
    /// The request's sequence number.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// How many expert servers received the request.
    pub fn servers(&self) -> usize {
        self.pending.number_of_server_connections()
    }

    /// The answer, once. Any further response to the same request (two experts up during a
    /// swap), or a response to another request, is dropped and counted in
    /// [`PendingQuery::duplicates`].
    pub fn poll(&mut self) -> Result<Option<QueryResponse>> {
        while let Some(r) = self
            .pending
            .receive()
            .map_err(transport("receive on", "query"))?
        {
            let resp = *r.payload();
            self.wire.check("query", &resp.header)?;
            if resp.request_seq != self.seq || self.answered {
                self.duplicates += 1;
                continue;
            }
            self.answered = true;
            return Ok(Some(resp));
        }
        Ok(None)
    }

    pub fn duplicates(&self) -> u32 {
        self.duplicates
    }
}

/// The expert's side of `query`.
pub struct QueryServer<'w> {
    wire: &'w Wire,
    port: Server<Transport, QueryRequest, (), QueryResponse, ()>,
}

impl fmt::Debug for QueryServer<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "QueryServer")
    }
}

impl<'w> QueryServer<'w> {
    /// The next request, if any. A request of another schema version is dropped unanswered and
    /// reported as [`WireError::SchemaMismatch`].
    pub fn receive(&self) -> Result<Option<IncomingQuery<'w>>> {
        match self
            .port
            .receive()
            .map_err(transport("receive on", "query"))?
        {
            None => Ok(None),
            Some(active) => {
                let request = *active.payload();
                self.wire.check("query", &request.header)?;
                Ok(Some(IncomingQuery {
                    wire: self.wire,
                    active,
                    request,
                }))
            }
        }
    }
}

/// A request the expert holds; answer it or drop it.
pub struct IncomingQuery<'w> {
    wire: &'w Wire,
    active: ActiveRequest<Transport, QueryRequest, (), QueryResponse, ()>,
    request: QueryRequest,
}

impl fmt::Debug for IncomingQuery<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "IncomingQuery({:?})", self.request)
    }
}

impl IncomingQuery<'_> {
    pub fn request(&self) -> &QueryRequest {
        &self.request
    }

    /// Whether the actor still waits for the answer (it gives up after its timeout).
    pub fn is_connected(&self) -> bool {
        self.active.is_connected()
    }

    /// Sends `response` (its header and `request_seq` are filled in here).
    pub fn answer(self, mut response: QueryResponse) -> Result<()> {
        response.header = self.wire.header(self.request.header.seq);
        response.request_seq = self.request.header.seq;
        response.actor = self.request.actor;
        self.active
            .send_copy(response)
            .map_err(transport("answer on", "query"))
    }
}

/// Rings a doorbell.
pub struct Bell {
    port: Notifier<Transport>,
    bell: Doorbell,
}

impl fmt::Debug for Bell {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Bell({:?})", self.bell)
    }
}

impl Bell {
    /// Wakes every process waiting on this doorbell; returns how many listeners were notified.
    pub fn ring(&self) -> Result<usize> {
        self.port
            .notify()
            .map_err(transport("notify", self.bell.topic()))
    }
}

/// The doorbells of the actors, opened as needed.
pub struct ActorBells<'w> {
    wire: &'w Wire,
    bells: Vec<Option<Bell>>,
}

impl fmt::Debug for ActorBells<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ActorBells({})", self.bells.iter().flatten().count())
    }
}

impl<'w> ActorBells<'w> {
    pub fn new(wire: &'w Wire) -> Self {
        Self {
            wire,
            bells: (0..MAX_ACTORS).map(|_| None).collect(),
        }
    }

    /// Wakes actor `id` if it waits on its doorbell.
    pub fn ring(&mut self, id: u16) -> Result<()> {
        let Some(slot) = self.bells.get_mut(id as usize) else {
            return Ok(());
        };
        if slot.is_none() {
            *slot = Some(self.wire.bell(Doorbell::Actor(id))?);
        }
        if let Some(bell) = slot {
            bell.ring()?;
        }
        Ok(())
    }

    /// Wakes actors `0..n`.
    pub fn ring_all(&mut self, n: usize) -> Result<()> {
        for id in 0..n.min(MAX_ACTORS) {
            self.ring(id as u16)?;
        }
        Ok(())
    }
}

/// Why [`Waiter::wait`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// The doorbell rang.
    Rang,
    /// The timeout passed.
    Timeout,
    /// SIGINT or SIGTERM arrived.
    Signal,
}

/// A process's own doorbell, and a WaitSet to block on it.
pub struct Waiter {
    listener: Listener<Transport>,
    waitset: WaitSet<Transport>,
    bell: Doorbell,
}

impl fmt::Debug for Waiter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Waiter({:?})", self.bell)
    }
}

impl Waiter {
    /// Blocks until the doorbell rings, `timeout` passes or a termination signal arrives. Rings
    /// that arrived before the call return at once; all pending rings are consumed.
    pub fn wait(&self, timeout: Duration) -> Result<Wake> {
        if TERMINATION_REQUESTED.load(Ordering::Relaxed) {
            return Ok(Wake::Signal);
        }
        let mut rang = false;
        {
            let _guard = self
                .waitset
                .attach_notification(&self.listener)
                .map_err(transport("attach to a waitset", self.bell.topic()))?;
            let result = self
                .waitset
                .wait_and_process_once_with_timeout(
                    |_| {
                        rang = true;
                        CallbackProgression::Continue
                    },
                    timeout,
                )
                .map_err(transport("wait on", self.bell.topic()))?;
            if matches!(
                result,
                WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt
            ) {
                TERMINATION_REQUESTED.store(true, Ordering::Relaxed);
                return Ok(Wake::Signal);
            }
        }
        let n = self.drain()?;
        Ok(if rang || n > 0 {
            Wake::Rang
        } else {
            Wake::Timeout
        })
    }

    /// Consumes pending rings without blocking; returns how many there were.
    pub fn drain(&self) -> Result<u64> {
        self.listener
            .try_wait(|_| {})
            .map_err(transport("drain", self.bell.topic()))
    }
}

/// A process's view of the launcher's [`Control`]: the first message is the schema handshake,
/// later ones carry the expert generations and shutdown, and their arrival is the launcher's
/// heartbeat.
pub struct ControlWatch<'w> {
    rx: Receiver<'w, Control>,
    current: Control,
    seen: bool,
    last_seen: std::time::Instant,
}

impl fmt::Debug for ControlWatch<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ControlWatch({:?})", self.current)
    }
}

/// How often the launcher republishes [`Control`] (its heartbeat).
pub const CONTROL_PERIOD: Duration = Duration::from_millis(200);

impl<'w> ControlWatch<'w> {
    pub fn new(wire: &'w Wire) -> Result<Self> {
        Ok(Self {
            rx: wire.control_receiver()?,
            current: Control::default(),
            seen: false,
            last_seen: std::time::Instant::now(),
        })
    }

    /// Waits (blocking on `waiter`) for the launcher's first message, up to `timeout`. This is
    /// where a process of another schema version learns it does not belong: it gets
    /// [`WireError::SchemaMismatch`].
    pub fn handshake(&mut self, waiter: &Waiter, timeout: Duration) -> Result<Control> {
        let start = std::time::Instant::now();
        loop {
            if self.poll()? {
                return Ok(self.current);
            }
            if start.elapsed() >= timeout {
                return Err(WireError::NoLauncher {
                    waited_ms: timeout.as_millis() as u64,
                });
            }
            if waiter.wait(CONTROL_PERIOD / 4)? == Wake::Signal {
                return Err(WireError::Interrupted);
            }
        }
    }

    /// Takes in what the launcher sent since the last call; `true` if anything came.
    pub fn poll(&mut self) -> Result<bool> {
        let mut any = false;
        while let Some(c) = self.rx.receive()? {
            self.current = c;
            any = true;
        }
        if any {
            self.seen = true;
            self.last_seen = std::time::Instant::now();
        }
        Ok(any)
    }

    /// The newest control message (all zero before the handshake).
    pub fn current(&self) -> Control {
        self.current
    }

    pub fn shutdown_requested(&self) -> bool {
        self.current.command == command::SHUTDOWN
    }

    /// Time since the launcher was last heard of.
    pub fn silence(&self) -> Duration {
        self.last_seen.elapsed()
    }
}

// ---------------------------------------------------------------------------------------------
// Files a run leaves in the system
// ---------------------------------------------------------------------------------------------

/// Files of run `run_id` left in iceoryx2's directories (`/tmp/iceoryx2`, `/dev/shm`). Empty once
/// every process of the run has exited cleanly.
pub fn leftover_files(run_id: &str) -> Vec<PathBuf> {
    let prefix = run_prefix(run_id);
    let mut found = Vec::new();
    let mut stack = vec![PathBuf::from("/tmp/iceoryx2"), PathBuf::from("/dev/shm")];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let is_dir = entry.file_type().map(|t| t.is_dir()).unwrap_or(false);
            if entry.file_name().to_string_lossy().starts_with(&prefix) {
                found.push(path);
            } else if is_dir {
                stack.push(path);
            }
        }
    }
    found.sort();
    found
}

/// Removes the resources of dead processes of run `run_id` (killed with SIGKILL, say); returns
/// the names of the nodes it removed.
pub fn cleanup_dead_nodes(run_id: &str) -> Result<Vec<String>> {
    let cfg = run_config(run_id)?;
    let mut dead = Vec::new();
    Node::<Transport>::list(&cfg, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    })
    .map_err(transport("list the nodes of", run_id))?;
    let mut removed = Vec::new();
    for view in dead {
        let name = view
            .details()
            .as_ref()
            .map(|d| d.name().to_string())
            .unwrap_or_else(|| "?".to_owned());
        if view.try_remove_stale_resources().is_ok() {
            removed.push(name);
        }
    }
    Ok(removed)
}

/// Names of the nodes of run `run_id` whose process is alive.
pub fn alive_nodes(run_id: &str) -> Result<Vec<String>> {
    let cfg = run_config(run_id)?;
    let mut alive = Vec::new();
    Node::<Transport>::list(&cfg, |state| {
        if let NodeState::Alive(view) = state {
            alive.push(
                view.details()
                    .as_ref()
                    .map(|d| d.name().to_string())
                    .unwrap_or_else(|| "?".to_owned()),
            );
        }
        CallbackProgression::Continue
    })
    .map_err(transport("list the nodes of", run_id))?;
    Ok(alive)
}

/// Removes what run `run_id` left in the system after its last process exited: the resources of
/// dead nodes, and the run's node counter (a persistent segment iceoryx2 keeps per prefix).
/// Refuses while a node of the run is alive (including one of the calling process).
pub fn close_run(run_id: &str) -> Result<()> {
    let cfg = run_config(run_id)?;
    cleanup_dead_nodes(run_id)?;
    let alive = alive_nodes(run_id)?;
    if !alive.is_empty() {
        return Err(WireError::RunAlive {
            run_id: run_id.to_owned(),
            nodes: alive.join(", "),
        });
    }
    #[allow(unsafe_code)]
    // SAFETY: iceoryx2 requires that no process uses the segment's domain. The domain is this
    // run's own prefix, and no node of the run is alive (checked just above); only the launcher
    // starts processes of a run, and it calls this after its last one exited.
    let removed = unsafe { iceoryx2::testing::remove_global_mgmt_segment::<Transport>(&cfg) };
    removed.map_err(transport("remove the node counter of", run_id))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    // Tests of the wire, in one process: every test uses its own run id, hence its own iceoryx2
    // prefix, so tests running in parallel never see each other.

    use std::sync::atomic::{AtomicU32, Ordering};
    use std::time::Duration;

    use super::*;

    fn run_id(test: &str) -> String {
        static N: AtomicU32 = AtomicU32::new(0);
        format!(
            "t{}-{}-{}",
            std::process::id(),
            test,
            N.fetch_add(1, Ordering::Relaxed)
        )
    }

    /// Runs `test` on a fresh run id, then checks that the run leaves nothing behind.
    fn with_run(name: &str, test: impl FnOnce(&str)) {
        let run = run_id(name);
        test(&run);
        close_run(&run).expect("every node of the test was dropped");
        assert_eq!(leftover_files(&run), Vec::<std::path::PathBuf>::new());
    }

    fn wire(run: &str, role: Role, id: u16) -> Wire {
        Wire::connect(run, Process::new(role, id), SCHEMA_VERSION).expect("connect")
    }

    fn transition(x: f32, demo: bool, terminated: bool) -> Transition {
        Transition {
            state: vec![x, x + 0.5, -x, 0.25],
            action: (x as u32) % 2,
            reward: x * 2.0,
            next_state: vec![x + 1.0, x + 1.5, -x - 1.0, 0.5],
            terminated,
            mask: vec![1.0, 0.0],
            demo,
        }
    }

    #[test]
    fn transitions_arrive_in_order_with_header_and_flags() {
        with_run("transitions", |run| {
            let actor = wire(run, Role::Actor, 3);
            let learner = wire(run, Role::Learner, 0);
            let rx = learner.transitions_receiver().unwrap();
            let mut tx = actor.transitions_sender().unwrap();

            let sent = [
                transition(1.0, false, false),
                transition(2.0, true, false),
                transition(3.0, false, true),
            ];
            let mut batch = TransitionBatch::new(3, 77, 4, 2, 10).unwrap();
            for (i, t) in sent.iter().enumerate() {
                batch.push(t, 5, false).unwrap();
                assert_eq!(batch.len(), i + 1);
            }
            assert_eq!(batch.end_seq(), 13);
            assert_eq!(tx.send(batch).unwrap(), 0);
            assert_eq!(
                tx.send(TransitionBatch::new(3, 77, 4, 2, 13).unwrap())
                    .unwrap(),
                1
            );

            let got = rx.receive().unwrap().expect("a batch");
            assert_eq!(got.header.schema, SCHEMA_VERSION);
            assert_eq!(got.header.sender(), "actor-3");
            assert_eq!(got.header.seq, 0);
            assert_eq!((got.actor, got.incarnation, got.first_seq), (3, 77, 10));
            let back: Vec<Transition> = got.transitions().collect();
            assert_eq!(back, sent);
            assert_eq!(got.records[1].flags, flags::DEMO);
            assert_eq!(got.records[2].flags, flags::TERMINATED | flags::EPISODE_END);
            let second = rx.receive().unwrap().expect("the empty batch");
            assert_eq!(second.header.seq, 1);
            assert!(second.is_empty());
            assert!(rx.receive().unwrap().is_none());
        });
    }

    #[test]
    fn a_batch_refuses_what_it_cannot_carry() {
        assert!(matches!(
            TransitionBatch::new(0, 1, MAX_OBS_DIM + 1, 2, 0),
            Err(WireError::TooLarge {
                max: MAX_OBS_DIM,
                ..
            })
        ));
        assert!(matches!(
            TransitionBatch::new(0, 1, 4, MAX_HEADS + 1, 0),
            Err(WireError::TooLarge { max: MAX_HEADS, .. })
        ));
        let mut b = TransitionBatch::new(0, 1, 4, 2, 0).unwrap();
        let mut wrong = transition(1.0, false, false);
        wrong.state.push(9.0);
        assert!(b.push(&wrong, 0, false).is_err());
        assert!(b.is_empty(), "a refused step is not stored");
        for i in 0..TRANSITIONS_PER_BATCH {
            b.push(&transition(i as f32, false, false), 0, false)
                .unwrap();
        }
        assert!(b.is_full());
        assert!(b.push(&transition(0.0, false, false), 0, false).is_err());
        let truncated = {
            let mut b = TransitionBatch::new(0, 1, 4, 2, 0).unwrap();
            b.push(&transition(1.0, false, false), 0, true).unwrap();
            b.records[0].flags
        };
        assert_eq!(truncated, flags::TRUNCATED | flags::EPISODE_END);
        assert!(QueryRequest::new(0, 1, 0, &[0.0; MAX_OBS_DIM + 1]).is_err());
    }

    #[test]
    fn another_schema_version_is_refused_naming_both_versions() {
        with_run("schema", |run| {
            let launcher = wire(run, Role::Launcher, 0);
            let stranger = Wire::connect(run, Process::new(Role::Actor, 1), 999).unwrap();
            let rx = stranger.control_receiver().unwrap();
            let mut tx = launcher.control_sender().unwrap();
            tx.send(Control {
                command: command::RUN,
                ..Control::default()
            })
            .unwrap();
            let err = rx.receive().unwrap_err();
            assert_eq!(
                err,
                WireError::SchemaMismatch {
                    service: "control",
                    ours: 999,
                    theirs: SCHEMA_VERSION,
                    sender: "launcher".to_owned(),
                }
            );
            let text = err.to_string();
            assert!(
                text.contains("999") && text.contains(&format!("version {SCHEMA_VERSION}")),
                "{text}"
            );
            // The bad message was consumed; the receiver goes on.
            assert!(rx.receive().unwrap().is_none());

            // The same on a slice service.
            let mut weights = stranger.weights_sender(3).unwrap();
            let learner_rx = launcher.weights_receiver().unwrap();
            weights.publish(1, 0, 0, &[1.0, 2.0, 3.0]).unwrap();
            let mut out = Vec::new();
            assert!(matches!(
                learner_rx.latest_into(&mut out),
                Err(WireError::SchemaMismatch {
                    ours: SCHEMA_VERSION,
                    theirs: 999,
                    ..
                })
            ));
        });
    }

    #[test]
    fn weights_reach_a_late_subscriber_and_only_the_newest_is_kept() {
        with_run("weights", |run| {
            let learner = wire(run, Role::Learner, 0);
            let actor = wire(run, Role::Actor, 0);
            let mut tx = learner.weights_sender(4500).unwrap();
            let w1: Vec<f32> = (0..4500).map(|i| i as f32 * 0.5).collect();
            tx.publish(1, 10, 20, &w1).unwrap();

            // Subscribes after the publication: gets it from the history once the publisher updates.
            let rx = actor.weights_receiver().unwrap();
            tx.update_connections().unwrap();
            let mut out = Vec::new();
            let h = rx.latest_into(&mut out).unwrap().expect("history sample");
            assert_eq!(
                (h.version, h.updates, h.env_steps, h.len),
                (1, 10, 20, 4500)
            );
            assert_eq!(out, w1);

            for v in 2..=4 {
                let w: Vec<f32> = vec![v as f32; 4500];
                tx.publish(v, 0, 0, &w).unwrap();
            }
            let h = rx.latest_into(&mut out).unwrap().unwrap();
            assert_eq!(h.version, 4);
            assert!(out.iter().all(|&x| x == 4.0));
            assert!(rx.latest_into(&mut out).unwrap().is_none());
        });
    }

    #[test]
    fn demo_model_bytes_round_trip() {
        with_run("demo-model", |run| {
            let expert = wire(run, Role::Expert, 2);
            let actor = wire(run, Role::Actor, 0);
            let rx = actor.demo_model_receiver().unwrap();
            let mut tx = expert.demo_model_sender().unwrap();
            // Larger than the initial 4 KiB: the publisher grows its segment.
            let bytes: Vec<u8> = (0..10_000u32).map(|i| (i % 251) as u8).collect();
            let header = DemoModelHeader {
                version: 7,
                last_demo_step: 1234,
                demos: 12,
                budget_total: 100,
                budget_left: 88,
                expert: 2,
                expert_name: name_to_bytes("cartpole-1000"),
                ..DemoModelHeader::default()
            };
            tx.publish(header, &bytes).unwrap();
            let mut out = Vec::new();
            let h = rx.latest_into(&mut out).unwrap().unwrap();
            assert_eq!(out, bytes);
            assert_eq!(
                (h.version, h.last_demo_step, h.demos, h.budget_left),
                (7, 1234, 12, 88)
            );
            assert_eq!(h.expert_name(), "cartpole-1000");
            assert_eq!(h.len, 10_000);
        });
    }

    #[test]
    fn a_query_without_expert_reaches_nobody() {
        with_run("query-none", |run| {
            let actor = wire(run, Role::Actor, 1);
            let mut client = actor.query_client().unwrap();
            assert_eq!(actor.query_servers().unwrap(), 0);
            let mut pending = client
                .ask(QueryRequest::new(1, 9, 0, &[0.1, 0.2, 0.3, 0.4]).unwrap())
                .unwrap();
            assert_eq!(pending.servers(), 0);
            assert!(pending.poll().unwrap().is_none());
        });
    }

    #[test]
    fn a_query_is_answered_once_and_duplicates_are_dropped() {
        with_run("query", |run| {
            let actor = wire(run, Role::Actor, 1);
            let old = wire(run, Role::Expert, 1);
            let new = wire(run, Role::Expert, 2);
            let s1 = old.query_server().unwrap();
            let s2 = new.query_server().unwrap();
            let mut client = actor.query_client().unwrap();
            assert_eq!(actor.query_servers().unwrap(), 2);

            // A first request, answered by nobody, then a second one answered by both experts.
            drop(
                client
                    .ask(QueryRequest::new(1, 9, 5, &[0.0; 4]).unwrap())
                    .unwrap(),
            );
            let mut pending = client
                .ask(QueryRequest::new(1, 9, 42, &[0.1, 0.2, 0.3, 0.4]).unwrap())
                .unwrap();
            assert_eq!(pending.seq(), 1);
            assert_eq!(pending.servers(), 2);
            for (server, expert, action) in [(&s1, 1u32, 0u32), (&s2, 2, 1)] {
                // The dropped first request may or may not still be queued; skip it.
                let mut q = server.receive().unwrap().expect("a request");
                if q.request().header.seq == 0 {
                    q = server.receive().unwrap().expect("the second request");
                }
                assert_eq!(q.request().state(), &[0.1, 0.2, 0.3, 0.4]);
                assert_eq!(q.request().global_step, 42);
                assert_eq!(q.request().header.sender(), "actor-1");
                assert!(q.is_connected());
                q.answer(QueryResponse {
                    outcome: outcome::ANSWERED,
                    action,
                    expert,
                    demo_index: 3,
                    expert_name: name_to_bytes(&format!("expert-{expert}")),
                    ..QueryResponse::default()
                })
                .unwrap();
            }
            let first = pending.poll().unwrap().expect("an answer");
            assert_eq!(
                (first.request_seq, first.actor, first.action, first.expert),
                (1, 1, 0, 1)
            );
            assert_eq!(first.expert_name(), "expert-1");
            assert!(
                pending.poll().unwrap().is_none(),
                "the second answer is dropped"
            );
            assert_eq!(pending.duplicates(), 1);
        });
    }

    #[test]
    fn an_abandoned_query_is_seen_by_the_expert() {
        with_run("query-abandoned", |run| {
            let actor = wire(run, Role::Actor, 0);
            let expert = wire(run, Role::Expert, 1);
            let server = expert.query_server().unwrap();
            let mut client = actor.query_client().unwrap();
            let pending = client
                .ask(QueryRequest::new(0, 1, 0, &[0.0; 4]).unwrap())
                .unwrap();
            let q = server.receive().unwrap().unwrap();
            assert!(q.is_connected());
            drop(pending); // the actor timed out
            assert!(!q.is_connected(), "the expert must not spend budget on it");
        });
    }

    #[test]
    fn credits_and_progress_carry_their_fields() {
        with_run("credits", |run| {
            let learner = wire(run, Role::Learner, 0);
            let actor = wire(run, Role::Actor, 2);
            let launcher = wire(run, Role::Launcher, 0);
            let mut credits = learner.credits_sender().unwrap();
            let crx = actor.credits_receiver().unwrap();
            let mut c = Credits {
                env_steps: 500,
                updates: 480,
                ..Credits::default()
            };
            c.incarnation[2] = 11;
            c.granted[2] = 96;
            credits.send(c).unwrap();
            c.granted[2] = 128;
            credits.send(c).unwrap();
            let got = crx.latest().unwrap().unwrap();
            assert_eq!(got.granted_for(2, 11), Some(128));
            assert_eq!(
                got.granted_for(2, 12),
                None,
                "a grant for another incarnation"
            );
            assert_eq!(got.granted_for(99, 11), None);
            assert_eq!(got.env_steps, 500);

            let prx = launcher.progress_receiver().unwrap();
            let mut ptx = actor.progress_sender().unwrap();
            for e in 0..3u64 {
                ptx.send(Progress {
                    kind: progress_kind::EPISODE,
                    episode: e,
                    episode_return: 10.0 + e as f64,
                    length: 10 + e,
                    ..Progress::default()
                })
                .unwrap();
            }
            let mut seen = Vec::new();
            while let Some(p) = prx.receive().unwrap() {
                seen.push((p.header.seq, p.episode, p.episode_return, p.length));
            }
            assert_eq!(
                seen,
                vec![(0, 0, 10.0, 10), (1, 1, 11.0, 11), (2, 2, 12.0, 12)]
            );
        });
    }

    #[test]
    fn a_doorbell_wakes_its_waiter_and_times_out_otherwise() {
        with_run("doorbell", |run| {
            let learner = wire(run, Role::Learner, 0);
            let actor = wire(run, Role::Actor, 0);
            let waiter = learner.waiter(Doorbell::Learner).unwrap();
            let bell = actor.bell(Doorbell::Learner).unwrap();
            let other = actor.bell(Doorbell::Expert).unwrap();
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout
            );
            other.ring().unwrap();
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout,
                "another role's bell does not wake the learner"
            );
            assert_eq!(bell.ring().unwrap(), 1);
            bell.ring().unwrap();
            assert_eq!(waiter.wait(Duration::from_secs(5)).unwrap(), Wake::Rang);
            // Both rings were consumed by the one wake-up.
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout
            );

            // A ring from another thread wakes a blocked waiter.
            let run2 = run.to_owned();
            let t = std::thread::spawn(move || {
                let w = wire(&run2, Role::Tool, 1);
                let b = w.bell(Doorbell::Learner).unwrap();
                std::thread::sleep(Duration::from_millis(50));
                b.ring().unwrap();
            });
            assert_eq!(waiter.wait(Duration::from_secs(10)).unwrap(), Wake::Rang);
            t.join().unwrap();
        });
    }

    #[test]
    fn two_runs_do_not_see_each_other_and_leave_nothing_behind() {
        let run_a = run_id("iso-a");
        let run_b = run_id("iso-b");
        {
            let a_launcher = wire(&run_a, Role::Launcher, 0);
            let b_launcher = wire(&run_b, Role::Launcher, 0);
            let a_actor = wire(&run_a, Role::Actor, 0);
            let b_actor = wire(&run_b, Role::Actor, 0);
            let mut a_tx = a_launcher.control_sender().unwrap();
            let mut b_tx = b_launcher.control_sender().unwrap();
            let a_rx = a_actor.control_receiver().unwrap();
            let b_rx = b_actor.control_receiver().unwrap();
            a_tx.send(Control {
                command: command::SHUTDOWN,
                ..Control::default()
            })
            .unwrap();
            assert_eq!(a_rx.receive().unwrap().unwrap().command, command::SHUTDOWN);
            assert!(
                b_rx.receive().unwrap().is_none(),
                "run b saw run a's control"
            );
            b_tx.send(Control {
                command: command::RUN,
                active_expert: 4,
                ..Control::default()
            })
            .unwrap();
            assert!(a_rx.receive().unwrap().is_none());
            assert_eq!(b_rx.receive().unwrap().unwrap().active_expert, 4);
            assert!(!leftover_files(&run_a).is_empty(), "a live run has files");
            assert!(leftover_files(&run_a)
                .iter()
                .all(|p| p.to_string_lossy().contains(&run_prefix(&run_a))));
            assert!(matches!(close_run(&run_a), Err(WireError::RunAlive { .. })));
            assert_eq!(alive_nodes(&run_b).unwrap().len(), 2);
        }
        assert_eq!(cleanup_dead_nodes(&run_a).unwrap(), Vec::<String>::new());
        assert_eq!(alive_nodes(&run_a).unwrap(), Vec::<String>::new());
        close_run(&run_a).unwrap();
        close_run(&run_b).unwrap();
        assert_eq!(leftover_files(&run_a), Vec::<std::path::PathBuf>::new());
        assert_eq!(leftover_files(&run_b), Vec::<std::path::PathBuf>::new());
    }

    #[test]
    fn run_ids_and_names_are_checked() {
        assert!(validate_run_id("20250101-120000_ab12").is_ok());
        for bad in ["", "a/b", "a b", "ü", &"x".repeat(65)] {
            assert_eq!(
                validate_run_id(bad),
                Err(WireError::InvalidRunId(bad.to_owned()))
            );
        }
        assert!(Wire::connect("bad/id", Process::new(Role::Tool, 0), SCHEMA_VERSION).is_err());
        assert_eq!(
            name_from_bytes(&name_to_bytes("cartpole-200")),
            "cartpole-200"
        );
        let long = "é".repeat(20); // 40 bytes: cut on a character boundary
        assert_eq!(name_from_bytes(&name_to_bytes(&long)), "é".repeat(16));
        assert_eq!(Process::new(Role::Actor, 3).to_string(), "actor-3");
        assert_eq!(Process::new(Role::Learner, 0).to_string(), "learner");
        assert_eq!(Role::from_u16(Role::Expert as u16), Some(Role::Expert));
        assert_eq!(Role::from_u16(0), None);
    }
}
