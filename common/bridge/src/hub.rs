//! The learner's host side of a run across hosts (`alfd run --listen`): the hub. It answers
//! joins (the [`Roster`] decides the actor ids), notices remote hosts leaving (their zenoh
//! liveliness token goes: a closed link or a dead process), and forwards the run's services:
//! what remote actors send (transitions, progress, queries) goes into this host's iceoryx2
//! services under the actors' own headers; what they need (credits, weights, the demonstration
//! model, control, answers) goes out over zenoh as it is published here.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use alfd_wire::{
    DemoModelHeader, Doorbell, IncomingQuery, PendingQuery, Process, QueryClient, Role, Sender,
    TransitionBatch, Wake, Wire, WireError, MAX_ACTORS, SCHEMA_VERSION,
};
use tracing::{debug, info, warn};
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;
use zenoh::Wait as _;

use crate::endpoint::Endpoint;
use crate::error::{zenoh_error, BridgeError, Result};
use crate::frame::{self, ExpertOrder, Frame};
use crate::inbox::{inbox, Mail, Post};
use crate::roster::{JoinReply, JoinRequest, Joined, RestartReply, RestartRequest, Roster};
use crate::worker;
use crate::{keys, TICK};

/// What the hub needs to know of the run.
#[derive(Debug, Clone)]
pub struct HubOptions {
    pub endpoint: Endpoint,
    pub run_id: String,
    /// Actors the launcher starts itself (ids below this are never given to remote hosts).
    pub local_actors: usize,
    pub first_incarnation: u64,
    /// Restarts allowed per remote actor (`alfd run --max-restarts`).
    pub max_restarts: u32,
    pub config_toml: String,
    pub runtime_toml: String,
    /// A remote query not answered within this long is dropped (the actor gave up already).
    pub query_timeout: Duration,
    /// `RUN_DIR/demos.jsonl`: a remote expert's demonstrations are written here before they
    /// are answered.
    pub demos_path: PathBuf,
}

/// What the launcher hears from the hub.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HubEvent {
    Joined {
        join_id: String,
        host: String,
        actors: Vec<(u16, u64)>,
        /// The demonstrator it offers to serve as the run's expert.
        expert: Option<String>,
    },
    /// A remote host left or its link dropped: its actors (and its expert) are gone, as if
    /// they had crashed.
    Left {
        join_id: String,
        actors: Vec<u16>,
        expert: bool,
    },
    /// A remote actor crashed and its host restarts it as `incarnation`.
    Restarted {
        join_id: String,
        actor: u16,
        incarnation: u64,
    },
    /// A remote expert process ended; every answer it sent before was taken in.
    ExpertExited {
        generation: u16,
        how: String,
        code: Option<i32>,
    },
}

/// A running hub; stop it with [`Hub::stop`] (or drop it).
pub struct Hub {
    roster: Arc<Mutex<Roster>>,
    events: mpsc::Receiver<HubEvent>,
    stop: Arc<AtomicBool>,
    post: Post,
    thread: Option<JoinHandle<Result<()>>>,
    _queryable: zenoh::query::Queryable<()>,
    _restarts: zenoh::query::Queryable<()>,
    _members: zenoh::pubsub::Subscriber<()>,
    _token: zenoh::liveliness::LivelinessToken,
    session: zenoh::Session,
}

impl std::fmt::Debug for Hub {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Hub")
    }
}

impl Hub {
    /// Listens on the endpoint and starts forwarding. The run's iceoryx2 services must exist
    /// (the launcher started its learner).
    pub fn start(opts: HubOptions) -> Result<Self> {
        let session = zenoh::open(opts.endpoint.listen_config()?)
            .wait()
            .map_err(|e| BridgeError::Zenoh(format!("cannot listen on {}: {e}", opts.endpoint)))?;
        let roster = Arc::new(Mutex::new(Roster::new(
            opts.local_actors,
            opts.first_incarnation,
            opts.max_restarts,
        )));
        let (events_tx, events) = mpsc::channel();
        let (post, inbox) = inbox(&opts.run_id, 1);
        let stop = Arc::new(AtomicBool::new(false));

        // Joins: a query on `alfd/<run>/join`.
        let queryable = {
            let roster = Arc::clone(&roster);
            let events_tx = events_tx.clone();
            let run_id = opts.run_id.clone();
            let config_toml = opts.config_toml.clone();
            let runtime_toml = opts.runtime_toml.clone();
            session
                .declare_queryable(keys::join(&opts.run_id))
                .callback(move |query| {
                    let reply = answer_join(
                        query.payload().map(|p| p.to_bytes().into_owned()),
                        &roster,
                        &run_id,
                        &config_toml,
                        &runtime_toml,
                    );
                    if let (JoinReply::Joined(j), Some(r)) = (&reply, &request_of(&query)) {
                        let _ = events_tx.send(HubEvent::Joined {
                            join_id: r.join_id.clone(),
                            host: r.host.clone(),
                            actors: j.actors.clone(),
                            expert: r.expert.clone(),
                        });
                    }
                    match frame::encode(SCHEMA_VERSION, &reply) {
                        Ok(bytes) => {
                            let _ = query.reply(query.key_expr().clone(), bytes).wait();
                        }
                        Err(e) => warn!("cannot answer a join: {e}"),
                    }
                })
                .wait()
                .map_err(zenoh_error)?
        };

        // Restarts: a remote host's actor crashed, and the host asks for a new incarnation.
        let restarts = {
            let roster = Arc::clone(&roster);
            let events_tx = events_tx.clone();
            session
                .declare_queryable(keys::restart(&opts.run_id))
                .callback(move |query| {
                    let request = query
                        .payload()
                        .map(|p| frame::decode::<RestartRequest>(SCHEMA_VERSION, &p.to_bytes()));
                    let reply = match request {
                        Some(Ok(r)) => match roster.lock().expect("roster").restart(&r.join_id, r.actor) {
                            Ok(incarnation) => {
                                let _ = events_tx.send(HubEvent::Restarted {
                                    join_id: r.join_id,
                                    actor: r.actor,
                                    incarnation,
                                });
                                RestartReply::Restart(incarnation)
                            }
                            Err(why) => {
                                warn!(join_id = %r.join_id, actor = r.actor, "restart refused: {why}");
                                RestartReply::Refused(why)
                            }
                        },
                        Some(Err(e)) => RestartReply::Refused(e.to_string()),
                        None => RestartReply::Refused("a restart without a request".to_owned()),
                    };
                    match frame::encode(SCHEMA_VERSION, &reply) {
                        Ok(bytes) => {
                            let _ = query.reply(query.key_expr().clone(), bytes).wait();
                        }
                        Err(e) => warn!("cannot answer a restart: {e}"),
                    }
                })
                .wait()
                .map_err(zenoh_error)?
        };

        // Members: each joined host holds a liveliness token; when it goes, so do its actors.
        let members = {
            let roster = Arc::clone(&roster);
            let post = post.clone();
            let events_tx = events_tx.clone();
            let prefix = keys::member(&opts.run_id, "");
            session
                .liveliness()
                .declare_subscriber(keys::member(&opts.run_id, "*"))
                .callback(move |sample| {
                    let key = sample.key_expr().as_str();
                    let join_id = key.strip_prefix(&prefix).unwrap_or(key).to_owned();
                    match sample.kind() {
                        SampleKind::Put => {
                            debug!(%join_id, "remote host up");
                            post.send(Mail::Joined);
                        }
                        SampleKind::Delete => {
                            post.send(Mail::Left(join_id.clone()));
                            let left = roster.lock().expect("roster").leave(&join_id);
                            if !left.actors.is_empty() || left.expert {
                                let _ = events_tx.send(HubEvent::Left {
                                    join_id,
                                    actors: left.actors,
                                    expert: left.expert,
                                });
                            }
                        }
                    }
                })
                .wait()
                .map_err(zenoh_error)?
        };
        let token = session
            .liveliness()
            .declare_token(keys::hub(&opts.run_id))
            .wait()
            .map_err(zenoh_error)?;

        // What remote hosts send.
        {
            let post = post.clone();
            session
                .declare_subscriber(keys::up(&opts.run_id))
                .callback(move |sample| {
                    post.send(Mail::Frame(sample.payload().to_bytes().into_owned()))
                })
                .background()
                .wait()
                .map_err(zenoh_error)?;
        }
        let down = session
            .declare_publisher(keys::down(&opts.run_id))
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(zenoh_error)?;

        let thread = {
            let stop = Arc::clone(&stop);
            let opts = opts.clone();
            let events_tx = events_tx.clone();
            std::thread::Builder::new()
                .name("hub".to_owned())
                .spawn(move || {
                    let r = forward(&opts, &inbox, &down, &stop, &events_tx);
                    if let Err(e) = &r {
                        warn!("the hub stopped: {e}");
                    }
                    r
                })
                .expect("a thread starts")
        };
        info!(endpoint = %opts.endpoint, "listening for remote hosts");
        Ok(Self {
            roster,
            events,
            stop,
            post,
            thread: Some(thread),
            _queryable: queryable,
            _restarts: restarts,
            _members: members,
            _token: token,
            session,
        })
    }

    /// Joins and departures since the last call.
    pub fn events(&self) -> Vec<HubEvent> {
        self.events.try_iter().collect()
    }

    /// Sends `order` to the remote hosts (again to each host that joins later, so an order
    /// given before the host's mirror listened still reaches it).
    pub fn order(&self, order: ExpertOrder) {
        self.post.send(Mail::Order(order));
    }

    /// Actor ids held by remote hosts now.
    pub fn remote_actors(&self) -> usize {
        self.roster.lock().expect("roster").remote()
    }

    /// Stops forwarding and closes the zenoh session.
    pub fn stop(mut self) -> Result<()> {
        self.halt()
    }

    fn halt(&mut self) -> Result<()> {
        self.stop.store(true, Ordering::Relaxed);
        let r = worker::join(&mut self.thread, "hub");
        let _ = self.session.close().wait();
        r
    }
}

impl Drop for Hub {
    fn drop(&mut self) {
        let _ = self.halt();
    }
}

fn request_of(query: &zenoh::query::Query) -> Option<JoinRequest> {
    let bytes = query.payload()?.to_bytes();
    frame::decode(SCHEMA_VERSION, &bytes).ok()
}

fn answer_join(
    payload: Option<Vec<u8>>,
    roster: &Mutex<Roster>,
    run_id: &str,
    config_toml: &str,
    runtime_toml: &str,
) -> JoinReply {
    let Some(bytes) = payload else {
        return JoinReply::Refused("a join without a request".to_owned());
    };
    let request: JoinRequest = match frame::decode(SCHEMA_VERSION, &bytes) {
        Ok(r) => r,
        Err(e) => return JoinReply::Refused(e.to_string()),
    };
    match roster.lock().expect("roster").join(&request) {
        Ok(actors) => {
            info!(host = %request.host, join_id = %request.join_id, ?actors, "remote actors joined");
            JoinReply::Joined(Joined {
                run_id: run_id.to_owned(),
                actors,
                config_toml: config_toml.to_owned(),
                runtime_toml: runtime_toml.to_owned(),
            })
        }
        Err(why) => {
            warn!(host = %request.host, "join refused: {why}");
            JoinReply::Refused(why)
        }
    }
}

/// The newest frame of each down service, sent again to a host that joins.
#[derive(Default)]
struct Newest {
    credits: Option<Vec<u8>>,
    weights: Option<Vec<u8>>,
    model: Option<Vec<u8>>,
    control: Option<Vec<u8>>,
    /// Orders to remote experts, in the order given.
    orders: Vec<Vec<u8>>,
}

/// The hub's thread: blocks on its doorbells (its own, rung when zenoh delivered something, and
/// every actor's, rung by the learner and the expert) and moves messages both ways.
fn forward(
    opts: &HubOptions,
    inbox: &crate::inbox::Inbox,
    down: &zenoh::pubsub::Publisher<'static>,
    stop: &AtomicBool,
    events: &mpsc::Sender<HubEvent>,
) -> Result<()> {
    let wire = Wire::connect(&opts.run_id, Process::new(Role::Bridge, 0), SCHEMA_VERSION)?;
    let mut bells = vec![Doorbell::Bridge];
    bells.extend((0..MAX_ACTORS as u16).map(Doorbell::Actor));
    let waiter = wire.waiter_on(&bells)?;
    let credits = wire.credits_receiver()?;
    let weights = wire.weights_receiver()?;
    let model = wire.demo_model_receiver()?;
    let control = wire.control_receiver()?;
    let mut progress = wire.progress_sender()?;
    let learner = wire.bell(Doorbell::Learner)?;
    let expert = wire.bell(Doorbell::Expert)?;
    let launcher = wire.bell(Doorbell::Launcher)?;
    // One publisher per remote actor, as each actor has its own on one host (the learner's
    // buffer is per publisher).
    let mut transitions: HashMap<u32, Sender<'_, TransitionBatch>> = HashMap::new();
    let mut clients: HashMap<u32, QueryClient<'_>> = HashMap::new();
    let mut pending: HashMap<u32, (PendingQuery<'_>, u64, Instant)> = HashMap::new();
    // A remote expert's side on this host: the hub serves the queries while it is active, and
    // publishes its model here.
    let server = wire.query_server()?;
    let mut held: HashMap<u32, IncomingQuery<'_>> = HashMap::new();
    let mut remote_model = None;
    // Generation → the host serving it; a generation whose host left writes nothing more.
    let mut remote_experts: HashMap<u16, String> = HashMap::new();
    // Lines of the run's demos.jsonl while a remote expert is active, and its newest model
    // while that model counts demonstrations not yet written here (its answers are on their
    // way): published here only once they are on disk.
    let mut written = 0usize;
    let mut early_model: Option<(DemoModelHeader, Vec<u8>)> = None;
    let mut active = 0u32;
    let mut actor_bells = alfd_wire::ActorBells::new(&wire);
    let mut newest = Newest::default();
    let mut params = Vec::new();
    let mut bytes = Vec::new();
    let mut refused = 0u64;
    let put = |b: &[u8]| down.put(b.to_vec()).wait().map_err(zenoh_error);

    while !stop.load(Ordering::Relaxed) {
        if waiter.wait(TICK)? == Wake::Signal {
            // The launcher handles the signal; this thread goes on until told to stop.
            std::thread::sleep(TICK);
        }
        // Up: from remote hosts into this host's services.
        while let Ok(mail) = inbox.mail.try_recv() {
            let b = match mail {
                Mail::Joined => {
                    for f in [
                        &newest.control,
                        &newest.credits,
                        &newest.weights,
                        &newest.model,
                    ]
                    .into_iter()
                    .flatten()
                    .chain(&newest.orders)
                    {
                        put(f)?;
                    }
                    continue;
                }
                Mail::Order(order) => {
                    if let ExpertOrder::Start {
                        generation,
                        join_id,
                        ..
                    } = &order
                    {
                        remote_experts.insert(*generation, join_id.clone());
                    }
                    let f = frame::encode(SCHEMA_VERSION, &Frame::Order(order))?;
                    put(&f)?;
                    newest.orders.push(f);
                    continue;
                }
                Mail::Left(join_id) => {
                    remote_experts.retain(|generation, j| {
                        let gone = *j == join_id;
                        if gone {
                            info!(generation, %join_id, "the remote expert's host left");
                        }
                        !gone
                    });
                    continue;
                }
                Mail::Exited { .. } => continue,
                Mail::Frame(b) => b,
            };
            let f = match frame::decode::<Frame>(SCHEMA_VERSION, &b) {
                Ok(f) => f,
                Err(e) => {
                    refused += 1;
                    if refused.is_power_of_two() {
                        warn!(refused, "frame from a remote host dropped: {e}");
                    }
                    continue;
                }
            };
            let sent = match f {
                Frame::Transitions(batch) => {
                    let tx = match transitions.entry(batch.actor) {
                        std::collections::hash_map::Entry::Occupied(o) => o.into_mut(),
                        std::collections::hash_map::Entry::Vacant(v) => {
                            v.insert(wire.transitions_sender()?)
                        }
                    };
                    tx.forward(batch).map(|_| learner.ring())
                }
                Frame::Progress(p) => progress.forward(p).map(|_| launcher.ring()),
                Frame::Query(q) => {
                    let client = match clients.entry(q.actor) {
                        std::collections::hash_map::Entry::Occupied(o) => o.into_mut(),
                        std::collections::hash_map::Entry::Vacant(v) => {
                            v.insert(wire.query_client()?)
                        }
                    };
                    let ask = client.ask(q)?;
                    // A newer query of the same actor replaces the older one (it gave up).
                    pending.insert(q.actor, (ask, q.header.seq, Instant::now()));
                    Ok(expert.ring())
                }
                Frame::DemoModel(h, b) if remote_experts.contains_key(&(h.expert as u16)) => {
                    if h.demos as usize > written {
                        // It counts an answer still on its way: published once that is written.
                        early_model = Some((h, b));
                        continue;
                    }
                    let tx = match &mut remote_model {
                        Some(tx) => tx,
                        None => remote_model.insert(wire.demo_model_sender()?),
                    };
                    tx.forward(h, &b).map(|_| Ok(0))
                }
                Frame::ExpertAnswer(r, _) if !remote_experts.contains_key(&(r.expert as u16)) => {
                    warn!(
                        generation = r.expert,
                        index = r.demo_index,
                        "an answer of a remote expert whose host left; not written, not answered"
                    );
                    continue;
                }
                Frame::ExpertAnswer(r, demo) => {
                    // On disk here before any actor sees it: no link loss can lose it.
                    if let Some(line) = demo {
                        if let Err(e) = crate::demos::append(&opts.demos_path, r.demo_index, &line)
                        {
                            warn!("a remote expert's demonstration refused: {e}; not answered");
                            continue;
                        }
                        written = r.demo_index as usize + 1;
                        // Its model, which counts it, before its answer (as on one host).
                        if let Some((h, b)) =
                            early_model.take_if(|(h, _)| h.demos as usize <= written)
                        {
                            let tx = match &mut remote_model {
                                Some(tx) => tx,
                                None => remote_model.insert(wire.demo_model_sender()?),
                            };
                            if let Err(e) = tx.forward(h, &b) {
                                warn!("{e}; a remote expert's model dropped");
                            }
                        }
                    }
                    let Some(q) = held.remove(&r.actor) else {
                        continue;
                    };
                    if q.request().header.seq != r.request_seq {
                        held.insert(r.actor, q);
                        continue;
                    }
                    let actor = r.actor;
                    q.answer(r).map(|_| {
                        u16::try_from(actor).map_or(Ok(0), |id| actor_bells.ring(id).map(|()| 0))
                    })
                }
                Frame::ExpertExited {
                    generation,
                    how,
                    code,
                } => {
                    remote_experts.remove(&generation);
                    early_model = None;
                    let _ = events.send(HubEvent::ExpertExited {
                        generation,
                        how,
                        code,
                    });
                    launcher.ring().map(Ok)
                }
                other => {
                    debug!(service = other.service(), "a down frame came up; dropped");
                    continue;
                }
            };
            match sent {
                Ok(rang) => {
                    rang?;
                }
                Err(e @ WireError::SchemaMismatch { .. }) => warn!("{e}; dropped"),
                Err(e) => return Err(e.into()),
            }
        }
        // Queries to a remote expert: held here while it is active, the others let go (this
        // host's expert answers them).
        loop {
            match server.receive() {
                Ok(Some(q)) if remote_experts.contains_key(&(active as u16)) => {
                    put(&frame::encode(SCHEMA_VERSION, &Frame::Query(*q.request()))?)?;
                    held.insert(q.request().actor, q);
                }
                Ok(Some(_)) => {}
                Ok(None) => break,
                Err(e @ WireError::SchemaMismatch { .. }) => warn!("{e}; dropped"),
                Err(e) => return Err(e.into()),
            }
        }
        held.retain(|_, q| q.is_connected());
        // Down: what this host publishes, to every remote host.
        if let Some(c) = credits.latest()? {
            let f = frame::encode(SCHEMA_VERSION, &Frame::Credits(c))?;
            put(&f)?;
            newest.credits = Some(f);
        }
        if let Some(h) = weights.latest_into(&mut params)? {
            let f = frame::encode(SCHEMA_VERSION, &Frame::Weights(h, params.clone()))?;
            put(&f)?;
            newest.weights = Some(f);
        }
        if let Some(h) = model.latest_into(&mut bytes)? {
            let f = frame::encode(SCHEMA_VERSION, &Frame::DemoModel(h, bytes.clone()))?;
            put(&f)?;
            newest.model = Some(f);
        }
        if let Some(c) = control.latest()? {
            if c.active_expert != active {
                active = c.active_expert;
                let generation = active as u16;
                if remote_experts.contains_key(&generation) {
                    // Every expert before it has exited and all its answers are written: the
                    // remote expert reads this back when it becomes active.
                    let text = crate::demos::read(&opts.demos_path)?;
                    written = text.lines().count();
                    early_model = None;
                    info!(
                        generation,
                        bytes = text.len(),
                        "demos.jsonl to the remote expert"
                    );
                    put(&frame::encode(
                        SCHEMA_VERSION,
                        &Frame::DemoLog { generation, text },
                    )?)?;
                }
            }
            let f = frame::encode(SCHEMA_VERSION, &Frame::Control(c))?;
            put(&f)?;
            newest.control = Some(f);
        }
        if let Some(tx) = &remote_model {
            tx.update_connections()?;
        }
        let mut answered = Vec::new();
        for (actor, (p, seq, asked)) in pending.iter_mut() {
            match p.poll() {
                Ok(Some(mut r)) => {
                    r.request_seq = *seq;
                    r.actor = *actor;
                    put(&frame::encode(SCHEMA_VERSION, &Frame::Answer(r))?)?;
                    answered.push(*actor);
                }
                Ok(None) if asked.elapsed() > opts.query_timeout => answered.push(*actor),
                Ok(None) => {}
                Err(e) => {
                    warn!("{e}; answer dropped");
                    answered.push(*actor);
                }
            }
        }
        for a in answered {
            pending.remove(&a);
        }
    }
    Ok(())
}
