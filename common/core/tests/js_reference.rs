//! The Jensen-Shannon divergence of K softmax policies (eq. 2-3) against NumPy's, to 1e-9.

use alfd_common::policy::js_divergence;
use alfd_common::qfunction::{QFunction, TabularQ};

#[derive(serde::Deserialize)]
struct Fixture {
    cases: Vec<Case>,
}

#[derive(serde::Deserialize)]
struct Case {
    /// `q_values[k][a]`.
    q_values: Vec<Vec<f64>>,
    js: f64,
}

fn fixture() -> Fixture {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/js_divergence.json");
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn js_divergence_matches_numpy_on_every_case() {
    let cases = fixture().cases;
    assert_eq!(cases.len(), 16);
    let mut worst = 0.0f64;
    for (i, c) in cases.iter().enumerate() {
        let heads = c.q_values.len();
        let flat: Vec<f64> = c.q_values.concat();
        let js = js_divergence(&flat, heads, 1.0);
        worst = worst.max((js - c.js).abs());
        assert!(
            (js - c.js).abs() <= 1e-9,
            "case {i} (K = {heads}): {js} vs {}",
            c.js
        );
    }
    assert!(worst <= 1e-9);
}

#[test]
fn tabular_heads_give_the_same_divergence_through_the_trait() {
    for c in fixture().cases {
        let (heads, actions) = (c.q_values.len(), c.q_values[0].len());
        let mut q = TabularQ::new(1, heads, actions, 0.0);
        for (k, row) in c.q_values.iter().enumerate() {
            for (a, &v) in row.iter().enumerate() {
                q.set(0, k, a, v);
            }
        }
        assert!((q.js_divergence(&0, 1.0) - c.js).abs() <= 1e-9);
    }
}
