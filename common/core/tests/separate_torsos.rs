//! Heads with separate torsos (`agent.shared_torso = false`): the block-diagonal network is the K
//! single-head networks cut out of it, in its forward pass, its gradients and its train steps,
//! and the weights off its blocks stay exactly zero through training.

use alfd_common::nn::{train_step, Adam, Mlp, Params, TrainScratch};
use alfd_common::replay::Batch;
use alfd_common::rng::seeded;
use nalgebra::{DMatrix, DVector};
use rand::Rng as _;

use crate::dqn_loss::{random_batch, OBS};

const H: usize = 6;
const K: usize = 3;
const A: usize = 2;

/// Head `k`'s own network, cut out of the blocks of `net`.
fn head_net(net: &Mlp, k: usize) -> Mlp {
    let p = net.params();
    let (h, a) = (H * k..H * (k + 1), A * k..A * (k + 1));
    let cut = |m: &DMatrix<f32>, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>| {
        DMatrix::from_fn(rows.len(), cols.len(), |i, j| {
            m[(rows.start + i, cols.start + j)]
        })
    };
    let part = |v: &DVector<f32>, r: std::ops::Range<usize>| {
        DVector::from_fn(r.len(), |i, _| v[r.start + i])
    };
    let params = Params {
        w0: cut(&p.w0, 0..OBS, h.clone()),
        b0: part(&p.b0, h.clone()),
        w1: cut(&p.w1, h.clone(), h.clone()),
        b1: part(&p.b1, h.clone()),
        wh: cut(&p.wh, h.clone(), a.clone()),
        bh: part(&p.bh, a),
    };
    Mlp::from_params(params, 1, A).unwrap()
}

/// Every weight of `torso.1` and `heads` off the torsos' blocks.
fn off_block(net: &Mlp) -> Vec<f32> {
    let p = net.params();
    let mut out = Vec::new();
    for i in 0..H * K {
        for j in 0..H * K {
            if i / H != j / H {
                out.push(p.w1[(i, j)]);
            }
        }
        for j in 0..K * A {
            if i / H != j / A {
                out.push(p.wh[(i, j)]);
            }
        }
    }
    out
}

/// Head `k`'s column of a batch's masks, as a one-head batch.
fn head_batch(batch: &Batch, k: usize) -> Batch {
    let masks = (0..batch.size).map(|i| batch.masks[i * K + k]).collect();
    Batch {
        heads: 1,
        masks,
        ..batch.clone()
    }
}

fn close(a: &[f32], b: &[f32], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
            "{what}[{i}]: {x} against {y}"
        );
    }
}

#[test]
fn a_separate_torso_network_is_its_heads_networks_side_by_side() {
    let net = Mlp::separate(OBS, H, K, A, &mut seeded(4));
    assert_eq!((net.hidden(), net.torsos()), (H * K, K));
    assert!(off_block(&net).iter().all(|&w| w == 0.0));
    // Each block is drawn with one torso's fan-in, as PyTorch draws a layer of H inputs.
    let bound = 1.0 / (H as f32).sqrt();
    assert!(net.params().w1.iter().all(|w| w.abs() < bound));
    let mut rng = seeded(9);
    for _ in 0..5 {
        let x: Vec<f32> = (0..OBS).map(|_| rng.random_range(-2.0..2.0)).collect();
        let mut q = vec![0.0; K * A];
        net.forward_one(&x, &mut q);
        for k in 0..K {
            let mut qk = vec![0.0; A];
            head_net(&net, k).forward_one(&x, &mut qk);
            close(&q[k * A..(k + 1) * A], &qk, "Q");
        }
    }
}

#[test]
fn train_steps_of_separate_torsos_are_those_of_each_head_alone_and_keep_the_blocks() {
    let mut online = Mlp::separate(OBS, H, K, A, &mut seeded(4));
    let target = online.clone();
    let mut heads: Vec<Mlp> = (0..K).map(|k| head_net(&online, k)).collect();
    let targets = heads.clone();
    let mut adam = Adam::new(&online);
    let mut adams: Vec<Adam> = heads.iter().map(Adam::new).collect();
    let (mut scratch, mut scratches) = (TrainScratch::default(), vec![TrainScratch::default(); K]);
    let mut rng = seeded(21);
    for _ in 0..4 {
        let batch = random_batch(16, K, A, &mut rng);
        let loss = train_step(&mut online, &target, &mut adam, &batch, 0.9, &mut scratch);
        let mut sum = 0.0;
        for k in 0..K {
            let b = head_batch(&batch, k);
            sum += train_step(
                &mut heads[k],
                &targets[k],
                &mut adams[k],
                &b,
                0.9,
                &mut scratches[k],
            );
        }
        close(&[loss], &[sum], "loss");
        assert!(
            off_block(&online).iter().all(|&w| w == 0.0),
            "off-block weights moved"
        );
        for (k, alone) in heads.iter().enumerate() {
            close(
                &head_net(&online, k).params_flat(),
                &alone.params_flat(),
                "weights",
            );
        }
    }
}

#[test]
fn a_prior_of_separate_torsos_has_separate_torsos_too() {
    let net = Mlp::separate(OBS, H, K, A, &mut seeded(4)).with_prior(3.0, 11);
    let prior = net.prior().unwrap().network();
    assert_eq!((prior.torsos(), prior.hidden()), (K, H * K));
    assert!(off_block(prior).iter().all(|&w| w == 0.0));
}
