//! `alfd local` with Python pieces: a Gymnasium environment (`[env] name = "gymnasium"`) and an
//! external expert (`python:MODULE:FUNCTION`, `sb3:ALGO:PATH`), served by adapters this process
//! starts (logs `OUT/adapter-env-0.log`, `OUT/adapter-expert-1.log`) on a run id of its own, and
//! stopped, with the run id's iceoryx2 files, when the run ends.

use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use alfd_common::agent::Demonstrator;
use alfd_common::config::ExperimentConfig;
use alfd_common::runner::NeuralEnvs;
use alfd_harness::python::{Adapter, AdapterDemonstrator, AdapterEnv};
use alfd_wire::{Process, Role, SCHEMA_VERSION};

/// How long the in-process run waits for an external expert's answer.
const EXPERT_TIMEOUT: Duration = Duration::from_secs(30);

/// Whether `cfg` needs Python pieces in `alfd local`.
pub(crate) fn needed(cfg: &ExperimentConfig) -> bool {
    let external = |name: &str| alfd_demonstrators::registry::external_policy(name).is_some();
    cfg.env.name.is_remote()
        || external(&cfg.expert.name)
        || cfg.experts.iter().any(|e| external(&e.name))
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

/// What [`start`] gives: the guard (keep it until the run ends), the environments when the
/// environment is a Gymnasium one, the demonstrator, and the demonstrators of `[[experts]]`.
pub(crate) struct Started {
    pub guard: LocalRemote,
    pub envs: Option<NeuralEnvs>,
    pub demonstrator: Box<dyn Demonstrator<[f32]>>,
    pub panel: Vec<Box<dyn Demonstrator<[f32]>>>,
}

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
    let actions = match &envs {
        Some(e) => e.env.num_actions(),
        None => alfd_common::env::vector_env(cfg)
            .map(|e| e.num_actions())
            .unwrap_or(0),
    };
    // External experts answer from adapters of their own: `expert-1` the one expert,
    // `expert-1-I` the I-th of `[[experts]]`.
    let adapter = |policy: &str, name: &str| {
        let log = out.join(format!("adapter-{name}.log"));
        let id = (run_id.as_str(), name);
        AdapterDemonstrator::start(
            policy,
            id,
            me,
            SCHEMA_VERSION,
            actions,
            &log,
            EXPERT_TIMEOUT,
        )
    };
    let demonstrator: Box<dyn Demonstrator<[f32]>> =
        match alfd_demonstrators::registry::external_policy(&cfg.expert.name) {
            Some(policy) => Box::new(adapter(policy, "expert-1")?),
            None if cfg.experts.is_empty() => crate::setup::neural_demonstrator(cfg)?,
            None => Box::new(alfd_common::agent::NoExpert),
        };
    let people = alfd_demonstrators::registry::People::Refused;
    let panel = alfd_demonstrators::registry::panel(cfg, people, |i, policy| {
        Ok(Box::new(adapter(policy, &format!("expert-1-{i}"))?))
    })?;
    Ok(Started {
        guard,
        envs,
        demonstrator,
        panel,
    })
}
