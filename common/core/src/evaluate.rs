//! Greedy evaluation and the Q-values a network takes on its own episodes: the `eval_return` of
//! an episode record, `alfd q-range`'s divergence check, and the returns of a demonstrator.

use crate::agent::neural::add_advice;
use crate::agent::{Demonstrator, NetworkDemonstrator};
use crate::demo_model::DemoModel;
use crate::env::{CartPole, CliffWalk, Env, EnvError, VectorEnv};
use crate::nn::Mlp;
use crate::query::mean_greedy;

/// Mean return of `episodes` episodes of `env` played greedily by `net` (on the mean of its
/// heads' Q-values), the first reset seeded with `seed`: the `eval_return` of a record.
pub fn evaluate_greedy(
    net: &Mlp,
    env: &mut VectorEnv,
    episodes: u32,
    seed: u64,
) -> Result<f64, EnvError> {
    Ok(q_range(net, env, episodes, seed)?.mean_return)
}

/// [`evaluate_greedy`] on the heads' `Q(s,a) + λ p(a|s)` when `advice` gives the demonstration
/// model and λ of look-ahead advice (`shaping.kind = "advice"`), as the actor acts.
pub fn evaluate_greedy_advised(
    net: &Mlp,
    advice: Option<(&DemoModel, f64)>,
    env: &mut VectorEnv,
    episodes: u32,
    seed: u64,
) -> Result<f64, EnvError> {
    let Some((model, lambda)) = advice else {
        return evaluate_greedy(net, env, episodes, seed);
    };
    let (mut q32, mut q) = (vec![0.0; net.outputs()], vec![0.0; net.outputs()]);
    let actions = net.actions();
    let returns = evaluate(env, episodes as usize, seed, |obs| {
        net.forward_one(obs, &mut q32);
        q.iter_mut().zip(&q32).for_each(|(v, &x)| *v = f64::from(x));
        add_advice(&mut q, actions, obs, model, lambda);
        mean_greedy(&q, net.heads())
    })?;
    Ok(returns.iter().sum::<f64>() / returns.len().max(1) as f64)
}

/// The Q-values a network takes on its own greedy episodes ([`q_range`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QRange {
    /// The smallest and the largest Q-value of any head and action at any state visited.
    pub min: f64,
    pub max: f64,
    /// The mean return of the episodes.
    pub mean_return: f64,
}

/// Plays `episodes` greedy episodes of `env` with `net` (on the mean of its heads), the first
/// reset seeded with `seed`: their mean return ([`evaluate_greedy`]) and the range of every
/// Q-value computed on the way, a check for divergence against [`value_bounds`].
pub fn q_range(
    net: &Mlp,
    env: &mut VectorEnv,
    episodes: u32,
    seed: u64,
) -> Result<QRange, EnvError> {
    let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut policy = NetworkDemonstrator::new(net.clone());
    let returns = evaluate(env, episodes as usize, seed, |obs| {
        let action = policy.act(obs);
        for &v in policy.last_q() {
            min = min.min(f64::from(v));
            max = max.max(f64::from(v));
        }
        action
    })?;
    Ok(QRange {
        min,
        max,
        mean_return: returns.iter().sum::<f64>() / returns.len().max(1) as f64,
    })
}

/// The range every true value lies in when each step's reward is in `[r_min, r_max]` and the
/// discount is `gamma < 1`: `[min(0, r_min), max(0, r_max)] / (1 - gamma)` (an episode may end
/// at any step, so 0 is always reachable). CartPole-1000 at γ = 0.995: `[0, 200]`.
pub fn value_bounds((r_min, r_max): (f64, f64), gamma: f64) -> (f64, f64) {
    (
        r_min.min(0.0) / (1.0 - gamma),
        r_max.max(0.0) / (1.0 - gamma),
    )
}

/// Returns of `episodes` episodes of `env` played by `act`, the first reset seeded with `seed`;
/// the environment's error if a step fails (one in another process that died, say).
pub fn evaluate<E: Env + ?Sized>(
    env: &mut E,
    episodes: usize,
    seed: u64,
    mut act: impl FnMut(&E::Observation) -> usize,
) -> Result<Vec<f64>, EnvError> {
    (0..episodes)
        .map(|i| {
            let mut obs = env.reset(if i == 0 { Some(seed) } else { None });
            let mut ret = 0.0;
            loop {
                let step = env.step(act(&obs))?;
                ret += step.reward;
                let done = step.done();
                obs = step.observation;
                if done {
                    return Ok(ret);
                }
            }
        })
        .collect()
}

/// Returns of `episodes` CartPole episodes (limit `max_steps`) played by `policy`.
pub fn evaluate_cartpole(
    policy: &mut dyn Demonstrator<[f32]>,
    episodes: usize,
    seed: u64,
    max_steps: usize,
) -> Vec<f64> {
    evaluate(&mut CartPole::new(max_steps), episodes, seed, |obs| {
        policy.act(obs)
    })
    .expect("the native CartPole steps every action of a live episode")
}

/// Returns of `episodes` CliffWalk episodes played by `policy` on a clone of `env`.
pub fn evaluate_cliffwalk(
    policy: &mut dyn Demonstrator<usize>,
    env: &CliffWalk,
    episodes: usize,
    seed: u64,
) -> Vec<f64> {
    evaluate(&mut env.clone(), episodes, seed, |s| policy.act(s))
        .expect("the native CliffWalk steps every action of a live episode")
}
