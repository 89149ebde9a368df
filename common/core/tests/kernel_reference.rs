//! The demonstration models (KRR and SVM) against scikit-learn's outputs in
//! `data/kernel_models.json`, and their behaviour on degenerate demonstrations.

use alfd_common::demo_model::{DemoModel, DemoModelError, DemoModelKind, KernelSvm};
use serde::Deserialize;

#[derive(Deserialize)]
struct Fixture {
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    train_states: Vec<Vec<f64>>,
    train_actions: Vec<usize>,
    query_states: Vec<Vec<f64>>,
    krr_predictions: Vec<Vec<f64>>,
    svc_decision_function: Vec<f64>,
    svc_predictions: Vec<usize>,
}

fn cases() -> Vec<Case> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/kernel_models.json");
    let text = std::fs::read_to_string(path).expect("read kernel_models.json");
    let fixture: Fixture = serde_json::from_str(&text).expect("parse kernel_models.json");
    assert_eq!(fixture.cases.len(), 3);
    fixture.cases
}

#[test]
fn krr_matches_scikit_learn() {
    for (c, case) in cases().iter().enumerate() {
        let model = DemoModel::fit(
            DemoModelKind::Krr,
            &case.train_states,
            &case.train_actions,
            2,
        )
        .unwrap();
        let mut max_err: f64 = 0.0;
        for (s, expected) in case.query_states.iter().zip(&case.krr_predictions) {
            let raw = model.raw(s);
            assert_eq!(raw.len(), 2);
            for (r, e) in raw.iter().zip(expected) {
                max_err = max_err.max((r - e).abs());
            }
        }
        println!(
            "case {c}: {} demos, KRR max abs error {max_err:.3e}",
            case.train_actions.len()
        );
        assert!(max_err < 1e-8, "case {c}: KRR max abs error {max_err:e}");
    }
}

#[test]
fn svm_decision_values_match_scikit_learn() {
    for (c, case) in cases().iter().enumerate() {
        let model = KernelSvm::fit(&case.train_states, &case.train_actions, 2).unwrap();
        let mut max_err: f64 = 0.0;
        for (q, s) in case.query_states.iter().enumerate() {
            let f = model.decision_value(s);
            let expected = case.svc_decision_function[q];
            assert_eq!(
                f > 0.0,
                expected > 0.0,
                "case {c} query {q}: {f} vs {expected}"
            );
            assert_eq!(
                usize::from(f > 0.0),
                case.svc_predictions[q],
                "case {c} query {q}"
            );
            max_err = max_err.max((f - expected).abs());
        }
        println!(
            "case {c}: SVM max abs decision error {max_err:.3e}, {} support vectors",
            model.num_support()
        );
        assert!(
            max_err < 1e-2,
            "case {c}: SVM max abs decision error {max_err:e}"
        );
    }
}

#[test]
fn svm_probabilities_are_calibrated_and_mostly_agree_with_the_decision() {
    let (mut agree, mut total) = (0, 0);
    for (c, case) in cases().iter().enumerate() {
        let model = DemoModel::fit(
            DemoModelKind::Svm,
            &case.train_states,
            &case.train_actions,
            2,
        )
        .unwrap();
        for s in &case.query_states {
            let p = model.probs(s);
            assert_eq!(p.len(), 2);
            assert!(p.iter().all(|v| (0.0..=1.0).contains(v)), "case {c}: {p:?}");
            assert!((p[0] + p[1] - 1.0).abs() < 1e-12, "case {c}: {p:?}");
            assert_eq!(model.prob(s, 1), p[1]);
            agree += usize::from((p[1] > 0.5) == (model.raw(s)[0] > 0.0));
            total += 1;
        }
    }
    let rate = agree as f64 / total as f64;
    println!("SVM: P(action 1) > 0.5 agrees with decision > 0 on {agree}/{total} queries");
    assert!(rate >= 0.9, "agreement {rate}");
}

#[test]
fn krr_probabilities_sum_to_one() {
    for case in cases() {
        let model = DemoModel::fit(
            DemoModelKind::Krr,
            &case.train_states,
            &case.train_actions,
            2,
        )
        .unwrap();
        for s in &case.query_states {
            let p = model.probs(s);
            let f = model.raw(s);
            assert!(p.iter().all(|v| (0.0..=1.0).contains(v)), "{p:?}");
            assert!((p[0] + p[1] - 1.0).abs() < 1e-12, "{p:?}");
            let expected = (0.5 + (f[1] - f[0]) / 2.0).clamp(0.0, 1.0);
            assert!((p[1] - expected).abs() < 1e-15);
        }
    }
}

#[test]
fn models_are_deterministic_and_survive_postcard() {
    let case = &cases()[1];
    for kind in [DemoModelKind::Krr, DemoModelKind::Svm] {
        let a = DemoModel::fit(kind, &case.train_states, &case.train_actions, 2).unwrap();
        let b = DemoModel::fit(kind, &case.train_states, &case.train_actions, 2).unwrap();
        assert_eq!(a, b, "{kind}: two fits differ");
        let bytes = postcard::to_stdvec(&a).unwrap();
        let back: DemoModel = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(back, a);
        assert_eq!(back.kind(), kind);
        for s in &case.query_states {
            let (pa, pb) = (a.probs(s), back.probs(s));
            assert_eq!(pa[0].to_bits(), pb[0].to_bits());
            assert_eq!(pa[1].to_bits(), pb[1].to_bits());
        }
    }
}

#[test]
fn svm_with_one_action_demonstrated_is_certain() {
    let states = vec![vec![0.0, 1.0], vec![1.0, 0.0], vec![2.0, 2.0]];
    for action in [0, 1] {
        let model = DemoModel::fit(DemoModelKind::Svm, &states, &[action; 3], 2).unwrap();
        for s in [[0.0, 0.0], [50.0, -3.0]] {
            let p = model.probs(&s);
            assert_eq!(p[action], 1.0);
            assert_eq!(p[1 - action], 0.0);
            assert_eq!(model.raw(&s), vec![if action == 1 { 1.0 } else { -1.0 }]);
        }
    }
}

#[test]
fn svm_with_fewer_demos_than_folds_still_fits() {
    // Two demos (one per action): Platt falls back to in-sample decision values.
    let states = vec![vec![-1.0, 0.0], vec![1.0, 0.0]];
    let model = KernelSvm::fit(&states, &[0, 1], 2).unwrap();
    assert!(model.decision_value(&[-1.0, 0.0]) < 0.0 && model.decision_value(&[1.0, 0.0]) > 0.0);
    let p = model.probs(&[1.0, 0.0]);
    assert!(p[1] > 0.5 && p[1] < 1.0, "{p:?}");
    let platt = model.platt().unwrap();
    assert!(platt.a < 0.0, "{platt:?}");

    // Four demos, two per action: cross-validation over non-empty folds only.
    let states = vec![vec![-2.0], vec![-1.5], vec![1.5], vec![2.0]];
    let model = KernelSvm::fit(&states, &[0, 0, 1, 1], 2).unwrap();
    assert!(model.probs(&[2.0])[1] > 0.5 && model.probs(&[-2.0])[0] > 0.5);
}

#[test]
fn bad_demonstrations_are_refused() {
    for kind in [DemoModelKind::Krr, DemoModelKind::Svm] {
        let none: Vec<Vec<f64>> = Vec::new();
        assert_eq!(
            DemoModel::fit(kind, &none, &[], 2).unwrap_err(),
            DemoModelError::NotEnoughDemos
        );
        let nan = vec![vec![0.0, 0.0], vec![0.0, 0.0], vec![1.0, f64::NAN]];
        let err = DemoModel::fit(kind, &nan, &[0, 1, 0], 2).unwrap_err();
        assert!(
            matches!(
                err,
                DemoModelError::NonFinite {
                    row: 2,
                    column: 1,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("demonstration 2"), "{err}");
    }
    let states = vec![vec![0.0], vec![1.0], vec![2.0]];
    let err = DemoModel::fit(DemoModelKind::Svm, &states, &[0, 1, 2], 3).unwrap_err();
    assert!(matches!(err, DemoModelError::Unsupported(_)), "{err}");
    assert!(err.to_string().contains("2 actions"), "{err}");
}

#[test]
fn contradictory_demonstrations_give_even_odds() {
    // The same state demonstrated with both actions, three times each.
    let states = vec![vec![0.3, -0.2]; 6];
    let actions = [0, 1, 0, 1, 0, 1];
    for kind in [DemoModelKind::Krr, DemoModelKind::Svm] {
        let model = DemoModel::fit(kind, &states, &actions, 2).unwrap();
        let p = model.probs(&[0.3, -0.2]);
        assert!((p[0] - 0.5).abs() < 1e-6, "{kind}: {p:?}");
    }
}

#[derive(Deserialize)]
struct WeightedFixture {
    cases: Vec<WeightedCase>,
}

#[derive(Deserialize)]
struct WeightedCase {
    train_states: Vec<Vec<f64>>,
    train_actions: Vec<usize>,
    weights: Vec<f64>,
    num_actions: usize,
    query_states: Vec<Vec<f64>>,
    predictions: Vec<Vec<f64>>,
}

/// `data/weighted_krr.json` (deploy/python/fixtures/weighted_krr_fixtures.py): scikit-learn's
/// KernelRidge fitted with `sample_weight`, 40 demonstrations (nalgebra's factor) and 600 (the
/// blocked one), some weights 0.
fn weighted_cases() -> Vec<WeightedCase> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/weighted_krr.json");
    let text = std::fs::read_to_string(path).expect("read weighted_krr.json");
    let fixture: WeightedFixture = serde_json::from_str(&text).expect("parse weighted_krr.json");
    assert_eq!(fixture.cases.len(), 2);
    fixture.cases
}

#[test]
fn krr_with_weights_matches_scikit_learn_fitted_or_grown() {
    use alfd_common::demo_model::krr::KrrFactor;
    use alfd_common::demo_model::lanes::Serial;
    for (c, case) in weighted_cases().iter().enumerate() {
        let (s, a, w, m) = (
            &case.train_states,
            &case.train_actions,
            &case.weights,
            case.num_actions,
        );
        assert!(w.contains(&0.0), "case {c} has a weight of 0");
        let fitted = KrrFactor::fit_weighted(s, a, w, m, &Serial).unwrap();
        let model = fitted.model();
        let mut max_err: f64 = 0.0;
        for (q, expected) in case.query_states.iter().zip(&case.predictions) {
            for (r, e) in model.raw(q).iter().zip(expected) {
                max_err = max_err.max((r - e).abs());
            }
        }
        println!(
            "weighted case {c}: {} demos, max abs error {max_err:.3e}",
            a.len()
        );
        assert!(max_err < 1e-8, "case {c}: max abs error {max_err:e}");
        // Grown a demonstration at a time from a fit on the first ones: the same factor.
        let k = a.len() - 5;
        let mut grown = KrrFactor::fit_weighted(&s[..k], &a[..k], &w[..k], m, &Serial).unwrap();
        for i in k..a.len() {
            grown.push_weighted(&s[i], a[i], w[i], &Serial).unwrap();
        }
        assert!(grown == fitted, "case {c}: grown differs from fitted");
    }
}

#[test]
fn weights_of_one_give_the_unweighted_bits_and_a_bad_weight_is_refused() {
    use alfd_common::demo_model::krr::KrrFactor;
    use alfd_common::demo_model::lanes::Serial;
    let case = &weighted_cases()[0];
    let (s, a, m) = (&case.train_states, &case.train_actions, case.num_actions);
    let ones = vec![1.0; a.len()];
    let weighted = KrrFactor::fit_weighted(s, a, &ones, m, &Serial).unwrap();
    assert!(weighted == KrrFactor::fit(s, a, m).unwrap());
    for bad in [-0.5, f64::NAN, f64::INFINITY] {
        let mut w = ones.clone();
        w[3] = bad;
        let e = KrrFactor::fit_weighted(s, a, &w, m, &Serial).unwrap_err();
        assert!(matches!(e, DemoModelError::Weights(_)), "{e}");
    }
    let e = KrrFactor::fit_weighted(s, a, &ones[1..], m, &Serial).unwrap_err();
    assert!(e.to_string().contains("weights for"), "{e}");
}
