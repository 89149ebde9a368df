//! A remote host serving the run's expert (`alfd join --expert NAME`): a local copy of the
//! run's services under an id of its own, in which `alfd-expert` runs unchanged. Its bridge
//! plays the launcher and the actors for the expert: the run's control comes down (and, before
//! the control message that makes this expert active, the run's `demos.jsonl`, which the
//! expert reads back as on one host), queries come down; the expert's status, model, answers
//! and every line it appends to this host's `demos.jsonl` go up (the lines in order, before the
//! answers they carry, whether or not an answer is still awaited: [`DemoShipper`]), and the
//! learner's host writes them to the run's `demos.jsonl` before any actor sees an answer.

use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use alfd_wire::{
    Doorbell, PendingQuery, Process, QueryClient, QueryResponse, Role, Wake, Wire, MAX_ACTORS,
    SCHEMA_VERSION,
};
use tracing::{debug, info, warn};
use zenoh::qos::CongestionControl;
use zenoh::Wait as _;

use crate::error::{zenoh_error, Result};
use crate::frame::{ExpertOrder, Frame};
use crate::inbox::{inbox, Mail, Post};
use crate::link::{self, drain};
use crate::mirror::Remote;
use crate::shipper::DemoShipper;
use crate::worker::{ForwardingThread, Heartbeat};
use crate::{keys, TICK};

/// What the run asks of `alfd join` about its expert.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ExpertHostOrder {
    /// Start `alfd-expert` as `generation` with demonstrator `name`.
    Start { generation: u16, name: String },
    /// Kill the expert of `generation`.
    Kill { generation: u16 },
    /// The run does not take this host's expert: why.
    Refused(String),
}

/// A running expert host; stop it with [`ExpertHost::stop`] (or drop it).
pub struct ExpertHost {
    post: Post,
    orders: mpsc::Receiver<ExpertHostOrder>,
    forwarder: ForwardingThread,
    _down: zenoh::pubsub::Subscriber<()>,
}

impl std::fmt::Debug for ExpertHost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ExpertHost")
    }
}

impl ExpertHost {
    /// Starts this host's copy of `remote`'s run for its expert as local run `host_run_id`
    /// (the expert's run directory is `run_dir`). `announce`: declare this host to the hub
    /// (a host that also has actors announces itself with its [`Mirror`](crate::Mirror)).
    pub fn start(
        remote: &Remote,
        host_run_id: &str,
        run_dir: &Path,
        announce: bool,
    ) -> Result<Self> {
        let session = remote.session().clone();
        let run_id = remote.joined.run_id.clone();
        let (post, inbox) = inbox(host_run_id, 1);
        let down = {
            let post = post.clone();
            session
                .declare_subscriber(keys::down(&run_id))
                .callback(move |s| post.send(Mail::Frame(s.payload().to_bytes().into_owned())))
                .wait()
                .map_err(zenoh_error)?
        };
        let up = session
            .declare_publisher(keys::up(&run_id, remote.join_id()))
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(zenoh_error)?;
        let (orders_tx, orders) = mpsc::channel();
        let (ready_tx, ready_rx) = mpsc::channel();
        let me = Me {
            run_id: host_run_id.to_owned(),
            join_id: remote.join_id().to_owned(),
            demos: run_dir.join("demos.jsonl"),
        };
        let mut forwarder = ForwardingThread::spawn("expert host", move |stop, heard| {
            forward(&me, inbox, &up, stop, heard, &orders_tx, ready_tx)
        });
        let _ = ready_rx.recv_timeout(Duration::from_secs(10));
        if announce {
            forwarder.announce(
                session
                    .liveliness()
                    .declare_token(keys::member(&run_id, remote.join_id()))
                    .wait()
                    .map_err(zenoh_error)?,
            );
        }
        Ok(Self {
            post,
            orders,
            forwarder,
            _down: down,
        })
    }

    /// The run's orders since the last call.
    pub fn orders(&self) -> Vec<ExpertHostOrder> {
        self.orders.try_iter().collect()
    }

    /// The expert of `generation` ended (`how`, and its exit code if it exited): said to the
    /// run once every answer it sent has gone up.
    pub fn exited(&self, generation: u16, how: String, code: Option<i32>) {
        self.post.send(Mail::Exited {
            generation,
            how,
            code,
        });
    }

    /// How long since the learner's host was last heard of (`None`: never yet).
    pub fn silence(&self) -> Option<Duration> {
        self.forwarder.silence()
    }

    /// Whether the bridge's thread ended (an error, said in the log).
    pub fn ended(&self) -> bool {
        self.forwarder.ended()
    }

    /// Stops forwarding (after what is under way) and leaves the run.
    pub fn stop(mut self) -> Result<()> {
        self.forwarder.halt()
    }
}

impl Drop for ExpertHost {
    fn drop(&mut self) {
        let _ = self.forwarder.halt();
    }
}

/// Who this host is.
struct Me {
    run_id: String,
    join_id: String,
    demos: PathBuf,
}

/// What a frame from the learner's host asks of this host, given the generations the run gave
/// its expert (`mine`, updated here): the pure part of [`forward`]'s down direction.
#[derive(Debug, PartialEq)]
enum Route {
    /// The launcher's control, for this host's expert.
    Control(alfd_wire::Control),
    /// An order for this host's expert process.
    Order(ExpertHostOrder),
    /// The run's `demos.jsonl`, for this host's expert before it becomes active.
    DemoLog { generation: u16, text: String },
    /// An actor's query, for this host's expert.
    Query(alfd_wire::QueryRequest),
    /// The run asks for this host's demonstrations of `generation` again from line `from`.
    Resend { generation: u16, from: u32 },
    /// Not for this host (another host's order, a generation not its own, a query while it
    /// serves none, a frame that only goes up).
    Ignore,
}

fn route(join_id: &str, mine: &mut HashSet<u16>, f: Frame) -> Route {
    match f {
        Frame::Control(c) => Route::Control(c),
        Frame::Order(ExpertOrder::Start {
            join_id: j,
            generation,
            name,
        }) if j == join_id => {
            if mine.insert(generation) {
                info!(generation, expert = %name, "the run takes this host's expert");
                Route::Order(ExpertHostOrder::Start { generation, name })
            } else {
                Route::Ignore
            }
        }
        Frame::Order(ExpertOrder::Kill { generation }) if mine.contains(&generation) => {
            Route::Order(ExpertHostOrder::Kill { generation })
        }
        Frame::Order(ExpertOrder::Refuse { join_id: j, why }) if j == join_id => {
            Route::Order(ExpertHostOrder::Refused(why))
        }
        Frame::Order(ExpertOrder::Resend { generation, from }) if mine.contains(&generation) => {
            Route::Resend { generation, from }
        }
        Frame::DemoLog { generation, text } if mine.contains(&generation) => {
            Route::DemoLog { generation, text }
        }
        Frame::Query(q) if !mine.is_empty() => Route::Query(q),
        _ => Route::Ignore,
    }
}

/// What the expert host's services held at one look: the expert's status reports, its answers,
/// its newest model, the lines it appended to `demos.jsonl`, and the exits of its processes that
/// the host saw.
struct Look {
    reports: Vec<alfd_wire::Progress>,
    answers: Vec<QueryResponse>,
    model: Option<(alfd_wire::DemoModelHeader, Vec<u8>)>,
    demos: Option<Frame>,
    exits: Vec<Frame>,
}

/// The frames that go up for one look, in the order the expert did things, given the
/// generations the run gave this host (`mine`, which loses an exited one): the model first, if
/// it is one of this host's generations (the actor shapes the step it asked about with it, as on
/// one host); then the new lines of `demos.jsonl`, so that the learner's host has written every
/// demonstration before it hears the answer that gives it; then the answers; then the status
/// reports, so that an `exiting` never overtakes an answer sent before it; the exits at the very
/// end.
fn plan_up(mine: &mut HashSet<u16>, look: Look) -> Vec<Frame> {
    let Look {
        reports,
        answers,
        model,
        demos,
        exits,
    } = look;
    let mut up = Vec::new();
    if let Some((h, bytes)) = model {
        if u16::try_from(h.expert).is_ok_and(|g| mine.contains(&g)) {
            up.push(Frame::DemoModel(h, bytes));
        }
    }
    up.extend(demos);
    up.extend(answers.into_iter().map(Frame::ExpertAnswer));
    up.extend(reports.into_iter().map(Frame::Progress));
    for f in exits {
        if let Frame::ExpertExited { generation, .. } = &f {
            mine.remove(generation);
        }
        up.push(f);
    }
    up
}

/// The bridge's thread: blocks on its own doorbell (zenoh delivered something), the
/// launcher's (the expert reports) and the actors' (the expert answered).
fn forward(
    me: &Me,
    inbox: crate::inbox::Inbox,
    up: &zenoh::pubsub::Publisher<'static>,
    stop: &AtomicBool,
    heard: &Heartbeat,
    orders: &mpsc::Sender<ExpertHostOrder>,
    ready: mpsc::Sender<()>,
) -> Result<()> {
    let wire = Wire::connect(&me.run_id, Process::new(Role::Bridge, 0), SCHEMA_VERSION)?;
    let mut bells = vec![Doorbell::Bridge, Doorbell::Launcher];
    bells.extend((0..MAX_ACTORS as u16).map(Doorbell::Actor));
    let waiter = wire.waiter_on(&bells)?;
    let mut host = HostForwarder {
        me,
        wire: &wire,
        up,
        heard,
        orders,
        control: wire.control_sender()?,
        progress: wire.progress_receiver()?,
        model: wire.demo_model_receiver()?,
        expert: wire.bell(Doorbell::Expert)?,
        clients: HashMap::new(),
        pending: HashMap::new(),
        replaced: Vec::new(),
        shipper: DemoShipper::default(),
        mine: HashSet::new(),
        bytes: Vec::new(),
        refused: 0,
    };
    let _ = ready.send(());
    loop {
        // Told to stop: one more pass, so that what was posted before (the expert's exit) goes.
        let last = stop.load(Ordering::Relaxed);
        if !last && waiter.wait(TICK * 4)? == Wake::Signal {
            std::thread::sleep(TICK);
        }
        let mut exits = Vec::new();
        while let Ok(mail) = inbox.mail.try_recv() {
            match mail {
                Mail::Frame(b) => host.down(&b)?,
                Mail::Exited {
                    generation,
                    how,
                    code,
                } => exits.push(Frame::ExpertExited {
                    generation,
                    how,
                    code,
                }),
                Mail::Joined | Mail::Order(_) | Mail::Left(_) | Mail::Up { .. } => {}
            }
        }
        host.up(exits)?;
        host.control.update_connections()?;
        if last {
            return Ok(());
        }
    }
}

/// The expert host thread's ports and state.
struct HostForwarder<'w, 'a> {
    me: &'a Me,
    wire: &'w Wire,
    up: &'a zenoh::pubsub::Publisher<'static>,
    heard: &'a Heartbeat,
    orders: &'a mpsc::Sender<ExpertHostOrder>,
    control: alfd_wire::Sender<'w, alfd_wire::Control>,
    progress: alfd_wire::Receiver<'w, alfd_wire::Progress>,
    model: alfd_wire::DemoModelReceiver<'w>,
    expert: alfd_wire::Bell,
    clients: HashMap<u32, QueryClient<'w>>,
    pending: HashMap<u32, (PendingQuery<'w>, u64)>,
    /// Answers to queries that a newer query of the same actor replaced: they go up (the hub
    /// counts them late).
    replaced: Vec<QueryResponse>,
    /// This host's `demos.jsonl` against the run's.
    shipper: DemoShipper,
    /// The generations the run gave this host's expert.
    mine: HashSet<u16>,
    bytes: Vec<u8>,
    /// Frames from the learner's host that could not be read.
    refused: u64,
}

impl HostForwarder<'_, '_> {
    fn put(&self, f: &Frame) -> Result<()> {
        link::put(self.up, f)
    }

    /// Down: a frame from the learner's host, into this host's services.
    fn down(&mut self, b: &[u8]) -> Result<()> {
        let Some(f) = link::take_in(b, &mut self.refused, "the learner's host") else {
            return Ok(());
        };
        let done = match route(&self.me.join_id, &mut self.mine, f) {
            Route::Control(c) => {
                self.heard.beat();
                self.control.forward(c)
            }
            Route::Order(order) => {
                let _ = self.orders.send(order);
                return Ok(());
            }
            Route::DemoLog { generation, text } => return self.activated(generation, &text),
            Route::Resend { generation, from } => {
                let host = crate::demos::read(&self.me.demos)?;
                self.shipper.rewind(generation, from as usize, &host);
                info!(generation, from, "the run asks for demonstrations again");
                return Ok(());
            }
            Route::Query(q) => {
                let client = match self.clients.entry(q.actor) {
                    Entry::Occupied(o) => o.into_mut(),
                    Entry::Vacant(v) => v.insert(self.wire.query_client(q.state.len())?),
                };
                // A newer query of the same actor replaces the older one (it gave up): an answer
                // to that one already here still goes up; if none is, the expert is told with
                // the newer query that this host let go of it (its numbering, not the actor's).
                let (seq, actor) = (q.header.seq, q.actor);
                let mut q = q;
                q.gave_up = 0;
                if let Some((mut old, old_seq)) = self.pending.remove(&actor) {
                    match old.poll() {
                        Ok(Some(r)) => self.replaced.push(QueryResponse {
                            request_seq: old_seq,
                            actor,
                            ..r
                        }),
                        _ => q.gave_up = old.seq(),
                    }
                }
                self.pending.insert(actor, (client.ask(&q)?, seq));
                Ok(())
            }
            Route::Ignore => return Ok(()),
        };
        if link::forwarded(done)?.is_some() {
            self.expert.ring()?;
        }
        Ok(())
    }

    /// The run's `demos.jsonl` for `generation`, before the control message that makes it
    /// active (one publisher, in order): it replaces this host's, and what this host held that
    /// the run never got is reported.
    fn activated(&mut self, generation: u16, text: &str) -> Result<()> {
        let host = crate::demos::read(&self.me.demos)?;
        let lost = self.shipper.activated(generation, text, &host);
        crate::demos::replace(&self.me.demos, text)?;
        debug!(generation, bytes = text.len(), "the run's demos.jsonl");
        if lost > 0 {
            warn!(
                generation,
                lost,
                "this host's demos.jsonl held demonstrations the run never got; replaced by the run's"
            );
            let lines = u32::try_from(lost).unwrap_or(u32::MAX);
            self.put(&Frame::DemosLost { generation, lines })?;
        }
        Ok(())
    }

    /// Up: what the expert did since the last look, in the order [`plan_up`] gives.
    fn up(&mut self, exits: Vec<Frame>) -> Result<()> {
        let mut reports = Vec::new();
        drain(
            || self.progress.receive(),
            |p| {
                reports.push(p);
                Ok(())
            },
        )?;
        let answers = self.answers();
        let model = self
            .model
            .latest_into(&mut self.bytes)?
            .map(|h| (h, self.bytes.clone()));
        // Read after the answers: every demonstration answered is on disk (the expert writes it
        // before it answers), so its line goes up before its answer.
        let demos = if self.shipper.shipping() {
            let tail = crate::demos::read_from(&self.me.demos, self.shipper.offset())?;
            self.shipper.ship(&tail)
        } else {
            None
        };
        for f in &exits {
            if let Frame::ExpertExited { generation, .. } = f {
                self.shipper.exited(*generation);
            }
        }
        let look = Look {
            reports,
            answers,
            model,
            demos,
            exits,
        };
        for f in plan_up(&mut self.mine, look) {
            self.put(&f)?;
        }
        Ok(())
    }

    /// The answers the expert gave since the last look.
    fn answers(&mut self) -> Vec<QueryResponse> {
        let mut answers = std::mem::take(&mut self.replaced);
        self.pending.retain(|&actor, (p, seq)| match p.poll() {
            Ok(Some(mut r)) => {
                r.request_seq = *seq;
                r.actor = actor;
                answers.push(r);
                false
            }
            Ok(None) => p.held(),
            Err(e) => {
                warn!("{e}; answer dropped");
                false
            }
        });
        answers
    }
}

#[cfg(test)]
mod route_tests {
    use super::*;
    use alfd_wire::outcome;

    fn start(join_id: &str, generation: u16) -> Frame {
        Frame::Order(ExpertOrder::Start {
            join_id: join_id.into(),
            generation,
            name: "scripted".into(),
        })
    }

    #[test]
    fn only_this_hosts_orders_and_generations_are_taken() {
        let mut mine = HashSet::new();
        // A query before the run gave this host a generation: not for it.
        let q = alfd_wire::QueryRequest::default();
        assert_eq!(
            route("me", &mut mine, Frame::Query(q.clone())),
            Route::Ignore
        );
        // Another host's start, and a kill of a generation not its own: ignored.
        assert_eq!(route("me", &mut mine, start("other", 2)), Route::Ignore);
        let kill = || Frame::Order(ExpertOrder::Kill { generation: 2 });
        assert_eq!(route("me", &mut mine, kill()), Route::Ignore);
        // Its own start, once (an order sent again to a host that rejoins starts nothing more).
        assert_eq!(
            route("me", &mut mine, start("me", 2)),
            Route::Order(ExpertHostOrder::Start {
                generation: 2,
                name: "scripted".into()
            })
        );
        assert_eq!(route("me", &mut mine, start("me", 2)), Route::Ignore);
        assert_eq!(
            route("me", &mut mine, kill()),
            Route::Order(ExpertHostOrder::Kill { generation: 2 })
        );
        assert!(matches!(
            route("me", &mut mine, Frame::Query(q)),
            Route::Query(_)
        ));
        let log = |generation| Frame::DemoLog {
            generation,
            text: "x\n".into(),
        };
        assert_eq!(route("me", &mut mine, log(3)), Route::Ignore);
        assert!(matches!(
            route("me", &mut mine, log(2)),
            Route::DemoLog { generation: 2, .. }
        ));
    }

    #[test]
    fn what_goes_up_keeps_the_experts_order_with_the_lines_before_the_answers() {
        let answer = |outcome, demo_index| QueryResponse {
            outcome,
            demo_index,
            ..QueryResponse::default()
        };
        let header = |expert| alfd_wire::DemoModelHeader {
            expert,
            ..alfd_wire::DemoModelHeader::default()
        };
        let exit = |generation| Frame::ExpertExited {
            generation,
            how: "exited".into(),
            code: Some(0),
        };
        let status = alfd_wire::Progress::default();
        let mut mine = HashSet::from([2u16]);
        let look = Look {
            reports: vec![status],
            answers: vec![
                answer(outcome::ANSWERED, 1),
                answer(outcome::DECLINED, 0),
                answer(outcome::ANSWERED, 0),
            ],
            model: Some((header(2), vec![7])),
            demos: Some(Frame::ExpertDemos {
                generation: 2,
                first: 0,
                lines: vec!["d0".into(), "d1".into()],
            }),
            exits: vec![exit(2)],
        };
        let up = plan_up(&mut mine, look);
        let kinds: Vec<String> = up
            .iter()
            .map(|f| match f {
                Frame::DemoModel(h, _) => format!("model {}", h.expert),
                Frame::ExpertDemos { first, lines, .. } => format!("lines {first} {lines:?}"),
                Frame::ExpertAnswer(r) => format!("answer {} {}", r.outcome, r.demo_index),
                Frame::Progress(_) => "status".into(),
                Frame::ExpertExited { generation, .. } => format!("exit {generation}"),
                _ => "other".into(),
            })
            .collect();
        let answered = outcome::ANSWERED;
        assert_eq!(
            kinds,
            vec![
                "model 2".to_owned(),
                r#"lines 0 ["d0", "d1"]"#.to_owned(),
                format!("answer {answered} 1"),
                format!("answer {} 0", outcome::DECLINED),
                format!("answer {answered} 0"),
                "status".into(),
                "exit 2".into(),
            ]
        );
        // The exited generation is no longer this host's: its model does not go up.
        assert!(mine.is_empty());
        let look = Look {
            reports: vec![],
            answers: vec![],
            model: Some((header(2), vec![7])),
            demos: None,
            exits: vec![],
        };
        assert!(plan_up(&mut mine, look).is_empty());
    }

    #[test]
    fn a_resend_is_taken_only_for_this_hosts_generations() {
        let mut mine = HashSet::from([2u16]);
        let resend = |generation| {
            Frame::Order(ExpertOrder::Resend {
                generation,
                from: 4,
            })
        };
        assert_eq!(
            route("me", &mut mine, resend(2)),
            Route::Resend {
                generation: 2,
                from: 4
            }
        );
        assert_eq!(route("me", &mut mine, resend(3)), Route::Ignore);
    }
}
