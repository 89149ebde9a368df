//! Demonstrators by name. Trained ones ship in `common/demonstrators/shipped/` and are compiled into the
//! binaries (no file to find at run time), scripted ones are built from [`crate::scripted`];
//! `manifest.json` there records how each was made and its measured quality.

use alfd_common::agent::{
    BalancingController, Becomes, Demonstrator, NetworkDemonstrator, TablePolicy,
};
use alfd_common::config::EnvName;
use alfd_common::env::cliffwalk::{value_iteration, CliffWalk};
use alfd_common::env::{DeepSeaCells, TabularEnv as _};
use alfd_common::nn::Mlp;
use alfd_harness::BadInput;
use serde::{Deserialize, Serialize};

use crate::scripted::Scripted;

/// A shipped demonstrator, as `manifest.json` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExpertEntry {
    pub name: String,
    /// `cartpole`, `cliffwalk`, `mountaincar` or `acrobot`.
    pub env: String,
    /// `analytic`, `value-iteration`, `dqn-checkpoint`, `policy-table` or `scripted`.
    pub kind: String,
    /// File in `common/demonstrators/shipped/`, if any.
    #[serde(default)]
    pub file: Option<String>,
    /// Measured mean return of the demonstrator's greedy policy (see `evaluation`).
    #[serde(default)]
    pub mean: Option<f64>,
    #[serde(default)]
    pub median: Option<f64>,
    #[serde(default)]
    pub std: Option<f64>,
    /// How the numbers were measured.
    #[serde(default)]
    pub evaluation: Option<String>,
    /// How the demonstrator was made.
    #[serde(default)]
    pub provenance: Option<String>,
}

/// An expert that cannot be loaded. The public functions return it as an
/// [`alfd_harness::BadInput`] (exit code 2: the name is the user's to fix).
#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    #[error("unknown expert `{name}` for {env}; known: {known}")]
    Unknown {
        name: String,
        env: String,
        known: String,
    },
    #[error("expert `{name}` demonstrates {its_env}, not {env}; experts for {env}: {known}")]
    WrongEnv {
        name: String,
        its_env: String,
        env: String,
        known: String,
    },
    #[error("expert `{name}`: {env} demonstrators act on {env}'s state ids, for Q-table agents")]
    NotVector { name: String, env: String },
    #[error("expert `{name}` is corrupt: {reason}")]
    Corrupt { name: String, reason: String },
}

impl From<RegistryError> for BadInput {
    fn from(e: RegistryError) -> Self {
        BadInput(e.to_string())
    }
}

const MANIFEST: &str = include_str!("../shipped/manifest.json");

/// The bytes of a shipped file, by its name in the manifest.
fn shipped_file(file: &str) -> Option<&'static [u8]> {
    SHIPPED.iter().find(|(n, _)| *n == file).map(|(_, b)| *b)
}

/// Files compiled in. Keep in step with `manifest.json` (a test checks it).
const SHIPPED: &[(&str, &[u8])] = &[
    (
        "cartpole-100.safetensors",
        include_bytes!("../shipped/cartpole-100.safetensors"),
    ),
    (
        "cartpole-1000.safetensors",
        include_bytes!("../shipped/cartpole-1000.safetensors"),
    ),
    (
        "cartpole-200.safetensors",
        include_bytes!("../shipped/cartpole-200.safetensors"),
    ),
    (
        "cartpole-50.safetensors",
        include_bytes!("../shipped/cartpole-50.safetensors"),
    ),
    (
        "cartpole-500.safetensors",
        include_bytes!("../shipped/cartpole-500.safetensors"),
    ),
    (
        "cliffwalk-qlearning-1000.json",
        include_bytes!("../shipped/cliffwalk-qlearning-1000.json"),
    ),
    (
        "cliffwalk-qlearning-200.json",
        include_bytes!("../shipped/cliffwalk-qlearning-200.json"),
    ),
    (
        "cliffwalk-qlearning-3000.json",
        include_bytes!("../shipped/cliffwalk-qlearning-3000.json"),
    ),
    (
        "cliffwalk-qlearning-50.json",
        include_bytes!("../shipped/cliffwalk-qlearning-50.json"),
    ),
    (
        "cliffwalk-sarsa-1000.json",
        include_bytes!("../shipped/cliffwalk-sarsa-1000.json"),
    ),
    (
        "cliffwalk-sarsa-200.json",
        include_bytes!("../shipped/cliffwalk-sarsa-200.json"),
    ),
    (
        "cliffwalk-sarsa-3000.json",
        include_bytes!("../shipped/cliffwalk-sarsa-3000.json"),
    ),
    (
        "cliffwalk-sarsa-50.json",
        include_bytes!("../shipped/cliffwalk-sarsa-50.json"),
    ),
];

/// Every demonstrator in the manifest.
pub fn list() -> Vec<ExpertEntry> {
    serde_json::from_str(MANIFEST)
        .expect("common/demonstrators/shipped/manifest.json is valid (tested)")
}

/// The manifest's entry `name` for `env`; the error names the experts of `env` (and the
/// environment `name` demonstrates, if it is another one).
fn entry(name: &str, env: &str) -> Result<ExpertEntry, RegistryError> {
    let all = list();
    let known = || {
        all.iter()
            .filter(|e| e.env == env)
            .map(|e| e.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    match all.iter().find(|e| e.name == name) {
        Some(e) if e.env == env => Ok(e.clone()),
        Some(e) => Err(RegistryError::WrongEnv {
            name: name.to_owned(),
            its_env: e.env.clone(),
            env: env.to_owned(),
            known: known(),
        }),
        None => Err(RegistryError::Unknown {
            name: name.to_owned(),
            env: env.to_owned(),
            known: known(),
        }),
    }
}

/// The policy of an external demonstrator's name (`python:MODULE:FUNCTION`,
/// `sb3:ALGO:PATH.zip`), answered by the Python adapter; `None` for a built-in name.
pub fn external_policy(name: &str) -> Option<&str> {
    (name.starts_with("python:") || name.starts_with("sb3:")).then_some(name)
}

/// Checks an external demonstrator's name: `python:MODULE:FUNCTION` or `sb3:ALGO:PATH`, each
/// part non-empty (whether it loads is the adapter's to say, at start-up).
pub fn check_external(name: &str) -> Result<(), BadInput> {
    check_external_name(name).map_err(BadInput::from)
}

fn check_external_name(name: &str) -> Result<(), RegistryError> {
    let mut parts = name.splitn(3, ':');
    let (kind, a, b) = (parts.next(), parts.next(), parts.next());
    let ok = matches!(kind, Some("python") | Some("sb3"))
        && a.is_some_and(|s| !s.is_empty())
        && b.is_some_and(|s| !s.is_empty());
    if ok {
        Ok(())
    } else {
        Err(RegistryError::Corrupt {
            name: name.to_owned(),
            reason: "an external expert is python:MODULE:FUNCTION or sb3:ALGO:PATH.zip".into(),
        })
    }
}

/// A CartPole demonstrator by name (the same as `for_env(EnvName::Cartpole, name)`).
pub fn cartpole(name: &str) -> Result<Box<dyn Demonstrator<[f32]> + Send>, BadInput> {
    for_env(EnvName::Cartpole, name)
}

/// The demonstrator `name` for an environment with vector observations (CartPole, MountainCar,
/// Acrobot). A name that is not one of `env`'s experts is refused with the list of those that
/// are; CliffWalk's demonstrators come from [`cliffwalk`] (they need the map).
pub fn for_env(env: EnvName, name: &str) -> Result<Box<dyn Demonstrator<[f32]> + Send>, BadInput> {
    vector_demonstrator(env, name).map_err(BadInput::from)
}

fn vector_demonstrator(
    env: EnvName,
    name: &str,
) -> Result<Box<dyn Demonstrator<[f32]> + Send>, RegistryError> {
    if env.is_tabular() {
        return Err(RegistryError::NotVector {
            name: name.to_owned(),
            env: env.to_string(),
        });
    }
    let e = entry(name, env.as_str())?;
    match (env, e.kind.as_str()) {
        (_, "scripted") => match Scripted::named(name) {
            Some(s) if s.env == env => Ok(s.build()),
            _ => Err(RegistryError::Corrupt {
                name: name.to_owned(),
                reason: format!("no scripted {env} expert has this name"),
            }),
        },
        (EnvName::Cartpole, "analytic") => Ok(Box::new(BalancingController)),
        (EnvName::Cartpole, "dqn-checkpoint") => {
            let file = e.file.as_deref().unwrap_or_default();
            let bytes = shipped_file(file).ok_or_else(|| RegistryError::Corrupt {
                name: name.to_owned(),
                reason: format!("file `{file}` is not compiled in"),
            })?;
            let net = Mlp::from_safetensors_bytes(bytes).map_err(|err| RegistryError::Corrupt {
                name: name.to_owned(),
                reason: err.to_string(),
            })?;
            Ok(Box::new(NetworkDemonstrator::new(net)))
        }
        (_, other) => Err(RegistryError::Corrupt {
            name: name.to_owned(),
            reason: format!("kind `{other}` is not a {env} kind"),
        }),
    }
}

/// How often each noisy DeepSea expert answers uniformly at random instead of moving right (a
/// generator seeded from its name): the good, fair and poor experts of MountainCar's and
/// Acrobot's ladders have the same shares.
const DEEPSEA_NOISE: [(&str, f64); 3] = [
    ("deepsea-good", 0.1),
    ("deepsea-fair", 0.25),
    ("deepsea-poor", 0.5),
];

/// `inner` as the DeepSea expert `e` (its kind): the right move, or that move with
/// [`DEEPSEA_NOISE`]'s share of random answers.
fn deepsea_expert<S: ?Sized, D: Demonstrator<S> + Send + 'static>(
    e: &ExpertEntry,
    inner: D,
) -> Result<Box<dyn Demonstrator<S> + Send>, BadInput> {
    let corrupt = |reason: String| {
        BadInput::from(RegistryError::Corrupt {
            name: e.name.clone(),
            reason,
        })
    };
    match e.kind.as_str() {
        "deepsea-optimal" => Ok(Box::new(inner)),
        "deepsea-noisy" => {
            let (_, epsilon) = DEEPSEA_NOISE
                .iter()
                .find(|(name, _)| *name == e.name)
                .ok_or_else(|| corrupt("no noisy DeepSea expert has this name".into()))?;
            Ok(Box::new(crate::scripted::Noisy::new(
                inner, *epsilon, 2, &e.name,
            )))
        }
        other => Err(corrupt(format!("kind `{other}` is not a deepsea kind"))),
    }
}

/// A DeepSea demonstrator by name, for the instance `env` (its action mapping):
/// `deepsea-optimal` moves right at every cell; `deepsea-good`, `deepsea-fair` and
/// `deepsea-poor` do so but answer uniformly at random one time in ten, four and two.
pub fn deepsea(
    name: &str,
    env: &DeepSeaCells,
) -> Result<Box<dyn Demonstrator<usize> + Send>, BadInput> {
    let e = entry(name, "deepsea").map_err(BadInput::from)?;
    let table = TablePolicy {
        actions: (0..env.num_states())
            .map(|s| env.optimal_action_at(s))
            .collect(),
    };
    deepsea_expert(&e, table)
}

/// The DeepSea instance's right moves for its one-hot observations (the neural agents' view):
/// at the all-zero observation after the last row, any action (0) is as good.
#[derive(Debug, Clone)]
struct DeepSeaGrid(alfd_common::env::DeepSea);

impl Demonstrator<[f32]> for DeepSeaGrid {
    fn act(&mut self, s: &[f32]) -> usize {
        self.0.optimal_action_for(s).unwrap_or(0)
    }
}

/// The demonstrator `name` for the environment of `cfg` with vector observations: as
/// [`for_env`], and DeepSea's for the instance the config names (`env.size`, its mapping
/// seed), acting on its one-hot grid.
pub fn for_config(
    cfg: &alfd_common::config::ExperimentConfig,
    name: &str,
) -> Result<Box<dyn Demonstrator<[f32]> + Send>, BadInput> {
    if cfg.env.name != EnvName::Deepsea {
        return for_env(cfg.env.name, name);
    }
    let e = entry(name, "deepsea").map_err(BadInput::from)?;
    let grid = alfd_common::env::DeepSea::new(cfg.env.deepsea_size(), cfg.deepsea_mapping_seed())
        .map_err(|err| BadInput(err.to_string()))?;
    deepsea_expert(&e, DeepSeaGrid(grid))
}

/// Whether a person (`human`) may be among `[[experts]]`: in `alfd run`, whose expert process
/// serves their page; not in a run of one process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum People {
    Allowed,
    Refused,
}

/// Stands for a person among several experts: never asked as a demonstrator (the panel hands
/// a state routed to them back, and their answer comes from the page).
#[derive(Debug, Clone, Copy, Default)]
pub struct PersonSlot;

impl Demonstrator<[f32]> for PersonSlot {
    fn act(&mut self, _: &[f32]) -> usize {
        0
    }

    fn try_act(&mut self, _: &[f32]) -> std::result::Result<usize, String> {
        Err("a person answers on the page, not as a demonstrator".to_owned())
    }
}

/// The demonstrators of `[[experts]]`, in order: a built-in one of the config's environment
/// (with `becomes`, one for its first `after` answers and another from then on), an external
/// one as `external(i, name)` starts it (`i` its place in the list), or for a person (at most
/// one, where `people` allows) a [`PersonSlot`].
pub fn panel(
    cfg: &alfd_common::config::ExperimentConfig,
    people: People,
    mut external: impl FnMut(usize, &str) -> alfd_harness::Result<Box<dyn Demonstrator<[f32]>>>,
) -> alfd_harness::Result<Vec<Box<dyn Demonstrator<[f32]>>>> {
    assemble(cfg, people, false, |i, elsewhere| match elsewhere {
        Elsewhere::External(policy) => external(i, policy),
        Elsewhere::BuiltIn => Ok(member(cfg, i)?),
    })
}

/// One of `[[experts]]` that answers from a process of its own, for [`panel_apart`]'s caller
/// to start and connect to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Elsewhere<'a> {
    /// `python:` or `sb3:`: the policy, served by a Python adapter.
    External(&'a str),
    /// A built-in expert, served by a process that builds it with [`member`].
    BuiltIn,
}

/// [`panel`] with every expert in a process of its own: each built-in and external expert is
/// checked here and then `elsewhere(i, what)` starts it and returns the demonstrator that asks
/// it; a person is a [`PersonSlot`] (the caller starts the process of their page).
pub fn panel_apart(
    cfg: &alfd_common::config::ExperimentConfig,
    people: People,
    elsewhere: impl FnMut(usize, Elsewhere<'_>) -> alfd_harness::Result<Box<dyn Demonstrator<[f32]>>>,
) -> alfd_harness::Result<Vec<Box<dyn Demonstrator<[f32]>>>> {
    assemble(cfg, people, true, elsewhere)
}

fn assemble(
    cfg: &alfd_common::config::ExperimentConfig,
    people: People,
    apart: bool,
    mut elsewhere: impl FnMut(
        usize,
        Elsewhere<'_>,
    ) -> alfd_harness::Result<Box<dyn Demonstrator<[f32]>>>,
) -> alfd_harness::Result<Vec<Box<dyn Demonstrator<[f32]>>>> {
    let refuse = |name: &str, why: &str| BadInput(format!("[[experts]]: `{name}` {why}"));
    let mut members: Vec<Box<dyn Demonstrator<[f32]>>> = Vec::new();
    for (i, e) in cfg.experts.iter().enumerate() {
        if e.name == alfd_harness::HUMAN_EXPERT {
            if people == People::Refused {
                return Err(refuse(
                    &e.name,
                    "(a person) answers among several experts in `alfd run` only, where a \
                     process of its own serves their page",
                )
                .into());
            }
            if e.becomes.is_some() {
                return Err(
                    refuse(&e.name, "is a person: `becomes` takes built-in experts").into(),
                );
            }
            members.push(Box::new(PersonSlot));
            continue;
        }
        if external_policy(&e.name).is_some() {
            if e.becomes.is_some() {
                return Err(
                    refuse(&e.name, "is external: `becomes` takes built-in experts").into(),
                );
            }
            check_external(&e.name)?;
            members.push(elsewhere(i, Elsewhere::External(&e.name))?);
            continue;
        }
        // Built here first: an unknown name is refused before any process starts.
        let built = member(cfg, i)?;
        members.push(match apart {
            true => elsewhere(i, Elsewhere::BuiltIn)?,
            false => built,
        });
    }
    Ok(members)
}

/// The built-in expert at place `i` of `[[experts]]` (with `becomes`, one for its first `after`
/// answers and another from then on); a person, an external expert or a place beyond the list
/// is bad input.
pub fn member(
    cfg: &alfd_common::config::ExperimentConfig,
    i: usize,
) -> Result<Box<dyn Demonstrator<[f32]>>, BadInput> {
    member_of(cfg, i, |name| for_config(cfg, name))
}

/// [`member`] for any kind of state: `build` gives a built-in expert by name (a Q-table run's
/// for its environment's state ids, say).
pub fn member_of<S: ?Sized + 'static>(
    cfg: &alfd_common::config::ExperimentConfig,
    i: usize,
    build: impl Fn(&str) -> Result<Box<dyn Demonstrator<S> + Send>, BadInput>,
) -> Result<Box<dyn Demonstrator<S>>, BadInput> {
    let built = |name: &str| build(name).map_err(|e| BadInput(format!("[[experts]]: {}", e.0)));
    let Some(e) = cfg.experts.get(i) else {
        return Err(BadInput(format!(
            "[[experts]] has {} experts: there is none at place {i}",
            cfg.experts.len()
        )));
    };
    if e.name == alfd_harness::HUMAN_EXPERT || external_policy(&e.name).is_some() {
        return Err(BadInput(format!(
            "[[experts]]: `{}` at place {i} is not a built-in expert",
            e.name
        )));
    }
    let first = built(&e.name)?;
    Ok(match (&e.becomes, e.after) {
        (Some(then), Some(after)) => Box::new(Becomes::new(first, built(then)?, after)),
        _ => first,
    })
}

/// A CliffWalk demonstrator by name, for `env` (the optimal one is computed for its map).
pub fn cliffwalk(
    name: &str,
    env: &CliffWalk,
) -> Result<Box<dyn Demonstrator<usize> + Send>, BadInput> {
    cliffwalk_demonstrator(name, env).map_err(BadInput::from)
}

fn cliffwalk_demonstrator(
    name: &str,
    env: &CliffWalk,
) -> Result<Box<dyn Demonstrator<usize> + Send>, RegistryError> {
    let e = entry(name, "cliffwalk")?;
    match e.kind.as_str() {
        "value-iteration" => {
            let vi = value_iteration(env, 0.99, 1e-10).map_err(|err| RegistryError::Corrupt {
                name: name.to_owned(),
                reason: err.to_string(),
            })?;
            Ok(Box::new(TablePolicy { actions: vi.policy }))
        }
        "policy-table" => {
            let file = e.file.as_deref().unwrap_or_default();
            let bytes = shipped_file(file).ok_or_else(|| RegistryError::Corrupt {
                name: name.to_owned(),
                reason: format!("file `{file}` is not compiled in"),
            })?;
            let table: TablePolicy =
                serde_json::from_slice(bytes).map_err(|err| RegistryError::Corrupt {
                    name: name.to_owned(),
                    reason: err.to_string(),
                })?;
            if table.actions.len() != env.num_states() || table.actions.iter().any(|&a| a >= 4) {
                return Err(RegistryError::Corrupt {
                    name: name.to_owned(),
                    reason: format!("its table has {} states; the map has {} (policy tables fit the default map only)", table.actions.len(), env.num_states()),
                });
            }
            Ok(Box::new(table))
        }
        other => Err(RegistryError::Corrupt {
            name: name.to_owned(),
            reason: format!("kind `{other}` is not a cliffwalk kind"),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manifest_parses_and_every_file_is_compiled_in() {
        let all = list();
        assert!(all.iter().any(|e| e.name == "cartpole-perfect"));
        for e in &all {
            if let Some(f) = &e.file {
                assert!(
                    shipped_file(f).is_some(),
                    "{} names {f}, which SHIPPED lacks",
                    e.name
                );
            }
        }
        for (f, _) in SHIPPED {
            assert!(
                all.iter().any(|e| e.file.as_deref() == Some(f)),
                "{f} is compiled in but not in the manifest"
            );
        }
    }

    #[test]
    fn deepseas_experts_move_right_at_their_share_of_cells_and_rank_by_it() {
        let sea = DeepSeaCells(alfd_common::env::DeepSea::new(20, 3).unwrap());
        let n = sea.num_states();
        let right_share = |name: &str| {
            let mut d = deepsea(name, &sea).unwrap();
            let right = (0..20_000)
                .filter(|i| d.act(&(i % n)) == sea.optimal_action_at(i % n))
                .count();
            right as f64 / 20_000.0
        };
        assert_eq!(right_share("deepsea-optimal"), 1.0);
        // A random answer is the right move half the time: 1 - epsilon / 2 of the answers.
        for (name, epsilon) in DEEPSEA_NOISE {
            let share = right_share(name);
            assert!(
                (share - (1.0 - epsilon / 2.0)).abs() < 0.01,
                "{name}: {share}"
            );
        }
        let err = deepsea("deepsea-great", &sea).err().unwrap().to_string();
        assert!(
            err.contains("deepsea-fair") && err.contains("deepsea-poor"),
            "{err}"
        );
    }

    #[test]
    fn unknown_names_are_refused_with_the_known_ones() {
        let err = cartpole("cartpole-9000").err().unwrap().to_string();
        assert!(
            err.contains("cartpole-9000") && err.contains("cartpole-perfect"),
            "{err}"
        );
    }

    #[test]
    fn every_scripted_expert_is_listed_and_loads_for_its_env_only() {
        let all = list();
        for s in crate::scripted::SCRIPTED {
            let e = all.iter().find(|e| e.name == s.name).expect(s.name);
            assert_eq!(
                (e.env.as_str(), e.kind.as_str()),
                (s.env.as_str(), "scripted")
            );
            assert!(e.mean.is_some() && e.evaluation.is_some(), "{}", s.name);
            assert!(for_env(s.env, s.name).is_ok(), "{}", s.name);
        }
        for e in all.iter().filter(|e| e.kind == "scripted") {
            assert!(
                crate::scripted::Scripted::named(&e.name).is_some(),
                "{} is in the manifest but not scripted",
                e.name
            );
        }
        assert!(for_env(EnvName::Cartpole, "cartpole-perfect").is_ok());
    }

    #[test]
    fn a_name_for_another_env_is_refused_with_that_envs_experts() {
        let err = for_env(EnvName::Mountaincar, "cartpole-1000")
            .err()
            .unwrap()
            .to_string();
        assert_eq!(
            err,
            "expert `cartpole-1000` demonstrates cartpole, not mountaincar; experts for \
             mountaincar: mountaincar-energy, mountaincar-good, mountaincar-fair, mountaincar-poor"
        );
        let err = for_env(EnvName::Acrobot, "acrobot-best")
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("unknown expert `acrobot-best` for acrobot")
                && err.contains("acrobot-energy, acrobot-good"),
            "{err}"
        );
        let err = cartpole("acrobot-energy").err().unwrap().to_string();
        assert!(err.contains("demonstrates acrobot, not cartpole"), "{err}");
        let err = for_env(EnvName::Cliffwalk, "cliffwalk-optimal")
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("state ids, for Q-table agents"), "{err}");
    }
}
