//! The network against a PyTorch trace (`data/mlp_torch_trace.json`, K = 3, A = 2): the forward
//! pass, the parameter gradients for a given dL/dQ, and the weights after 5 Adam steps.
//!
//! Tolerance: `|ours - torch| <= 1e-4 * max(|torch|, 1e-3)`, i.e. 1e-4 relative, with an
//! absolute floor of 1e-7 for values near zero (f32 sums over 64 samples in a different order
//! differ by about that much).

use alfd_common::nn::{Adam, ForwardCache, Mlp, Params, PARAM_NAMES};
use nalgebra::DMatrix;
use serde_json::Value;

fn trace() -> Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/mlp_torch_trace.json"
    );
    let text = std::fs::read_to_string(path).expect("read the PyTorch trace");
    serde_json::from_str(&text).expect("parse the PyTorch trace")
}

/// A JSON number, or a (nested) array of numbers, flattened row-major.
fn flat(v: &Value) -> Vec<f32> {
    match v {
        Value::Number(n) => vec![n.as_f64().expect("a finite number") as f32],
        Value::Array(items) => items.iter().flat_map(flat).collect(),
        other => panic!("expected numbers, found {other}"),
    }
}

/// The six tensors of a `{name: tensor}` object, flattened in the order of `PARAM_NAMES`.
fn tensors(v: &Value) -> Vec<Vec<f32>> {
    PARAM_NAMES.iter().map(|name| flat(&v[*name])).collect()
}

fn rows(v: &Value) -> usize {
    v.as_array().expect("an array of rows").len()
}

/// `(worst |a - b| / (1e-4 * max(|b|, 1e-3)), index)`: below 1 means within tolerance.
fn worst_ratio(ours: &[f32], torch: &[f32]) -> (f64, usize) {
    assert_eq!(ours.len(), torch.len());
    ours.iter()
        .zip(torch)
        .map(|(&a, &b)| {
            let (a, b) = (f64::from(a), f64::from(b));
            (a - b).abs() / (1e-4 * b.abs().max(1e-3))
        })
        .enumerate()
        .map(|(i, r)| (r, i))
        .fold((0.0, 0), |best, x| if x.0 > best.0 { x } else { best })
}

fn assert_close(what: &str, ours: &[f32], torch: &[f32]) {
    let (ratio, i) = worst_ratio(ours, torch);
    assert!(
        ratio <= 1.0,
        "{what}: index {i}: ours {} vs torch {} ({ratio:.2}x the tolerance)",
        ours[i],
        torch[i]
    );
}

fn within_tolerance(ours: &Params, torch: &[Vec<f32>]) -> bool {
    ours.tensors()
        .iter()
        .zip(torch)
        .all(|(o, t)| worst_ratio(o, t).0 <= 1.0)
}

struct Setup {
    net: Mlp,
    input: Vec<f32>,
    dq: DMatrix<f32>,
    json: Value,
}

fn setup() -> Setup {
    let json = trace();
    let heads = json["heads"].as_u64().expect("heads") as usize;
    let actions = json["actions"].as_u64().expect("actions") as usize;
    assert_eq!((heads, actions), (3, 2));
    let weights = tensors(&json["weights"]);
    let obs_dim = weights[0].len() / weights[1].len();
    let hidden = weights[1].len();
    let mut net = Mlp::new(
        obs_dim,
        hidden,
        heads,
        actions,
        &mut alfd_common::rng::seeded(0),
    );
    let flat_weights: Vec<f32> = weights.concat();
    net.load_params_flat(&flat_weights)
        .expect("the trace's weights fit the network");
    let input = flat(&json["input"]);
    let batch = rows(&json["input"]);
    let dq = DMatrix::from_row_slice(batch, heads * actions, &flat(&json["upstream_grad"]));
    Setup {
        net,
        input,
        dq,
        json,
    }
}

fn grads(net: &Mlp, input: &[f32], dq: &DMatrix<f32>, cache: &mut ForwardCache) -> Params {
    let mut g = net.params().zeros_like();
    net.forward_batch(input, cache);
    net.backward(cache, dq, &mut g);
    g
}

#[test]
fn forward_matches_pytorch() {
    let s = setup();
    let mut cache = ForwardCache::default();
    s.net.forward_batch(&s.input, &mut cache);
    let q = cache.q();
    let torch = flat(&s.json["q_values"]);
    // Our Q is (batch, K*A) column-major; compare row-major.
    let ours: Vec<f32> = (0..q.nrows())
        .flat_map(|i| (0..q.ncols()).map(move |c| (i, c)))
        .map(|ic| q[ic])
        .collect();
    assert_eq!(ours.len(), 64 * 6);
    assert_close("q_values", &ours, &torch);
    // And the single-state path gives the same numbers.
    let mut out = [0.0f32; 6];
    for (i, x) in s.input.chunks_exact(4).enumerate() {
        s.net.forward_one(x, &mut out);
        assert_close("forward_one", &out, &torch[i * 6..(i + 1) * 6]);
    }
}

#[test]
fn gradients_match_pytorch() {
    let s = setup();
    let g = grads(&s.net, &s.input, &s.dq, &mut ForwardCache::default());
    let torch = tensors(&s.json["grads"]);
    for ((name, ours), t) in PARAM_NAMES.iter().zip(g.tensors()).zip(&torch) {
        assert_close(name, ours, t);
    }
}

/// The trace's `source` says the loss is `sum(Q * G)`: each of the 5 steps recomputes the
/// gradient at the current weights (a normal training loop), with the same input and G. Applying
/// the first gradient 5 times gives different weights, and this checks that it does not match,
/// so that the test tells the two readings apart.
#[test]
fn five_adam_steps_match_pytorch() {
    let s = setup();
    let source = s.json["source"].as_str().expect("source");
    assert!(
        source.contains("sum(Q * G)") && source.contains("5 steps"),
        "{source}"
    );
    let torch = tensors(&s.json["weights_after_5_adam_steps"]);
    let mut cache = ForwardCache::default();

    let mut net = s.net.clone();
    let mut adam = Adam::new(&net);
    for _ in 0..5 {
        let g = grads(&net, &s.input, &s.dq, &mut cache);
        adam.step(&mut net, &g);
    }
    assert_eq!(adam.steps(), 5);
    for ((name, ours), t) in PARAM_NAMES.iter().zip(net.params().tensors()).zip(&torch) {
        assert_close(name, ours, t);
    }

    let mut stale = s.net.clone();
    let mut adam = Adam::new(&stale);
    let g0 = grads(&stale, &s.input, &s.dq, &mut cache);
    for _ in 0..5 {
        adam.step(&mut stale, &g0);
    }
    assert!(
        !within_tolerance(stale.params(), &torch),
        "reusing the first gradient also matches: the trace does not tell the readings apart"
    );
    // The weights did move: 5 steps of about lr each.
    let moved = net
        .params_flat()
        .iter()
        .zip(s.net.params_flat())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(moved > 4e-3 && moved < 6e-3, "{moved}");
}
