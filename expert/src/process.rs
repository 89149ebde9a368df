//! The expert process: loads a demonstrator by name, answers the actors' queries within the global
//! budget B (the core's [`ExpertCore`]), appends every answer to `demos.jsonl` before sending it,
//! and publishes the refitted demonstration model.
//!
//! An expert answers only while the launcher's [`Control`](alfd_wire::Control) names its
//! generation as the active one; a newer generation makes it exit. Swaps are made before broken:
//! the new expert is up (standby) before the old one goes, and becomes active only after the old
//! one has exited, reading `demos.jsonl` back at that moment. So at most one expert ever spends
//! budget, and none spends it twice.
//!
//! The decisions are [`ExpertMachine`]'s (`machine.rs`); this file is its I/O shell: it reads the
//! wire, the page and the clock into events and carries out the machine's actions.

use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use alfd_common::agent::{Demonstrator, ExpertCore, Refitted};
use alfd_common::demo_model::lanes::SharedLanes;
use alfd_common::environment_loop::panel_expert::PanelAsk;
use alfd_common::panel::Asker;
use alfd_harness::python::{Adapter, AdapterDemonstrator};
use alfd_harness::{BadInput, ProcessArgs, Refit, Session};
use alfd_harness::{HarnessError, What as _};
use alfd_wire::{
    name_to_bytes, outcome, progress_kind, ActorBells, DemoModelHeader, Doorbell, IncomingQuery,
    Process, Progress, QueryServer, RemoteDemonstrator, Role, WireError,
};
use tracing::{debug, info};

use crate::human::{self, HumanPage, PageState, HUMAN};
use crate::late::LateBook;
use crate::machine::{Action, ExpertMachine, Mode, PanelNote, QueryIn};
use crate::page_member::{PageApart, PageLink};
use crate::quality_file;
use alfd_demonstrators::demo_log::{self, DemoLog};
use alfd_demonstrators::registry;

/// `alfd-expert`: the expert process of a run (started by `alfd run` and `alfd swap-expert`).
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "alfd-expert", version)]
pub struct Args {
    #[command(flatten)]
    pub process: ProcessArgs,
    /// The demonstrator, by name (`alfd expert list`); default the config's `expert.name`.
    #[arg(long)]
    pub expert: Option<String>,
    /// This expert's generation in the run (1 for the first, +1 per swap).
    #[arg(long, default_value_t = 1)]
    pub generation: u16,
    /// Answer only as the built-in expert at this place of `[[experts]]` (from 0), serving
    /// `remote/<name>`: the expert process starts one such process per built-in expert.
    #[arg(long, requires = "name")]
    pub member: Option<usize>,
    /// With `--member`: the service's name (`expert-<generation>-<member>`), also its log's
    /// (`adapter-<name>.log`).
    #[arg(long, requires = "member")]
    pub name: Option<String>,
    /// With `--member`: the pid of the process that started it; this one stops once it is gone.
    #[arg(long)]
    pub parent: Option<u32>,
}

/// The name of the process's log file (without `.log`).
pub fn log_name(args: &Args) -> String {
    match &args.name {
        Some(name) if args.member.is_some() => format!("adapter-{name}"),
        _ => format!("expert-{}", args.generation),
    }
}

/// Who demonstrates: a built-in demonstrator, an external one behind a Python adapter, or a
/// person on the page.
enum Source {
    BuiltIn(Box<dyn Demonstrator<[f32]> + Send>),
    External {
        adapter: Adapter,
        remote: Box<RemoteDemonstrator>,
    },
    Person,
    /// Several built-in experts (`[[experts]]`), a query routed to one of them.
    Panel(Box<PanelAsk<'static, [f32]>>),
}

type Machine<'w> = ExpertMachine<IncomingQuery<'w>>;

/// Runs the expert (or with `--member`, one of several experts) until the launcher says stop, a
/// newer expert replaces it, or a termination signal arrives.
pub fn run(args: &Args, schema: u32) -> alfd_harness::Result<()> {
    match args.member {
        Some(member) => crate::member::serve(args, member, schema),
        None => expert(args, schema),
    }
}

fn expert(args: &Args, schema: u32) -> alfd_harness::Result<()> {
    // Answering is the query path: woken by an actor, it runs before a busy learner or refit.
    alfd_harness::Sched::query_path().apply();
    let setup = args.process.load()?;
    let runtime = &setup.runtime;
    let (obs_dim, actions) = setup.env_dims()?;
    let (name, cfg) = roster(args, &setup.config)?;
    let cfg = &cfg;
    let panel = !cfg.experts.is_empty();
    let demos_path = args.process.run_dir.join("demos.jsonl");
    // Read the demonstrations now, to refuse a bad file before the run depends on us; they are
    // read again when this expert becomes active (its predecessor may have added some).
    let earlier = read_demos(&demos_path, obs_dim, actions)?;
    info!(expert = %name, generation = args.generation, demos = earlier.len(), "expert starting");
    let me = Process::new(Role::Expert, args.generation);
    // A run that never asks (B = 0) needs no expert for its environment: its own (the config's)
    // is not built; one swapped in by name is.
    let source = if panel {
        panel_source(args, (cfg, &name), (me, schema), actions, runtime)?
    } else if name == setup.config.expert.name && !cfg.needs_expert() {
        Source::BuiltIn(Box::new(alfd_common::agent::NoExpert))
    } else {
        source(args, cfg, &name, me, schema, actions)?
    };
    let wire = args.process.connect(me, schema)?;
    let session = Session::join(&wire, Doorbell::Expert, runtime.handshake_timeout())?;
    let core = expert_core(args, cfg, obs_dim, actions)?;
    let page = page(
        args,
        (cfg, &name, &source),
        (me, schema),
        runtime,
        (actions, &core),
    )?;
    let mut machine = ExpertMachine::new(
        args.generation,
        &name,
        matches!(source, Source::Person),
        core,
    );
    if runtime.refit == Refit::Background {
        machine.refit_in_background();
    }
    let mut shell = Shell {
        server: wire.query_server()?,
        model_tx: wire.demo_model_sender()?,
        actors: ActorBells::new(&wire),
        launcher: wire.bell(Doorbell::Launcher)?,
        progress: wire.progress_sender()?,
        log: None,
        source,
        page,
        experts_path: args.process.run_dir.join("experts.csv"),
        demos_path,
        obs_dim,
        actions,
        query_timeout: runtime.query_timeout(),
        clock: Instant::now(),
        disk_full_until: None,
        refused: 0,
        late: LateBook::default(),
        delay: answer_delay(),
        refit: None,
        wire_model: None,
    };
    let start = machine.start(shell.now());
    shell.apply(&mut machine, start)?;
    let stop_reason = serve(&session, &mut machine, &mut shell)?;
    let stop = machine.stop();
    shell.apply(&mut machine, stop)?;
    log_counts(&machine, stop_reason);
    Ok(())
}

/// The name this process answers under (`--expert`, else the run's) and the config with the
/// experts it names: several when it is their joined name (the run's own, or one `alfd expert
/// add|remove` made), else one.
pub(crate) fn roster(
    args: &Args,
    config: &alfd_common::config::ExperimentConfig,
) -> alfd_harness::Result<(String, alfd_common::config::ExperimentConfig)> {
    let name = args
        .expert
        .clone()
        .unwrap_or_else(|| config.run_expert_name());
    let added = alfd_demonstrators::added::read(&args.process.run_dir)?;
    let cfg = match name.as_str() {
        HUMAN => config.with_one_expert(HUMAN),
        _ => config.with_roster(&name, &added),
    };
    Ok((name, cfg))
}

/// What the expert did, in its log as it stops.
fn log_counts(machine: &Machine<'_>, reason: &str) {
    let c = machine.counts();
    info!(
        reason,
        answered = c.answered,
        refused = c.refused,
        abandoned = c.abandoned,
        declined = c.declined,
        demos = machine.core().budget().used(),
        "expert stopping"
    );
}

/// The expert's side of the config, with the run's prior demonstrations (`demos.prior`) in its
/// model, fitting on this machine's cores.
fn expert_core(
    args: &Args,
    cfg: &alfd_common::config::ExperimentConfig,
    obs_dim: usize,
    actions: usize,
) -> alfd_harness::Result<ExpertCore> {
    let mut core = ExpertCore::for_config(cfg, actions);
    // Models fitted anew (the prior's, the SVM's at each demonstration) on this machine's cores.
    core.set_lanes(SharedLanes::new(alfd_harness::Threads::machine()));
    let prior = alfd_harness::read_prior(&args.process.run_dir, obs_dim, actions)?;
    if !prior.is_empty() {
        let records = prior.iter().enumerate().map(|(i, p)| p.record(i)).collect();
        core.set_prior(records)
            .what(|| "the demonstration model of the prior demonstrations".to_owned())?;
        info!(
            demos = prior.len(),
            "prior demonstrations in the demonstration model"
        );
    }
    Ok(core)
}

/// The expert's loop: the launcher's control, queries, the person's page and a background
/// refit in, the machine's actions carried out, until a stop; returns why it stopped.
fn serve<'w>(
    session: &Session<'_>,
    machine: &mut Machine<'w>,
    shell: &mut Shell<'w>,
) -> alfd_harness::Result<&'static str> {
    Ok(loop {
        if let Some(stop) = session.should_stop()? {
            break stop.0;
        }
        let c = session.control();
        let control = machine.control(c.active_expert, c.newest_expert);
        if let Some(reason) = shell.apply(machine, control)? {
            break reason;
        }
        shell.poll_queries(machine)?;
        shell.poll_page(machine)?;
        if let Some(reason) = shell.poll_refit(machine)? {
            break reason;
        }
        let tick = machine.tick(shell.now());
        shell.apply(machine, tick)?;
        // An actor that subscribed since the last publication gets the history sample now.
        shell.model_tx.update_connections()?;
        if let Some(stop) = session.wait(shell.patience())? {
            break stop.0;
        }
    })
}

/// A fault drill's knob: the expert takes this many milliseconds more for each demonstration
/// (the tests and `alfd chaos` make answers slower than the query timeout with it).
pub const ANSWER_DELAY_VAR: &str = "ALFD_EXPERT_ANSWER_DELAY_MS";

/// The delay [`ANSWER_DELAY_VAR`] asks for (none when unset or not a number of milliseconds).
fn answer_delay() -> Duration {
    let ms = std::env::var(ANSWER_DELAY_VAR)
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok())
        .unwrap_or(0);
    if ms > 0 {
        tracing::warn!("{ANSWER_DELAY_VAR}={ms}: every demonstration is {ms} ms slower");
    }
    Duration::from_millis(ms)
}

/// `demos.jsonl`, checked against the environment (a bad file is bad input: exit code 2).
fn read_demos(
    path: &std::path::Path,
    obs_dim: usize,
    actions: usize,
) -> Result<Vec<alfd_common::agent::DemoRecord>, BadInput> {
    demo_log::read(path)
        .and_then(|r| demo_log::check_fits(&r, path, obs_dim, actions).map(|()| r))
        .map_err(|e| BadInput(format!("{e:#}")))
}

/// The demonstrator named `name`: built in, or external (a Python adapter started here; it
/// answers as `remote/expert-<generation>`, logs to RUN_DIR/adapter-expert-<generation>.log and
/// stops with this process), or a person. Budget, demos.jsonl and the model stay here either way.
fn source(
    args: &Args,
    cfg: &alfd_common::config::ExperimentConfig,
    name: &str,
    me: Process,
    schema: u32,
    actions: usize,
) -> alfd_harness::Result<Source> {
    if name == HUMAN {
        return Ok(Source::Person);
    }
    let Some(policy) = registry::external_policy(name) else {
        return Ok(Source::BuiltIn(registry::for_config(cfg, name)?));
    };
    let adapter_name = format!("expert-{}", args.generation);
    let log = args
        .process
        .run_dir
        .join(format!("adapter-{adapter_name}.log"));
    let adapter = Adapter::expert(policy, &args.process.run_id, &adapter_name, schema, &log)?;
    let remote =
        RemoteDemonstrator::new(adapter.connect(&args.process.run_id, me, schema)?, actions);
    Ok(Source::External {
        adapter,
        remote: Box::new(remote),
    })
}

/// The experts of `[[experts]]` and the panel that routes the queries among them. Each expert
/// answers from a process of its own that stops with this one (a person's page: `page_apart`),
/// named
/// `expert-<generation>-<i>` (its service `remote/<that name>`, its log
/// RUN_DIR/adapter-<that name>.log): a built-in one from `alfd-expert --member i`, an external
/// one (`python:`, `sb3:`) from a Python adapter. This process supervises them: one whose
/// process has ended is started again before its next question (at most `--max-restarts`
/// times); one that still cannot answer, or not within `timeout` (its process paused, say), is
/// asked no more, and its queries go to the others.
fn panel_source(
    args: &Args,
    (cfg, joined): (&alfd_common::config::ExperimentConfig, &str),
    (me, schema): (Process, u32),
    actions: usize,
    runtime: &alfd_harness::RuntimeConfig,
) -> alfd_harness::Result<Source> {
    let program = std::env::current_exe().what(|| "cannot find alfd-expert itself".to_owned())?;
    let run_id = args.process.run_id.clone();
    let members = registry::panel_apart(cfg, registry::People::Allowed, |i, elsewhere| {
        let name = crate::member::member_name(args.generation, i);
        let log = args.process.run_dir.join(format!("adapter-{name}.log"));
        let (process, program, joined) = (args.process.clone(), program.clone(), joined.to_owned());
        let policy = match elsewhere {
            registry::Elsewhere::External(policy) => Some(policy.to_owned()),
            registry::Elsewhere::BuiltIn => None,
        };
        let generation = args.generation;
        let (id, service, timeout) = (run_id.clone(), name.clone(), runtime.query_timeout());
        let start: crate::member::Start = Box::new(move || {
            let adapter = match &policy {
                Some(policy) => Adapter::expert(policy, &id, &service, schema, &log)?,
                None => {
                    let member = (joined.as_str(), generation, i);
                    Adapter::member(&program, &process, member, &service, &log)?
                }
            };
            AdapterDemonstrator::connect(adapter, &id, me, schema, actions, timeout)
        });
        let expert = crate::member::Supervised::start(start, &name, &run_id, runtime.max_restarts)?;
        Ok(Box::new(expert))
    })?;
    let panel = PanelAsk::new(cfg, members, actions);
    Ok(Source::Panel(Box::new(match person_in(cfg) {
        Some(i) => panel.with_person(i),
        None => panel,
    })))
}

/// The page a person answers on: the expert's (served here), or one of several experts' (served
/// by a process of its own); `None` without a person.
fn page(
    args: &Args,
    (cfg, name, source): (&alfd_common::config::ExperimentConfig, &str, &Source),
    (me, schema): (Process, u32),
    runtime: &alfd_harness::RuntimeConfig,
    (actions, core): (usize, &ExpertCore),
) -> alfd_harness::Result<Option<PageLink>> {
    Ok(match (source, person_in(cfg)) {
        (Source::Person, _) => Some(PageLink::Here(start_page(
            args,
            runtime.human_port,
            cfg,
            actions,
            core,
        )?)),
        (_, Some(i)) => Some(PageLink::Apart(Box::new(page_apart(
            args,
            (name, i),
            (me, schema),
            runtime,
        )?))),
        _ => None,
    })
}

/// The page of the person at place `i` of `[[experts]]` (`joined`: the experts' joined name), in
/// a process of its own, `expert-<generation>-<i>` as every member (its log
/// RUN_DIR/adapter-<that name>.log), started again under `--max-restarts` if it ends.
fn page_apart(
    args: &Args,
    (joined, i): (&str, usize),
    (me, schema): (Process, u32),
    runtime: &alfd_harness::RuntimeConfig,
) -> alfd_harness::Result<PageApart> {
    let program = std::env::current_exe().what(|| "cannot find alfd-expert itself".to_owned())?;
    let name = crate::member::member_name(args.generation, i);
    let log = args.process.run_dir.join(format!("adapter-{name}.log"));
    let (process, joined, generation) = (args.process.clone(), joined.to_owned(), args.generation);
    let start: crate::page_member::Start = Box::new(move || {
        let member = (joined.as_str(), generation, i);
        let adapter = Adapter::member(&program, &process, member, &name, &log)?;
        crate::page_member::connect(adapter, &process.run_id, me, schema)
    });
    PageApart::start(
        start,
        &args.process.run_id,
        runtime.max_restarts,
        PAGE_SYNC_TIMEOUT,
    )
}

/// How long a sync with a person's page in a process of its own may take (it is answered at
/// once; a paused page process holds the expert up this long, every
/// `page_member::QUIET_AFTER_FAILURE`).
const PAGE_SYNC_TIMEOUT: Duration = Duration::from_millis(200);

/// Where a person (`human`) is among `cfg`'s several experts, if they are.
fn person_in(cfg: &alfd_common::config::ExperimentConfig) -> Option<usize> {
    cfg.experts.iter().position(|e| e.name == HUMAN)
}

/// A person as the expert: the page is up from the start (standing by until active); its
/// address with the token goes to the run directory's private file.
fn start_page(
    args: &Args,
    port: u16,
    cfg: &alfd_common::config::ExperimentConfig,
    actions: usize,
    core: &ExpertCore,
) -> alfd_harness::Result<HumanPage> {
    let env = cfg.env.name.as_str();
    let page = HumanPage::start(
        port,
        PageState {
            budget_total: core.budget().total(),
            budget_left: core.budget().remaining(),
            // The demonstrations in this model (with refits in the background, possibly fewer
            // than recorded): the actors start shaping at `shaping.min_demos` of them.
            demos: core.model_run_demos(),
            ..PageState::blank(env, actions)
        },
    )
    .map_err(|e| BadInput(e.to_string()))?;
    info!(addr = %page.addr(), "the human expert's page is served (its address with the token: the run directory's human-page file)");
    human::write_address(&args.process.run_dir, args.generation, &page)?;
    Ok(page)
}

/// The nice value of a background refit's thread (and of the threads it starts): the query path,
/// the learner and the actors go first when the cores are busy.
const REFIT_NICE: i32 = 10;

/// The expert's I/O: the wire's ports, the demonstration log, the demonstrator, the page.
struct Shell<'w> {
    server: QueryServer<'w>,
    model_tx: alfd_wire::DemoModelSender<'w>,
    actors: ActorBells<'w>,
    launcher: alfd_wire::Bell,
    progress: alfd_wire::Sender<'w, Progress>,
    log: Option<DemoLog>,
    source: Source,
    page: Option<PageLink>,
    demos_path: PathBuf,
    /// Several experts' quality as the run sees it, a row per answer.
    experts_path: PathBuf,
    obs_dim: usize,
    actions: usize,
    query_timeout: Duration,
    clock: Instant,
    /// Until when no query is asked (a full disk refused the last demonstration).
    disk_full_until: Option<Duration>,
    /// Demonstrations a full disk refused since the last one recorded.
    refused: u32,
    /// Answers with a demonstration that their actor never read, having stopped waiting (the
    /// demonstration is kept; the actor acted alone).
    late: LateBook,
    /// How long each demonstration is held back before it is asked for ([`ANSWER_DELAY_VAR`]).
    delay: Duration,
    /// Where the refit running on its own thread sends its result.
    refit: Option<mpsc::Receiver<RefitResult>>,
    /// The model a refit just gave the core, serialised for the wire on the refit's thread, with
    /// the core's model version it became: taken by the next publication if it is still that
    /// version, so that the query path copies bytes instead of serialising the model.
    wire_model: Option<(u64, Vec<u8>)>,
}

/// A refit's result, with its model serialised for the wire.
type RefitResult = (Refitted, Option<Vec<u8>>);

/// How long the expert leaves queries unanswered after a full disk refused a demonstration, before
/// it tries to record one again.
const DISK_FULL_PAUSE: Duration = Duration::from_secs(1);

impl<'w> Shell<'w> {
    fn now(&self) -> Duration {
        self.clock.elapsed()
    }

    /// The refit the machine owes, on a thread of its own (the queries are answered meanwhile).
    fn start_refit(&mut self, m: &mut Machine<'w>) {
        let Some(job) = m.take_refit_job() else {
            return;
        };
        let job = job.in_background();
        let (tx, rx) = mpsc::channel();
        debug!(demos = job.covers(), "refitting the demonstration model");
        std::thread::spawn(move || {
            alfd_harness::Sched::background(REFIT_NICE).apply();
            let refitted = job.run();
            // A model that cannot be serialised here is serialised again, and its error
            // reported, when it is published.
            let bytes = refitted.model().and_then(|m| postcard::to_stdvec(m).ok());
            // The receiver is gone only when the process is stopping.
            let _ = tx.send((refitted, bytes));
        });
        self.refit = Some(rx);
    }

    /// The refit's result, if it has ended, as an event.
    fn poll_refit(&mut self, m: &mut Machine<'w>) -> alfd_harness::Result<Option<&'static str>> {
        let Some(rx) = &self.refit else {
            return Ok(None);
        };
        let (refitted, bytes) = match rx.try_recv() {
            Ok(r) => r,
            Err(mpsc::TryRecvError::Empty) => return Ok(None),
            Err(mpsc::TryRecvError::Disconnected) => {
                return Err(HarnessError::Run(
                    "the demonstration model's refit ended without a result".into(),
                ))
            }
        };
        self.refit = None;
        let before = m.core().model_version();
        let next = m.refitted(refitted);
        let version = m.core().model_version();
        let publishes = next.iter().any(|a| matches!(a, Action::PublishModel));
        if version != before && publishes {
            self.wire_model = bytes.map(|b| (version, b));
        }
        self.apply(m, next)
    }

    /// How long the loop may wait for its doorbell: briefly while a refit runs, so that its
    /// model is published soon after it ends.
    fn patience(&self) -> Duration {
        if self.refit.is_some() {
            Duration::from_millis(2)
        } else {
            Duration::from_millis(100)
        }
    }

    /// Every query waiting on the wire, as events.
    fn poll_queries(&mut self, m: &mut Machine<'w>) -> alfd_harness::Result<()> {
        loop {
            let query = match self.server.receive() {
                Ok(Some(q)) => q,
                Ok(None) => return Ok(()),
                Err(e @ WireError::SchemaMismatch { .. }) => {
                    tracing::error!("{e}; query dropped");
                    continue;
                }
                Err(e) => return Err(e.into()),
            };
            let request = query.request();
            if let Some(seq) = request.gave_up() {
                self.late.gave_up((request.actor, request.incarnation), seq);
            }
            if request.is_report() {
                // It asks nothing: dropped unanswered, the asker sees it let go.
                continue;
            }
            let q = QueryIn {
                actor: request.actor,
                step: request.global_step,
                episode: request.episode,
                last_return: request.last_return(),
                connected: query.is_connected(),
                state: request
                    .checked_state(self.obs_dim)
                    .map(<[f32]>::to_vec)
                    .map_err(|e| e.to_string()),
            };
            let actions = m.query(query, q);
            self.apply(m, actions)?;
        }
    }

    /// The queries whose actors stopped waiting, the person's decisions, and the page's state.
    fn poll_page(&mut self, m: &mut Machine<'w>) -> alfd_harness::Result<()> {
        let now = Instant::now();
        let Some(decisions) = self.page.as_mut().map(|p| p.decisions(now)).transpose()? else {
            return Ok(());
        };
        // The actors that gave up waiting (their timeout) are no longer shown, nor answered.
        m.prune(|q| q.is_connected());
        for d in decisions {
            let panel = match &mut self.source {
                Source::Panel(p) => Some(p.as_mut()),
                _ => None,
            };
            let answered = m.decision(d.id, d.action, panel);
            // The first reply answers the decision (refusals of the rest may follow it).
            if let Some(Action::Reply {
                actor, response, ..
            }) = answered.iter().find(|a| matches!(a, Action::Reply { .. }))
            {
                info!(actor, outcome = response.outcome, "the person decided");
            }
            self.apply(m, answered)?;
        }
        let page = self.page.as_mut().expect("checked above");
        let (core, c) = (m.core(), m.counts());
        page.show(&m.waiting(), |s| {
            s.active = m.mode() == Mode::Active;
            s.budget_left = core.budget().remaining();
            s.budget_total = core.budget().total();
            s.demos = core.budget().used();
            s.answered = c.person_answered;
            s.declined = c.declined;
        });
        Ok(())
    }

    /// Carries out the machine's actions in order; returns the reason to stop if one says so.
    fn apply(
        &mut self,
        m: &mut Machine<'w>,
        actions: Vec<Action<IncomingQuery<'w>>>,
    ) -> alfd_harness::Result<Option<&'static str>> {
        for action in actions {
            match action {
                Action::Exit(reason) => return Ok(Some(reason)),
                Action::LoadDemos => {
                    if let Some(reason) = self.load_demos(m)? {
                        return Ok(Some(reason));
                    }
                }
                Action::CloseLog => {
                    info!("no longer the active expert: standing by");
                    self.log = None;
                }
                Action::Record(record) => {
                    if !self.record(&record, None)? {
                        // Not on disk, so not given: the query goes unanswered (the actor acts
                        // on its own), and the budget and the model go back to what
                        // demos.jsonl holds, as a restarted expert's would.
                        return self.apply(m, vec![Action::LoadDemos]);
                    }
                }
                Action::RecordOf(record, note) => {
                    if !self.record(&record, Some(&note))? {
                        // Not on disk, so not given: the query goes unanswered (the actor acts
                        // on its own), and the budget and the model go back to what
                        // demos.jsonl holds, as a restarted expert's would.
                        return self.apply(m, vec![Action::LoadDemos]);
                    }
                }
                Action::PublishModel => {
                    let ready = self.wire_model.take();
                    publish_model(&mut self.model_tx, m, ready)?;
                }
                Action::StartRefit => self.start_refit(m),
                Action::Reply {
                    query,
                    actor,
                    response,
                } => {
                    if response.outcome == outcome::ANSWERED {
                        let held = query.is_connected();
                        let r = query.request();
                        self.late
                            .answered((r.actor, r.incarnation), r.header.seq, held);
                        if !held {
                            debug!(
                                actor,
                                index = response.demo_index,
                                "the actor stopped waiting; demonstration kept, answer late"
                            );
                        }
                    }
                    query.answer(response)?;
                    ring_actor(&mut self.actors, actor)?;
                }
                Action::Ask {
                    query,
                    asker,
                    state,
                    step,
                } => {
                    if let Some(reason) = self.demonstrate(m, (query, asker), &state, step)? {
                        return Ok(Some(reason));
                    }
                }
                Action::Drop { actor, why } => debug!(actor, "{why}; query left unanswered"),
                Action::Status(state) => self.status(state, m.core())?,
                Action::RingLauncher => {
                    self.launcher.ring()?;
                }
            }
        }
        Ok(None)
    }

    /// Becomes the active expert: reads `demos.jsonl` back (a file that went bad meanwhile is
    /// bad input too, exit code 2), refits on it, opens the log and carries out what follows.
    fn load_demos(&mut self, m: &mut Machine<'w>) -> alfd_harness::Result<Option<&'static str>> {
        let records = read_demos(&self.demos_path, self.obs_dim, self.actions)?;
        quality_file::trim(&self.experts_path, &self.demos_path)
            .what(|| format!("cannot cut back {}", self.experts_path.display()))?;
        let n = records.len();
        let next = m
            .activate(records)
            .what(|| "cannot refit the demonstration model on demos.jsonl".into())?;
        let log = DemoLog::open(&self.demos_path).what(|| "the demonstration log".into())?;
        self.log = Some(log);
        let left = m.core().budget().remaining();
        info!(demos = n, budget_left = left, "active: answering queries");
        self.apply(m, next)
    }

    /// Asks the demonstrator for `state` (none while the disk was full a moment ago, or when an
    /// external one failed) and carries out what the answer leads to.
    fn demonstrate(
        &mut self,
        m: &mut Machine<'w>,
        (query, asker): (IncomingQuery<'w>, Asker),
        state: &[f32],
        step: u64,
    ) -> alfd_harness::Result<Option<&'static str>> {
        let actor = asker.actor;
        if self.disk_full_until.is_some_and(|t| self.now() < t) {
            debug!(
                actor,
                "the disk was full a moment ago; query left unanswered"
            );
            return Ok(None);
        }
        if !self.delay.is_zero() {
            std::thread::sleep(self.delay);
        }
        if let Source::Panel(panel) = &mut self.source {
            let next = m.panel_demonstrated((query, asker), state, step, panel);
            return self.apply(m, next);
        }
        let Some(action) = self.ask(actor, state)? else {
            return Ok(None);
        };
        let next = m.demonstrated(query, actor, state, step, action);
        self.apply(m, next)
    }

    /// Appends a demonstration to `demos.jsonl`; `false` when a full disk refused it (then no
    /// query is asked for [`DISK_FULL_PAUSE`]).
    fn record(
        &mut self,
        record: &alfd_common::agent::DemoRecord,
        panel: Option<&PanelNote>,
    ) -> alfd_harness::Result<bool> {
        // The quality row first (see `quality_file`).
        let row_at = match panel.map(|n| quality_file::append(&self.experts_path, &n.quality_line))
        {
            None => None,
            Some(Ok(at)) => Some(at),
            Some(Err(e)) if alfd_harness::disk_full(&e) => {
                return Ok(self.refuse(record, &e));
            }
            Some(Err(e)) => {
                let path = self.experts_path.display().to_string();
                return Err(e).what(|| format!("cannot write {path}"));
            }
        };
        let Some(log) = self.log.as_mut() else {
            return Err(HarnessError::Run("a demonstration with no log open".into()));
        };
        let appended = match panel {
            Some(n) => log.append_of(record, n.cost, n.double_asked),
            None => log.append(record),
        };
        if let Err(e) = appended {
            if let Some(at) = row_at {
                quality_file::cut_back(&self.experts_path, at);
            }
            if !e.is_disk_full() {
                return Err(e).what(|| "the demonstration log".into());
            }
            return Ok(self.refuse(record, &e));
        }
        if self.refused > 0 {
            info!(
                refused = self.refused,
                "demonstrations are recorded again after a full disk"
            );
            self.refused = 0;
        }
        debug!(
            index = record.index,
            action = record.action,
            "demonstration"
        );
        Ok(true)
    }

    /// A demonstration a full disk refused: not kept, and no query is answered for
    /// [`DISK_FULL_PAUSE`]; `false`.
    fn refuse(
        &mut self,
        record: &alfd_common::agent::DemoRecord,
        e: &dyn std::fmt::Display,
    ) -> bool {
        tracing::warn!(
            "{e}: demonstration {} not kept; no query is answered for {:?}",
            record.index,
            DISK_FULL_PAUSE
        );
        self.disk_full_until = Some(self.now() + DISK_FULL_PAUSE);
        self.refused += 1;
        false
    }

    /// The demonstrator's action for `state`, or `None` when an external one failed (the actor
    /// acts on its own after its timeout; no budget is spent).
    fn ask(&mut self, actor: u32, state: &[f32]) -> alfd_harness::Result<Option<usize>> {
        match &mut self.source {
            Source::BuiltIn(d) => Ok(Some(d.act(state))),
            Source::External { adapter, remote } => match remote.act(state, self.query_timeout) {
                Ok(action) => Ok(Some(action)),
                Err(e) => {
                    tracing::error!(actor, "external expert: {e}; query dropped");
                    if let Some(why) = adapter.gone() {
                        let why = format!("the external expert stopped: {why}");
                        return Err(HarnessError::Run(why));
                    }
                    Ok(None)
                }
            },
            Source::Person => unreachable!("the machine asks a person on the page"),
            Source::Panel(_) => unreachable!("a panel's experts are asked by the machine"),
        }
    }

    fn status(&mut self, state: u32, core: &ExpertCore) -> alfd_harness::Result<()> {
        self.progress.send(Progress {
            kind: progress_kind::STATUS,
            state,
            pid: std::process::id(),
            demos: u64::from(core.budget().used()),
            budget_left: u64::from(core.budget().remaining()),
            answers_late: self.late.late(),
            ..Progress::default()
        })?;
        Ok(())
    }
}

/// Rings the doorbell of the actor that asked (an id beyond `u16` has none: it is not truncated
/// onto another actor's).
fn ring_actor(actors: &mut ActorBells<'_>, actor: u32) -> alfd_harness::Result<()> {
    if let Ok(id) = u16::try_from(actor) {
        actors.ring(id)?;
    }
    Ok(())
}

/// Publishes the current demonstration model (empty bytes when there is none yet), with the
/// budget and the step of the last demonstration. `ready`: the model already serialised, with
/// the model version it is, used if that is still the core's.
fn publish_model(
    tx: &mut alfd_wire::DemoModelSender<'_>,
    m: &Machine<'_>,
    ready: Option<(u64, Vec<u8>)>,
) -> alfd_harness::Result<()> {
    let core = m.core();
    let bytes = match (core.model(), ready) {
        (None, _) => Vec::new(),
        (Some(_), Some((version, bytes))) if version == core.model_version() => bytes,
        (Some(model), _) => {
            postcard::to_stdvec(model).what(|| "cannot serialise the demonstration model".into())?
        }
    };
    tx.publish(
        DemoModelHeader {
            version: (u64::from(m.generation()) << 32) | core.model_version(),
            last_demo_step: core.last_demo_step(),
            // The demonstrations in this model (with refits in the background, possibly fewer
            // than recorded): the actors start shaping at `shaping.min_demos` of them.
            demos: core.model_run_demos(),
            budget_total: core.budget().total(),
            budget_left: core.budget().remaining(),
            expert: u32::from(m.generation()),
            expert_name: name_to_bytes(m.name()),
            ..DemoModelHeader::default()
        },
        &bytes,
    )?;
    Ok(())
}
