//! Criterion benchmarks of the core's hot paths: the learner's train step and the actor's act step
//! (targets 80 µs and 5 µs). Results and machine in BENCHMARKS.md.

use std::hint::black_box;

use alfd_common::nn::{train_step, Adam, Mlp, TrainScratch};
use alfd_common::query::PercentileGate;
use alfd_common::replay::{Batch, ReplayBuffer, Transition};
use alfd_common::rng::seeded;
use criterion::{criterion_group, criterion_main, Criterion};
use rand::Rng as _;

const OBS: usize = 4;
const HIDDEN: usize = 64;
const HEADS: usize = 2;
const ACTIONS: usize = 2;
const BATCH: usize = 64;

fn random_state(rng: &mut alfd_common::rng::Rng) -> Vec<f32> {
    (0..OBS).map(|_| rng.random_range(-2.0f32..2.0)).collect()
}

/// A replay buffer of random CartPole-sized transitions with Bernoulli(0.5) masks.
fn replay(rng: &mut alfd_common::rng::Rng) -> ReplayBuffer {
    let mut buffer = ReplayBuffer::new(10_000, OBS, HEADS);
    for _ in 0..10_000 {
        let t = Transition {
            state: random_state(rng),
            action: rng.random_range(0..ACTIONS as u32),
            reward: 1.0,
            next_state: random_state(rng),
            terminated: rng.random::<f32>() < 0.05,
            mask: (0..HEADS)
                .map(|_| if rng.random::<bool>() { 1.0 } else { 0.0 })
                .collect(),
            demo: false,
            horizon: 1,
        };
        buffer.push(&t);
    }
    buffer
}

fn bench_train_step(c: &mut Criterion) {
    let mut rng = seeded(1);
    let mut online = Mlp::new(OBS, HIDDEN, HEADS, ACTIONS, &mut rng);
    let target = online.clone();
    let mut adam = Adam::new(&online);
    let mut scratch = TrainScratch::default();
    let buffer = replay(&mut rng);
    let mut batch = Batch::default();
    buffer.sample_into(BATCH, &mut rng, &mut batch);

    // The update alone: online forward, target forward, loss, backward, Adam.
    c.bench_function("train_step_k2_a2_b64", |b| {
        b.iter(|| {
            black_box(train_step(
                &mut online,
                &target,
                &mut adam,
                black_box(&batch),
                0.99,
                &mut scratch,
            ))
        })
    });
    // The learner's whole iteration: sampling the batch from a full buffer, then the update.
    c.bench_function("sample_and_train_step_k2_a2_b64", |b| {
        b.iter(|| {
            buffer.sample_into(BATCH, &mut rng, &mut batch);
            black_box(train_step(
                &mut online,
                &target,
                &mut adam,
                &batch,
                0.99,
                &mut scratch,
            ))
        })
    });
}

fn bench_act_step(c: &mut Criterion) {
    let mut rng = seeded(2);
    let net = Mlp::new(OBS, HIDDEN, HEADS, ACTIONS, &mut rng);
    let states: Vec<Vec<f32>> = (0..256).map(|_| random_state(&mut rng)).collect();
    let mut rule = PercentileGate::new(1000, 99.0);
    let mut i = 0;

    c.bench_function("forward_one_k2_a2", |b| {
        let mut q = [0.0f32; HEADS * ACTIONS];
        b.iter(|| {
            i = (i + 1) % states.len();
            net.forward_one(black_box(&states[i]), &mut q);
            black_box(q)
        })
    });
    // Algorithm 1 lines 3-16 as the actor runs them (`NeuralActor::decide`): the K heads'
    // Q-values, their JS divergence, the query decision (L_q = 1000, p_r = 99, the CartPole
    // configs' values) and the greedy action of the episode's head.
    c.bench_function("act_step_k2_a2", |b| {
        let cfg = alfd_common::config::ExperimentConfig::from_toml(
            "seed = 0\nepisodes = 1\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n[query]\nrule = \"js\"\nqueue_len = 1000\npercentile = 99.0\n",
        )
        .expect("valid config");
        let mut actor = alfd_common::agent::NeuralActor::new(
            &cfg.agent,
            &cfg.rule_spec(),
            cfg.shaping.kind,
            OBS,
            ACTIONS,
            seeded(3),
        );
        actor.copy_weights_from(&net, 0);
        actor.begin_episode();
        b.iter(|| {
            i = (i + 1) % states.len();
            black_box(actor.decide(
                black_box(&states[i]),
                i as u64,
                alfd_common::query::BudgetView::FRESH,
            ))
        })
    });
    c.bench_function("query_rule_observe_lq1000", |b| {
        b.iter(|| {
            i = (i + 1) % states.len();
            black_box(rule.observe(black_box(f64::from(states[i][0]).abs())))
        })
    });
}

/// The single-core FMA peak (12 independent chains of FMAs as wide as the products' kernels:
/// 384 flops a round with AVX-512, 192 with AVX2), against
/// which the train step's GFLOP/s are reported in BENCHMARKS.md.
fn bench_fma_peak(c: &mut Criterion) {
    if alfd_common::nn::fma_peak_probe(1).is_none() {
        eprintln!("no AVX2+FMA: fma_peak_10k_rounds skipped");
        return;
    }
    c.bench_function("fma_peak_10k_rounds", |b| {
        b.iter(|| black_box(alfd_common::nn::fma_peak_probe(black_box(10_000))))
    });
}

criterion_group!(benches, bench_train_step, bench_act_step, bench_fma_peak);
criterion_main!(benches);
