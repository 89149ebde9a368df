//! The K-head MLP: PyTorch's default initialisation, the single-state forward of the act step,
//! the batched forward and backward passes of the learner, and the flat parameter vector that
//! carries weights between processes.
//!
//! Batched activations are nalgebra matrices of shape `(batch, features)`, one sample per row;
//! with the weights stored as `(in, out)` (see the module docs of [`crate::nn`]) a layer is
//! `Z = A W^T + b = A * w + b`. The 64x64 products go to [`super::gemm`] (a fixed order of fused
//! multiply-adds, the same on every CPU), the bias and ReLU added as they end; the thin ones
//! (4 inputs, K*A outputs) keep the order of axpys ([`super::gemm::thin`]) or of dot products
//! over contiguous columns ([`super::dots`]).

use nalgebra::{DMatrix, DVector};
use rand::Rng as _;

use super::dots::{self, dot, dot4};
use super::gemm::{gemm, thin, wide, Epi, MatRef};
use super::prior::Prior;
use super::{torch_shapes, NnError, Params, Result};
use crate::rng::Rng;

/// Hidden widths up to this keep the act step's activations on the stack.
const STACK_HIDDEN: usize = 256;

/// The network `obs_dim -> hidden -> hidden -> K*A` with ReLU; output `k * A + a` is `Q_k(s, a)`.
///
/// With separate torsos ([`Mlp::separate`]) the K heads share nothing: the network is K
/// networks `obs_dim -> h -> h -> A` side by side, held as one of width `hidden = K * h` whose
/// `torso.1` and `heads` weights are block-diagonal (hidden units `k*h .. (k+1)*h` are head k's and
/// feed only its outputs). The off-block weights are zero from the start and their gradients are
/// zeroed in every backward pass, so Adam never moves them: the forward pass, the gradients and
/// the updates are those of the K networks apart, at K times the arithmetic of `torso.1`.
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    heads: usize,
    actions: usize,
    /// 1: one torso shared by the heads; K: each head its own (block-diagonal, see above).
    torsos: usize,
    pub(crate) params: Params,
    /// A randomized prior function added to every output (absent: none).
    prior: Option<Box<Prior>>,
}

/// Activations of one batched forward pass, kept for the backward pass, plus the backward pass's
/// temporaries. Reused across calls: it reallocates only when the batch size or the network's
/// dimensions change.
#[derive(Debug, Clone)]
pub struct ForwardCache {
    /// The input, `(batch, obs_dim)`.
    x: DMatrix<f32>,
    /// ReLU outputs of `torso.0` and `torso.1`, `(batch, hidden)`.
    h0: DMatrix<f32>,
    h1: DMatrix<f32>,
    /// The Q-values, `(batch, K*A)`.
    q: DMatrix<f32>,
    /// dL/d(pre-activation) of `torso.1` and `torso.0`, `(batch, hidden)`.
    dz1: DMatrix<f32>,
    dz0: DMatrix<f32>,
    /// Scratch of the wide products (a transposed operand, packed).
    pack: Vec<f32>,
    /// The prior network's own pass (networks with a prior).
    prior: Option<Box<ForwardCache>>,
}

impl Default for ForwardCache {
    fn default() -> Self {
        Self {
            x: DMatrix::zeros(0, 0),
            h0: DMatrix::zeros(0, 0),
            h1: DMatrix::zeros(0, 0),
            q: DMatrix::zeros(0, 0),
            dz1: DMatrix::zeros(0, 0),
            dz0: DMatrix::zeros(0, 0),
            pack: Vec::new(),
            prior: None,
        }
    }
}

impl ForwardCache {
    /// The Q-values of the last forward pass, `(batch, K*A)`: `q[(i, k * A + a)]` is
    /// `Q_k(s_i, a)`.
    pub fn q(&self) -> &DMatrix<f32> {
        &self.q
    }

    /// The batch size of the last forward pass.
    pub fn batch_size(&self) -> usize {
        self.q.nrows()
    }

    fn ensure(&mut self, batch: usize, obs_dim: usize, hidden: usize, outputs: usize) {
        ensure_shape(&mut self.x, batch, obs_dim);
        ensure_shape(&mut self.h0, batch, hidden);
        ensure_shape(&mut self.h1, batch, hidden);
        ensure_shape(&mut self.q, batch, outputs);
        ensure_shape(&mut self.dz1, batch, hidden);
        ensure_shape(&mut self.dz0, batch, hidden);
    }
}

impl Mlp {
    /// A freshly initialised network, as PyTorch's `nn.Linear` does by default: every weight and
    /// bias of a layer with `fan_in` inputs uniform in `[-1/sqrt(fan_in), 1/sqrt(fan_in))`
    /// (`kaiming_uniform_(a = sqrt(5))` for weights). Values are drawn layer by layer, weight
    /// (row-major `[out, in]`) then bias.
    ///
    /// Panics if a dimension is zero (configurations are validated before they get here).
    pub fn new(obs_dim: usize, hidden: usize, heads: usize, actions: usize, rng: &mut Rng) -> Self {
        assert!(
            obs_dim > 0 && hidden > 0 && heads > 0 && actions > 0,
            "network dimensions must be positive: obs_dim {obs_dim}, hidden {hidden}, heads {heads}, actions {actions}"
        );
        let mut params = Params::zeros(obs_dim, hidden, heads * actions);
        init_linear(params.w0.as_mut_slice(), params.b0.as_mut_slice(), rng);
        init_linear(params.w1.as_mut_slice(), params.b1.as_mut_slice(), rng);
        init_linear(params.wh.as_mut_slice(), params.bh.as_mut_slice(), rng);
        Self {
            heads,
            actions,
            torsos: 1,
            params,
            prior: None,
        }
    }

    /// A freshly initialised network whose K heads each have their own torso of `hidden` units
    /// (Osband et al.'s ensemble on DeepSea), held block-diagonally in one network of width
    /// `K * hidden` (see [`Mlp`]). Each layer is drawn as [`Mlp::new`] draws it, with the fan-in of
    /// one torso (`hidden` for `torso.1` and `heads`), and the off-block weights then set to zero.
    ///
    /// Panics if a dimension is zero.
    pub fn separate(
        obs_dim: usize,
        hidden: usize,
        heads: usize,
        actions: usize,
        rng: &mut Rng,
    ) -> Self {
        assert!(
            obs_dim > 0 && hidden > 0 && heads > 0 && actions > 0,
            "network dimensions must be positive: obs_dim {obs_dim}, hidden {hidden}, heads {heads}, actions {actions}"
        );
        let width = hidden * heads;
        let mut params = Params::zeros(obs_dim, width, heads * actions);
        let p = &mut params;
        init_linear_fan(p.w0.as_mut_slice(), p.b0.as_mut_slice(), obs_dim, rng);
        init_linear_fan(p.w1.as_mut_slice(), p.b1.as_mut_slice(), hidden, rng);
        init_linear_fan(p.wh.as_mut_slice(), p.bh.as_mut_slice(), hidden, rng);
        mask_blocks(&mut params, heads, actions);
        Self {
            heads,
            actions,
            torsos: heads,
            params,
            prior: None,
        }
    }

    /// The number of torsos: 1 (shared by the heads) or K (one each, [`Mlp::separate`]).
    pub fn torsos(&self) -> usize {
        self.torsos
    }

    /// The network as K separate torsos (`torsos = K`) or one shared (`torsos = 1`); the weights
    /// off the blocks are set to zero. An error if `torsos` is neither, or does not divide the
    /// hidden width.
    pub fn with_torsos(mut self, torsos: usize) -> Result<Self> {
        if torsos != 1 && (torsos != self.heads || !self.hidden().is_multiple_of(torsos)) {
            return Err(NnError::Dims(format!(
                "{torsos} torsos for {} heads and a hidden width of {}: torsos must be 1 or the \
                 number of heads, dividing the width",
                self.heads,
                self.hidden()
            )));
        }
        self.torsos = torsos;
        mask_blocks(&mut self.params, torsos, self.actions);
        Ok(self)
    }

    /// The network with a randomized prior function of scale `scale` drawn from `seed` (see
    /// [`Prior`]); scale 0 gives the network without one.
    pub fn with_prior(mut self, scale: f32, seed: u64) -> Self {
        self.prior = (scale != 0.0).then(|| {
            let (d, h) = (self.obs_dim(), self.hidden() / self.torsos);
            let separate = self.torsos > 1;
            Box::new(Prior::new(
                (d, h, self.heads, self.actions),
                separate,
                scale,
                seed,
            ))
        });
        self
    }

    /// The randomized prior function, if the network has one.
    pub fn prior(&self) -> Option<&Prior> {
        self.prior.as_deref()
    }

    /// A network from given tensors; checks that their shapes fit together and with
    /// `heads * actions` outputs.
    pub fn from_params(params: Params, heads: usize, actions: usize) -> Result<Self> {
        let (d, h) = (params.w0.nrows(), params.w0.ncols());
        if d == 0 || h == 0 || heads == 0 || actions == 0 {
            return Err(NnError::Dims(format!(
                "obs_dim {d}, hidden {h}, heads {heads}, actions {actions} must all be positive"
            )));
        }
        let outputs = heads.checked_mul(actions).ok_or_else(|| {
            NnError::Dims(format!("heads {heads} times actions {actions} overflows"))
        })?;
        let expected = torch_shapes(d, h, outputs);
        let found = [
            vec![params.w0.ncols(), params.w0.nrows()],
            vec![params.b0.len()],
            vec![params.w1.ncols(), params.w1.nrows()],
            vec![params.b1.len()],
            vec![params.wh.ncols(), params.wh.nrows()],
            vec![params.bh.len()],
        ];
        for ((name, e), f) in super::PARAM_NAMES.iter().zip(&expected).zip(&found) {
            if e != f {
                return Err(NnError::Shape {
                    name: (*name).to_string(),
                    expected: e.clone(),
                    found: f.clone(),
                });
            }
        }
        Ok(Self {
            heads,
            actions,
            torsos: 1,
            params,
            prior: None,
        })
    }

    pub fn obs_dim(&self) -> usize {
        self.params.obs_dim()
    }

    pub fn hidden(&self) -> usize {
        self.params.hidden()
    }

    /// `K`, the number of heads.
    pub fn heads(&self) -> usize {
        self.heads
    }

    /// `A`, the number of actions.
    pub fn actions(&self) -> usize {
        self.actions
    }

    /// `K * A`, the width of the output layer.
    pub fn outputs(&self) -> usize {
        self.heads * self.actions
    }

    /// The six tensors (PyTorch layout).
    pub fn params(&self) -> &Params {
        &self.params
    }

    pub fn into_params(self) -> Params {
        self.params
    }

    /// The number of scalar parameters, the length of [`Mlp::params_flat`].
    pub fn num_params(&self) -> usize {
        self.params.len()
    }

    /// All parameters in one vector: the tensors of [`super::PARAM_NAMES`] in that order, each
    /// flattened row-major in PyTorch's layout (`[out, in]` for weights).
    pub fn params_flat(&self) -> Vec<f32> {
        let mut out = vec![0.0; self.num_params()];
        // The length is right by construction.
        let _ = self.copy_params_into(&mut out);
        out
    }

    /// Writes [`Mlp::params_flat`] into `out` without allocating; `out` must have
    /// [`Mlp::num_params`] values.
    pub fn copy_params_into(&self, out: &mut [f32]) -> Result<()> {
        self.check_flat_len(out.len())?;
        let mut offset = 0;
        for t in self.params.tensors() {
            out[offset..offset + t.len()].copy_from_slice(t);
            offset += t.len();
        }
        Ok(())
    }

    /// Loads parameters written by [`Mlp::params_flat`] of a network of the same dimensions.
    pub fn load_params_flat(&mut self, flat: &[f32]) -> Result<()> {
        self.check_flat_len(flat.len())?;
        let mut offset = 0;
        for t in self.params.tensors_mut() {
            let n = t.len();
            t.copy_from_slice(&flat[offset..offset + n]);
            offset += n;
        }
        Ok(())
    }

    /// Copies the parameters of `other` (same dimensions) without allocating: the target
    /// network's update.
    pub fn copy_params_from(&mut self, other: &Mlp) -> Result<()> {
        if self.params.dims() != other.params.dims()
            || (self.heads, self.torsos) != (other.heads, other.torsos)
        {
            return Err(NnError::Dims(format!(
                "cannot copy a network of shapes {:?} ({} heads) into one of shapes {:?} ({} heads)",
                other.params.shapes(),
                other.heads,
                self.params.shapes(),
                self.heads
            )));
        }
        for (dst, src) in self
            .params
            .tensors_mut()
            .into_iter()
            .zip(other.params.tensors())
        {
            dst.copy_from_slice(src);
        }
        Ok(())
    }

    /// Polyak averaging towards `other` (same dimensions): `p <- tau * p_other + (1 - tau) * p`,
    /// the soft target update; `tau = 1` is [`Mlp::copy_params_from`].
    pub fn polyak_from(&mut self, other: &Mlp, tau: f32) -> Result<()> {
        if tau >= 1.0 {
            return self.copy_params_from(other);
        }
        if self.params.dims() != other.params.dims()
            || (self.heads, self.torsos) != (other.heads, other.torsos)
        {
            return Err(NnError::Dims(
                "cannot average networks of different shapes".to_owned(),
            ));
        }
        for (dst, src) in self
            .params
            .tensors_mut()
            .into_iter()
            .zip(other.params.tensors())
        {
            for (d, &s) in dst.iter_mut().zip(src) {
                *d = tau * s + (1.0 - tau) * *d;
            }
        }
        Ok(())
    }

    fn check_flat_len(&self, found: usize) -> Result<()> {
        let expected = self.num_params();
        if found != expected {
            return Err(NnError::ParamCount { expected, found });
        }
        Ok(())
    }

    /// The Q-values of one state, `out[k * A + a] = Q_k(x, a)`: the act step's path. It does not
    /// allocate for hidden widths up to 256.
    ///
    /// Panics if `x` does not have `obs_dim` values or `out` does not have `K * A`.
    pub fn forward_one(&self, x: &[f32], out: &mut [f32]) {
        assert_eq!(x.len(), self.obs_dim(), "state has the wrong dimension");
        assert_eq!(out.len(), self.outputs(), "output has the wrong length");
        let h = self.hidden();
        if h <= STACK_HIDDEN {
            let mut h0 = [0.0f32; STACK_HIDDEN];
            let mut h1 = [0.0f32; STACK_HIDDEN];
            self.forward_one_with(x, out, &mut h0[..h], &mut h1[..h]);
        } else {
            let mut h0 = vec![0.0f32; h];
            let mut h1 = vec![0.0f32; h];
            self.forward_one_with(x, out, &mut h0, &mut h1);
        }
    }

    fn forward_one_with(&self, x: &[f32], out: &mut [f32], h0: &mut [f32], h1: &mut [f32]) {
        let p = &self.params;
        dense_one(&p.w0, &p.b0, x, h0, true);
        dense_one(&p.w1, &p.b1, h0, h1, true);
        dense_one(&p.wh, &p.bh, h1, out, false);
        if let Some(prior) = &self.prior {
            prior.add_one(x, out);
        }
    }

    /// The batched forward pass: `states` holds `batch * obs_dim` values, one state per row
    /// (the layout of [`crate::replay::Batch`]). The Q-values are in [`ForwardCache::q`], and the
    /// cache is ready for [`Mlp::backward`].
    ///
    /// Panics if `states.len()` is not a multiple of `obs_dim`.
    pub fn forward_batch(&self, states: &[f32], cache: &mut ForwardCache) {
        let d = self.obs_dim();
        assert_eq!(
            states.len() % d,
            0,
            "states must hold batch * obs_dim values"
        );
        let batch = states.len() / d;
        cache.ensure(batch, d, self.hidden(), self.outputs());
        // Column by column: contiguous stores, the loads a row apart.
        for (i, x_col) in cache
            .x
            .as_mut_slice()
            .chunks_exact_mut(batch.max(1))
            .enumerate()
        {
            for (x, row) in x_col.iter_mut().zip(states.chunks_exact(d)) {
                *x = row[i];
            }
        }
        let p = &self.params;
        // AVX2 where there is one: faster, the same numbers (see `gemm::wide`).
        wide(
            #[inline(always)]
            || {
                // Each product ends with its bias (and ReLU) added in registers.
                matmul(
                    &mut cache.h0,
                    &cache.x,
                    view(&p.w0),
                    Epi::Bias(p.b0.as_slice(), true),
                );
                matmul(
                    &mut cache.h1,
                    &cache.h0,
                    view(&p.w1),
                    Epi::Bias(p.b1.as_slice(), true),
                );
                matmul(
                    &mut cache.q,
                    &cache.h1,
                    view(&p.wh),
                    Epi::Bias(p.bh.as_slice(), false),
                );
            },
        );
        if let Some(prior) = &self.prior {
            let scratch = cache.prior.get_or_insert_with(Box::default);
            prior.add_batch(states, &mut cache.q, scratch);
        }
    }

    /// The backward pass of the batch last given to [`Mlp::forward_batch`] with `cache`: from
    /// `dq` = dL/dQ, `(batch, K*A)` laid out as [`ForwardCache::q`], it writes dL/dθ for all six
    /// tensors into `grads` (overwritten, PyTorch layout). No allocation once `grads` has the
    /// network's shapes.
    ///
    /// Panics if `dq` does not have the shape of the cached Q-values.
    pub fn backward(&self, cache: &mut ForwardCache, dq: &DMatrix<f32>, grads: &mut Params) {
        assert_eq!(
            dq.shape(),
            cache.q.shape(),
            "dL/dQ must have the shape of the Q-values"
        );
        if grads.dims() != self.params.dims() {
            *grads = self.params.zeros_like();
        }
        let p = &self.params;
        let c = cache;
        // AVX2 where there is one: faster, the same numbers (see `gemm::wide`).
        wide(
            #[inline(always)]
            || {
                // Output layer: Q = h1 * wh + bh.
                layer_grads((&mut grads.wh, &mut grads.bh), &c.h1, dq, &mut c.pack);
                // ReLU's backward (PyTorch's `threshold_backward`) as the product ends.
                matmul(
                    &mut c.dz1,
                    dq,
                    transposed(&p.wh),
                    Epi::Mask(c.h1.as_slice()),
                );
                // torso.1: h1 = relu(h0 * w1 + b1).
                layer_grads((&mut grads.w1, &mut grads.b1), &c.h0, &c.dz1, &mut c.pack);
                matmul(
                    &mut c.dz0,
                    &c.dz1,
                    transposed(&p.w1),
                    Epi::Mask(c.h0.as_slice()),
                );
                // torso.0: h0 = relu(x * w0 + b0).
                layer_grads((&mut grads.w0, &mut grads.b0), &c.x, &c.dz0, &mut c.pack);
            },
        );
        mask_blocks(grads, self.torsos, self.actions);
    }
}

/// PyTorch's `nn.Linear` default initialisation of one layer; `w` is row-major `[out, in]`, so
/// `fan_in = w.len() / b.len()`.
fn init_linear(w: &mut [f32], b: &mut [f32], rng: &mut Rng) {
    init_linear_fan(w, b, w.len() / b.len(), rng);
}

/// [`init_linear`] with a given fan-in (that of one torso, in a block-diagonal layer).
fn init_linear_fan(w: &mut [f32], b: &mut [f32], fan_in: usize, rng: &mut Rng) {
    let bound = 1.0 / (fan_in as f32).sqrt();
    for v in w.iter_mut().chain(b.iter_mut()) {
        *v = rng.random_range(-bound..bound);
    }
}

/// Zeroes what lies off the blocks of `torsos` torsos in `torso.1` and `heads` (weights or their
/// gradients, `actions` outputs a head); nothing with one torso.
fn mask_blocks(p: &mut Params, torsos: usize, actions: usize) {
    if torsos == 1 {
        return;
    }
    let width = p.hidden();
    let h = width / torsos;
    // Column j of an `(in, out)` matrix holds output j's weights from every input.
    for (j, col) in p.w1.as_mut_slice().chunks_exact_mut(width).enumerate() {
        zero_outside(col, (j / h) * h, h);
    }
    for (j, col) in p.wh.as_mut_slice().chunks_exact_mut(width).enumerate() {
        zero_outside(col, (j / actions) * h, h);
    }
}

/// Sets every value of `col` to zero but those at `start .. start + len`.
fn zero_outside(col: &mut [f32], start: usize, len: usize) {
    col[..start].fill(0.0);
    col[start + len..].fill(0.0);
}

fn ensure_shape(m: &mut DMatrix<f32>, rows: usize, cols: usize) {
    if m.shape() != (rows, cols) {
        *m = DMatrix::zeros(rows, cols);
    }
}

/// `m` as the wide products read it.
fn view(m: &DMatrix<f32>) -> MatRef<'_> {
    MatRef {
        data: m.as_slice(),
        rs: 1,
        cs: m.nrows(),
    }
}

/// The transpose of `m`, without copying.
fn transposed(m: &DMatrix<f32>) -> MatRef<'_> {
    MatRef {
        data: m.as_slice(),
        rs: m.nrows(),
        cs: 1,
    }
}

/// Below this, a dimension is "thin": products whose dimensions all exceed it go to
/// [`super::gemm::gemm`] (the bound at which nalgebra handed them to matrixmultiply, whose results
/// that kernel keeps), the others to [`super::gemm::thin`] (the order of the axpys this module
/// did before).
const THIN: usize = 5;

/// `out = a * b`, ended as `epi` says (plus the bias, ReLU, ReLU's mask), `b` of shape
/// `(a.ncols(), out.ncols())`.
#[inline(always)]
fn matmul(out: &mut DMatrix<f32>, a: &DMatrix<f32>, b: MatRef<'_>, epi: Epi<'_>) {
    let (m, k) = a.shape();
    let n = out.ncols();
    debug_assert_eq!(out.nrows(), m);
    if m > THIN && k > THIN && n > THIN {
        gemm(
            (m, k, n),
            view(a),
            b,
            epi,
            out.as_mut_slice(),
            &mut Vec::new(),
        );
    } else {
        thin((m, k, n), a.as_slice(), b, epi, out.as_mut_slice());
    }
}

/// `out = a^T * b` (overwritten), `a` and `b` with the same number of rows (the batch). Thin
/// products become dot products of contiguous columns ([`dots::tr_dots`]).
#[inline(always)]
fn tr_matmul(out: &mut DMatrix<f32>, a: &DMatrix<f32>, b: &DMatrix<f32>, pack: &mut Vec<f32>) {
    let (m, k) = a.shape();
    let n = b.ncols();
    debug_assert_eq!(b.nrows(), m);
    debug_assert_eq!(out.shape(), (k, n));
    if m > THIN && k > THIN && n > THIN {
        gemm(
            (k, m, n),
            transposed(a),
            view(b),
            Epi::Set,
            out.as_mut_slice(),
            pack,
        );
        return;
    }
    dots::tr_dots((m, k, n), a.as_slice(), b.as_slice(), out.as_mut_slice());
}

/// A layer's weight and bias gradients from its input `a` and the gradient `dz` of its output:
/// `w = a^T dz` ([`tr_matmul`]) and `bias[j] = sum_i dz[(i, j)]`. A thin product reads `dz`
/// once for both ([`dots::tr_dots_and_sums`]).
#[inline(always)]
fn layer_grads(
    (w, bias): (&mut DMatrix<f32>, &mut DVector<f32>),
    a: &DMatrix<f32>,
    dz: &DMatrix<f32>,
    pack: &mut Vec<f32>,
) {
    let (m, k) = a.shape();
    let n = dz.ncols();
    if m > THIN && k > THIN && n > THIN {
        tr_matmul(w, a, dz, pack);
        dots::column_sums(m, dz.as_slice(), bias.as_mut_slice());
    } else {
        debug_assert_eq!((dz.nrows(), w.shape()), (m, (k, n)));
        let sums = bias.as_mut_slice();
        dots::tr_dots_and_sums(
            (m, k, n),
            a.as_slice(),
            dz.as_slice(),
            w.as_mut_slice(),
            sums,
        );
    }
}

/// One dense layer for one input: `out[o] = b[o] + w[:, o] . x`, with ReLU if asked; `w` is
/// `(in, out)` column-major, so each output's weights are contiguous. Four outputs at a time
/// share the loads of `x` and keep independent accumulators.
fn dense_one(w: &DMatrix<f32>, b: &DVector<f32>, x: &[f32], out: &mut [f32], relu: bool) {
    let n_in = w.nrows();
    let finish = |v: f32| if relu { v.max(0.0) } else { v };
    let w = w.as_slice();
    let b = b.as_slice();
    let mut out_blocks = out.chunks_exact_mut(4);
    let mut w_blocks = w.chunks_exact(4 * n_in);
    let mut b_blocks = b.chunks_exact(4);
    for ((o, wb), bb) in (&mut out_blocks).zip(&mut w_blocks).zip(&mut b_blocks) {
        let (w0, rest) = wb.split_at(n_in);
        let (w1, rest) = rest.split_at(n_in);
        let (w2, w3) = rest.split_at(n_in);
        let d = dot4([w0, w1, w2, w3], x);
        for ((o, d), &bias) in o.iter_mut().zip(d).zip(bb) {
            *o = finish(d + bias);
        }
    }
    let w_rest = w_blocks.remainder();
    for ((o, col), &bias) in out_blocks
        .into_remainder()
        .iter_mut()
        .zip(w_rest.chunks_exact(n_in))
        .zip(b_blocks.remainder())
    {
        *o = finish(dot(col, x) + bias);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn net() -> Mlp {
        Mlp::new(4, 16, 2, 3, &mut crate::rng::seeded(5))
    }

    #[test]
    fn init_is_bounded_by_one_over_sqrt_fan_in_and_seeded() {
        let a = net();
        assert_eq!(a, net());
        let b = Mlp::new(4, 16, 2, 3, &mut crate::rng::seeded(6));
        assert_ne!(a, b);
        let p = a.params();
        assert!(p.w0.iter().chain(p.b0.iter()).all(|v| v.abs() <= 0.5));
        assert!(p.w1.iter().chain(p.bh.iter()).all(|v| v.abs() <= 0.25));
        // The bound is used, not something much smaller.
        assert!(p.w0.iter().any(|v| v.abs() > 0.4));
        assert!(p.w1.iter().any(|v| v.abs() > 0.2));
        assert_eq!(a.num_params(), 16 * 4 + 16 + 16 * 16 + 16 + 6 * 16 + 6);
    }

    /// `net`'s batched pass on five 4-dimensional states gives its one-state pass on each.
    fn assert_batch_matches_one(net: &Mlp, states: &[f32]) {
        let mut cache = ForwardCache::default();
        net.forward_batch(states, &mut cache);
        assert_eq!(cache.batch_size(), 5);
        let mut out = [0.0f32; 6];
        for (j, s) in states.chunks_exact(4).enumerate() {
            net.forward_one(s, &mut out);
            for (c, &o) in out.iter().enumerate() {
                assert!((cache.q()[(j, c)] - o).abs() < 1e-5, "row {j} col {c}");
            }
        }
    }

    #[test]
    fn forward_one_matches_forward_batch() {
        let states: Vec<f32> = (0..20).map(|i| (i as f32 * 0.7).sin() * 2.0).collect();
        assert_batch_matches_one(&net(), &states);
    }

    #[test]
    fn a_batch_of_no_states_gives_no_q_values() {
        let mut cache = ForwardCache::default();
        net().forward_batch(&[], &mut cache);
        assert_eq!(cache.q().nrows(), 0);
    }

    #[test]
    fn flat_params_round_trip_and_refuse_wrong_lengths() {
        let a = net();
        let flat = a.params_flat();
        assert_eq!(flat.len(), a.num_params());
        // The first values are torso.0.weight row-major: row 0 is output 0's weights.
        assert_eq!(flat[..4], a.params().w0.column(0).as_slice()[..]);
        let mut b = Mlp::new(4, 16, 2, 3, &mut crate::rng::seeded(9));
        assert_ne!(a, b);
        b.load_params_flat(&flat).unwrap();
        assert_eq!(a, b);
        assert!(matches!(
            b.load_params_flat(&flat[1..]),
            Err(NnError::ParamCount { expected, found }) if expected == flat.len() && found == flat.len() - 1
        ));
        let mut short = vec![0.0; 3];
        assert!(a.copy_params_into(&mut short).is_err());
        let mut c = Mlp::new(4, 8, 2, 3, &mut crate::rng::seeded(9));
        assert!(c.copy_params_from(&a).is_err());
        let mut d = Mlp::new(4, 16, 2, 3, &mut crate::rng::seeded(10));
        d.copy_params_from(&a).unwrap();
        assert_eq!(d, a);
    }

    #[test]
    fn from_params_checks_shapes() {
        let p = net().into_params();
        assert!(Mlp::from_params(p.clone(), 2, 3).is_ok());
        let err = Mlp::from_params(p.clone(), 3, 3).unwrap_err();
        assert!(err.to_string().contains("heads.weight"), "{err}");
        let mut bad = p;
        bad.b1 = DVector::zeros(3);
        let err = Mlp::from_params(bad, 2, 3).unwrap_err();
        assert!(err.to_string().contains("torso.1.bias"), "{err}");
    }

    #[test]
    fn matmul_kernels_match_nalgebra_products() {
        let mut rng = crate::rng::seeded(4);
        let mut rand =
            |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.random_range(-1.0f32..1.0));
        // Thin (axpy and dot kernels) and wide (matrixmultiply) shapes.
        for (m, k, n) in [(64, 4, 64), (64, 64, 4), (7, 3, 2), (64, 64, 64), (9, 8, 7)] {
            let a = rand(m, k);
            let b = rand(k, n);
            let mut out = rand(m, n);
            let expected = &a * &b + &out;
            matmul(&mut out, &a, view(&b), Epi::Add);
            assert!((out - &expected).abs().max() < 1e-5, "matmul {m}x{k}x{n}");
            let bt = b.transpose();
            let mut out = rand(m, n);
            matmul(&mut out, &a, transposed(&bt), Epi::Set);
            assert!(
                (out - &a * &b).abs().max() < 1e-5,
                "matmul by a view {m}x{k}x{n}"
            );
            let c = rand(m, n);
            let mut out = rand(k, n);
            tr_matmul(&mut out, &a, &c, &mut Vec::new());
            assert!(
                (out - a.transpose() * &c).abs().max() < 1e-5,
                "tr_matmul {m}x{k}x{n}"
            );
        }
    }

    #[test]
    fn a_prior_adds_beta_times_its_fixed_network_to_every_output() {
        let base = net();
        assert!(base.clone().with_prior(0.0, 1).prior().is_none());
        let with = base.clone().with_prior(2.5, 7);
        let prior = with.prior().unwrap();
        assert_eq!((prior.scale(), prior.seed()), (2.5, 7));
        // The same seed draws the same prior; another seed another one.
        assert_eq!(with, base.clone().with_prior(2.5, 7));
        assert_ne!(with, base.clone().with_prior(2.5, 8));
        let x = [0.3f32, -1.2, 0.8, 2.0];
        let (mut f, mut p, mut q) = ([0.0f32; 6], [0.0f32; 6], [0.0f32; 6]);
        base.forward_one(&x, &mut f);
        prior.network().forward_one(&x, &mut p);
        with.forward_one(&x, &mut q);
        for c in 0..6 {
            assert!((q[c] - (f[c] + 2.5 * p[c])).abs() < 1e-5, "output {c}");
            assert!(p[c] != 0.0);
        }
        // The batched pass adds the same prior.
        let states: Vec<f32> = (0..20).map(|i| (i as f32 * 0.3).cos()).collect();
        assert_batch_matches_one(&with, &states);
    }

    #[test]
    fn a_prior_is_not_trained_sent_or_overwritten() {
        let base = net();
        let with = base.clone().with_prior(1.0, 3);
        // The prior is no parameter: not in the flat vector, untouched by loading weights.
        assert_eq!(with.num_params(), base.num_params());
        let mut other = Mlp::new(4, 16, 2, 3, &mut crate::rng::seeded(8)).with_prior(1.0, 3);
        other.load_params_flat(&base.params_flat()).unwrap();
        assert_eq!(other, with);
        let mut copied = Mlp::new(4, 16, 2, 3, &mut crate::rng::seeded(9)).with_prior(1.0, 3);
        copied.copy_params_from(&base).unwrap();
        assert_eq!(copied, with);
        // The gradients of the trained weights do not depend on the prior: dQ/dθ is the plain
        // network's at the same activations.
        let states: Vec<f32> = (0..12).map(|i| (i as f32 * 0.9).sin()).collect();
        let dq = DMatrix::from_fn(3, 6, |i, j| (i as f32 - j as f32) * 0.1);
        let (mut g_base, mut g_with) = (base.params().zeros_like(), base.params().zeros_like());
        let (mut c_base, mut c_with) = (ForwardCache::default(), ForwardCache::default());
        base.forward_batch(&states, &mut c_base);
        base.backward(&mut c_base, &dq, &mut g_base);
        with.forward_batch(&states, &mut c_with);
        with.backward(&mut c_with, &dq, &mut g_with);
        assert_eq!(g_base, g_with);
        assert_ne!(c_base.q(), c_with.q());
    }

    #[test]
    fn dot_and_sum_handle_tails() {
        let a: Vec<f32> = (0..13).map(|i| i as f32).collect();
        assert_eq!(dots::sum(&a), 78.0);
        assert_eq!(dot(&a, &a), (0..13).map(|i| (i * i) as f32).sum::<f32>());
        assert_eq!(dots::sum(&[]), 0.0);
    }
}
