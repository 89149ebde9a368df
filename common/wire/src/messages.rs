//! The messages of the wire: limits, identities, the [`Header`] every message starts with, and
//! one fixed-size, plain-data type per service (iceoryx2 copies them as they are).

use std::fmt;

use alfd_common::record::EpisodeRecord;
use alfd_common::replay::Transition;
use iceoryx2::prelude::ZeroCopySend;

use crate::error::{Result, WireError};

/// The version of the messages below. Bump it whenever a message changes, or the zenoh keys the
/// bridges send them on (`alfd_bridge`), so that a process or host of another build is refused
/// by name.
pub const SCHEMA_VERSION: u32 = 9;
/// Actors per run (the credit table has one slot per actor id).
pub const MAX_ACTORS: usize = 16;
/// Largest observation a message may claim (a peer's bytes can make a receiver allocate no
/// more). A run sizes its services to its own observations and heads; how much shared memory
/// that takes is [`transitions_bytes`](crate::transitions_bytes).
pub const MAX_OBS_DIM: usize = u16::MAX as usize;
/// Largest number of heads (K) a bootstrap mask may claim.
pub const MAX_HEADS: usize = u16::MAX as usize;
/// Transitions per [`TransitionBatch`].
pub const TRANSITIONS_PER_BATCH: usize = 32;
/// The learner's subscriber queue per actor, in batches. The credit window may not exceed it:
/// an actor never has more batches in flight than unpaid steps, so no batch is ever dropped.
pub const TRANSITIONS_BUFFER: usize = 64;
/// Largest credit window, in environment steps.
pub const MAX_CREDIT_WINDOW: u64 = TRANSITIONS_BUFFER as u64;
/// Nodes a service may have: launcher, learner, two experts during a swap, the actors, actors
/// killed but not yet cleaned up, and a few tools (benchmarks, monitors).
pub(crate) const MAX_NODES: usize = 2 * MAX_ACTORS + 16;
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
    /// A bridge between a run's iceoryx2 services and zenoh (`alfd run --listen`, `alfd join`).
    Bridge = 6,
}

impl Role {
    pub fn from_u16(v: u16) -> Option<Role> {
        Some(match v {
            1 => Role::Launcher,
            2 => Role::Learner,
            3 => Role::Expert,
            4 => Role::Actor,
            5 => Role::Tool,
            6 => Role::Bridge,
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
            Role::Bridge => "bridge",
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

// ---------------------------------------------------------------------------------------------
// Messages
// ---------------------------------------------------------------------------------------------

/// What every message starts with: the schema version, the sender, and the sender's sequence
/// number on that service (0, 1, 2, ...).
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
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
    /// The step ended in a terminal state (no bootstrapping from `next_state`).
    pub const TERMINATED: u32 = 1;
    /// The action came from the expert.
    pub const DEMO: u32 = 4;
    /// The last step of an episode (terminated or truncated): where the learner may checkpoint
    /// in step with the actors (see `alfd_common::checkpoint::Cadence`).
    pub const EPISODE_END: u32 = 8;
    /// Bits 16-23 hold the transition's horizon minus one (0 for a one-step transition; see
    /// `alfd_common::n_step`).
    pub const HORIZON_SHIFT: u32 = 16;
    /// The horizon's bits, after shifting.
    pub const HORIZON_MASK: u32 = 0xff;
}

/// The horizon a record's `flags` give (1 to 256; [`TransitionBatch::check`] refuses more than
/// `agent.n_step` allows).
fn horizon_of(bits: u32) -> u32 {
    ((bits >> flags::HORIZON_SHIFT) & flags::HORIZON_MASK) + 1
}

/// Values one step of a batch takes: `state`, `next_state` and the mask.
fn stride(obs_dim: usize, heads: usize) -> usize {
    2 * obs_dim + heads
}

/// Refuses an observation or a mask larger than a message may claim.
fn check_sizes(obs_dim: usize, heads: usize) -> Result<()> {
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
    Ok(())
}

/// The fixed part of one environment step as it travels from an actor to the learner; its
/// observations and bootstrap mask travel in [`TransitionBatch::values`].
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
#[type_name("alfd.TransitionRecord")]
pub struct TransitionRecord {
    pub action: u32,
    /// The reward learned from (shaped when shaping was on).
    pub reward: f32,
    /// See [`flags`].
    pub flags: u32,
}

/// What a [`TransitionBatch`] carries besides its values: the user header of a `transitions`
/// sample, whose payload is the batch's values.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
#[type_name("alfd.TransitionHeader")]
pub struct TransitionHeader {
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

/// Up to [`TRANSITIONS_PER_BATCH`] consecutive steps of one actor: the header as the wire
/// carries it, and the steps' observations and masks, as long as the run's (`obs_dim`, `heads`):
/// the `transitions` service carries them as a slice sized by each actor for its run.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TransitionBatch {
    pub head: TransitionHeader,
    /// Per step, one after another: `state`, `next_state` (`obs_dim` values each) and the
    /// bootstrap mask (`heads` values); [`TransitionBatch::stride`] values a step.
    pub values: Vec<f32>,
}

impl TransitionBatch {
    /// An empty batch whose first step will have sequence number `first_seq`.
    pub fn new(
        actor: u16,
        incarnation: u64,
        obs_dim: usize,
        heads: usize,
        first_seq: u64,
    ) -> Result<Self> {
        check_sizes(obs_dim, heads)?;
        Ok(Self {
            head: TransitionHeader {
                actor: u32::from(actor),
                obs_dim: obs_dim as u16,
                heads: heads as u16,
                incarnation,
                first_seq,
                ..TransitionHeader::default()
            },
            values: Vec::with_capacity(TRANSITIONS_PER_BATCH * stride(obs_dim, heads)),
        })
    }

    /// Values one step takes: two observations and a mask.
    pub fn stride(&self) -> usize {
        stride(usize::from(self.head.obs_dim), usize::from(self.head.heads))
    }

    /// A batch as received: its header and the values of its sample (the values of `len`
    /// steps and no more are kept; [`TransitionBatch::check`] refuses a batch short of them).
    pub fn from_wire(head: &TransitionHeader, values: &[f32]) -> Self {
        let used = (head.len as usize)
            .min(TRANSITIONS_PER_BATCH)
            .saturating_mul(stride(usize::from(head.obs_dim), usize::from(head.heads)));
        Self {
            head: *head,
            values: values[..used.min(values.len())].to_vec(),
        }
    }

    pub fn len(&self) -> usize {
        self.head.len as usize
    }

    pub fn is_empty(&self) -> bool {
        self.head.len == 0
    }

    pub fn is_full(&self) -> bool {
        self.len() == TRANSITIONS_PER_BATCH
    }

    /// Sequence number one past the last step of this batch (saturating: a batch received from
    /// another process may carry any `first_seq`; [`TransitionBatch::check`] refuses one whose
    /// end does not fit).
    pub fn end_seq(&self) -> u64 {
        self.head.first_seq.saturating_add(u64::from(self.head.len))
    }

    /// Checks a received batch against what its receiver expects: at most
    /// [`TRANSITIONS_PER_BATCH`] steps, the observation size `obs_dim` and `heads` heads, the
    /// values of every step, each action below `actions`, and sequence numbers that fit in a
    /// `u64`. The error names the field.
    pub fn check(&self, obs_dim: usize, heads: usize, actions: usize) -> Result<()> {
        if self.len() > TRANSITIONS_PER_BATCH {
            return Err(WireError::TooLarge {
                what: "transition batch",
                got: self.len(),
                max: TRANSITIONS_PER_BATCH,
            });
        }
        let range = |what, value: u64, expected| {
            Err(WireError::OutOfRange {
                what,
                value,
                expected,
            })
        };
        if usize::from(self.head.obs_dim) != obs_dim {
            return range(
                "transition batch obs_dim",
                u64::from(self.head.obs_dim),
                "the environment's observation size",
            );
        }
        if usize::from(self.head.heads) != heads {
            return range(
                "transition batch heads",
                u64::from(self.head.heads),
                "the config's K",
            );
        }
        if self.values.len() != self.len() * self.stride() {
            return range(
                "transition batch values",
                self.values.len() as u64,
                "len × (2 obs_dim + heads)",
            );
        }
        if self
            .head
            .first_seq
            .checked_add(u64::from(self.head.len))
            .is_none()
        {
            return range(
                "transition batch first_seq",
                self.head.first_seq,
                "first_seq + len must fit in 64 bits",
            );
        }
        let records = &self.head.records[..self.len()];
        if let Some(r) = records.iter().find(|r| r.action as usize >= actions) {
            return range(
                "transition action",
                u64::from(r.action),
                "below the environment's number of actions",
            );
        }
        if let Some(r) = records
            .iter()
            .find(|r| horizon_of(r.flags) > alfd_common::config::MAX_N_STEP)
        {
            return range(
                "transition horizon",
                u64::from(horizon_of(r.flags)),
                "at most agent.n_step's limit",
            );
        }
        Ok(())
    }

    /// Appends a step.
    pub fn push(&mut self, t: &Transition) -> Result<()> {
        if self.is_full() {
            return Err(WireError::TooLarge {
                what: "transition batch",
                got: TRANSITIONS_PER_BATCH + 1,
                max: TRANSITIONS_PER_BATCH,
            });
        }
        let d = usize::from(self.head.obs_dim);
        let h = usize::from(self.head.heads);
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
        self.values.truncate(self.len() * self.stride());
        self.values.extend_from_slice(&t.state);
        self.values.extend_from_slice(&t.next_state);
        self.values.extend_from_slice(&t.mask);
        self.head.records[self.len()] = TransitionRecord {
            action: t.action,
            reward: t.reward,
            flags: (if t.terminated { flags::TERMINATED } else { 0 })
                | (if t.demo { flags::DEMO } else { 0 })
                | (u32::from(t.horizon.max(1) - 1) << flags::HORIZON_SHIFT),
        };
        self.head.len += 1;
        Ok(())
    }

    /// Step `i` of the batch as the replay buffer stores it; `None` beyond the batch's steps
    /// (`len`, at most [`TRANSITIONS_PER_BATCH`]) or its values ([`TransitionBatch::check`]
    /// refuses a batch short of them).
    pub fn transition(&self, i: usize) -> Option<Transition> {
        if i >= self.len().min(TRANSITIONS_PER_BATCH) {
            return None;
        }
        let d = usize::from(self.head.obs_dim);
        let start = i.checked_mul(self.stride())?;
        let v = self.values.get(start..start.checked_add(self.stride())?)?;
        let r = &self.head.records[i];
        Some(Transition {
            state: v[..d].to_vec(),
            action: r.action,
            reward: r.reward,
            next_state: v[d..2 * d].to_vec(),
            terminated: r.flags & flags::TERMINATED != 0,
            mask: v[2 * d..].to_vec(),
            demo: r.flags & flags::DEMO != 0,
            horizon: horizon_of(r.flags).min(u32::from(u8::MAX)) as u8,
        })
    }

    /// Flags the last step pushed as the end of its episode.
    pub fn mark_episode_end(&mut self) {
        if let Some(i) = self.len().checked_sub(1) {
            if let Some(r) = self.head.records.get_mut(i) {
                r.flags |= flags::EPISODE_END;
            }
        }
    }

    /// Whether step `i` of the batch ended its episode.
    pub fn ends_episode(&self, i: usize) -> bool {
        self.head
            .records
            .get(i)
            .is_some_and(|r| r.flags & flags::EPISODE_END != 0)
    }

    /// The steps of the batch, in order (at most [`TRANSITIONS_PER_BATCH`], whatever `len` says).
    pub fn transitions(&self) -> impl Iterator<Item = Transition> + '_ {
        (0..self.len().min(TRANSITIONS_PER_BATCH)).filter_map(|i| self.transition(i))
    }
}

/// The learner's grants to all actors, and its global counters.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
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

    /// How many actors the learner has granted steps to (ids with an incarnation).
    pub fn actors(&self) -> usize {
        self.incarnation.iter().filter(|&&i| i != 0).count()
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
        self.env_steps
            .saturating_add(produced.saturating_sub(received))
    }
}

/// User header of the `weights` slice.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
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
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
#[type_name("alfd.DemoModelHeader")]
pub struct DemoModelHeader {
    pub header: Header,
    /// Increases with every publication of the same expert; a new expert starts above the old.
    pub version: u64,
    /// Global step of the last demonstration (shaping stops at a multiple of it).
    pub last_demo_step: u64,
    /// The run's demonstrations the model was fitted on (not the prior ones).
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

/// What a [`QueryRequest`] carries besides its state: the user header of a `query` request,
/// whose payload is the state.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
#[type_name("alfd.QueryHeader")]
pub struct QueryHeader {
    pub header: Header,
    pub actor: u32,
    pub obs_dim: u32,
    pub incarnation: u64,
    pub global_step: u64,
    pub episode: u64,
    pub last_return: f64,
    pub gave_up: u64,
}

/// An actor asks the expert for the action at `state` (as long as the run's observations).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct QueryRequest {
    pub header: Header,
    pub actor: u32,
    pub obs_dim: u32,
    pub incarnation: u64,
    /// The global step as the actor knows it.
    pub global_step: u64,
    /// The episodes the actor finished before the one asking (several experts learn from
    /// their returns).
    pub episode: u64,
    /// The return of the actor's episode before this one; NaN in its first.
    pub last_return: f64,
    /// The sequence number of this asker's previous query when it stopped waiting for it with
    /// no answer in hand; 0 when it did not. An expert that answered that query while its asker
    /// still held it counts the answer late: it was sent, kept, and never read.
    pub gave_up: u64,
    pub state: Vec<f32>,
}

impl QueryRequest {
    pub fn new(actor: u16, incarnation: u64, global_step: u64, state: &[f32]) -> Result<Self> {
        check_sizes(state.len(), 0)?;
        Ok(Self {
            actor: u32::from(actor),
            obs_dim: state.len() as u32,
            incarnation,
            global_step,
            last_return: f64::NAN,
            state: state.to_vec(),
            ..Self::default()
        })
    }

    /// The request as asked in the actor's episode `episode` (its count of finished episodes),
    /// the episode before it having returned `last_return` (none: NaN).
    pub fn in_episode(self, episode: u64, last_return: Option<f64>) -> Self {
        Self {
            episode,
            last_return: last_return.unwrap_or(f64::NAN),
            ..self
        }
    }

    /// A request that asks nothing and only says that the asker stopped waiting for its query
    /// `gave_up` (an actor's last word before it leaves); the expert answers none.
    pub fn report(actor: u16, incarnation: u64, gave_up: u64) -> Self {
        Self {
            actor: u32::from(actor),
            incarnation,
            gave_up,
            last_return: f64::NAN,
            ..Self::default()
        }
    }

    /// Whether the request only reports (see [`QueryRequest::report`]).
    pub fn is_report(&self) -> bool {
        self.obs_dim == 0
    }

    /// The asker's previous query that it stopped waiting for, if any.
    pub fn gave_up(&self) -> Option<u64> {
        (self.gave_up != 0).then_some(self.gave_up)
    }

    /// The return of the actor's episode before this one, if it told one.
    pub fn last_return(&self) -> Option<f64> {
        self.last_return.is_finite().then_some(self.last_return)
    }

    /// The request's header on the wire (all but its state).
    pub fn wire_header(&self) -> QueryHeader {
        QueryHeader {
            header: self.header,
            actor: self.actor,
            obs_dim: self.obs_dim,
            incarnation: self.incarnation,
            global_step: self.global_step,
            episode: self.episode,
            last_return: self.last_return,
            gave_up: self.gave_up,
        }
    }

    /// A request as received: its header and the values of its payload (at most `obs_dim` of
    /// them are kept; [`QueryRequest::checked_state`] refuses a request short of them).
    pub fn from_wire(h: &QueryHeader, values: &[f32]) -> Self {
        let used = (h.obs_dim as usize).min(values.len());
        Self {
            header: h.header,
            actor: h.actor,
            obs_dim: h.obs_dim,
            incarnation: h.incarnation,
            global_step: h.global_step,
            episode: h.episode,
            last_return: h.last_return,
            gave_up: h.gave_up,
            state: values[..used].to_vec(),
        }
    }

    pub fn state(&self) -> &[f32] {
        &self.state[..(self.obs_dim as usize).min(self.state.len())]
    }

    /// The state, if it has the `obs_dim` its receiver expects and only finite values.
    pub fn checked_state(&self, obs_dim: usize) -> Result<&[f32]> {
        if self.obs_dim as usize != obs_dim || self.state().len() != obs_dim {
            return Err(WireError::OutOfRange {
                what: "query obs_dim",
                value: u64::from(self.obs_dim),
                expected: "the environment's observation size",
            });
        }
        let state = self.state();
        if state.iter().any(|x| !x.is_finite()) {
            return Err(WireError::OutOfRange {
                what: "query state",
                value: obs_dim as u64,
                expected: "finite values",
            });
        }
        Ok(state)
    }
}

/// `outcome` of a [`QueryResponse`].
pub mod outcome {
    /// `action` is the expert's demonstration.
    pub const ANSWERED: u32 = 1;
    /// The budget is spent: no demonstration, act on your own.
    pub const BUDGET_EXHAUSTED: u32 = 2;
    /// The expert (a person) declined to answer: act on your own; no budget was spent.
    pub const DECLINED: u32 = 3;
}

/// The expert's answer.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
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
    /// An actor played its share of the episodes; `episodes_sent` says how many records it
    /// sent before. Sent after them on the same publisher, again every second until the run
    /// stops: the launcher learns of a last record lost on the way.
    pub const SHARE_PLAYED: u32 = 3;
}

/// `state` of a status [`Progress`] message.
pub mod process_state {
    pub const STARTING: u32 = 1;
    pub const RUNNING: u32 = 2;
    /// An expert that is up but not answering (it waits to be made active).
    pub const STANDBY: u32 = 3;
    pub const EXITING: u32 = 4;
}

/// An [`EpisodeRecord`] as a payload: the core's record, byte for byte.
#[repr(transparent)]
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Episode(pub EpisodeRecord);

// SAFETY: `EpisodeRecord` is `repr(C)` and holds only `f64`, `u64`, `u32` and `u16` fields (any bit pattern, NaN included, is a value): no
// pointers, no references, nothing owned elsewhere, valid for any bit pattern its writer put there,
// so a copy in shared memory means the same in every process of this build. `Episode` is
// `repr(transparent)` over it. The type name carries the layout's version: the schema version
// of every message (`Header`) is bumped whenever the record changes, and
// `an_episode_record_has_the_layout_the_wire_expects` pins its size and alignment.
#[allow(unsafe_code)]
unsafe impl ZeroCopySend for Episode {
    /// # Safety
    /// iceoryx2 compares this name between processes to check that they share a type: it is
    /// unique to this record's layout (see the SAFETY comment of the impl).
    unsafe fn type_name() -> &'static str {
        "alfd.EpisodeRecord"
    }
}

/// Progress and metrics, from every process to the launcher. An episode message carries the
/// core's [`EpisodeRecord`] as the actor recorded it; the sender is `header.id`.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
#[type_name("alfd.Progress")]
pub struct Progress {
    pub header: Header,
    /// See [`progress_kind`].
    pub kind: u32,
    /// See [`process_state`] (status messages).
    pub state: u32,
    pub pid: u32,
    /// Answers with a demonstration sent after their actor stopped waiting (expert, status
    /// messages): the demonstration is kept, the actor acted alone.
    pub answers_late: u32,
    pub incarnation: u64,
    /// An episode (kind EPISODE), numbered by its actor.
    pub episode: Episode,
    // --- counters (status; `env_steps` also of kind SHARE_PLAYED) ---
    /// Environment steps received (learner); the episode records this incarnation sent (an
    /// actor's SHARE_PLAYED).
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

impl Progress {
    /// An actor's finished episode.
    pub fn episode(incarnation: u64, record: EpisodeRecord) -> Self {
        Self {
            kind: progress_kind::EPISODE,
            incarnation,
            episode: Episode(record),
            ..Self::default()
        }
    }

    /// An actor's share played, after `sent` episode records.
    pub fn share_played(incarnation: u64, sent: u64) -> Self {
        Self {
            kind: progress_kind::SHARE_PLAYED,
            incarnation,
            env_steps: sent,
            ..Self::default()
        }
    }

    /// The episode records an actor's SHARE_PLAYED message says it sent.
    pub fn episodes_sent(&self) -> u64 {
        self.env_steps
    }
}

/// `command` of a [`Control`] message.
pub mod command {
    pub const RUN: u32 = 1;
    pub const SHUTDOWN: u32 = 2;
}

/// The launcher's word to every process. Published with history 1 and republished periodically,
/// so a late process gets it; it doubles as the launcher's heartbeat.
#[repr(C)]
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize,
)]
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

#[cfg(test)]
mod tests;
