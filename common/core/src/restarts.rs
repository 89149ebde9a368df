//! The one restart rule of a run's supervisors: the launcher's for its actors, its learner and
//! its expert (`alfd_launcher::expert_lifecycle`), a joined host's for its actors (through the
//! run's roster, `alfd_bridge::roster`), and the expert process's for the processes of its
//! several experts (`alfd-expert`'s `member.rs`). A process that ended without
//! finishing its work is started again while its restarts are fewer than the run's
//! `--max-restarts`, unless it refused its input (exit code 2): the same input would be refused
//! again. Pure: a supervisor says how a process ended and carries out the verdict.

use std::collections::BTreeMap;
use std::fmt;

/// The exit code of a process that refuses its input (a bad config, a missing file).
pub const BAD_INPUT_CODE: i32 = 2;

/// How a supervised process ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// It exited successfully with its work done (an actor that played its share).
    Finished,
    /// It refused its input (exit code 2).
    Refused,
    /// Anything else: killed by a signal, a failure, or a successful exit with work left.
    Crashed,
}

impl Ended {
    /// How a process ended with exit code `code` (`None`: killed by a signal); `done`: its work
    /// was done.
    pub fn of(code: Option<i32>, done: bool) -> Self {
        match code {
            Some(0) if done => Ended::Finished,
            Some(BAD_INPUT_CODE) => Ended::Refused,
            _ => Ended::Crashed,
        }
    }
}

/// What the supervisor does about a process that ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// Nothing: it finished.
    Done,
    /// Start it again; this is its `nth` restart (1-based).
    Restart { nth: u32 },
    /// Start it no more, for this reason.
    GiveUp(GiveUp),
}

/// Why a process is not started again.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GiveUp {
    /// It refused its input.
    Refused,
    /// Its restarts are used up.
    Exhausted { restarts: u32, max: u32 },
}

impl fmt::Display for GiveUp {
    /// Reads after the process's name: "alfd-actor actor-1 ..., and {this}".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GiveUp::Refused => write!(
                f,
                "refused its input (exit code {BAD_INPUT_CODE}), which a restart would meet again"
            ),
            GiveUp::Exhausted { restarts, max } => write!(
                f,
                "was restarted {restarts} times already (--max-restarts {max})"
            ),
        }
    }
}

/// The restarts of the processes one supervisor keeps, by key (an actor id, "the learner").
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Restarts<K> {
    max: u32,
    counts: BTreeMap<K, u32>,
}

impl<K: Ord + Clone> Restarts<K> {
    /// At most `max` restarts per key.
    pub fn new(max: u32) -> Self {
        Self {
            max,
            counts: BTreeMap::new(),
        }
    }

    /// The restarts of `key` so far.
    pub fn of(&self, key: &K) -> u32 {
        self.counts.get(key).copied().unwrap_or(0)
    }

    /// The restarts of every key so far.
    pub fn total(&self) -> u32 {
        self.counts.values().sum()
    }

    /// `key` starts counting again (a new host holds that actor id).
    pub fn forget(&mut self, key: &K) {
        self.counts.remove(key);
    }

    /// The process `key` ended `how`: the verdict, a restart counted when it is one.
    pub fn ended(&mut self, key: &K, how: Ended) -> Verdict {
        match how {
            Ended::Finished => Verdict::Done,
            Ended::Refused => Verdict::GiveUp(GiveUp::Refused),
            Ended::Crashed => {
                let restarts = self.of(key);
                if restarts >= self.max {
                    return Verdict::GiveUp(GiveUp::Exhausted {
                        restarts,
                        max: self.max,
                    });
                }
                self.counts.insert(key.clone(), restarts + 1);
                Verdict::Restart { nth: restarts + 1 }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn how_a_process_ended_follows_its_exit_code_and_its_work() {
        assert_eq!(Ended::of(Some(0), true), Ended::Finished);
        // A successful exit with work left is a crash: something stopped it early.
        assert_eq!(Ended::of(Some(0), false), Ended::Crashed);
        assert_eq!(Ended::of(Some(2), false), Ended::Refused);
        assert_eq!(Ended::of(Some(2), true), Ended::Refused);
        assert_eq!(Ended::of(Some(1), true), Ended::Crashed);
        assert_eq!(Ended::of(None, true), Ended::Crashed, "killed by a signal");
    }

    #[test]
    fn a_crashed_process_restarts_until_its_restarts_are_used_up_per_key() {
        let mut r = Restarts::new(2);
        assert_eq!(r.ended(&1u16, Ended::Crashed), Verdict::Restart { nth: 1 });
        assert_eq!(r.ended(&1, Ended::Crashed), Verdict::Restart { nth: 2 });
        let spent = GiveUp::Exhausted {
            restarts: 2,
            max: 2,
        };
        assert_eq!(r.ended(&1, Ended::Crashed), Verdict::GiveUp(spent.clone()));
        assert_eq!(
            spent.to_string(),
            "was restarted 2 times already (--max-restarts 2)"
        );
        // Another key has restarts of its own; a finished process is no restart.
        assert_eq!(r.ended(&2, Ended::Crashed), Verdict::Restart { nth: 1 });
        assert_eq!(r.ended(&2, Ended::Finished), Verdict::Done);
        assert_eq!((r.of(&1), r.of(&2), r.total()), (2, 1, 3));
        // A new holder of key 1 counts from zero.
        r.forget(&1);
        assert_eq!(r.ended(&1, Ended::Crashed), Verdict::Restart { nth: 1 });
    }

    #[test]
    fn a_process_that_refused_its_input_is_not_restarted_and_costs_no_restart() {
        let mut r = Restarts::new(5);
        assert_eq!(
            r.ended(&(), Ended::Refused),
            Verdict::GiveUp(GiveUp::Refused)
        );
        assert_eq!(r.total(), 0);
        assert!(GiveUp::Refused.to_string().contains("exit code 2"));
        let mut none = Restarts::new(0);
        assert!(matches!(
            none.ended(&(), Ended::Crashed),
            Verdict::GiveUp(_)
        ));
    }
}
