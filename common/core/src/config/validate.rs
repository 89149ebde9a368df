//! [`ExperimentConfig::validate`]: every value of a config checked, the error naming the field;
//! sizes (buffers, layers, queues) have upper limits so that no config asks for absurd memory.

use super::{
    invalid, AgentConfig, AgentKind, DemoModelChoice, EnvName, ExperimentConfig, Result, RuleKind,
};
use crate::demo_model::nystrom::MAX_APPROX_DEMOS;
use crate::demo_model::MAX_DEMOS;

/// The largest `agent.replay_capacity`: a million transitions take about 100 MB.
pub const MAX_REPLAY_CAPACITY: usize = 1_000_000;
/// The largest `agent.batch_size`.
pub const MAX_BATCH_SIZE: usize = 8192;
/// The largest `agent.hidden` (the width of the two hidden layers; the paper's is 64).
pub const MAX_HIDDEN: usize = 1024;

/// The largest `heads × hidden` of a network with separate torsos (its hidden layers' width).
pub const MAX_SEPARATE_WIDTH: usize = 2048;
/// The largest `query.queue_len` (L_q; the paper's is 1000).
pub const MAX_QUEUE_LEN: usize = 100_000;
/// The longest n-step return `agent.n_step` may ask for.
pub const MAX_N_STEP: u32 = 100;

/// `value` in `1..=max`, else an error naming `field`.
fn in_range(field: &'static str, value: usize, max: usize) -> Result<()> {
    if value == 0 {
        return Err(invalid(field, "must be at least 1"));
    }
    if value > max {
        return Err(invalid(
            field,
            format!("must be at most {max}, got {value}"),
        ));
    }
    Ok(())
}

/// `agent.shared_torso = false` only for networks, and no wider than [`MAX_SEPARATE_WIDTH`].
fn check_torsos(a: &AgentConfig) -> Result<()> {
    if a.shared_torso {
        return Ok(());
    }
    if a.kind.is_tabular() {
        return Err(invalid(
            "agent.shared_torso",
            "applies to neural agents only (Q-tables have no torso)",
        ));
    }
    let width = a.hidden * a.heads();
    if width > MAX_SEPARATE_WIDTH {
        return Err(invalid(
            "agent.shared_torso",
            format!(
                "false makes the hidden layers heads × hidden = {width} wide, at most \
                 {MAX_SEPARATE_WIDTH}: use fewer heads or a smaller agent.hidden"
            ),
        ));
    }
    Ok(())
}

/// A Gymnasium id as `gymnasium.make` takes it: 1 to 128 ASCII letters, digits and `-_./:`.
fn valid_gym_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 128
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-_./:".contains(&b))
}

impl ExperimentConfig {
    /// The most demonstrations the config's demonstration model takes (`nystrom`: up to
    /// 1,000,000; the exact ones 10,000).
    pub fn max_model_demos(&self) -> usize {
        match self.expert.model {
            DemoModelChoice::Nystrom => MAX_APPROX_DEMOS,
            _ => MAX_DEMOS,
        }
    }

    /// Checks every value; the error names the field.
    pub fn validate(&self) -> Result<()> {
        self.validate_run()?;
        self.validate_env()?;
        self.validate_agent()?;
        self.validate_agent_learning()?;
        self.validate_agent_training()?;
        self.validate_query()?;
        self.validate_budget()?;
        self.validate_experts()?;
        Ok(())
    }

    /// The run's length and evaluation.
    fn validate_run(&self) -> Result<()> {
        if self.episodes == 0 && self.steps == 0 {
            return Err(invalid(
                "episodes",
                "set `episodes` or `steps` (or both) to at least 1",
            ));
        }
        if self.evaluation.every > 0 && self.evaluation.episodes == 0 {
            return Err(invalid("evaluation.episodes", "must be at least 1"));
        }
        Ok(())
    }

    /// The `[env]` section.
    fn validate_env(&self) -> Result<()> {
        let e = &self.env;
        if !(e.p_success > 0.0 && e.p_success <= 1.0) {
            return Err(invalid(
                "env.p_success",
                format!("must be in (0, 1], got {}", e.p_success),
            ));
        }
        if e.max_episode_steps == Some(0) {
            return Err(invalid("env.max_episode_steps", "must be at least 1"));
        }
        if e.name == EnvName::Gymnasium {
            match e.id.as_deref() {
                None => {
                    return Err(invalid(
                        "env.id",
                        "is needed for gymnasium: the id given to gymnasium.make, e.g. \"Acrobot-v1\"",
                    ))
                }
                Some(id) if !valid_gym_id(id) => {
                    return Err(invalid(
                        "env.id",
                        format!("`{id}` is not a Gymnasium id (letters, digits, `-`, `_`, `.`, `/`, `:`; e.g. Acrobot-v1)"),
                    ))
                }
                Some(_) => {}
            }
        } else if e.id.is_some() || e.kwargs.is_some() {
            let field = if e.id.is_some() {
                "env.id"
            } else {
                "env.kwargs"
            };
            return Err(invalid(field, "applies to gymnasium only"));
        }
        if e.name != EnvName::Cliffwalk && e.map.is_some() {
            return Err(invalid("env.map", "applies to cliffwalk only"));
        }
        if e.name != EnvName::Deepsea && (e.size.is_some() || e.mapping_seed.is_some()) {
            let field = if e.size.is_some() {
                "env.size"
            } else {
                "env.mapping_seed"
            };
            return Err(invalid(field, "applies to deepsea only"));
        }
        let max = crate::config::MAX_DEEPSEA_SIZE;
        if e.name == EnvName::Deepsea && !(1..=max).contains(&e.deepsea_size()) {
            return Err(invalid(
                "env.size",
                format!("N must be in 1..={max}, got {}", e.deepsea_size()),
            ));
        }
        Ok(())
    }

    /// The `[agent]` section: the kind (for the environment), K and γ.
    fn validate_agent(&self) -> Result<()> {
        let e = &self.env;
        let a = &self.agent;
        if a.heads() == 0 {
            return Err(invalid("agent.heads", "K must be at least 1"));
        }
        let most = crate::config::MAX_HEADS;
        if a.heads() > most {
            return Err(invalid(
                "agent.heads",
                format!(
                    "at most {most} heads are supported for {:?}, got {}",
                    a.kind,
                    a.heads()
                ),
            ));
        }
        if matches!(
            a.kind,
            AgentKind::Qlearning | AgentKind::Sarsa | AgentKind::Dqn
        ) && a.heads() != 1
        {
            return Err(invalid(
                "agent.heads",
                format!(
                    "{:?} has one head; use bdqn or bootstrapped-q for K > 1",
                    a.kind
                ),
            ));
        }
        // DeepSea takes both: Q-tables on its cells, networks on its one-hot grid.
        if e.name != EnvName::Deepsea && a.kind.is_tabular() != e.name.is_tabular() {
            return Err(invalid(
                "agent.kind",
                format!("{:?} does not run on {}: tabular agents run on cliffwalk and deepsea, neural ones on cartpole, mountaincar, acrobot, deepsea and gymnasium", a.kind, e.name),
            ));
        }
        if !(a.gamma >= 0.0 && a.gamma <= 1.0) {
            return Err(invalid(
                "agent.gamma",
                format!("must be in [0, 1], got {}", a.gamma),
            ));
        }
        if a.kind.is_tabular() && a.gamma >= 1.0 {
            return Err(invalid(
                "agent.gamma",
                format!(
                    "must be in [0, 1) for the tabular agents (the values of their policies, computed \
                     at the end of the run, are finite only with discounting), got {}",
                    a.gamma
                ),
            ));
        }
        Ok(())
    }

    /// The `[agent]` section: exploration, learning rate, bootstrap mask, replay and network
    /// sizes, target updates, updates per step.
    fn validate_agent_learning(&self) -> Result<()> {
        let a = &self.agent;
        if !(a.temperature > 0.0 && a.temperature.is_finite()) {
            return Err(invalid(
                "agent.temperature",
                format!("must be > 0, got {}", a.temperature),
            ));
        }
        if !(a.learning_rate() > 0.0 && a.learning_rate().is_finite()) {
            return Err(invalid(
                "agent.learning_rate",
                format!("must be > 0, got {}", a.learning_rate()),
            ));
        }
        for (field, v) in [
            ("agent.epsilon_start", a.epsilon_start),
            ("agent.epsilon_end", a.epsilon_end),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(invalid(field, format!("must be in [0, 1], got {v}")));
            }
        }
        if !(a.epsilon_decay_steps > 0.0 && a.epsilon_decay_steps.is_finite()) {
            return Err(invalid(
                "agent.epsilon_decay_steps",
                format!("must be > 0 and finite, got {}", a.epsilon_decay_steps),
            ));
        }
        if !(a.bootstrap_probability > 0.0 && a.bootstrap_probability <= 1.0) {
            return Err(invalid(
                "agent.bootstrap_probability",
                format!("must be in (0, 1], got {}", a.bootstrap_probability),
            ));
        }
        for (field, v, max) in [
            (
                "agent.replay_capacity",
                a.replay_capacity,
                MAX_REPLAY_CAPACITY,
            ),
            ("agent.batch_size", a.batch_size, MAX_BATCH_SIZE),
            ("agent.hidden", a.hidden, MAX_HIDDEN),
        ] {
            in_range(field, v, max)?;
        }
        if a.target_update_every == 0 {
            return Err(invalid("agent.target_update_every", "must be at least 1"));
        }
        check_torsos(a)?;
        if !a.kind.is_tabular() {
            if a.replay_capacity < a.batch_size {
                return Err(invalid(
                    "agent.replay_capacity",
                    format!(
                        "must hold at least one batch (batch_size = {}), got {}",
                        a.batch_size, a.replay_capacity
                    ),
                ));
            }
            if a.updates_per_step == 0 {
                return Err(invalid(
                    "agent.updates_per_step",
                    "must be at least 1 (with 0 the agent never learns)",
                ));
            }
        }
        Ok(())
    }

    /// The `[agent]` section: the update's options (Huber δ, τ, target bounds, gradient clipping,
    /// demonstration fraction and margin loss, learning-rate annealing, n-step, prior scale).
    fn validate_agent_training(&self) -> Result<()> {
        let a = &self.agent;
        if !(a.tau > 0.0 && a.tau <= 1.0) {
            return Err(invalid(
                "agent.tau",
                format!("must be in (0, 1], got {}", a.tau),
            ));
        }
        if !(a.huber_delta > 0.0 && a.huber_delta.is_finite()) {
            return Err(invalid(
                "agent.huber_delta",
                format!("must be > 0, got {}", a.huber_delta),
            ));
        }
        if let Some([lo, hi]) = a.target_bounds {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid(
                    "agent.target_bounds",
                    format!("must be [lo, hi] with finite lo < hi, got [{lo}, {hi}]"),
                ));
            }
        }
        if let Some(g) = a.max_grad_norm {
            if !(g > 0.0 && g.is_finite()) {
                return Err(invalid(
                    "agent.max_grad_norm",
                    format!("must be > 0, got {g}"),
                ));
            }
        }
        if !(0.0..=1.0).contains(&a.demo_fraction) {
            return Err(invalid(
                "agent.demo_fraction",
                format!("must be in [0, 1], got {}", a.demo_fraction),
            ));
        }
        if let Some(end) = a.learning_rate_end {
            if a.kind.is_tabular() {
                return Err(invalid(
                    "agent.learning_rate_end",
                    "applies to the neural agents (dqn, bdqn); the tabular ones anneal with \
                     agent.learning_rate_decay",
                ));
            }
            if !(end >= 0.0 && end.is_finite()) {
                return Err(invalid(
                    "agent.learning_rate_end",
                    format!("must be >= 0, got {end}"),
                ));
            }
        } else if a.learning_rate_anneal_steps > 0 {
            return Err(invalid(
                "agent.learning_rate_anneal_steps",
                "has no effect without agent.learning_rate_end",
            ));
        }
        if !(1..=MAX_N_STEP).contains(&a.n_step) {
            return Err(invalid(
                "agent.n_step",
                format!("must be in [1, {MAX_N_STEP}], got {}", a.n_step),
            ));
        }
        if a.n_step > 1 && a.kind.is_tabular() {
            return Err(invalid(
                "agent.n_step",
                "applies to the neural agents (dqn, bdqn); the tabular ones learn one step at a time",
            ));
        }
        for (field, v) in [
            ("agent.margin_loss_weight", a.margin_loss_weight),
            ("agent.margin", a.margin),
            ("agent.prior_scale", a.prior_scale),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(invalid(field, format!("must be >= 0, got {v}")));
            }
        }
        Ok(())
    }

    /// The `[query]` section.
    fn validate_query(&self) -> Result<()> {
        let q = &self.query;
        if q.queue_len == 0 {
            return Err(invalid("query.queue_len", "L_q must be at least 1"));
        }
        in_range("query.queue_len", q.queue_len, MAX_QUEUE_LEN)?;
        if !(0.0..=100.0).contains(&q.percentile) {
            return Err(invalid(
                "query.percentile",
                format!("p_r must be in [0, 100], got {}", q.percentile),
            ));
        }
        if !(0.0..=1.0).contains(&q.probability) {
            return Err(invalid(
                "query.probability",
                format!("must be in [0, 1], got {}", q.probability),
            ));
        }
        if q.burst == 0 {
            return Err(invalid("query.burst", "must be at least 1"));
        }
        if q.gap == 0 {
            return Err(invalid("query.gap", "must be at least 1"));
        }
        if q.gate.is_some() && q.rule != RuleKind::Never {
            return Err(invalid(
                "query.gate",
                format!(
                    "a rule is either `query.rule` (here `{}`) or `query.allowance` with \
                     `query.gate`, not both",
                    q.rule.name()
                ),
            ));
        }
        if q.gate.is_none() && q.allowance.is_some() {
            return Err(invalid(
                "query.allowance",
                "says when a demonstration may be asked for; `query.gate` must say which state",
            ));
        }
        if q.spreads() && q.horizon_for(self.steps) == 0 {
            return Err(invalid(
                "query.horizon",
                format!(
                    "`{}` spreads B over the run's steps: set `steps`, or `query.horizon` for a \
                     run limited by `episodes`",
                    q.rule_name()
                ),
            ));
        }
        if q.rule == RuleKind::Random && q.schedule.is_none() {
            return Err(invalid(
                "query.schedule",
                "rule `random` asks at the steps of a recorded run: give its demos.jsonl",
            ));
        }
        Ok(())
    }

    /// The `[budget]`, `[shaping]` and `[expert]` sections.
    fn validate_budget(&self) -> Result<()> {
        let a = &self.agent;
        if self.budget.total < 0 {
            return Err(invalid(
                "budget.total",
                format!("B must not be negative, got {}", self.budget.total),
            ));
        }
        if self.budget.total > u32::MAX as i64 {
            return Err(invalid("budget.total", "is too large"));
        }
        let s = &self.shaping;
        if !(s.lambda >= 0.0 && s.lambda.is_finite()) {
            return Err(invalid(
                "shaping.lambda",
                format!("must be >= 0, got {}", s.lambda),
            ));
        }
        if !(s.stop_multiple >= 0.0 && s.stop_multiple.is_finite()) {
            return Err(invalid(
                "shaping.stop_multiple",
                format!("must be >= 0, got {}", s.stop_multiple),
            ));
        }
        let max_demos = self.max_model_demos();
        if self.shaping_enabled() && self.budget.total > max_demos as i64 {
            return Err(invalid(
                "budget.total",
                format!(
                    "is {}, but the demonstration model (`expert.model`) is refitted on every \
                     demonstration and takes at most {max_demos} (`nystrom` takes up to \
                     {MAX_APPROX_DEMOS})",
                    self.budget.total
                ),
            ));
        }
        if self.shaping_enabled() && a.kind.is_tabular() {
            return Err(invalid(
                "expert.model",
                "reward shaping with a kernel model applies to the neural agents (cartpole, mountaincar, acrobot)",
            ));
        }
        if self.expert.name.trim().is_empty() {
            return Err(invalid("expert.name", "must not be empty"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NEURAL: &str =
        "seed = 0\nepisodes = 1\n[env]\nname = \"cartpole\"\n[agent]\nkind = \"bdqn\"\n";
    const TABULAR: &str =
        "seed = 0\nepisodes = 1\n[env]\nname = \"cliffwalk\"\n[agent]\nkind = \"qlearning\"\n";

    fn check(base: &str, sets: &[&str]) -> Result<ExperimentConfig> {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        ExperimentConfig::from_toml_with_overrides(base, &sets)
    }

    fn error(base: &str, sets: &[&str]) -> String {
        check(base, sets).unwrap_err().to_string()
    }

    #[test]
    fn tabular_agents_need_gamma_below_one_neural_ones_may_use_one() {
        for kind in ["qlearning", "sarsa", "bootstrapped-q"] {
            let e = error(TABULAR, &[&format!("agent.kind={kind}"), "agent.gamma=1.0"]);
            assert!(
                e.starts_with(
                    "invalid config: `agent.gamma` must be in [0, 1) for the tabular agents"
                ) && e.ends_with("got 1"),
                "{kind}: {e}"
            );
        }
        assert!(check(TABULAR, &["agent.gamma=0.999"]).is_ok());
        assert_eq!(
            check(NEURAL, &["agent.gamma=1.0"]).unwrap().agent.gamma,
            1.0
        );
    }

    #[test]
    fn epsilon_decay_steps_must_be_positive_and_finite() {
        for v in ["inf", "nan", "-3.0", "0.0", "-inf"] {
            let e = error(NEURAL, &[&format!("agent.epsilon_decay_steps={v}")]);
            assert!(
                e.starts_with(
                    "invalid config: `agent.epsilon_decay_steps` must be > 0 and finite, got"
                ),
                "{v}: {e}"
            );
        }
    }

    #[test]
    fn separate_torsos_are_for_networks_and_bounded_in_width() {
        assert!(check(NEURAL, &["agent.shared_torso=false", "agent.heads=20"]).is_ok());
        let e = error(
            NEURAL,
            &[
                "agent.shared_torso=false",
                "agent.heads=20",
                "agent.hidden=200",
            ],
        );
        assert!(
            e.contains("`agent.shared_torso`") && e.contains("4000"),
            "{e}"
        );
        let e = error(TABULAR, &["agent.shared_torso=false"]);
        assert!(
            e.contains("`agent.shared_torso`") && e.contains("neural"),
            "{e}"
        );
    }

    #[test]
    fn sizes_have_upper_limits_naming_the_field() {
        for (field, max) in [
            ("agent.replay_capacity", MAX_REPLAY_CAPACITY),
            ("agent.batch_size", MAX_BATCH_SIZE),
            ("agent.hidden", MAX_HIDDEN),
            ("query.queue_len", MAX_QUEUE_LEN),
        ] {
            // The largest value is allowed (with a buffer that holds a batch).
            let mut at_max = vec![format!("{field}={max}")];
            if field == "agent.batch_size" {
                at_max.push(format!("agent.replay_capacity={max}"));
            }
            let at_max: Vec<&str> = at_max.iter().map(String::as_str).collect();
            assert!(check(NEURAL, &at_max).is_ok(), "{field} = {max}");
            let e = error(NEURAL, &[&format!("{field}={}", max + 1)]);
            assert_eq!(
                e,
                format!(
                    "invalid config: `{field}` must be at most {max}, got {}",
                    max + 1
                )
            );
            let e = error(NEURAL, &[&format!("{field}=100000000000")]);
            assert!(
                e.contains(&format!("`{field}` must be at most {max}")),
                "{e}"
            );
        }
    }

    #[test]
    fn the_budget_of_a_shaped_run_is_limited_by_what_the_model_can_be_fitted_on() {
        let max = MAX_DEMOS as i64;
        assert!(check(
            NEURAL,
            &["expert.model=\"krr\"", &format!("budget.total={max}")]
        )
        .is_ok());
        let e = error(
            NEURAL,
            &["expert.model=\"svm\"", &format!("budget.total={}", max + 1)],
        );
        assert!(
            e.starts_with(&format!(
                "invalid config: `budget.total` is {}, but the demonstration model",
                max + 1
            )) && e.contains(&format!("takes at most {max} (`nystrom`")),
            "{e}"
        );
        // The Nyström model takes budgets a hundred times larger, and no more.
        let approx = MAX_APPROX_DEMOS as i64;
        assert!(check(
            NEURAL,
            &[
                "expert.model=\"nystrom\"",
                &format!("budget.total={approx}")
            ]
        )
        .is_ok());
        let e = error(
            NEURAL,
            &[
                "expert.model=\"nystrom\"",
                &format!("budget.total={}", approx + 1),
            ],
        );
        assert!(e.contains(&format!("takes at most {approx} ")), "{e}");
        // Without a model, demonstrations are only stored: the budget is not limited by it.
        assert!(check(NEURAL, &["budget.total=1000000"]).is_ok());
    }
}
