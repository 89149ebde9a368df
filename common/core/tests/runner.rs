//! The single-process runner end to end: determinism, the budget, the query modes, shaping, and
//! the tabular study's yardstick (Q-learning's greedy policy against value iteration).

use std::ops::ControlFlow;

use alfd_common::agent::{BalancingController, TablePolicy};
use alfd_common::config::ExperimentConfig;
use alfd_common::env::cliffwalk::{policy_evaluation, value_iteration, CliffMap, CliffWalk};
use alfd_common::record::episodes_csv;
use alfd_common::runner::{run_neural, run_tabular};

fn config(name: &str) -> String {
    std::fs::read_to_string(format!(
        "{}/../../deploy/configs/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
}

fn cfg(name: &str, overrides: &[&str]) -> ExperimentConfig {
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    ExperimentConfig::from_toml_with_overrides(&config(name), &o).unwrap()
}

fn cliffwalk() -> CliffWalk {
    CliffWalk::new(CliffMap::default_map(), 0.9, 500).unwrap()
}

fn optimal(env: &CliffWalk) -> TablePolicy {
    TablePolicy {
        actions: value_iteration(env, 0.99, 1e-10).unwrap().policy,
    }
}

#[test]
fn tabular_runs_are_byte_identical_for_one_seed_and_differ_across_seeds() {
    let env = cliffwalk();
    let run = |seed: &str| {
        let c = cfg("cliffwalk-bootstrapped", &[seed, "episodes=200"]);
        episodes_csv(
            &run_tabular(&c, env.clone(), &mut optimal(&env), |_, _| {
                ControlFlow::Continue(())
            })
            .records,
        )
    };
    let a = run("seed=3");
    assert_eq!(a, run("seed=3"));
    assert_ne!(a, run("seed=4"));
    assert_eq!(a.lines().count(), 201);
    assert!(a.starts_with("episode,return,length,demos_used,mean_js"));
}

#[test]
fn neural_runs_are_byte_identical_for_one_seed() {
    let run = |seed: &str| {
        let c = cfg(
            "cartpole-bdqn-krr",
            &[seed, "episodes=15", "expert.name=cartpole-perfect"],
        );
        episodes_csv(
            &run_neural(&c, &mut BalancingController, |_, _| {
                ControlFlow::Continue(())
            })
            .records,
        )
    };
    let a = run("seed=5");
    assert_eq!(a, run("seed=5"));
    assert_ne!(a, run("seed=6"));
}

#[test]
fn qlearning_greedy_policy_reaches_the_value_iteration_optimum_within_5_percent() {
    let env = cliffwalk();
    let v_star = value_iteration(&env, 0.99, 1e-10).unwrap().values[env.map().start()];
    let mut values = Vec::new();
    for seed in 0..10 {
        let c = cfg("cliffwalk-qlearning", &[&format!("seed={seed}")]);
        let run = run_tabular(&c, env.clone(), &mut optimal(&env), |_, _| {
            ControlFlow::Continue(())
        });
        values.push(policy_evaluation(&env, &run.greedy_policy, 0.99).unwrap()[env.map().start()]);
    }
    for (seed, v) in values.iter().enumerate() {
        assert!(
            (v - v_star).abs() <= 0.05 * v_star.abs(),
            "seed {seed}: V(S) = {v}, V*(S) = {v_star}"
        );
    }
}

#[test]
fn demos_first_spends_the_whole_budget_at_the_start_and_never_more() {
    let env = cliffwalk();
    let c = cfg("cliffwalk-qlearning-demos-first", &["episodes=50"]);
    let run = run_tabular(&c, env.clone(), &mut optimal(&env), |_, _| {
        ControlFlow::Continue(())
    });
    // The optimal expert reaches the goal in ~20 steps, so the 100 demonstrations span the first
    // few episodes, all of whose steps are demonstrations.
    let mut spent = 0;
    for r in &run.records {
        if spent < 100 {
            assert_eq!(
                r.queries,
                r.length.min(100 - spent),
                "episode {}",
                r.episode
            );
        } else {
            assert_eq!(r.queries, 0);
        }
        spent += r.queries;
        assert_eq!(r.demos_used, spent);
    }
    assert_eq!(spent, 100);
}

#[test]
fn active_queries_respect_the_budget_and_fire_on_divergence() {
    let env = cliffwalk();
    for budget in [0, 7, 100] {
        let c = cfg(
            "cliffwalk-bootstrapped",
            &[&format!("budget.total={budget}"), "episodes=300"],
        );
        let run = run_tabular(&c, env.clone(), &mut optimal(&env), |_, _| {
            ControlFlow::Continue(())
        });
        let used = run.records.last().unwrap().demos_used;
        let queries: u32 = run.records.iter().map(|r| r.queries).sum();
        assert_eq!(used, queries);
        assert!(used <= budget, "{used} > {budget}");
        if budget > 0 {
            assert_eq!(
                used, budget,
                "the divergence of two heads fires the rule within 300 episodes"
            );
        }
        assert!(run.records.iter().any(|r| r.mean_js > 0.0));
    }
    // Never mode never asks.
    let c = cfg("cliffwalk-qlearning", &["episodes=50"]);
    let run = run_tabular(&c, env.clone(), &mut optimal(&env), |_, _| {
        ControlFlow::Continue(())
    });
    assert_eq!(run.records.last().unwrap().demos_used, 0);
}

#[test]
fn shaping_changes_the_learned_reward_but_not_the_reported_return() {
    let c = cfg(
        "cartpole-bdqn-krr",
        &["episodes=40", "expert.name=cartpole-perfect", "seed=1"],
    );
    let run = run_neural(&c, &mut BalancingController, |_, _| {
        ControlFlow::Continue(())
    });
    let shaped: u32 = run.records.iter().map(|r| r.shaped_steps).sum();
    assert!(
        shaped > 0,
        "shaping should start once min_demos demonstrations exist"
    );
    for r in &run.records {
        // CartPole pays +1 per step: the reported return is the length, never the shaped sum.
        assert_eq!(r.ret, f64::from(r.length));
    }
    let demos = run.expert.demos();
    assert_eq!(demos.len() as u32, run.records.last().unwrap().demos_used);
    assert!(demos.len() <= 100);
    // Without a model there is no shaping at all.
    let c = cfg(
        "cartpole-bdqn",
        &["episodes=20", "expert.name=cartpole-perfect"],
    );
    let run = run_neural(&c, &mut BalancingController, |_, _| {
        ControlFlow::Continue(())
    });
    assert_eq!(run.records.iter().map(|r| r.shaped_steps).sum::<u32>(), 0);
}

#[test]
fn shaping_runs_from_min_demos_until_twice_the_last_demonstration_step() {
    // The expert answers steps 0..12 (budget 12, every step until spent). Shaping starts at step 9
    // (the 10th demonstration) and stops at 2 x 11 = 22: exactly steps 9..=21 are shaped.
    let c = cfg(
        "cartpole-bdqn-krr",
        &[
            "episodes=30",
            "expert.name=cartpole-perfect",
            "query.rule=first",
            "budget.total=12",
            "seed=2",
        ],
    );
    let run = run_neural(&c, &mut BalancingController, |_, _| {
        ControlFlow::Continue(())
    });
    assert_eq!(run.expert.demos().len(), 12);
    assert_eq!(run.expert.last_demo_step(), 11);
    assert!(run.records.last().unwrap().total_steps > 22);
    assert_eq!(run.records.iter().map(|r| r.shaped_steps).sum::<u32>(), 13);
}

#[test]
fn dqn_demos_first_uses_the_expert_for_the_first_b_steps() {
    let c = cfg(
        "cartpole-dqn-demos-first",
        &["episodes=5", "expert.name=cartpole-perfect"],
    );
    let run = run_neural(&c, &mut BalancingController, |_, _| {
        ControlFlow::Continue(())
    });
    // The perfect controller balances, so the first episode lasts at least the 100 demonstrated steps.
    assert_eq!(run.records[0].queries, 100);
    assert!(run.records[0].length >= 100);
    assert_eq!(run.records.iter().map(|r| r.queries).sum::<u32>(), 100);
}

#[test]
fn single_head_never_queries_because_one_head_has_no_divergence() {
    let c = cfg(
        "cartpole-bdqn-single-head",
        &["episodes=10", "expert.name=cartpole-perfect"],
    );
    let run = run_neural(&c, &mut BalancingController, |_, _| {
        ControlFlow::Continue(())
    });
    assert!(run
        .records
        .iter()
        .all(|r| r.mean_js == 0.0 && r.queries == 0));
}

/// `q_range` sees every Q-value of the greedy episodes: with zero weights and output biases
/// (3, 250) for head 0 and (−7, 1) for head 1, every Q-value is one of those four, so the range
/// is [−7, 250]; the heads' mean (−2, 125.5) always picks action 1, which CartPole plays to a
/// fall; `value_bounds` gives CartPole-1000's [0, 200] at γ = 0.995.
#[test]
fn q_range_reports_every_q_value_of_the_greedy_episodes() {
    use alfd_common::config::EnvName;
    use alfd_common::env::vector_env_named;
    use alfd_common::evaluate::{evaluate_greedy, q_range, value_bounds};
    use alfd_common::nn::{Mlp, Params};

    let mut params = Params::zeros(4, 8, 4);
    params
        .bh
        .as_mut_slice()
        .copy_from_slice(&[3.0, 250.0, -7.0, 1.0]);
    let net = Mlp::from_params(params, 2, 2).unwrap();
    let mut env = vector_env_named(EnvName::Cartpole, 1000).unwrap();
    let r = q_range(&net, env.as_mut(), 2, 5).unwrap();
    assert_eq!((r.min, r.max), (-7.0, 250.0));
    let mut env = vector_env_named(EnvName::Cartpole, 1000).unwrap();
    assert_eq!(
        r.mean_return,
        evaluate_greedy(&net, env.as_mut(), 2, 5).unwrap()
    );
    assert!(
        r.mean_return < 20.0,
        "always pushing right falls: {}",
        r.mean_return
    );
    let (lo, hi) = value_bounds(EnvName::Cartpole.reward_range().unwrap(), 0.995);
    assert_eq!(lo, 0.0);
    assert!((hi - 200.0).abs() < 1e-9, "{hi}");
    let (lo, hi) = value_bounds(EnvName::Acrobot.reward_range().unwrap(), 0.99);
    assert!((lo + 100.0).abs() < 1e-9 && hi == 0.0, "[{lo}, {hi}]");
    assert_eq!(EnvName::Gymnasium.reward_range(), None);
}
