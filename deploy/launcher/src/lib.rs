//! The launcher of a multi-process run: starts the learner, the expert and N actors as separate OS
//! processes under one run id (with its own iceoryx2 prefix), shows progress, writes the run
//! directory, restarts crashed actors, carries out expert swaps, and stops everything cleanly.
//!
//! # Expert swap (make before break)
//! `alfd swap-expert` drops `swap-expert.request.json` into the run directory; the launcher
//! 1. starts the new expert (generation g + 1); it loads its demonstrator, checks `demos.jsonl`,
//!    joins the run and reports `standby` (a new expert that fails here leaves the run untouched);
//! 2. announces generation g + 1 as the newest: the old expert stops answering and exits;
//! 3. once the old process has exited, makes the new one active: it reads `demos.jsonl` back
//!    (budget left, demonstration set, model) and answers from then on;
//! 4. writes `swap-expert.response.json`.
//!
//! Only the active expert answers, and it is made active only after its predecessor exited, so
//! no demonstration is counted twice and the budget is never exceeded. Queries asked in the short
//! gap go unanswered and the actors act on their own.
//!
//! # Faults
//! - An actor that dies is restarted as a new incarnation (up to `--max-restarts` per actor).
//! - An expert that dies is restarted as a new generation, like a swap without the old one: it
//!   reads `demos.jsonl` back, so the budget and the demonstrations carry over; meanwhile the
//!   actors act on their own (up to `--max-restarts` expert restarts). The decisions are in
//!   [`ExpertLifecycle`].
//! - A learner that dies is restarted from its last checkpoint (`RUN_DIR/learner.ckpt`, every
//!   `checkpoint_every` updates) while the actors wait for credits; what it learned since that
//!   checkpoint is lost (up to `--max-restarts` learner restarts).
//! - A launcher that dies is noticed at once by its children (re-parented): the learner saves
//!   its weights and checkpoint, everyone exits, and the learner, last out, removes the run's
//!   iceoryx2 files; `alfd resume RUN_DIR` continues the run.
//! - Stray signals (SIGCONT, SIGTSTP, ...) stop no process: the launcher and its children are
//!   caught by iceoryx2's handler, and only SIGINT/SIGTERM count. Ctrl-Z (SIGTSTP) is therefore
//!   ignored by the launcher (the children, in process groups of their own, never see it): the
//!   run goes on; Ctrl-C stops it cleanly.

mod bar;
mod children;
mod episodes;
mod error;
pub mod expert_lifecycle;
mod experts;
mod finish;
#[cfg(feature = "hosts")]
mod remote;
#[cfg(not(feature = "hosts"))]
#[path = "remote_off.rs"]
mod remote;

use std::collections::{HashMap, VecDeque};
use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use alfd_common::config::ExperimentConfig;
use alfd_common::record::{mean_return_last_50, EpisodeRecord, RunSummary, RuntimeSummary};
use alfd_harness::{RuntimeConfig, What as _, RUNTIME_FILE};
use alfd_wire::{
    self as wire, command, process_state, progress_kind, ActorBells, Bell, Control, Doorbell,
    Process, Progress, Role, Wake, Wire, WireError, CONTROL_PERIOD,
};
use serde::{Deserialize, Serialize};
use tracing::{debug, info, warn};

use alfd_common::restarts::{Ended, Restarts, Verdict};
use bar::{demo_troubles, progress_bar};
use children::{describe, last_error, pin, proc_binary, RateMeter};
use episodes::{open_episodes, shares, Arrivals, EpisodeLog, Row};
use error::{bail, ensure};
use expert_lifecycle::{Action, Exit, ExpertLifecycle};

pub use children::{describe as describe_status, find_process};
pub use error::{LaunchError, Result};
/// Where `--listen` takes other hosts' actors: `alfd_bridge::Endpoint`, or, in a build without
/// the `hosts` feature, a type with no value (no run there listens).
pub use remote::Endpoint;

/// The launcher's own processes whose restarts it counts (the expert's are the lifecycle's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Supervised {
    Actor(u16),
    Learner,
}

/// Everything a launch needs.
#[derive(Debug, Clone)]
pub struct Plan {
    pub cfg: ExperimentConfig,
    pub actors: usize,
    pub run_dir: PathBuf,
    pub run_id: String,
    /// The runtime settings every process reads (`runtime.toml`).
    pub runtime: RuntimeConfig,
    /// Restarts allowed per actor, and of the expert, before the run fails.
    pub max_restarts: u32,
    pub progress: bool,
    /// Pin the learner to CPU 0 and the other processes to the other CPUs (with `taskset`).
    pub pin: bool,
    /// Where `alfd-learner`, `alfd-actor` and `alfd-expert` are.
    pub bin_dir: PathBuf,
    /// Continue the run in `run_dir` (`alfd resume`): the learner from its checkpoint, the
    /// expert from `demos.jsonl`, `episodes.csv` appended to.
    pub resume: bool,
    /// Which launcher of the run this is (1, plus one per resume).
    pub launches: u32,
    /// The run ids of the run's earlier launches (`alfd resume`), oldest first: what their
    /// processes left is removed when this launch ends.
    pub earlier_run_ids: Vec<String>,
    /// A resumed run: the global step of the state in `actor-<id>.ckpt` each actor id starts
    /// from (`alfd-actor --restore-step`); none: a fresh actor.
    pub restore_actors: Vec<Option<u64>>,
    /// Take actors from other hosts too (`--listen`, see `alfd_bridge` and `remote.rs`); such a
    /// run has no per-actor episode shares: every actor plays to the run's limit.
    pub listen: Option<Endpoint>,
}

impl Plan {
    fn first_incarnation(&self) -> u64 {
        u64::from(self.launches.max(1) - 1) * INCARNATIONS_PER_LAUNCH + 1
    }
}

/// What `run.json` records: how to reach a live run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunInfo {
    pub run_id: String,
    pub prefix: String,
    pub launcher_pid: u32,
    pub actors: usize,
    pub schema_version: u32,
    /// Launchers this run has had: 1, plus one per `alfd resume`.
    #[serde(default = "one")]
    pub launches: u32,
    /// Restarts allowed per actor, of the expert and of the learner (`--max-restarts`), kept
    /// by `alfd resume`.
    #[serde(default = "default_max_restarts")]
    pub max_restarts: u32,
    /// The run ids of the run's earlier launches, oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub earlier_run_ids: Vec<String>,
}

fn one() -> u32 {
    1
}

pub use alfd_harness::DEFAULT_MAX_RESTARTS;

fn default_max_restarts() -> u32 {
    DEFAULT_MAX_RESTARTS
}

/// Incarnation numbers of the actors of a run's n-th launcher start at `(n - 1) ×` this `+ 1`,
/// so that a resumed run's actors draw new seed streams.
pub const INCARNATIONS_PER_LAUNCH: u64 = 1_000_000;

pub use crate::expert_lifecycle::SwapRequest;

/// `swap-expert.response.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SwapResponse {
    pub id: String,
    pub ok: bool,
    pub message: String,
    pub from: String,
    pub to: String,
    pub generation: u32,
    /// Episodes recorded when the new expert became active.
    pub at_episode: u64,
}

pub const SWAP_REQUEST: &str = "swap-expert.request.json";
pub const SWAP_RESPONSE: &str = "swap-expert.response.json";

#[derive(Debug, Clone, PartialEq, Eq)]
enum Kind {
    Learner { incarnation: u32 },
    Expert { generation: u16, name: String },
    Actor { id: u16, incarnation: u64 },
}

/// One child process.
#[derive(Debug)]
struct Proc {
    name: String,
    kind: Kind,
    child: Child,
}

/// The latest status of each process, as reported on `progress`.
#[derive(Debug, Default)]
struct Seen {
    learner_state: u32,
    learner_env_steps: u64,
    learner_updates: u64,
}

/// A run id: the time and the launcher's pid, `r<unix seconds>-<pid>`.
pub fn new_run_id() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    format!("r{secs}-{}", std::process::id())
}

/// Where the process binaries are: `ALFD_BIN_DIR`, else next to the running `alfd`.
pub fn bin_dir() -> Result<PathBuf> {
    if let Some(d) = std::env::var_os("ALFD_BIN_DIR") {
        return Ok(PathBuf::from(d));
    }
    let exe =
        std::env::current_exe().what(|| "cannot locate the running alfd binary".to_owned())?;
    match exe.parent() {
        Some(dir) => Ok(dir.to_owned()),
        None => bail!("the alfd binary has no parent directory"),
    }
}

/// Runs the plan to the end (or to Ctrl-C); an error names the process that failed.
pub fn launch(plan: &Plan) -> Result<RunSummary> {
    for bin in ["alfd-learner", "alfd-actor", "alfd-expert"] {
        let p = plan.bin_dir.join(bin);
        ensure!(
            p.is_file(),
            "{bin} not found in {} (build every binary: `cargo build --release`, or use deploy/run.sh)",
            plan.bin_dir.display()
        );
    }
    std::fs::create_dir_all(&plan.run_dir)
        .what(|| format!("cannot create run directory {}", plan.run_dir.display()))?;
    if !plan.resume {
        write_patiently(&plan.run_dir, "config.toml", plan.cfg.to_toml().as_bytes())?;
    }
    write_patiently(
        &plan.run_dir,
        RUNTIME_FILE,
        plan.runtime.to_toml().as_bytes(),
    )?;
    let info = RunInfo {
        run_id: plan.run_id.clone(),
        prefix: wire::run_prefix(&plan.run_id),
        launcher_pid: std::process::id(),
        actors: plan.actors,
        schema_version: wire::SCHEMA_VERSION,
        launches: plan.launches,
        max_restarts: plan.max_restarts,
        earlier_run_ids: plan.earlier_run_ids.clone(),
    };
    write_patiently(
        &plan.run_dir,
        "run.json",
        serde_json::to_string_pretty(&info)?.as_bytes(),
    )?;
    let _ = std::fs::remove_file(plan.run_dir.join(SWAP_REQUEST));
    let _ = std::fs::remove_file(plan.run_dir.join(SWAP_RESPONSE));

    let result = {
        let wire = Wire::connect(
            &plan.run_id,
            Process::new(Role::Launcher, 0),
            wire::SCHEMA_VERSION,
        )
        .what(|| "cannot create the run's iceoryx2 node".to_owned())?;
        let mut launcher = Launcher::new(plan, &wire)?;
        let result = launcher.run();
        // Whatever happened, no child outlives the launcher.
        launcher.stop_all();
        result
    };
    // Every process of the run is gone: remove what iceoryx2 keeps per prefix, and what a child
    // killed while it created its node left.
    match wire::close_dead_run(&plan.run_id) {
        Ok(wire::Cleaned::Live(nodes)) => warn!(?nodes, "processes of the run are still alive"),
        Ok(wire::Cleaned::Removed(_)) => {}
        Err(e) => warn!("cannot close the run's iceoryx2 resources: {e}"),
    }
    let left = wire::leftover_files(&plan.run_id);
    if !left.is_empty() {
        warn!(files = ?left, "iceoryx2 files left behind");
    }
    // A child started just before its launcher died gives up at its handshake timeout.
    let patience = plan.runtime.handshake_timeout() + Duration::from_secs(10);
    clean_earlier_launches(&plan.earlier_run_ids, patience);
    result
}

/// Removes what the processes of the run's earlier launches left: `alfd resume` cleans the
/// launch before it as it starts, but a process of a killed launcher that comes up (or is
/// killed) after that cleaning leaves files that only this removes. A launch whose processes
/// still live is waited for, up to `patience` in all (a child started just before its launcher
/// was killed lives until its handshake times out), then left alone with a warning.
fn clean_earlier_launches(run_ids: &[String], patience: Duration) {
    let deadline = Instant::now() + patience;
    for id in run_ids.iter().filter(|id| wire::is_launcher_run_id(id)) {
        loop {
            match wire::clean_run(id) {
                Ok(wire::Cleaned::Live(_)) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(200));
                }
                Ok(wire::Cleaned::Live(nodes)) => {
                    warn!(run_id = %id, ?nodes, "an earlier launch's processes are still alive");
                    break;
                }
                Ok(wire::Cleaned::Removed(files)) => {
                    if !files.is_empty() {
                        info!(run_id = %id, files = files.len(), "removed what an earlier launch left");
                    }
                    break;
                }
                Err(e) => {
                    warn!(run_id = %id, "cannot remove what an earlier launch left: {e}");
                    break;
                }
            }
        }
    }
}

struct Launcher<'a, 'w> {
    plan: &'a Plan,
    control: Control,
    control_tx: wire::Sender<'w, Control>,
    progress_rx: wire::Receiver<'w, Progress>,
    waiter: wire::Waiter,
    bells: [Bell; 2],
    actor_bells: ActorBells<'w>,
    procs: Vec<Proc>,
    seen: Seen,
    csv: EpisodeLog,
    /// The run's TensorBoard scalars (`RUN_DIR/tb/`).
    board: alfd_harness::tensorboard::Board,
    recorded: u64,
    /// Episode records that never arrived (their numbers show them).
    arrivals: Arrivals,
    returns: VecDeque<f64>,
    all_returns: Vec<f64>,
    /// Demonstrations used, as the actors reported them with their episodes (monotone).
    demos_used: u32,
    /// Demonstrations answered, as the active expert reports them (for the progress bar only:
    /// its reports arrive in no fixed order with the actors' episodes).
    demos_answered: u64,
    /// The most demonstrations any expert counted in the run (each counts what it read back
    /// and what it wrote): `demos.jsonl` must hold at least these at the end.
    demos_experts_wrote: u64,
    /// Per expert generation, its answers with a demonstration that came after their actor
    /// stopped waiting (the newest count it reported).
    answers_late: HashMap<u16, u32>,
    /// What the hub counted (lines of remote experts not taken, late answers), last read.
    hub_counts: (u64, u64),
    /// The newest incarnation of each actor id that recorded an episode (0: none yet).
    incarnations: [u64; alfd_wire::MAX_ACTORS],
    /// The restarts of the actors and the learner.
    restarts: Restarts<Supervised>,
    /// Restarts of remote actors by their hosts (the run's roster counts them per id).
    remote_restarts: u32,
    /// Episodes each actor id is to play (a run with an episode limit), and has recorded.
    quota: Option<[u32; alfd_wire::MAX_ACTORS]>,
    recorded_by: [u32; alfd_wire::MAX_ACTORS],
    /// Per actor id: the steps of its recorded episodes, all incarnations and launches (ε's
    /// clock for an incarnation that takes over).
    explored: [u64; alfd_wire::MAX_ACTORS],
    /// The expert generations: swaps and restarts.
    experts: ExpertLifecycle,
    /// The restarts and swaps last written to the TensorBoard file (see [`Launcher::mark_events`]).
    marked: Option<[u32; 4]>,
    started: Instant,
    /// When the actors were started (rates are measured from here).
    running_since: Instant,
    last_control: Instant,
    bar: indicatif::ProgressBar,
    rate: RateMeter,
    /// The bridge to other hosts (`--listen`), once the learner is up.
    hub: Option<remote::Hub>,
    /// Remote hosts that joined, and that left or dropped (their links).
    remote_joins: u32,
    remote_losses: u32,
    /// Expert generations served by remote hosts (`alfd join --expert`).
    remote_experts: remote::RemoteExperts,
    /// The newest expert generation whose human page's address was printed.
    human_page_shown: u16,
}

impl<'a, 'w> Launcher<'a, 'w> {
    fn new(plan: &'a Plan, wire: &'w Wire) -> Result<Self> {
        let control = Control {
            command: command::RUN,
            active_expert: 0,
            newest_expert: 1,
            ..Control::default()
        };
        let mut control_tx = wire.control_sender()?;
        control_tx.send(control)?;
        let (csv, earlier) = open_episodes(&plan.run_dir, plan.resume)?;
        let demos_before = earlier.last().map_or(0, |r| r.demos_used);
        let all_returns: Vec<f64> = earlier.iter().map(|r| r.ret).collect();
        let explored = explored_steps(&earlier);
        let quota = plan
            .cfg
            .episode_limit()
            .filter(|_| plan.listen.is_none())
            .map(|n| {
                shares(
                    u64::from(n).saturating_sub(all_returns.len() as u64),
                    plan.actors,
                )
            });
        let bar = progress_bar(plan);
        Ok(Self {
            plan,
            control,
            control_tx,
            progress_rx: wire.progress_receiver()?,
            waiter: wire.waiter(Doorbell::Launcher)?,
            bells: [wire.bell(Doorbell::Learner)?, wire.bell(Doorbell::Expert)?],
            actor_bells: ActorBells::new(wire),
            procs: Vec::new(),
            seen: Seen::default(),
            csv: EpisodeLog::new(csv, plan.run_dir.join("episodes.csv")),
            board: alfd_harness::tensorboard::Board::open(&plan.run_dir, "launcher", &plan.cfg),
            recorded: all_returns.len() as u64,
            arrivals: Arrivals::default(),
            returns: all_returns.iter().rev().take(20).rev().copied().collect(),
            all_returns,
            demos_used: demos_before,
            demos_answered: 0,
            demos_experts_wrote: 0,
            answers_late: HashMap::new(),
            hub_counts: (0, 0),
            incarnations: [0; alfd_wire::MAX_ACTORS],
            restarts: Restarts::new(plan.max_restarts),
            marked: None,
            remote_restarts: 0,
            quota,
            recorded_by: [0; alfd_wire::MAX_ACTORS],
            explored,
            experts: ExpertLifecycle::new(plan.max_restarts),
            started: Instant::now(),
            running_since: Instant::now(),
            last_control: Instant::now(),
            bar,
            rate: RateMeter::default(),
            hub: None,
            remote_joins: 0,
            remote_losses: 0,
            remote_experts: remote::RemoteExperts::default(),
            human_page_shown: 0,
        })
    }

    fn run(&mut self) -> Result<RunSummary> {
        info!(run_id = %self.plan.run_id, actors = self.plan.actors, "run starting");
        self.spawn(Kind::Learner { incarnation: 1 })?;
        let first = self
            .experts
            .start(&self.plan.cfg.run_expert_name(), Instant::now());
        self.apply(first)?;
        // The learner and the expert are up (the expert active) before the first actor asks
        // anything.
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if self.tick()? == Wake::Signal {
                return Ok(self.summary(true));
            }
            self.check_children()?;
            self.check_swap()?;
            if self.seen.learner_state == process_state::RUNNING && self.experts.settled() {
                break;
            }
            ensure!(
                Instant::now() < deadline,
                "the learner and the expert did not come up within 60 s (see learner.log, expert-1.log)"
            );
        }
        self.running_since = Instant::now();
        if let Some(endpoint) = &self.plan.listen {
            self.hub = Some(self.start_hub(endpoint)?);
        }
        let first = self.plan.first_incarnation();
        for id in 0..self.plan.actors as u16 {
            if self.episodes_left(id) != Some(0) {
                self.spawn(Kind::Actor {
                    id,
                    incarnation: first,
                })?;
            }
        }
        let interrupted = loop {
            if self.tick()? == Wake::Signal {
                break true;
            }
            self.check_children()?;
            self.check_swap()?;
            self.mark_events();
            if self.done() {
                break false;
            }
        };
        self.shutdown()?;
        self.bar.finish_and_clear();
        Ok(self.summary(interrupted))
    }

    /// The run's restarts and swaps as TensorBoard scalars (`run/actor_restarts`,
    /// `run/learner_restarts`, `run/expert_restarts`, `run/expert_swaps`) at the global step,
    /// written when one changes (and once at the start): the watch page marks them on its axes.
    fn mark_events(&mut self) {
        let counts = [
            self.restarts.total() - self.restarts.of(&Supervised::Learner) + self.remote_restarts,
            self.restarts.of(&Supervised::Learner),
            self.experts.restarts(),
            self.experts.swaps(),
        ];
        if self.marked == Some(counts) {
            return;
        }
        self.marked = Some(counts);
        let tags = [
            "run/actor_restarts",
            "run/learner_restarts",
            "run/expert_restarts",
            "run/expert_swaps",
        ];
        let values: Vec<(String, f32)> = tags
            .iter()
            .zip(counts)
            .map(|(t, n)| ((*t).to_owned(), n as f32))
            .collect();
        self.board.scalars(self.seen.learner_env_steps, &values);
    }

    /// Waits for news (at most 100 ms), takes in progress, keeps the heartbeat going.
    fn tick(&mut self) -> Result<Wake> {
        let wake = self.waiter.wait(Duration::from_millis(100))?;
        self.drain_progress()?;
        self.csv.flush();
        self.check_hub()?;
        if self.last_control.elapsed() >= CONTROL_PERIOD {
            self.publish_control()?;
        }
        self.show();
        Ok(wake)
    }

    fn publish_control(&mut self) -> Result<()> {
        self.control_tx.send(self.control)?;
        for b in &self.bells {
            b.ring()?;
        }
        self.actor_bells.ring_all(self.plan.actors)?;
        self.last_control = Instant::now();
        Ok(())
    }

    fn drain_progress(&mut self) -> Result<()> {
        loop {
            let p = match self.progress_rx.receive() {
                Ok(Some(p)) => p,
                Ok(None) => return Ok(()),
                Err(e @ WireError::SchemaMismatch { .. }) => {
                    warn!("{e}; progress message dropped");
                    continue;
                }
                Err(e) => return Err(e.into()),
            };
            let role = Role::from_u16(p.header.role);
            match (p.kind, role) {
                (progress_kind::EPISODE, Some(Role::Actor)) => {
                    let lost = self
                        .arrivals
                        .arrive(p.header.id, p.incarnation, p.header.seq);
                    self.note_lost(&p, lost);
                    self.record_episode(&p)?;
                }
                (progress_kind::SHARE_PLAYED, Some(Role::Actor)) => {
                    let sent = p.episodes_sent();
                    let lost = self.arrivals.played(p.header.id, p.incarnation, sent);
                    self.note_lost(&p, lost);
                }
                (progress_kind::STATUS, Some(Role::Learner)) => {
                    self.seen.learner_state = p.state;
                    self.seen.learner_env_steps = p.env_steps;
                    self.seen.learner_updates = p.updates;
                    self.rate.observe(p.env_steps, p.updates);
                }
                (progress_kind::STATUS, Some(Role::Expert)) => {
                    debug!(
                        generation = p.header.id,
                        state = p.state,
                        demos = p.demos,
                        "expert status"
                    );
                    if p.header.id == self.control.active_expert as u16 {
                        self.demos_answered = self.demos_answered.max(p.demos);
                    }
                    self.demos_experts_wrote = self.demos_experts_wrote.max(p.demos);
                    self.answers_late.insert(p.header.id, p.answers_late);
                    let now = Instant::now();
                    if p.state == process_state::STANDBY {
                        self.show_human_page(p.header.id);
                    }
                    let actions = match p.state {
                        process_state::STANDBY => self.experts.standby(p.header.id, now),
                        process_state::RUNNING => self.experts.running(p.header.id, now),
                        _ => Vec::new(),
                    };
                    self.apply(actions)?;
                }
                _ => {}
            }
        }
    }

    /// Prints the address of a human expert's page (once per generation), as the expert wrote
    /// it in the run directory before reporting `standby`.
    fn show_human_page(&mut self, generation: u16) {
        if generation <= self.human_page_shown {
            return;
        }
        let file = self
            .plan
            .run_dir
            .join(alfd_expert::human::human_page_file(generation));
        if let Ok(url) = std::fs::read_to_string(&file) {
            self.human_page_shown = generation;
            let url = url.trim().to_owned();
            info!(url = %url, generation, "human expert's page");
            self.bar.suspend(|| {
                eprintln!("you are the expert: answer the queries at {url}");
            });
        }
    }

    /// Says that `lost` records of `p`'s actor never came (see [`Arrivals`]): the run counts
    /// them played (an episode limit is reached without them).
    fn note_lost(&self, p: &Progress, lost: u64) {
        if lost > 0 {
            warn!(
                actor = p.header.id,
                incarnation = p.incarnation,
                lost,
                "episode records lost on the way to the launcher: counted played, not in episodes.csv"
            );
        }
    }

    /// Whether the episodes recorded, with those whose records were lost, reach the run's
    /// episode limit (if it has one).
    fn episode_limit_reached(&self) -> bool {
        let played = self.recorded + self.arrivals.lost();
        self.plan
            .cfg
            .episode_limit()
            .is_some_and(|n| played >= u64::from(n))
    }

    fn record_episode(&mut self, p: &Progress) -> Result<()> {
        let cfg = &self.plan.cfg;
        let episodes_done = self.episode_limit_reached();
        // By its own global step, not by when its message comes: the learner's count that ends
        // a step-limited run can arrive before the last episodes within the limit.
        let past_steps = cfg
            .step_limit()
            .is_some_and(|n| p.episode.0.total_steps > n);
        if episodes_done || past_steps {
            // Past the run's end: not recorded (an episode running at the step limit is not).
            return Ok(());
        }
        let actor = p.header.id as usize;
        if let Some(seen) = self.incarnations.get_mut(actor) {
            if p.incarnation > *seen {
                if *seen != 0 {
                    // Part of a recovery, reported beside the death that caused it.
                    warn!(
                        actor,
                        incarnation = p.incarnation,
                        "first episode of a restarted actor"
                    );
                }
                *seen = p.incarnation;
            }
        }
        if let Some(n) = self.recorded_by.get_mut(actor) {
            *n = n.saturating_add(1);
        }
        if let Some(n) = self.explored.get_mut(actor) {
            *n = n.saturating_add(u64::from(p.episode.0.length));
        }
        // Episodes are numbered in order of arrival; demonstrations used never go down.
        let r = EpisodeRecord {
            episode: self.recorded as u32,
            demos_used: self.demos_used.max(p.episode.0.demos_used),
            ..p.episode.0
        };
        self.demos_used = r.demos_used;
        // A write that fails (a full disk) takes back what it wrote of the row, so the file
        // stays whole rows for `alfd resume`; the row waits in memory for room.
        self.csv
            .append(u64::from(r.episode), format!("{}\n", r.csv_row()));
        self.board.episode(&r);
        self.recorded += 1;
        self.returns.push_back(r.ret);
        if self.returns.len() > 20 {
            self.returns.pop_front();
        }
        self.all_returns.push(r.ret);
        match self.plan.cfg.episode_limit() {
            Some(_) => self.bar.inc(1),
            None => self.bar.set_position(r.total_steps),
        }
        Ok(())
    }

    /// Episodes actor `id` has still to play (a run with an episode limit).
    /// The checkpointed global step actor `id`'s `incarnation` continues from, if any.
    fn restore_step(&self, id: u16, incarnation: u64) -> Option<u64> {
        (incarnation == self.plan.first_incarnation())
            .then(|| {
                self.plan
                    .restore_actors
                    .get(usize::from(id))
                    .copied()
                    .flatten()
            })
            .flatten()
    }

    fn episodes_left(&self, id: u16) -> Option<u32> {
        let i = usize::from(id);
        let played = self.recorded_by[i].saturating_add(self.arrivals.lost_by(id));
        self.quota.map(|q| q[i].saturating_sub(played))
    }

    /// Whether the run has reached its episode or step limit.
    fn done(&self) -> bool {
        self.episode_limit_reached()
            || self
                .plan
                .cfg
                .step_limit()
                .is_some_and(|n| self.seen.learner_env_steps >= n)
    }

    fn show(&self) {
        let mean = if self.returns.is_empty() {
            0.0
        } else {
            self.returns.iter().sum::<f64>() / self.returns.len() as f64
        };
        let (sps, ups) = self.rate.rates();
        let remote = self
            .hub
            .as_ref()
            .map(|h| format!("  remote actors {}", h.remote_actors()))
            .unwrap_or_default();
        self.bar.set_message(format!(
            "return {mean:.1} (last 20)  demos {}/{}{}  {sps:.0} steps/s  {ups:.0} updates/s{remote}",
            u64::from(self.demos_used).max(self.demos_answered),
            self.plan.cfg.budget(),
            demo_troubles(self.answers_late(), self.hub_counts.0),
        ));
    }

    /// Answers with a demonstration that came after their actor stopped waiting: every
    /// expert's own count and the hub's.
    fn answers_late(&self) -> u64 {
        self.answers_late
            .values()
            .map(|&n| u64::from(n))
            .sum::<u64>()
            + self.hub_counts.1
    }

    fn spawn(&mut self, kind: Kind) -> Result<()> {
        let plan = self.plan;
        let (bin, name, mut args) = match &kind {
            Kind::Learner { incarnation } => (
                "alfd-learner",
                "learner".to_owned(),
                // A restarted learner continues from its checkpoint, as does a resumed run's.
                if *incarnation > 1 || plan.resume {
                    vec!["--restore".to_owned()]
                } else {
                    vec![]
                },
            ),
            Kind::Expert { generation, name } => (
                "alfd-expert",
                format!("expert-{generation}"),
                vec![
                    format!("--generation={generation}"),
                    format!("--expert={name}"),
                ],
            ),
            Kind::Actor { id, incarnation } => (
                "alfd-actor",
                format!("actor-{id}"),
                [
                    format!("--actor-id={id}"),
                    format!("--incarnation={incarnation}"),
                ]
                .into_iter()
                .chain(self.episodes_left(*id).map(|n| format!("--episodes={n}")))
                // The first actors of a resumed launch continue from their checkpoints; any other
                // takes over ε's clock where the id's episodes so far leave it.
                .chain(std::iter::once(
                    match self.restore_step(*id, *incarnation) {
                        Some(step) => format!("--restore-step={step}"),
                        None => format!("--explored-steps={}", self.explored[usize::from(*id)]),
                    },
                ))
                .collect(),
            ),
        };
        args.push(format!("--run-id={}", plan.run_id));
        args.push(format!("--run-dir={}", plan.run_dir.display()));
        let log_path = plan.run_dir.join(format!("{name}.log"));
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .what(|| format!("cannot open {}", log_path.display()))?;
        let child = Command::new(plan.bin_dir.join(bin))
            .args(&args)
            .stdin(Stdio::null())
            .stdout(log.try_clone()?)
            .stderr(log)
            // Its own process group: Ctrl-C reaches the launcher only, which stops the run in order.
            .process_group(0)
            .spawn()
            .what(|| format!("cannot start {bin}"))?;
        info!(process = %name, pid = child.id(), "started");
        if plan.pin {
            pin(child.id(), matches!(kind, Kind::Learner { .. }));
        }
        self.procs.push(Proc { name, kind, child });
        Ok(())
    }

    /// Reaps exited children: restarts actors and the expert, fails the run for the learner.
    fn check_children(&mut self) -> Result<()> {
        let mut i = 0;
        while i < self.procs.len() {
            let Some(status) = self.procs[i].child.try_wait()? else {
                i += 1;
                continue;
            };
            let proc = self.procs.remove(i);
            // What it said before it exited counts (its last episodes).
            self.drain_progress()?;
            // The dead process's iceoryx2 node goes before its successor comes.
            self.cleanup_dead_nodes();
            match proc.kind {
                Kind::Actor { id, incarnation } => {
                    self.actor_ended(&proc.name, (id, incarnation), status)?
                }
                Kind::Expert { generation, .. } => self.expert_ended(&proc, generation, status)?,
                Kind::Learner { incarnation } => {
                    self.learner_ended(&proc.name, incarnation, status)?
                }
            }
        }
        Ok(())
    }

    /// Actor `id` (of `incarnation`) exited: done with its share, restarted, or the run given up.
    fn actor_ended(
        &mut self,
        name: &str,
        (id, incarnation): (u16, u64),
        status: ExitStatus,
    ) -> Result<()> {
        let how = describe(status);
        let done = self.episodes_left(id) == Some(0);
        match self
            .restarts
            .ended(&Supervised::Actor(id), Ended::of(status.code(), done))
        {
            Verdict::Done => info!(process = %name, "played its share of the episodes"),
            Verdict::Restart { .. } => {
                warn!(process = %name, "{how}");
                self.spawn(Kind::Actor {
                    id,
                    incarnation: incarnation + 1,
                })?;
            }
            Verdict::GiveUp(why) => bail!(
                "alfd-actor {name} {how}, and {why}; see {}",
                self.log_of(name)
            ),
        }
        Ok(())
    }

    /// An expert exited: its lifecycle decides what follows.
    fn expert_ended(&mut self, proc: &Proc, generation: u16, status: ExitStatus) -> Result<()> {
        let reason = last_error(&self.plan.run_dir.join(format!("{}.log", proc.name)));
        let exit = Exit {
            how: describe(status),
            code: status.code(),
            reason,
        };
        let who = proc_binary(&proc.kind, &proc.name);
        if generation == self.experts.active() {
            warn!("{who} {}", exit.how);
        } else {
            info!("{who} {}", exit.how);
        }
        let actions = self.experts.exited(generation, &exit, Instant::now());
        self.apply(actions)
    }

    /// The learner exited: restarted from its last checkpoint, or the run given up.
    fn learner_ended(&mut self, name: &str, incarnation: u32, status: ExitStatus) -> Result<()> {
        let how = describe(status);
        let reason = last_error(&self.plan.run_dir.join("learner.log"));
        let how_ended = Ended::of(status.code(), false);
        if let Verdict::GiveUp(why) = self.restarts.ended(&Supervised::Learner, how_ended) {
            bail!(
                "alfd-learner {how}{}, and {why}; the episodes so far are in {}, its last \
                 checkpoint in {}; see {}",
                reason.map(|r| format!(" ({r})")).unwrap_or_default(),
                self.plan.run_dir.join("episodes.csv").display(),
                self.plan.run_dir.join("learner.ckpt").display(),
                self.log_of(name)
            );
        }
        warn!(
            "alfd-learner {how}; restarting it from its last checkpoint (the actors wait \
             meanwhile)"
        );
        self.rate.reset();
        self.spawn(Kind::Learner {
            incarnation: incarnation + 1,
        })
    }

    fn cleanup_dead_nodes(&self) {
        match wire::cleanup_dead_nodes(&self.plan.run_id) {
            Ok(removed) if !removed.is_empty() => info!(?removed, "dead nodes cleaned up"),
            Ok(_) => {}
            Err(e) => warn!("cannot clean up dead nodes: {e}"),
        }
    }
}

/// Writes `bytes` to `dir/name`, replacing the file whole (a reader never sees half of it).
fn write(dir: &Path, name: &str, bytes: &[u8]) -> Result<()> {
    Ok(alfd_harness::write_atomically(&dir.join(name), bytes)?)
}

/// [`write`], waiting out a full disk (up to `DISK_FULL_PATIENCE`): the files a launch starts
/// with, which a resume on a disk filled for a moment must not fail on.
fn write_patiently(dir: &Path, name: &str, bytes: &[u8]) -> Result<()> {
    let path = dir.join(name);
    Ok(alfd_harness::write_atomically_patiently(
        &path,
        bytes,
        alfd_harness::DISK_FULL_PATIENCE,
    )?)
}

/// Reads `run.json` of a run directory.
pub fn read_run_info(run_dir: &Path) -> Result<RunInfo> {
    let path = run_dir.join("run.json");
    let text = std::fs::read_to_string(&path)
        .what(|| format!("{} is not a run directory (no run.json)", run_dir.display()))?;
    Ok(serde_json::from_str(&text).what(|| format!("malformed {}", path.display()))?)
}

/// Per actor id, the steps of its episodes among `rows`.
fn explored_steps(rows: &[Row]) -> [u64; alfd_wire::MAX_ACTORS] {
    let mut steps = [0u64; alfd_wire::MAX_ACTORS];
    for r in rows {
        if let Some(n) = steps.get_mut(usize::from(r.actor)) {
            *n = n.saturating_add(r.length);
        }
    }
    steps
}
