//! `alfd run`: a multi-process run (learner, expert, N actors over iceoryx2), and
//! `alfd swap-expert`: replace the expert of a live run.

use std::path::PathBuf;

use alfd_harness::RuntimeConfig;
use alfd_wire::MAX_ACTORS;

use crate::setup;
use crate::usage::usage;
use alfd_harness::run_dir;
use alfd_lab::report::{self, Output};
use alfd_launcher::{self as launcher, Plan};

/// The default experiment: the recommended CartPole-1000 preset (Bootstrapped DQN with 300 active
/// demonstrations of the 1000 expert, 50,000 steps).
pub const DEFAULT_CONFIG: &str = include_str!("../../configs/recommended/cartpole.toml");

#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The experiment config (TOML); default: the recommended CartPole-1000 preset
    /// (deploy/configs/recommended/cartpole.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Number of actor processes on this host (0 with --listen: all actors are remote).
    #[arg(long, default_value_t = 2)]
    pub actors: usize,
    /// Also take actors from other hosts: listen on quic/ADDR:PORT (mutual TLS: --tls-ca, --tls-cert,
    /// --tls-key) or tcp/ADDR:PORT (with --insecure) for `alfd join --connect` (zenoh). Remote
    /// actors get the free actor ids above this host's.
    #[arg(long, value_name = "quic/ADDR:PORT")]
    pub listen: Option<String>,
    #[command(flatten)]
    pub link: crate::link_flags::LinkFlags,
    /// Override a config value, e.g. `--set budget.total=20` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// The run directory; default `runs/<run id>`. It must not hold a run already.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print no progress bar and no summary at the end.
    #[arg(long)]
    pub quiet: bool,
    /// Print only the machine-readable line: the run's summary as JSON on stdout (printed also
    /// without this flag when stdout is not a terminal).
    #[arg(long)]
    pub json: bool,
    /// Credit window: steps an actor may run ahead of the learner's updates (1..=64); default 1
    /// (actors in lockstep with the learner: with one actor, `alfd local`'s run to the byte), or
    /// 32 with --listen (remote actors' transitions cross the link in batches). Less lag learns
    /// more reliably at the same speed (BENCHMARKS.md, the credit window).
    #[arg(long)]
    pub window: Option<u64>,
    /// Milliseconds an actor waits for the expert's answer before acting on its own.
    #[arg(long, default_value_t = 1000)]
    pub query_timeout_ms: u64,
    /// The demonstrator, by name (`alfd expert list`, `python:MODULE:FUNCTION`, `sb3:ALGO:PATH`,
    /// or `human`: a person answers on a web page); default the config's `expert.name`.
    #[arg(long)]
    pub expert: Option<String>,
    /// Milliseconds an actor waits for a person's answer (`--expert human`) before acting on its
    /// own.
    #[arg(long, default_value_t = alfd_harness::DEFAULT_HUMAN_QUERY_TIMEOUT_MS)]
    pub human_query_timeout_ms: u64,
    /// The port of the human expert's page on 127.0.0.1 (0: a free port; the address is
    /// printed, and kept in `RUN_DIR/human-page-<generation>.txt`).
    #[arg(long, default_value_t = 0)]
    pub human_port: u16,
    /// The learner publishes its weights every this many updates.
    #[arg(long, default_value_t = 1)]
    pub weights_every: u64,
    /// The learner and the actors checkpoint their whole state at the first episode end after
    /// every this many updates' worth of steps (0: only at the end); a learner that dies is
    /// restarted from its last checkpoint, and `alfd resume` continues from them.
    #[arg(long, default_value_t = alfd_harness::DEFAULT_CHECKPOINT_EVERY)]
    pub checkpoint_every: u64,
    /// When the expert refits its demonstration model: `inline`, before it answers the query
    /// that brought the demonstration (the actor shapes that very step with it; one actor's run
    /// is `alfd local`'s to the byte), or `background`, on a thread of its own while it answers
    /// (queries never wait for a refit: for large models; the model is published when ready).
    #[arg(long, value_enum, default_value_t = alfd_harness::Refit::Inline)]
    pub refit: alfd_harness::Refit,
    /// Restarts allowed per actor, of the expert, of the learner (before the run fails) and of
    /// each of several experts' processes (before it is asked no more) (kept
    /// by `alfd resume`).
    #[arg(long, default_value_t = alfd_launcher::DEFAULT_MAX_RESTARTS)]
    pub max_restarts: u32,
    /// Pin the learner to CPU 0 and the other processes to the other CPUs (`taskset`); helps on
    /// an otherwise idle machine, hurts on a shared one.
    #[arg(long)]
    pub pin: bool,
    /// Serve a page on 127.0.0.1 that shows the run as it learns (as `alfd watch RUN_DIR`); its
    /// address is printed and kept in RUN_DIR/watch-page.txt.
    #[arg(long)]
    pub watch: bool,
    /// The port of that page (0: a free port).
    #[arg(long, default_value_t = 0)]
    pub watch_port: u16,
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let mut cfg = match &args.config {
        Some(path) => setup::load_config(path, &args.set)?,
        None => setup::parse_config(DEFAULT_CONFIG, &args.set, "the default config")?,
    };
    if let Some(expert) = &args.expert {
        if !cfg.experts.is_empty() {
            return Err(usage(format!(
                "--expert {expert}: the config lists several experts (`[[experts]]`), who all \
                 answer; leave --expert out, or list {expert} among them"
            )));
        }
        cfg.expert.name = expert.clone();
    }
    cfg.check_multi_process()
        .map_err(|e| usage(e.to_string()))?;
    // With --listen, remote hosts may bring actors up to the run's limit.
    let publishers = if args.listen.is_some() {
        MAX_ACTORS
    } else {
        args.actors
    };
    let env_spec = env_spec(&cfg, publishers)?;
    let prior = prior_demos(&cfg, env_spec.as_ref())?;
    let listen = listen_and_actors(&args)?;
    let runtime = runtime_config(&args, listen.is_some(), env_spec)?;
    // Fail before starting anything if the expert is unknown.
    setup::check_run_demonstrator(&cfg)?;
    let person = cfg.expert.name == alfd_expert::human::HUMAN
        || cfg
            .experts
            .iter()
            .any(|e| e.name == alfd_expert::human::HUMAN);
    if person {
        check_human_port(args.human_port)?;
    }
    let run_id = launcher::new_run_id();
    let run_dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(&run_id));
    // A run directory belongs to one run: refused if it holds one, locked while this one runs.
    let _lock = run_dir::claim_new(&run_dir)?;
    if args.watch {
        let page = crate::cmd_watch::serve(&run_dir, args.watch_port)?;
        eprintln!("watch the run at {}", page.url());
    }
    if !prior.is_empty() {
        std::fs::create_dir_all(&run_dir)?;
        alfd_harness::write_prior(&run_dir, &prior)?;
    }
    let output = Output {
        json: args.json,
        quiet: args.quiet,
    };
    let plan = Plan {
        cfg,
        actors: args.actors,
        run_dir: run_dir.clone(),
        run_id,
        runtime,
        max_restarts: args.max_restarts,
        progress: output.progress(),
        pin: args.pin,
        bin_dir: launcher::bin_dir()?,
        resume: false,
        launches: 1,
        earlier_run_ids: Vec::new(),
        restore_actors: Vec::new(),
        listen,
    };
    finish(&plan, output)
}

/// The endpoint of `--listen` (if given), with `--actors` checked against it: at least one
/// actor on this host unless other hosts bring them.
fn listen_and_actors(args: &RunArgs) -> anyhow::Result<Option<alfd_launcher::Endpoint>> {
    let listen = args
        .listen
        .as_deref()
        .map(|text| listen_on(args, text))
        .transpose()?;
    let least = usize::from(listen.is_none());
    if !(least..=MAX_ACTORS).contains(&args.actors) {
        return Err(usage(format!(
            "--actors must be in {least}..={MAX_ACTORS}{}, got {}",
            if listen.is_none() {
                " (0 only with --listen)"
            } else {
                ""
            },
            args.actors
        )));
    }
    Ok(listen)
}

#[cfg(feature = "hosts")]
fn listen_on(args: &RunArgs, text: &str) -> anyhow::Result<alfd_launcher::Endpoint> {
    args.link.endpoint("--listen", text)
}

/// `--listen` in a build without the `hosts` feature: exit 2, saying how to build it.
#[cfg(not(feature = "hosts"))]
fn listen_on(_: &RunArgs, text: &str) -> anyhow::Result<alfd_launcher::Endpoint> {
    Err(crate::usage::without_hosts(&format!("--listen {text}")))
}

/// The human expert's page port (0: any free one), refused now if something else holds it
/// rather than by the expert at start-up.
fn check_human_port(port: u16) -> anyhow::Result<()> {
    if port == 0 {
        return Ok(());
    }
    std::net::TcpListener::bind((std::net::Ipv4Addr::LOCALHOST, port)).map_err(|e| {
        usage(format!(
            "--human-port {port}: cannot serve the human expert's page on 127.0.0.1:{port}: {e}"
        ))
    })?;
    Ok(())
}

/// The sizes of a Gymnasium environment, probed once in Python now (a wrong space is refused
/// before anything starts; its sizes go to runtime.toml for the learner and the expert), or
/// `None` for a native one; either way checked against the shared memory `actors` actors take.
fn env_spec(
    cfg: &alfd_common::config::ExperimentConfig,
    actors: usize,
) -> anyhow::Result<Option<alfd_harness::python::EnvSpec>> {
    if cfg.env.name.is_remote() {
        let spec = alfd_harness::python::probe_env(&cfg.env)?;
        alfd_harness::check_wire_limits(cfg, (spec.obs_dim, spec.num_actions), actors)
            .map_err(|e| usage(e.to_string()))?;
        Ok(Some(spec))
    } else {
        let env = alfd_common::env::vector_env(cfg).ok_or_else(|| {
            usage(format!(
                "`alfd run` needs an environment with vector observations, not {:?}",
                cfg.env.name
            ))
        })?;
        alfd_harness::check_wire_limits(cfg, (env.observation_dim(), env.num_actions()), actors)
            .map_err(|e| usage(e.to_string()))?;
        Ok(None)
    }
}

/// The expert steps of the dataset `demos.prior` names, checked against the run's environment
/// (none without one): the processes read them from `RUN_DIR/prior-demos.jsonl`.
fn prior_demos(
    cfg: &alfd_common::config::ExperimentConfig,
    spec: Option<&alfd_harness::python::EnvSpec>,
) -> anyhow::Result<Vec<alfd_common::agent::PriorDemo>> {
    let prior = crate::cmd_local::read_prior(cfg)?;
    if prior.is_none() {
        return Ok(Vec::new());
    }
    let (obs_dim, actions) = match spec {
        Some(s) => (s.obs_dim, s.num_actions),
        None => {
            let env = alfd_common::env::vector_env(cfg)
                .ok_or_else(|| anyhow::anyhow!("no vector environment"))?;
            (env.observation_dim(), env.num_actions())
        }
    };
    crate::cmd_local::prior_steps(cfg, prior.as_ref(), obs_dim, actions)
}

/// The runtime settings every process reads, from `alfd run`'s flags, validated (the error names
/// the flag).
fn runtime_config(
    args: &RunArgs,
    listen: bool,
    env_spec: Option<alfd_harness::python::EnvSpec>,
) -> anyhow::Result<RuntimeConfig> {
    let runtime = RuntimeConfig {
        window: args.window.unwrap_or(if listen { 32 } else { 1 }),
        query_timeout_ms: args.query_timeout_ms,
        human_query_timeout_ms: args.human_query_timeout_ms,
        human_port: args.human_port,
        weights_every: args.weights_every,
        checkpoint_every: args.checkpoint_every,
        refit: args.refit,
        max_restarts: args.max_restarts,
        env_spec,
        ..RuntimeConfig::default()
    };
    runtime.validate().map_err(|e| {
        usage(format!(
            "{e} (flag --{})",
            match e {
                alfd_harness::RuntimeConfigError::Invalid { field, .. } => field.replace('_', "-"),
                _ => String::new(),
            }
        ))
    })?;
    Ok(runtime)
}

/// Runs `plan` to its end, writes `summary.json` and reports (the learning curve, the JSON
/// line, the summary: see `alfd_lab::report`).
pub fn finish(plan: &Plan, output: Output) -> anyhow::Result<()> {
    let run_dir = &plan.run_dir;
    let summary = launcher::launch(plan)?;
    alfd_lab::output::write(
        run_dir,
        "summary.json",
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    report::finish_run(&plan.cfg, run_dir, &summary, output)?;
    if let Some(r) = &summary.runtime {
        anyhow::ensure!(
            r.demos as u64 >= r.demos_experts_wrote,
            "demonstrations lost: {} holds {} where the run's experts wrote {} ({} refused); \
             see the expert logs and the run's log",
            run_dir.join("demos.jsonl").display(),
            r.demos,
            r.demos_experts_wrote,
            r.demos_refused
        );
    }
    if let Some(lost) = summary
        .runtime
        .as_ref()
        .map(|r| r.episodes_lost)
        .filter(|&n| n > 0)
    {
        eprintln!(
            "warning: {lost} episode records never reached the launcher (see the run's log): \
             the run counted them played, {} lacks their rows",
            run_dir.join("episodes.csv").display()
        );
    }
    if summary.runtime.as_ref().is_some_and(|r| r.interrupted) {
        eprintln!(
            "interrupted: the run was stopped cleanly; its directory is {}",
            run_dir.display()
        );
        std::process::exit(130);
    }
    Ok(())
}
