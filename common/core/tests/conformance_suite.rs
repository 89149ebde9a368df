//! The conformance suite of the `Env` trait, written once: seeding determinism, `reset(None)`
//! continuing the generator (or, for an environment that draws nothing, the same trajectory
//! whatever the seed), the action space, truncation at the step limit, termination (always
//! exercised, by a policy that reaches a terminal state), no step after the end and no step
//! before the first reset. Run on every built-in environment (`env_conformance.rs`) and on a
//! Gymnasium environment through the Python adapter (`deploy/cli/tests/gymnasium.rs`, which includes
//! this file).

use alfd_common::env::{Env, EnvError, Step};

/// The initial observation, then every step until the episode ends or `max_steps` steps.
pub type Trajectory<O> = (O, Vec<Step<O>>);

pub fn run_episode<E: Env>(
    env: &mut E,
    seed: Option<u64>,
    action_at: &impl Fn(usize) -> usize,
    max_steps: usize,
) -> Trajectory<E::Observation> {
    let first = env.reset(seed);
    let mut steps = Vec::new();
    for i in 0..max_steps {
        let step = env
            .step(action_at(i))
            .expect("valid action in a running episode");
        let done = step.done();
        steps.push(step);
        if done {
            break;
        }
    }
    (first, steps)
}

/// Runs the whole suite on the environment built by `make(max_episode_steps)`.
///
/// `action_at(i)` is the action at step `i` of an episode; with a step limit of 5 it must not
/// reach a terminal state, so that the limit is what ends the episode. `reach` is a policy that
/// does reach a terminal state within 200 steps from the initial state of some seed in `0..20`.
pub fn conformance<E: Env>(
    name: &str,
    make: impl Fn(usize) -> E,
    num_actions: usize,
    action_at: impl Fn(usize) -> usize,
    reach: impl Fn(&E::Observation) -> usize,
) where
    E::Observation: PartialEq,
{
    conformance_with(name, make, num_actions, action_at, reach, true);
}

/// [`conformance`], for an environment whose episodes depend on the seed of `reset`
/// (`seed_matters`: another seed gives another trajectory, `reset(None)` continues the
/// generator into another episode) or do not (a deterministic one, such as DeepSea: every seed
/// and every `reset(None)` give the same trajectory for the same actions).
pub fn conformance_with<E: Env>(
    name: &str,
    make: impl Fn(usize) -> E,
    num_actions: usize,
    action_at: impl Fn(usize) -> usize,
    reach: impl Fn(&E::Observation) -> usize,
    seed_matters: bool,
) where
    E::Observation: PartialEq,
{
    let long = 200;
    // What a change of seed must do to a trajectory.
    let another_seed = |x: &Trajectory<E::Observation>, y: &Trajectory<E::Observation>, what| {
        if seed_matters {
            assert_ne!(x, y, "{name}: {what}");
        } else {
            assert_eq!(x, y, "{name}: deterministic, whatever the seed: {what}");
        }
    };

    // Seeding determinism: same seed and actions => same trajectory; another seed differs.
    let a = run_episode(&mut make(long), Some(7), &action_at, long);
    let b = run_episode(&mut make(long), Some(7), &action_at, long);
    let c = run_episode(&mut make(long), Some(8), &action_at, long);
    assert!(
        a.1.len() >= 5,
        "{name}: the seeded episode is long enough to compare"
    );
    assert_eq!(a, b, "{name}: same seed, same actions, same trajectory");
    another_seed(&a, &c, "another seed gives another trajectory");

    // A fresh environment behaves as if seeded with 0.
    let unseeded = run_episode(&mut make(long), None, &action_at, long);
    let zero = run_episode(&mut make(long), Some(0), &action_at, long);
    assert_eq!(
        unseeded, zero,
        "{name}: a never-seeded environment uses seed 0"
    );

    // reset(None) continues the generator: the second episode is reproducible from the first
    // seed, and is not a replay of the first episode.
    let mut env = make(long);
    let first = run_episode(&mut env, Some(7), &action_at, long);
    let second = run_episode(&mut env, None, &action_at, long);
    let mut again = make(long);
    run_episode(&mut again, Some(7), &action_at, long);
    assert_eq!(first, a, "{name}");
    assert_eq!(
        second,
        run_episode(&mut again, None, &action_at, long),
        "{name}"
    );
    another_seed(&second, &first, "reset(None) does not reseed");
    let mut other = make(long);
    run_episode(&mut other, Some(8), &action_at, long);
    let other_second = run_episode(&mut other, None, &action_at, long);
    another_seed(
        &second,
        &other_second,
        "after reset(None) the episode still depends on the earlier seed",
    );

    // Action space: out-of-range actions are errors and change nothing.
    let mut env = make(long);
    assert_eq!(env.num_actions(), num_actions, "{name}");
    let start = env.reset(Some(7));
    assert_eq!(start, a.0, "{name}");
    for bad in [num_actions, num_actions + 1, usize::MAX] {
        assert_eq!(
            env.step(bad),
            Err(EnvError::InvalidAction {
                action: bad,
                num_actions
            }),
            "{name}: action {bad}"
        );
    }
    for (i, expected) in a.1.iter().enumerate() {
        assert_eq!(
            &env.step(action_at(i)).expect("running"),
            expected,
            "{name}: step {i}"
        );
        if i == 0 {
            assert!(env.step(num_actions).is_err(), "{name}");
        }
    }

    // Truncation at the limit, never reported as termination, and no step after the end.
    let mut env = make(5);
    assert_eq!(env.max_episode_steps(), 5, "{name}");
    for seed in [1, 2, 3] {
        env.reset(Some(seed));
        for i in 0..5 {
            let step = env.step(action_at(i)).expect("running");
            assert!(
                !step.terminated,
                "{name}: seed {seed} step {i} must not terminate"
            );
            assert_eq!(step.truncated, i == 4, "{name}: seed {seed} step {i}");
        }
        for action in 0..num_actions {
            assert_eq!(env.step(action), Err(EnvError::EpisodeOver), "{name}");
        }
        assert_eq!(env.step(num_actions), Err(EnvError::EpisodeOver), "{name}");
    }
    // Termination, found deterministically: the first seed from which `reach` ends an episode
    // with `terminated` before the limit. The same seed terminates at the same step again, the
    // environment refuses steps after it, and a reset starts a new episode.
    let terminating = |env: &mut E, seed: u64| -> Option<(usize, Step<E::Observation>)> {
        let mut obs = env.reset(Some(seed));
        for i in 0..long {
            let step = env.step(reach(&obs)).expect("running");
            if step.done() {
                return step.terminated.then_some((i, step));
            }
            obs = step.observation;
        }
        unreachable!("{name}: the limit ends every episode")
    };
    let mut env = make(long);
    let (seed, (at, step)) = (0..20)
        .find_map(|seed| terminating(&mut env, seed).map(|found| (seed, found)))
        .unwrap_or_else(|| panic!("{name}: `reach` terminated no episode of seeds 0..20"));
    assert!(!step.truncated && at + 1 < long, "{name}: seed {seed}");
    for action in 0..num_actions {
        assert_eq!(env.step(action), Err(EnvError::EpisodeOver), "{name}");
    }
    assert_eq!(
        terminating(&mut make(long), seed),
        Some((at, step)),
        "{name}: seed {seed}"
    );
    env.reset(None);
    assert!(env.step(action_at(0)).is_ok(), "{name}");

    // A limit of 1 truncates the first step.
    let mut env = make(1);
    env.reset(Some(4));
    assert!(env.step(action_at(0)).expect("running").truncated, "{name}");

    // No step before the first reset.
    let mut env = make(5);
    assert_eq!(env.step(0), Err(EnvError::NotReset), "{name}");
    assert_eq!(env.step(num_actions), Err(EnvError::NotReset), "{name}");
}
