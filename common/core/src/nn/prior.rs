//! Randomized prior functions (Osband, Aslanides and Cassirer, "Randomized Prior Functions for
//! Deep Reinforcement Learning", NeurIPS 2018): each head's Q-function is its trained output plus
//! `scale` times the output of a fixed network that is never trained,
//! `Q_k(s, a) = f_k(s, a; θ) + β p_k(s, a)`.
//!
//! The prior network has the trained network's shape, PyTorch's default initialisation, and is
//! drawn from its own seed, so every process of a run (actors, learner, expert) builds the same
//! one from the config alone: it is never sent over the wire nor stored as tensors. Its heads
//! differ through their own output columns on one shared random torso, as the trained heads do,
//! or each has its own torso when the network's heads do.
//!
//! A prior adds a term that does not depend on θ: the gradients of the trained weights are those
//! of the plain network at the same activations, and the TD targets (computed with the target
//! network, which carries the same prior) see the prior too.

use super::Mlp;

/// Output widths `K * A` up to this keep the prior's act-step output on the stack.
const STACK_OUTPUTS: usize = 64;

/// The fixed random network and its scale β.
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    scale: f32,
    seed: u64,
    net: Mlp,
}

impl Prior {
    /// The prior of a network of dimensions `(obs_dim, hidden, heads, actions)` (`hidden` per
    /// torso), drawn from `seed`; with `separate` torsos as the network's are.
    pub fn new(
        (obs_dim, hidden, heads, actions): (usize, usize, usize, usize),
        separate: bool,
        scale: f32,
        seed: u64,
    ) -> Self {
        let mut rng = crate::rng::seeded(crate::rng::derive_seed(seed, "prior"));
        let net = if separate {
            Mlp::separate(obs_dim, hidden, heads, actions, &mut rng)
        } else {
            Mlp::new(obs_dim, hidden, heads, actions, &mut rng)
        };
        Self { scale, seed, net }
    }

    /// β.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// The seed the prior network was drawn from.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The untrained network p.
    pub fn network(&self) -> &Mlp {
        &self.net
    }

    /// `out += β p(x)` for one state.
    /// No allocation for up to [`STACK_OUTPUTS`] outputs.
    pub(super) fn add_one(&self, x: &[f32], out: &mut [f32]) {
        let mut stack = [0.0f32; STACK_OUTPUTS];
        let mut heap = Vec::new();
        let p = if out.len() <= STACK_OUTPUTS {
            &mut stack[..out.len()]
        } else {
            heap.resize(out.len(), 0.0);
            &mut heap[..]
        };
        self.net.forward_one(x, p);
        for (o, v) in out.iter_mut().zip(p.iter()) {
            *o += self.scale * v;
        }
    }

    /// `q += β p(states)` for a batch, `q` laid out as [`super::ForwardCache::q`]; `cache` is the
    /// prior's own scratch.
    pub(super) fn add_batch(
        &self,
        states: &[f32],
        q: &mut nalgebra::DMatrix<f32>,
        cache: &mut super::ForwardCache,
    ) {
        self.net.forward_batch(states, cache);
        for (o, v) in q.iter_mut().zip(cache.q().iter()) {
            *o += self.scale * v;
        }
    }
}
