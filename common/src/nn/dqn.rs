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

use nalgebra::DMatrix;

use super::{Adam, ForwardCache, Mlp, Params};
use crate::replay::Batch;

/// Buffers of the train step, reused from step to step so that the loop does not allocate.
#[derive(Debug, Clone, Default)]
pub struct TrainScratch {
    online: ForwardCache,
    target: ForwardCache,
    /// dL/dQ of the online network, `(batch, K*A)`.
    dq: DMatrix<f32>,
    grads: Option<Params>,
}

impl TrainScratch {
    /// The gradients of the last [`loss_and_grads`] (or [`train_step`]), if any.
    pub fn grads(&self) -> Option<&Params> {
        self.grads.as_ref()
    }

    /// The online network's Q-values on the states of the last batch, `(batch, K*A)`.
    pub fn online_q(&self) -> &DMatrix<f32> {
        self.online.q()
    }
}

/// SmoothL1 with `beta = 1`.
#[inline]
pub fn huber(td: f32) -> f32 {
    if td.abs() < 1.0 {
        0.5 * td * td
    } else {
        td.abs() - 0.5
    }
}

/// The derivative of [`huber`]: `td` clipped to `[-1, 1]`.
#[inline]
fn huber_grad(td: f32) -> f32 {
    td.clamp(-1.0, 1.0)
}

/// The loss of the module docs, without gradients.
pub fn dqn_loss(
    online: &Mlp,
    target: &Mlp,
    batch: &Batch,
    gamma: f32,
    scratch: &mut TrainScratch,
) -> f32 {
    td_loss(online, target, batch, gamma, scratch, false)
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
    let loss = td_loss(online, target, batch, gamma, scratch, true);
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
    let loss = loss_and_grads(online, target, batch, gamma, scratch);
    if let Some(grads) = scratch.grads.as_ref() {
        adam.step(online, grads);
    }
    loss
}

fn check_batch(online: &Mlp, target: &Mlp, batch: &Batch) {
    assert_eq!(
        online.params().shapes(),
        target.params().shapes(),
        "online and target networks differ in shape"
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
    gamma: f32,
    scratch: &mut TrainScratch,
    with_grad: bool,
) -> f32 {
    check_batch(online, target, batch);
    online.forward_batch(&batch.states, &mut scratch.online);
    target.forward_batch(&batch.next_states, &mut scratch.target);
    let (n, heads, actions) = (batch.size, online.heads(), online.actions());
    if with_grad {
        if scratch.dq.shape() != (n, heads * actions) {
            scratch.dq = DMatrix::zeros(n, heads * actions);
        } else {
            scratch.dq.as_mut_slice().fill(0.0);
        }
    }
    let q = scratch.online.q();
    let q_next = scratch.target.q();
    let inv_n = 1.0 / n as f32;
    let mut loss = 0.0f64;
    for i in 0..n {
        let a = batch.actions[i] as usize;
        let bootstrap = gamma * (1.0 - batch.terminated[i]);
        for k in 0..heads {
            let mask = batch.masks[i * heads + k];
            if mask == 0.0 {
                continue;
            }
            let mut max_next = f32::NEG_INFINITY;
            for b in 0..actions {
                max_next = max_next.max(q_next[(i, k * actions + b)]);
            }
            let y = batch.rewards[i] + bootstrap * max_next;
            let td = q[(i, k * actions + a)] - y;
            loss += f64::from(mask * huber(td));
            if with_grad {
                scratch.dq[(i, k * actions + a)] = mask * huber_grad(td) * inv_n;
            }
        }
    }
    (loss / n as f64) as f32
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
        assert_eq!(huber_grad(0.25), 0.25);
        assert_eq!(huber_grad(-7.0), -1.0);
    }
}
