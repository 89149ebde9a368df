//! The remote host's side of a run across hosts (`alfd join`): asking the run for actor ids, and
//! the mirror, a local copy of the run's iceoryx2 services (its own run id, so its own prefix)
//! that the actors started here use unchanged. The mirror's bridge plays the learner, the expert
//! and the launcher for them: what they send goes to the learner's host over zenoh, what comes
//! back is published here under the sender's own header.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use alfd_wire::{ActorBells, Doorbell, IncomingQuery, Process, Role, Wake, Wire, SCHEMA_VERSION};
use tracing::{debug, info};
use zenoh::qos::CongestionControl;
use zenoh::Wait as _;

use crate::endpoint::Endpoint;
use crate::error::{zenoh_error, BridgeError, Result};
use crate::frame::{self, Frame};
use crate::inbox::{inbox, Mail};
use crate::link::{self, drain, HeldQueries};
use crate::roster::{JoinReply, JoinRequest, Joined, RestartReply, RestartRequest};
use crate::worker::{ForwardingThread, Heartbeat};
use crate::{keys, TICK};

/// A remote host's connection to a run: the zenoh session and the run's answer to the join.
pub struct Remote {
    session: zenoh::Session,
    pub joined: Joined,
    join_id: String,
}

impl Remote {
    /// The zenoh session to the learner's host.
    pub(crate) fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// This host's join id.
    pub(crate) fn join_id(&self) -> &str {
        &self.join_id
    }
}

impl std::fmt::Debug for Remote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Remote({})", self.joined.run_id)
    }
}

/// Why a connection failed, in a line: the TLS handshake's reason when there is one.
fn connect_failure(error: &str) -> String {
    let said = crate::tls::tls_reason(error).unwrap_or_else(|| {
        // zenoh's own text names where in zenoh it failed: left out.
        let text = error.split(" at /").next().unwrap_or(error);
        text.trim().trim_end_matches('!')
    });
    said.to_owned()
}

#[cfg(test)]
#[test]
fn a_connection_failure_is_said_in_a_line() {
    assert_eq!(
        connect_failure("Unable to connect to any of [Single(quic/h:1)]!  at /x/y.rs:447."),
        "Unable to connect to any of [Single(quic/h:1)]"
    );
    assert_eq!(
        connect_failure("x { reason: b\"invalid peer certificate: Expired\" } at /z"),
        "invalid peer certificate: Expired"
    );
}

/// Connects to `endpoint` and asks the run listening there for `actors` actor ids, speaking
/// schema version `schema` (normally [`SCHEMA_VERSION`]; a run of another version refuses).
pub fn join(
    endpoint: &Endpoint,
    request: JoinRequest,
    wait: Duration,
    schema: u32,
) -> Result<Remote> {
    let no_run = |why: String| BridgeError::NoRun {
        endpoint: endpoint.to_string(),
        waited_ms: wait.as_millis() as u64,
        why,
    };
    let started = Instant::now();
    // The run may not listen yet (its hub starts once its learner is up): try again until the
    // deadline.
    let session = loop {
        match zenoh::open(endpoint.connect_config()?).wait() {
            Ok(s) => break s,
            Err(e) if started.elapsed() >= wait => {
                debug!("cannot connect to {endpoint}: {e}");
                return Err(no_run(connect_failure(&e.to_string())));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(250)),
        }
    };
    let payload = frame::encode(schema, &request)?;
    // The link may take a moment to come up: ask again until the deadline.
    let reply = loop {
        let replies = session
            .get(keys::join("*"))
            .payload(payload.clone())
            .timeout(Duration::from_secs(2).min(wait))
            .wait()
            .map_err(zenoh_error)?;
        let mut got = Vec::new();
        while let Ok(r) = replies.recv() {
            if let Ok(s) = r.result() {
                got.push(s.payload().to_bytes().into_owned());
            }
        }
        match got.len() {
            0 if started.elapsed() < wait => std::thread::sleep(Duration::from_millis(200)),
            0 => return Err(no_run("connected, but no run answered".to_owned())),
            1 => break got.remove(0),
            n => {
                return Err(BridgeError::Refused(format!(
                    "{n} runs answered at {endpoint}; give each run its own port"
                )))
            }
        }
    };
    match frame::decode::<JoinReply>(schema, &reply)? {
        JoinReply::Refused(why) => Err(BridgeError::Refused(why)),
        JoinReply::Joined(joined) => {
            info!(run_id = %joined.run_id, actors = ?joined.actors, "joined");
            Ok(Remote {
                session,
                joined,
                join_id: request.join_id,
            })
        }
    }
}

/// A running mirror; stop it with [`Mirror::stop`] (or drop it).
pub struct Mirror {
    /// The forwarding thread; it hears of the learner's host by its control messages, every
    /// `alfd_wire::CONTROL_PERIOD`.
    forwarder: ForwardingThread,
    _down: zenoh::pubsub::Subscriber<()>,
    session: zenoh::Session,
    run_id: String,
    join_id: String,
}

impl std::fmt::Debug for Mirror {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Mirror")
    }
}

impl Mirror {
    /// Starts the mirror of `remote`'s run as local run `mirror_run_id`, then announces this host
    /// to the hub (which sends it the newest of everything).
    pub fn start(remote: Remote, mirror_run_id: &str) -> Result<Self> {
        let Remote {
            session,
            joined,
            join_id,
        } = remote;
        let (post, inbox) = inbox(mirror_run_id, 1);
        let down = {
            let post = post.clone();
            session
                .declare_subscriber(keys::down(&joined.run_id))
                .callback(move |s| post.send(Mail::Frame(s.payload().to_bytes().into_owned())))
                .wait()
                .map_err(zenoh_error)?
        };
        let up = session
            .declare_publisher(keys::up(&joined.run_id, &join_id))
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(zenoh_error)?;
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let mirror_run_id = mirror_run_id.to_owned();
        let ids: Vec<u16> = joined.actors.iter().map(|a| a.0).collect();
        let mut forwarder = ForwardingThread::spawn("mirror", move |stop, heard| {
            forward(&mirror_run_id, &ids, inbox, &up, stop, heard, ready_tx)
        });
        // The mirror's services exist before the hub is told this host is up.
        let _ = ready_rx.recv_timeout(Duration::from_secs(10));
        forwarder.announce(
            session
                .liveliness()
                .declare_token(keys::member(&joined.run_id, &join_id))
                .wait()
                .map_err(zenoh_error)?,
        );
        Ok(Self {
            forwarder,
            _down: down,
            session,
            run_id: joined.run_id,
            join_id,
        })
    }

    /// Actor `actor` of this host crashed: asks the run for its new incarnation (waiting at
    /// most `wait`). The run refuses after its `--max-restarts` restarts of the id.
    pub fn restart(&self, actor: u16, wait: Duration) -> Result<u64> {
        let request = RestartRequest {
            join_id: self.join_id.clone(),
            actor,
        };
        let replies = self
            .session
            .get(keys::restart(&self.run_id))
            .payload(frame::encode(SCHEMA_VERSION, &request)?)
            .timeout(wait)
            .wait()
            .map_err(zenoh_error)?;
        while let Ok(r) = replies.recv() {
            if let Ok(s) = r.result() {
                return match frame::decode::<RestartReply>(SCHEMA_VERSION, &s.payload().to_bytes())?
                {
                    RestartReply::Restart(incarnation) => Ok(incarnation),
                    RestartReply::Refused(why) => Err(BridgeError::Refused(why)),
                };
            }
        }
        Err(BridgeError::Zenoh(format!(
            "the run did not answer a restart of actor {actor} within {} ms",
            wait.as_millis()
        )))
    }

    /// How long since the learner's host was last heard of (`None`: never yet).
    pub fn silence(&self) -> Option<Duration> {
        self.forwarder.silence()
    }

    /// Whether the mirror's thread ended (an error, said in the log).
    pub fn ended(&self) -> bool {
        self.forwarder.ended()
    }

    /// Stops forwarding, leaves the run (the token goes) and closes the session.
    pub fn stop(mut self) -> Result<()> {
        self.halt()
    }

    fn halt(&mut self) -> Result<()> {
        let r = self.forwarder.halt();
        let _ = self.session.close().wait();
        r
    }
}

impl Drop for Mirror {
    fn drop(&mut self) {
        let _ = self.halt();
    }
}

/// The mirror's thread: blocks on the doorbells the local actors ring (the learner's, the
/// expert's, the launcher's) and its own (zenoh delivered something).
#[allow(clippy::too_many_arguments)]
fn forward(
    run_id: &str,
    ids: &[u16],
    inbox: crate::inbox::Inbox,
    up: &zenoh::pubsub::Publisher<'static>,
    stop: &AtomicBool,
    heard: &Heartbeat,
    ready: std::sync::mpsc::Sender<()>,
) -> Result<()> {
    let wire = Wire::connect(run_id, Process::new(Role::Bridge, 0), SCHEMA_VERSION)?;
    let waiter = wire.waiter_on(&[
        Doorbell::Bridge,
        Doorbell::Learner,
        Doorbell::Expert,
        Doorbell::Launcher,
    ])?;
    let transitions = wire.transitions_receiver()?;
    let progress = wire.progress_receiver()?;
    let queries = wire.query_server()?;
    let mut here = Here {
        wire: &wire,
        ids,
        heard,
        credits: wire.credits_sender()?,
        control: wire.control_sender()?,
        model: wire.demo_model_sender()?,
        weights: None,
        bells: ActorBells::new(&wire),
        held: HeldQueries::default(),
        refused: 0,
    };
    let put = |f: &Frame| link::put(up, f);
    let _ = ready.send(());
    while !stop.load(Ordering::Relaxed) {
        if waiter.wait(TICK * 4)? == Wake::Signal {
            // `alfd join` handles the signal; this thread goes on until told to stop.
            std::thread::sleep(TICK);
        }
        // Down: from the learner's host to the actors here.
        while let Ok(mail) = inbox.mail.try_recv() {
            if let Mail::Frame(b) = mail {
                here.down(&b)?;
            }
        }
        // Up: what the actors here sent.
        drain(|| transitions.receive(), |b| put(&Frame::Transitions(b)))?;
        drain(|| progress.receive(), |p| put(&Frame::Progress(p)))?;
        let held = &mut here.held;
        drain(
            || queries.receive(),
            |q| {
                put(&Frame::Query(q.request().clone()))?;
                held.hold(q.request().actor, q);
                Ok(())
            },
        )?;
        held.prune(|q| q.is_connected());
        here.update_connections()?;
    }
    Ok(())
}

/// What the mirror does with a frame from the learner's host (a value of one call, never
/// stored: the size of its frame does not matter).
#[derive(Debug, PartialEq)]
#[allow(clippy::large_enum_variant)]
enum Down {
    /// Published to this host's actors under the sender's header; `wake`: ring every actor here
    /// afterwards (credits and control may unblock one that waits); `heard`: the learner's host
    /// is alive (its control messages are its heartbeat).
    Publish {
        frame: Frame,
        wake: bool,
        heard: bool,
    },
    /// The answer to a query held for one of this host's actors.
    Answer(alfd_wire::QueryResponse),
    /// A frame that only goes up, or to a remote expert: dropped (its service named).
    Drop(&'static str),
}

fn route_down(f: Frame) -> Down {
    let publish = |frame, wake, heard| Down::Publish { frame, wake, heard };
    match f {
        Frame::Credits(_) => publish(f, true, false),
        Frame::Control(_) => publish(f, true, true),
        Frame::Weights(..) | Frame::DemoModel(..) => publish(f, false, false),
        Frame::Answer(r) => Down::Answer(r),
        other => Down::Drop(other.service()),
    }
}

/// The mirror's side of this host's services: what comes down goes to the actors here.
struct Here<'w, 'a> {
    wire: &'w Wire,
    ids: &'a [u16],
    heard: &'a Heartbeat,
    credits: alfd_wire::Sender<'w, alfd_wire::Credits>,
    control: alfd_wire::Sender<'w, alfd_wire::Control>,
    model: alfd_wire::DemoModelSender<'w>,
    weights: Option<alfd_wire::WeightsSender<'w>>,
    bells: ActorBells<'w>,
    /// The actors' queries, waiting for the answer from the learner's host.
    held: HeldQueries<IncomingQuery<'w>>,
    refused: u64,
}

impl Here<'_, '_> {
    /// A frame from the learner's host, into this host's services ([`route_down`] decides).
    fn down(&mut self, b: &[u8]) -> Result<()> {
        let Some(f) = link::take_in(b, &mut self.refused, "the learner's host") else {
            return Ok(());
        };
        let (frame, wake) = match route_down(f) {
            Down::Publish { frame, wake, heard } => {
                if heard {
                    self.heard.beat();
                }
                (frame, wake)
            }
            Down::Answer(r) => {
                if let Ok(q) = self.held.take(&r) {
                    q.answer(r)?;
                    if let Ok(id) = u16::try_from(r.actor) {
                        self.bells.ring(id)?;
                    }
                }
                return Ok(());
            }
            Down::Drop(service) => {
                debug!(service, "an up frame came down; dropped");
                return Ok(());
            }
        };
        let published = match frame {
            Frame::Credits(c) => self.credits.forward(c).map(|_| ()),
            Frame::Control(c) => self.control.forward(c).map(|_| ()),
            Frame::Weights(h, params) => {
                let tx = match &mut self.weights {
                    Some(tx) => tx,
                    None => self.weights.insert(self.wire.weights_sender(params.len())?),
                };
                tx.forward(h, &params).map(|_| ())
            }
            Frame::DemoModel(h, bytes) => self.model.forward(h, &bytes).map(|_| ()),
            _ => unreachable!("route_down publishes only these"),
        };
        if link::forwarded(published)?.is_some() && wake {
            for &id in self.ids {
                self.bells.ring(id)?;
            }
        }
        Ok(())
    }

    /// Actors that started since the last publication get the newest of each (history 1).
    fn update_connections(&self) -> Result<()> {
        self.credits.update_connections()?;
        self.control.update_connections()?;
        self.model.update_connections()?;
        if let Some(w) = &self.weights {
            w.update_connections()?;
        }
        Ok(())
    }
}

#[cfg(test)]
#[test]
fn down_frames_reach_the_actors_and_wake_them_only_when_they_may_be_waiting() {
    use alfd_wire::{
        Control, Credits, DemoModelHeader, QueryRequest, QueryResponse, WeightsHeader,
    };
    let publish = |f: Frame| match route_down(f) {
        Down::Publish { wake, heard, .. } => Some((wake, heard)),
        _ => None,
    };
    // Credits and control may unblock a waiting actor; control is also the heartbeat.
    assert_eq!(
        publish(Frame::Credits(Credits::default())),
        Some((true, false))
    );
    assert_eq!(
        publish(Frame::Control(Control::default())),
        Some((true, true))
    );
    // Weights and the demonstration model are taken at the actors' next step: no ring.
    let weights = Frame::Weights(WeightsHeader::default(), vec![0.5; 3]);
    assert_eq!(publish(weights), Some((false, false)));
    let model = Frame::DemoModel(DemoModelHeader::default(), vec![1, 2]);
    assert_eq!(publish(model), Some((false, false)));
    let r = QueryResponse {
        actor: 3,
        ..QueryResponse::default()
    };
    assert_eq!(route_down(Frame::Answer(r)), Down::Answer(r));
    // What only goes up is dropped, named.
    let up = Frame::Query(QueryRequest::default());
    assert_eq!(route_down(up), Down::Drop("query"));
    let exited = Frame::ExpertExited {
        generation: 1,
        how: "exited".into(),
        code: Some(0),
    };
    assert!(matches!(route_down(exited), Down::Drop(_)));
}
