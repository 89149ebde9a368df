//! `alfd config`: every key of an experiment config, and a config checked without running it.

use std::path::PathBuf;

use crate::usage::usage;

#[derive(Debug, clap::Args)]
pub struct ConfigArgs {
    #[command(subcommand)]
    pub command: ConfigCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum ConfigCommand {
    /// Print every key of an experiment config with its type, default and meaning (Markdown,
    /// made from the config types; README.md, "Configuration reference", is this text).
    Reference,
    /// Read and validate a config (with `--set` overrides) and print it in full as TOML, every
    /// default filled in; a bad one is refused with exit code 2, naming the key.
    Check {
        /// The experiment config (TOML).
        config: PathBuf,
        /// Override a key, `key=value` (dotted keys, TOML values; bare words are strings).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
}

pub fn run(args: ConfigArgs) -> anyhow::Result<()> {
    match args.command {
        ConfigCommand::Reference => print!("{}", alfd_common::config::reference::markdown()),
        ConfigCommand::Check { config, set } => {
            let text = std::fs::read_to_string(&config)
                .map_err(|e| usage(format!("cannot read {}: {e}", config.display())))?;
            let source = config.display().to_string();
            let cfg = crate::setup::parse_config(&text, &set, &source)?;
            print!("{}", cfg.to_toml());
        }
    }
    Ok(())
}
