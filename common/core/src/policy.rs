//! The softmax policy of a Q-function head (paper eq. 2) and the Jensen-Shannon divergence across
//! heads (paper eq. 3, natural log).
//!
//! Q-values of K heads over A actions are laid out head-major: `q[k * A + a]` is `Q_k(s, a)`, the
//! same layout as the network's output layer.

/// `out[a] = exp(q[a] / T) / sum_a' exp(q[a'] / T)`, computed stably (max subtracted).
pub fn softmax_into(q: &[f64], temperature: f64, out: &mut [f64]) {
    debug_assert_eq!(q.len(), out.len());
    debug_assert!(temperature > 0.0);
    let max = q.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut sum = 0.0;
    for (o, &v) in out.iter_mut().zip(q) {
        *o = crate::math::exp((v - max) / temperature);
        sum += *o;
    }
    for o in out.iter_mut() {
        *o /= sum;
    }
}

/// The softmax policy of one head, eq. 2 (temperature 1 in the paper).
pub fn softmax(q: &[f64], temperature: f64) -> Vec<f64> {
    let mut out = vec![0.0; q.len()];
    softmax_into(q, temperature, &mut out);
    out
}

/// Shannon entropy with the natural log; `0 log 0 = 0`.
pub fn entropy(p: &[f64]) -> f64 {
    -p.iter()
        .filter(|&&x| x > 0.0)
        .map(|&x| x * crate::math::ln(x))
        .sum::<f64>()
}

/// Index of the largest value; the first one on ties (as NumPy's argmax).
pub fn argmax<T: PartialOrd + Copy>(v: &[T]) -> usize {
    let mut best = 0;
    for i in 1..v.len() {
        if v[i] > v[best] {
            best = i;
        }
    }
    best
}

/// Jensen-Shannon divergence of the K softmax policies (eq. 3):
/// `H(mean_k pi_k) - mean_k H(pi_k)`, where `q` holds `heads * q.len()/heads` values head-major.
///
/// It keeps its buffers on the stack for up to 64 actions (the act step's hot path) and falls back
/// to the heap above that.
pub fn js_divergence(q: &[f64], heads: usize, temperature: f64) -> f64 {
    assert!(
        heads > 0 && q.len().is_multiple_of(heads),
        "q must hold heads * actions values"
    );
    let actions = q.len() / heads;
    let mut stack_mix = [0.0f64; 64];
    let mut stack_pi = [0.0f64; 64];
    let mut heap_mix;
    let mut heap_pi;
    let (mix, pi): (&mut [f64], &mut [f64]) = if actions <= 64 {
        (&mut stack_mix[..actions], &mut stack_pi[..actions])
    } else {
        heap_mix = vec![0.0; actions];
        heap_pi = vec![0.0; actions];
        (&mut heap_mix[..], &mut heap_pi[..])
    };
    let mut mean_entropy = 0.0;
    for k in 0..heads {
        softmax_into(&q[k * actions..(k + 1) * actions], temperature, pi);
        mean_entropy += entropy(pi);
        for (m, &p) in mix.iter_mut().zip(pi.iter()) {
            *m += p;
        }
    }
    let k = heads as f64;
    for m in mix.iter_mut() {
        *m /= k;
    }
    // Clamp the tiny negative values rounding can give for identical heads.
    (entropy(mix) - mean_entropy / k).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn softmax_sums_to_one_and_orders_like_q() {
        let p = softmax(&[1.0, 2.0, 0.5], 1.0);
        assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(p[1] > p[0] && p[0] > p[2]);
        // A high temperature flattens the policy.
        let flat = softmax(&[1.0, 2.0, 0.5], 1e6);
        assert!(flat.iter().all(|&x| (x - 1.0 / 3.0).abs() < 1e-5));
    }

    #[test]
    fn softmax_is_stable_for_large_values() {
        let p = softmax(&[1000.0, 1001.0], 1.0);
        assert!((p[1] - 1.0 / (1.0 + (-1.0f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn js_of_identical_heads_is_zero_and_of_opposite_heads_is_positive() {
        assert_eq!(js_divergence(&[1.0, 2.0, 1.0, 2.0], 2, 1.0), 0.0);
        let js = js_divergence(&[0.0, 50.0, 50.0, 0.0], 2, 1.0);
        assert!((js - std::f64::consts::LN_2).abs() < 1e-9, "{js}");
    }

    #[test]
    fn argmax_takes_first_on_ties() {
        assert_eq!(argmax(&[1.0, 3.0, 3.0]), 1);
    }
}
