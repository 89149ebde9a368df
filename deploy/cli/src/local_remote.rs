//! `alfd local` with Python pieces: a Gymnasium environment (`[env] name = "gymnasium"`) and an
//! external expert (`python:MODULE:FUNCTION`, `sb3:ALGO:PATH`), served by adapters this process
//! starts (logs `OUT/adapter-env-0.log`, `OUT/adapter-expert-1.log`) on a run id of its own, and
//! stopped, with the run id's iceoryx2 files, when the run ends.

use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use alfd_common::agent::Demonstrator;
use alfd_common::config::ExperimentConfig;
use alfd_common::runner::NeuralEnvs;
use alfd_harness::python::{Adapter, AdapterEnv};
use alfd_wire::{Process, RemoteDemonstrator, Role, SCHEMA_VERSION};

/// How long the in-process run waits for an external expert's answer.
const EXPERT_TIMEOUT: Duration = Duration::from_secs(30);

/// Whether `cfg` needs Python pieces in `alfd local`.
pub(crate) fn needed(cfg: &ExperimentConfig) -> bool {
    cfg.env.name.is_remote()
        || alfd_demonstrators::registry::external_policy(&cfg.expert.name).is_some()
}

/// The adapters of one single-process run; dropping it stops them and removes the run id's
/// iceoryx2 files.
pub(crate) struct LocalRemote {
    run_id: String,
}

impl Drop for LocalRemote {
    fn drop(&mut self) {
        if let Err(e) = alfd_wire::close_run(&self.run_id) {
            tracing::warn!("cannot remove the adapters' iceoryx2 files: {e}");
        }
    }
}

/// An external demonstrator for the in-process expert: [`Demonstrator::try_act`] asks the
/// adapter (the in-process expert calls only that); `act` gives action 0 when it fails.
struct External {
    remote: RemoteDemonstrator,
    adapter: Adapter,
}

impl Demonstrator<[f32]> for External {
    fn act(&mut self, s: &[f32]) -> usize {
        self.try_act(s).unwrap_or_else(|e| {
            tracing::error!("{e}");
            0
        })
    }

    fn try_act(&mut self, s: &[f32]) -> Result<usize, String> {
        self.remote
            .act(s, EXPERT_TIMEOUT)
            .map_err(|e| match self.adapter.gone() {
                Some(why) => format!("{e}: {why}"),
                None => e.to_string(),
            })
    }
}

/// What [`start`] gives: the guard (keep it until the run ends), the environments when the
/// environment is a Gymnasium one, and the demonstrator.
pub(crate) type Started = (
    LocalRemote,
    Option<NeuralEnvs>,
    Box<dyn Demonstrator<[f32]>>,
);

/// Starts the adapters `cfg` needs, logging into `out`.
pub(crate) fn start(cfg: &ExperimentConfig, out: &std::path::Path) -> anyhow::Result<Started> {
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() % 1_000_000_000_000);
    let guard = LocalRemote {
        run_id: format!("local-{}-{nanos}", std::process::id()),
    };
    let run_id = guard.run_id.clone();
    let me = Process::new(Role::Tool, 0);
    let envs = if cfg.env.name.is_remote() {
        let log = out.join("adapter-env-0.log");
        let adapter = Arc::new(Adapter::env(
            &cfg.env,
            &run_id,
            "env-0",
            SCHEMA_VERSION,
            &log,
        )?);
        let env = AdapterEnv::open(adapter.clone(), &cfg.env, &run_id, me, SCHEMA_VERSION)?;
        let eval_env = AdapterEnv::open(adapter, &cfg.env, &run_id, me, SCHEMA_VERSION)?;
        Some(NeuralEnvs {
            env: Box::new(env),
            eval_env: Box::new(eval_env),
            oracle: None,
            panel: Vec::new(),
        })
    } else {
        None
    };
    let demonstrator: Box<dyn Demonstrator<[f32]>> =
        match alfd_demonstrators::registry::external_policy(&cfg.expert.name) {
            Some(policy) => {
                let log = out.join("adapter-expert-1.log");
                let adapter = Adapter::expert(policy, &run_id, "expert-1", SCHEMA_VERSION, &log)?;
                let actions = match &envs {
                    Some(e) => e.env.num_actions(),
                    None => alfd_common::env::vector_env(cfg)
                        .map(|e| e.num_actions())
                        .unwrap_or(0),
                };
                let remote =
                    RemoteDemonstrator::new(adapter.connect(&run_id, me, SCHEMA_VERSION)?, actions);
                Box::new(External { remote, adapter })
            }
            None => crate::setup::neural_demonstrator(cfg)?,
        };
    Ok((guard, envs, demonstrator))
}
