//! `alfd`: the command line of the project.

mod cmd_demo_model;

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(name = "alfd", about = "Active learning from demonstrations")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Fit a demonstration model on demonstrations and print its outputs for query states.
    DemoModel(cmd_demo_model::DemoModelArgs),
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::DemoModel(args) => cmd_demo_model::run(args),
    };
    if let Err(e) = result {
        eprintln!("alfd: {e:#}");
        let code = if e.downcast_ref::<cmd_demo_model::UsageError>().is_some() {
            2
        } else {
            1
        };
        std::process::exit(code);
    }
}
