//! The episode life cycle the classic-control environments share: the generator `reset(seed)`
//! reseeds, the step counter of Gymnasium's `TimeLimit`, and the refusal of a step before the
//! first reset or after the end.

use rand::SeedableRng;

use super::EnvError;
use crate::rng::Rng;

/// Where the environment is in its episode life cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Phase {
    NotReset,
    Running,
    Over,
}

impl Phase {
    /// Its number in an [`super::EnvState`].
    pub(crate) fn code(self) -> u8 {
        match self {
            Phase::NotReset => 0,
            Phase::Running => 1,
            Phase::Over => 2,
        }
    }

    pub(crate) fn from_code(code: u8) -> Result<Self, EnvError> {
        Ok(match code {
            0 => Phase::NotReset,
            1 => Phase::Running,
            2 => Phase::Over,
            p => return Err(EnvError::BadState(format!("unknown phase {p}"))),
        })
    }
}

/// An environment's generator, step counter and step limit.
///
/// A fresh one behaves as if `begin(Some(0))` had been called (the core never draws entropy from
/// the operating system), except that it refuses steps until the first `begin`.
#[derive(Debug, Clone)]
pub(crate) struct Episode {
    max_steps: usize,
    rng: Rng,
    phase: Phase,
    elapsed_steps: usize,
}

impl Episode {
    /// Episodes truncated after `max_steps` steps (a limit of 0 truncates at the first step, as
    /// a limit of 1 does, as in Gymnasium).
    pub(crate) fn new(max_steps: usize) -> Self {
        Self {
            max_steps,
            rng: crate::rng::seeded(0),
            phase: Phase::NotReset,
            elapsed_steps: 0,
        }
    }

    pub(crate) fn max_steps(&self) -> usize {
        self.max_steps
    }

    /// Starts an episode: reseeds the generator when `seed` is given (Gymnasium's
    /// `reset(seed=...)`), continues it otherwise, and returns it to draw the initial state.
    pub(crate) fn begin(&mut self, seed: Option<u64>) -> &mut Rng {
        if let Some(seed) = seed {
            self.rng = Rng::seed_from_u64(seed);
        }
        self.start_at_given_state();
        &mut self.rng
    }

    /// Starts an episode without touching the generator (an initial state set from outside).
    pub(crate) fn start_at_given_state(&mut self) {
        self.phase = Phase::Running;
        self.elapsed_steps = 0;
    }

    /// The generator, phase and step count, with `state` (the environment's physical state).
    pub(crate) fn snapshot(&self, state: &[f64]) -> super::EnvState {
        super::EnvState {
            rng: crate::rng::RngState::of(&self.rng),
            phase: self.phase.code(),
            elapsed_steps: self.elapsed_steps as u64,
            state: state.to_vec(),
        }
    }

    /// Restores what [`Episode::snapshot`] saved and writes the physical state into `state`.
    pub(crate) fn restore(
        &mut self,
        saved: &super::EnvState,
        state: &mut [f64],
    ) -> Result<(), EnvError> {
        if saved.state.len() != state.len() {
            return Err(EnvError::BadState(format!(
                "{} state values where this environment has {}",
                saved.state.len(),
                state.len()
            )));
        }
        self.phase = Phase::from_code(saved.phase)?;
        self.rng = saved.rng.to_rng();
        self.elapsed_steps = saved.elapsed_steps as usize;
        state.copy_from_slice(&saved.state);
        Ok(())
    }

    /// Refuses a step before the first reset, after the end, or with an action outside
    /// `0..num_actions`, in that order of precedence.
    pub(crate) fn check_step(&self, action: usize, num_actions: usize) -> Result<(), EnvError> {
        match self.phase {
            Phase::NotReset => Err(EnvError::NotReset),
            Phase::Over => Err(EnvError::EpisodeOver),
            Phase::Running if action >= num_actions => Err(EnvError::InvalidAction {
                action,
                num_actions,
            }),
            Phase::Running => Ok(()),
        }
    }

    /// Counts a step that `terminated` (or not) and returns whether the limit truncates it; the
    /// episode is over after either.
    pub(crate) fn count_step(&mut self, terminated: bool) -> bool {
        self.elapsed_steps += 1;
        let truncated = self.elapsed_steps >= self.max_steps;
        if terminated || truncated {
            self.phase = Phase::Over;
        }
        truncated
    }
}
