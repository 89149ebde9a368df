//! `[env]`: which environment, and its options.

use serde::{Deserialize, Serialize};

/// Which environment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum EnvName {
    /// CartPole-1000: Gymnasium's CartPole-v1 dynamics, episodes of up to 1,000 steps (the
    /// paper's).
    Cartpole,
    /// The paper's tabular grid with a cliff (section 5.1.1), moves that succeed with
    /// `env.p_success`.
    Cliffwalk,
    /// MountainCar-v0 (Gymnasium's dynamics; sparse reward, 200 steps).
    Mountaincar,
    /// Acrobot-v1 (Gymnasium's dynamics; sparse reward, 500 steps).
    Acrobot,
    /// Any Gymnasium environment (`env.id`), served by a Python adapter in another process.
    Gymnasium,
    /// bsuite's DeepSea(N) (`env.size`, `env.mapping_seed`): deterministic, the treasure at the
    /// bottom right behind N moves right that each cost 0.01/N; the tabular agents see the cell,
    /// the neural ones bsuite's one-hot grid of N² values (in `alfd run` too).
    Deepsea,
}

impl EnvName {
    /// Every environment, in the order a message lists them.
    pub const ALL: [EnvName; 6] = [
        EnvName::Cartpole,
        EnvName::Cliffwalk,
        EnvName::Mountaincar,
        EnvName::Acrobot,
        EnvName::Gymnasium,
        EnvName::Deepsea,
    ];

    /// The name a config uses (`cartpole`, `cliffwalk`, `mountaincar`, `acrobot`, `gymnasium`).
    pub fn as_str(self) -> &'static str {
        match self {
            EnvName::Cartpole => "cartpole",
            EnvName::Cliffwalk => "cliffwalk",
            EnvName::Mountaincar => "mountaincar",
            EnvName::Acrobot => "acrobot",
            EnvName::Gymnasium => "gymnasium",
            EnvName::Deepsea => "deepsea",
        }
    }

    /// The step limit of a config that sets none: the paper's 1000 for CartPole, CliffWalk's
    /// 500, and `gym.make`'s for MountainCar-v0 (200) and Acrobot-v1 (500); 0 for Gymnasium,
    /// meaning the registration's own (the adapter reports it).
    pub fn default_max_episode_steps(self) -> usize {
        match self {
            EnvName::Cartpole => 1000,
            EnvName::Cliffwalk => 500,
            EnvName::Mountaincar => 200,
            EnvName::Acrobot => 500,
            EnvName::Gymnasium => 0,
            // N, set from `env.size` ([`EnvConfig::max_episode_steps`]).
            EnvName::Deepsea => 0,
        }
    }

    /// The range `[r_min, r_max]` of one step's reward (CartPole 1, MountainCar −1, Acrobot −1 or
    /// 0); `None` where it is not known here (CliffWalk's maps, Gymnasium's environments).
    pub fn reward_range(self) -> Option<(f64, f64)> {
        match self {
            EnvName::Cartpole => Some((1.0, 1.0)),
            EnvName::Mountaincar => Some((-1.0, -1.0)),
            EnvName::Acrobot => Some((-1.0, 0.0)),
            EnvName::Cliffwalk | EnvName::Gymnasium | EnvName::Deepsea => None,
        }
    }

    /// Whether the environment runs in another process (a Gymnasium adapter).
    pub fn is_remote(self) -> bool {
        self == EnvName::Gymnasium
    }

    /// Whether the states are ids (the tabular agents' environments) rather than vectors.
    pub fn is_tabular(self) -> bool {
        matches!(self, EnvName::Cliffwalk | EnvName::Deepsea)
    }
}

impl std::fmt::Display for EnvName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for EnvName {
    type Err = String;

    /// A config name; the error lists the known ones.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|e| e.as_str() == s)
            .ok_or_else(|| {
                let known: Vec<&str> = Self::ALL.iter().map(|e| e.as_str()).collect();
                format!("unknown environment `{s}` (known: {})", known.join(", "))
            })
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EnvConfig {
    /// The environment: CartPole-1000, CliffWalk, MountainCar-v0, Acrobot-v1 (Gymnasium's
    /// dynamics, reimplemented), or any Gymnasium environment.
    pub name: EnvName,
    /// Step limit after which an episode is truncated, ≥ 1 (by default CartPole 1000, CliffWalk 500,
    /// MountainCar 200, Acrobot 500, DeepSea N, a Gymnasium environment its registration's).
    #[serde(default)]
    pub max_episode_steps: Option<usize>,
    /// Gymnasium: the environment id given to `gymnasium.make`, e.g. `Acrobot-v1`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// Gymnasium: keyword arguments of `gymnasium.make` (numbers, strings, booleans).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<std::collections::BTreeMap<String, String>>")]
    pub kwargs: Option<toml::Table>,
    /// CliffWalk: probability that the chosen move happens, in (0, 1].
    #[serde(default = "default_p_success")]
    pub p_success: f64,
    /// CliffWalk: a map file of `S`, `G`, `X`, `.`; the built-in map when absent.
    #[serde(default)]
    pub map: Option<String>,
    /// DeepSea: N, the grid's side (1 to 100); episodes last N steps.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<usize>,
    /// DeepSea: the seed of the action mapping (bsuite's `mapping_seed`); by default the run's
    /// `seed`, so that each seed of a sweep plays its own instance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mapping_seed: Option<u32>,
}

/// DeepSea's N when `env.size` is not given.
pub const DEFAULT_DEEPSEA_SIZE: usize = 10;
/// The largest DeepSea N a config may ask for (a grid of N² cells).
pub const MAX_DEEPSEA_SIZE: usize = 100;

/// Largest K, for Q-tables and networks alike (Osband et al. use up to 20 heads on DeepSea).
pub const MAX_HEADS: usize = 20;

fn default_p_success() -> f64 {
    0.9
}

impl EnvConfig {
    pub fn max_episode_steps(&self) -> usize {
        let default = match self.name {
            EnvName::Deepsea => self.size.unwrap_or(DEFAULT_DEEPSEA_SIZE),
            other => other.default_max_episode_steps(),
        };
        self.max_episode_steps.unwrap_or(default)
    }

    /// DeepSea's N (`env.size`, default 10).
    pub fn deepsea_size(&self) -> usize {
        self.size.unwrap_or(DEFAULT_DEEPSEA_SIZE)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn deepsea_takes_its_size_and_mapping_seed_and_only_it_does() {
        let parse = |text: &str| crate::config::ExperimentConfig::from_toml(text);
        let c = parse(
            "seed = 4\nepisodes = 3\n[env]\nname = \"deepsea\"\nsize = 20\n\
             [agent]\nkind = \"bootstrapped-q\"\nheads = 20\n",
        )
        .unwrap();
        assert_eq!((c.env.deepsea_size(), c.env.max_episode_steps()), (20, 20));
        assert_eq!(c.expert.name, "deepsea-optimal");
        let err = |text: &str| parse(text).unwrap_err().to_string();
        assert!(err("seed = 1\nepisodes = 3\n[env]\nname = \"cartpole\"\nsize = 3\n[agent]\nkind = \"bdqn\"\n").contains("deepsea only"));
        assert!(err(
            "seed = 1\nepisodes = 3\n[env]\nname = \"deepsea\"\nsize = 101\n[agent]\nkind = \"qlearning\"\n"
        )
        .contains("1..=100"));
        // K up to 20, for Q-tables and networks alike; networks play DeepSea's one-hot grid.
        assert!(err(
            "seed = 1\nepisodes = 3\n[env]\nname = \"deepsea\"\n[agent]\nkind = \"bootstrapped-q\"\nheads = 21\n"
        )
        .contains("at most 20"));
        let neural = parse(
            "seed = 1\nepisodes = 3\n[env]\nname = \"deepsea\"\n[agent]\nkind = \"bdqn\"\nheads = 20\n",
        )
        .unwrap();
        assert_eq!(neural.agent.heads(), 20);
    }
}
