//! The expert's generations in a live run as a pure state machine: which expert process runs,
//! which one answers, make-before-break swaps, and restarts after a crash. The launcher feeds it
//! what happened (a process reported a state, exited, a swap was asked for, time passed) and
//! carries out the [`Action`]s it returns; the machine itself starts nothing and reads no clock.
//!
//! The rule that keeps the budget safe is one: a generation is made active only once it reported
//! `standby` and **no other expert process is alive**. A swap tells the old expert to go (a newer
//! generation exists) once the new one is up; a restart has no old process to wait for. Either
//! way the new expert reads `demos.jsonl` back when it becomes active, so the budget and the
//! demonstrations carry over and none is counted twice.
//!
//! While no expert is active (`active = 0`) the actors act on their own at once; their queries
//! cost nothing.
//!
//! An expert served by another host (`alfd join --expert`) that is lost (its host died, the
//! link dropped, or its process ended there) is restarted on this host under the same name, as
//! after a crash ([`ExpertLifecycle::lost`]); but if that replacement cannot start here (a
//! `python:` module only the other host has) or no restart is left, the run goes on without an
//! expert ([`Action::NoExpert`]): the actors act on their own, and a later swap may bring one.

use std::time::{Duration, Instant};

use alfd_common::config::{changed_roster, RosterChange};
use alfd_common::restarts::{Ended, Restarts, Verdict};
use serde::{Deserialize, Serialize};

/// A request to swap the expert (`swap-expert.request.json`): for `expert`, or with `change`
/// for the run's experts with `expert` added or removed (`alfd expert add|remove`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SwapRequest {
    pub id: String,
    pub expert: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub change: Option<RosterChange>,
}

/// How long a new expert may take to report `standby`.
pub const START_TIMEOUT: Duration = Duration::from_secs(60);
/// How long an expert told to go may take to exit before it is killed.
pub const LEAVE_TIMEOUT: Duration = Duration::from_secs(30);

/// What the launcher must do.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    /// Start `alfd-expert` as `generation` with demonstrator `name`.
    Spawn { generation: u16, name: String },
    /// Kill the process of `generation` (it will be reported as exited).
    Kill { generation: u16 },
    /// Publish these expert fields of the control message.
    Control { newest: u16, active: u16 },
    /// Answer the `alfd swap-expert` that made `request`.
    Respond {
        request: SwapRequest,
        ok: bool,
        message: String,
        /// The expert being replaced.
        from: String,
        generation: u16,
    },
    /// A restarted expert answers again, `took` after its predecessor died.
    Recovered {
        generation: u16,
        died: u16,
        took: Duration,
    },
    /// The run cannot go on: `message` says why (about the process of `generation`).
    Fail { generation: u16, message: String },
    /// The run goes on without an expert (the actors act on their own): `message` says why
    /// (about the process of `generation`, the replacement of a lost remote expert).
    NoExpert { generation: u16, message: String },
}

/// How an expert process ended, as the launcher saw it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Exit {
    /// "exited with status 1", "was killed by signal 9".
    pub how: String,
    /// The exit code, if it exited.
    pub code: Option<i32>,
    /// The error it printed last, if any (from its log).
    pub reason: Option<String>,
}

impl Exit {
    fn describe(&self) -> String {
        match &self.reason {
            Some(r) => format!("{}: {r}", self.how),
            None => self.how.clone(),
        }
    }
}

/// Why a generation is on its way in.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Why {
    /// The run's first expert.
    Start,
    /// `alfd swap-expert` asked for it; `from` is the expert it replaces.
    Swap { request: SwapRequest, from: String },
    /// Its predecessor `died` at `since`; `remote`: it ran on another host, so this host may
    /// not be able to start it (the run then goes on without an expert rather than failing).
    Restart {
        died: u16,
        since: Instant,
        remote: bool,
    },
}

/// A generation started but not yet answering.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Incoming {
    generation: u16,
    name: String,
    why: Why,
    started: Instant,
    /// When it reported `standby` (and older experts were told to go).
    standby: Option<Instant>,
}

/// The expert generations of one run.
#[derive(Debug, Clone)]
pub struct ExpertLifecycle {
    /// The expert that answers (or answered last): generation and demonstrator.
    current: Option<(u16, String)>,
    incoming: Option<Incoming>,
    /// Generations whose process is running.
    alive: Vec<u16>,
    last_generation: u16,
    newest: u16,
    active: u16,
    /// The expert's restarts after crashes (one key: the run's expert, whichever generation).
    restarts: Restarts<()>,
    swaps: u32,
}

impl ExpertLifecycle {
    /// A run with at most `max_restarts` restarts of its expert after crashes.
    pub fn new(max_restarts: u32) -> Self {
        Self {
            current: None,
            incoming: None,
            alive: Vec::new(),
            last_generation: 0,
            newest: 0,
            active: 0,
            restarts: Restarts::new(max_restarts),
            swaps: 0,
        }
    }

    /// Starts the run's first expert, `name`.
    pub fn start(&mut self, name: &str, now: Instant) -> Vec<Action> {
        let mut out = Vec::new();
        self.spawn(name, Why::Start, now, &mut out);
        self.newest = self.last_generation;
        out
    }

    /// The generation that answers queries (0: none right now).
    pub fn active(&self) -> u16 {
        self.active
    }

    /// The expert answering or last answering, by name.
    pub fn current_name(&self) -> Option<&str> {
        self.current.as_ref().map(|c| c.1.as_str())
    }

    /// Whether an expert answers and no swap or restart is under way.
    pub fn settled(&self) -> bool {
        self.incoming.is_none() && self.current.is_some() && self.active != 0
    }

    pub fn restarts(&self) -> u32 {
        self.restarts.of(&())
    }

    pub fn swaps(&self) -> u32 {
        self.swaps
    }

    /// The expert of `generation` reported `standby` (up, not answering).
    pub fn standby(&mut self, generation: u16, now: Instant) -> Vec<Action> {
        let mut out = Vec::new();
        let Some(inc) = self.incoming.as_mut() else {
            return out;
        };
        if inc.generation != generation || inc.standby.is_some() {
            return out;
        }
        inc.standby = Some(now);
        // Make before break: the new one is up, so every older one may go now.
        self.newest = generation;
        if self.alive.iter().any(|&g| g != generation) {
            self.active = 0;
        }
        self.publish(&mut out);
        self.try_activate(&mut out);
        out
    }

    /// The expert of `generation` reported `running`: it read `demos.jsonl` back and answers.
    pub fn running(&mut self, generation: u16, now: Instant) -> Vec<Action> {
        let mut out = Vec::new();
        let Some(inc) = self.incoming.take_if(|i| i.generation == generation) else {
            return out;
        };
        if self.active != generation {
            // Not made active yet (a stale report): still on its way in.
            self.incoming = Some(inc);
            return out;
        }
        self.current = Some((generation, inc.name.clone()));
        match inc.why {
            Why::Start => {}
            Why::Swap { request, from } => {
                self.swaps += 1;
                out.push(Action::Respond {
                    request,
                    ok: true,
                    message: "swapped".to_owned(),
                    from,
                    generation,
                });
            }
            Why::Restart { died, since, .. } => out.push(Action::Recovered {
                generation,
                died,
                took: now.saturating_duration_since(since),
            }),
        }
        out
    }

    /// The process of `generation` ended.
    pub fn exited(&mut self, generation: u16, exit: &Exit, now: Instant) -> Vec<Action> {
        self.ended(generation, exit, now, false)
    }

    /// The process of `generation` ran on another host and is gone (it ended there, or its
    /// host or the link was lost). As [`exited`](Self::exited), except that its replacement
    /// on this host is a best effort: if it cannot start here, or no restart is left, the run
    /// goes on without an expert ([`Action::NoExpert`]) instead of failing.
    pub fn lost(&mut self, generation: u16, exit: &Exit, now: Instant) -> Vec<Action> {
        self.ended(generation, exit, now, true)
    }

    fn ended(&mut self, generation: u16, exit: &Exit, now: Instant, remote: bool) -> Vec<Action> {
        let mut out = Vec::new();
        self.alive.retain(|&g| g != generation);
        if self.active == generation {
            // Nobody answers for now: the actors act on their own without waiting.
            self.active = 0;
            self.publish(&mut out);
        }
        let incoming_died = self
            .incoming
            .as_ref()
            .is_some_and(|i| i.generation == generation);
        let current_died = self.current.as_ref().is_some_and(|c| c.0 == generation);
        if incoming_died {
            let inc = self.incoming.take().expect("checked");
            match inc.why {
                // Killed by a signal on its way in (not a failure of its own): the run's first
                // expert is started again, a restart like any other.
                Why::Start
                    if exit.code.is_none()
                        && matches!(
                            self.restarts.ended(&(), Ended::Crashed),
                            Verdict::Restart { .. }
                        ) =>
                {
                    self.spawn(&inc.name, Why::Start, now, &mut out);
                    self.newest = self.last_generation;
                }
                Why::Start => out.push(Action::Fail {
                    generation,
                    message: format!(
                        "alfd-expert (expert-{generation}) {} before the run began",
                        exit.describe()
                    ),
                }),
                Why::Swap { request, from } => {
                    out.push(Action::Respond {
                        request,
                        ok: false,
                        message: format!("the new expert {}", exit.describe()),
                        from,
                        generation,
                    });
                    self.after_failed_swap(now, &mut out);
                }
                Why::Restart { remote: true, .. } => self.go_on_without(
                    generation,
                    format!(
                        "alfd-expert (expert-{generation}), started here in place of the lost \
                         remote expert, {}",
                        exit.describe()
                    ),
                    &mut out,
                ),
                Why::Restart { .. } => self.restart(generation, exit, now, false, &mut out),
            }
        } else if current_died {
            match &self.incoming {
                // Its successor is on its way in (a swap): it becomes active once up.
                Some(_) => self.try_activate(&mut out),
                None => self.restart(generation, exit, now, remote, &mut out),
            }
        } else {
            // An older generation that was told to go, or one that was killed.
            self.try_activate(&mut out);
        }
        out
    }

    /// `alfd swap-expert` asks for `request.expert`.
    pub fn swap(&mut self, request: SwapRequest, now: Instant) -> Vec<Action> {
        let mut out = Vec::new();
        let busy = match self.incoming.as_ref().map(|i| &i.why) {
            Some(Why::Start) => Some("the run is still starting".to_owned()),
            Some(Why::Swap { request: r, .. }) => Some(format!(
                "another swap (to {}) is in progress; try again when it is done",
                r.expert
            )),
            Some(Why::Restart { .. }) => Some(
                "the expert is being restarted after a crash; try again when it answers".to_owned(),
            ),
            None => None,
        };
        if let Some(message) = busy {
            out.push(Action::Respond {
                request,
                ok: false,
                message,
                from: self.current_name().unwrap_or_default().to_owned(),
                generation: self.last_generation,
            });
            return out;
        }
        let from = self.current_name().unwrap_or_default().to_owned();
        let mut request = request;
        if let Some(change) = request.change {
            match changed_roster(&from, change, &request.expert) {
                Ok(name) => request.expert = name,
                Err(message) => {
                    let generation = self.last_generation;
                    out.push(Action::Respond {
                        request,
                        ok: false,
                        message,
                        from,
                        generation,
                    });
                    return out;
                }
            }
        }
        let name = request.expert.clone();
        self.spawn(&name, Why::Swap { request, from }, now, &mut out);
        out
    }

    /// Timeouts: a new expert that does not come up, an old one that does not leave.
    pub fn tick(&mut self, now: Instant) -> Vec<Action> {
        let mut out = Vec::new();
        let Some(inc) = self.incoming.clone() else {
            return out;
        };
        match inc.standby {
            None if now.saturating_duration_since(inc.started) > START_TIMEOUT => {
                let late = format!(
                    "did not report standby within {} s",
                    START_TIMEOUT.as_secs()
                );
                match inc.why {
                    Why::Swap { request, from } => {
                        self.incoming = None;
                        out.push(Action::Kill {
                            generation: inc.generation,
                        });
                        out.push(Action::Respond {
                            request,
                            ok: false,
                            message: format!("the new expert {late}"),
                            from,
                            generation: inc.generation,
                        });
                        self.after_failed_swap(now, &mut out);
                    }
                    Why::Restart { remote: true, .. } => {
                        out.push(Action::Kill {
                            generation: inc.generation,
                        });
                        self.go_on_without(
                            inc.generation,
                            format!(
                                "alfd-expert (expert-{}), started here in place of the lost \
                                 remote expert, {late}",
                                inc.generation
                            ),
                            &mut out,
                        );
                    }
                    Why::Start | Why::Restart { .. } => out.push(Action::Fail {
                        generation: inc.generation,
                        message: format!("alfd-expert (expert-{}) {late}", inc.generation),
                    }),
                }
            }
            Some(told) if now.saturating_duration_since(told) > LEAVE_TIMEOUT => {
                for &g in self.alive.iter().filter(|&&g| g < inc.generation) {
                    out.push(Action::Kill { generation: g });
                }
            }
            _ => {}
        }
        out
    }

    /// A swap failed: the old expert answers again if it is still there, else it is restarted.
    fn after_failed_swap(&mut self, now: Instant, out: &mut Vec<Action>) {
        let Some((generation, _)) = self.current.clone() else {
            return;
        };
        if self.alive.contains(&generation) && self.newest <= generation {
            // It was never told to go.
            if self.active != generation {
                self.active = generation;
                self.publish(out);
            }
        } else {
            let exit = Exit {
                how: "left for a swap that failed".to_owned(),
                code: None,
                reason: None,
            };
            self.restart(generation, &exit, now, false, out);
        }
    }

    /// Starts the current expert again as a new generation, if restarts are left (`remote`:
    /// the one that died ran on another host).
    fn restart(
        &mut self,
        died: u16,
        exit: &Exit,
        now: Instant,
        remote: bool,
        out: &mut Vec<Action>,
    ) {
        let Some((_, name)) = self.current.clone() else {
            return;
        };
        let why = match self.restarts.ended(&(), Ended::of(exit.code, false)) {
            Verdict::GiveUp(why) => why,
            Verdict::Restart { .. } | Verdict::Done => {
                let why = Why::Restart {
                    died,
                    since: now,
                    remote,
                };
                return self.spawn(&name, why, now, out);
            }
        };
        let message = if remote {
            format!(
                "the remote expert-{died} {}, and the expert {why}",
                exit.describe()
            )
        } else {
            format!(
                "alfd-expert (expert-{died}) {}, and the expert {why}",
                exit.describe()
            )
        };
        if remote {
            self.go_on_without(died, message, out);
        } else {
            out.push(Action::Fail {
                generation: died,
                message,
            });
        }
    }

    /// No expert from now on (until a swap brings one): nobody answers, the actors act on
    /// their own.
    fn go_on_without(&mut self, generation: u16, message: String, out: &mut Vec<Action>) {
        self.incoming = None;
        self.current = None;
        if self.active != 0 {
            self.active = 0;
            self.publish(out);
        }
        out.push(Action::NoExpert {
            generation,
            message,
        });
    }

    fn spawn(&mut self, name: &str, why: Why, now: Instant, out: &mut Vec<Action>) {
        self.last_generation += 1;
        let generation = self.last_generation;
        self.alive.push(generation);
        self.incoming = Some(Incoming {
            generation,
            name: name.to_owned(),
            why,
            started: now,
            standby: None,
        });
        out.push(Action::Spawn {
            generation,
            name: name.to_owned(),
        });
    }

    /// Makes the incoming generation active once it is up and alone.
    fn try_activate(&mut self, out: &mut Vec<Action>) {
        let Some(inc) = &self.incoming else {
            return;
        };
        let alone = self.alive.iter().all(|&g| g == inc.generation);
        if inc.standby.is_some() && alone && self.active != inc.generation {
            self.active = inc.generation;
            self.publish(out);
        }
    }

    fn publish(&self, out: &mut Vec<Action>) {
        out.push(Action::Control {
            newest: self.newest,
            active: self.active,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn killed() -> Exit {
        Exit {
            how: "was killed by signal 9".to_owned(),
            code: None,
            reason: None,
        }
    }

    fn request(expert: &str) -> SwapRequest {
        SwapRequest {
            id: format!("req-{expert}"),
            expert: expert.to_owned(),
            change: None,
        }
    }

    fn spawned(actions: &[Action]) -> Vec<u16> {
        actions
            .iter()
            .filter_map(|a| match a {
                Action::Spawn { generation, .. } => Some(*generation),
                _ => None,
            })
            .collect()
    }

    fn last_control(actions: &[Action]) -> Option<(u16, u16)> {
        actions.iter().rev().find_map(|a| match a {
            Action::Control { newest, active } => Some((*newest, *active)),
            _ => None,
        })
    }

    /// A run whose expert `cartpole-1000` (generation 1) answers.
    fn running(max_restarts: u32, t0: Instant) -> ExpertLifecycle {
        let mut e = ExpertLifecycle::new(max_restarts);
        assert_eq!(
            e.start("cartpole-1000", t0),
            vec![Action::Spawn {
                generation: 1,
                name: "cartpole-1000".into()
            }]
        );
        assert_eq!(e.active(), 0);
        assert_eq!(last_control(&e.standby(1, t0)), Some((1, 1)));
        assert!(e.running(1, t0).is_empty());
        assert!(e.settled());
        e
    }

    #[test]
    fn a_crashed_expert_is_restarted_as_a_new_generation_and_made_active_once_up() {
        let t0 = Instant::now();
        let mut e = running(5, t0);
        let t1 = t0 + Duration::from_secs(3);
        let a = e.exited(1, &killed(), t1);
        // Nobody answers at once (actors stop waiting), and generation 2 starts.
        assert_eq!(
            a,
            vec![
                Action::Control {
                    newest: 1,
                    active: 0
                },
                Action::Spawn {
                    generation: 2,
                    name: "cartpole-1000".into()
                }
            ]
        );
        assert_eq!(e.restarts(), 1);
        assert!(!e.settled());
        // Its `running` before it was made active is not taken as an answer.
        assert!(e.running(2, t1).is_empty());
        assert_eq!(last_control(&e.standby(2, t1)), Some((2, 2)));
        assert!(
            e.standby(2, t1).is_empty(),
            "a repeated standby changes nothing"
        );
        let t2 = t1 + Duration::from_millis(250);
        assert_eq!(
            e.running(2, t2),
            vec![Action::Recovered {
                generation: 2,
                died: 1,
                took: Duration::from_millis(250)
            }]
        );
        assert!(e.settled());
        assert_eq!((e.active(), e.current_name()), (2, Some("cartpole-1000")));
    }

    #[test]
    fn an_expert_added_or_removed_starts_the_run_s_experts_changed_and_a_bad_change_is_refused() {
        let t0 = Instant::now();
        let mut e = ExpertLifecycle::new(5);
        e.start("a+b", t0);
        e.standby(1, t0);
        e.running(1, t0);
        let change = |expert: &str, change| SwapRequest {
            id: "x".into(),
            expert: expert.into(),
            change: Some(change),
        };
        let a = e.swap(change("c", RosterChange::Add), t0);
        assert_eq!(
            a,
            vec![Action::Spawn {
                generation: 2,
                name: "a+b+c".into()
            }]
        );
        e.standby(2, t0);
        e.exited(1, &killed(), t0);
        e.running(2, t0);
        assert_eq!(e.current_name(), Some("a+b+c"));
        let a = e.swap(change("a", RosterChange::Remove), t0);
        assert_eq!(spawned(&a), vec![3]);
        assert!(matches!(&a[0], Action::Spawn { name, .. } if name == "b+c"));
        // A swap is under way: a second change waits its turn; then a bad one is refused.
        let busy = e.swap(change("c", RosterChange::Remove), t0);
        assert!(matches!(&busy[0], Action::Respond { ok: false, .. }));
        e.standby(3, t0);
        e.exited(2, &killed(), t0);
        e.running(3, t0);
        let a = e.swap(change("a", RosterChange::Remove), t0);
        match &a[..] {
            [Action::Respond { ok, message, .. }] => {
                assert!(!ok && message.contains("not one"), "{message}")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_first_expert_killed_on_its_way_in_is_started_again_and_one_that_fails_is_not() {
        let t0 = Instant::now();
        let mut e = ExpertLifecycle::new(1);
        assert_eq!(spawned(&e.start("cartpole-1000", t0)), vec![1]);
        // SIGKILL before it answered: generation 2, the same expert, is the run's first now.
        assert_eq!(spawned(&e.exited(1, &killed(), t0)), vec![2]);
        assert_eq!(e.restarts(), 1);
        assert_eq!(last_control(&e.standby(2, t0)), Some((2, 2)));
        assert!(e.running(2, t0).is_empty());
        assert!(e.settled());
        assert_eq!(e.current_name(), Some("cartpole-1000"));
        // An expert that fails on its own at start (bad input, exit 2) fails the run, and so
        // does a kill once no restart is left.
        let bad = Exit {
            how: "exited with status 2".to_owned(),
            code: Some(2),
            reason: Some("unknown expert".to_owned()),
        };
        let mut e = ExpertLifecycle::new(5);
        e.start("nobody", t0);
        let a = e.exited(1, &bad, t0);
        assert!(matches!(a.last(), Some(Action::Fail { .. })), "{a:?}");
        let mut e = ExpertLifecycle::new(0);
        e.start("cartpole-1000", t0);
        let a = e.exited(1, &killed(), t0);
        assert!(matches!(a.last(), Some(Action::Fail { .. })), "{a:?}");
    }

    #[test]
    fn restarts_are_limited_and_a_refusing_restart_fails_the_run_at_once() {
        let t0 = Instant::now();
        let mut e = running(2, t0);
        assert_eq!(spawned(&e.exited(1, &killed(), t0)), vec![2]);
        // The restarted one crashes before it is up: another restart (the second and last).
        assert_eq!(spawned(&e.exited(2, &killed(), t0)), vec![3]);
        let a = e.exited(3, &killed(), t0);
        assert!(spawned(&a).is_empty());
        let Some(Action::Fail {
            generation,
            message,
        }) = a.last()
        else {
            panic!("{a:?}")
        };
        assert_eq!(*generation, 3);
        assert!(
            message.contains("restarted 2 times already") && message.contains("--max-restarts 2"),
            "{message}"
        );

        // Bad input (exit code 2, e.g. a bad line in demos.jsonl) is not retried.
        let mut e = running(5, t0);
        e.exited(1, &killed(), t0);
        let refused = Exit {
            how: "exited with status 2".into(),
            code: Some(2),
            reason: Some("demos.jsonl line 7: not a demonstration record".into()),
        };
        let a = e.exited(2, &refused, t0);
        assert!(
            matches!(a.last(), Some(Action::Fail { message, .. }) if message.contains("line 7")),
            "{a:?}"
        );
        assert_eq!(e.restarts(), 1);
    }

    #[test]
    fn the_first_expert_failing_to_start_fails_the_run() {
        let t0 = Instant::now();
        let mut e = ExpertLifecycle::new(5);
        e.start("cartpole-1000", t0);
        // Failing on its own (an exit status; a kill is started again, tested above).
        let failed = Exit {
            how: "exited with status 1".to_owned(),
            code: Some(1),
            reason: None,
        };
        let a = e.exited(1, &failed, t0);
        assert!(
            matches!(a.last(), Some(Action::Fail { generation: 1, .. })),
            "{a:?}"
        );
        let mut e = ExpertLifecycle::new(5);
        e.start("cartpole-1000", t0);
        assert!(e.tick(t0 + START_TIMEOUT / 2).is_empty());
        let a = e.tick(t0 + START_TIMEOUT + Duration::from_secs(1));
        assert!(matches!(a.last(), Some(Action::Fail { .. })), "{a:?}");
    }

    #[test]
    fn a_swap_is_made_before_broken() {
        let t0 = Instant::now();
        let mut e = running(5, t0);
        assert_eq!(spawned(&e.swap(request("cartpole-200"), t0)), vec![2]);
        // The old one answers until the new one is up; then it is told to go.
        assert_eq!(e.active(), 1);
        assert_eq!(last_control(&e.standby(2, t0)), Some((2, 0)));
        // The new one is made active only once the old one has exited.
        assert_eq!(
            e.exited(1, &killed(), t0),
            vec![Action::Control {
                newest: 2,
                active: 2
            }]
        );
        assert_eq!(e.restarts(), 0, "an expert leaving for a swap is no crash");
        let a = e.running(2, t0);
        assert!(
            matches!(&a[..], [Action::Respond { ok: true, from, generation: 2, .. }] if from == "cartpole-1000"),
            "{a:?}"
        );
        assert_eq!((e.swaps(), e.current_name()), (1, Some("cartpole-200")));
    }

    #[test]
    fn a_second_swap_or_a_swap_during_a_restart_is_refused_at_once() {
        let t0 = Instant::now();
        let mut e = running(5, t0);
        e.swap(request("cartpole-200"), t0);
        let a = e.swap(request("cartpole-500"), t0);
        assert!(
            matches!(&a[..], [Action::Respond { ok: false, message, request, .. }]
                if message.contains("another swap (to cartpole-200)") && request.expert == "cartpole-500"),
            "{a:?}"
        );
        let mut e = running(5, t0);
        e.exited(1, &killed(), t0);
        let a = e.swap(request("cartpole-200"), t0);
        assert!(
            matches!(&a[..], [Action::Respond { ok: false, message, .. }] if message.contains("restarted")),
            "{a:?}"
        );
    }

    #[test]
    fn a_failed_swap_leaves_the_old_expert_answering_or_restarts_it() {
        let t0 = Instant::now();
        let refused = Exit {
            how: "exited with status 2".into(),
            code: Some(2),
            reason: Some("demos.jsonl line 3: bad".into()),
        };
        // The new one dies while starting: the old one was never told to go and answers on.
        let mut e = running(5, t0);
        e.swap(request("cartpole-200"), t0);
        let a = e.exited(2, &refused, t0);
        assert!(
            matches!(&a[..], [Action::Respond { ok: false, message, .. }]
                if message == "the new expert exited with status 2: demos.jsonl line 3: bad"),
            "{a:?}"
        );
        assert!(e.settled());
        assert_eq!((e.active(), e.restarts()), (1, 0));

        // The new one dies after the old one was told to go: the old expert is restarted.
        let mut e = running(5, t0);
        e.swap(request("cartpole-200"), t0);
        e.standby(2, t0);
        e.exited(1, &killed(), t0);
        let a = e.exited(2, &killed(), t0);
        assert!(
            matches!(a[..], [.., Action::Respond { ok: false, .. }, Action::Spawn { generation: 3, ref name }] if name == "cartpole-1000"),
            "{a:?}"
        );
        assert_eq!(e.restarts(), 1);

        // The new one never comes up: killed, the swap refused, the old one answers on.
        let mut e = running(5, t0);
        e.swap(request("cartpole-200"), t0);
        let a = e.tick(t0 + START_TIMEOUT + Duration::from_secs(1));
        assert!(
            matches!(
                &a[..],
                [
                    Action::Kill { generation: 2 },
                    Action::Respond { ok: false, .. }
                ]
            ),
            "{a:?}"
        );
        assert!(e.exited(2, &killed(), t0).is_empty());
        assert!(e.settled());
    }

    #[test]
    fn the_old_expert_dying_during_a_swap_lets_the_new_one_in() {
        let t0 = Instant::now();
        let mut e = running(5, t0);
        e.swap(request("cartpole-200"), t0);
        // Killed while its successor starts: no restart, and nobody answers meanwhile.
        let a = e.exited(1, &killed(), t0);
        assert_eq!(
            a,
            vec![Action::Control {
                newest: 1,
                active: 0
            }]
        );
        // Once up, the successor is alone: active at once.
        assert_eq!(last_control(&e.standby(2, t0)), Some((2, 2)));
        assert!(matches!(
            e.running(2, t0)[..],
            [Action::Respond { ok: true, .. }]
        ));
        assert_eq!(e.restarts(), 0);
    }

    fn no_expert(actions: &[Action]) -> Option<&str> {
        actions.iter().find_map(|a| match a {
            Action::NoExpert { message, .. } => Some(message.as_str()),
            _ => None,
        })
    }

    /// A run whose expert, served by another host, answers as generation 2.
    fn remote_running(max_restarts: u32, t0: Instant) -> ExpertLifecycle {
        let mut e = running(max_restarts, t0);
        e.swap(request("python:here_only:policy"), t0);
        e.standby(2, t0);
        e.exited(1, &killed(), t0);
        e.running(2, t0);
        assert_eq!(
            (e.active(), e.current_name()),
            (2, Some("python:here_only:policy"))
        );
        e
    }

    #[test]
    fn a_lost_remote_expert_is_restarted_here_and_a_name_unknown_here_leaves_the_run_without_one() {
        let t0 = Instant::now();
        let lost = Exit {
            how: "was lost with its host".into(),
            code: None,
            reason: None,
        };
        // Restarted here under the same name, as after a crash; it comes up and answers.
        let mut e = remote_running(5, t0);
        let a = e.lost(2, &lost, t0);
        assert_eq!(last_control(&a), Some((2, 0)));
        assert_eq!(spawned(&a), vec![3]);
        e.standby(3, t0);
        assert!(matches!(
            e.running(3, t0)[..],
            [Action::Recovered {
                generation: 3,
                died: 2,
                ..
            }]
        ));
        // Once it answers here, it is a local expert: a refusing restart fails the run again.
        e.exited(3, &killed(), t0);
        let refused = Exit {
            how: "exited with status 2".into(),
            code: Some(2),
            reason: Some("no module named here_only".into()),
        };
        assert!(matches!(
            e.exited(4, &refused, t0).last(),
            Some(Action::Fail { generation: 4, .. })
        ));

        // The replacement cannot start here (the module is on the other host only): the run
        // goes on without an expert, nobody answers, and a later swap brings one.
        let mut e = remote_running(5, t0);
        e.lost(2, &lost, t0);
        let a = e.exited(3, &refused, t0);
        let why = no_expert(&a).expect("no expert");
        assert!(
            why.contains("expert-3") && why.contains("no module named here_only"),
            "{why}"
        );
        assert!(!a.iter().any(|a| matches!(a, Action::Fail { .. })), "{a:?}");
        assert_eq!(
            (e.active(), e.current_name(), e.settled()),
            (0, None, false)
        );
        assert_eq!(spawned(&e.swap(request("cartpole-200"), t0)), vec![4]);
        assert_eq!(last_control(&e.standby(4, t0)), Some((4, 4)));
        assert!(matches!(
            &e.running(4, t0)[..],
            [Action::Respond { ok: true, from, .. }] if from.is_empty()
        ));
        assert!(e.settled());

        // A replacement that never comes up is killed, and the run goes on without an expert.
        let mut e = remote_running(5, t0);
        e.lost(2, &lost, t0);
        let a = e.tick(t0 + START_TIMEOUT + Duration::from_secs(1));
        assert!(matches!(a[0], Action::Kill { generation: 3 }), "{a:?}");
        assert!(no_expert(&a).is_some(), "{a:?}");
        assert!(e.exited(3, &killed(), t0).is_empty());

        // No restart left: no replacement, and no failure either.
        let mut e = remote_running(0, t0);
        let a = e.lost(2, &lost, t0);
        assert!(spawned(&a).is_empty());
        assert!(
            no_expert(&a).is_some_and(|m| m.contains("--max-restarts 0")),
            "{a:?}"
        );
        assert_eq!(e.active(), 0);
    }

    #[test]
    fn an_old_expert_that_does_not_leave_is_killed() {
        let t0 = Instant::now();
        let mut e = running(5, t0);
        e.swap(request("cartpole-200"), t0);
        e.standby(2, t0);
        assert!(e.tick(t0 + LEAVE_TIMEOUT / 2).is_empty());
        assert_eq!(
            e.tick(t0 + LEAVE_TIMEOUT + Duration::from_secs(1)),
            vec![Action::Kill { generation: 1 }]
        );
    }
}
