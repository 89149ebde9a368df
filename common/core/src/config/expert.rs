//! The budget and the expert: `[budget]`, `[expert]` and, for several experts at once,
//! `[[experts]]` with the route that picks one per query (`crate::panel`).

use serde::{Deserialize, Serialize};

use super::{invalid, DemoModelChoice, ExperimentConfig, Result};
use crate::panel::Route;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BudgetConfig {
    /// B: how many demonstrations may be asked for in the whole run (≥ 0).
    #[serde(default = "default_budget")]
    pub total: i64,
    /// With several experts: the most the run may spend on answers, in the experts' `cost`
    /// (> 0); absent: no limit but `total`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<f64>,
}

fn default_budget() -> i64 {
    100
}

impl Default for BudgetConfig {
    fn default() -> Self {
        Self {
            total: default_budget(),
            cost: None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExpertConfig {
    /// The demonstrator, by name (`alfd expert list`); default the environment's reference expert
    /// (`cartpole-1000`, `cliffwalk-optimal`, `mountaincar-energy`, `acrobot-energy`).
    #[serde(default = "default_expert")]
    pub name: String,
    /// The demonstration model fitted on the demonstrations.
    #[serde(default = "default_model")]
    pub model: DemoModelChoice,
    /// With several experts (`[[experts]]`): which one a query goes to. `best-known` (always
    /// `best_known`, for comparison), `cheapest`, `round-robin`, `interval` (the cheapest whose
    /// quality interval can still be the best's, after IEThresh), `upper-per-cost` (the highest
    /// upper end of the quality interval per unit of cost), `escalate` (the cheapest, and where
    /// its answer disagrees with the demonstration model, or there is none yet, the next expert
    /// up the cost ladder too, whose answer is acted on; a differing answer overrules the first,
    /// which is kept at weight 0), `signal-per-cost` (the most agreement above chance, squared,
    /// per unit of cost: the upper end of the quality interval, rescaled so that agreeing by
    /// chance is 0).
    #[serde(default = "default_route", skip_serializing_if = "is_default_route")]
    pub route: Route,
    /// With several experts: the expert `best-known` asks (default the first of `[[experts]]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub best_known: Option<String>,
    /// With several experts: the probability that a query is also asked of a second expert (the
    /// one with the fewest answers), so that experts can be compared, in [0, 1].
    #[serde(
        default = "default_double_ask",
        skip_serializing_if = "is_default_double_ask"
    )]
    pub double_ask: f64,
    /// With several experts: each expert's quality is over its last this many rewards (≥ 2).
    #[serde(
        default = "default_quality_window",
        skip_serializing_if = "is_default_window"
    )]
    pub quality_window: usize,
    /// With several experts: the returns of the episodes that followed each expert's advice
    /// count toward its quality too (each expert that answered in an episode earns the episode
    /// return's percentile rank among the episodes before it).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub quality_from_returns: bool,
}

fn default_route() -> Route {
    Route::Interval
}
fn is_default_route(r: &Route) -> bool {
    *r == default_route()
}
fn default_double_ask() -> f64 {
    0.1
}
fn is_default_double_ask(p: &f64) -> bool {
    *p == default_double_ask()
}
fn default_quality_window() -> usize {
    100
}
fn is_default_window(w: &usize) -> bool {
    *w == default_quality_window()
}

/// One of several experts (`[[experts]]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PanelEntry {
    /// The demonstrator, by name (`alfd expert list`), or an external one (`python:MODULE:FUNCTION`,
    /// `sb3:ALGO:PATH.zip`) answering from an adapter process of its own.
    pub name: String,
    /// What one answer costs (> 0), in any unit the run's `budget.cost` shares.
    #[serde(default = "default_cost")]
    pub cost: f64,
    /// A name for tables and plots (default `name`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// A change behind the same name: after `after` answers this expert answers as the
    /// demonstrator `becomes` (`alfd expert list`), as a live `alfd swap-expert` would; for
    /// measuring how fast the quality estimate follows. Given together with `after`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub becomes: Option<String>,
    /// The answers after which `becomes` answers instead (≥ 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub after: Option<u64>,
}

fn default_cost() -> f64 {
    1.0
}

fn default_expert() -> String {
    "cartpole-1000".to_owned()
}
fn default_model() -> DemoModelChoice {
    DemoModelChoice::None
}

impl Default for ExpertConfig {
    fn default() -> Self {
        Self {
            name: default_expert(),
            model: default_model(),
            route: default_route(),
            best_known: None,
            double_ask: default_double_ask(),
            quality_window: default_quality_window(),
            quality_from_returns: false,
        }
    }
}

/// An expert named both in `[expert]` and in `[[experts]]` is refused: which one the run means
/// would be a guess. Read from the TOML as written (and the `--set` overrides), before the
/// environment's default expert is filled in.
pub(super) fn check_named_once(table: &toml::Table, overrides: &[String]) -> Result<()> {
    let listed: Vec<&str> = match table.get("experts") {
        Some(toml::Value::Array(a)) => a
            .iter()
            .filter_map(|e| e.get("name").and_then(toml::Value::as_str))
            .collect(),
        _ => return Ok(()),
    };
    let written = table
        .get("expert")
        .and_then(|e| e.get("name"))
        .and_then(toml::Value::as_str);
    let set = overrides
        .iter()
        .rev()
        .find_map(|o| o.strip_prefix("expert.name="))
        .map(|v| v.trim().trim_matches('"'));
    match set.or(written) {
        Some(name) if listed.contains(&name) => Err(invalid(
            "expert.name",
            format!(
                "names `{name}`, which `[[experts]]` lists too: with several experts, list every \
                 one in `[[experts]]` and leave `expert.name` out"
            ),
        )),
        _ => Ok(()),
    }
}

impl ExperimentConfig {
    /// `[[experts]]`, `budget.cost` and the route's settings.
    pub(super) fn validate_experts(&self) -> Result<()> {
        let e = &self.expert;
        if !(0.0..=1.0).contains(&e.double_ask) {
            return Err(invalid(
                "expert.double_ask",
                format!("must be in [0, 1], got {}", e.double_ask),
            ));
        }
        if e.quality_window < 2 {
            return Err(invalid("expert.quality_window", "must be at least 2"));
        }
        if let Some(c) = self.budget.cost {
            if !(c > 0.0 && c.is_finite()) {
                return Err(invalid("budget.cost", format!("must be > 0, got {c}")));
            }
        }
        if self.experts.is_empty() {
            if self.budget.cost.is_some() {
                return Err(invalid(
                    "budget.cost",
                    "counts the cost of several experts: list them in `[[experts]]`",
                ));
            }
            if e.best_known.is_some() {
                return Err(invalid(
                    "expert.best_known",
                    "names one of several experts: list them in `[[experts]]`",
                ));
            }
            return Ok(());
        }
        for (i, x) in self.experts.iter().enumerate() {
            let elsewhere = ["python:", "sb3:"].iter().any(|p| x.name.starts_with(p));
            if self.agent.kind.is_tabular() && (elsewhere || x.name == "human") {
                return Err(invalid(
                    "experts",
                    format!(
                        "`{}`: a Q-table agent's experts are built-in ones (`alfd expert \
                         list`); Python policies and people answer neural agents",
                        x.name
                    ),
                ));
            }
            if x.name.trim().is_empty() {
                return Err(invalid("experts", format!("entry {} has no name", i + 1)));
            }
            if !(x.cost > 0.0 && x.cost.is_finite()) {
                return Err(invalid(
                    "experts",
                    format!("`{}` costs {}: a cost must be > 0", x.name, x.cost),
                ));
            }
            match (&x.becomes, x.after) {
                (Some(_), Some(n)) if n >= 1 => {}
                (None, None) => {}
                _ => {
                    return Err(invalid(
                        "experts",
                        format!(
                            "`{}`: `becomes` and `after` (≥ 1 answers) are given together",
                            x.name
                        ),
                    ))
                }
            }
            if self.experts[..i].iter().any(|y| y.name == x.name) {
                return Err(invalid("experts", format!("`{}` is listed twice", x.name)));
            }
        }
        if let Some(b) = &e.best_known {
            if !self.experts.iter().any(|x| &x.name == b) {
                return Err(invalid(
                    "expert.best_known",
                    format!("`{b}` is not one of `[[experts]]`"),
                ));
            }
        }
        Ok(())
    }

    /// The index in `[[experts]]` of the expert route `best-known` asks.
    pub fn best_known(&self) -> usize {
        let named = self.expert.best_known.as_ref();
        named
            .and_then(|b| self.experts.iter().position(|x| &x.name == b))
            .unwrap_or(0)
    }
}

/// A change to a live run's experts (`alfd expert add|remove`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RosterChange {
    Add,
    Remove,
}

/// The experts' joined name after `change` of `expert` in a run whose experts are `current`
/// (their names joined by `+`), or why the change cannot be made.
pub fn changed_roster(current: &str, change: RosterChange, expert: &str) -> Result<String, String> {
    let mut names: Vec<&str> = current.split('+').collect();
    let listed = names.contains(&expert);
    match change {
        RosterChange::Add if listed => {
            return Err(format!("`{expert}` is one of the run's experts already"))
        }
        RosterChange::Add => names.push(expert),
        RosterChange::Remove if !listed => {
            return Err(format!(
                "`{expert}` is not one of the run's experts ({current})"
            ))
        }
        RosterChange::Remove if names.len() == 1 => {
            return Err(format!(
                "`{expert}` is the run's only expert; `alfd swap-expert` replaces it"
            ))
        }
        RosterChange::Remove => names.retain(|n| *n != expert),
    }
    Ok(names.join("+"))
}

impl ExperimentConfig {
    /// The config of a live run whose expert is `name`. In a run with `[[experts]]`: its own
    /// experts under their joined name, and for any other name the experts it joins (names
    /// joined by `+`, or one), each the entry `added` gives it (the experts `alfd expert add`
    /// gave the run, the newest entry of a name first), else that of `[[experts]]`, else cost 1,
    /// so that every answer is counted at its cost. A name with `+` in a run of one expert is
    /// read the same way; any other name is the run's one expert.
    pub fn with_roster(&self, name: &str, added: &[PanelEntry]) -> Self {
        if !self.experts.is_empty() && name == self.run_expert_name() {
            return self.clone();
        }
        if self.experts.is_empty() && !name.contains('+') {
            return self.with_one_expert(name);
        }
        let mut cfg = self.clone();
        let entry = |part: &str| {
            let newest = added.iter().rev().find(|e| e.name == part);
            newest
                .or_else(|| self.experts.iter().find(|e| e.name == part))
                .cloned()
                .unwrap_or_else(|| PanelEntry {
                    name: part.to_owned(),
                    cost: default_cost(),
                    label: None,
                    becomes: None,
                    after: None,
                })
        };
        cfg.experts = name.split('+').map(entry).collect();
        cfg
    }

    /// The config with `name` as its one expert, without `[[experts]]`.
    pub fn with_one_expert(&self, name: &str) -> Self {
        let mut cfg = self.clone();
        cfg.experts.clear();
        cfg.expert.name = name.to_owned();
        cfg
    }
}

#[cfg(test)]
mod tests {
    use crate::config::ExperimentConfig;

    const BASE: &str =
        "seed = 1\nepisodes = 3\n[env]\nname = \"mountaincar\"\n[agent]\nkind = \"bdqn\"\n";

    fn parse(extra: &str, sets: &[&str]) -> Result<ExperimentConfig, String> {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        ExperimentConfig::from_toml_with_overrides(&format!("{BASE}{extra}"), &sets)
            .map_err(|e| e.to_string())
    }

    const THREE: &str = "[[experts]]\nname = \"mountaincar-energy\"\ncost = 10\n\
                         [[experts]]\nname = \"mountaincar-fair\"\ncost = 2\n\
                         [[experts]]\nname = \"mountaincar-poor\"\n";

    #[test]
    fn several_experts_are_listed_with_costs_and_a_route() {
        let c = parse(THREE, &["expert.route=cheapest", "budget.cost=50"]).unwrap();
        assert_eq!(c.experts.len(), 3);
        assert_eq!((c.experts[0].cost, c.experts[2].cost), (10.0, 1.0));
        assert_eq!(c.expert.route, crate::panel::Route::Cheapest);
        assert_eq!((c.budget.cost, c.best_known()), (Some(50.0), 0));
        let c = parse(THREE, &["expert.best_known=mountaincar-fair"]).unwrap();
        assert_eq!(c.best_known(), 1);
        // It reads back equal once written.
        assert_eq!(ExperimentConfig::from_toml(&c.to_toml()).unwrap(), c);
    }

    #[test]
    fn an_expert_named_in_both_places_or_a_bad_entry_is_refused() {
        let both = parse(
            &format!("[expert]\nname = \"mountaincar-fair\"\n{THREE}"),
            &[],
        )
        .unwrap_err();
        assert!(
            both.contains("expert.name") && both.contains("mountaincar-fair"),
            "{both}"
        );
        let set = parse(THREE, &["expert.name=mountaincar-poor"]).unwrap_err();
        assert!(set.contains("leave `expert.name` out"), "{set}");
        let twice = format!("{THREE}[[experts]]\nname = \"mountaincar-poor\"\n");
        assert!(parse(&twice, &[]).unwrap_err().contains("listed twice"));
        let half = "[[experts]]\nname = \"mountaincar-good\"\nbecomes = \"mountaincar-poor\"\n";
        assert!(parse(half, &[]).unwrap_err().contains("given together"));
        let whole = format!("{half}after = 40\n");
        assert_eq!(parse(&whole, &[]).unwrap().experts[0].after, Some(40));
        let free = "[[experts]]\nname = \"mountaincar-poor\"\ncost = 0\n";
        assert!(parse(free, &[]).unwrap_err().contains("must be > 0"));
        assert!(parse("", &["budget.cost=5"])
            .unwrap_err()
            .contains("[[experts]]"));
        assert!(parse(THREE, &["expert.best_known=nobody"])
            .unwrap_err()
            .contains("nobody"));
        assert!(parse(THREE, &["expert.double_ask=2"])
            .unwrap_err()
            .contains("[0, 1]"));
        let multi = ExperimentConfig::for_multi_process(&format!("{BASE}{THREE}")).unwrap();
        assert_eq!(multi.experts.len(), 3);
    }

    #[test]
    fn q_tables_take_built_in_experts_only() {
        let qtables = |name: &str| {
            let text = format!(
                "seed = 1\nepisodes = 3\n[env]\nname = \"deepsea\"\n[agent]\n\
                 kind = \"bootstrapped-q\"\n[[experts]]\nname = \"deepsea-good\"\n\
                 [[experts]]\nname = \"{name}\"\n"
            );
            ExperimentConfig::from_toml(&text).map_err(|e| e.to_string())
        };
        assert_eq!(qtables("deepsea-poor").unwrap().experts.len(), 2);
        for other in ["human", "python:module:policy", "sb3:dqn:model.zip"] {
            let err = qtables(other).unwrap_err();
            assert!(
                err.contains(&format!(
                    "`{other}`: a Q-table agent's experts are built-in"
                )),
                "{err}"
            );
        }
    }

    #[test]
    fn a_roster_changes_by_name_and_its_config_takes_each_entry_from_where_it_was_given() {
        use super::{changed_roster, PanelEntry, RosterChange::*};
        assert_eq!(changed_roster("a+b", Add, "c").unwrap(), "a+b+c");
        assert_eq!(changed_roster("a", Add, "c").unwrap(), "a+c");
        assert_eq!(changed_roster("a+b+c", Remove, "b").unwrap(), "a+c");
        assert!(changed_roster("a+b", Add, "b")
            .unwrap_err()
            .contains("already"));
        assert!(changed_roster("a+b", Remove, "c")
            .unwrap_err()
            .contains("not one"));
        assert!(changed_roster("a", Remove, "a")
            .unwrap_err()
            .contains("swap-expert"));
        let cfg = ExperimentConfig::from_toml(&format!("{BASE}{THREE}")).unwrap();
        let joined = cfg.run_expert_name();
        assert_eq!(cfg.with_roster(&joined, &[]), cfg);
        // One of them alone still answers at its cost.
        let one = cfg.with_roster("mountaincar-fair", &[]);
        assert_eq!(one.experts, [cfg.experts[1].clone()]);
        let single = parse("", &[]).unwrap();
        let swapped = single.with_roster("mountaincar-fair", &[]);
        assert!(swapped.experts.is_empty());
        assert_eq!(swapped.expert.name, "mountaincar-fair");
        assert_eq!(
            single
                .with_roster("mountaincar-fair+mountaincar-poor", &[])
                .experts
                .len(),
            2
        );
        let added = |cost| PanelEntry {
            name: "mountaincar-good".into(),
            cost,
            label: None,
            becomes: None,
            after: None,
        };
        let two = cfg.with_roster(
            "mountaincar-poor+mountaincar-good+mountaincar-energy",
            &[added(4.0), added(5.0)],
        );
        let got: Vec<(&str, f64)> = two
            .experts
            .iter()
            .map(|e| (e.name.as_str(), e.cost))
            .collect();
        assert_eq!(
            got,
            [
                ("mountaincar-poor", cfg.experts[2].cost),
                ("mountaincar-good", 5.0),
                ("mountaincar-energy", cfg.experts[0].cost)
            ]
        );
        let unknown = cfg.with_roster("mountaincar-poor+somebody", &[]);
        assert_eq!(unknown.experts[1].cost, 1.0);
    }
}
