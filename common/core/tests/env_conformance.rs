//! The conformance suite of the `Env` trait (`conformance_suite.rs`) run on every built-in
//! environment.

use alfd_common::env::cliffwalk::{value_iteration, CliffMap, CliffWalk};
use alfd_common::env::{Acrobot, CartPole, DeepSea, MountainCar};

use crate::conformance_suite::{conformance, conformance_with};

#[test]
fn cartpole_conforms() {
    // Alternating pushes keep the pole up for far more than 5 steps; always pushing left drops
    // it.
    conformance("cartpole", CartPole::new, 2, |i| i % 2, |_| 0);
}

#[test]
fn mountaincar_conforms() {
    // No sequence of 5 actions reaches the flag; pushing along the velocity does (energy pumping).
    conformance(
        "mountaincar",
        MountainCar::new,
        3,
        |i| i % 3,
        |obs| if obs[1] >= 0.0 { 2 } else { 0 },
    );
}

#[test]
fn acrobot_conforms() {
    // 5 steps cannot lift the tip from hanging; torque against the first link's swing pumps
    // energy into it until the tip clears the bar.
    conformance(
        "acrobot",
        Acrobot::new,
        3,
        |i| i % 3,
        |obs| if obs[4] > 0.0 { 0 } else { 2 },
    );
}

/// The optimal policy of a CliffWalk (it reaches the goal, the only terminal state).
fn optimal(map: &CliffMap) -> impl Fn(&usize) -> usize {
    let env = CliffWalk::new(map.clone(), 0.9, 200).expect("valid parameters");
    let policy = value_iteration(&env, 0.99, 1e-10)
        .expect("valid gamma")
        .policy;
    move |&s| policy[s]
}

#[test]
fn cliffwalk_conforms() {
    // The goal is 9 moves from the start: out of reach within a limit of 5.
    let map = CliffMap::parse("..........\nS........G\n..........\n").expect("valid map");
    conformance(
        "cliffwalk",
        |limit| CliffWalk::new(map.clone(), 0.9, limit).expect("valid parameters"),
        4,
        |i| if i % 3 == 2 { 0 } else { 1 },
        optimal(&map),
    );
}

#[test]
fn cliffwalk_conforms_on_the_default_map() {
    // From S on the default map, up-up-right-right-... stays off the goal for 5 steps.
    conformance(
        "cliffwalk-default",
        |limit| CliffWalk::new(CliffMap::default_map(), 0.9, limit).expect("valid parameters"),
        4,
        |i| if i < 2 { 0 } else { 1 },
        optimal(&CliffMap::default_map()),
    );
}

#[test]
fn deepsea_conforms_as_a_deterministic_environment() {
    // Every episode of DeepSea(10) ends at its 10th step, after more than 5; the limit of 200
    // never cuts one. Nothing is drawn, so every seed gives the same trajectory.
    let make = |limit| DeepSea::with_max_episode_steps(10, 42, limit).expect("valid size");
    let map = make(10);
    let reach = move |obs: &Vec<f32>| map.optimal_action_for(obs).expect("a cell");
    let seed_matters = false;
    conformance_with("deepsea", make, 2, |i| i % 2, reach, seed_matters);
}
