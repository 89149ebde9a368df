//! The learner's options beside the paper's loss: MSE, Double DQN targets, DQfD's large-margin
//! loss, gradient clipping, Polyak target updates, `learning_starts`, demonstrations sampled more
//! often, n-step targets. Each is checked against an f64 recomputation (and its gradient against central finite
//! differences of it) or a hand-computed case.

use alfd_common::agent::NeuralLearner;
use alfd_common::config::ExperimentConfig;
use alfd_common::nn::{
    clip_grad_norm, loss_and_grads_with, Mlp, Params, TdConfig, TdLoss, TrainScratch,
};
use alfd_common::replay::{Batch, Transition};
use alfd_common::rng::seeded;

use crate::dqn_loss::{forward64, random_batch, OBS};

/// The loss of `TdConfig` written out again in f64. Double DQN's next action is chosen by
/// `chooser` (the unperturbed online network in finite differences: the gradient holds the
/// argmax fixed).
fn loss64(
    online: &[f64],
    chooser: &[f64],
    target: &[f64],
    dims: (usize, usize, usize),
    b: &Batch,
    cfg: &TdConfig,
) -> f64 {
    let (hidden, heads, actions) = dims;
    let row = |v: &[f32], i: usize| -> Vec<f64> {
        v[i * OBS..(i + 1) * OBS]
            .iter()
            .map(|&x| x.into())
            .collect()
    };
    let mut total = 0.0;
    let delta = f64::from(cfg.huber_delta);
    for i in 0..b.size {
        let q = forward64(online, hidden, heads * actions, &row(&b.states, i));
        let qt = forward64(target, hidden, heads * actions, &row(&b.next_states, i));
        let qo = forward64(chooser, hidden, heads * actions, &row(&b.next_states, i));
        let a = b.actions[i] as usize;
        for k in 0..heads {
            let m = f64::from(b.masks[i * heads + k]);
            if m == 0.0 {
                continue;
            }
            let h = |v: &[f64], c: usize| v[k * actions + c];
            let next = if cfg.double {
                let best = (0..actions).fold(0, |x, c| if h(&qo, c) > h(&qo, x) { c } else { x });
                h(&qt, best)
            } else {
                (0..actions)
                    .map(|c| h(&qt, c))
                    .fold(f64::NEG_INFINITY, f64::max)
            };
            // An h-step transition bootstraps with gamma^h.
            let horizon = b.horizons.get(i).map_or(1, |&h| i32::from(h));
            let y = f64::from(b.rewards[i])
                + f64::from(cfg.gamma).powi(horizon) * (1.0 - f64::from(b.terminated[i])) * next;
            let y = match cfg.target_bounds {
                Some((lo, hi)) => y.clamp(f64::from(lo), f64::from(hi)),
                None => y,
            };
            let td = h(&q, a) - y;
            total += m * match cfg.loss {
                TdLoss::Huber if td.abs() < delta => 0.5 * td * td,
                TdLoss::Huber => delta * (td.abs() - 0.5 * delta),
                TdLoss::Mse => td * td,
            };
            if cfg.margin_weight > 0.0 && b.demos[i] != 0.0 {
                let best = (0..actions)
                    .map(|c| h(&q, c) + if c == a { 0.0 } else { f64::from(cfg.margin) })
                    .fold(f64::NEG_INFINITY, f64::max);
                total += m * f64::from(cfg.margin_weight) * (best - h(&q, a));
            }
        }
    }
    total / b.size as f64
}

fn check_against_f64(cfg: TdConfig) {
    check_against_f64_with(cfg, vec![]);
}

/// As [`check_against_f64`], the batch's transitions with these horizons (empty: one-step).
fn check_against_f64_with(cfg: TdConfig, horizons: Vec<u8>) {
    let (hidden, heads, actions) = (8, 2, 3);
    let mut rng = seeded(77);
    let online = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let target = Mlp::new(OBS, hidden, heads, actions, &mut rng);
    let mut batch = random_batch(24, heads, actions, &mut rng);
    batch.demos = (0..batch.size)
        .map(|i| if i % 3 == 0 { 1.0 } else { 0.0 })
        .collect();
    batch.horizons = horizons;
    let mut scratch = TrainScratch::default();
    let loss = loss_and_grads_with(&online, &target, &batch, &cfg, &mut scratch);
    let grads: Vec<f32> = scratch.grads().expect("gradients").tensors().concat();
    let p: Vec<f64> = online.params_flat().iter().map(|&x| x.into()).collect();
    let t: Vec<f64> = target.params_flat().iter().map(|&x| x.into()).collect();
    let dims = (hidden, heads, actions);
    let reference = loss64(&p, &p, &t, dims, &batch, &cfg);
    assert!(
        (f64::from(loss) - reference).abs() <= 1e-5 * reference.abs().max(1.0),
        "{cfg:?}: loss {loss} vs f64 {reference}"
    );
    let eps = 1e-5;
    let mut largest = 0.0f64;
    for j in 0..p.len() {
        let (mut plus, mut minus) = (p.clone(), p.clone());
        plus[j] += eps;
        minus[j] -= eps;
        let fd = (loss64(&plus, &p, &t, dims, &batch, &cfg)
            - loss64(&minus, &p, &t, dims, &batch, &cfg))
            / (2.0 * eps);
        let g = f64::from(grads[j]);
        assert!(
            (g - fd).abs() <= 1e-3 * fd.abs() + 1e-5,
            "{cfg:?}: parameter {j}: analytic {g} vs finite difference {fd}"
        );
        largest = largest.max(fd.abs());
    }
    assert!(largest > 1e-3, "{cfg:?}: no gradient worth checking");
}

#[test]
fn each_loss_option_matches_an_f64_recomputation_and_finite_differences() {
    let base = TdConfig::dqn(0.9);
    check_against_f64(TdConfig {
        loss: TdLoss::Mse,
        ..base
    });
    check_against_f64(TdConfig {
        double: true,
        ..base
    });
    check_against_f64(TdConfig {
        target_bounds: Some((-0.2, 0.3)),
        loss: TdLoss::Mse,
        ..base
    });
    check_against_f64(TdConfig {
        huber_delta: 0.3,
        double: true,
        ..base
    });
    check_against_f64(TdConfig {
        margin_weight: 0.5,
        margin: 0.8,
        ..base
    });
    check_against_f64(TdConfig {
        loss: TdLoss::Mse,
        double: true,
        margin_weight: 1.0,
        margin: 0.3,
        ..base
    });
}

#[test]
fn n_step_targets_bootstrap_with_gamma_to_the_horizon() {
    // Horizons 1 to 5 across the batch, with and without Double DQN and the margin loss.
    let horizons: Vec<u8> = (0..24).map(|i| (i % 5 + 1) as u8).collect();
    check_against_f64_with(TdConfig::dqn(0.9), horizons.clone());
    check_against_f64_with(
        TdConfig {
            loss: TdLoss::Mse,
            double: true,
            margin_weight: 1.0,
            margin: 0.8,
            ..TdConfig::dqn(0.9)
        },
        horizons,
    );
    // By hand: one head, one action, Q = 0 online and 10 in the target; reward 1 over 3 steps
    // with gamma 0.5: y = 1 + 0.125 * 10 = 2.25, huber(0 - 2.25) = 1.75; one step: y = 6,
    // huber = 5.5.
    let mut params = Params::zeros(OBS, 4, 1);
    params.bh.as_mut_slice().copy_from_slice(&[10.0]);
    let target = Mlp::from_params(params, 1, 1).unwrap();
    let online = Mlp::from_params(Params::zeros(OBS, 4, 1), 1, 1).unwrap();
    let batch = |h: Vec<u8>| Batch {
        size: 1,
        obs_dim: OBS,
        heads: 1,
        states: vec![0.0; OBS],
        actions: vec![0],
        rewards: vec![1.0],
        next_states: vec![0.0; OBS],
        terminated: vec![0.0],
        masks: vec![1.0],
        demos: vec![],
        horizons: h,
    };
    let mut scratch = TrainScratch::default();
    let cfg = TdConfig::dqn(0.5);
    assert_eq!(
        loss_and_grads_with(&online, &target, &batch(vec![3]), &cfg, &mut scratch),
        1.75
    );
    assert_eq!(
        loss_and_grads_with(&online, &target, &batch(vec![1]), &cfg, &mut scratch),
        5.5
    );
    assert_eq!(
        loss_and_grads_with(&online, &target, &batch(vec![]), &cfg, &mut scratch),
        5.5
    );
    // Targets clamped to [0, 4]: the one-step y = 6 becomes 4, huber(0 - 4) = 3.5; the 3-step
    // y = 2.25 is inside and stays.
    let bounded = TdConfig {
        target_bounds: Some((0.0, 4.0)),
        ..cfg
    };
    assert_eq!(
        loss_and_grads_with(&online, &target, &batch(vec![1]), &bounded, &mut scratch),
        3.5
    );
    assert_eq!(
        loss_and_grads_with(&online, &target, &batch(vec![3]), &bounded, &mut scratch),
        1.75
    );
}

#[test]
fn the_margin_loss_is_zero_when_the_demonstrated_action_wins_by_the_margin() {
    // One head, two actions, hand-set output bias: Q(s, ·) = (2.0, 0.5) for every state.
    let mut params = Params::zeros(OBS, 4, 2);
    params.bh.as_mut_slice().copy_from_slice(&[2.0, 0.5]);
    let net = Mlp::from_params(params, 1, 2).unwrap();
    let batch = |action: u32| Batch {
        size: 1,
        obs_dim: OBS,
        heads: 1,
        states: vec![0.0; OBS],
        actions: vec![action],
        rewards: vec![0.0],
        next_states: vec![0.0; OBS],
        terminated: vec![1.0],
        masks: vec![1.0],
        demos: vec![1.0],
        horizons: vec![],
    };
    let cfg = TdConfig {
        margin_weight: 1.0,
        margin: 0.8,
        ..TdConfig::dqn(0.9)
    };
    let td_only = TdConfig::dqn(0.9);
    let mut s = TrainScratch::default();
    // a_E = 0: 2.0 beats 0.5 + 0.8 = 1.3, no margin loss; TD loss huber(2.0 - 0) = 1.5.
    let l = loss_and_grads_with(&net, &net, &batch(0), &cfg, &mut s);
    assert_eq!(l, 1.5);
    // a_E = 1: max(2.0 + 0.8, 0.5) - 0.5 = 2.3 on top of huber(0.5) = 0.125.
    let with = loss_and_grads_with(&net, &net, &batch(1), &cfg, &mut s);
    let without = loss_and_grads_with(&net, &net, &batch(1), &td_only, &mut s);
    assert_eq!(without, 0.125);
    assert!((with - (0.125 + 2.3)).abs() < 1e-6, "{with}");
}

#[test]
fn gradient_clipping_scales_to_the_max_norm() {
    let mut g = Params::zeros(1, 1, 1);
    g.w0.as_mut_slice()[0] = 3.0;
    g.b0.as_mut_slice()[0] = 4.0;
    let norm = clip_grad_norm(&mut g, 1.0);
    assert_eq!(norm, 5.0);
    assert!((g.w0[0] - 3.0 / (5.0 + 1e-6)).abs() < 1e-7);
    assert!((g.b0[0] - 4.0 / (5.0 + 1e-6)).abs() < 1e-7);
    // Below the maximum nothing changes.
    let before = g.clone();
    clip_grad_norm(&mut g, 10.0);
    assert_eq!(g, before);
}

#[test]
fn polyak_moves_the_target_a_fraction_tau_of_the_way() {
    let mut rng = seeded(1);
    let online = Mlp::new(OBS, 4, 1, 2, &mut rng);
    let mut target = Mlp::new(OBS, 4, 1, 2, &mut rng);
    let before = target.params_flat();
    target.polyak_from(&online, 0.25).unwrap();
    for ((t, o), b) in target
        .params_flat()
        .iter()
        .zip(online.params_flat())
        .zip(before)
    {
        assert!((t - (0.25 * o + 0.75 * b)).abs() < 1e-6);
    }
    target.polyak_from(&online, 1.0).unwrap();
    assert_eq!(target.params_flat(), online.params_flat());
}

fn learner(extra: &str) -> NeuralLearner {
    let text = format!(
        "seed = 0\nepisodes = 1\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\nbatch_size = 4\nreplay_capacity = 16\n{extra}"
    );
    let cfg = ExperimentConfig::from_toml(&text).unwrap();
    NeuralLearner::new(&cfg.agent, OBS, 2, seeded(3))
}

fn step(x: f32, demo: bool) -> Transition {
    Transition {
        state: vec![x; OBS],
        action: u32::from(demo),
        reward: 1.0,
        next_state: vec![x + 0.1; OBS],
        terminated: false,
        mask: vec![1.0, 1.0],
        demo,
        horizon: 1,
    }
}

#[test]
fn learning_starts_after_the_configured_number_of_steps() {
    let mut plain = learner("");
    let mut late = learner("learning_starts = 10");
    for i in 0..12 {
        let (a, b) = (
            plain.learn(&step(i as f32, false)),
            late.learn(&step(i as f32, false)),
        );
        assert_eq!(
            a.is_some(),
            i >= 3,
            "a full batch of 4 is enough at step {i}"
        );
        assert_eq!(
            b.is_some(),
            i >= 9,
            "the 10th stored step starts learning, not step {i}"
        );
    }
}

#[test]
fn config_refuses_options_out_of_range_naming_the_field() {
    let bad = |extra: &str, field: &str| {
        let text = format!(
            "seed = 0\nepisodes = 1\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n{extra}"
        );
        let e = ExperimentConfig::from_toml(&text).unwrap_err().to_string();
        assert!(e.contains(field), "{extra}: {e}");
    };
    bad("tau = 0.0", "agent.tau");
    bad("tau = 1.5", "agent.tau");
    bad("max_grad_norm = -1.0", "agent.max_grad_norm");
    bad("demo_fraction = 1.5", "agent.demo_fraction");
    bad("margin_loss_weight = -0.1", "agent.margin_loss_weight");
    bad(
        "replay_capacity = 8\nbatch_size = 32",
        "agent.replay_capacity",
    );
    bad("updates_per_step = 0", "agent.updates_per_step");
    bad("epsilon_decay_steps = inf", "agent.epsilon_decay_steps");
    bad("loss = \"l1\"", "loss");
    bad("learning_rate_end = -0.1", "agent.learning_rate_end");
    bad("learning_rate_end = nan", "agent.learning_rate_end");
    bad("n_step = 0", "agent.n_step");
    bad("n_step = 101", "agent.n_step");
}

#[test]
fn the_learning_rate_anneals_linearly_over_stored_transitions() {
    let text = "seed = 0\nepisodes = 1\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n\
                learning_rate = 0.001\nlearning_rate_end = 0.0001\nlearning_rate_anneal_steps = 10\n";
    let s = ExperimentConfig::from_toml(text)
        .unwrap()
        .agent
        .learning_rate_schedule()
        .unwrap();
    // By hand: 1e-3 + (1e-4 - 1e-3) * n / 10, then 1e-4.
    for (n, lr) in [
        (0, 1e-3),
        (5, 5.5e-4),
        (9, 1.9e-4),
        (10, 1e-4),
        (10_000, 1e-4),
    ] {
        assert!((s.at(n) - lr).abs() < 1e-15, "at {n}: {} vs {lr}", s.at(n));
    }
    let e = ExperimentConfig::from_toml(&text.replace("learning_rate_end = 0.0001\n", ""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("agent.learning_rate_anneal_steps"), "{e}");
}

#[test]
fn an_annealed_learner_moves_until_its_rate_reaches_zero_then_holds() {
    // Batch 4: updates from the 4th stored transition; the rate is 1e-3 * (1 - n/6), 0 from n = 6.
    let mut annealed = learner("learning_rate_end = 0.0\nlearning_rate_anneal_steps = 6");
    let mut constant = learner("");
    let mut moved = Vec::new();
    for i in 0..10 {
        let before = annealed.network().params_flat();
        annealed.learn(&step(i as f32, false));
        constant.learn(&step(i as f32, false));
        moved.push(annealed.network().params_flat() != before);
    }
    // Inserted n = i + 1 before the update: rate > 0 for n = 4, 5; 0 for n >= 6.
    assert_eq!(
        moved,
        [false, false, false, true, true, false, false, false, false, false]
    );
    assert_ne!(
        annealed.network().params_flat(),
        constant.network().params_flat()
    );
    // A schedule that starts and ends at the same rate is the constant learner, to the bit.
    let mut flat = learner("learning_rate_end = 0.001\nlearning_rate_anneal_steps = 6");
    let mut plain = learner("");
    for i in 0..10 {
        flat.learn(&step(i as f32, true));
        plain.learn(&step(i as f32, true));
    }
    assert_eq!(flat.network().params_flat(), plain.network().params_flat());
}
