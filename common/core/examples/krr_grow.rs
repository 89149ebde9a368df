//! `cargo run --release -p alfd-common --example krr_grow -- B R`: the cost of one more
//! demonstration for KRR at B demonstrations, grown (`KrrFactor::push` and the solve for the
//! model) against fitted anew (`KrrFactor::fit` and the solve), on CartPole-like states (two
//! actions). Prints one JSON line: the seconds per grown demonstration (the mean over R of them,
//! from B on; `push_s` the new row of the factor, `model_s` the solve for the model) and the seconds of one fit on B + R, and whether the two models agree bit for bit.

use alfd_common::demo_model::krr::KrrFactor;
use alfd_common::rng::seeded;
use rand::Rng as _;

fn main() {
    let mut args = std::env::args().skip(1);
    let b: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(1000);
    let r: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(10);
    let mut rng = seeded(20261202);
    let states: Vec<[f64; 4]> = (0..b + r)
        .map(|_| {
            [
                rng.random_range(-2.4..2.4),
                rng.random_range(-3.0..3.0),
                rng.random_range(-0.21..0.21),
                rng.random_range(-3.5..3.5),
            ]
        })
        .collect();
    let actions: Vec<usize> = states.iter().map(|s| usize::from(s[2] > 0.0)).collect();

    let mut grown = KrrFactor::fit(&states[..b], &actions[..b], 2).expect("a factor");
    let (mut push_s, mut model_s) = (0.0, 0.0);
    let mut model = None;
    for i in b..b + r {
        let t = std::time::Instant::now();
        grown.push(&states[i], actions[i]).expect("a new row");
        push_s += t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        model = Some(grown.model());
        model_s += t.elapsed().as_secs_f64();
    }
    let (push_s, model_s) = (push_s / r as f64, model_s / r as f64);
    let grow_s = push_s + model_s;

    let t = std::time::Instant::now();
    let fitted = KrrFactor::fit(&states, &actions, 2)
        .expect("a factor")
        .model();
    let fit_s = t.elapsed().as_secs_f64();
    let same = model.as_ref() == Some(&fitted);
    println!(
        r#"{{"demos": {b}, "grown": {r}, "grow_s": {grow_s:.6}, "push_s": {push_s:.6}, "model_s": {model_s:.6}, "fit_s": {fit_s:.6}, "same_bits": {same}}}"#
    );
}
