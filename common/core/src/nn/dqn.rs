//! The DQN and Bootstrapped DQN loss (paper section 3.2) and the train step: one Adam update of
//! the online network on a replay batch, with the target network's bootstrap.
//!
//! For head `k` and transition `i` of a batch of size `B`:
//!
//! ```text
//! y_ik  = r_i + gamma * (1 - terminated_i) * max_a Q_target_k(s'_i, a)
//! td_ik = Q_k(s_i, a_i) - y_ik
//! loss  = sum_k sum_i mask[i, k] * huber(td_ik) / B
//! ```
//!
//! `huber` is PyTorch's `SmoothL1Loss` with `beta = 1` (`td^2 / 2` inside `[-1, 1]`,
//! `|td| - 1/2` outside), the loss of PyTorch's DQN tutorial and of the Nature DQN's clipped error.
//! With one head and all-ones masks this is plain DQN with `SmoothL1Loss(reduction = "mean")`.
//! Gradients flow only through `Q_k(s_i, a_i)` of the online network: the target is a constant.
//! Each head bootstraps from its own target head.
//!
//! [`TdConfig`] adds, each off by default ([`TdConfig::dqn`] is the loss above):
//! - `loss = Mse`: `td^2` instead of `huber(td)` (CleanRL's `F.mse_loss`);
//! - `huber_delta = δ`: PyTorch's `HuberLoss(delta = δ)`, `td^2 / 2` inside `[-δ, δ]`,
//!   `δ (|td| - δ/2)` outside, instead of `beta = 1` (δ = 1 is the loss above, to the bit): a TD
//!   error larger than δ pulls with a force of only δ, so with returns in the hundreds
//!   (CartPole-1000 at γ = 0.995) a δ of 1 lets rare large errors, those of terminal transitions,
//!   lose against the many small ones (EXPERIMENTS.md, the CartPole Q-value divergence);
//! - `double`: Double DQN targets, `y = r + gamma * Q_target_k(s', argmax_a Q_k(s', a))`
//!   (van Hasselt et al. 2016), the action chosen by the online head;
//! - `margin_weight > 0`: DQfD's large-margin loss on demonstrated transitions (Hester et al.
//!   2018; the paper's ref. \[5\] adds it to the TD loss),
//!   `lambda_E * (max_a [Q_k(s, a) + l(a_E, a)] - Q_k(s, a_E)) / B` with `l = margin` for
//!   `a != a_E`, 0 otherwise;
//! - `target_bounds = (lo, hi)`: each target `y` clamped to `[lo, hi]`, the range every true value
//!   lies in (with rewards in `[r_min, r_max]`, `[r_min, r_max] / (1 - gamma)`), so that a
//!   diverging bootstrap cannot carry the targets past what any return could be;
//! - `max_grad_norm`: the gradient scaled to at most this global L2 norm (PyTorch's
//!   `clip_grad_norm_`) before Adam's step.
//!
//! A batch of n-step transitions (`Batch::horizons`, made by the n-step window) bootstraps transition
//! `i` with `gamma^h_i` instead of `gamma`; its reward is already the discounted sum of the `h_i`
//! rewards.

use nalgebra::DMatrix;

use super::{Adam, ForwardCache, Mlp, Params};
use crate::replay::Batch;

/// The regression loss on TD errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TdLoss {
    /// SmoothL1 with `beta = 1`.
    Huber,
    /// Squared error.
    Mse,
}

/// How the loss is made (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TdConfig {
    pub gamma: f32,
    pub loss: TdLoss,
    /// δ of the Huber loss (1: SmoothL1 with `beta = 1`); unused by `Mse`.
    pub huber_delta: f32,
    pub double: bool,
    /// `lambda_E` of the large-margin loss (0: off).
    pub margin_weight: f32,
    /// `l(a_E, a)` for `a != a_E`.
    pub margin: f32,
    pub max_grad_norm: Option<f32>,
    /// `[lo, hi]` every TD target is clamped to (`None`: unclamped).
    pub target_bounds: Option<(f32, f32)>,
}

impl TdConfig {
    /// The loss of the paper (and of the module docs' first formula).
    pub fn dqn(gamma: f32) -> Self {
        Self {
            gamma,
            loss: TdLoss::Huber,
            huber_delta: 1.0,
            double: false,
            margin_weight: 0.0,
            margin: 0.8,
            max_grad_norm: None,
            target_bounds: None,
        }
    }
}

/// Buffers of the train step, reused from step to step so that the loop does not allocate.
#[derive(Debug, Clone, Default)]
pub struct TrainScratch {
    online: ForwardCache,
    target: ForwardCache,
    /// The online network on the next states (Double DQN).
    online_next: ForwardCache,
    /// dL/dQ of the online network, `(batch, K*A)`.
    dq: DMatrix<f32>,
    grads: Option<Params>,
}

impl TrainScratch {
    /// The gradients of the last [`loss_and_grads`] (or [`train_step`]), if any.
    pub fn grads(&self) -> Option<&Params> {
        self.grads.as_ref()
    }

    /// The mean of the online network's Q-values over the last batch (every head and action);
    /// NaN before the first.
    pub fn q_mean(&self) -> f32 {
        let q = self.online.q();
        if q.is_empty() {
            f32::NAN
        } else {
            q.mean()
        }
    }
}

/// SmoothL1 with `beta = 1` (the Huber loss with δ = 1).
#[inline]
pub fn huber(td: f32) -> f32 {
    huber_with(td, 1.0)
}

/// PyTorch's `HuberLoss(delta)`: `td^2 / 2` for `|td| < delta`, `delta * (|td| - delta / 2)`
/// beyond.
#[inline]
pub fn huber_with(td: f32, delta: f32) -> f32 {
    if td.abs() < delta {
        0.5 * td * td
    } else {
        delta * (td.abs() - 0.5 * delta)
    }
}

/// The derivative of [`huber_with`]: `td` clipped to `[-delta, delta]`.
#[inline]
fn huber_grad(td: f32, delta: f32) -> f32 {
    td.clamp(-delta, delta)
}

/// The loss of the module docs, without gradients.
pub fn dqn_loss(
    online: &Mlp,
    target: &Mlp,
    batch: &Batch,
    gamma: f32,
    scratch: &mut TrainScratch,
) -> f32 {
    td_loss(online, target, batch, &TdConfig::dqn(gamma), scratch, false)
}

/// The loss of the module docs, with its gradient with respect to the online network's
/// parameters left in [`TrainScratch::grads`].
pub fn loss_and_grads(
    online: &Mlp,
    target: &Mlp,
    batch: &Batch,
    gamma: f32,
    scratch: &mut TrainScratch,
) -> f32 {
    loss_and_grads_with(online, target, batch, &TdConfig::dqn(gamma), scratch)
}

/// [`loss_and_grads`] with the options of `cfg` (gradient clipping is the train step's).
pub fn loss_and_grads_with(
    online: &Mlp,
    target: &Mlp,
    batch: &Batch,
    cfg: &TdConfig,
    scratch: &mut TrainScratch,
) -> f32 {
    let loss = td_loss(online, target, batch, cfg, scratch, true);
    let grads = scratch
        .grads
        .get_or_insert_with(|| online.params().zeros_like());
    online.backward(&mut scratch.online, &scratch.dq, grads);
    loss
}

/// One update of `online` with Adam on `batch`; returns the loss before the update.
///
/// Panics if the batch does not fit the networks (state dimension, number of heads, an action
/// out of range) or the two networks differ in shape: batches come from the replay buffer, so
/// that is a bug, not bad input.
pub fn train_step(
    online: &mut Mlp,
    target: &Mlp,
    adam: &mut Adam,
    batch: &Batch,
    gamma: f32,
    scratch: &mut TrainScratch,
) -> f32 {
    train_step_with(online, target, adam, batch, &TdConfig::dqn(gamma), scratch)
}

/// [`train_step`] with the options of `cfg`.
pub fn train_step_with(
    online: &mut Mlp,
    target: &Mlp,
    adam: &mut Adam,
    batch: &Batch,
    cfg: &TdConfig,
    scratch: &mut TrainScratch,
) -> f32 {
    let loss = loss_and_grads_with(online, target, batch, cfg, scratch);
    if let Some(grads) = scratch.grads.as_mut() {
        if let Some(max) = cfg.max_grad_norm {
            clip_grad_norm(grads, max);
        }
        adam.step(online, grads);
    }
    loss
}

/// Scales `grads` so that their global L2 norm is at most `max` (PyTorch's `clip_grad_norm_`:
/// factor `max / (norm + 1e-6)` when below 1); returns the norm before clipping.
pub fn clip_grad_norm(grads: &mut Params, max: f32) -> f32 {
    let norm = grads
        .tensors()
        .iter()
        .flat_map(|t| t.iter())
        .map(|&g| f64::from(g) * f64::from(g))
        .sum::<f64>()
        .sqrt() as f32;
    let coef = max / (norm + 1e-6);
    if coef < 1.0 {
        for t in grads.tensors_mut() {
            t.iter_mut().for_each(|g| *g *= coef);
        }
    }
    norm
}

fn check_batch(online: &Mlp, target: &Mlp, batch: &Batch) {
    assert!(
        online.params().dims() == target.params().dims(),
        "online and target networks differ in shape: {:?} and {:?}",
        online.params().shapes(),
        target.params().shapes()
    );
    assert_eq!(
        online.heads(),
        target.heads(),
        "online and target heads differ"
    );
    let (n, d, k) = (batch.size, online.obs_dim(), online.heads());
    assert_eq!(
        batch.heads, k,
        "batch masks are for another number of heads"
    );
    assert_eq!(
        batch.states.len(),
        n * d,
        "batch states have the wrong length"
    );
    assert_eq!(
        batch.next_states.len(),
        n * d,
        "batch next states have the wrong length"
    );
    assert_eq!(
        batch.actions.len(),
        n,
        "batch actions have the wrong length"
    );
    assert_eq!(
        batch.rewards.len(),
        n,
        "batch rewards have the wrong length"
    );
    assert_eq!(
        batch.terminated.len(),
        n,
        "batch terminal flags have the wrong length"
    );
    assert_eq!(
        batch.masks.len(),
        n * k,
        "batch masks have the wrong length"
    );
    assert!(n > 0, "empty batch");
    assert!(
        batch
            .actions
            .iter()
            .all(|&a| (a as usize) < online.actions()),
        "batch action out of range"
    );
}

fn td_loss(
    online: &Mlp,
    target: &Mlp,
    batch: &Batch,
    cfg: &TdConfig,
    scratch: &mut TrainScratch,
    with_grad: bool,
) -> f32 {
    check_batch(online, target, batch);
    online.forward_batch(&batch.states, &mut scratch.online);
    target.forward_batch(&batch.next_states, &mut scratch.target);
    if cfg.double {
        online.forward_batch(&batch.next_states, &mut scratch.online_next);
    }
    let (n, heads, actions) = (batch.size, online.heads(), online.actions());
    if with_grad {
        if scratch.dq.shape() != (n, heads * actions) {
            scratch.dq = DMatrix::zeros(n, heads * actions);
        } else {
            scratch.dq.as_mut_slice().fill(0.0);
        }
    }
    // Column-major `(n, K·A)`: sample i's value of output column c at `i + c n`.
    let q = scratch.online.q().as_slice();
    let q_next = scratch.target.q().as_slice();
    let q_online_next = cfg.double.then(|| scratch.online_next.q().as_slice());
    let dq: &mut [f32] = if with_grad {
        scratch.dq.as_mut_slice()
    } else {
        &mut []
    };
    let margin_on = cfg.margin_weight > 0.0 && batch.demos.len() == n;
    let inv_n = 1.0 / n as f32;
    let mut loss = 0.0f64;
    for i in 0..n {
        let a = batch.actions[i] as usize;
        let bootstrap = match batch.horizons.get(i) {
            Some(&h) if h > 1 => gamma_bootstrap(gamma_power(cfg.gamma, h), batch.terminated[i]),
            _ => gamma_bootstrap(cfg.gamma, batch.terminated[i]),
        };
        let demo = margin_on && batch.demos[i] != 0.0;
        let masks = &batch.masks[i * heads..(i + 1) * heads];
        for (k, &mask) in masks.iter().enumerate() {
            if mask == 0.0 {
                continue;
            }
            // Sample i's entries of head k's columns.
            let at = |b: usize| i + (k * actions + b) * n;
            let next = next_value(q_next, q_online_next, actions, at);
            let y = batch.rewards[i] + bootstrap * next;
            let y = match cfg.target_bounds {
                Some((lo, hi)) => y.clamp(lo, hi),
                None => y,
            };
            let (l, g) = loss_and_grad(q[at(a)] - y, cfg);
            loss += f64::from(mask * l);
            if with_grad {
                dq[at(a)] += mask * g * inv_n;
            }
            if demo {
                let (best, j) = large_margin(q, a, actions, cfg.margin, at);
                loss += f64::from(mask * cfg.margin_weight * j);
                if with_grad && best != a {
                    let w = mask * cfg.margin_weight * inv_n;
                    dq[at(best)] += w;
                    dq[at(a)] -= w;
                }
            }
        }
    }
    (loss / n as f64) as f32
}

/// The value of the next state for one sample and head (`at(b)`: the entry of action `b`): the
/// target head's best, or with double DQN (`q_online_next`) the target head's value of the
/// online head's pick.
#[inline(always)]
fn next_value(
    q_next: &[f32],
    q_online_next: Option<&[f32]>,
    actions: usize,
    at: impl Fn(usize) -> usize,
) -> f32 {
    match q_online_next {
        Some(qo) => {
            let best = (0..actions).fold(0, |m, b| if qo[at(b)] > qo[at(m)] { b } else { m });
            q_next[at(best)]
        }
        None => (0..actions).fold(f32::NEG_INFINITY, |m, b| m.max(q_next[at(b)])),
    }
}

/// The loss of a TD error and its derivative.
#[inline(always)]
fn loss_and_grad(td: f32, cfg: &TdConfig) -> (f32, f32) {
    match cfg.loss {
        TdLoss::Huber => (
            huber_with(td, cfg.huber_delta),
            huber_grad(td, cfg.huber_delta),
        ),
        TdLoss::Mse => (td * td, 2.0 * td),
    }
}

/// The large-margin term of a demonstrated action `a` (the demonstrated action must beat every
/// other by `margin`): the action that wins with the margin added, and by how much it beats `a`.
#[inline(always)]
fn large_margin(
    q: &[f32],
    a: usize,
    actions: usize,
    margin: f32,
    at: impl Fn(usize) -> usize,
) -> (usize, f32) {
    let (best, value) = (0..actions)
        .map(|b| (b, q[at(b)] + if b == a { 0.0 } else { margin }))
        .fold((a, f32::NEG_INFINITY), |m, c| if c.1 > m.1 { c } else { m });
    (best, value - q[at(a)])
}

/// `gamma^h` for an h-step transition, multiplied out in f64 (no libm: the same bits on every
/// machine).
fn gamma_power(gamma: f32, h: u8) -> f32 {
    let g = f64::from(gamma);
    (0..h).fold(1.0f64, |p, _| p * g) as f32
}

/// `gamma * (1 - terminated)`.
#[inline]
fn gamma_bootstrap(gamma: f32, terminated: f32) -> f32 {
    gamma * (1.0 - terminated)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huber_is_smooth_l1_with_beta_one() {
        assert_eq!(huber(0.5), 0.125);
        assert_eq!(huber(-0.5), 0.125);
        assert_eq!(huber(3.0), 2.5);
        assert_eq!(huber(-3.0), 2.5);
        assert_eq!(huber(1.0), 0.5);
        assert_eq!(huber_grad(0.25, 1.0), 0.25);
        assert_eq!(huber_grad(-7.0, 1.0), -1.0);
    }

    #[test]
    fn huber_with_delta_is_torch_huber_loss() {
        // torch.nn.HuberLoss(delta=10): 0.5 * 4^2 = 8 inside, 10 * (30 - 5) = 250 outside.
        assert_eq!(huber_with(4.0, 10.0), 8.0);
        assert_eq!(huber_with(-30.0, 10.0), 250.0);
        assert_eq!(huber_with(10.0, 10.0), 50.0);
        assert_eq!(huber_grad(-30.0, 10.0), -10.0);
        assert_eq!(huber_grad(4.0, 10.0), 4.0);
        // δ = 1 is SmoothL1 with beta = 1, to the bit.
        for td in [-3.7f32, -1.0, -0.3, 0.0, 0.99, 1.0, 2.5, 1e4] {
            assert_eq!(huber_with(td, 1.0).to_bits(), huber(td).to_bits());
        }
    }

    #[test]
    fn an_n_step_target_bootstraps_with_gamma_to_the_n() {
        assert_eq!(gamma_power(0.5, 1), 0.5);
        assert_eq!(gamma_power(0.5, 3), 0.125);
        let g = f64::from(0.99f32);
        assert_eq!(gamma_power(0.99, 5), (g * g * g * g * g) as f32);
        assert_ne!(gamma_power(0.99, 5), 0.99);
    }
}
