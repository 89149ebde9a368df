//! `alfd config`: every key of an experiment config, and a config checked without running it.

use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct ConfigArgs {
    #[command(subcommand)]
    pub command: ConfigCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum ConfigCommand {
    /// Print every key of an experiment config with its type, default and meaning (Markdown,
    /// made from the config types; the manual's docs/src/configuration.md, "Configuration reference", is this text).
    Reference,
    /// Read and validate a config (with `--set` overrides; its expert must exist) and print it in
    /// full as TOML, every default filled in; a bad one is refused with exit code 2, naming the
    /// key.
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
            let cfg = crate::setup::load_config(&config, &set)?;
            crate::setup::check_demonstrator(&cfg)?;
            print!("{}", cfg.to_toml());
        }
    }
    Ok(())
}
