//! `cargo run --release -p alfd-common --example krr_grow -- B R`: the cost of one more
//! demonstration for KRR at B demonstrations, grown (`KrrFactor::push_on` and the solve for the
//! model, `model_on`) against fitted anew (`KrrFactor::fit` and the solve), on CartPole-like
//! states (two actions). The R arrivals from B on take turns on one lane and on two lanes that
//! run at once; every model is solved on both. Prints one JSON line: the median seconds per grown
//! demonstration on one lane (`grow_s`: `push_s` the new row of the factor, `model_s` the solve
//! for the model) and on two (`grow_2_s`, `push_2_s`, `model_2_s`), the seconds of one fit on
//! B + R, and whether every model agrees bit for bit (one lane, two lanes, fitted anew).

use alfd_common::demo_model::krr::KrrFactor;
use alfd_common::demo_model::lanes::{Lanes, Serial};
use alfd_common::rng::seeded;
use rand::Rng as _;

/// Two lanes that run at once, each job on a scoped thread (as `alfd_harness::Threads`, which
/// this crate's examples cannot use).
struct Two;

impl Lanes for Two {
    fn width(&self) -> usize {
        2
    }
    fn run<'a>(&self, jobs: Vec<Box<dyn FnOnce() + Send + 'a>>) {
        std::thread::scope(|scope| {
            for job in jobs {
                scope.spawn(job);
            }
        });
    }
    fn concurrent(&self) -> bool {
        true
    }
    fn pause(&self) {
        std::thread::yield_now();
    }
}

/// Seconds of each push and each solve per lane count (index 0: one lane, 1: two).
#[derive(Default)]
struct Times {
    push: [Vec<f64>; 2],
    model: [Vec<f64>; 2],
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    match xs.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => xs[n / 2],
        n => (xs[n / 2 - 1] + xs[n / 2]) / 2.0,
    }
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = std::time::Instant::now();
    let v = f();
    (v, t.elapsed().as_secs_f64())
}

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
    let lanes: [&dyn Lanes; 2] = [&Serial, &Two];

    let mut grown = KrrFactor::fit(&states[..b], &actions[..b], 2).expect("a factor");
    let mut times = Times::default();
    let mut same = true;
    let mut model = None;
    for i in b..b + r {
        let on = (i - b) % 2;
        let (pushed, s) = timed(|| grown.push_on(&states[i], actions[i], lanes[on]));
        pushed.expect("a new row");
        times.push[on].push(s);
        let models = lanes.map(|l| {
            let (m, s) = timed(|| grown.model_on(l));
            (m, s)
        });
        for (t, (_, s)) in times.model.iter_mut().zip(&models) {
            t.push(*s);
        }
        let [(one, _), (two, _)] = models;
        same &= one == two;
        model = Some(one);
    }
    let push = times.push.map(median);
    let solve = times.model.map(median);

    let (fitted, fit_s) = timed(|| {
        KrrFactor::fit(&states, &actions, 2)
            .expect("a factor")
            .model()
    });
    same &= model.as_ref() == Some(&fitted);
    println!(
        r#"{{"demos": {b}, "grown": {r}, "grow_s": {:.6}, "push_s": {:.6}, "model_s": {:.6}, "grow_2_s": {:.6}, "push_2_s": {:.6}, "model_2_s": {:.6}, "fit_s": {fit_s:.6}, "same_bits": {same}}}"#,
        push[0] + solve[0],
        push[0],
        solve[0],
        push[1] + solve[1],
        push[1],
        solve[1],
    );
}
