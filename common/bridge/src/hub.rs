//! The learner's host side of a run across hosts (`alfd run --listen`): the hub. It answers
//! joins (the [`Roster`] decides the actor ids), notices remote hosts leaving (their zenoh
//! liveliness token goes: a closed link or a dead process), and forwards the run's services:
//! what remote actors send (transitions, progress, queries) goes into this host's iceoryx2
//! services under the actors' own headers; what they need (credits, weights, the demonstration
//! model, control, answers) goes out over zenoh as it is published here.

use std::collections::hash_map::Entry;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use alfd_wire::{
    outcome, DemoModelHeader, Doorbell, IncomingQuery, PendingQuery, Process, QueryClient,
    QueryResponse, Role, Sender, TransitionSender, Wake, Wire, WireError, MAX_ACTORS,
    SCHEMA_VERSION,
};
use tracing::{debug, info, warn};
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;
use zenoh::Wait as _;

use crate::desk::{Answer, ExpertDesk, Intake};
use crate::endpoint::Endpoint;
use crate::error::{zenoh_error, BridgeError, Result};
use crate::frame::{self, ExpertOrder, Frame};
use crate::inbox::{inbox, Mail, Post};
use crate::link::{self, drain};
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

/// What the hub counts of the run's demonstrations, read by the launcher for its summary.
#[derive(Debug, Default)]
struct Counters {
    /// Lines of remote experts the run's `demos.jsonl` did not take.
    demos_refused: AtomicU64,
    /// Answers with a demonstration that came after their query stopped waiting.
    answers_late: AtomicU64,
}

/// A running hub; stop it with [`Hub::stop`] (or drop it).
pub struct Hub {
    roster: Arc<Mutex<Roster>>,
    counters: Arc<Counters>,
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
        let counters = Arc::new(Counters::default());
        let (post, inbox) = inbox(&opts.run_id, 1);
        let stop = Arc::new(AtomicBool::new(false));

        let queryable = joins(&session, &opts, &roster, &events_tx)?;
        let restarts = restarts(&session, &opts.run_id, &roster, &events_tx)?;
        let members = members(&session, &opts.run_id, &post)?;
        let token = session
            .liveliness()
            .declare_token(keys::hub(&opts.run_id))
            .wait()
            .map_err(zenoh_error)?;

        // What remote hosts send.
        {
            let post = post.clone();
            session
                .declare_subscriber(keys::up_all(&opts.run_id))
                .callback(move |sample| {
                    if let Some(from) = keys::up_sender(sample.key_expr().as_str()) {
                        post.send(Mail::Up {
                            from: from.to_owned(),
                            bytes: sample.payload().to_bytes().into_owned(),
                        })
                    }
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
            let held = Arc::clone(&roster);
            let counters = Arc::clone(&counters);
            std::thread::Builder::new()
                .name("hub".to_owned())
                .spawn(move || {
                    let r = forward(&opts, &inbox, &down, &stop, &events_tx, (held, counters));
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
            counters,
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

    /// Lines remote experts wrote that the run's `demos.jsonl` did not take (refused, or lost
    /// with a host that stopped before they went up).
    pub fn demos_refused(&self) -> u64 {
        self.counters.demos_refused.load(Ordering::Relaxed)
    }

    /// Answers with a demonstration that came to the hub after their query stopped waiting
    /// (the demonstration is kept; the actor acted alone).
    pub fn answers_late(&self) -> u64 {
        self.counters.answers_late.load(Ordering::Relaxed)
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

/// Joins: a query on `alfd/<run>/join`, answered by the roster.
fn joins(
    session: &zenoh::Session,
    opts: &HubOptions,
    roster: &Arc<Mutex<Roster>>,
    events_tx: &mpsc::Sender<HubEvent>,
) -> Result<zenoh::query::Queryable<()>> {
    let roster = Arc::clone(roster);
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
        .map_err(zenoh_error)
}

/// Restarts: a remote host's actor crashed, and the host asks for a new incarnation.
fn restarts(
    session: &zenoh::Session,
    run_id: &str,
    roster: &Arc<Mutex<Roster>>,
    events_tx: &mpsc::Sender<HubEvent>,
) -> Result<zenoh::query::Queryable<()>> {
    let roster = Arc::clone(roster);
    let events_tx = events_tx.clone();
    session
        .declare_queryable(keys::restart(run_id))
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
        .map_err(zenoh_error)
}

/// Members: each joined host holds a liveliness token; when it goes, so do its actors. Its
/// going is posted to the hub's thread, in order with the host's last frames: the roster and the
/// launcher learn it only there, after every frame the host sent before it is handled (a
/// remote expert counted gone while its last demonstrations wait in the inbox would let a new
/// expert write at their indices).
fn members(
    session: &zenoh::Session,
    run_id: &str,
    post: &Post,
) -> Result<zenoh::pubsub::Subscriber<()>> {
    let post = post.clone();
    let prefix = keys::member(run_id, "");
    session
        .liveliness()
        .declare_subscriber(keys::member(run_id, "*"))
        .callback(move |sample| {
            let key = sample.key_expr().as_str();
            let join_id = key.strip_prefix(&prefix).unwrap_or(key).to_owned();
            match sample.kind() {
                SampleKind::Put => {
                    debug!(%join_id, "remote host up");
                    post.send(Mail::Joined);
                }
                SampleKind::Delete => post.send(Mail::Left(join_id)),
            }
        })
        .wait()
        .map_err(zenoh_error)
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
    (roster, counters): (Arc<Mutex<Roster>>, Arc<Counters>),
) -> Result<()> {
    let wire = Wire::connect(&opts.run_id, Process::new(Role::Bridge, 0), SCHEMA_VERSION)?;
    let mut bells = vec![Doorbell::Bridge];
    bells.extend((0..MAX_ACTORS as u16).map(Doorbell::Actor));
    let waiter = wire.waiter_on(&bells)?;
    let mut hub = Forwarder::new(&wire, opts, down, events, (roster, counters))?;
    while !stop.load(Ordering::Relaxed) {
        if waiter.wait(TICK)? == Wake::Signal {
            // The launcher handles the signal; this thread goes on until told to stop.
            std::thread::sleep(TICK);
        }
        while let Ok(mail) = inbox.mail.try_recv() {
            hub.mail(mail)?;
        }
        hub.queries_for_remote_expert()?;
        hub.down()?;
        hub.poll_answers()?;
    }
    Ok(())
}

/// The hub thread's ports and state: this host's services on one side, zenoh's `down`
/// publisher on the other, and the remote expert's [`ExpertDesk`].
struct Forwarder<'w, 'a> {
    wire: &'w Wire,
    opts: &'a HubOptions,
    down: &'a zenoh::pubsub::Publisher<'static>,
    events: &'a mpsc::Sender<HubEvent>,
    credits: alfd_wire::Receiver<'w, alfd_wire::Credits>,
    weights: alfd_wire::WeightsReceiver<'w>,
    model: alfd_wire::DemoModelReceiver<'w>,
    control: alfd_wire::Receiver<'w, alfd_wire::Control>,
    progress: Sender<'w, alfd_wire::Progress>,
    learner: alfd_wire::Bell,
    expert: alfd_wire::Bell,
    launcher: alfd_wire::Bell,
    /// One publisher per remote actor, as each actor has its own on one host (the learner's
    /// buffer is per publisher).
    transitions: HashMap<u32, TransitionSender<'w>>,
    clients: HashMap<u32, QueryClient<'w>>,
    /// Remote actors' queries to this host's expert: the pending answer, the query's sequence
    /// number, when it was asked.
    pending: HashMap<u32, (PendingQuery<'w>, u64, Instant)>,
    /// A remote expert's side on this host: the hub serves the queries while it is active, and
    /// publishes its model here.
    server: alfd_wire::QueryServer<'w>,
    desk: ExpertDesk<IncomingQuery<'w>>,
    remote_model: Option<alfd_wire::DemoModelSender<'w>>,
    actor_bells: alfd_wire::ActorBells<'w>,
    newest: Newest,
    params: Vec<f32>,
    bytes: Vec<u8>,
    refused: u64,
    /// Which actor ids remote hosts hold (a frame speaking for another is refused).
    roster: Arc<Mutex<Roster>>,
    /// Frames refused for what they said (see [`refusal`]).
    impostors: u64,
    /// Answers of this host's expert to a remote actor's query that the actor replaced.
    late: u64,
    counters: Arc<Counters>,
}

impl<'w, 'a> Forwarder<'w, 'a> {
    fn new(
        wire: &'w Wire,
        opts: &'a HubOptions,
        down: &'a zenoh::pubsub::Publisher<'static>,
        events: &'a mpsc::Sender<HubEvent>,
        (roster, counters): (Arc<Mutex<Roster>>, Arc<Counters>),
    ) -> Result<Self> {
        Ok(Self {
            roster,
            impostors: 0,
            late: 0,
            counters,
            wire,
            opts,
            down,
            events,
            credits: wire.credits_receiver()?,
            weights: wire.weights_receiver()?,
            model: wire.demo_model_receiver()?,
            control: wire.control_receiver()?,
            progress: wire.progress_sender()?,
            learner: wire.bell(Doorbell::Learner)?,
            expert: wire.bell(Doorbell::Expert)?,
            launcher: wire.bell(Doorbell::Launcher)?,
            transitions: HashMap::new(),
            clients: HashMap::new(),
            pending: HashMap::new(),
            server: wire.query_server()?,
            desk: ExpertDesk::default(),
            remote_model: None,
            actor_bells: alfd_wire::ActorBells::new(wire),
            newest: Newest::default(),
            params: Vec::new(),
            bytes: Vec::new(),
            refused: 0,
        })
    }

    /// Sends `f` down; returns its bytes (kept as the newest of its service).
    fn put_frame(&self, f: &Frame) -> Result<Vec<u8>> {
        let b = frame::encode(SCHEMA_VERSION, f)?;
        link::put_bytes(self.down, b.clone())?;
        Ok(b)
    }

    /// Publishes the counts the launcher reads.
    fn count(&self) {
        let c = &self.counters;
        c.demos_refused
            .store(self.desk.refused(), Ordering::Relaxed);
        c.answers_late
            .store(self.desk.late() + self.late, Ordering::Relaxed);
    }

    /// Up: what zenoh delivered, into this host's services.
    fn mail(&mut self, mail: Mail) -> Result<()> {
        match mail {
            Mail::Joined => {
                let n = &self.newest;
                for f in [&n.control, &n.credits, &n.weights, &n.model]
                    .into_iter()
                    .flatten()
                    .chain(&n.orders)
                {
                    link::put_bytes(self.down, f.clone())?;
                }
            }
            Mail::Order(order) => {
                if let ExpertOrder::Start {
                    generation,
                    join_id,
                    ..
                } = &order
                {
                    self.desk.started(*generation, join_id);
                }
                let f = self.put_frame(&Frame::Order(order))?;
                self.newest.orders.push(f);
            }
            Mail::Left(join_id) => {
                // In the inbox's order: every frame the host sent before it left is handled, so
                // its expert's last lines are in demos.jsonl before the launcher counts it gone.
                for generation in self.desk.host_left(&join_id) {
                    info!(generation, %join_id, "the remote expert's host left");
                }
                let left = self.roster.lock().expect("roster").leave(&join_id);
                if !left.actors.is_empty() || left.expert {
                    let _ = self.events.send(HubEvent::Left {
                        join_id,
                        actors: left.actors,
                        expert: left.expert,
                    });
                }
            }
            Mail::Exited { .. } => {}
            Mail::Up { from, bytes } => {
                if let Some(f) = link::take_in(&bytes, &mut self.refused, "a remote host") {
                    self.frame(f, &from)?;
                }
            }
            Mail::Frame(_) => debug!("a frame without its sender; dropped"),
        }
        Ok(())
    }

    /// A frame from the joined host `from`.
    fn frame(&mut self, f: Frame, from: &str) -> Result<()> {
        let refused = {
            let roster = self.roster.lock().expect("roster");
            refusal(&f, from, |id| roster.holder(id) == Some(from))
                .or_else(|| self.desk.refusal(&f, from))
        };
        if let Some(why) = refused {
            self.impostors += 1;
            if self.impostors.is_power_of_two() {
                warn!(
                    refused = self.impostors,
                    "frame from a remote host refused: {why}"
                );
            }
            return Ok(());
        }
        let sent = match f {
            Frame::Transitions(batch) => self.transitions(&batch),
            Frame::Progress(p) => self.progress.forward(p).map(|_| self.launcher.ring()),
            Frame::Query(q) => self.query(&q),
            Frame::DemoModel(h, b) => match self.desk.model(h, b) {
                Some((h, b)) => self.publish_model(h, &b).map(|()| Ok(0)),
                None => return Ok(()),
            },
            Frame::ExpertAnswer(r) => return self.expert_answer(r),
            Frame::ExpertDemos {
                generation,
                first,
                lines,
            } => return self.expert_demos(generation, first, lines),
            Frame::DemosLost { generation, lines } => {
                warn!(
                    generation,
                    lines,
                    "the remote expert's host held demonstrations the run never got (it stopped \
                     before they went up); the run's demos.jsonl replaced them there"
                );
                self.desk.lost(lines);
                self.count();
                return Ok(());
            }
            Frame::ExpertExited {
                generation,
                how,
                code,
            } => {
                self.desk.exited(generation);
                let _ = self.events.send(HubEvent::ExpertExited {
                    generation,
                    how,
                    code,
                });
                self.launcher.ring().map(Ok)
            }
            other => {
                debug!(service = other.service(), "a down frame came up; dropped");
                return Ok(());
            }
        };
        if let Some(rang) = link::forwarded(sent)? {
            rang?;
        }
        Ok(())
    }

    /// A remote actor's batch into this host's `transitions`, through a publisher of its own
    /// (sized by its first batch), the learner rung.
    fn transitions(
        &mut self,
        batch: &alfd_wire::TransitionBatch,
    ) -> alfd_wire::Result<alfd_wire::Result<usize>> {
        let tx = match self.transitions.entry(batch.head.actor) {
            Entry::Occupied(o) => o.into_mut(),
            Entry::Vacant(v) => v.insert(self.wire.transitions_sender(
                usize::from(batch.head.obs_dim),
                usize::from(batch.head.heads),
            )?),
        };
        tx.forward(batch).map(|_| self.learner.ring())
    }

    /// A remote actor's query to this host's expert, the expert rung. A newer query of the same
    /// actor replaces the older one (it gave up): an answer to that one already here is late,
    /// and if none is here the expert is told, with the newer query, that the hub let go of it
    /// (an answer sent in the instant before is late too, counted by the expert).
    fn query(
        &mut self,
        q: &alfd_wire::QueryRequest,
    ) -> alfd_wire::Result<alfd_wire::Result<usize>> {
        let mut forwarded = q.clone();
        forwarded.gave_up = 0;
        if let Some((mut old, ..)) = self.pending.remove(&q.actor) {
            if old.poll()?.is_some_and(|r| r.outcome == outcome::ANSWERED) {
                self.late += 1;
                self.count();
            } else {
                forwarded.gave_up = old.seq();
            }
        }
        let client = match self.clients.entry(q.actor) {
            Entry::Occupied(o) => o.into_mut(),
            Entry::Vacant(v) => v.insert(self.wire.query_client(q.state.len())?),
        };
        let ask = client.ask(&forwarded)?;
        self.pending
            .insert(q.actor, (ask, q.header.seq, Instant::now()));
        Ok(self.expert.ring())
    }

    fn publish_model(
        &mut self,
        h: DemoModelHeader,
        b: &[u8],
    ) -> std::result::Result<(), WireError> {
        let tx = match &mut self.remote_model {
            Some(tx) => tx,
            None => self.remote_model.insert(self.wire.demo_model_sender()?),
        };
        tx.forward(h, b)
    }

    /// Lines of a remote expert's `demos.jsonl`: appended to the run's in order (the file's
    /// next lines only; a gap is asked for again), then the model that waited for them.
    fn expert_demos(&mut self, generation: u16, first: u32, lines: Vec<String>) -> Result<()> {
        match self.desk.demos(generation, first, lines) {
            Intake::Append(lines) => {
                let n = lines.len();
                match crate::demos::append_lines(&self.opts.demos_path, &lines) {
                    Ok(()) => {
                        if let Some((h, b)) = self.desk.appended(n) {
                            if let Err(e) = self.publish_model(h, &b) {
                                warn!("{e}; a remote expert's model dropped");
                            }
                        }
                    }
                    Err(e) => {
                        warn!("{n} demonstrations of the remote expert not written: {e}");
                        self.desk.append_failed(n);
                    }
                }
            }
            Intake::Resend { generation, from } => {
                warn!(
                    generation,
                    from, "demonstrations of the remote expert came out of order; asked again"
                );
                self.put_frame(&Frame::Order(ExpertOrder::Resend { generation, from }))?;
            }
            Intake::Nothing | Intake::Wait => {}
            Intake::Refused(why) => warn!("{why}; not written"),
        }
        self.count();
        Ok(())
    }

    /// A remote expert's answer: delivered once its demonstration is on disk here (its line came
    /// up before it), to the query it answers.
    fn expert_answer(&mut self, r: QueryResponse) -> Result<()> {
        if let Err(why) = self.desk.check_answer(&r) {
            warn!("{why}; not answered");
            return Ok(());
        }
        let answer = self.desk.answered(r);
        self.count();
        match answer {
            Answer::Dropped(why) => debug!("{why}; answer not sent"),
            Answer::Deliver { query, response } => {
                let actor = response.actor;
                query.answer(response)?;
                if let Ok(id) = u16::try_from(actor) {
                    self.actor_bells.ring(id)?;
                }
            }
        }
        Ok(())
    }

    /// Queries to a remote expert: held here while it is active, the others let go (this host's
    /// expert answers them).
    fn queries_for_remote_expert(&mut self) -> Result<()> {
        let (server, desk) = (&self.server, &mut self.desk);
        let down = self.down;
        drain(
            || server.receive(),
            |q| {
                if desk.holds_queries() {
                    link::put(down, &Frame::Query(q.request().clone()))?;
                    desk.hold(q.request().actor, q);
                }
                Ok(())
            },
        )?;
        self.desk.prune(|q| q.is_connected());
        Ok(())
    }

    /// Down: what this host publishes, to every remote host.
    fn down(&mut self) -> Result<()> {
        if let Some(c) = self.credits.latest()? {
            self.newest.credits = Some(self.put_frame(&Frame::Credits(c))?);
        }
        if let Some(h) = self.weights.latest_into(&mut self.params)? {
            let f = Frame::Weights(h, self.params.clone());
            self.newest.weights = Some(self.put_frame(&f)?);
        }
        if let Some(h) = self.model.latest_into(&mut self.bytes)? {
            let f = Frame::DemoModel(h, self.bytes.clone());
            self.newest.model = Some(self.put_frame(&f)?);
        }
        if let Some(c) = self.control.latest()? {
            if let Some(generation) = self.desk.control(c.active_expert) {
                // Every expert before it has exited and all its answers are written: the
                // remote expert reads this back when it becomes active.
                let text = crate::demos::read(&self.opts.demos_path)?;
                self.desk.log_sent(text.lines().count());
                info!(
                    generation,
                    bytes = text.len(),
                    "demos.jsonl to the remote expert"
                );
                self.put_frame(&Frame::DemoLog { generation, text })?;
            }
            self.newest.control = Some(self.put_frame(&Frame::Control(c))?);
        }
        if let Some(tx) = &self.remote_model {
            tx.update_connections()?;
        }
        Ok(())
    }

    /// Answers of this host's expert to remote actors' queries, up to them; a query unanswered
    /// within the query timeout is dropped (its actor gave up already).
    fn poll_answers(&mut self) -> Result<()> {
        let mut answered = Vec::new();
        let down = self.down;
        for (actor, (p, seq, asked)) in self.pending.iter_mut() {
            match p.poll() {
                Ok(Some(mut r)) => {
                    r.request_seq = *seq;
                    r.actor = *actor;
                    link::put(down, &Frame::Answer(r))?;
                    answered.push(*actor);
                }
                Ok(None) if asked.elapsed() > self.opts.query_timeout => answered.push(*actor),
                Ok(None) => {}
                Err(e) => {
                    warn!("{e}; answer dropped");
                    answered.push(*actor);
                }
            }
        }
        for a in answered {
            self.pending.remove(&a);
        }
        Ok(())
    }
}

/// Why the hub refuses an up frame from the joined host `from`, if it does: a message of another
/// schema version than this run's, or one speaking for an actor id that `from` does not hold
/// (`held`: a local actor's, another host's, or nobody's): a remote host may act only as the
/// actors the run gave it.
pub(crate) fn refusal(f: &Frame, from: &str, held: impl Fn(u16) -> bool) -> Option<String> {
    let (service, header, actor) = match f {
        Frame::Transitions(b) => ("transitions", b.head.header, Some(b.head.actor)),
        Frame::Query(q) => ("query", q.header, Some(q.actor)),
        Frame::Progress(p) => (
            "progress",
            p.header,
            (p.header.role == Role::Actor as u16).then_some(u32::from(p.header.id)),
        ),
        _ => return None,
    };
    if header.schema != SCHEMA_VERSION {
        return Some(format!(
            "a {service} message of schema version {} (this run speaks {SCHEMA_VERSION})",
            header.schema
        ));
    }
    if let Some(a) = actor.filter(|&a| !u16::try_from(a).is_ok_and(&held)) {
        return Some(format!(
            "a {service} message from host {from} for actor {a}, which it does not hold"
        ));
    }
    // A batch whose values do not fit its own sizes is refused before a publisher is sized
    // for it (the learner checks the sizes against the run's).
    match f {
        Frame::Transitions(b) => b
            .check(
                usize::from(b.head.obs_dim),
                usize::from(b.head.heads),
                usize::MAX,
            )
            .err()
            .map(|e| {
                format!("a transitions message from host {from} that does not hold together: {e}")
            }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_wire::Header;

    fn header(role: Role, id: u16, schema: u32) -> Header {
        Header {
            schema,
            role: role as u16,
            id,
            seq: 1,
        }
    }

    #[test]
    fn a_remote_host_speaks_only_for_the_actors_it_holds_in_this_run_s_schema() {
        // Actors 0 and 1 are this host's; the joined host "a" holds 2 and 3, "b" holds 4; the
        // frames come from "a".
        let holder = |id: u16| match id {
            2 | 3 => Some("a"),
            4 => Some("b"),
            _ => None,
        };
        let held = |id: u16| holder(id) == Some("a");
        let batch = |actor: u32, schema: u32| {
            let mut b = alfd_wire::TransitionBatch::new(actor as u16, 1, 4, 2, 0).unwrap();
            b.head.header = header(Role::Actor, actor as u16, schema);
            Frame::Transitions(b)
        };
        assert_eq!(refusal(&batch(2, SCHEMA_VERSION), "a", held), None);
        let local = refusal(&batch(0, SCHEMA_VERSION), "a", held).unwrap();
        assert!(
            local.contains("transitions message from host a for actor 0"),
            "{local}"
        );
        // Another joined host's actor.
        let other = refusal(&batch(4, SCHEMA_VERSION), "a", held).unwrap();
        assert!(
            other.contains("for actor 4, which it does not hold"),
            "{other}"
        );
        assert!(refusal(&batch(9, SCHEMA_VERSION), "a", held).is_some());
        let old = refusal(&batch(3, SCHEMA_VERSION + 1), "a", held).unwrap();
        assert!(old.contains("schema version"), "{old}");
        // A batch claiming a huge observation it does not carry.
        let Frame::Transitions(mut huge) = batch(2, SCHEMA_VERSION) else {
            unreachable!()
        };
        (huge.head.obs_dim, huge.head.heads, huge.head.len) = (u16::MAX, u16::MAX, 1);
        let why = refusal(&Frame::Transitions(huge), "a", held).unwrap();
        assert!(why.contains("does not hold together"), "{why}");

        let query = |actor: u32| {
            Frame::Query(alfd_wire::QueryRequest {
                header: header(Role::Actor, actor as u16, SCHEMA_VERSION),
                actor,
                ..Default::default()
            })
        };
        assert_eq!(refusal(&query(3), "a", held), None);
        assert!(refusal(&query(1), "a", held).is_some());
        assert!(refusal(&query(70_000), "a", held).is_some());

        let progress = |role: Role, id: u16| {
            Frame::Progress(alfd_wire::Progress {
                header: header(role, id, SCHEMA_VERSION),
                ..Default::default()
            })
        };
        assert_eq!(refusal(&progress(Role::Actor, 2), "a", held), None);
        assert!(refusal(&progress(Role::Actor, 0), "a", held).is_some());
        // A remote expert's status speaks for no actor.
        assert_eq!(refusal(&progress(Role::Expert, 0), "a", held), None);
        // Frames that go down are not a remote host's to send, and are dropped elsewhere.
        assert_eq!(
            refusal(&Frame::Control(Default::default()), "a", held),
            None
        );
    }
}
