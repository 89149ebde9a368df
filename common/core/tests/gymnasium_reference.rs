//! The classic-control environments against trajectories recorded from Gymnasium 1.4.0
//! (CartPole-v1 with a 1000-step limit, MountainCar-v0, Acrobot-v1): from each recorded initial
//! state, every float64 state after every step to 1e-9, the observation made of it, the rewards
//! and both end flags.

use alfd_common::env::{Acrobot, CartPole, Env, EnvError, MountainCar};
use serde::Deserialize;

#[derive(Debug, Deserialize)]
struct Fixture {
    trajectories: Vec<Trajectory>,
}

#[derive(Debug, Deserialize)]
struct Trajectory {
    initial_state: Vec<f64>,
    actions: Vec<usize>,
    states: Vec<Vec<f64>>,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
}

/// How to replay a fixture on one environment.
struct Replay<E: Env, const N: usize> {
    file: &'static str,
    make: fn() -> E,
    set_state: fn(&mut E, [f64; N]),
    state: fn(&E) -> [f64; N],
    observe: fn(&[f64; N]) -> E::Observation,
}

fn fixture(file: &str) -> Fixture {
    let path = format!("{}/tests/data/{file}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("fixture readable");
    serde_json::from_str(&text).expect("fixture parses")
}

fn state<const N: usize>(values: &[f64], what: &str) -> [f64; N] {
    values
        .try_into()
        .unwrap_or_else(|_| panic!("{what}: {} values, expected {N}", values.len()))
}

/// Replays every trajectory of the fixture; returns the episode lengths and the largest
/// deviation from Gymnasium's states. Both end flags must occur among the trajectories.
fn replay<E: Env, const N: usize>(r: &Replay<E, N>) -> (Vec<usize>, f64)
where
    E::Observation: PartialEq,
{
    let fixture = fixture(r.file);
    let (mut saw_truncation, mut saw_termination) = (false, false);
    let mut lengths = Vec::new();
    let mut max_err: f64 = 0.0;
    for (i, t) in fixture.trajectories.iter().enumerate() {
        let n = t.actions.len();
        assert_eq!((t.states.len(), t.rewards.len()), (n, n));
        assert_eq!((t.terminated.len(), t.truncated.len()), (n, n));
        let mut env = (r.make)();
        (r.set_state)(&mut env, state(&t.initial_state, "initial state"));
        for (k, &action) in t.actions.iter().enumerate() {
            let step = env.step(action).expect("the episode is still running");
            let got = (r.state)(&env);
            let theirs: [f64; N] = state(&t.states[k], "state");
            for (j, (ours, theirs)) in got.iter().zip(&theirs).enumerate() {
                let err = (ours - theirs).abs();
                max_err = max_err.max(err);
                assert!(
                    err <= 1e-9,
                    "{} trajectory {i} step {k} value {j}: {ours} vs gymnasium {theirs} (error {err:e})",
                    r.file
                );
            }
            assert_eq!(step.observation, (r.observe)(&got));
            let at = format!("{} trajectory {i} step {k}", r.file);
            assert_eq!(step.reward, t.rewards[k], "{at} reward");
            assert_eq!(step.terminated, t.terminated[k], "{at} terminated");
            assert_eq!(step.truncated, t.truncated[k], "{at} truncated");
        }
        assert!(
            t.terminated[n - 1] || t.truncated[n - 1],
            "trajectory {i} ends"
        );
        assert_eq!(env.step(0), Err(EnvError::EpisodeOver));
        saw_truncation |= t.truncated[n - 1];
        saw_termination |= t.terminated[n - 1];
        lengths.push(n);
    }
    assert!(saw_truncation && saw_termination, "{}", r.file);
    let total: usize = lengths.iter().sum();
    eprintln!(
        "{}: largest deviation from gymnasium over {total} steps: {max_err:e}",
        r.file
    );
    (lengths, max_err)
}

#[test]
fn cartpole_matches_gymnasium_trajectories() {
    let (lengths, max_err) = replay(&Replay {
        file: "cartpole_trajectories.json",
        make: || CartPole::new(1000),
        set_state: CartPole::set_state,
        state: CartPole::state,
        observe: |s| s.map(|v| v as f32),
    });
    // Below 1e-15 in practice; the remainder is serde_json's parsing of the fixture (its
    // default float parser can be 1 ulp off), the CLI reproduces the fixture bit for bit.
    assert!(max_err < 1e-12, "{max_err:e}");
    assert_eq!(lengths, [13, 746, 11, 39, 1000, 10]);
}

#[test]
fn mountaincar_matches_gymnasium_trajectories() {
    let (lengths, max_err) = replay(&Replay {
        file: "mountaincar_trajectories.json",
        make: MountainCar::default,
        set_state: MountainCar::set_state,
        state: MountainCar::state,
        observe: |s| s.map(|v| v as f32),
    });
    assert!(max_err < 1e-12, "{max_err:e}");
    // Random and constant policies never reach the flag; energy pumping does, in 122 steps.
    assert_eq!(lengths, [200, 122, 200, 200, 122, 200]);
}

#[test]
fn acrobot_matches_gymnasium_trajectories() {
    let (lengths, max_err) = replay(&Replay {
        file: "acrobot_trajectories.json",
        make: Acrobot::default,
        set_state: Acrobot::set_state,
        state: Acrobot::state,
        observe: Acrobot::observe,
    });
    // Below 1e-14 in practice (RK4 over chaotic swings for 500 steps): well within 1e-9.
    assert!(max_err <= 1e-9, "{max_err:e}");
    // Random and constant torques stay below the bar for 500 steps; the swing-up gets there.
    assert_eq!(lengths, [500, 109, 500, 500, 91, 500]);
}
