//! CliffWalk of the paper (section 4): a grid of plates, pits, a start and a goal, with slippery
//! moves; its text map format; and value iteration on its exact transition model (the perfect
//! expert and the yardstick for learned policies).
//!
//! # Rules
//! - The state is the id of the tile the agent is on, `row * width + col`.
//! - Actions: [`UP`] = 0, [`RIGHT`] = 1, [`DOWN`] = 2, [`LEFT`] = 3.
//! - The chosen move happens with probability `p_success`; otherwise one of the 4 moves is drawn
//!   uniformly at random (which may be the chosen one again). So the chosen move happens with
//!   probability `p_success + (1 - p_success) / 4` and each other one with `(1 - p_success) / 4`.
//! - Moving into the outer wall leaves the agent where it is.
//! - The reward is the reward of the tile the agent lands on (also when it stays in place):
//!   plates and the start tile -0.1, pits -5, the goal +5.
//! - Only the goal ends the episode (`terminated`). **A pit does not end it**: the paper says the
//!   game stops when the agent reaches the finishing point, so the agent stays on the pit tile,
//!   receives -5 and goes on from there (it pays -5 again for every step it lands on a pit,
//!   including bumping into a wall while standing on one).
//! - A step limit (default 500) ends the episode as `truncated`.
//!
//! # Map text format
//! One row per line, one character per tile: `S` start, `G` goal, `X` pit, `.` plate. Exactly one
//! `S` and one `G`; all rows of the same width; trailing whitespace on a line and blank lines at
//! the end are ignored; at most [`MAX_MAP_SIDE`] rows and columns. Lines and columns in errors
//! count from 1.

use std::fmt;
use std::str::FromStr;

use rand::{Rng as _, SeedableRng};

use super::episode::Phase;
use super::{Env, EnvError, Step};

mod planning;

use crate::rng::Rng;
pub use planning::{
    policy_evaluation, policy_evaluation_stochastic, value_iteration, ValueIteration,
};

/// Action: one row up.
pub const UP: usize = 0;
/// Action: one column right.
pub const RIGHT: usize = 1;
/// Action: one row down.
pub const DOWN: usize = 2;
/// Action: one column left.
pub const LEFT: usize = 3;
/// Number of actions (and of possible moves).
pub const NUM_ACTIONS: usize = 4;

/// The paper's probability that the chosen move happens.
pub const DEFAULT_P_SUCCESS: f64 = 0.9;
/// Default step limit of an episode.
pub const DEFAULT_MAX_EPISODE_STEPS: usize = 500;
/// The paper's discount factor.
pub const DEFAULT_GAMMA: f64 = 0.99;

/// Reward for landing on a plate or on the start tile.
pub const PLATE_REWARD: f64 = -0.1;
/// Reward for landing on a pit.
pub const PIT_REWARD: f64 = -5.0;
/// Reward for reaching the goal.
pub const GOAL_REWARD: f64 = 5.0;

/// The built-in 15×15 map: S bottom-left, G bottom-right, a cliff of pits between them along the
/// bottom row (the paper's figure 1, classic cliff walking) and 8 scattered pits. Under value
/// iteration (p_success 0.9, γ 0.99) the best path does not hug the cliff: it climbs three rows to
/// row 11, between the pits of rows 10 and 12, and comes back down at the right edge.
pub const DEFAULT_MAP: &str = "\
...............
...............
...............
...X......X....
...............
.......X.......
...............
..X............
...........X...
...............
......X........
...............
....X....X.....
...............
SXXXXXXXXXXXXXG
";

/// The largest number of rows, and of columns, of a map. On a 128×128 map (16,384 states) value
/// iteration takes about a second and exact policy evaluation (a banded solve) a fraction of one;
/// a 1000×1000 map would take minutes.
pub const MAX_MAP_SIDE: usize = 128;

/// A malformed map text. Lines and columns count from 1.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MapError {
    #[error("map is empty: it needs at least one row with an `S` and a `G`")]
    Empty,
    #[error("map is too large: {width}x{height} tiles (width x height, the width of line 1); at most {max}x{max} are allowed")]
    TooLarge {
        width: usize,
        height: usize,
        max: usize,
    },
    #[error("map line {line}, column {column}: unknown character {found:?} (expected one of `S`, `G`, `X`, `.`)")]
    UnknownCharacter {
        line: usize,
        column: usize,
        found: char,
    },
    #[error("map line {line}: row has {found} tiles but line 1 has {expected} (rows must all have the same width)")]
    RaggedRow {
        line: usize,
        expected: usize,
        found: usize,
    },
    #[error("map line {line}: blank line inside the map")]
    BlankLine { line: usize },
    #[error("map has no start tile `S`")]
    NoStart,
    #[error("map has no goal tile `G`")]
    NoGoal,
    #[error("map line {line}, column {column}: second start tile `S` (the first is at line {first_line}, column {first_column})")]
    DuplicateStart {
        line: usize,
        column: usize,
        first_line: usize,
        first_column: usize,
    },
    #[error("map line {line}, column {column}: second goal tile `G` (the first is at line {first_line}, column {first_column})")]
    DuplicateGoal {
        line: usize,
        column: usize,
        first_line: usize,
        first_column: usize,
    },
}

/// Invalid parameters of CliffWalk, of value iteration or of policy evaluation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CliffWalkError {
    #[error("p_success must be in (0, 1], got {0}")]
    PSuccess(f64),
    #[error("gamma must be in [0, 1), got {0}")]
    Gamma(f64),
    #[error("tol must be positive and finite, got {0}")]
    Tolerance(f64),
    #[error("policy has {found} entries but the map needs {expected}")]
    PolicyLength { expected: usize, found: usize },
    #[error("policy gives action {action} in state {state}, outside 0..4")]
    PolicyAction { state: usize, action: usize },
    #[error("policy probabilities of state {state} are not a distribution (negative, not finite, or summing to {sum})")]
    PolicyRow { state: usize, sum: f64 },
    #[error(
        "value iteration did not reach tol {tol} in {iterations} sweeps (last change {residual})"
    )]
    NotConverged {
        tol: f64,
        iterations: usize,
        residual: f64,
    },
    #[error("policy evaluation: the linear system is singular")]
    Singular,
}

/// One tile of the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tile {
    Start,
    Goal,
    Pit,
    Plate,
}

impl Tile {
    /// The reward for landing on this tile.
    pub fn reward(self) -> f64 {
        match self {
            Tile::Start | Tile::Plate => PLATE_REWARD,
            Tile::Pit => PIT_REWARD,
            Tile::Goal => GOAL_REWARD,
        }
    }

    /// The character of this tile in the text format.
    pub fn symbol(self) -> char {
        match self {
            Tile::Start => 'S',
            Tile::Goal => 'G',
            Tile::Pit => 'X',
            Tile::Plate => '.',
        }
    }

    fn from_symbol(c: char) -> Option<Self> {
        match c {
            'S' => Some(Tile::Start),
            'G' => Some(Tile::Goal),
            'X' => Some(Tile::Pit),
            '.' => Some(Tile::Plate),
            _ => None,
        }
    }
}

/// A CliffWalk grid: validated to hold exactly one start and one goal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CliffMap {
    width: usize,
    height: usize,
    tiles: Vec<Tile>,
    start: usize,
    goal: usize,
}

/// Notes where the map's one start or goal (`tile`) is, at `(line, column)`; a second one is
/// refused, naming both places.
fn note_once(
    slot: &mut Option<(usize, usize)>,
    tile: Tile,
    (line, column): (usize, usize),
) -> Result<(), MapError> {
    let Some((first_line, first_column)) = *slot else {
        *slot = Some((line, column));
        return Ok(());
    };
    Err(if tile == Tile::Start {
        MapError::DuplicateStart {
            line,
            column,
            first_line,
            first_column,
        }
    } else {
        MapError::DuplicateGoal {
            line,
            column,
            first_line,
            first_column,
        }
    })
}

impl CliffMap {
    /// Parses the text format (see the module documentation).
    pub fn parse(text: &str) -> Result<Self, MapError> {
        let lines: Vec<&str> = text.lines().map(str::trim_end).collect();
        let used = lines
            .iter()
            .rposition(|l| !l.is_empty())
            .map_or(0, |i| i + 1);
        if used == 0 {
            return Err(MapError::Empty);
        }
        let width = lines[0].chars().count();
        if width == 0 {
            return Err(MapError::BlankLine { line: 1 });
        }
        if width > MAX_MAP_SIDE || used > MAX_MAP_SIDE {
            return Err(MapError::TooLarge {
                width,
                height: used,
                max: MAX_MAP_SIDE,
            });
        }
        let mut tiles = Vec::with_capacity(width * used);
        let mut start: Option<(usize, usize)> = None;
        let mut goal: Option<(usize, usize)> = None;
        for (row, line) in lines[..used].iter().enumerate() {
            let line_no = row + 1;
            if line.is_empty() {
                return Err(MapError::BlankLine { line: line_no });
            }
            for (col, c) in line.chars().enumerate() {
                let column = col + 1;
                let tile = Tile::from_symbol(c).ok_or(MapError::UnknownCharacter {
                    line: line_no,
                    column,
                    found: c,
                })?;
                let slot = match tile {
                    Tile::Start => Some(&mut start),
                    Tile::Goal => Some(&mut goal),
                    _ => None,
                };
                if let Some(slot) = slot {
                    note_once(slot, tile, (line_no, column))?;
                }
                tiles.push(tile);
            }
            let found = line.chars().count();
            if found != width {
                return Err(MapError::RaggedRow {
                    line: line_no,
                    expected: width,
                    found,
                });
            }
        }
        let id = |(line, column): (usize, usize)| (line - 1) * width + (column - 1);
        let start = start.map(id).ok_or(MapError::NoStart)?;
        let goal = goal.map(id).ok_or(MapError::NoGoal)?;
        Ok(Self {
            width,
            height: used,
            tiles,
            start,
            goal,
        })
    }

    /// The built-in 15×15 map, [`DEFAULT_MAP`].
    pub fn default_map() -> Self {
        match Self::parse(DEFAULT_MAP) {
            Ok(map) => map,
            // DEFAULT_MAP is a constant checked by a unit test.
            Err(e) => unreachable!("the built-in map is valid: {e}"),
        }
    }

    /// Number of columns.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Number of rows.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Number of tiles, i.e. of states.
    pub fn num_states(&self) -> usize {
        self.tiles.len()
    }

    /// Id of the start tile.
    pub fn start(&self) -> usize {
        self.start
    }

    /// Id of the goal tile.
    pub fn goal(&self) -> usize {
        self.goal
    }

    /// The tile with id `state` (`row * width + col`); `None` outside the grid.
    pub fn tile(&self, state: usize) -> Option<Tile> {
        self.tiles.get(state).copied()
    }

    /// `(row, col)` of a tile id.
    pub fn position(&self, state: usize) -> (usize, usize) {
        (state / self.width, state % self.width)
    }

    /// Where `direction` (an action, 0..4) leads from `state`; the outer wall leaves it in place.
    pub fn neighbour(&self, state: usize, direction: usize) -> usize {
        let (row, col) = self.position(state);
        match direction {
            UP if row > 0 => state - self.width,
            RIGHT if col + 1 < self.width => state + 1,
            DOWN if row + 1 < self.height => state + self.width,
            LEFT if col > 0 => state - 1,
            _ => state,
        }
    }

    /// Number of pits.
    pub fn num_pits(&self) -> usize {
        self.tiles.iter().filter(|&&t| t == Tile::Pit).count()
    }
}

impl Default for CliffMap {
    fn default() -> Self {
        Self::default_map()
    }
}

impl FromStr for CliffMap {
    type Err = MapError;

    fn from_str(s: &str) -> Result<Self, MapError> {
        Self::parse(s)
    }
}

/// The text format, one row per line, each line ending with `\n` (so it parses back to the same map).
impl fmt::Display for CliffMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for row in self.tiles.chunks(self.width) {
            for tile in row {
                write!(f, "{}", tile.symbol())?;
            }
            writeln!(f)?;
        }
        Ok(())
    }
}

/// The CliffWalk environment. Observations are tile ids (`usize`), starting at the map's `S`.
///
/// An environment that was never seeded behaves as if `reset(Some(0))` had been called first.
#[derive(Debug, Clone)]
pub struct CliffWalk {
    map: CliffMap,
    p_success: f64,
    max_episode_steps: usize,
    rng: Rng,
    position: usize,
    phase: Phase,
    elapsed_steps: usize,
}

impl Default for CliffWalk {
    /// The paper's setting: the default map, p_success 0.9, a 500-step limit.
    fn default() -> Self {
        Self {
            map: CliffMap::default_map(),
            p_success: DEFAULT_P_SUCCESS,
            max_episode_steps: DEFAULT_MAX_EPISODE_STEPS,
            rng: crate::rng::seeded(0),
            position: 0,
            phase: Phase::NotReset,
            elapsed_steps: 0,
        }
    }
}

impl CliffWalk {
    /// A CliffWalk on `map` where the chosen move happens with probability `p_success` (in
    /// (0, 1]) and episodes are truncated after `max_episode_steps` steps (Gymnasium's
    /// `TimeLimit` semantics: a limit of 0 truncates at the first step, as a limit of 1 does).
    pub fn new(
        map: CliffMap,
        p_success: f64,
        max_episode_steps: usize,
    ) -> Result<Self, CliffWalkError> {
        // Written so that NaN is refused too.
        if !(p_success > 0.0 && p_success <= 1.0) {
            return Err(CliffWalkError::PSuccess(p_success));
        }
        Ok(Self {
            map,
            p_success,
            max_episode_steps,
            ..Self::default()
        })
    }

    /// The map.
    pub fn map(&self) -> &CliffMap {
        &self.map
    }

    /// Probability that the chosen move happens (before the random branch).
    pub fn p_success(&self) -> f64 {
        self.p_success
    }

    /// Number of states (tiles).
    pub fn num_states(&self) -> usize {
        self.map.num_states()
    }

    /// The tile the agent is on.
    pub fn position(&self) -> usize {
        self.position
    }

    /// Whether `state` ends the episode (the goal).
    pub fn is_terminal(&self, state: usize) -> bool {
        state == self.map.goal
    }

    /// The reward for landing on `state`.
    pub fn reward(&self, state: usize) -> f64 {
        self.map.tile(state).map_or(PLATE_REWARD, Tile::reward)
    }

    /// The exact transition model: `(next_state, probability)` for each of the 4 moves, the chosen
    /// one first. Entries may repeat a next state (walls); the probabilities sum to 1.
    pub fn transition_probs(&self, state: usize, action: usize) -> [(usize, f64); NUM_ACTIONS] {
        let slip = (1.0 - self.p_success) / NUM_ACTIONS as f64;
        let mut out = [(state, slip); NUM_ACTIONS];
        out[0] = (self.map.neighbour(state, action), self.p_success + slip);
        let others = (0..NUM_ACTIONS).filter(|&d| d != action);
        for (slot, direction) in out[1..].iter_mut().zip(others) {
            *slot = (self.map.neighbour(state, direction), slip);
        }
        out
    }

    /// The move that actually happens when `action` is chosen: `action` with probability
    /// `p_success`, otherwise a uniform draw among the 4 moves.
    fn sample_direction(&mut self, action: usize) -> usize {
        if self.rng.random::<f64>() < self.p_success {
            action
        } else {
            self.rng.random_range(0..NUM_ACTIONS)
        }
    }
}

impl crate::env::TabularEnv for CliffWalk {
    fn num_states(&self) -> usize {
        self.map.num_states()
    }
}

impl Env for CliffWalk {
    type Observation = usize;

    fn num_actions(&self) -> usize {
        NUM_ACTIONS
    }

    fn observation_dim(&self) -> usize {
        1
    }

    fn max_episode_steps(&self) -> usize {
        self.max_episode_steps
    }

    fn reset(&mut self, seed: Option<u64>) -> usize {
        if let Some(seed) = seed {
            self.rng = Rng::seed_from_u64(seed);
        }
        self.position = self.map.start;
        self.phase = Phase::Running;
        self.elapsed_steps = 0;
        self.position
    }

    fn step(&mut self, action: usize) -> Result<Step<usize>, EnvError> {
        match self.phase {
            Phase::NotReset => return Err(EnvError::NotReset),
            Phase::Over => return Err(EnvError::EpisodeOver),
            Phase::Running => {}
        }
        if action >= NUM_ACTIONS {
            return Err(EnvError::InvalidAction {
                action,
                num_actions: NUM_ACTIONS,
            });
        }
        let direction = self.sample_direction(action);
        let from = self.position;
        self.position = self.map.neighbour(from, direction);
        self.elapsed_steps += 1;
        let terminated = self.is_terminal(self.position);
        let truncated = self.elapsed_steps >= self.max_episode_steps;
        if terminated || truncated {
            self.phase = Phase::Over;
        }
        tracing::trace!(
            from,
            action,
            direction,
            to = self.position,
            "cliffwalk step"
        );
        Ok(Step {
            observation: self.position,
            reward: self.reward(self.position),
            terminated,
            truncated,
        })
    }

    /// The position is the physical state (one value).
    fn snapshot(&self) -> super::EnvState {
        super::EnvState {
            rng: crate::rng::RngState::of(&self.rng),
            phase: self.phase.code(),
            elapsed_steps: self.elapsed_steps as u64,
            state: vec![self.position as f64],
        }
    }

    fn restore(&mut self, saved: &super::EnvState) -> Result<(), EnvError> {
        let bad = |why: String| Err(EnvError::BadState(why));
        let position = match saved.state[..] {
            [p] if p >= 0.0 && p.fract() == 0.0 && (p as usize) < self.num_states() => p as usize,
            _ => return bad(format!("{:?} is no position of this map", saved.state)),
        };
        self.phase = Phase::from_code(saved.phase)?;
        self.rng = saved.rng.to_rng();
        self.position = position;
        self.elapsed_steps = saved.elapsed_steps as usize;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(map: &str, p_success: f64) -> CliffWalk {
        CliffWalk::new(CliffMap::parse(map).expect("valid map"), p_success, 100).expect("valid")
    }

    #[test]
    fn default_map_is_15_by_15_with_a_cliff_and_scattered_pits() {
        let map = CliffMap::default_map();
        assert_eq!((map.width(), map.height(), map.num_states()), (15, 15, 225));
        assert_eq!(map.position(map.start()), (14, 0));
        assert_eq!(map.position(map.goal()), (14, 14));
        for col in 1..14 {
            assert_eq!(map.tile(14 * 15 + col), Some(Tile::Pit));
        }
        let scattered = map.num_pits() - 13;
        assert!((6..=10).contains(&scattered), "{scattered} scattered pits");
        assert_eq!(map.to_string(), DEFAULT_MAP);
    }

    #[test]
    fn display_parses_back_to_the_same_map() {
        let map = CliffMap::parse("S.X\r\n..G  \n\n\n").expect("valid");
        assert_eq!(map.to_string(), "S.X\n..G\n");
        assert_eq!(map.to_string().parse::<CliffMap>(), Ok(map));
    }

    #[test]
    fn map_parse_errors_name_the_line_and_column() {
        let cases: [(&str, MapError); 9] = [
            ("", MapError::Empty),
            ("\n  \n", MapError::Empty),
            ("...\n..G\n.X.\n...", MapError::NoStart),
            ("S..\n...", MapError::NoGoal),
            (
                "S.G\n.S.",
                MapError::DuplicateStart {
                    line: 2,
                    column: 2,
                    first_line: 1,
                    first_column: 1,
                },
            ),
            (
                "SGG",
                MapError::DuplicateGoal {
                    line: 1,
                    column: 3,
                    first_line: 1,
                    first_column: 2,
                },
            ),
            (
                "S..\n..\nG..",
                MapError::RaggedRow {
                    line: 2,
                    expected: 3,
                    found: 2,
                },
            ),
            (
                "S.G\n.o.",
                MapError::UnknownCharacter {
                    line: 2,
                    column: 2,
                    found: 'o',
                },
            ),
            ("S.G\n\n...", MapError::BlankLine { line: 2 }),
        ];
        for (text, expected) in cases {
            assert_eq!(CliffMap::parse(text), Err(expected), "map {text:?}");
        }
        let message = CliffMap::parse("S.G\n.o.").unwrap_err().to_string();
        assert!(message.contains("line 2, column 2"), "{message}");
    }

    /// A `width`×`height` map of plates with S at the top left and G at the bottom right.
    fn open_map(width: usize, height: usize) -> String {
        let mut rows = vec![".".repeat(width); height];
        rows[0].replace_range(0..1, "S");
        let last = &mut rows[height - 1];
        last.replace_range(width - 1..width, "G");
        rows.join("\n")
    }

    #[test]
    fn maps_larger_than_the_limit_are_refused_naming_their_size_and_the_limit() {
        let side = MAX_MAP_SIDE;
        let largest = CliffMap::parse(&open_map(side, side)).expect("the largest map is allowed");
        assert_eq!(largest.num_states(), side * side);
        for (width, height) in [(side + 1, 2), (2, side + 1), (1000, 1000)] {
            let e = CliffMap::parse(&open_map(width, height)).unwrap_err();
            assert_eq!(
                e,
                MapError::TooLarge {
                    width,
                    height,
                    max: side
                }
            );
            assert_eq!(
                e.to_string(),
                format!("map is too large: {width}x{height} tiles (width x height, the width of line 1); at most 128x128 are allowed")
            );
        }
    }

    #[test]
    fn p_success_outside_zero_one_is_refused() {
        for p in [0.0, -0.1, 1.0001, f64::NAN] {
            let err = CliffWalk::new(CliffMap::default_map(), p, 10).unwrap_err();
            assert!(err.to_string().contains("p_success"), "{err}");
        }
        assert!(CliffWalk::new(CliffMap::default_map(), 1.0, 10).is_ok());
    }

    #[test]
    fn walls_leave_the_agent_in_place() {
        // A 2×2 map, deterministic moves.
        let mut e = env("S.\n.G", 1.0);
        e.reset(Some(0));
        for action in [UP, LEFT] {
            let step = e.step(action).expect("running");
            assert_eq!(step.observation, 0);
            assert_eq!(step.reward, PLATE_REWARD);
            assert!(!step.done());
        }
        assert_eq!(e.step(RIGHT).expect("running").observation, 1);
        let step = e.step(RIGHT).expect("running");
        assert_eq!((step.observation, step.reward), (1, PLATE_REWARD));
        assert_eq!(e.step(UP).expect("running").observation, 1);
        let step = e.step(DOWN).expect("running");
        assert_eq!(step.observation, 3);
        assert!(step.terminated);
    }

    #[test]
    fn pits_cost_five_and_do_not_end_the_episode_the_goal_pays_five_and_ends_it() {
        let mut e = env("SXG", 1.0);
        assert_eq!(e.reset(Some(1)), 0);
        let step = e.step(RIGHT).expect("running");
        assert_eq!(
            step,
            Step {
                observation: 1,
                reward: -5.0,
                terminated: false,
                truncated: false
            }
        );
        // Bumping into the wall while on the pit lands on the pit again.
        let step = e.step(UP).expect("running");
        assert_eq!(
            (step.observation, step.reward, step.done()),
            (1, -5.0, false)
        );
        // Back to the start tile: a plate.
        let step = e.step(LEFT).expect("running");
        assert_eq!((step.observation, step.reward), (0, -0.1));
        e.step(RIGHT).expect("running");
        let step = e.step(RIGHT).expect("running");
        assert_eq!(
            step,
            Step {
                observation: 2,
                reward: 5.0,
                terminated: true,
                truncated: false
            }
        );
        assert_eq!(e.step(LEFT), Err(EnvError::EpisodeOver));
    }

    #[test]
    fn the_chosen_move_happens_with_p_success_plus_a_quarter_of_the_rest() {
        // From the centre of a 3×3 map every move leads to a different tile and none to the goal.
        let mut e = env("...\n.S.\n..G", 0.9);
        let trials = 40_000;
        let mut counts = [0usize; 4];
        e.reset(Some(11));
        for _ in 0..trials {
            let s = e.step(RIGHT).expect("running").observation;
            let direction = [1, 5, 7, 3]
                .iter()
                .position(|&t| t == s)
                .expect("a neighbour");
            counts[direction] += 1;
            e.reset(None);
        }
        let freq = counts.map(|c| c as f64 / trials as f64);
        eprintln!("move frequencies (up, right, down, left) for action right: {freq:?}");
        assert!((freq[RIGHT] - 0.925).abs() < 0.006, "{freq:?}");
        for d in [UP, DOWN, LEFT] {
            assert!((freq[d] - 0.025).abs() < 0.004, "{freq:?}");
        }
    }

    #[test]
    fn transition_probs_sum_to_one_and_favour_the_chosen_move() {
        let e = CliffWalk::default();
        for s in 0..e.num_states() {
            for a in 0..4 {
                let t = e.transition_probs(s, a);
                let total: f64 = t.iter().map(|(_, p)| p).sum();
                assert!((total - 1.0).abs() < 1e-15);
                assert_eq!(t[0], (e.map().neighbour(s, a), 0.925));
            }
        }
    }
}
