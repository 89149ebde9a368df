//! CartPole against trajectories recorded from Gymnasium 1.4.0 CartPole-v1 (limit 1000 steps):
//! every float64 state after every step to 1e-9, the rewards and both end flags.

use alfd_common::env::{CartPole, Env, EnvError};
use serde::Deserialize;

#[derive(Debug, Deserialize)]
struct Fixture {
    trajectories: Vec<Trajectory>,
}

#[derive(Debug, Deserialize)]
struct Trajectory {
    initial_state: [f64; 4],
    actions: Vec<usize>,
    states: Vec<[f64; 4]>,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
}

fn fixture() -> Fixture {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/cartpole_trajectories.json"
    );
    let text = std::fs::read_to_string(path).expect("fixture readable");
    serde_json::from_str(&text).expect("fixture parses")
}

#[test]
fn cartpole_matches_gymnasium_trajectories() {
    let fixture = fixture();
    assert_eq!(fixture.trajectories.len(), 6);
    let mut saw_truncation = false;
    let mut saw_termination = false;
    let mut total_steps = 0;
    let mut max_err: f64 = 0.0;
    for (i, t) in fixture.trajectories.iter().enumerate() {
        let n = t.actions.len();
        assert_eq!((t.states.len(), t.rewards.len()), (n, n));
        assert_eq!((t.terminated.len(), t.truncated.len()), (n, n));
        let mut env = CartPole::new(1000);
        env.set_state(t.initial_state);
        for (k, &action) in t.actions.iter().enumerate() {
            let step = env.step(action).expect("the episode is still running");
            let got = env.state();
            for (j, (ours, theirs)) in got.iter().zip(&t.states[k]).enumerate() {
                let err = (ours - theirs).abs();
                max_err = max_err.max(err);
                assert!(
                    err <= 1e-9,
                    "trajectory {i} step {k} value {j}: {ours} vs gymnasium {theirs} (error {err:e})"
                );
            }
            assert_eq!(step.observation, got.map(|v| v as f32));
            assert_eq!(step.reward, t.rewards[k], "trajectory {i} step {k} reward");
            assert_eq!(
                step.terminated, t.terminated[k],
                "trajectory {i} step {k} terminated"
            );
            assert_eq!(
                step.truncated, t.truncated[k],
                "trajectory {i} step {k} truncated"
            );
        }
        assert!(
            t.terminated[n - 1] || t.truncated[n - 1],
            "trajectory {i} ends"
        );
        assert_eq!(env.step(0), Err(EnvError::EpisodeOver));
        saw_truncation |= t.truncated[n - 1];
        saw_termination |= t.terminated[n - 1];
        total_steps += n;
    }
    assert!(saw_truncation && saw_termination);
    // Below 1e-15 in practice; the remainder is serde_json's parsing of the fixture (its
    // default float parser can be 1 ulp off), the CLI reproduces the fixture bit for bit.
    eprintln!("largest deviation from gymnasium over {total_steps} steps: {max_err:e}");
    assert_eq!(total_steps, 13 + 746 + 11 + 39 + 1000 + 10);
}
