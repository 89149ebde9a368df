//! `cargo run --release -p alfd-common --example nystrom_agreement -- B...`: the Nyström model
//! (`nystrom.rs`, 512 landmarks) against the exact KRR on B CartPole demonstrations, and alone
//! beyond the exact model's 10,000. The demonstrations are the states of CartPole-v1 episodes
//! played by a linear controller that takes a random action one step in four (so that the states
//! spread), each with the controller's action; the held-out states come from other episodes.
//! Prints one JSON line per B: the share of held-out states on which the two models' greedy
//! actions agree, the largest difference of p(a|s), each model's agreement with the controller,
//! the seconds of each fit and the microseconds of one query (the exact model only up to
//! 10,000 demonstrations).

use alfd_common::demo_model::{DemoModel, DemoModelKind, MAX_DEMOS};
use alfd_common::env::{CartPole, Env};
use alfd_common::policy::argmax;
use alfd_common::rng::{derive_seed, seeded};
use rand::Rng as _;

/// The controller: push towards where the pole falls.
fn controller(s: &[f64]) -> usize {
    usize::from(s[2] + 0.5 * s[3] + 0.05 * s[0] + 0.2 * s[1] > 0.0)
}

/// `n` states the controller's episodes visit (random actions one step in four) and its actions.
fn demonstrations(n: usize, seed: u64) -> (Vec<Vec<f64>>, Vec<usize>) {
    let mut env = CartPole::new(500);
    let mut rng = seeded(derive_seed(seed, "explore"));
    let (mut states, mut actions) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut obs = env.reset(Some(seed));
    while states.len() < n {
        let s: Vec<f64> = obs.iter().map(|&v| f64::from(v)).collect();
        let a = controller(&s);
        let played = if rng.random_range(0..4) == 0 {
            rng.random_range(0..2)
        } else {
            a
        };
        states.push(s);
        actions.push(a);
        let step = env.step(played).expect("a live episode");
        obs = if step.done() {
            env.reset(None)
        } else {
            step.observation
        };
    }
    (states, actions)
}

/// A model's greedy actions on `states`, and its p(a|s), with the microseconds of one query.
fn answers(model: &DemoModel, states: &[Vec<f64>]) -> (Vec<usize>, Vec<Vec<f64>>, f64) {
    let t = std::time::Instant::now();
    let probs: Vec<Vec<f64>> = states.iter().map(|s| model.probs(s)).collect();
    let us = t.elapsed().as_secs_f64() * 1e6 / states.len() as f64;
    (probs.iter().map(|p| argmax(p)).collect(), probs, us)
}

fn share(a: &[usize], b: &[usize]) -> f64 {
    a.iter().zip(b).filter(|(x, y)| x == y).count() as f64 / a.len() as f64
}

fn main() {
    let sizes: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("a number of demonstrations"))
        .collect();
    let (held_out, truth) = demonstrations(2000, 7_000_001);
    for b in sizes {
        let (states, actions) = demonstrations(b, 20261202);
        let t = std::time::Instant::now();
        let approx = DemoModel::fit(DemoModelKind::Nystrom, &states, &actions, 2).expect("a fit");
        let approx_fit_s = t.elapsed().as_secs_f64();
        let (greedy_a, probs_a, approx_query_us) = answers(&approx, &held_out);
        let mut line = format!(
            r#"{{"demos": {b}, "nystrom_fit_s": {approx_fit_s:.4}, "nystrom_query_us": {approx_query_us:.2}, "nystrom_vs_controller": {:.4}"#,
            share(&greedy_a, &truth)
        );
        if b <= MAX_DEMOS {
            let t = std::time::Instant::now();
            let exact = DemoModel::fit(DemoModelKind::Krr, &states, &actions, 2).expect("a fit");
            let exact_fit_s = t.elapsed().as_secs_f64();
            let (greedy_e, probs_e, exact_query_us) = answers(&exact, &held_out);
            let max_dp = probs_a
                .iter()
                .zip(&probs_e)
                .map(|(a, e)| (a[0] - e[0]).abs())
                .fold(0.0, f64::max);
            line += &format!(
                r#", "krr_fit_s": {exact_fit_s:.4}, "krr_query_us": {exact_query_us:.2}, "krr_vs_controller": {:.4}, "agreement": {:.4}, "max_dp": {max_dp:.4}"#,
                share(&greedy_e, &truth),
                share(&greedy_a, &greedy_e)
            );
        }
        println!("{line}}}");
    }
}
