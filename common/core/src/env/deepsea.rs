//! DeepSea(N) of bsuite 0.3.6 (`bsuite/environments/deep_sea.py` with its defaults:
//! deterministic, `unscaled_move_cost` 0.01, randomized actions) with Gymnasium's semantics.
//!
//! # Rules
//! - An N×N grid; the agent starts at the top-left cell (row 0, column 0) and falls one row per
//!   step: every episode lasts exactly N steps and the N-th ends it (`terminated`).
//! - At each cell one of the two actions moves right (the column grows by 1, at most to N-1), the
//!   other left (the column shrinks by 1, at least to 0). Which one is the action mapping:
//!   `np.random.RandomState(mapping_seed).binomial(1, 0.5, [N, N])`, the action equal to the
//!   mapping's entry moving right, reproduced here draw for draw ([`numpy_legacy`]).
//! - The reward of a step: `+1` for moving right from the last column (which only the bottom-right
//!   cell can be, reached by moving right at every row), then `-0.01 / N` for any move right;
//!   moving left gives 0. In bsuite's order of operations: `0 + 1 - 0.01/N` on the treasure step,
//!   `0 - 0.01/N` on another move right. Always moving right returns `1 - 0.01`, bsuite's
//!   `optimal_return` (up to the rounding of the sum).
//! - The observation is the grid, row-major, `1.0` at the agent's cell and `0.0` elsewhere; after
//!   the last row (the observation of the terminating step) it is all zeros.
//! - Nothing is random in an episode. bsuite's `seed` only seeds the noise of its stochastic
//!   variant (in the deterministic one it still draws one `rand()` per move right and discards
//!   it); `reset(seed)` here reseeds a generator nothing draws from, so every seed gives the same
//!   episode.
//! - A step limit (default N) truncates as Gymnasium's `TimeLimit` does: at the default, the
//!   N-th step is both `terminated` and `truncated`.
//!
//! bsuite resets itself when stepped after the end (dm_env); here that step is
//! [`EnvError::EpisodeOver`], as for every [`Env`]. bsuite's count of "bad episodes" (a move left
//! from the diagonal) is not kept.

mod cells;
pub mod numpy_legacy;

pub use cells::DeepSeaCells;

use super::episode::{Episode, Phase};
use super::{Env, EnvError, EnvState, Step};
use numpy_legacy::RandomState;

/// The largest N: an observation has N² values (10,000 at N = 100), and an episode N steps.
pub const MAX_SIZE: usize = crate::config::MAX_DEEPSEA_SIZE;
/// bsuite's `unscaled_move_cost`: a move right costs this divided by N.
pub const UNSCALED_MOVE_COST: f64 = 0.01;
/// The reward for moving right from the bottom-right cell.
pub const TREASURE: f64 = 1.0;
/// The two actions; which one moves right depends on the cell.
pub const NUM_ACTIONS: usize = 2;

/// A DeepSea that cannot be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DeepSeaError {
    #[error("DeepSea size must be at least 1, got 0")]
    ZeroSize,
    #[error("DeepSea size {size} is over the limit of {max} (an observation has size² values)")]
    TooLarge { size: usize, max: usize },
}

/// DeepSea(N) with bsuite's action mapping for `mapping_seed` (see the module's docs).
///
/// The physical state is the agent's `(row, column)`; an [`EnvState`] keeps it as two values.
#[derive(Debug, Clone)]
pub struct DeepSea {
    size: usize,
    mapping_seed: u32,
    /// `mapping[row * size + column]`: the action that moves right at that cell.
    mapping: Vec<u8>,
    episode: Episode,
    row: usize,
    column: usize,
}

impl DeepSea {
    /// DeepSea(`size`) with the action mapping of `mapping_seed` and a step limit of `size`
    /// (bsuite's `DeepSea(size=size, mapping_seed=mapping_seed)`).
    pub fn new(size: usize, mapping_seed: u32) -> Result<Self, DeepSeaError> {
        Self::with_max_episode_steps(size, mapping_seed, size)
    }

    /// The same with episodes truncated after `max_episode_steps` steps (Gymnasium's
    /// `TimeLimit`; a limit of N or more never cuts an episode short).
    pub fn with_max_episode_steps(
        size: usize,
        mapping_seed: u32,
        max_episode_steps: usize,
    ) -> Result<Self, DeepSeaError> {
        if size == 0 {
            return Err(DeepSeaError::ZeroSize);
        }
        if size > MAX_SIZE {
            return Err(DeepSeaError::TooLarge {
                size,
                max: MAX_SIZE,
            });
        }
        Ok(Self {
            size,
            mapping_seed,
            mapping: action_mapping(size, mapping_seed),
            episode: Episode::new(max_episode_steps),
            row: 0,
            column: 0,
        })
    }

    /// N.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The seed of the action mapping.
    pub fn mapping_seed(&self) -> u32 {
        self.mapping_seed
    }

    /// The action mapping, row-major: entry `row * N + column` is the action that moves right at
    /// that cell (bsuite's `_action_mapping`, flattened).
    pub fn action_mapping(&self) -> &[u8] {
        &self.mapping
    }

    /// The agent's `(row, column)`; `None` after the last row.
    pub fn position(&self) -> Option<(usize, usize)> {
        (self.row < self.size).then_some((self.row, self.column))
    }

    /// The cost of one move right, `0.01 / N`.
    pub fn move_cost(&self) -> f64 {
        UNSCALED_MOVE_COST / self.size as f64
    }

    /// The return of always moving right, `1 - 0.01` (bsuite's `_optimal_return`).
    pub fn optimal_return(&self) -> f64 {
        TREASURE - UNSCALED_MOVE_COST
    }

    /// The action that moves right at the agent's cell (the optimal one); 0 after the last row,
    /// where the episode is over and no action is taken.
    pub fn optimal_action(&self) -> usize {
        self.position()
            .map_or(0, |(row, column)| self.right_action(row, column))
    }

    /// The action that moves right at the cell an observation of this DeepSea shows; `None` for
    /// the all-zero observation after the last row or one of another size.
    pub fn optimal_action_for(&self, observation: &[f32]) -> Option<usize> {
        let (row, column) = self.cell_of(observation)?;
        Some(self.right_action(row, column))
    }

    /// The `(row, column)` an observation of this DeepSea shows: the cell of its first non-zero
    /// value; `None` when all are zero or the length is not N².
    pub fn cell_of(&self, observation: &[f32]) -> Option<(usize, usize)> {
        if observation.len() != self.size * self.size {
            return None;
        }
        let hot = observation.iter().position(|&v| v != 0.0)?;
        Some((hot / self.size, hot % self.size))
    }

    /// The action that moves right at `(row, column)` (both below N).
    fn right_action(&self, row: usize, column: usize) -> usize {
        usize::from(self.mapping[row * self.size + column])
    }

    fn observation(&self) -> Vec<f32> {
        let mut grid = vec![0.0; self.size * self.size];
        if let Some((row, column)) = self.position() {
            grid[row * self.size + column] = 1.0;
        }
        grid
    }

    /// Moves the agent down one row and right or left; returns the reward, in bsuite's order of
    /// operations.
    fn advance(&mut self, right: bool) -> f64 {
        let last_column = self.size - 1;
        let mut reward = 0.0;
        if right && self.column == last_column {
            reward += TREASURE;
        }
        if right {
            self.column = (self.column + 1).min(last_column);
            reward -= self.move_cost();
        } else {
            self.column = self.column.saturating_sub(1);
        }
        self.row += 1;
        reward
    }

    /// The `(row, column)` a saved state holds, refused unless this DeepSea can be there after
    /// the saved number of steps.
    fn saved_position(&self, saved: &EnvState) -> Result<(usize, usize), EnvError> {
        let index =
            |v: f64| (v >= 0.0 && v.fract() == 0.0 && v <= MAX_SIZE as f64).then_some(v as usize);
        let (row, column) = match saved.state[..] {
            [row, column] => (index(row), index(column)),
            _ => (None, None),
        };
        let over = saved.phase == Phase::Over.code();
        match (row, column) {
            (Some(r), Some(c))
                if c <= r
                    && c < self.size
                    && (r < self.size || (r == self.size && over))
                    && r as u64 == saved.elapsed_steps =>
            {
                Ok((r, c))
            }
            _ => Err(EnvError::BadState(format!(
                "{:?} after {} steps is no (row, column) of DeepSea({})",
                saved.state, saved.elapsed_steps, self.size
            ))),
        }
    }
}

/// `np.random.RandomState(seed).binomial(1, 0.5, [size, size])`, row-major.
fn action_mapping(size: usize, seed: u32) -> Vec<u8> {
    let mut rng = RandomState::new(seed);
    (0..size * size)
        .map(|_| {
            let coin = rng
                .binomial(1, 0.5)
                .expect("binomial(1, 0.5) is drawn by inversion");
            coin as u8
        })
        .collect()
}

impl Env for DeepSea {
    type Observation = Vec<f32>;

    fn num_actions(&self) -> usize {
        NUM_ACTIONS
    }

    fn observation_dim(&self) -> usize {
        self.size * self.size
    }

    fn max_episode_steps(&self) -> usize {
        self.episode.max_steps()
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        self.episode.begin(seed);
        (self.row, self.column) = (0, 0);
        self.observation()
    }

    fn step(&mut self, action: usize) -> Result<Step<Vec<f32>>, EnvError> {
        self.episode.check_step(action, NUM_ACTIONS)?;
        let (row, column) = (self.row, self.column);
        let right = action == self.right_action(row, column);
        let reward = self.advance(right);
        let terminated = self.row == self.size;
        let truncated = self.episode.count_step(terminated);
        tracing::trace!(row, column, action, right, reward, "deepsea step");
        Ok(Step {
            observation: self.observation(),
            reward,
            terminated,
            truncated,
        })
    }

    /// The physical state is `[row, column]`.
    fn snapshot(&self) -> EnvState {
        self.episode
            .snapshot(&[self.row as f64, self.column as f64])
    }

    fn restore(&mut self, saved: &EnvState) -> Result<(), EnvError> {
        let (row, column) = self.saved_position(saved)?;
        self.episode.restore(saved, &mut [0.0; 2])?;
        (self.row, self.column) = (row, column);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hot(observation: &[f32]) -> Option<usize> {
        observation.iter().position(|&v| v == 1.0)
    }

    #[test]
    fn sizes_zero_and_over_the_limit_are_refused() {
        assert_eq!(DeepSea::new(0, 0).err(), Some(DeepSeaError::ZeroSize));
        assert_eq!(
            DeepSea::new(MAX_SIZE + 1, 0).err(),
            Some(DeepSeaError::TooLarge {
                size: MAX_SIZE + 1,
                max: MAX_SIZE
            })
        );
        let largest = DeepSea::new(MAX_SIZE, 0).expect("the limit itself is allowed");
        assert_eq!(largest.observation_dim(), 10_000);
        assert_eq!(largest.max_episode_steps(), MAX_SIZE);
    }

    #[test]
    fn always_right_finds_the_treasure_on_the_diagonal() {
        let mut env = DeepSea::new(8, 42).expect("valid");
        assert_eq!(hot(&env.reset(Some(3))), Some(0));
        let mut rewards = Vec::new();
        for i in 0..8 {
            assert_eq!(env.position(), Some((i, i)));
            let step = env.step(env.optimal_action()).expect("running");
            assert_eq!(step.terminated, i == 7);
            assert_eq!(step.truncated, i == 7, "the default limit is N");
            let diagonal = (i < 7).then_some((i + 1) * 9);
            assert_eq!(hot(&step.observation), diagonal);
            rewards.push(step.reward);
        }
        assert_eq!(rewards[..7], [-0.01 / 8.0; 7]);
        assert_eq!(rewards[7], 1.0 - 0.01 / 8.0);
        assert!((rewards.iter().sum::<f64>() - env.optimal_return()).abs() < 1e-15);
        assert_eq!(env.position(), None);
        assert_eq!(env.optimal_action(), 0);
        assert_eq!(env.step(0), Err(EnvError::EpisodeOver));
    }

    #[test]
    fn always_left_stays_in_the_first_column_for_nothing() {
        let mut env = DeepSea::new(5, 0).expect("valid");
        let mut obs = env.reset(None);
        for _ in 0..5 {
            assert_eq!(env.cell_of(&obs).map(|(_, c)| c), Some(0));
            let left = 1 - env.optimal_action_for(&obs).expect("a cell");
            let step = env.step(left).expect("running");
            assert_eq!(step.reward, 0.0);
            obs = step.observation;
        }
        assert!(obs.iter().all(|&v| v == 0.0) && obs.len() == 25);
        assert_eq!(env.cell_of(&obs), None);
    }

    #[test]
    fn a_shorter_limit_truncates_without_terminating() {
        let mut env = DeepSea::with_max_episode_steps(6, 1, 2).expect("valid");
        env.reset(None);
        assert!(!env.step(0).expect("running").done());
        let step = env.step(0).expect("running");
        assert!(step.truncated && !step.terminated);
    }

    #[test]
    fn a_snapshot_restores_the_position_and_bad_ones_are_refused() {
        let mut env = DeepSea::new(6, 7).expect("valid");
        env.reset(Some(1));
        env.step(1).expect("running");
        env.step(0).expect("running");
        let saved = env.snapshot();
        assert_eq!(saved.state.len(), 2);
        let next = env.step(1).expect("running");
        let mut other = DeepSea::new(6, 7).expect("valid");
        other.restore(&saved).expect("a state of this DeepSea");
        assert_eq!(other.position(), Some((2, saved.state[1] as usize)));
        assert_eq!(other.step(1), Ok(next));
        let before = other.position();
        let bad = |state: Vec<f64>, elapsed_steps| EnvState {
            state,
            elapsed_steps,
            ..saved.clone()
        };
        for wrong in [
            bad(vec![2.0], 2),
            bad(vec![2.0, 3.0], 2),
            bad(vec![2.0, 1.5], 2),
            bad(vec![2.0, 1.0], 3),
            bad(vec![6.0, 1.0], 6),
            bad(vec![-1.0, 0.0], 0),
        ] {
            assert!(
                matches!(other.restore(&wrong), Err(EnvError::BadState(_))),
                "{wrong:?}"
            );
        }
        assert_eq!(other.position(), before, "a refused state changes nothing");
    }
}
