//! `alfd`: the command line of the project. Each subcommand is a small module; this file parses
//! arguments, installs logging, and maps errors to exit codes (2 for bad input, 1 otherwise).

mod chaos;
mod checkpoint_file;
mod cmd_certs;
mod cmd_clean;
mod cmd_config;
mod cmd_demo_model;
mod cmd_demo_model_policy;
mod cmd_demos;
mod cmd_docs;
mod cmd_env;
mod cmd_expert;
mod cmd_join;
mod cmd_local;
mod cmd_q_range;
mod cmd_resume;
mod cmd_run;
mod cmd_swap;
mod cmd_sweep;
mod cmd_watch;
mod link_flags;
mod local_remote;
mod setup;
mod usage;

use clap::{Parser, Subcommand};

/// Active learning from demonstrations: actor, learner and expert processes, experiments.
#[derive(Debug, Parser)]
#[command(name = "alfd", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run an experiment config in one process.
    Local(cmd_local::LocalArgs),
    /// Continue a stopped or crashed run: `alfd local --checkpoint-every N` from its checkpoint,
    /// `alfd run` from its learner's checkpoint and `demos.jsonl`.
    Resume(cmd_resume::ResumeArgs),
    /// Remove what dead runs left in iceoryx2's directories (never a live run's files).
    Clean(cmd_clean::CleanArgs),
    /// Run an experiment as separate processes: learner, expert and N actors over iceoryx2.
    Run(cmd_run::RunArgs),
    /// Actors on this host for a run on another (`alfd run --listen`), over zenoh.
    Join(cmd_join::JoinArgs),
    /// Certificates for runs across hosts: the run's CA and one per host (mutual TLS).
    Certs(cmd_certs::CertsArgs),
    /// Replace the expert of a live run (make before break).
    SwapExpert(cmd_swap::SwapArgs),
    /// A multi-process run under faults drawn from a seed (kill -9, SIGSTOP, expert swaps, the
    /// launcher killed and resumed, a full disk), then its invariants checked.
    Chaos(chaos::ChaosArgs),
    /// Environments: roll out CartPole, MountainCar or Acrobot from a state, show a CliffWalk map.
    Env(cmd_env::EnvArgs),
    /// Demonstrators: list them, evaluate one.
    Expert(cmd_expert::ExpertArgs),
    /// Train the demonstrators of known quality and save them.
    TrainExperts(cmd_expert::TrainExpertsArgs),
    /// Demonstrations as datasets: a run's episodes exported to Minari.
    Demos(cmd_demos::DemosArgs),
    /// Fit a demonstration model (KRR or SVM) on demonstrations and query it.
    DemoModel(cmd_demo_model::DemoModelArgs),
    /// Run an experiment file over many seeds: curves, plot, summary table.
    Sweep(cmd_sweep::SweepArgs),
    /// How the time to a threshold grows with a task's size: one sweep's `runs.csv` per size, as
    /// a table, a CSV and plots of the median demonstrations and episodes.
    Scaling(alfd_lab::sweep::scaling::ScalingArgs),
    /// Evaluate a demonstration model fitted on an expert's demonstrations as a policy.
    DemoModelPolicy(cmd_demo_model_policy::DemoModelPolicyArgs),
    /// The Q-values of runs' learned networks on greedy episodes against the range of the true
    /// values: a check for divergence.
    QRange(cmd_q_range::QRangeArgs),
    /// Re-make the generated tables of README.md, EXPERIMENTS.md, BENCHMARKS.md and the manual
    /// (docs/src) from the committed results (`--check`: fail if any differs).
    Docs(cmd_docs::DocsArgs),
    /// Experiment configs: every key with its default (`reference`), or one file validated and
    /// printed in full (`check`).
    Config(cmd_config::ConfigArgs),
    /// Serve a page on 127.0.0.1 that shows a run (running or finished) as it learns: learning
    /// curves, demonstrations against the budget, the gate's firing, throughput.
    Watch(cmd_watch::WatchArgs),
}

/// Blocks the products read start on a cache line (see `alfd_common::alloc`).
#[global_allocator]
static ALLOC: alfd_common::alloc::CacheAligned = alfd_common::alloc::CacheAligned;

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    setup::init_logging();
    alfd_harness::portable_kernels_from_env();
    let result = match cli.command {
        Command::Local(a) => cmd_local::run(a),
        Command::Resume(a) => cmd_resume::run(a),
        Command::Clean(a) => cmd_clean::run(a),
        Command::Run(a) => cmd_run::run(a),
        Command::Join(a) => cmd_join::run(a),
        Command::Certs(a) => cmd_certs::run(a),
        Command::SwapExpert(a) => cmd_swap::swap(a),
        Command::Chaos(a) => chaos::run(a),
        Command::Env(a) => cmd_env::run(a),
        Command::Expert(a) => cmd_expert::run(a),
        Command::TrainExperts(a) => cmd_expert::train(a),
        Command::Demos(a) => cmd_demos::run(a),
        Command::DemoModel(a) => cmd_demo_model::run(a),
        Command::Sweep(a) => cmd_sweep::run(a),
        Command::Scaling(a) => cmd_sweep::scaling(a),
        Command::DemoModelPolicy(a) => cmd_demo_model_policy::run(a),
        Command::QRange(a) => cmd_q_range::run(a),
        Command::Docs(a) => cmd_docs::run(a),
        Command::Config(a) => cmd_config::run(a),
        Command::Watch(a) => cmd_watch::run(a),
    };
    if let Err(err) = result {
        eprintln!("error: {}", alfd_harness::describe(err.as_ref()));
        std::process::exit(usage::exit_code(&err));
    }
}
