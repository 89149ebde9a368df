//! Checkpoints of single-process runs: every snapshot round-trips through the checkpoint format,
//! and a run resumed from any of its checkpoints is the uninterrupted run, record for record.

use std::ops::ControlFlow;

use alfd_common::agent::{BalancingController, NeuralLearner, TablePolicy};
use alfd_common::checkpoint::{config_hash, decode, encode};
use alfd_common::config::{EnvName, ExperimentConfig};
use alfd_common::env::cliffwalk::{value_iteration, CliffMap, CliffWalk};
use alfd_common::env::{vector_env_named, Env};
use alfd_common::record::{episodes_csv, EpisodeRecord};
use alfd_common::rng::seeded;
use alfd_common::runner::{
    run_neural, run_neural_checkpointed, run_tabular, run_tabular_checkpointed, Checkpoints,
    RunState,
};

fn cfg(name: &str, overrides: &[&str]) -> ExperimentConfig {
    let text = std::fs::read_to_string(format!(
        "{}/../../deploy/configs/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    ExperimentConfig::from_toml_with_overrides(&text, &o).unwrap()
}

fn round_trip(state: &RunState) -> RunState {
    let hash = config_hash("the config");
    let bytes = encode(state, hash);
    let back: RunState = decode(&bytes, hash).unwrap();
    // Bytes, not `==`: records hold NaN (no evaluation) and NaN != NaN.
    assert!(
        encode(&back, hash) == bytes,
        "a checkpoint decodes to the state it holds"
    );
    back
}

/// The records of a run resumed after episode `at` are the uninterrupted run's, to the byte.
fn same_records(resumed: &[EpisodeRecord], whole: &[EpisodeRecord], name: &str, at: u32) {
    assert_eq!(
        episodes_csv(resumed),
        episodes_csv(whole),
        "{name} resumed after episode {at}"
    );
}

#[test]
fn a_neural_run_resumed_from_any_checkpoint_is_the_uninterrupted_run() {
    let c = cfg(
        "cartpole-bdqn-krr",
        &[
            "episodes=12",
            "expert.name=cartpole-perfect",
            "agent.replay_capacity=300",
            "evaluation.every=5",
        ],
    );
    let whole = run_neural(&c, &mut BalancingController, |_, _| {
        ControlFlow::Continue(())
    });
    assert!(whole.expert.demos().len() > 10, "the expert was asked");
    let every = Checkpoints {
        from: None,
        every: Some(4),
    };
    let mut saved = Vec::new();
    let checkpointed = run_neural_checkpointed(
        &c,
        &mut BalancingController,
        every,
        |s| {
            saved.push(s.clone());
            ControlFlow::Continue(())
        },
        |_, _| ControlFlow::Continue(()),
    )
    .unwrap();
    assert_eq!(
        episodes_csv(&checkpointed.records),
        episodes_csv(&whole.records)
    );
    let at: Vec<u32> = saved.iter().map(|s| s.progress.episodes).collect();
    assert_eq!(at, [4, 8], "after every 4 episodes, not after the last");
    for s in saved {
        let RunState::Neural(s) = round_trip(&RunState::Neural(Box::new(s))) else {
            unreachable!()
        };
        assert_eq!(
            episodes_csv(&s.records),
            episodes_csv(&whole.records[..s.progress.episodes as usize])
        );
        let resumed = run_neural_checkpointed(
            &c,
            &mut BalancingController,
            Checkpoints {
                from: Some(&s),
                every: Some(4),
            },
            |_| ControlFlow::Continue(()),
            |_, _| ControlFlow::Continue(()),
        )
        .unwrap();
        same_records(&resumed.records, &whole.records, "", s.progress.episodes);
        assert!(resumed.network == whole.network, "the same weights");
        assert_eq!(resumed.expert.demos(), whole.expert.demos());
    }
}

#[test]
fn a_tabular_run_resumed_from_any_checkpoint_is_the_uninterrupted_run() {
    let env = CliffWalk::new(CliffMap::default_map(), 0.9, 500).unwrap();
    let optimal = TablePolicy {
        actions: value_iteration(&env, 0.99, 1e-10).unwrap().policy,
    };
    for name in ["cliffwalk-bootstrapped", "cliffwalk-sarsa"] {
        let c = cfg(name, &["episodes=30"]);
        let whole = run_tabular(&c, env.clone(), &mut optimal.clone(), |_, _| {
            ControlFlow::Continue(())
        });
        let mut saved = Vec::new();
        run_tabular_checkpointed(
            &c,
            env.clone(),
            (&mut optimal.clone(), Vec::new()),
            None,
            Checkpoints {
                from: None,
                every: Some(7),
            },
            |s| {
                saved.push(s.clone());
                ControlFlow::Break(()).then_if(saved.len() == 3)
            },
            |_, _| ControlFlow::Continue(()),
        )
        .unwrap();
        assert_eq!(saved.len(), 3, "{name}: `save` may stop the run");
        for s in saved {
            let RunState::Tabular(s) = round_trip(&RunState::Tabular(Box::new(s))) else {
                unreachable!()
            };
            let resumed = run_tabular_checkpointed(
                &c,
                env.clone(),
                (&mut optimal.clone(), Vec::new()),
                None,
                Checkpoints {
                    from: Some(&s),
                    every: None,
                },
                |_| ControlFlow::Continue(()),
                |_, _| ControlFlow::Continue(()),
            )
            .unwrap();
            same_records(&resumed.records, &whole.records, name, s.progress.episodes);
            assert!(resumed.agent.q() == whole.agent.q(), "the same Q-tables");
        }
    }
}

/// `Break(())` when `cond`, else `Continue(())`.
trait ThenIf {
    fn then_if(self, cond: bool) -> Self;
}

impl ThenIf for ControlFlow<()> {
    fn then_if(self, cond: bool) -> Self {
        if cond {
            self
        } else {
            ControlFlow::Continue(())
        }
    }
}

#[test]
fn every_environment_continues_exactly_from_its_snapshot_mid_episode() {
    for name in [EnvName::Cartpole, EnvName::Mountaincar, EnvName::Acrobot] {
        let mut env = vector_env_named(name, 50).unwrap();
        env.reset(Some(9));
        for i in 0..7 {
            env.step(i % env.num_actions()).unwrap();
        }
        let saved = env.snapshot();
        let bytes = postcard::to_stdvec(&saved).unwrap();
        let mut copy = vector_env_named(name, 50).unwrap();
        copy.restore(&postcard::from_bytes(&bytes).unwrap())
            .unwrap();
        for i in 0..100 {
            let a = (i * 7 + 1) % env.num_actions();
            let (x, y) = (env.step(a), copy.step(a));
            assert_eq!(x, y, "{name:?} step {i}");
            if x.as_ref().is_ok_and(|s| s.done()) {
                assert_eq!(
                    env.reset(None),
                    copy.reset(None),
                    "{name:?}: the next reset too"
                );
            }
        }
        let mut other = vector_env_named(name, 50).unwrap();
        let mut wrong = saved.clone();
        wrong.state.push(0.0);
        assert!(other.restore(&wrong).is_err(), "{name:?}: another size");
    }
    let mut env = CliffWalk::new(CliffMap::default_map(), 0.9, 500).unwrap();
    env.reset(Some(4));
    env.step(0).unwrap();
    let saved = env.snapshot();
    let mut copy = CliffWalk::new(CliffMap::default_map(), 0.9, 500).unwrap();
    copy.restore(&saved).unwrap();
    for i in 0..40 {
        assert_eq!(env.step(i % 4), copy.step(i % 4));
    }
    let mut off_map = saved.clone();
    off_map.state = vec![1e6];
    assert!(copy.restore(&off_map).is_err());
}

#[test]
fn a_learner_snapshot_round_trips_and_refuses_another_shape() {
    let c = cfg("cartpole-bdqn-krr", &["agent.batch_size=8"]);
    let mut learner = NeuralLearner::new(&c.agent, 4, 2, seeded(1));
    let mut env = vector_env_named(EnvName::Cartpole, 500).unwrap();
    let mut obs = env.reset(Some(1));
    for i in 0..40 {
        let step = env.step(i % 2).unwrap();
        let t = alfd_common::replay::Transition {
            state: obs.clone(),
            action: (i % 2) as u32,
            reward: 1.0,
            next_state: step.observation.clone(),
            terminated: step.terminated,
            mask: vec![1.0, 0.0],
            demo: i % 5 == 0,
            horizon: 1,
        };
        learner.learn(&t);
        obs = if step.done() {
            env.reset(None)
        } else {
            step.observation
        };
    }
    assert!(learner.updates() > 0);
    let s = learner.snapshot();
    let back: alfd_common::agent::LearnerSnapshot =
        postcard::from_bytes(&postcard::to_stdvec(&s).unwrap()).unwrap();
    assert_eq!(back, s);
    let mut fresh = NeuralLearner::new(&c.agent, 4, 2, seeded(2));
    fresh.restore(&back).unwrap();
    assert_eq!(fresh.snapshot(), s);
    let (mut a, mut b) = (learner.clone(), fresh);
    for _ in 0..5 {
        assert_eq!(a.update(), b.update(), "the same batches, the same updates");
    }
    assert_eq!(a.network(), b.network());

    let small = cfg("cartpole-bdqn-krr", &["agent.replay_capacity=100"]);
    let mut other = NeuralLearner::new(&small.agent, 4, 2, seeded(2));
    let e = other.restore(&s).unwrap_err();
    assert!(e.to_string().contains("replay buffer"), "{e}");
}
