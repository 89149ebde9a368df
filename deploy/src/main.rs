//! `alfd`: the command line of the project.
//!
//! (Wired here by the env branch only to try `alfd env`; the lead's main.rs supersedes it.)

mod cmd_env;

use std::process::ExitCode;

use clap::Parser;

/// The alfd command line.
#[derive(Debug, clap::Parser)]
#[command(name = "alfd", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, clap::Subcommand)]
enum Command {
    /// Look at the environments: roll CartPole out, show a CliffWalk map.
    Env(cmd_env::EnvArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Env(args) => cmd_env::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("alfd: {e:#}");
            if cmd_env::is_usage_error(&e) {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}
