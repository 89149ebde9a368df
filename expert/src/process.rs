//! The expert process: loads a demonstrator by name, answers the actors' queries within the global
//! budget B (the core's [`ExpertCore`]), appends every answer to `demos.jsonl` before sending it,
//! and publishes the refitted demonstration model.
//!
//! An expert answers only while the launcher's [`Control`](alfd_wire::Control) names its
//! generation as the active one; a newer generation makes it exit. Swaps are made before broken:
//! the new expert is up (standby) before the old one goes, and becomes active only after the old
//! one has exited, reading `demos.jsonl` back at that moment. So at most one expert ever spends
//! budget, and none spends it twice.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use alfd_common::agent::{Demonstrator, ExpertCore};
use alfd_common::runner::expert_core;
use alfd_harness::python::Adapter;
use alfd_harness::{BadInput, ProcessArgs, Session};
use alfd_wire::{
    name_to_bytes, outcome, process_state, progress_kind, ActorBells, DemoModelHeader, Doorbell,
    IncomingQuery, Process, Progress, QueryResponse, RemoteDemonstrator, Role, WireError,
};
use anyhow::Context as _;
use tracing::{debug, info};

use crate::demo_log::{self, DemoLog};
use crate::human::{self, HumanPage, PageState, ShownQuery, HUMAN};
use crate::registry;

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
}

/// The name of the process's log file (without `.log`).
pub fn log_name(args: &Args) -> String {
    format!("expert-{}", args.generation)
}

/// Whether this expert may answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Standby,
    Active,
}

/// Runs the expert until the launcher says stop, a newer expert replaces it, or a termination
/// signal arrives.
pub fn run(args: &Args, schema: u32) -> anyhow::Result<()> {
    let setup = args.process.load()?;
    let (cfg, runtime) = (&setup.config, &setup.runtime);
    let (obs_dim, actions) = setup.env_dims()?;
    let name = args
        .expert
        .clone()
        .unwrap_or_else(|| cfg.expert.name.clone());
    // A built-in demonstrator, or an external one: a Python adapter started here (it answers as
    // `remote/expert-<generation>`, logs to RUN_DIR/adapter-expert-<generation>.log and stops
    // with this process). Budget, demos.jsonl and the model stay here either way.
    let adapter = match registry::external_policy(&name) {
        Some(policy) => {
            let adapter_name = format!("expert-{}", args.generation);
            let log = args
                .process
                .run_dir
                .join(format!("adapter-{adapter_name}.log"));
            Some(Adapter::expert(
                policy,
                &args.process.run_id,
                &adapter_name,
                schema,
                &log,
            )?)
        }
        None => None,
    };
    let human = name == HUMAN;
    let mut builtin = match adapter {
        Some(_) => None,
        None if human => None,
        None => Some(registry::for_env(cfg.env.name, &name)?),
    };
    let demos_path = args.process.run_dir.join("demos.jsonl");
    // Read the demonstrations now, to refuse a bad file before the run depends on us; they are
    // read again when this expert becomes active (its predecessor may have added some).
    let earlier = demo_log::read(&demos_path)
        .and_then(|r| demo_log::check_fits(&r, &demos_path, obs_dim, actions).map(|()| r))
        .map_err(|e| BadInput(format!("{e:#}")))?;
    info!(expert = %name, generation = args.generation, demos = earlier.len(), "expert starting");

    let me = Process::new(Role::Expert, args.generation);
    let mut external = match &adapter {
        Some(a) => Some(RemoteDemonstrator::new(
            a.connect(&args.process.run_id, me, schema)?,
            actions,
        )),
        None => None,
    };
    let wire = args.process.connect(me, schema)?;
    let session = Session::join(&wire, Doorbell::Expert, runtime.handshake_timeout())?;
    let server = wire.query_server()?;
    let mut model_tx = wire.demo_model_sender()?;
    let mut actors = ActorBells::new(&wire);
    let launcher = wire.bell(Doorbell::Launcher)?;
    let mut progress = wire.progress_sender()?;

    let mut core = expert_core(cfg, actions);
    // A person as the expert: the page is up from the start (standing by until active).
    let page = if human {
        let page = HumanPage::start(
            runtime.human_port,
            PageState {
                env: cfg.env.name.to_string(),
                actions: human::action_labels(cfg.env.name.as_str(), actions),
                active: false,
                budget_total: core.budget().total(),
                budget_left: core.budget().remaining(),
                demos: core.budget().used(),
                waiting: 0,
                query: None,
                answered: 0,
                declined: 0,
                version: 0,
            },
        )
        .map_err(|e| BadInput(e.to_string()))?;
        let url = page.url();
        info!(addr = %page.addr(), "the human expert's page is served (its address with the token: the run directory's human-page file)");
        alfd_harness::write_private(
            &args
                .process
                .run_dir
                .join(human::human_page_file(args.generation)),
            format!("{url}\n").as_bytes(),
        )?;
        Some(page)
    } else {
        None
    };
    // Queries waiting for the person, oldest first, with the page's number for each.
    let mut waiting: VecDeque<(ShownQuery, IncomingQuery<'_>)> = VecDeque::new();
    let mut next_shown = 0u64;
    let (mut declined, mut person_answered) = (0u64, 0u64);
    let mut log: Option<DemoLog> = None;
    let mut mode = Mode::Standby;
    let pid = std::process::id();
    let status = |progress: &mut alfd_wire::Sender<'_, Progress>,
                  state: u32,
                  core: &ExpertCore|
     -> anyhow::Result<()> {
        progress.send(Progress {
            kind: progress_kind::STATUS,
            state,
            pid,
            demos: u64::from(core.budget().used()),
            budget_left: u64::from(core.budget().remaining()),
            ..Progress::default()
        })?;
        Ok(())
    };
    status(&mut progress, process_state::STANDBY, &core)?;
    launcher.ring()?;
    let mut last_status = Instant::now();
    let (mut answered, mut refused, mut abandoned) = (0u64, 0u64, 0u64);

    let stop_reason = loop {
        if let Some(stop) = session.should_stop()? {
            break stop.0;
        }
        let c = session.control();
        if u32::from(args.generation) < c.newest_expert {
            break "replaced by a newer expert";
        }
        let should_be_active = c.active_expert == u32::from(args.generation);
        if should_be_active && mode == Mode::Standby {
            // Make-before-break: the previous expert has exited; its demonstrations are final.
            // A file that went bad meanwhile is bad input too (exit code 2, the reason in the
            // launcher's message).
            let records = demo_log::read(&demos_path)
                .and_then(|r| demo_log::check_fits(&r, &demos_path, obs_dim, actions).map(|()| r))
                .map_err(|e| BadInput(format!("{e:#}")))?;
            let n = records.len();
            core.restore(records)
                .context("cannot refit the demonstration model on demos.jsonl")?;
            log = Some(DemoLog::open(&demos_path)?);
            mode = Mode::Active;
            publish_model(&mut model_tx, &core, args.generation, &name)?;
            status(&mut progress, process_state::RUNNING, &core)?;
            launcher.ring()?;
            info!(
                demos = n,
                budget_left = core.budget().remaining(),
                "active: answering queries"
            );
        } else if !should_be_active && mode == Mode::Active {
            info!("no longer the active expert: standing by");
            release(&mut waiting, &mut actors, args.generation, &name)?;
            mode = Mode::Standby;
            log = None;
            status(&mut progress, process_state::STANDBY, &core)?;
            launcher.ring()?;
        }

        loop {
            let query = match server.receive() {
                Ok(Some(q)) => q,
                Ok(None) => break,
                Err(e @ WireError::SchemaMismatch { .. }) => {
                    tracing::error!("{e}; query dropped");
                    continue;
                }
                Err(e) => return Err(e.into()),
            };
            let (Mode::Active, Some(_)) = (mode, log.as_ref()) else {
                debug!("standing by: query left unanswered");
                continue;
            };
            if !query.is_connected() {
                // The actor gave up waiting and acted on its own: spend no budget on it.
                abandoned += 1;
                continue;
            }
            let request = *query.request();
            // A state of another size (or not finite) would break the demonstrator and the
            // demonstration model: refused, and the actor acts on its own after its timeout.
            let state = match request.checked_state(obs_dim) {
                Ok(state) => state,
                Err(e) => {
                    tracing::error!(actor = request.actor, "{e}; query dropped");
                    continue;
                }
            };
            if page.is_some() && !core.budget().is_exhausted() {
                // For the person: shown on the page, answered when they decide.
                next_shown += 1;
                let shown = ShownQuery {
                    id: next_shown,
                    actor: request.actor,
                    step: request.global_step,
                    state: state.to_vec(),
                };
                waiting.push_back((shown, query));
                continue;
            }
            let step = request.global_step.max(core.last_demo_step());
            let mut response = QueryResponse {
                expert: u32::from(args.generation),
                budget_total: core.budget().total(),
                expert_name: name_to_bytes(&name),
                ..QueryResponse::default()
            };
            let answer = match (builtin.as_mut(), external.as_mut()) {
                (Some(d), _) => core.answer(d.as_mut(), state, step, &name),
                // A person with no budget left: not asked.
                (None, None) if human => None,
                // No budget, no question to the external demonstrator.
                (None, Some(_)) if core.budget().is_exhausted() => None,
                (None, Some(remote)) => match remote.act(state, runtime.query_timeout()) {
                    Ok(action) => core.answer(&mut Given(action), state, step, &name),
                    Err(e) => {
                        // The actor acts on its own after its timeout; no budget is spent.
                        tracing::error!(
                            actor = request.actor,
                            "external expert: {e}; query dropped"
                        );
                        if let Some(why) = adapter.as_ref().and_then(|a| a.gone()) {
                            anyhow::bail!("the external expert stopped: {why}");
                        }
                        continue;
                    }
                },
                (None, None) => unreachable!("an expert is built-in, external or human"),
            };
            let log = log.as_mut().expect("active with a log");
            match answer {
                Some(action) => {
                    let index = send_demonstration(
                        Answering {
                            core: &core,
                            log,
                            model_tx: &mut model_tx,
                            actors: &mut actors,
                            generation: args.generation,
                            name: &name,
                        },
                        query,
                        response,
                        request.actor,
                        action,
                    )?;
                    debug!(index, actor = request.actor, action, step, "demonstration");
                    answered += 1;
                }
                None => {
                    response.outcome = outcome::BUDGET_EXHAUSTED;
                    response.budget_left = 0;
                    query.answer(response)?;
                    ring_actor(&mut actors, request.actor)?;
                    refused += 1;
                }
            }
        }
        if let Some(page) = &page {
            // The actors that gave up waiting (their timeout) are no longer shown.
            waiting.retain(|(_, q)| {
                let wanted = q.is_connected();
                if !wanted {
                    abandoned += 1;
                }
                wanted
            });
            for decision in page.decisions() {
                let Some(i) = waiting.iter().position(|(s, _)| s.id == decision.id) else {
                    continue;
                };
                let (shown, query) = waiting.remove(i).expect("position is in range");
                let (Mode::Active, Some(log)) = (mode, log.as_mut()) else {
                    continue;
                };
                let step = shown.step.max(core.last_demo_step());
                let mut response = QueryResponse {
                    expert: u32::from(args.generation),
                    budget_total: core.budget().total(),
                    expert_name: name_to_bytes(&name),
                    ..QueryResponse::default()
                };
                let answer = match decision.action {
                    None => {
                        // Declined: the actor acts on its own, no budget is spent and nothing
                        // is recorded.
                        response.outcome = outcome::DECLINED;
                        response.budget_left = core.budget().remaining();
                        query.answer(response)?;
                        ring_actor(&mut actors, shown.actor)?;
                        declined += 1;
                        info!(actor = shown.actor, "the person declined a query");
                        continue;
                    }
                    Some(action) => core.answer(&mut Given(action), &shown.state, step, &name),
                };
                match answer {
                    Some(action) => {
                        let index = send_demonstration(
                            Answering {
                                core: &core,
                                log,
                                model_tx: &mut model_tx,
                                actors: &mut actors,
                                generation: args.generation,
                                name: &name,
                            },
                            query,
                            response,
                            shown.actor,
                            action,
                        )?;
                        info!(index, actor = shown.actor, action, "the person answered");
                        answered += 1;
                        person_answered += 1;
                    }
                    None => {
                        response.outcome = outcome::BUDGET_EXHAUSTED;
                        query.answer(response)?;
                        ring_actor(&mut actors, shown.actor)?;
                        refused += 1;
                    }
                }
            }
            if core.budget().is_exhausted() {
                // Nothing more to ask the person: the rest act on their own.
                for (shown, query) in waiting.drain(..) {
                    query.answer(QueryResponse {
                        outcome: outcome::BUDGET_EXHAUSTED,
                        expert: u32::from(args.generation),
                        budget_total: core.budget().total(),
                        expert_name: name_to_bytes(&name),
                        ..QueryResponse::default()
                    })?;
                    ring_actor(&mut actors, shown.actor)?;
                    refused += 1;
                }
            }
            let shown: Vec<ShownQuery> = waiting.iter().map(|(s, _)| s.clone()).collect();
            page.set_waiting(&shown);
            page.update(|s| {
                s.active = mode == Mode::Active;
                s.budget_left = core.budget().remaining();
                s.budget_total = core.budget().total();
                s.demos = core.budget().used();
                s.answered = person_answered;
                s.declined = declined;
            });
        }
        if last_status.elapsed() >= Duration::from_millis(500) {
            let state = if mode == Mode::Active {
                process_state::RUNNING
            } else {
                process_state::STANDBY
            };
            status(&mut progress, state, &core)?;
            last_status = Instant::now();
        }
        // An actor that subscribed since the last publication gets the history sample now.
        model_tx.update_connections()?;
        if let Some(stop) = session.wait(Duration::from_millis(100))? {
            break stop.0;
        }
    };
    // Actors waiting for the person act on their own now rather than at their timeout.
    release(&mut waiting, &mut actors, args.generation, &name)?;
    info!(
        reason = stop_reason,
        answered,
        refused,
        abandoned,
        declined,
        demos = core.budget().used(),
        "expert stopping"
    );
    status(&mut progress, process_state::EXITING, &core)?;
    launcher.ring()?;
    Ok(())
}

/// Answers every query still waiting for the person with "declined" (the actor acts on its
/// own; no budget is spent): this expert stops answering.
fn release(
    waiting: &mut VecDeque<(ShownQuery, IncomingQuery<'_>)>,
    actors: &mut ActorBells<'_>,
    generation: u16,
    name: &str,
) -> anyhow::Result<()> {
    for (shown, query) in waiting.drain(..) {
        query.answer(QueryResponse {
            outcome: outcome::DECLINED,
            expert: u32::from(generation),
            expert_name: name_to_bytes(name),
            ..QueryResponse::default()
        })?;
        ring_actor(actors, shown.actor)?;
    }
    Ok(())
}

/// The action an external demonstrator gave, as the core's demonstrator (so the core records it
/// as it records a built-in one's).
struct Given(usize);

impl Demonstrator<[f32]> for Given {
    fn act(&mut self, _s: &[f32]) -> usize {
        self.0
    }
}

/// Publishes the current demonstration model (empty bytes when there is none yet), with the
/// budget and the step of the last demonstration.
/// Rings the doorbell of the actor that asked (an id beyond `u16` has none: it is not truncated
/// onto another actor's).
/// What answering a query with a demonstration needs of the expert process.
struct Answering<'a, 'w> {
    core: &'a ExpertCore,
    log: &'a mut DemoLog,
    model_tx: &'a mut alfd_wire::DemoModelSender<'w>,
    actors: &'a mut ActorBells<'w>,
    generation: u16,
    name: &'a str,
}

/// Answers `query` of `actor` with `action`, the demonstration `core` has just recorded, in the
/// one order every expert kind keeps: on disk first (no demonstration is ever lost), then the
/// model refitted with it (so the actor shapes the step it asked about with it, as in one
/// process), then the answer and the actor's doorbell. Returns the demonstration's index.
fn send_demonstration(
    a: Answering<'_, '_>,
    query: IncomingQuery<'_>,
    mut response: QueryResponse,
    actor: u32,
    action: usize,
) -> anyhow::Result<u32> {
    let record = a
        .core
        .demos()
        .last()
        .expect("answer recorded a demonstration");
    a.log.append(record)?;
    response.outcome = outcome::ANSWERED;
    response.action = action as u32;
    response.demo_index = record.index;
    response.budget_left = a.core.budget().remaining();
    publish_model(a.model_tx, a.core, a.generation, a.name)?;
    query.answer(response)?;
    ring_actor(a.actors, actor)?;
    Ok(record.index)
}

fn ring_actor(actors: &mut ActorBells<'_>, actor: u32) -> anyhow::Result<()> {
    if let Ok(id) = u16::try_from(actor) {
        actors.ring(id)?;
    }
    Ok(())
}

fn publish_model(
    tx: &mut alfd_wire::DemoModelSender<'_>,
    core: &ExpertCore,
    generation: u16,
    name: &str,
) -> anyhow::Result<()> {
    let bytes = match core.model() {
        Some(m) => postcard::to_stdvec(m).context("cannot serialise the demonstration model")?,
        None => Vec::new(),
    };
    tx.publish(
        DemoModelHeader {
            version: (u64::from(generation) << 32) | core.model_version(),
            last_demo_step: core.last_demo_step(),
            demos: core.budget().used(),
            budget_total: core.budget().total(),
            budget_left: core.budget().remaining(),
            expert: u32::from(generation),
            expert_name: name_to_bytes(name),
            ..DemoModelHeader::default()
        },
        &bytes,
    )?;
    Ok(())
}
