//! The single-process runner: one experiment config, the whole loop of Algorithm 1 in one process,
//! deterministic from the config's seed. It returns the episode records; writing them is the
//! caller's business ([`episodes_csv`] formats them).

use std::ops::ControlFlow;

use crate::agent::{
    query_decision, Demonstrator, ExpertCore, NeuralActor, NeuralLearner, TabularAgent,
};
use crate::config::{ExperimentConfig, QueryMode};
use crate::env::{CartPole, CliffWalk, Env};
use crate::nn::Mlp;
use crate::query::QueryRule;
use crate::rng::{derive_seed, seeded};

/// One training episode, as `episodes.csv` records it.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRecord {
    /// 0-based episode index.
    pub episode: u32,
    /// The environment's undiscounted return (never the shaped one).
    pub ret: f64,
    pub length: u32,
    /// Demonstrations used so far in the run (cumulative).
    pub demos_used: u32,
    /// Mean JS divergence over the episode's steps (0 with one head).
    pub mean_js: f64,
    /// Queries answered during this episode.
    pub queries: u32,
    /// Steps whose reward was shaped during this episode.
    pub shaped_steps: u32,
    /// Global environment steps at the end of the episode.
    pub total_steps: u64,
}

/// The header of `episodes.csv`.
pub const CSV_HEADER: &str =
    "episode,return,length,demos_used,mean_js,queries,shaped_steps,total_steps";

impl EpisodeRecord {
    /// One CSV row (no newline); floats in Rust's shortest round-trip form, so rows are
    /// byte-identical for identical runs.
    pub fn csv_row(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{}",
            self.episode,
            self.ret,
            self.length,
            self.demos_used,
            self.mean_js,
            self.queries,
            self.shaped_steps,
            self.total_steps
        )
    }
}

/// `episodes.csv` as text.
pub fn episodes_csv(records: &[EpisodeRecord]) -> String {
    let mut out = String::with_capacity(64 * (records.len() + 1));
    out.push_str(CSV_HEADER);
    out.push('\n');
    for r in records {
        out.push_str(&r.csv_row());
        out.push('\n');
    }
    out
}

/// What a tabular run leaves behind.
#[derive(Debug, Clone)]
pub struct TabularRun {
    pub records: Vec<EpisodeRecord>,
    /// The greedy policy learned (mean over heads).
    pub greedy_policy: Vec<usize>,
    pub agent: TabularAgent,
}

/// What a neural run leaves behind.
#[derive(Debug, Clone)]
pub struct NeuralRun {
    pub records: Vec<EpisodeRecord>,
    pub network: Mlp,
    pub expert: ExpertCore,
}

/// Runs a tabular experiment (CliffWalk) on `env` with `demonstrator` as the expert.
/// `on_episode` sees each record and the agent as each episode completes (progress, evaluation)
/// and may stop the run early with `ControlFlow::Break`.
pub fn run_tabular(
    cfg: &ExperimentConfig,
    mut env: CliffWalk,
    demonstrator: &mut dyn Demonstrator<usize>,
    mut on_episode: impl FnMut(&EpisodeRecord, &TabularAgent) -> ControlFlow<()>,
) -> TabularRun {
    let mut agent = TabularAgent::new(
        &cfg.agent,
        env.num_states(),
        env.num_actions(),
        seeded(derive_seed(cfg.seed, "agent")),
    );
    let mut expert = ExpertCore::new(
        cfg.budget(),
        cfg.expert.model,
        env.num_actions(),
        cfg.shaping.schedule(),
    );
    let mut rule = QueryRule::new(cfg.query.queue_len, cfg.query.percentile);
    let sarsa = cfg.agent.kind == crate::config::AgentKind::Sarsa;
    let mut records = Vec::with_capacity(cfg.episodes as usize);
    let mut global_step = 0u64;

    // One decision at state s: Algorithm 1 lines 3-16.
    let mut decide = |agent: &mut TabularAgent,
                      expert: &mut ExpertCore,
                      s: usize,
                      step: u64,
                      js_sum: &mut f64,
                      queries: &mut u32| {
        let js = agent.js_divergence(s);
        *js_sum += js;
        let own = agent.act(s);
        if query_decision(
            cfg.query.mode,
            &mut rule,
            js,
            !expert.budget().is_exhausted(),
        ) {
            let a = demonstrator.act(&s);
            if expert
                .record(&[s as f64], a, step, &cfg.expert.name)
                .is_some()
            {
                *queries += 1;
                return a;
            }
        }
        own
    };

    for episode in 0..cfg.episodes {
        let mut s = env.reset(if episode == 0 {
            Some(derive_seed(cfg.seed, "env"))
        } else {
            None
        });
        agent.begin_episode();
        let (mut ret, mut length, mut js_sum, mut queries) = (0.0, 0u32, 0.0, 0u32);
        let mut a = decide(
            &mut agent,
            &mut expert,
            s,
            global_step,
            &mut js_sum,
            &mut queries,
        );
        loop {
            let step = env
                .step(a)
                .expect("the runner only steps a live episode with a valid action");
            ret += step.reward;
            length += 1;
            global_step += 1;
            let s_next = step.observation;
            if step.done() {
                agent.learn(s, a, step.reward, s_next, step.terminated, None);
                break;
            }
            if sarsa {
                // SARSA needs the next action before it can update.
                let a_next = decide(
                    &mut agent,
                    &mut expert,
                    s_next,
                    global_step,
                    &mut js_sum,
                    &mut queries,
                );
                agent.learn(s, a, step.reward, s_next, false, Some(a_next));
                a = a_next;
            } else {
                agent.learn(s, a, step.reward, s_next, false, None);
                a = decide(
                    &mut agent,
                    &mut expert,
                    s_next,
                    global_step,
                    &mut js_sum,
                    &mut queries,
                );
            }
            s = s_next;
        }
        let record = EpisodeRecord {
            episode,
            ret,
            length,
            demos_used: expert.budget().used(),
            mean_js: js_sum / length as f64,
            queries,
            shaped_steps: 0,
            total_steps: global_step,
        };
        let flow = on_episode(&record, &agent);
        records.push(record);
        if flow.is_break() {
            break;
        }
    }
    let greedy_policy = agent.greedy_policy();
    TabularRun {
        records,
        greedy_policy,
        agent,
    }
}

/// Runs a neural experiment (CartPole): Algorithm 1 with the actor and the learner in one
/// process, the actor acting on the learner's latest weights at every step. `on_episode` sees
/// each record and the learner's network, and may stop the run early.
pub fn run_neural(
    cfg: &ExperimentConfig,
    demonstrator: &mut dyn Demonstrator<[f32]>,
    mut on_episode: impl FnMut(&EpisodeRecord, &Mlp) -> ControlFlow<()>,
) -> NeuralRun {
    let mut env = CartPole::new(cfg.env.max_episode_steps());
    let obs_dim = 4;
    let actions = env.num_actions();
    let mut learner = NeuralLearner::new(
        &cfg.agent,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, "learner")),
    );
    let mut actor = NeuralActor::new(
        &cfg.agent,
        &cfg.query,
        obs_dim,
        actions,
        seeded(derive_seed(cfg.seed, "actor-0")),
    );
    actor.copy_weights_from(learner.network(), 0);
    let mut expert = ExpertCore::new(
        cfg.budget(),
        cfg.expert.model,
        actions,
        cfg.shaping.schedule(),
    );
    let mut records = Vec::with_capacity(cfg.episodes as usize);
    let mut global_step = 0u64;

    for episode in 0..cfg.episodes {
        let mut obs = env.reset(if episode == 0 {
            Some(derive_seed(cfg.seed, "env"))
        } else {
            None
        });
        actor.begin_episode();
        let (mut ret, mut length, mut js_sum, mut queries, mut shaped_steps) =
            (0.0, 0u32, 0.0, 0u32, 0u32);
        loop {
            let decision = actor.decide(&obs, !expert.budget().is_exhausted());
            js_sum += decision.js;
            let mut action = decision.action;
            let mut demo = false;
            if decision.query {
                if let Some(a) = expert.answer(demonstrator, &obs, global_step, &cfg.expert.name) {
                    action = a;
                    demo = true;
                    queries += 1;
                }
            }
            let step = env
                .step(action)
                .expect("the runner only steps a live episode with a valid action");
            let shaping = if cfg.shaping_enabled() {
                expert.shaping_model(global_step)
            } else {
                None
            };
            shaped_steps += u32::from(shaping.is_some());
            let t = actor.transition(
                &obs,
                action,
                step.reward,
                &step.observation,
                step.terminated,
                demo,
                shaping,
            );
            learner.insert(&t);
            let mut updated = false;
            for _ in 0..cfg.agent.updates_per_step {
                updated |= learner.update().is_some();
            }
            if updated {
                actor.copy_weights_from(learner.network(), learner.updates());
            }
            ret += step.reward;
            length += 1;
            global_step += 1;
            obs = step.observation;
            if step.done() {
                break;
            }
        }
        let record = EpisodeRecord {
            episode,
            ret,
            length,
            demos_used: expert.budget().used(),
            mean_js: js_sum / f64::from(length),
            queries,
            shaped_steps,
            total_steps: global_step,
        };
        let flow = on_episode(&record, learner.network());
        records.push(record);
        if flow.is_break() {
            break;
        }
    }
    NeuralRun {
        records,
        network: learner.network().clone(),
        expert,
    }
}

/// Whether a config never asks the expert (so no demonstrator is needed).
pub fn needs_expert(cfg: &ExperimentConfig) -> bool {
    cfg.query.mode != QueryMode::Never && cfg.budget() > 0
}

/// Mean, median and (population) standard deviation of returns, as `alfd expert eval` prints them.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReturnStats {
    pub mean: f64,
    pub median: f64,
    pub std: f64,
}

impl ReturnStats {
    pub fn of(returns: &[f64]) -> Self {
        assert!(!returns.is_empty(), "no returns to summarise");
        let n = returns.len() as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        let median = crate::query::percentile(returns, 50.0).expect("non-empty");
        Self { mean, median, std }
    }
}

/// Returns of `episodes` episodes of `env` played by `act`, the first reset seeded with `seed`.
pub fn evaluate<E: Env>(
    env: &mut E,
    episodes: usize,
    seed: u64,
    mut act: impl FnMut(&E::Observation) -> usize,
) -> Vec<f64> {
    (0..episodes)
        .map(|i| {
            let mut obs = env.reset(if i == 0 { Some(seed) } else { None });
            let mut ret = 0.0;
            loop {
                let step = env.step(act(&obs)).expect("valid action on a live episode");
                ret += step.reward;
                let done = step.done();
                obs = step.observation;
                if done {
                    return ret;
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
}

/// Returns of `episodes` CliffWalk episodes played by `policy` on a clone of `env`.
pub fn evaluate_cliffwalk(
    policy: &mut dyn Demonstrator<usize>,
    env: &CliffWalk,
    episodes: usize,
    seed: u64,
) -> Vec<f64> {
    evaluate(&mut env.clone(), episodes, seed, |s| policy.act(s))
}
