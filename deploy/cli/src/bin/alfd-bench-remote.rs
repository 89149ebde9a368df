//! `alfd-bench-remote`: speed of a Gymnasium environment served by the Python adapter (steps per
//! second through `RemoteEnv`, episodes reset as they end), and the round trip of an external
//! expert (`python:alfd_examples:cartpole_balance`). Prints one JSON object per measurement;
//! `deploy/bench/runtime.sh` runs it beside Gymnasium stepping in-process
//! (`deploy/python/bench_inprocess.py`) and `BENCHMARKS.md` records the numbers.
//!
//!     alfd-bench-remote [ENV_ID] [STEPS] [QUERIES]   # default CartPole-v1 20000 5000

use std::sync::Arc;
use std::time::{Duration, Instant};

use alfd_common::config::{EnvConfig, EnvName};
use alfd_common::env::Env;
use alfd_harness::python::{Adapter, AdapterEnv};
use alfd_wire::{self as wire, Process, RemoteDemonstrator, Role, SCHEMA_VERSION};
use anyhow::Context as _;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let id = args
        .first()
        .cloned()
        .unwrap_or_else(|| "CartPole-v1".into());
    let steps: usize = args.get(1).map_or(Ok(20_000), |s| s.parse())?;
    let queries: usize = args.get(2).map_or(Ok(5_000), |s| s.parse())?;
    let run_id = format!("bench-remote-{}", std::process::id());
    let dir = tempfile::Builder::new()
        .prefix("alfd-bench-remote-")
        .tempdir()
        .context("cannot make a scratch directory")?;
    let me = Process::new(Role::Tool, 0);
    let cfg = EnvConfig {
        name: EnvName::Gymnasium,
        max_episode_steps: None,
        p_success: 0.9,
        map: None,
        id: Some(id.clone()),
        kwargs: None,
        size: None,
        mapping_seed: None,
    };
    {
        let adapter = Arc::new(Adapter::env(
            &cfg,
            &run_id,
            "env-0",
            SCHEMA_VERSION,
            &dir.path().join("env.log"),
        )?);
        let mut env = AdapterEnv::open(adapter, &cfg, &run_id, me, SCHEMA_VERSION)?;
        let n = env.num_actions();
        env.reset(Some(0));
        let (mut episodes, start) = (0u64, Instant::now());
        for i in 0..steps {
            let s = env.step((i * 7 + i / 3) % n).context("a step")?;
            if s.done() {
                env.reset(None);
                episodes += 1;
            }
        }
        let secs = start.elapsed().as_secs_f64();
        println!(
            "{}",
            serde_json::json!({"bench": "remote_env", "env": id, "steps": steps,
                "episodes": episodes, "seconds": secs, "steps_per_s": steps as f64 / secs})
        );

        let expert = Adapter::expert(
            "python:alfd_examples:cartpole_balance",
            &run_id,
            "expert-1",
            SCHEMA_VERSION,
            &dir.path().join("expert.log"),
        )?;
        let mut remote = RemoteDemonstrator::new(expert.connect(&run_id, me, SCHEMA_VERSION)?, 2);
        let mut times = Vec::with_capacity(queries);
        for i in 0..queries {
            let x = (i as f32 * 0.37).sin() * 0.1;
            let t = Instant::now();
            remote.act(&[x, -x, x * 0.5, x], Duration::from_secs(10))?;
            times.push(t.elapsed().as_secs_f64() * 1e6);
        }
        times.sort_by(f64::total_cmp);
        let q = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
        println!(
            "{}",
            serde_json::json!({"bench": "external_expert_round_trip_us", "queries": queries,
                "median": q(0.5), "p90": q(0.9), "p99": q(0.99)})
        );
    }
    wire::close_run(&run_id)?;
    Ok(())
}
