//! `alfd-bench-ipc`: speed of the runtime's wire between two real processes (this binary starts a
//! copy of itself as the peer): expert query round trip (busy-polling, and blocking on doorbells
//! as the actor and the expert do), transitions per second from an actor to the learner under the
//! credit protocol, and the latency of a weight broadcast of the K = 2 network (4,740 `f32`).
//!
//! With `--zenoh`, the query round trip (blocking) and the transitions go across hosts as a run
//! across hosts does, on loopback: the actor side in a mirror (its own run id), the expert or
//! learner side behind a hub, the two bridges (`alfd_bridge`) in this process, joined over
//! zenoh TCP on 127.0.0.1.
//!
//! Prints one JSON object; `deploy/bench/runtime.sh` writes the numbers, with the machine, for
//! `BENCHMARKS.md`.

use std::process::{Child, Command};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use alfd_common::replay::Transition;
use alfd_wire::{
    self as wire, command, process_state, progress_kind, Control, ControlWatch, Credits, Doorbell,
    Process, Progress, QueryRequest, QueryResponse, Role, Sender, TransitionBatch, Waiter, Wake,
    Wire, SCHEMA_VERSION, TRANSITIONS_PER_BATCH,
};
use anyhow::{bail, Context as _};

/// Parameters of the K = 2 network: 4 → 64 → 64 → 2·2.
const WEIGHTS_LEN: usize = 4 * 64 + 64 + 64 * 64 + 64 + 64 * 4 + 4;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Bench {
    QueryPoll,
    QueryBlock,
    Transitions,
    Weights,
}

impl Bench {
    fn name(self) -> &'static str {
        match self {
            Bench::QueryPoll => "query-poll",
            Bench::QueryBlock => "query-block",
            Bench::Transitions => "transitions",
            Bench::Weights => "weights",
        }
    }

    fn from_name(s: &str) -> anyhow::Result<Self> {
        Ok(match s {
            "query-poll" => Bench::QueryPoll,
            "query-block" => Bench::QueryBlock,
            "transitions" => Bench::Transitions,
            "weights" => Bench::Weights,
            other => bail!("unknown benchmark {other}"),
        })
    }
}

fn main() -> anyhow::Result<()> {
    wire::quiet_transport_logs();
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("peer") {
        let bench = Bench::from_name(args.get(2).context("peer needs a benchmark")?)?;
        let run_id = args.get(3).context("peer needs a run id")?;
        let n: usize = args.get(4).context("peer needs a count")?.parse()?;
        let ring = args.get(5).map(String::as_str) == Some("ring");
        return peer(bench, run_id, n, ring);
    }
    let zenoh = args.get(1).map(String::as_str) == Some("--zenoh");
    let scale: f64 = std::env::var("ALFD_BENCH_SCALE")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.0);
    let n = |base: f64| ((base * scale) as usize).max(100);
    let mut out = serde_json::Map::new();
    let benches = if zenoh {
        vec![
            (Bench::QueryBlock, n(2_000.0)),
            (Bench::Transitions, n(1_000_000.0)),
        ]
    } else {
        vec![
            (Bench::QueryPoll, n(50_000.0)),
            (Bench::QueryBlock, n(5_000.0)),
            (Bench::Transitions, n(3_000_000.0)),
            (Bench::Weights, n(10_000.0)),
        ]
    };
    for (bench, count) in benches {
        let result = measure(bench, count, zenoh)?;
        eprintln!("{}: {result}", bench.name());
        out.insert(bench.name().to_owned(), result);
    }
    println!("{}", serde_json::Value::Object(out));
    Ok(())
}

/// Runs one benchmark: this process is the actor side (or the subscriber), the peer the other.
/// Across hosts (`zenoh`), the actor side is in a mirror: this process's for the query, the
/// peer's for the transitions.
fn measure(bench: Bench, n: usize, zenoh: bool) -> anyhow::Result<serde_json::Value> {
    let run_id = format!("bench-{}-{}", std::process::id(), bench.name());
    let mirror_id = format!("{run_id}-m");
    let result = {
        let me = Wire::connect(&run_id, Process::new(Role::Launcher, 0), SCHEMA_VERSION)?;
        let bridges = if zenoh {
            Some(bridges(&run_id, &mirror_id)?)
        } else {
            None
        };
        let peer_run = if zenoh && bench == Bench::Transitions {
            &mirror_id
        } else {
            &run_id
        };
        let mut control = me.control_sender()?;
        control.send(Control {
            command: command::RUN,
            ..Control::default()
        })?;
        let progress = me.progress_receiver()?;
        let mut child = Command::new(std::env::current_exe()?)
            .args(["peer", bench.name(), peer_run, &n.to_string()])
            .args(zenoh.then_some("ring"))
            .spawn()
            .context("cannot start the peer")?;
        // The peer reports once its ports exist.
        let start = Instant::now();
        loop {
            control.send(Control {
                command: command::RUN,
                ..Control::default()
            })?;
            if progress.receive()?.is_some() {
                break;
            }
            if start.elapsed() > Duration::from_secs(20) {
                let _ = child.kill();
                bail!("the peer did not come up");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let actor_side = if zenoh {
            Some(Wire::connect(
                &mirror_id,
                Process::new(Role::Actor, 0),
                SCHEMA_VERSION,
            )?)
        } else {
            None
        };
        let result = match bench {
            Bench::QueryPoll => query(&me, n, false)?,
            Bench::QueryBlock => query(actor_side.as_ref().unwrap_or(&me), n, true)?,
            Bench::Transitions => transitions(&me, n, zenoh)?,
            Bench::Weights => weights(&me, n)?,
        };
        control.send(Control {
            command: command::SHUTDOWN,
            ..Control::default()
        })?;
        for bell in [Doorbell::Expert, Doorbell::Actor(0), Doorbell::Learner] {
            me.bell(bell)?.ring()?;
        }
        wait_child(&mut child)?;
        drop(actor_side);
        if let Some((hub, mirror)) = bridges {
            mirror.stop()?;
            hub.stop()?;
        }
        result
    };
    wire::close_run(&run_id)?;
    if zenoh {
        wire::close_run(&mirror_id)?;
    }
    Ok(result)
}

/// A hub on run `run_id` listening on a free port of 127.0.0.1, and a mirror of it as run
/// `mirror_id`, joined for one actor (id 0, incarnation 1).
fn bridges(
    run_id: &str,
    mirror_id: &str,
) -> anyhow::Result<(alfd_bridge::Hub, alfd_bridge::Mirror)> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    let endpoint = alfd_bridge::Endpoint::parse(
        &format!("tcp/127.0.0.1:{port}"),
        alfd_bridge::Security::Insecure,
    )?;
    let hub = alfd_bridge::Hub::start(alfd_bridge::HubOptions {
        endpoint: endpoint.clone(),
        run_id: run_id.to_owned(),
        local_actors: 0,
        first_incarnation: 1,
        max_restarts: 0,
        config_toml: String::new(),
        runtime_toml: String::new(),
        query_timeout: Duration::from_secs(1),
        // No remote expert in the benchmark: nothing is written there.
        demos_path: std::env::temp_dir().join(format!("alfd-bench-{run_id}-demos.jsonl")),
    })?;
    let remote = alfd_bridge::join(
        &endpoint,
        alfd_bridge::JoinRequest {
            join_id: format!("bench-{}", std::process::id()),
            host: "bench".to_owned(),
            actors: 1,
            expert: None,
        },
        Duration::from_secs(10),
        SCHEMA_VERSION,
    )?;
    let mirror = alfd_bridge::Mirror::start(remote, mirror_id)?;
    Ok((hub, mirror))
}

fn wait_child(child: &mut Child) -> anyhow::Result<()> {
    let start = Instant::now();
    loop {
        if let Some(s) = child.try_wait()? {
            anyhow::ensure!(s.success(), "the peer failed: {s}");
            return Ok(());
        }
        if start.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            bail!("the peer did not stop");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Percentiles of durations in microseconds.
fn percentiles(mut ns: Vec<u64>) -> serde_json::Value {
    ns.sort_unstable();
    let p = |q: f64| ns[((ns.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0;
    serde_json::json!({
        "samples": ns.len(),
        "p50_us": p(0.5),
        "p90_us": p(0.9),
        "p99_us": p(0.99),
        "p999_us": p(0.999),
        "max_us": p(1.0),
    })
}

/// Query round trips: send, wait for the answer (busy-polling, or blocking on the actors'
/// doorbell after ringing the expert's, as the actor process does).
fn query(me: &Wire, n: usize, block: bool) -> anyhow::Result<serde_json::Value> {
    let mut client = me.query_client(4)?;
    let expert = me.bell(Doorbell::Expert)?;
    let waiter = me.waiter(Doorbell::Actor(0))?;
    let state = [0.01f32, -0.02, 0.03, -0.04];
    let warmup = n / 10;
    let mut ns = Vec::with_capacity(n);
    for i in 0..n + warmup {
        let t = Instant::now();
        let mut pending = client.ask(&QueryRequest::new(0, 1, i as u64, &state)?)?;
        anyhow::ensure!(pending.servers() == 1, "no server");
        if block {
            expert.ring()?;
        }
        let answer = loop {
            if let Some(r) = pending.poll()? {
                break r;
            }
            if block && waiter.wait(Duration::from_millis(100))? == Wake::Signal {
                bail!("interrupted");
            }
        };
        let dt = t.elapsed();
        anyhow::ensure!(
            answer.request_seq == pending.seq(),
            "answer to another request"
        );
        if i >= warmup {
            ns.push(dt.as_nanos() as u64);
        }
    }
    Ok(percentiles(ns))
}

/// Transitions from the peer (an actor) under the credit protocol (window 64), learner side;
/// `ring`: the actor's doorbell is rung after each grant, as the learner rings an actor waiting
/// for credits (a hub sleeps until then).
fn transitions(me: &Wire, n: usize, ring: bool) -> anyhow::Result<serde_json::Value> {
    let rx = me.transitions_receiver()?;
    let mut credits = me.credits_sender()?;
    let actor = me.bell(Doorbell::Actor(0))?;
    let window = wire::MAX_CREDIT_WINDOW;
    let mut received = 0u64;
    let mut c = Credits::default();
    c.incarnation[0] = 1;
    c.granted[0] = window;
    credits.send(c)?;
    let mut start = None;
    while received < n as u64 {
        if let Some(b) = rx.receive()? {
            start.get_or_insert_with(Instant::now);
            received += b.len() as u64;
            c.received[0] = received;
            c.granted[0] = received + window;
            credits.send(c)?;
            if ring {
                actor.ring()?;
            }
        }
    }
    let secs = start.map_or(f64::NAN, |s| s.elapsed().as_secs_f64());
    Ok(serde_json::json!({
        "transitions": received,
        "seconds": secs,
        "transitions_per_s": received as f64 / secs,
        "batch": TRANSITIONS_PER_BATCH,
        "window": window,
    }))
}

/// Weight broadcasts of the K = 2 network; the latency from publishing to a copy in hand.
fn weights(me: &Wire, n: usize) -> anyhow::Result<serde_json::Value> {
    let rx = me.weights_receiver()?;
    let mut buf = Vec::with_capacity(WEIGHTS_LEN);
    let mut ns = Vec::with_capacity(n);
    let mut last = 0;
    let deadline = Instant::now() + Duration::from_secs(60);
    while ns.len() < n && Instant::now() < deadline {
        if let Some(h) = rx.latest_into(&mut buf)? {
            let now = unix_ns();
            anyhow::ensure!(buf.len() == WEIGHTS_LEN, "wrong length");
            if h.version > last && h.version > 100 {
                ns.push(now.saturating_sub(h.updates));
            }
            last = h.version;
        }
    }
    let mut v = percentiles(ns);
    v["floats"] = WEIGHTS_LEN.into();
    Ok(v)
}

fn unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// The other process of a benchmark; `ring`: the actor rings the learner's doorbell after each
/// batch, as `alfd-actor` does (a bridge sleeps until then).
fn peer(bench: Bench, run_id: &str, n: usize, ring: bool) -> anyhow::Result<()> {
    let role = match bench {
        Bench::QueryPoll | Bench::QueryBlock => Process::new(Role::Expert, 1),
        Bench::Transitions => Process::new(Role::Actor, 0),
        Bench::Weights => Process::new(Role::Learner, 0),
    };
    let me = Wire::connect(run_id, role, SCHEMA_VERSION)?;
    let waiter = me.waiter(match bench {
        Bench::QueryPoll | Bench::QueryBlock => Doorbell::Expert,
        Bench::Transitions => Doorbell::Actor(0),
        Bench::Weights => Doorbell::Learner,
    })?;
    let mut control = ControlWatch::new(&me)?;
    control.handshake(&waiter, Duration::from_secs(10))?;
    let progress = me.progress_sender()?;
    let mut side = PeerSide {
        progress,
        control,
        waiter,
    };
    match bench {
        Bench::QueryPoll | Bench::QueryBlock => {
            answer_queries(&me, &mut side, bench == Bench::QueryBlock)
        }
        Bench::Transitions => send_transitions(&me, &mut side, n, ring),
        Bench::Weights => broadcast_weights(&me, &mut side),
    }
}

/// What the peer holds in every benchmark once connected (dropped in this order).
struct PeerSide<'w> {
    progress: Sender<'w, Progress>,
    control: ControlWatch<'w>,
    waiter: Waiter,
}

impl PeerSide<'_> {
    /// Tells the measuring process that the peer is running.
    fn ready(&mut self) -> anyhow::Result<()> {
        self.progress.send(Progress {
            kind: progress_kind::STATUS,
            state: process_state::RUNNING,
            ..Progress::default()
        })?;
        Ok(())
    }
}

/// The expert's side of the query benchmarks: answers every query until shut down; `block`:
/// rings the actor after answering and sleeps on the expert's doorbell between rounds.
fn answer_queries(me: &Wire, side: &mut PeerSide<'_>, block: bool) -> anyhow::Result<()> {
    let server = me.query_server()?;
    let actors = me.bell(Doorbell::Actor(0))?;
    side.ready()?;
    while !side.control.shutdown_requested() {
        let mut answered = false;
        while let Some(q) = server.receive()? {
            q.answer(QueryResponse {
                outcome: wire::outcome::ANSWERED,
                action: 1,
                ..QueryResponse::default()
            })?;
            answered = true;
        }
        if answered && block {
            actors.ring()?;
        }
        if block {
            side.waiter.wait(Duration::from_millis(100))?;
        }
        side.control.poll()?;
    }
    Ok(())
}

/// The actor's side of the transitions benchmark: sends `n` transitions in batches as the
/// learner's credits allow (ringing the learner after each with `ring`), then waits for the
/// shutdown.
fn send_transitions(
    me: &Wire,
    side: &mut PeerSide<'_>,
    n: usize,
    ring: bool,
) -> anyhow::Result<()> {
    let mut tx = me.transitions_sender(4, 2)?;
    let credits = me.credits_receiver()?;
    let learner = me.bell(Doorbell::Learner)?;
    side.ready()?;
    let t = Transition {
        state: vec![0.1, 0.2, 0.3, 0.4],
        action: 1,
        reward: 1.0,
        next_state: vec![0.2, 0.3, 0.4, 0.5],
        terminated: false,
        mask: vec![1.0, 0.0],
        demo: false,
        horizon: 1,
    };
    let mut sent = 0u64;
    let mut granted = 0u64;
    let mut since_poll = 0u32;
    while sent < n as u64 && !side.control.shutdown_requested() {
        if let Some(c) = credits.latest()? {
            granted = c.granted_for(0, 1).unwrap_or(granted);
        }
        if sent + TRANSITIONS_PER_BATCH as u64 <= granted {
            let mut b = TransitionBatch::new(0, 1, 4, 2, sent)?;
            for _ in 0..TRANSITIONS_PER_BATCH {
                b.push(&t)?;
            }
            tx.send(&b)?;
            if ring {
                learner.ring()?;
            }
            sent += TRANSITIONS_PER_BATCH as u64;
        }
        since_poll += 1;
        if since_poll > 10_000 {
            side.control.poll()?;
            since_poll = 0;
        }
    }
    while !side.control.shutdown_requested() {
        side.waiter.wait(Duration::from_millis(20))?;
        side.control.poll()?;
    }
    Ok(())
}

/// The learner's side of the weights benchmark: broadcasts the weights every 100 µs until shut
/// down.
fn broadcast_weights(me: &Wire, side: &mut PeerSide<'_>) -> anyhow::Result<()> {
    let mut tx = me.weights_sender(WEIGHTS_LEN)?;
    side.ready()?;
    let w: Vec<f32> = (0..WEIGHTS_LEN).map(|i| i as f32 * 1e-3).collect();
    let mut version = 0u64;
    while !side.control.shutdown_requested() {
        version += 1;
        tx.publish(version, unix_ns(), 0, &[&w])?;
        // One broadcast every 100 µs, about the learner's pace.
        let t = Instant::now();
        while t.elapsed() < Duration::from_micros(100) {
            std::hint::spin_loop();
        }
        if version.is_multiple_of(100) {
            side.control.poll()?;
        }
    }
    Ok(())
}
