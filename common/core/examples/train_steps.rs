//! `cargo run --release -p alfd-common --example train_steps -- N`: N train steps of the
//! benchmark's shape (K = 2, A = 2, batch 64, hidden 64 unless a second argument says), for
//! `perf stat -e cycles:u` (CPU cycles per step do not depend on what else the machine runs, as
//! wall-clock time does). Prints the steps, the seconds, the last loss and a hash of the weights. `-- peak N`: N rounds
//! of the FMA peak probe instead (192 flops a round).

use alfd_common::nn::{train_step, Adam, Mlp, TrainScratch};
use alfd_common::replay::{Batch, ReplayBuffer, Transition};
use alfd_common::rng::seeded;
use rand::Rng as _;

fn main() {
    let mut args = std::env::args().skip(1).peekable();
    if args.peek().map(String::as_str) == Some("peak") {
        // The FMA peak: 192 flops a round, timed by the caller (`perf stat -e task-clock`).
        let rounds: u64 = args
            .nth(1)
            .and_then(|a| a.parse().ok())
            .unwrap_or(100_000_000);
        let t = std::time::Instant::now();
        let v = alfd_common::nn::fma_peak_probe(rounds);
        let s = t.elapsed().as_secs_f64();
        println!(
            "{rounds} rounds of 192 flops in {s:.3} s: {:.1} GFLOP/s of wall-clock ({v:?})",
            rounds as f64 * 192.0 / s / 1e9
        );
        return;
    }
    let steps: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let hidden: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(64);
    if std::env::var_os("ALFD_PORTABLE_KERNELS").is_some_and(|v| v == "1") {
        alfd_common::nn::use_portable_kernels(true);
    }
    let mut rng = seeded(1);
    let mut online = Mlp::new(4, hidden, 2, 2, &mut rng);
    let target = online.clone();
    let mut adam = Adam::new(&online);
    let mut scratch = TrainScratch::default();
    let mut buffer = ReplayBuffer::new(1000, 4, 2);
    for _ in 0..1000 {
        buffer.push(&Transition {
            state: (0..4).map(|_| rng.random_range(-2.0f32..2.0)).collect(),
            action: rng.random_range(0..2),
            reward: 1.0,
            next_state: (0..4).map(|_| rng.random_range(-2.0f32..2.0)).collect(),
            terminated: rng.random::<f32>() < 0.05,
            mask: vec![1.0, if rng.random::<bool>() { 1.0 } else { 0.0 }],
            demo: false,
            horizon: 1,
        });
    }
    let mut batch = Batch::default();
    buffer.sample_into(64, &mut rng, &mut batch);
    let t = std::time::Instant::now();
    let mut loss = 0.0;
    for _ in 0..steps {
        loss = train_step(&mut online, &target, &mut adam, &batch, 0.99, &mut scratch);
    }
    let secs = t.elapsed().as_secs_f64();
    // FNV-1a over the weights' bits: a kernel change that keeps the numbers keeps this.
    let hash = online
        .params_flat()
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
            (h ^ u64::from(v.to_bits())).wrapping_mul(0x0100_0000_01b3)
        });
    println!("{steps} train steps (hidden {hidden}) in {secs:.3} s; last loss {loss}; weights {hash:016x}");
}
