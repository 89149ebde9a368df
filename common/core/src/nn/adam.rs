//! Adam (Kingma & Ba), computed as PyTorch's `torch.optim.Adam` does without weight decay or
//! AMSGrad, so that our weights follow a PyTorch run step for step.
//!
//! One difference: a moment whose magnitude falls below `f32::MIN_POSITIVE` (a subnormal, as
//! the first moment of a weight whose gradient stays zero becomes within a thousand steps) is
//! kept as zero. Subnormal arithmetic costs some CPUs (Intel's) tens of cycles an operation, and
//! such a moment moves no weight: its update is below 1e-30 (the denominator is at least
//! `eps`), and a weight's own rounding step is larger unless the weight is itself below 1e-20.

use super::{Mlp, Params};
use crate::math;

/// Adam's hyper-parameters; the defaults are the paper's (and PyTorch's, but for `lr`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamConfig {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// The optimiser state: the step count and the first and second moments of every parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Adam {
    config: AdamConfig,
    step: u64,
    m: Params,
    v: Params,
    /// The steps after which `beta1^t` and `beta2^t` no longer change their bias corrections:
    /// see [`one_minus_power`].
    negligible_after: [f64; 2],
}

/// Adam's state in a checkpoint: the step count and the moments, flattened in the order of
/// [`Params::tensors`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdamState {
    pub step: u64,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
}

fn flat(p: &Params) -> Vec<f32> {
    p.tensors().concat()
}

fn unflat(p: &mut Params, flat: &[f32]) -> bool {
    if flat.len() != p.len() {
        return false;
    }
    let mut offset = 0;
    for t in p.tensors_mut() {
        let n = t.len();
        t.copy_from_slice(&flat[offset..offset + n]);
        offset += n;
    }
    true
}

impl Adam {
    /// The step count and the moments, for a checkpoint.
    pub fn state(&self) -> AdamState {
        AdamState {
            step: self.step,
            m: flat(&self.m),
            v: flat(&self.v),
        }
    }

    /// Restores [`Adam::state`]; `false` (nothing changed) if the moments have other sizes.
    pub fn restore(&mut self, state: &AdamState) -> bool {
        let (mut m, mut v) = (self.m.clone(), self.v.clone());
        if !unflat(&mut m, &state.m) || !unflat(&mut v, &state.v) {
            return false;
        }
        (self.m, self.v, self.step) = (m, v, state.step);
        true
    }

    /// Adam with the default hyper-parameters for the parameters of `net`.
    pub fn new(net: &Mlp) -> Self {
        Self::with_config(net, AdamConfig::default())
    }

    pub fn with_config(net: &Mlp, config: AdamConfig) -> Self {
        Self {
            config,
            step: 0,
            m: net.params().zeros_like(),
            v: net.params().zeros_like(),
            negligible_after: [config.beta1, config.beta2].map(negligible_after),
        }
    }

    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// How many steps were taken.
    /// Sets the learning rate of the next steps (a schedule's).
    pub fn set_lr(&mut self, lr: f64) {
        self.config.lr = lr;
    }

    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One update of `net` with the gradients `grads` (same shapes). As PyTorch's single-tensor
    /// Adam: `m <- lerp(m, g, 1 - beta1)`, `v <- beta2 v + (1 - beta2) g^2`, then
    /// `p <- p - lr / (1 - beta1^t) * m / (sqrt(v) / sqrt(1 - beta2^t) + eps)`, with the bias
    /// corrections in f64 (Python floats) and the element-wise work in f32.
    ///
    /// Panics if `grads` does not have the shapes of `net`'s parameters.
    pub fn step(&mut self, net: &mut Mlp, grads: &Params) {
        assert!(
            grads.dims() == self.m.dims(),
            "gradients do not have the optimiser's shapes: {:?} and {:?}",
            grads.shapes(),
            self.m.shapes()
        );
        assert!(
            net.params.dims() == self.m.dims(),
            "network does not have the optimiser's shapes: {:?} and {:?}",
            net.params.shapes(),
            self.m.shapes()
        );
        self.step += 1;
        let c = &self.config;
        let t = self.step as f64;
        let bias_correction1 = one_minus_power(c.beta1, t, self.negligible_after[0]);
        let bias_correction2 = one_minus_power(c.beta2, t, self.negligible_after[1]);
        let step_size = (c.lr / bias_correction1) as f32;
        let bias_correction2_sqrt = bias_correction2.sqrt() as f32;
        let update = Update {
            w1: (1.0 - c.beta1) as f32,
            beta2: c.beta2 as f32,
            w2: (1.0 - c.beta2) as f32,
            eps: c.eps as f32,
            step_size,
            bias_correction2_sqrt,
        };
        // From about 16,600 steps on (beta2 = 0.999) the correction rounds to 1 in f32, and a
        // division by 1 is the identity: skipping it leaves the same bits and one division per
        // parameter instead of two (the divider bounds this loop).
        let unit_correction = bias_correction2_sqrt == 1.0;
        let tensors = net
            .params
            .tensors_mut()
            .into_iter()
            .zip(grads.tensors())
            .zip(self.m.tensors_mut())
            .zip(self.v.tensors_mut());
        // Element by element: AVX-512 or AVX2 where there is one changes the speed, not the
        // numbers.
        super::gemm::widest(
            #[inline(always)]
            || {
                for (((p, g), m), v) in tensors {
                    if unit_correction {
                        update.tensor::<true>(p, g, m, v);
                    } else {
                        update.tensor::<false>(p, g, m, v);
                    }
                }
            },
        );
    }
}

/// `1 - beta^t` in f64, without computing the power once it is too small to change the
/// difference: for `t` beyond [`negligible_after`], `|beta|^t < e^-40 < 2^-55`, and `1 - p` with
/// `|p| < 2^-54` rounds to 1 (half the gap between 1 and the float below it), whatever `powf`
/// gives within an ulp of the power.
fn one_minus_power(beta: f64, t: f64, negligible_after: f64) -> f64 {
    if t > negligible_after {
        1.0
    } else {
        1.0 - math::powf(beta, t)
    }
}

/// The step count from which `|beta|^t < e^-40` (`t ln|beta| < -40`; never for `|beta| >= 1`
/// or a NaN). The margin to `2^-55` (about `e^-38.1`) covers the logarithm's rounding, so
/// where the threshold falls does not change any result.
fn negligible_after(beta: f64) -> f64 {
    let log = math::ln(beta.abs());
    if log < 0.0 {
        -40.0 / log
    } else {
        f64::INFINITY
    }
}

/// The constants of one Adam step.
struct Update {
    w1: f32,
    beta2: f32,
    w2: f32,
    eps: f32,
    step_size: f32,
    bias_correction2_sqrt: f32,
}

impl Update {
    /// One tensor's parameters `p`, gradients `g` and moments `m`, `v`; `UNIT` when the second
    /// moment's correction is 1 (not divided by).
    #[inline(always)]
    fn tensor<const UNIT: bool>(&self, p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32]) {
        for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
            *m = normal_or_zero(*m + self.w1 * (g - *m));
            *v = normal_or_zero(*v * self.beta2 + self.w2 * (g * g));
            let root = if UNIT {
                v.sqrt()
            } else {
                v.sqrt() / self.bias_correction2_sqrt
            };
            *p -= self.step_size * (*m / (root + self.eps));
        }
    }
}

/// `x`, or zero where `x` is subnormal (below `f32::MIN_POSITIVE` in magnitude).
#[inline(always)]
fn normal_or_zero(x: f32) -> f32 {
    if x.abs() < f32::MIN_POSITIVE {
        0.0
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_every_parameter_by_lr_against_its_gradient() {
        let mut net = Mlp::new(3, 5, 1, 2, &mut crate::rng::seeded(1));
        let before = net.params_flat();
        let mut grads = net.params().zeros_like();
        let mut i = 0;
        for t in grads.tensors_mut() {
            for g in t {
                *g = if i % 2 == 0 { 0.3 } else { -2.0 };
                i += 1;
            }
        }
        let mut adam = Adam::new(&net);
        adam.step(&mut net, &grads);
        assert_eq!(adam.steps(), 1);
        // At t = 1, m / sqrt(v) (bias-corrected) is sign(g), so each step is lr.
        for (j, (a, b)) in net.params_flat().iter().zip(&before).enumerate() {
            let expected = if j % 2 == 0 { -1e-3 } else { 1e-3 };
            assert!((a - b - expected).abs() < 1e-6, "param {j}: {}", a - b);
        }
    }

    #[test]
    fn a_step_whose_correction_rounds_to_one_moves_each_parameter_as_the_formula() {
        for step in [16_000, 16_700, 40_000] {
            // Tensors of 120, 40, 1,600, 40, 80 and 2 parameters: the 16- and 8-lane loops
            // and their tails.
            let mut net = Mlp::new(3, 40, 1, 2, &mut crate::rng::seeded(2));
            let mut adam = Adam::new(&net);
            let mut grads = net.params().zeros_like();
            for (i, g) in grads.tensors_mut().into_iter().flatten().enumerate() {
                *g = 0.01 * i as f32 - 0.2;
            }
            adam.step(&mut net, &grads);
            let mut state = adam.state();
            state.step = step;
            assert!(adam.restore(&state));
            let (before, s) = (net.params_flat(), adam.state());
            adam.step(&mut net, &grads);
            let c = AdamConfig::default();
            let t = (step + 1) as f64;
            let step_size = (c.lr / (1.0 - math::powf(c.beta1, t))) as f32;
            let correction = (1.0 - math::powf(c.beta2, t)).sqrt() as f32;
            // Below about 16,600 steps the correction is not 1 and is divided by.
            assert_eq!(correction == 1.0, step > 16_000, "step {step}");
            let flat_grads = grads.tensors().concat();
            for (j, g) in flat_grads.into_iter().enumerate() {
                let m = s.m[j] + (1.0 - c.beta1) as f32 * (g - s.m[j]);
                let v = s.v[j] * c.beta2 as f32 + (1.0 - c.beta2) as f32 * (g * g);
                let p = before[j] - step_size * (m / (v.sqrt() / correction + c.eps as f32));
                assert_eq!(
                    net.params_flat()[j].to_bits(),
                    p.to_bits(),
                    "step {step}, param {j}"
                );
            }
        }
    }

    #[test]
    fn bias_corrections_skip_the_power_only_where_it_rounds_away() {
        for beta in [0.0, 0.5, 0.9, 0.99, 0.999, 0.9999, -0.9] {
            let after = negligible_after(beta);
            for t in [1.0, 10.0, 300.0, 381.0, 5_000.0, 39_000.0, 40_000.0, 1e6] {
                let exact = 1.0 - math::powf(beta, t);
                let skipped = one_minus_power(beta, t, after);
                assert_eq!(skipped.to_bits(), exact.to_bits(), "beta {beta}, t {t}");
            }
        }
        assert_eq!(negligible_after(1.0), f64::INFINITY);
        assert_eq!(negligible_after(f64::NAN), f64::INFINITY);
        assert!(negligible_after(0.9) < 400.0 && negligible_after(0.999) < 40_000.0);
    }

    #[test]
    fn zero_gradient_leaves_parameters_alone() {
        let mut net = Mlp::new(3, 5, 2, 2, &mut crate::rng::seeded(1));
        let before = net.clone();
        let grads = net.params().zeros_like();
        let mut adam = Adam::new(&net);
        adam.step(&mut net, &grads);
        assert_eq!(net, before);
    }

    #[test]
    fn decayed_moments_are_zero_rather_than_subnormal() {
        let mut net = Mlp::new(3, 5, 2, 2, &mut crate::rng::seeded(1));
        let mut grads = net.params().zeros_like();
        grads
            .tensors_mut()
            .into_iter()
            .flatten()
            .for_each(|g| *g = 1e-3);
        let mut adam = Adam::new(&net);
        adam.step(&mut net, &grads);
        let zeros = net.params().zeros_like();
        // 0.9^1000 of 1e-4 is about 1e-50: the first moment passes through the subnormals.
        for _ in 0..1000 {
            adam.step(&mut net, &zeros);
        }
        let s = adam.state();
        assert!(s.m.iter().all(|&m| m == 0.0), "{:?}", &s.m[..4]);
        assert!(s.v.iter().all(|&v| v == 0.0 || v.is_normal()));
        assert!(
            s.v.iter().any(|&v| v > 0.0),
            "the second moment decays slower"
        );
    }
}
