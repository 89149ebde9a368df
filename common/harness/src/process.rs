//! What the three process binaries share: their common arguments, reading the run directory
//! (`config.toml`, `runtime.toml`), the wire's limits, joining the run, and `main` with its exit
//! codes (2 for bad input, 1 for anything else).

use std::path::{Path, PathBuf};

use alfd_common::config::ExperimentConfig;
use alfd_common::env::{vector_env, Env as _, VectorEnv};
use std::sync::Arc;

use alfd_wire::{Process, Role, Wire, MAX_HEADS, MAX_OBS_DIM};

use crate::bad_input::{describe, exit_code, BadInput, Result, What as _};
use crate::python::{Adapter, AdapterEnv};
use crate::runtime::{RuntimeConfig, RUNTIME_FILE};

/// The arguments every process takes.
#[derive(Debug, Clone, clap::Args)]
pub struct ProcessArgs {
    /// The run directory (`config.toml`, `runtime.toml`, logs).
    #[arg(long)]
    pub run_dir: PathBuf,
    /// The run id (names the run's iceoryx2 services).
    #[arg(long)]
    pub run_id: String,
}

/// A run directory's settings, validated.
#[derive(Debug, Clone)]
pub struct Setup {
    pub config: ExperimentConfig,
    pub runtime: RuntimeConfig,
}

impl ProcessArgs {
    /// Reads `RUN_DIR/config.toml` and `RUN_DIR/runtime.toml`; a bad file is [`BadInput`].
    pub fn load(&self) -> Result<Setup> {
        let config = read(&self.run_dir.join("config.toml"), |t| {
            let mut cfg = ExperimentConfig::for_multi_process(t).map_err(|e| e.to_string())?;
            cfg.load_schedule(read_text).map_err(|e| e.to_string())?;
            Ok(cfg)
        })?;
        let runtime = read(&self.run_dir.join(RUNTIME_FILE), |t| {
            RuntimeConfig::from_toml(t).map_err(|e| e.to_string())
        })?;
        let setup = Setup { config, runtime };
        setup.env_dims()?;
        Ok(setup)
    }

    /// Joins the run as `me`, speaking schema version `schema`.
    pub fn connect(&self, me: Process, schema: u32) -> Result<Wire> {
        Wire::connect(&self.run_id, me, schema).what(|| "cannot join the run".to_owned())
    }
}

/// A file's text, or why it cannot be read (what [`ExperimentConfig::load_schedule`] reads
/// rule `random`'s schedule with).
pub fn read_text(path: &str) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| e.to_string())
}

fn read<T>(path: &Path, parse: impl FnOnce(&str) -> Result<T, String>) -> Result<T> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| BadInput(format!("cannot read {}: {e}", path.display())))?;
    Ok(parse(&text).map_err(|e| BadInput(format!("in {}: {e}", path.display())))?)
}

impl Setup {
    /// The environment's observation size and number of actions, checked against what the wire
    /// carries: a built-in environment's, or a Gymnasium environment's as `runtime.toml`
    /// recorded them when the run started.
    pub fn env_dims(&self) -> Result<(usize, usize)> {
        if self.config.env.name.is_remote() {
            let spec = self.runtime.env_spec.ok_or_else(|| {
                BadInput(format!(
                    "{RUNTIME_FILE} has no env_spec for the gymnasium environment (the launcher \
                     writes it)"
                ))
            })?;
            check_wire_limits(&self.config, (spec.obs_dim, spec.num_actions), 1)?;
            return Ok((spec.obs_dim, spec.num_actions));
        }
        let env = self.vector_env()?;
        Ok((env.observation_dim(), env.num_actions()))
    }

    /// The environment actor `actor_id` plays: a built-in one, or a session on the actor's
    /// Gymnasium adapter (`remote/env-<id>`), which the first call starts (logging to
    /// `RUN_DIR/adapter-env-<id>.log`) and later calls share.
    pub fn actor_env(
        &self,
        adapter: &mut Option<Arc<Adapter>>,
        process: &ProcessArgs,
        actor_id: u16,
        schema: u32,
    ) -> Result<Box<VectorEnv>> {
        if !self.config.env.name.is_remote() {
            return self.vector_env();
        }
        let name = format!("env-{actor_id}");
        let adapter = match adapter {
            Some(a) => a.clone(),
            None => {
                let log = process.run_dir.join(format!("adapter-{name}.log"));
                let a = Arc::new(Adapter::env(
                    &self.config.env,
                    &process.run_id,
                    &name,
                    schema,
                    &log,
                )?);
                *adapter = Some(a.clone());
                a
            }
        };
        let me = Process::new(Role::Actor, actor_id);
        let env = AdapterEnv::open(adapter, &self.config.env, &process.run_id, me, schema)?;
        let (obs_dim, actions) = self.env_dims()?;
        if (env.observation_dim(), env.num_actions()) != (obs_dim, actions) {
            return Err(BadInput(format!(
                "the adapter's environment has {} values and {} actions, but the run started \
                 with {obs_dim} and {actions}",
                env.observation_dim(),
                env.num_actions()
            ))
            .into());
        }
        Ok(Box::new(env))
    }

    /// The config's built-in environment, checked against what the wire carries.
    pub fn vector_env(&self) -> Result<Box<VectorEnv>> {
        let env = vector_env(&self.config).ok_or_else(|| {
            BadInput(format!(
                "{:?} has no vector observations; the multi-process runtime runs neural agents",
                self.config.env.name
            ))
        })?;
        check_wire_limits(&self.config, (env.observation_dim(), env.num_actions()), 1)?;
        Ok(env)
    }
}

/// Where iceoryx2 keeps the shared memory of every run on this host.
const SHM_DIR: &str = "/dev/shm";

/// Refuses a run whose transitions and weights the machine's shared memory cannot hold: `actors`
/// actors, each publishing batches of the environment's observations (`obs_dim` values) and
/// masks of the config's K ([`alfd_wire::transitions_bytes`] each), and the learner publishing
/// its network ([`alfd_wire::weights_bytes`]), against what `/dev/shm` has free.
pub fn check_wire_limits(
    cfg: &ExperimentConfig,
    (obs_dim, actions): (usize, usize),
    actors: usize,
) -> Result<(), BadInput> {
    let heads = cfg.agent.heads();
    let params = alfd_common::nn::param_count(
        obs_dim,
        cfg.agent.network_width(),
        heads.saturating_mul(actions),
    );
    let need = Need {
        obs_dim,
        heads,
        actors,
        params,
    };
    check_sizes(need, shm_free(Path::new(SHM_DIR)))
}

/// What a run's services hold: its observations, heads, actors and network.
#[derive(Debug, Clone, Copy)]
struct Need {
    obs_dim: usize,
    heads: usize,
    actors: usize,
    params: usize,
}

/// [`check_wire_limits`] with the free shared memory given (`None`: not known, not checked).
fn check_sizes(n: Need, free: Option<u64>) -> Result<(), BadInput> {
    let Need {
        obs_dim,
        heads,
        actors,
        params,
    } = n;
    if obs_dim > MAX_OBS_DIM {
        return Err(BadInput(format!(
            "the environment's observations have {obs_dim} values; a message carries at most \
             MAX_OBS_DIM = {MAX_OBS_DIM}"
        )));
    }
    if heads > MAX_HEADS {
        return Err(BadInput(format!(
            "the agent has {heads} heads; a message carries at most MAX_HEADS = {MAX_HEADS}"
        )));
    }
    let need = alfd_wire::transitions_bytes(obs_dim, heads)
        .saturating_mul(actors.max(1) as u64)
        .saturating_add(alfd_wire::weights_bytes(params));
    match free {
        Some(free) if need > free => Err(BadInput(format!(
            "{actors} actor(s) with observations of {obs_dim} values and {heads} heads, and a \
             network of {params} parameters, need {} MiB of shared memory; {SHM_DIR} has {} MiB \
             free (fewer actors, a smaller observation, fewer heads or hidden units fit)",
            need >> 20,
            free >> 20
        ))),
        _ => Ok(()),
    }
}

/// Bytes free to an unprivileged user on the file system of `dir`; `None` if it cannot be read.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
// The counts are u64 on 64-bit Linux and may be u32 elsewhere.
#[allow(clippy::useless_conversion)]
fn shm_free(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let path = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    let mut st = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `path` is a NUL-terminated string that outlives the call, and `st` points to
    // memory for one `statvfs`, which the call fills when it returns 0 (read only then).
    let st = unsafe {
        if libc::statvfs(path.as_ptr(), st.as_mut_ptr()) != 0 {
            return None;
        }
        st.assume_init()
    };
    Some(u64::from(st.f_bavail).saturating_mul(u64::from(st.f_frsize)))
}

#[cfg(not(target_os = "linux"))]
fn shm_free(_dir: &Path) -> Option<u64> {
    None
}

/// The `main` of a process binary: logs to `RUN_DIR/LOG.log`, learns the schema version it
/// speaks, runs `run`, and exits 0, 1 or 2 (bad input).
pub fn main<A, E: AsRef<dyn std::error::Error + 'static>>(
    binary: &str,
    args: &A,
    process: &ProcessArgs,
    log: &str,
    run: impl FnOnce(&A, u32) -> Result<(), E>,
) -> ! {
    crate::startup::init_process_logging(binary, &process.run_dir, log);
    crate::startup::portable_kernels_from_env();
    let schema = crate::startup::schema_version_from_env().unwrap_or_else(|e| {
        eprintln!("{binary}: {e}");
        std::process::exit(2)
    });
    match run(args, schema) {
        Ok(()) => std::process::exit(0),
        Err(err) => {
            let message = describe(err.as_ref());
            tracing::error!("{message}");
            eprintln!("{binary}: error: {message}");
            std::process::exit(exit_code(&err))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_name_both_numbers_and_bad_input_exits_2() {
        let need = |obs_dim, heads, actors, params| Need {
            obs_dim,
            heads,
            actors,
            params,
        };
        assert!(check_sizes(need(MAX_OBS_DIM, MAX_HEADS, 1, 1), None).is_ok());
        let e = check_sizes(need(MAX_OBS_DIM + 2, 1, 1, 1), None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("have 65537 values") && e.contains("MAX_OBS_DIM = 65535"),
            "{e}"
        );
        let e = check_sizes(need(4, MAX_HEADS + 1, 1, 1), None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("65536 heads") && e.contains("MAX_HEADS = 65535"),
            "{e}"
        );
        // DeepSea(50)'s grid, 20 heads of 2 actions, 64 hidden units, 2 actors: 2 × 266 samples
        // of 32 × 5,020 values, and 147 samples of the network's 166,824 parameters.
        let params = alfd_common::nn::param_count(2500, 64, 40);
        assert_eq!(params, 166_824);
        let header = |n| n as u64;
        let one = alfd_wire::transitions_bytes(2500, 20);
        assert_eq!(
            one,
            266 * (32 * 5020 * 4 + header(std::mem::size_of::<alfd_wire::TransitionHeader>()))
        );
        let weights = alfd_wire::weights_bytes(params);
        assert_eq!(
            weights,
            147 * (166_824 * 4 + header(std::mem::size_of::<alfd_wire::WeightsHeader>()))
        );
        let deepsea = need(2500, 20, 2, params);
        assert!(check_sizes(deepsea, Some(2 * one + weights)).is_ok());
        let e = check_sizes(deepsea, Some(2 * one + weights - 1))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("2 actor(s)")
                && e.contains("need 419 MiB")
                && e.contains("/dev/shm has 419 MiB free"),
            "{e}"
        );
        assert!(shm_free(Path::new(SHM_DIR)).is_some_and(|b| b > 0));
        let bad = anyhow::Error::new(BadInput("x".into())).context("while starting");
        assert_eq!(exit_code(&bad), 2);
        assert_eq!(exit_code(&anyhow::anyhow!("broken pipe")), 1);
    }

    #[test]
    fn a_run_directory_is_read_and_its_faults_are_bad_input() {
        let tmp = crate::fs::test_dir("harness");
        let dir = tmp.path();
        let args = ProcessArgs {
            run_dir: dir.to_path_buf(),
            run_id: "r1".into(),
        };
        let e = args.load().unwrap_err();
        assert_eq!(exit_code(&e), 2);
        assert!(format!("{e:#}").contains("config.toml"), "{e:#}");
        let cfg = "seed = 1\nepisodes = 2\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n";
        std::fs::write(dir.join("config.toml"), cfg).unwrap();
        let e = args.load().unwrap_err();
        assert!(format!("{e:#}").contains("runtime.toml"), "{e:#}");
        std::fs::write(dir.join(RUNTIME_FILE), "window = 0\n").unwrap();
        let e = args.load().unwrap_err();
        assert_eq!(exit_code(&e), 2);
        std::fs::write(dir.join(RUNTIME_FILE), RuntimeConfig::default().to_toml()).unwrap();
        let setup = args.load().unwrap();
        assert_eq!(setup.runtime, RuntimeConfig::default());
        assert_eq!(setup.vector_env().unwrap().observation_dim(), 4);
        let tabular =
            "seed = 1\nepisodes = 2\n[env]\nname = \"cliffwalk\"\n[agent]\nkind = \"qlearning\"\n";
        std::fs::write(dir.join("config.toml"), tabular).unwrap();
        assert_eq!(exit_code(&args.load().unwrap_err()), 2);
    }
}
