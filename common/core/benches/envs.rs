//! Criterion benchmarks of the environments' step: CartPole, MountainCar-v0
//! and Acrobot-v1 stepped through a fixed, random-looking sequence of actions, reset (without a
//! new seed, as Gymnasium's `reset()`) whenever an episode ends. One iteration is one step, so
//! Criterion's throughput is environment steps per second. `deploy/bench/peers.sh` runs them
//! beside Gymnasium's; results in BENCHMARKS.md.

use std::hint::black_box;

use alfd_common::config::EnvName;
use alfd_common::env::{vector_env_named, Acrobot, CartPole, Env, MountainCar};
use alfd_common::rng::seeded;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rand::Rng as _;

/// Length of the action sequence, cycled through.
const ACTIONS_LEN: usize = 4096;

/// The fixed action sequence for an environment with `n` actions.
fn action_sequence(n: usize, seed: u64) -> Vec<usize> {
    let mut rng = seeded(seed);
    (0..ACTIONS_LEN).map(|_| rng.random_range(0..n)).collect()
}

/// Benchmarks `env.step` under `name`, one step per iteration.
fn bench_env<E: Env + ?Sized>(c: &mut Criterion, name: &str, env: &mut E) {
    let actions = action_sequence(env.num_actions(), 7);
    env.reset(Some(0));
    let mut i = 0;
    let mut group = c.benchmark_group("envs");
    group.throughput(Throughput::Elements(1));
    group.bench_function(name, |b| {
        b.iter(|| {
            i = (i + 1) % ACTIONS_LEN;
            let step = env.step(black_box(actions[i])).expect("valid action");
            if step.done() {
                env.reset(None);
            }
            black_box(step.observation)
        })
    });
    group.finish();
}

fn bench_envs(c: &mut Criterion) {
    // CartPole with a long limit, as Gymnasium's CartPole-v1 made with a large
    // `max_episode_steps`: episodes end by termination. MountainCar-v0 and Acrobot-v1 keep their
    // registered limits (200 and 500 steps).
    bench_env(c, "env_step_cartpole", &mut CartPole::new(1_000_000));
    bench_env(c, "env_step_mountaincar", &mut MountainCar::new(200));
    bench_env(c, "env_step_acrobot", &mut Acrobot::new(500));
    // CartPole as the runner steps it: boxed, observations as `Vec<f32>`.
    let mut env = vector_env_named(EnvName::Cartpole, 1_000_000).expect("a vector environment");
    bench_env(c, "env_step_cartpole_vec", &mut *env);
}

criterion_group!(benches, bench_envs);
criterion_main!(benches);
