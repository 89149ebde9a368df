//! A remote host serving the run's expert (`alfd join --expert NAME`): a local copy of the
//! run's services under an id of its own, in which `alfd-expert` runs unchanged. Its bridge
//! plays the launcher and the actors for the expert: the run's control comes down (and, before
//! the control message that makes this expert active, the run's `demos.jsonl`, which the
//! expert reads back as on one host), queries come down; the expert's status, model and
//! answers go up, each answer with its demonstration, which the learner's host writes to the
//! run's `demos.jsonl` before any actor sees it.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

use alfd_wire::{
    outcome, Doorbell, PendingQuery, Process, QueryClient, Role, Wake, Wire, WireError, MAX_ACTORS,
    SCHEMA_VERSION,
};
use tracing::{debug, info, warn};
use zenoh::qos::CongestionControl;
use zenoh::Wait as _;

use crate::error::{zenoh_error, Result};
use crate::frame::{self, ExpertOrder, Frame};
use crate::inbox::{inbox, Mail, Post};
use crate::mirror::Remote;
use crate::worker::{self, Heartbeat};
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
    stop: Arc<AtomicBool>,
    post: Post,
    orders: mpsc::Receiver<ExpertHostOrder>,
    thread: Option<JoinHandle<Result<()>>>,
    heard: Heartbeat,
    _token: Option<zenoh::liveliness::LivelinessToken>,
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
            .declare_publisher(keys::up(&run_id))
            .congestion_control(CongestionControl::Block)
            .wait()
            .map_err(zenoh_error)?;
        let stop = Arc::new(AtomicBool::new(false));
        let heard = Heartbeat::new();
        let (orders_tx, orders) = mpsc::channel();
        let (ready_tx, ready_rx) = mpsc::channel();
        let thread = {
            let stop = Arc::clone(&stop);
            let heard = heard.clone();
            let me = Me {
                run_id: host_run_id.to_owned(),
                join_id: remote.join_id().to_owned(),
                demos: run_dir.join("demos.jsonl"),
            };
            std::thread::Builder::new()
                .name("expert-host".to_owned())
                .spawn(move || {
                    let r = forward(&me, inbox, &up, &stop, &heard, &orders_tx, ready_tx);
                    if let Err(e) = &r {
                        warn!("the expert host's bridge stopped: {e}");
                    }
                    r
                })
                .expect("a thread starts")
        };
        let _ = ready_rx.recv_timeout(Duration::from_secs(10));
        let token = if announce {
            Some(
                session
                    .liveliness()
                    .declare_token(keys::member(&run_id, remote.join_id()))
                    .wait()
                    .map_err(zenoh_error)?,
            )
        } else {
            None
        };
        Ok(Self {
            stop,
            post,
            orders,
            thread: Some(thread),
            heard,
            _token: token,
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
        self.heard.silence()
    }

    /// Whether the bridge's thread ended (an error, said in the log).
    pub fn ended(&self) -> bool {
        self.thread.as_ref().is_none_or(|t| t.is_finished())
    }

    /// Stops forwarding (after what is under way) and leaves the run.
    pub fn stop(mut self) -> Result<()> {
        self.halt()
    }

    fn halt(&mut self) -> Result<()> {
        self.stop.store(true, Ordering::Relaxed);
        let r = worker::join(&mut self.thread, "expert host");
        if let Some(t) = self._token.take() {
            let _ = t.undeclare().wait();
        }
        r
    }
}

impl Drop for ExpertHost {
    fn drop(&mut self) {
        let _ = self.halt();
    }
}

/// Who this host is.
struct Me {
    run_id: String,
    join_id: String,
    demos: PathBuf,
}

/// The bridge's thread: blocks on its own doorbell (zenoh delivered something), the
/// launcher's (the expert reports) and the actors' (the expert answered).
#[allow(clippy::too_many_arguments)]
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
    let mut control = wire.control_sender()?;
    let progress = wire.progress_receiver()?;
    let model = wire.demo_model_receiver()?;
    let expert = wire.bell(Doorbell::Expert)?;
    let mut clients: HashMap<u32, QueryClient<'_>> = HashMap::new();
    let mut pending: HashMap<u32, (PendingQuery<'_>, u64)> = HashMap::new();
    // The generations the run gave this host's expert.
    let mut mine: HashSet<u16> = HashSet::new();
    let mut bytes = Vec::new();
    let put = |f: &Frame| -> Result<()> {
        up.put(frame::encode(SCHEMA_VERSION, f)?)
            .wait()
            .map_err(zenoh_error)
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
            let b = match mail {
                Mail::Frame(b) => b,
                Mail::Exited {
                    generation,
                    how,
                    code,
                } => {
                    exits.push(Frame::ExpertExited {
                        generation,
                        how,
                        code,
                    });
                    continue;
                }
                Mail::Joined | Mail::Order(_) | Mail::Left(_) => continue,
            };
            let f = match frame::decode::<Frame>(SCHEMA_VERSION, &b) {
                Ok(f) => f,
                Err(e) => {
                    warn!("frame from the learner's host dropped: {e}");
                    continue;
                }
            };
            let done = match f {
                Frame::Control(c) => {
                    heard.beat();
                    control.forward(c)
                }
                Frame::Order(ExpertOrder::Start {
                    join_id,
                    generation,
                    name,
                }) if join_id == me.join_id => {
                    if mine.insert(generation) {
                        info!(generation, expert = %name, "the run takes this host's expert");
                        let _ = orders.send(ExpertHostOrder::Start { generation, name });
                    }
                    continue;
                }
                Frame::Order(ExpertOrder::Kill { generation }) if mine.contains(&generation) => {
                    let _ = orders.send(ExpertHostOrder::Kill { generation });
                    continue;
                }
                Frame::Order(ExpertOrder::Refuse { join_id, why }) if join_id == me.join_id => {
                    let _ = orders.send(ExpertHostOrder::Refused(why));
                    continue;
                }
                Frame::DemoLog { generation, text } if mine.contains(&generation) => {
                    // Before the control message that makes it active (one publisher, in order).
                    crate::demos::replace(&me.demos, &text)?;
                    debug!(generation, bytes = text.len(), "the run's demos.jsonl");
                    continue;
                }
                Frame::Query(q) if !mine.is_empty() => {
                    let client = match clients.entry(q.actor) {
                        std::collections::hash_map::Entry::Occupied(o) => o.into_mut(),
                        std::collections::hash_map::Entry::Vacant(v) => {
                            v.insert(wire.query_client()?)
                        }
                    };
                    // A newer query of the same actor replaces the older one (it gave up).
                    pending.insert(q.actor, (client.ask(q)?, q.header.seq));
                    Ok(())
                }
                _ => continue,
            };
            match done {
                Ok(()) => {
                    expert.ring()?;
                }
                Err(e @ WireError::SchemaMismatch { .. }) => warn!("{e}; dropped"),
                Err(e) => return Err(e.into()),
            }
        }
        // Up, in the order the expert did things: its status reports are taken first and sent
        // last, so an `exiting` never overtakes an answer sent before it; the model before the
        // answers (the actor shapes the step it asked about with it, as on one host).
        let mut reports = Vec::new();
        loop {
            match progress.receive() {
                Ok(Some(p)) => reports.push(p),
                Ok(None) => break,
                Err(e @ WireError::SchemaMismatch { .. }) => warn!("{e}; dropped"),
                Err(e) => return Err(e.into()),
            }
        }
        let mut answers = Vec::new();
        pending.retain(|&actor, (p, seq)| match p.poll() {
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
        // Up in the order the expert wrote them (the pending map has no order): the learner's
        // host appends a demonstration only as its file's next line, so one sent ahead of its
        // predecessor would be refused, and every one after it.
        answers.sort_by_key(|r| (r.outcome == outcome::ANSWERED, r.demo_index));
        if let Some(h) = model.latest_into(&mut bytes)? {
            if mine.contains(&(h.expert as u16)) {
                put(&Frame::DemoModel(h, bytes.clone()))?;
            }
        }
        for r in answers {
            let demo = if r.outcome == outcome::ANSWERED {
                let text = crate::demos::read(&me.demos)?;
                match text.lines().nth(r.demo_index as usize) {
                    Some(line) => Some(line.to_owned()),
                    None => {
                        warn!(
                            index = r.demo_index,
                            "an answer without its demonstration; dropped"
                        );
                        continue;
                    }
                }
            } else {
                None
            };
            put(&Frame::ExpertAnswer(r, demo))?;
        }
        for p in reports {
            put(&Frame::Progress(p))?;
        }
        for f in exits {
            if let Frame::ExpertExited { generation, .. } = &f {
                mine.remove(generation);
            }
            put(&f)?;
        }
        control.update_connections()?;
        if last {
            return Ok(());
        }
    }
}
