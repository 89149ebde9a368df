//! `cargo run --release -p alfd-common --example train_steps -- N`: N train steps of the
//! benchmark's shape (4 observations, K = 2 heads, A = 2 actions, batch 64, hidden 64 unless a
//! second argument says; `nn::train_step`: DQN targets, Huber loss, Adam). `-- N preset`: the
//! recommended CartPole preset's step instead (hidden 128, K = 4, batch 128, double DQN, the
//! large-margin loss on a tenth of the batch, clipped gradients and bounded targets:
//! `nn::train_step_with`). Prints the steps, the seconds, the last loss and a hash of the
//! weights. `-- peak N`: N rounds of the FMA peak probe instead (384 flops a round where the
//! products use AVX-512, 192 where they use AVX2; the first line of output says which).
//! `-- parts N [HIDDEN | preset]`: where the step's time goes, one JSON line: N calls of each
//! part alone (a forward pass on the batch's states, the backward pass, Adam's step from a
//! fresh optimiser, the gradient clipping where the step clips) and N whole steps, taken in
//! turns of 100 calls each, in microseconds of wall-clock per call.

use alfd_common::nn::{
    clip_grad_norm, train_step_with, Adam, ForwardCache, Mlp, TdConfig, TdLoss, TrainScratch,
};
use alfd_common::replay::{Batch, ReplayBuffer, Transition};
use alfd_common::rng::seeded;
use rand::Rng as _;

/// As the binaries: blocks the products read start on a cache line.
#[global_allocator]
static ALLOC: alfd_common::alloc::CacheAligned = alfd_common::alloc::CacheAligned;

fn main() {
    let mut args = std::env::args().skip(1).peekable();
    match args.peek().map(String::as_str) {
        Some("peak") => peak(
            args.nth(1)
                .and_then(|a| a.parse().ok())
                .unwrap_or(100_000_000),
        ),
        Some("parts") => {
            let steps = args.nth(1).and_then(|a| a.parse().ok()).unwrap_or(10_000);
            parts(steps, &Shape::parse(args.next()));
        }
        _ => {
            let steps = args.next().and_then(|a| a.parse().ok()).unwrap_or(10_000);
            steps_timed(steps, &Shape::parse(args.next()));
        }
    }
}

/// The FMA peak, timed by the caller (its CPU time).
fn peak(rounds: u64) {
    let flops = alfd_common::nn::fma_peak_flops_per_round().unwrap_or(0);
    println!("flops_per_round {flops}");
    let t = std::time::Instant::now();
    let v = alfd_common::nn::fma_peak_probe(rounds);
    let s = t.elapsed().as_secs_f64();
    println!(
        "{rounds} rounds of {flops} flops in {s:.3} s: {:.1} GFLOP/s of wall-clock ({v:?})",
        rounds as f64 * flops as f64 / s / 1e9
    );
}

/// The network, loss and batch of one benchmark shape.
struct Shape {
    preset: bool,
    hidden: usize,
    heads: usize,
    batch_size: usize,
    cfg: TdConfig,
}

impl Shape {
    /// `HIDDEN`, `preset`, or hidden 64 when absent.
    fn parse(arg: Option<String>) -> Self {
        let preset = arg.as_deref() == Some("preset");
        let hidden: usize = match &arg {
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
        Self {
            preset,
            hidden,
            heads,
            batch_size,
            cfg,
        }
    }

    /// One train step of this shape's loss.
    fn step(
        &self,
        online: &mut Mlp,
        target: &Mlp,
        adam: &mut Adam,
        batch: &Batch,
        scratch: &mut TrainScratch,
    ) -> f32 {
        train_step_with(online, target, adam, batch, &self.cfg, scratch)
    }

    /// A fresh network and a batch of the replay buffer.
    fn setup(&self) -> (Mlp, Batch) {
        if std::env::var_os("ALFD_PORTABLE_KERNELS").is_some_and(|v| v == "1") {
            alfd_common::nn::use_portable_kernels(true);
        }
        let mut rng = seeded(1);
        let online = Mlp::new(4, self.hidden, self.heads, 2, &mut rng);
        let mut buffer = ReplayBuffer::new(1000, 4, self.heads);
        for _ in 0..1000 {
            buffer.push(&Transition {
                state: (0..4).map(|_| rng.random_range(-2.0f32..2.0)).collect(),
                action: rng.random_range(0..2),
                reward: 1.0,
                next_state: (0..4).map(|_| rng.random_range(-2.0f32..2.0)).collect(),
                terminated: rng.random::<f32>() < 0.05,
                mask: (0..self.heads)
                    .map(|k| {
                        if k == 0 || rng.random::<bool>() {
                            1.0
                        } else {
                            0.0
                        }
                    })
                    .collect(),
                demo: self.preset && rng.random::<f32>() < 0.1,
                horizon: 1,
            });
        }
        let mut batch = Batch::default();
        buffer.sample_into(self.batch_size, &mut rng, &mut batch);
        (online, batch)
    }
}

/// `steps` train steps; prints the seconds, the last loss and a hash of the weights.
fn steps_timed(steps: u64, shape: &Shape) {
    let (mut online, batch) = shape.setup();
    let target = online.clone();
    let mut adam = Adam::new(&online);
    let mut scratch = TrainScratch::default();
    let t = std::time::Instant::now();
    let mut loss = 0.0;
    for _ in 0..steps {
        loss = shape.step(&mut online, &target, &mut adam, &batch, &mut scratch);
    }
    let secs = t.elapsed().as_secs_f64();
    // FNV-1a over the weights' bits: a kernel change that keeps the numbers keeps this.
    let hash = online
        .params_flat()
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
            (h ^ u64::from(v.to_bits())).wrapping_mul(0x0100_0000_01b3)
        });
    let (hidden, heads, batch_size) = (shape.hidden, shape.heads, shape.batch_size);
    println!("{steps} train steps (hidden {hidden}, K = {heads}, batch {batch_size}) in {secs:.3} s; last loss {loss}; weights {hash:016x}");
}

/// Seconds of `calls` calls of `f`.
fn timed(calls: u64, mut f: impl FnMut()) -> f64 {
    let t = std::time::Instant::now();
    for _ in 0..calls {
        f();
    }
    t.elapsed().as_secs_f64()
}

/// Each part of the step alone and the whole step, about `n` times each: one JSON line.
fn parts(n: u64, shape: &Shape) {
    let (mut online, batch) = shape.setup();
    let target = online.clone();
    // The loss's gradient once, for Adam to work on; for the backward pass, dL/dQ nonzero for
    // one action of two in each head, as the loss leaves it (its values do not change the time).
    let mut scratch = TrainScratch::default();
    alfd_common::nn::loss_and_grads_with(&online, &target, &batch, &shape.cfg, &mut scratch);
    let mut grads = scratch.grads().expect("the loss leaves gradients").clone();
    let dq = nalgebra::DMatrix::from_fn(shape.batch_size, online.outputs(), |i, j| {
        if (i + j) % online.actions() == 0 {
            0.01
        } else {
            0.0
        }
    });
    let mut cache = ForwardCache::default();
    online.forward_batch(&batch.states, &mut cache);
    let mut back = grads.clone();
    let mut moved = online.clone();
    let mut adam_alone = Adam::new(&online);
    let mut adam = Adam::new(&online);
    // In chunks of CHUNK calls of each part in turn, so that every part meets the same moments
    // of the machine (a virtual machine's speed drifts within seconds).
    const CHUNK: u64 = 100;
    let mut secs = [0.0f64; 5];
    for _ in 0..n.div_ceil(CHUNK) {
        secs[0] += timed(CHUNK, || online.forward_batch(&batch.states, &mut cache));
        secs[1] += timed(CHUNK, || online.backward(&mut cache, &dq, &mut back));
        secs[2] += timed(CHUNK, || adam_alone.step(&mut moved, &grads));
        if let Some(max) = shape.cfg.max_grad_norm {
            secs[3] += timed(CHUNK, || {
                clip_grad_norm(&mut grads, max);
            });
        }
        secs[4] += timed(CHUNK, || {
            shape.step(&mut online, &target, &mut adam, &batch, &mut scratch);
        });
        // The step moved the weights: the next backward pass reads the activations of these.
        online.forward_batch(&batch.states, &mut cache);
    }
    let calls = n.div_ceil(CHUNK) * CHUNK;
    let [forward_us, backward_us, adam_us, clip_us, step_us] = secs.map(|s| s / calls as f64 * 1e6);
    let forwards = if shape.cfg.double { 3 } else { 2 };
    println!(
        "{{\"calls\": {calls}, \"forward_us\": {forward_us:.4}, \"forwards_per_step\": {forwards}, \"backward_us\": {backward_us:.4}, \"adam_us\": {adam_us:.4}, \"clip_us\": {clip_us:.4}, \"step_us\": {step_us:.4}}}"
    );
}
