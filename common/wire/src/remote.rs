//! Services to processes outside the workspace: an environment and a demonstrator served by a
//! Python adapter (`deploy/python/alfd_adapter.py`), over request/response with two plain
//! `#[repr(C)]` messages that Python's `ctypes` mirrors field for field.
//!
//! | service                      | pattern          | from → to           | payload |
//! |------------------------------|------------------|---------------------|---------|
//! | `remote/<name>`              | request/response | client → adapter    | [`RemoteRequest`] → [`RemoteResponse`] |
//! | `remote/<name>/request`      | event            | client → adapter    | (wakes the adapter) |
//! | `remote/<name>/reply`        | event            | adapter → clients   | (wakes the client)  |
//!
//! `<name>` is `env-<actor id>` for an actor's environment and `expert-<generation>` for an
//! external demonstrator. A client asks one thing at a time and waits for the answer with a
//! timeout (no adapter, or a dead one, is an error naming the service, never a hang).
//!
//! [`RemoteEnv`] is the core's [`Env`] over such a service, so agents, the environment loop and
//! the processes run on it unchanged; [`RemoteDemonstrator`] asks an external demonstrator.

use std::fmt;
use std::time::{Duration, Instant};

use alfd_common::env::{Env, EnvError, EnvState, Step};
use alfd_common::rng::RngState;
use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;

use crate::connection::{run_config, Transport};
use crate::error::{transport, Result, WireError};
use crate::messages::{Header, Process};
use crate::services::patiently;

/// Values a remote message carries: an observation (a Gymnasium environment's, one-hot for a
/// `Discrete` space) or an environment's internal state.
pub const MAX_REMOTE_VALUES: usize = 64;
/// Bytes of the error message of a [`RemoteResponse`].
pub const REMOTE_MESSAGE_LEN: usize = 128;

/// The settings every side builds the remote services with (the Python adapter uses the same
/// numbers: a service opened with other ones is refused).
pub mod remote_limits {
    pub const MAX_SERVERS: usize = 1;
    pub const MAX_CLIENTS: usize = 16;
    pub const MAX_NODES: usize = 32;
    pub const MAX_ACTIVE_REQUESTS_PER_CLIENT: usize = 2;
    pub const MAX_RESPONSE_BUFFER_SIZE: usize = 2;
    pub const MAX_LISTENERS: usize = 16;
    pub const MAX_NOTIFIERS: usize = 16;
    pub const EVENT_ID_MAX_VALUE: usize = 255;
}

/// `kind` of a [`RemoteRequest`] (echoed in the response).
pub mod remote_kind {
    /// Environment: open a session (a fresh `gymnasium.make`), with `max_episode_steps` (0: the
    /// registration's); the answer has its spaces and limit.
    pub const OPEN: u32 = 1;
    /// Environment: `reset(seed)` (`has_seed` 0: no seed; a session's first reset without one
    /// uses seed 0). The answer has the observation.
    pub const RESET: u32 = 2;
    /// Environment: `step(action)`: observation, reward, terminated, truncated.
    pub const STEP: u32 = 3;
    /// Environment: the internal physical state (`env.unwrapped.state`).
    pub const GET_STATE: u32 = 4;
    /// Environment: sets the internal physical state to `values`.
    pub const SET_STATE: u32 = 5;
    /// Environment: closes the session.
    pub const CLOSE: u32 = 6;
    /// Demonstrator: the action at observation `values`; the answer's `action`.
    pub const ACT: u32 = 7;
    /// A person's page in a process of its own: what the page shows, in `values`; the answer
    /// carries the person's oldest decision not yet delivered, if any (the expert's
    /// `human::link` module has the layout).
    pub const PAGE: u32 = 8;
}

/// `status` of a [`RemoteResponse`].
pub mod remote_status {
    pub const OK: u32 = 0;
    /// The request failed; `message` says why.
    pub const FAILED: u32 = 1;
}

/// A request to an adapter.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("alfd.RemoteRequest")]
pub struct RemoteRequest {
    pub header: Header,
    /// See [`remote_kind`].
    pub kind: u32,
    /// The environment session (from the answer to [`remote_kind::OPEN`]).
    pub session: u32,
    pub action: u32,
    /// 1 when `seed` is set.
    pub has_seed: u32,
    pub seed: u64,
    pub max_episode_steps: u64,
    /// Values used in `values`.
    pub len: u32,
    pub _pad: u32,
    pub values: [f64; MAX_REMOTE_VALUES],
}

impl Default for RemoteRequest {
    fn default() -> Self {
        Self {
            header: Header::default(),
            kind: 0,
            session: 0,
            action: 0,
            has_seed: 0,
            seed: 0,
            max_episode_steps: 0,
            len: 0,
            _pad: 0,
            values: [0.0; MAX_REMOTE_VALUES],
        }
    }
}

impl RemoteRequest {
    /// A request of `kind` for `session`.
    pub fn new(kind: u32, session: u32) -> Self {
        Self {
            kind,
            session,
            ..Self::default()
        }
    }

    /// Sets `values`; refused beyond [`MAX_REMOTE_VALUES`].
    pub fn with_values(mut self, values: &[f64]) -> Result<Self> {
        if values.len() > MAX_REMOTE_VALUES {
            return Err(WireError::TooLarge {
                what: "remote request",
                got: values.len(),
                max: MAX_REMOTE_VALUES,
            });
        }
        self.values[..values.len()].copy_from_slice(values);
        self.len = values.len() as u32;
        Ok(self)
    }
}

/// An adapter's answer.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("alfd.RemoteResponse")]
pub struct RemoteResponse {
    pub header: Header,
    /// `header.seq` of the request answered.
    pub request_seq: u64,
    pub kind: u32,
    /// See [`remote_status`].
    pub status: u32,
    pub session: u32,
    /// The action space's size (OPEN), or the demonstrator's action (ACT).
    pub action: u32,
    /// Values of an observation (OPEN).
    pub obs_dim: u32,
    pub terminated: u32,
    pub truncated: u32,
    /// Values used in `values`.
    pub len: u32,
    pub max_episode_steps: u64,
    pub reward: f64,
    /// The observation (RESET, STEP) or the internal state (GET_STATE).
    pub values: [f64; MAX_REMOTE_VALUES],
    /// UTF-8, NUL-padded: why the request failed.
    pub message: [u8; REMOTE_MESSAGE_LEN],
}

impl Default for RemoteResponse {
    fn default() -> Self {
        Self {
            header: Header::default(),
            request_seq: 0,
            kind: 0,
            status: 0,
            session: 0,
            action: 0,
            obs_dim: 0,
            terminated: 0,
            truncated: 0,
            len: 0,
            max_episode_steps: 0,
            reward: 0.0,
            values: [0.0; MAX_REMOTE_VALUES],
            message: [0; REMOTE_MESSAGE_LEN],
        }
    }
}

impl RemoteResponse {
    /// The values sent (at most [`MAX_REMOTE_VALUES`], whatever `len` says).
    pub fn values(&self) -> &[f64] {
        &self.values[..(self.len as usize).min(MAX_REMOTE_VALUES)]
    }

    /// The error message.
    pub fn message(&self) -> String {
        let end = self
            .message
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(REMOTE_MESSAGE_LEN);
        String::from_utf8_lossy(&self.message[..end]).into_owned()
    }
}

fn service_name(run_id: &str, topic: &str) -> Result<ServiceName> {
    let name = format!("alfd/{run_id}/{topic}");
    ServiceName::new(&name).map_err(transport("name service", name.clone()))
}

type RemoteRr = iceoryx2::service::port_factory::request_response::PortFactory<
    Transport,
    RemoteRequest,
    (),
    RemoteResponse,
    (),
>;
type RemoteEvent = iceoryx2::service::port_factory::event::PortFactory<Transport>;

/// The three services of `remote/<name>` opened (or created) on a node of their own, with the
/// settings both sides and the Python adapter use.
pub(crate) struct RemoteServices {
    pub(crate) rr: RemoteRr,
    /// `remote/<name>/request`: a client wakes the server.
    pub(crate) request: RemoteEvent,
    /// `remote/<name>/reply`: the server wakes its clients.
    pub(crate) reply: RemoteEvent,
    pub(crate) node: Node<Transport>,
}

impl RemoteServices {
    pub(crate) fn open(
        run_id: &str,
        name: &str,
        node_name: &str,
        signals: SignalHandlingMode,
    ) -> Result<Self> {
        use remote_limits::*;
        let cfg = run_config(run_id)?;
        let service = format!("remote/{name}");
        let node = NodeBuilder::new()
            .name(&NodeName::new(node_name).map_err(transport("name node", node_name.to_owned()))?)
            .config(&cfg)
            .signal_handling_mode(signals)
            .create::<Transport>()
            .map_err(transport("create node", node_name.to_owned()))?;
        let rr_name = service_name(run_id, &service)?;
        let rr = patiently(&rr_name, || {
            node.service_builder(&rr_name)
                .request_response::<RemoteRequest, RemoteResponse>()
                .max_servers(MAX_SERVERS)
                .max_clients(MAX_CLIENTS)
                .max_nodes(MAX_NODES)
                .max_active_requests_per_client(MAX_ACTIVE_REQUESTS_PER_CLIENT)
                .max_response_buffer_size(MAX_RESPONSE_BUFFER_SIZE)
                .enable_safe_overflow_for_requests(true)
                .enable_safe_overflow_for_responses(true)
                .open_or_create()
        })
        .map_err(transport("open", service.clone()))?;
        let event = |topic: &str| {
            let name = service_name(run_id, &format!("{service}/{topic}"))?;
            patiently(&name, || {
                node.service_builder(&name)
                    .event()
                    .max_listeners(MAX_LISTENERS)
                    .max_notifiers(MAX_NOTIFIERS)
                    .max_nodes(MAX_NODES)
                    .event_id_max_value(EVENT_ID_MAX_VALUE)
                    .open_or_create()
            })
            .map_err(transport("open", name.to_string()))
        };
        Ok(Self {
            rr,
            request: event("request")?,
            reply: event("reply")?,
            node,
        })
    }
}

/// Says why an adapter will never answer (it exited), `None` while it runs.
pub type Liveness = Box<dyn Fn() -> Option<String>>;

/// One side's connection to an adapter: its own iceoryx2 node (so that an environment can live
/// in a `Box<dyn Env>` without borrowing the process's [`Wire`](crate::Wire)), a client, and
/// the two doorbells.
pub struct RemoteClient {
    client: Client<Transport, RemoteRequest, (), RemoteResponse, ()>,
    request_bell: Notifier<Transport>,
    reply: Listener<Transport>,
    seq: u64,
    service: String,
    me: Process,
    schema: u32,
    /// Asked while waiting for an answer: why the adapter will never answer (it exited).
    gone: Option<Liveness>,
    // Dropped last: the ports above belong to it.
    _node: Node<Transport>,
}

impl fmt::Debug for RemoteClient {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "RemoteClient({}, seq {})", self.service, self.seq)
    }
}

/// Waits up to `wait` until `served` (the adapter of `service` serves); `gone` says why it never
/// will (it exited).
fn wait_for_server(
    service: &str,
    wait: Duration,
    gone: &mut dyn FnMut() -> Option<String>,
    served: impl Fn() -> bool,
) -> Result<()> {
    let deadline = Instant::now() + wait;
    while !served() {
        if let Some(why) = gone() {
            return Err(WireError::Remote {
                service: service.to_owned(),
                message: why,
            });
        }
        if Instant::now() >= deadline {
            return Err(WireError::NoAnswer {
                service: service.to_owned(),
                waited_ms: wait.as_millis() as u64,
            });
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

impl RemoteClient {
    /// Connects to adapter `name` of run `run_id` as `me`, waiting up to `wait` for it to serve;
    /// `gone` is asked while waiting and returns why the adapter will never come (it exited).
    pub fn connect(
        run_id: &str,
        name: &str,
        me: Process,
        schema: u32,
        wait: Duration,
        gone: &mut dyn FnMut() -> Option<String>,
    ) -> Result<Self> {
        let service = format!("remote/{name}");
        let ports = RemoteServices::open(
            run_id,
            name,
            &format!("{me}-{name}"),
            SignalHandlingMode::Disabled,
        )?;
        let request_bell = ports
            .request
            .notifier_builder()
            .create()
            .map_err(transport("create a notifier on", service.clone()))?;
        let reply = ports
            .reply
            .listener_builder()
            .create()
            .map_err(transport("create a listener on", service.clone()))?;
        let client = ports
            .rr
            .client_builder()
            .create()
            .map_err(transport("create a client on", service.clone()))?;
        let rr = &ports.rr;
        wait_for_server(&service, wait, gone, || {
            rr.dynamic_config().number_of_servers() > 0
        })?;
        Ok(Self {
            client,
            request_bell,
            reply,
            seq: 0,
            service,
            me,
            schema,
            gone: None,
            _node: ports.node,
        })
    }

    /// Makes a wait for an answer end as soon as `gone` says the adapter exited (instead of at
    /// the timeout).
    pub fn with_liveness(mut self, gone: Liveness) -> Self {
        self.gone = Some(gone);
        self
    }

    /// The service's name (`remote/<name>`), for messages.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Sends `request` and waits up to `timeout` for its answer. A failed request is
    /// [`WireError::Remote`] with the adapter's message.
    pub fn call(
        &mut self,
        mut request: RemoteRequest,
        timeout: Duration,
    ) -> Result<RemoteResponse> {
        let seq = self.seq;
        self.seq += 1;
        request.header = Header {
            schema: self.schema,
            role: self.me.role as u16,
            id: self.me.id,
            seq,
        };
        let pending = self
            .client
            .send_copy(request)
            .map_err(transport("send on", self.service.clone()))?;
        self.request_bell
            .notify()
            .map_err(transport("notify", self.service.clone()))?;
        let deadline = Instant::now() + timeout;
        loop {
            while let Some(r) = pending
                .receive()
                .map_err(transport("receive on", self.service.clone()))?
            {
                let resp = *r.payload();
                if resp.header.schema != self.schema {
                    return Err(WireError::SchemaMismatch {
                        service: "remote",
                        ours: self.schema,
                        theirs: resp.header.schema,
                        sender: self.service.clone(),
                    });
                }
                if resp.request_seq != seq {
                    continue;
                }
                if resp.status != remote_status::OK {
                    return Err(WireError::Remote {
                        service: self.service.clone(),
                        message: resp.message(),
                    });
                }
                return Ok(resp);
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(WireError::NoAnswer {
                    service: self.service.clone(),
                    waited_ms: timeout.as_millis() as u64,
                });
            }
            if let Some(why) = self.gone.as_ref().and_then(|g| g()) {
                return Err(WireError::Remote {
                    service: self.service.clone(),
                    message: why,
                });
            }
            // A signal cuts the wait short: the loop looks again.
            let _ = self
                .reply
                .timed_wait(|_| {}, (deadline - now).min(Duration::from_millis(100)));
        }
    }
}

/// What an adapter's environment is: its spaces and step limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RemoteSpec {
    pub obs_dim: usize,
    pub num_actions: usize,
    pub max_episode_steps: usize,
}

/// Where an episode of a [`RemoteEnv`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    NotReset,
    Running,
    Over,
}

/// How long a remote environment's requests may take: opening makes the environment (imports,
/// `gymnasium.make`), the others are a step.
const OPEN_TIMEOUT: Duration = Duration::from_secs(60);
const STEP_TIMEOUT: Duration = Duration::from_secs(30);

/// The core's [`Env`] over a remote environment session. The action space, the episode's phase
/// (no step before a reset or after the end) and the step count are checked here, so a wrong
/// call never reaches the adapter; what the adapter does is Gymnasium's.
///
/// A failure of the adapter (it died, it did not answer, it raised) in `step` is
/// [`EnvError::Remote`]; in `reset`, which cannot fail in the trait, it is kept and returned by
/// the next `step`. Checkpoints: [`Env::snapshot`] records the phase and the step count only,
/// and [`Env::restore`] is [`EnvError::Unsupported`] (the generator lives in the adapter).
pub struct RemoteEnv {
    client: RemoteClient,
    session: u32,
    spec: RemoteSpec,
    phase: Phase,
    elapsed: u64,
    broken: Option<String>,
    label: String,
}

impl fmt::Debug for RemoteEnv {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "RemoteEnv({}, session {})", self.label, self.session)
    }
}

impl RemoteEnv {
    /// Opens a session on the adapter of `client`, truncating episodes after
    /// `max_episode_steps` steps (0: the environment's own limit). `label` names the
    /// environment in messages (e.g. `gymnasium:Acrobot-v1`).
    pub fn open(mut client: RemoteClient, max_episode_steps: usize, label: &str) -> Result<Self> {
        let mut req = RemoteRequest::new(remote_kind::OPEN, 0);
        req.max_episode_steps = max_episode_steps as u64;
        let resp = client.call(req, OPEN_TIMEOUT)?;
        let spec = RemoteSpec {
            obs_dim: resp.obs_dim as usize,
            num_actions: resp.action as usize,
            max_episode_steps: resp.max_episode_steps as usize,
        };
        if spec.obs_dim == 0 || spec.obs_dim > MAX_REMOTE_VALUES {
            return Err(WireError::TooLarge {
                what: "remote environment observation",
                got: spec.obs_dim,
                max: MAX_REMOTE_VALUES,
            });
        }
        if spec.num_actions == 0 {
            return Err(WireError::OutOfRange {
                what: "remote environment actions",
                value: 0,
                expected: "at least one action",
            });
        }
        Ok(Self {
            client,
            session: resp.session,
            spec,
            phase: Phase::NotReset,
            elapsed: 0,
            broken: None,
            label: label.to_owned(),
        })
    }

    pub fn spec(&self) -> RemoteSpec {
        self.spec
    }

    fn remote(&self, e: WireError) -> EnvError {
        EnvError::Remote(format!("{}: {e}", self.label))
    }

    fn observation(&self, resp: &RemoteResponse) -> Result<Vec<f32>, EnvError> {
        let v = resp.values();
        if v.len() != self.spec.obs_dim {
            return Err(EnvError::Remote(format!(
                "{}: an observation of {} values, expected {}",
                self.label,
                v.len(),
                self.spec.obs_dim
            )));
        }
        Ok(v.iter().map(|&x| x as f32).collect())
    }

    /// The environment's internal physical state (Gymnasium's `env.unwrapped.state`), exactly.
    pub fn internal_state(&mut self) -> Result<Vec<f64>, EnvError> {
        let resp = self
            .client
            .call(
                RemoteRequest::new(remote_kind::GET_STATE, self.session),
                STEP_TIMEOUT,
            )
            .map_err(|e| self.remote(e))?;
        Ok(resp.values().to_vec())
    }

    /// Sets the internal physical state (as [`RemoteEnv::internal_state`] gives it) in a
    /// running episode; the step count and the generator are left as they are.
    pub fn set_internal_state(&mut self, state: &[f64]) -> Result<(), EnvError> {
        let req = RemoteRequest::new(remote_kind::SET_STATE, self.session)
            .with_values(state)
            .map_err(|e| self.remote(e))?;
        self.client
            .call(req, STEP_TIMEOUT)
            .map_err(|e| self.remote(e))?;
        Ok(())
    }
}

impl Drop for RemoteEnv {
    fn drop(&mut self) {
        let close = RemoteRequest::new(remote_kind::CLOSE, self.session);
        if let Err(e) = self.client.call(close, Duration::from_secs(2)) {
            tracing::debug!("closing {}: {e}", self.label);
        }
    }
}

impl Env for RemoteEnv {
    type Observation = Vec<f32>;

    fn num_actions(&self) -> usize {
        self.spec.num_actions
    }

    fn observation_dim(&self) -> usize {
        self.spec.obs_dim
    }

    fn max_episode_steps(&self) -> usize {
        self.spec.max_episode_steps
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        let mut req = RemoteRequest::new(remote_kind::RESET, self.session);
        if let Some(s) = seed {
            req.has_seed = 1;
            req.seed = s;
        }
        self.elapsed = 0;
        let obs = self
            .client
            .call(req, STEP_TIMEOUT)
            .map_err(|e| self.remote(e))
            .and_then(|resp| self.observation(&resp));
        match obs {
            Ok(obs) => {
                self.phase = Phase::Running;
                self.broken = None;
                obs
            }
            Err(e) => {
                tracing::error!("{e}");
                self.broken = Some(e.to_string());
                self.phase = Phase::Running;
                vec![0.0; self.spec.obs_dim]
            }
        }
    }

    fn step(&mut self, action: usize) -> Result<Step<Vec<f32>>, EnvError> {
        match self.phase {
            Phase::NotReset => return Err(EnvError::NotReset),
            Phase::Over => return Err(EnvError::EpisodeOver),
            Phase::Running => {}
        }
        if let Some(why) = &self.broken {
            return Err(EnvError::Remote(format!("the last reset failed: {why}")));
        }
        if action >= self.spec.num_actions {
            return Err(EnvError::InvalidAction {
                action,
                num_actions: self.spec.num_actions,
            });
        }
        let mut req = RemoteRequest::new(remote_kind::STEP, self.session);
        req.action = action as u32;
        let resp = self
            .client
            .call(req, STEP_TIMEOUT)
            .map_err(|e| self.remote(e))?;
        let observation = self.observation(&resp)?;
        self.elapsed += 1;
        let step = Step {
            observation,
            reward: resp.reward,
            terminated: resp.terminated != 0,
            truncated: resp.truncated != 0,
        };
        if step.done() {
            self.phase = Phase::Over;
        }
        Ok(step)
    }

    fn snapshot(&self) -> EnvState {
        EnvState {
            rng: RngState {
                seed: [0; 32],
                stream: 0,
                word_pos: 0,
            },
            phase: match self.phase {
                Phase::NotReset => 0,
                Phase::Running => 1,
                Phase::Over => 2,
            },
            elapsed_steps: self.elapsed,
            state: Vec::new(),
        }
    }

    fn restore(&mut self, _state: &EnvState) -> Result<(), EnvError> {
        Err(EnvError::Unsupported(format!(
            "restoring the state of the remote environment {} from a checkpoint (its generator \
             and state live in the Python adapter); start a new run instead of resuming",
            self.label
        )))
    }
}

/// A demonstrator in another process (`python:module:function`, `sb3:policy.zip`): the action
/// at an observation, or an error naming the adapter.
#[derive(Debug)]
pub struct RemoteDemonstrator {
    client: RemoteClient,
    num_actions: usize,
}

impl RemoteDemonstrator {
    pub fn new(client: RemoteClient, num_actions: usize) -> Self {
        Self {
            client,
            num_actions,
        }
    }

    /// The demonstrator's action at `obs`, waiting at most `timeout`.
    pub fn act(&mut self, obs: &[f32], timeout: Duration) -> Result<usize> {
        let values: Vec<f64> = obs.iter().map(|&x| f64::from(x)).collect();
        let req = RemoteRequest::new(remote_kind::ACT, 0).with_values(&values)?;
        let resp = self.client.call(req, timeout)?;
        let action = resp.action as usize;
        if action >= self.num_actions {
            return Err(WireError::OutOfRange {
                what: "external demonstrator's action",
                value: u64::from(resp.action),
                expected: "below the environment's number of actions",
            });
        }
        Ok(action)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_remote_messages_have_the_layout_python_mirrors() {
        // deploy/python/alfd_adapter.py declares the same fields; these sizes are its checks.
        assert_eq!(std::mem::size_of::<RemoteRequest>(), 568);
        assert_eq!(std::mem::size_of::<RemoteResponse>(), 712);
        assert_eq!(std::mem::align_of::<RemoteRequest>(), 8);
        assert_eq!(std::mem::offset_of!(RemoteRequest, values), 56);
        assert_eq!(std::mem::offset_of!(RemoteResponse, values), 72);
        assert_eq!(std::mem::offset_of!(RemoteResponse, message), 584);
        let r = RemoteRequest::new(remote_kind::STEP, 3)
            .with_values(&[1.0, 2.0])
            .unwrap();
        assert_eq!((r.len, r.values[1]), (2, 2.0));
        assert!(RemoteRequest::default()
            .with_values(&[0.0; MAX_REMOTE_VALUES + 1])
            .is_err());
        let mut resp = RemoteResponse {
            len: u32::MAX,
            ..RemoteResponse::default()
        };
        assert_eq!(resp.values().len(), MAX_REMOTE_VALUES);
        resp.message[..5].copy_from_slice(b"boom!");
        assert_eq!(resp.message(), "boom!");
    }

    mod fuzz {
        use super::super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            /// A response as an adapter may have filled it: any length, any message bytes.
            #[test]
            fn fuzz_remote_response(
                len in any::<u32>(),
                values in any::<[f64; MAX_REMOTE_VALUES]>(),
                message in proptest::collection::vec(any::<u8>(), REMOTE_MESSAGE_LEN),
            ) {
                let mut r = RemoteResponse { len, values, ..RemoteResponse::default() };
                r.message.copy_from_slice(&message);
                prop_assert!(r.values().len() <= MAX_REMOTE_VALUES);
                prop_assert_eq!(r.values().len(), (len as usize).min(MAX_REMOTE_VALUES));
                prop_assert!(!r.message().contains('\0'));
            }
        }
    }
}
