//! DeepSea for the tabular agents: the same environment with the agent's cell as a state id
//! (`row · N + column`, and `N²` for the all-zero observation after the last row) in place of
//! the one-hot grid, which holds exactly the same information.

use super::{DeepSea, NUM_ACTIONS};
use crate::env::{Env, EnvError, EnvState, Step, TabularEnv};

/// [`DeepSea`] with state ids (see the module's docs).
#[derive(Debug, Clone)]
pub struct DeepSeaCells(pub DeepSea);

impl DeepSeaCells {
    /// The id of the agent's cell (`N²` after the last row).
    fn id(&self) -> usize {
        let n = self.0.size();
        self.0
            .position()
            .map_or(n * n, |(row, column)| row * n + column)
    }

    /// The action that moves right at state `s` (0 at the end state, where none is taken).
    pub fn optimal_action_at(&self, s: usize) -> usize {
        let n = self.0.size();
        if s >= n * n {
            return 0;
        }
        usize::from(self.0.action_mapping()[s])
    }
}

impl TabularEnv for DeepSeaCells {
    fn num_states(&self) -> usize {
        let n = self.0.size();
        n * n + 1
    }
}

impl Env for DeepSeaCells {
    type Observation = usize;

    fn num_actions(&self) -> usize {
        NUM_ACTIONS
    }

    fn observation_dim(&self) -> usize {
        1
    }

    fn max_episode_steps(&self) -> usize {
        self.0.max_episode_steps()
    }

    fn reset(&mut self, seed: Option<u64>) -> usize {
        self.0.reset(seed);
        self.id()
    }

    fn step(&mut self, action: usize) -> Result<Step<usize>, EnvError> {
        let s = self.0.step(action)?;
        Ok(Step {
            observation: self.id(),
            reward: s.reward,
            terminated: s.terminated,
            truncated: s.truncated,
        })
    }

    fn snapshot(&self) -> EnvState {
        self.0.snapshot()
    }

    fn restore(&mut self, state: &EnvState) -> Result<(), EnvError> {
        self.0.restore(state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_follow_the_one_hot_grid_and_the_optimal_action_reaches_the_treasure() {
        let mut cells = DeepSeaCells(DeepSea::new(5, 3).unwrap());
        let mut grid = DeepSea::new(5, 3).unwrap();
        let (mut s, mut obs) = (cells.reset(Some(0)), grid.reset(Some(0)));
        let mut ret = 0.0;
        loop {
            assert_eq!(Some(s), obs.iter().position(|&v| v == 1.0));
            let a = cells.optimal_action_at(s);
            assert_eq!(Some(a), grid.optimal_action_for(&obs));
            let (c, g) = (cells.step(a).unwrap(), grid.step(a).unwrap());
            assert_eq!((c.reward, c.terminated), (g.reward, g.terminated));
            ret += c.reward;
            (s, obs) = (c.observation, g.observation);
            if c.terminated {
                break;
            }
        }
        assert_eq!(s, 25, "the end state after the last row");
        assert!((ret - 0.99).abs() < 1e-12, "{ret}");
        assert_eq!(cells.num_states(), 26);
    }
}
