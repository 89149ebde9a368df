//! `cargo run --release -p alfd-common --example train_steps -- N`: N train steps of the
//! benchmark's shape (4 observations, K = 2 heads, A = 2 actions, batch 64, hidden 64 unless a
//! second argument says; `nn::train_step`: DQN targets, Huber loss, Adam). `-- N preset`: the
//! recommended CartPole preset's step instead (hidden 128, K = 4, batch 128, double DQN, the
//! large-margin loss on a tenth of the batch, clipped gradients and bounded targets:
//! `nn::train_step_with`). Prints the steps, the seconds, the last loss and a hash of the
//! weights. `-- peak N`: N rounds of the FMA peak probe instead (384 flops a round where the
//! products use AVX-512, 192 where they use AVX2; the first line of output says which).

use alfd_common::nn::{train_step_with, Adam, Mlp, TdConfig, TdLoss, TrainScratch};
use alfd_common::replay::{Batch, ReplayBuffer, Transition};
use alfd_common::rng::seeded;
use rand::Rng as _;

/// As the binaries: blocks the products read start on a cache line.
#[global_allocator]
static ALLOC: alfd_common::alloc::CacheAligned = alfd_common::alloc::CacheAligned;

fn main() {
    let mut args = std::env::args().skip(1).peekable();
    if args.peek().map(String::as_str) == Some("peak") {
        // The FMA peak, timed by the caller (its CPU time).
        let rounds: u64 = args
            .nth(1)
            .and_then(|a| a.parse().ok())
            .unwrap_or(100_000_000);
        let flops = alfd_common::nn::fma_peak_flops_per_round().unwrap_or(0);
        println!("flops_per_round {flops}");
        let t = std::time::Instant::now();
        let v = alfd_common::nn::fma_peak_probe(rounds);
        let s = t.elapsed().as_secs_f64();
        println!(
            "{rounds} rounds of {flops} flops in {s:.3} s: {:.1} GFLOP/s of wall-clock ({v:?})",
            rounds as f64 * flops as f64 / s / 1e9
        );
        return;
    }
    let steps: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let shape = args.next();
    let preset = shape.as_deref() == Some("preset");
    let hidden: usize = match &shape {
        _ if preset => 128,
        Some(h) => h
            .parse()
            .expect("HIDDEN must be a positive integer or `preset`"),
        None => 64,
    };
    let (heads, batch_size) = if preset { (4, 128) } else { (2, 64) };
    let cfg = if preset {
        TdConfig {
            gamma: 0.995f32.powi(3),
            loss: TdLoss::Huber,
            huber_delta: 1.0,
            double: true,
            margin_weight: 1.0,
            margin: 0.8,
            max_grad_norm: Some(10.0),
            target_bounds: Some((0.0, 200.0)),
        }
    } else {
        TdConfig::dqn(0.99)
    };
    if std::env::var_os("ALFD_PORTABLE_KERNELS").is_some_and(|v| v == "1") {
        alfd_common::nn::use_portable_kernels(true);
    }
    let mut rng = seeded(1);
    let mut online = Mlp::new(4, hidden, heads, 2, &mut rng);
    let target = online.clone();
    let mut adam = Adam::new(&online);
    let mut scratch = TrainScratch::default();
    let mut buffer = ReplayBuffer::new(1000, 4, heads);
    for _ in 0..1000 {
        buffer.push(&Transition {
            state: (0..4).map(|_| rng.random_range(-2.0f32..2.0)).collect(),
            action: rng.random_range(0..2),
            reward: 1.0,
            next_state: (0..4).map(|_| rng.random_range(-2.0f32..2.0)).collect(),
            terminated: rng.random::<f32>() < 0.05,
            mask: (0..heads)
                .map(|k| {
                    if k == 0 || rng.random::<bool>() {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect(),
            demo: preset && rng.random::<f32>() < 0.1,
            horizon: 1,
        });
    }
    let mut batch = Batch::default();
    buffer.sample_into(batch_size, &mut rng, &mut batch);
    let t = std::time::Instant::now();
    let mut loss = 0.0;
    for _ in 0..steps {
        loss = train_step_with(&mut online, &target, &mut adam, &batch, &cfg, &mut scratch);
    }
    let secs = t.elapsed().as_secs_f64();
    // FNV-1a over the weights' bits: a kernel change that keeps the numbers keeps this.
    let hash = online
        .params_flat()
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
            (h ^ u64::from(v.to_bits())).wrapping_mul(0x0100_0000_01b3)
        });
    println!("{steps} train steps (hidden {hidden}, K = {heads}, batch {batch_size}) in {secs:.3} s; last loss {loss}; weights {hash:016x}");
}
