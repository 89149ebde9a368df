//! The (Bootstrapped) DQN loss and train step: the loss against a separate f64 implementation,
//! its gradient against central finite differences of that implementation, the role of masks and
//! terminal flags, and learning on a small fixed problem.

use alfd_common::nn::{dqn_loss, loss_and_grads, train_step, Adam, Mlp, TrainScratch, PARAM_NAMES};
use alfd_common::replay::Batch;
use alfd_common::rng::{seeded, Rng};
use rand::Rng as _;

pub(crate) const OBS: usize = 4;

/// A random batch: states in [-2, 2], rewards in [-3, 3] (so that some TD errors fall in
/// Huber's linear part), a third of transitions terminal, masks Bernoulli(0.6).
pub(crate) fn random_batch(size: usize, heads: usize, actions: usize, rng: &mut Rng) -> Batch {
    let mut uniform = |lo: f32, hi: f32, n: usize| -> Vec<f32> {
        (0..n).map(|_| rng.random_range(lo..hi)).collect()
    };
    let states = uniform(-2.0, 2.0, size * OBS);
    let next_states = uniform(-2.0, 2.0, size * OBS);
    let rewards = uniform(-3.0, 3.0, size);
    let terminated = uniform(0.0, 1.0, size)
        .into_iter()
        .map(|u| if u < 0.33 { 1.0 } else { 0.0 })
        .collect();
    let masks = uniform(0.0, 1.0, size * heads)
        .into_iter()
        .map(|u| if u < 0.6 { 1.0 } else { 0.0 })
        .collect();
    let actions = (0..size)
        .map(|_| rng.random_range(0..actions as u32))
        .collect();
    Batch {
        size,
        obs_dim: OBS,
        heads,
        states,
        actions,
        rewards,
        next_states,
        terminated,
        masks,
        demos: vec![],
        horizons: vec![],
    }
}

/// A separate forward pass in f64 over the flat parameters (PyTorch layout).
pub(crate) fn forward64(p: &[f64], hidden: usize, outputs: usize, x: &[f64]) -> Vec<f64> {
    let layer = |p: &[f64], n_in: usize, n_out: usize, x: &[f64], relu: bool| -> Vec<f64> {
        let (w, b) = p.split_at(n_in * n_out);
        (0..n_out)
            .map(|r| {
                let z = b[r] + (0..n_in).map(|c| w[r * n_in + c] * x[c]).sum::<f64>();
                if relu {
                    z.max(0.0)
                } else {
                    z
                }
            })
            .collect()
    };
    let l0 = OBS * hidden + hidden;
    let l1 = hidden * hidden + hidden;
    let h0 = layer(&p[..l0], OBS, hidden, x, true);
    let h1 = layer(&p[l0..l0 + l1], hidden, hidden, &h0, true);
    layer(&p[l0 + l1..], hidden, outputs, &h1, false)
}

/// The loss of `alfd_common::nn::dqn`, written out again in f64.
fn loss64(
    online: &[f64],
    target: &[f64],
    dims: (usize, usize, usize),
    b: &Batch,
    gamma: f64,
) -> f64 {
    let (hidden, heads, actions) = dims;
    let huber = |td: f64| {
        if td.abs() < 1.0 {
            0.5 * td * td
        } else {
            td.abs() - 0.5
        }
    };
    let mut total = 0.0;
    for i in 0..b.size {
        let s: Vec<f64> = b.states[i * OBS..(i + 1) * OBS]
            .iter()
            .map(|&v| v.into())
            .collect();
        let s2: Vec<f64> = b.next_states[i * OBS..(i + 1) * OBS]
            .iter()
            .map(|&v| v.into())
            .collect();
        let q = forward64(online, hidden, heads * actions, &s);
        let qt = forward64(target, hidden, heads * actions, &s2);
        for k in 0..heads {
            let max_next = qt[k * actions..(k + 1) * actions]
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max);
            let y = f64::from(b.rewards[i]) + gamma * (1.0 - f64::from(b.terminated[i])) * max_next;
            let td = q[k * actions + b.actions[i] as usize] - y;
            total += f64::from(b.masks[i * heads + k]) * huber(td);
        }
    }
    total / b.size as f64
}

fn to64(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x.into()).collect()
}

#[test]
fn gradient_matches_finite_differences_of_the_loss() {
    let (hidden, heads, actions) = (16, 2, 3);
    let mut rng = seeded(21);
    let online = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let target = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let batch = random_batch(32, heads, actions, &mut rng);
    let gamma = 0.99;
    let mut scratch = TrainScratch::default();
    let loss = loss_and_grads(&online, &target, &batch, gamma, &mut scratch);
    let grads: Vec<f32> = scratch.grads().expect("gradients").tensors().concat();

    let p = to64(&online.params_flat());
    let t = to64(&target.params_flat());
    let dims = (hidden, heads, actions);
    let reference = loss64(&p, &t, dims, &batch, f64::from(gamma));
    assert!(
        (f64::from(loss) - reference).abs() <= 1e-5 * reference,
        "loss {loss} vs f64 {reference}"
    );
    assert_eq!(
        loss,
        dqn_loss(&online, &target, &batch, gamma, &mut scratch)
    );

    // Central differences over every parameter (454 of them).
    let eps = 1e-5;
    let mut checked = 0;
    let mut worst = 0.0f64;
    let mut offset = 0;
    for (name, tensor) in PARAM_NAMES.iter().zip(online.params().tensors()) {
        let mut largest = 0.0f64;
        for j in offset..offset + tensor.len() {
            let mut plus = p.clone();
            plus[j] += eps;
            let mut minus = p.clone();
            minus[j] -= eps;
            let fd = (loss64(&plus, &t, dims, &batch, f64::from(gamma))
                - loss64(&minus, &t, dims, &batch, f64::from(gamma)))
                / (2.0 * eps);
            let g = f64::from(grads[j]);
            let err = (g - fd).abs() / (1e-3 * fd.abs() + 1e-6);
            assert!(
                err <= 1.0,
                "{name}[{}]: analytic {g} vs finite difference {fd}",
                j - offset
            );
            worst = worst.max(err);
            largest = largest.max(fd.abs());
            checked += 1;
        }
        // Every tensor has a gradient worth checking.
        assert!(largest > 1e-3, "{name}: largest gradient {largest}");
        offset += tensor.len();
    }
    assert_eq!(checked, online.num_params());
    assert!(worst <= 1.0);
}

#[test]
fn masked_heads_get_no_gradient() {
    let (hidden, heads, actions) = (8, 3, 2);
    let mut rng = seeded(5);
    let online = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let target = online.clone();
    let mut batch = random_batch(16, heads, actions, &mut rng);
    // Head 1 trains on nothing, heads 0 and 2 on everything.
    for i in 0..batch.size {
        batch.masks[i * heads..(i + 1) * heads].copy_from_slice(&[1.0, 0.0, 1.0]);
    }
    let mut scratch = TrainScratch::default();
    loss_and_grads(&online, &target, &batch, 0.99, &mut scratch);
    let g = scratch.grads().expect("gradients");
    for k in 0..heads {
        for a in 0..actions {
            let col = k * actions + a;
            let norm: f32 = g.wh.column(col).iter().map(|v| v.abs()).sum::<f32>() + g.bh[col].abs();
            if k == 1 {
                assert_eq!(norm, 0.0, "head 1 action {a}");
            } else {
                assert!(norm > 0.0, "head {k} action {a}");
            }
        }
    }
}

#[test]
fn terminal_steps_do_not_bootstrap_and_others_do() {
    let (hidden, heads, actions) = (8, 1, 2);
    let mut rng = seeded(8);
    let online = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let target = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let mut batch = random_batch(1, heads, actions, &mut rng);
    batch.masks = vec![1.0];
    batch.rewards = vec![0.25];
    let (mut q, mut qt) = ([0.0f32; 2], [0.0f32; 2]);
    online.forward_one(&batch.states, &mut q);
    target.forward_one(&batch.next_states, &mut qt);
    let q_sa = q[batch.actions[0] as usize];
    let huber = |td: f32| {
        if td.abs() < 1.0 {
            0.5 * td * td
        } else {
            td.abs() - 0.5
        }
    };
    let mut scratch = TrainScratch::default();

    batch.terminated = vec![1.0];
    let terminal = dqn_loss(&online, &target, &batch, 0.9, &mut scratch);
    assert!((terminal - huber(q_sa - 0.25)).abs() < 1e-6, "{terminal}");

    batch.terminated = vec![0.0];
    let bootstrapped = dqn_loss(&online, &target, &batch, 0.9, &mut scratch);
    let y = 0.25 + 0.9 * qt[0].max(qt[1]);
    assert!(
        (bootstrapped - huber(q_sa - y)).abs() < 1e-6,
        "{bootstrapped}"
    );
    assert!((terminal - bootstrapped).abs() > 1e-4);
}

#[test]
fn train_step_learns_a_fixed_batch() {
    // Terminal transitions: the targets are the rewards, r = sin(2 s_0) + (a - 0.5) s_1.
    let (hidden, heads, actions) = (64, 2, 2);
    let mut rng = seeded(3);
    let mut online = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let target = online.clone();
    let mut batch = random_batch(64, heads, actions, &mut rng);
    batch.terminated = vec![1.0; 64];
    batch.masks = vec![1.0; 64 * heads];
    batch.rewards = (0..64)
        .map(|i| {
            let s = &batch.states[i * OBS..(i + 1) * OBS];
            (2.0 * s[0]).sin() + (batch.actions[i] as f32 - 0.5) * s[1]
        })
        .collect();
    let mut adam = Adam::new(&online);
    let mut scratch = TrainScratch::default();
    let first = train_step(&mut online, &target, &mut adam, &batch, 0.99, &mut scratch);
    let mut last = first;
    for _ in 0..999 {
        last = train_step(&mut online, &target, &mut adam, &batch, 0.99, &mut scratch);
    }
    assert_eq!(adam.steps(), 1000);
    assert!(first > 0.1, "initial loss {first}");
    assert!(last < first / 100.0, "loss went from {first} to {last}");
    // The target network was only read.
    assert_ne!(online, target);
}
