//! The K-head Q-network of the agents: a small MLP on nalgebra with hand-written backpropagation,
//! PyTorch's Adam, safetensors checkpoints and the (Bootstrapped) DQN loss.
//!
//! The network is `obs_dim -> hidden -> hidden -> K*A` with ReLU, all K heads in one output layer:
//! output column `k * A + a` is `Q_k(s, a)`, the layout of [`crate::policy`].
//!
//! # Parameter layout
//!
//! The six tensors follow PyTorch's `nn.Linear` (weight `[out, in]`, bias `[out]`) under the
//! names of [`PARAM_NAMES`]. Each weight is kept as an nalgebra (column-major) matrix of shape
//! `(in, out)`, whose memory is exactly PyTorch's row-major `[out, in]`; so a tensor's slice is its
//! PyTorch data, and the flat parameter vector ([`Mlp::params_flat`]) is the six tensors, each
//! flattened row-major, in the order of [`PARAM_NAMES`]: the same as
//! `torch.cat([p.flatten() for p in net.parameters()])` for a module that declares `torso`
//! before `heads`.

mod adam;
mod dots;
pub mod dqn;
mod gemm;
mod io;
mod mlp;
mod prior;

pub use crate::cpu::use_portable_kernels;
pub use adam::{Adam, AdamConfig, AdamState};
pub use dqn::{
    clip_grad_norm, dqn_loss, loss_and_grads, loss_and_grads_with, train_step, train_step_with,
    TdConfig, TdLoss, TrainScratch,
};
pub(crate) use gemm::{avx512_available, wide};
pub use gemm::{fma_peak_flops_per_round, fma_peak_probe};
pub use io::FORMAT_VERSION;
pub use mlp::{ForwardCache, Mlp};
pub use prior::Prior;

use nalgebra::{DMatrix, DVector};

/// The names of the six tensors, in the order of the flat parameter vector and of
/// [`Params::tensors`].
pub const PARAM_NAMES: [&str; 6] = [
    "torso.0.weight",
    "torso.0.bias",
    "torso.1.weight",
    "torso.1.bias",
    "heads.weight",
    "heads.bias",
];

/// Everything that can go wrong when weights come from outside: a flat vector, a checkpoint.
#[derive(Debug, thiserror::Error)]
pub enum NnError {
    #[error("the flat parameter vector has {found} values, the network has {expected}")]
    ParamCount { expected: usize, found: usize },
    #[error("invalid safetensors data: {0}")]
    Safetensors(#[from] safetensors::SafeTensorError),
    #[error("tensor `{0}` is missing")]
    MissingTensor(String),
    #[error("unexpected tensor `{0}` (expected only {names:?})", names = PARAM_NAMES)]
    UnexpectedTensor(String),
    #[error("tensor `{name}` has dtype {found}, expected F32")]
    Dtype { name: String, found: String },
    #[error("tensor `{name}` has shape {found:?}, expected {expected:?}")]
    Shape {
        name: String,
        expected: Vec<usize>,
        found: Vec<usize>,
    },
    #[error("metadata `{key}`: {reason}")]
    Metadata { key: String, reason: String },
    #[error("invalid network dimensions: {0}")]
    Dims(String),
}

pub type Result<T, E = NnError> = std::result::Result<T, E>;

/// The six tensors of the network in PyTorch layout (see the module docs). The same type holds
/// the weights, their gradients and Adam's moments.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// `torso.0.weight`: `(obs_dim, hidden)` column-major = PyTorch `[hidden, obs_dim]` row-major.
    pub w0: DMatrix<f32>,
    /// `torso.0.bias`: `[hidden]`.
    pub b0: DVector<f32>,
    /// `torso.1.weight`: `(hidden, hidden)` column-major = PyTorch `[hidden, hidden]` row-major.
    pub w1: DMatrix<f32>,
    /// `torso.1.bias`: `[hidden]`.
    pub b1: DVector<f32>,
    /// `heads.weight`: `(hidden, K*A)` column-major = PyTorch `[K*A, hidden]` row-major.
    pub wh: DMatrix<f32>,
    /// `heads.bias`: `[K*A]`.
    pub bh: DVector<f32>,
}

impl Params {
    /// All-zero tensors for a network `obs_dim -> hidden -> hidden -> outputs`.
    pub fn zeros(obs_dim: usize, hidden: usize, outputs: usize) -> Self {
        Self {
            w0: DMatrix::zeros(obs_dim, hidden),
            b0: DVector::zeros(hidden),
            w1: DMatrix::zeros(hidden, hidden),
            b1: DVector::zeros(hidden),
            wh: DMatrix::zeros(hidden, outputs),
            bh: DVector::zeros(outputs),
        }
    }

    /// All-zero tensors of the same shapes as `self`.
    pub fn zeros_like(&self) -> Self {
        Self::zeros(self.obs_dim(), self.hidden(), self.outputs())
    }

    pub fn obs_dim(&self) -> usize {
        self.w0.nrows()
    }

    pub fn hidden(&self) -> usize {
        self.w0.ncols()
    }

    /// `K * A`.
    pub fn outputs(&self) -> usize {
        self.wh.ncols()
    }

    /// `(obs_dim, hidden, outputs)`: equal exactly when [`Params::shapes`] are, without
    /// allocating.
    pub(crate) fn dims(&self) -> (usize, usize, usize) {
        (self.obs_dim(), self.hidden(), self.outputs())
    }

    /// The PyTorch shapes (`[out, in]` for weights) in the order of [`PARAM_NAMES`].
    pub fn shapes(&self) -> [Vec<usize>; 6] {
        torch_shapes(self.obs_dim(), self.hidden(), self.outputs())
    }

    /// The six tensors' data (PyTorch row-major order), in the order of [`PARAM_NAMES`].
    pub fn tensors(&self) -> [&[f32]; 6] {
        [
            self.w0.as_slice(),
            self.b0.as_slice(),
            self.w1.as_slice(),
            self.b1.as_slice(),
            self.wh.as_slice(),
            self.bh.as_slice(),
        ]
    }

    /// Mutable access to the six tensors' data, in the order of [`PARAM_NAMES`].
    pub fn tensors_mut(&mut self) -> [&mut [f32]; 6] {
        [
            self.w0.as_mut_slice(),
            self.b0.as_mut_slice(),
            self.w1.as_mut_slice(),
            self.b1.as_mut_slice(),
            self.wh.as_mut_slice(),
            self.bh.as_mut_slice(),
        ]
    }

    /// The total number of scalars.
    pub fn len(&self) -> usize {
        self.tensors().iter().map(|t| t.len()).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Sets every value to `v`.
    pub fn fill(&mut self, v: f32) {
        for t in self.tensors_mut() {
            t.fill(v);
        }
    }
}

/// The parameters of a network with `obs_dim` inputs, `hidden` units in each of its two hidden
/// layers and `outputs` outputs (K · A): what its weights publish.
pub fn param_count(obs_dim: usize, hidden: usize, outputs: usize) -> usize {
    torch_shapes(obs_dim, hidden, outputs)
        .iter()
        .map(|s| s.iter().product::<usize>())
        .sum()
}

/// The PyTorch shapes of the six tensors, in the order of [`PARAM_NAMES`].
pub(crate) fn torch_shapes(obs_dim: usize, hidden: usize, outputs: usize) -> [Vec<usize>; 6] {
    [
        vec![hidden, obs_dim],
        vec![hidden],
        vec![hidden, hidden],
        vec![hidden],
        vec![outputs, hidden],
        vec![outputs],
    ]
}
