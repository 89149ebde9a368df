//! The expert process's decisions as a state machine: events in (the launcher's control, a query,
//! a demonstrator's action, the person's decision, the time), actions out (record, publish, reply,
//! report), with no I/O, clock or socket inside. `process.rs` is the shell that reads the wire
//! and the page, feeds the events and carries the actions out in the order they come.
//!
//! Its rules are the ones a fault must not break:
//! - only the active generation answers; a newer generation makes this one exit; a standby
//!   expert answers nothing and spends nothing;
//! - becoming active reads `demos.jsonl` back first ([`Action::LoadDemos`], then
//!   [`ExpertMachine::activate`]), so the budget counts what every predecessor spent;
//! - a demonstration is recorded on disk, then the model is published, then the actor hears the
//!   answer ([`Action::Record`], [`Action::PublishModel`], [`Action::Reply`], in that order);
//!   with refits in the background ([`ExpertMachine::refit_in_background`]) the actor hears the
//!   answer once it is on disk, and the model refitted with it is published when its refit
//!   ([`Action::StartRefit`], one at a time) ends;
//! - a query whose actor stopped waiting spends no budget; a decision for a query that is no
//!   longer waiting (answered, abandoned, or dropped by a swap) is ignored;
//! - queries waiting for a person are answered "declined" when this expert stops answering, and
//!   "budget exhausted" by the answer that spends the last of the budget.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use alfd_common::agent::{DemoRecord, Demonstrator, ExpertCore, RefitJob, Refitted};
use alfd_common::demo_model::DemoModelError;
use alfd_common::environment_loop::panel_expert::{PanelAsk, Routed};
use alfd_common::panel::{Ask, Asker};
use alfd_wire::{name_to_bytes, outcome, process_state, QueryResponse};

use crate::human::ShownQuery;

/// How often the expert reports its status while nothing else happens.
pub const STATUS_EVERY: Duration = Duration::from_millis(500);

/// Whether this expert may answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    Standby,
    Active,
}

/// What the shell does, in the order given. `Q` is the shell's handle of a query.
#[derive(Debug, PartialEq)]
pub enum Action<Q> {
    /// Read `demos.jsonl` back and call [`ExpertMachine::activate`] with its records.
    LoadDemos,
    /// Close the demonstration log (this expert stands by).
    CloseLog,
    /// Append this demonstration to `demos.jsonl`.
    Record(DemoRecord),
    /// With several experts: append this demonstration to `demos.jsonl` with what it cost and
    /// whether its state was asked twice, and its expert's quality row to `experts.csv`.
    RecordOf(DemoRecord, PanelNote),
    /// Publish the current demonstration model ([`ExpertMachine::core`]).
    PublishModel,
    /// Take the refit the model owes ([`ExpertMachine::take_refit_job`]), run it off the query
    /// path, and give what it returns to [`ExpertMachine::refitted`].
    StartRefit,
    /// Answer the query and ring its actor's doorbell.
    Reply {
        query: Q,
        actor: u32,
        response: QueryResponse,
    },
    /// Ask the demonstrator for this state's action and give it to
    /// [`ExpertMachine::demonstrated`] (or drop the query if the demonstrator fails).
    Ask {
        query: Q,
        asker: Asker,
        state: Vec<f32>,
        step: u64,
    },
    /// A query left unanswered (the actor acts on its own after its timeout), and why.
    Drop { actor: u32, why: String },
    /// Send a status report in this process state.
    Status(u32),
    /// Ring the launcher's doorbell.
    RingLauncher,
    /// Stop the process's loop, for this reason.
    Exit(&'static str),
}

/// What a run with several experts records beside a demonstration.
#[derive(Debug, Clone, PartialEq)]
pub struct PanelNote {
    pub cost: f64,
    pub double_asked: bool,
    /// The answering expert's line of `experts.csv` after this answer.
    pub quality_line: String,
}

/// What arrived with a query: its actor, step, whether its actor still waits, and its state
/// (or why the state is unusable).
#[derive(Debug, Clone)]
pub struct QueryIn {
    pub actor: u32,
    pub step: u64,
    /// The actor's finished episodes, and the last one's return (none in its first).
    pub episode: u64,
    pub last_return: Option<f64>,
    pub connected: bool,
    pub state: Result<Vec<f32>, String>,
}

impl QueryIn {
    /// Who asks, as several experts see it.
    pub fn asker(&self) -> Asker {
        Asker {
            actor: self.actor,
            episode: self.episode,
            last_return: self.last_return,
        }
    }
}

/// The counts the expert logs when it stops.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Demonstrations given (by any demonstrator).
    pub answered: u64,
    /// Queries refused because the budget was spent.
    pub refused: u64,
    /// Queries whose actor stopped waiting before an answer.
    pub abandoned: u64,
    /// Queries the person declined.
    pub declined: u64,
    /// Demonstrations the person gave.
    pub person_answered: u64,
}

/// The expert process's state: its generation and demonstrator's name, the core (budget,
/// demonstrations, model), its mode, the queries waiting for a person, and its counts.
pub struct ExpertMachine<Q> {
    generation: u16,
    name: String,
    human: bool,
    core: ExpertCore,
    mode: Mode,
    waiting: VecDeque<(ShownQuery, Q)>,
    /// Of the waiting queries, those several experts' panel routed to the person: its ask.
    routed: BTreeMap<u64, (Ask, Asker)>,
    next_shown: u64,
    counts: Counts,
    last_status: Option<Duration>,
}

impl<Q> ExpertMachine<Q> {
    /// A standby expert of generation `generation`; `human` when a person answers on the page
    /// (queries wait for their decision instead of being asked of a demonstrator).
    pub fn new(generation: u16, name: &str, human: bool, core: ExpertCore) -> Self {
        Self {
            generation,
            name: name.to_string(),
            human,
            core,
            mode: Mode::Standby,
            waiting: VecDeque::new(),
            routed: BTreeMap::new(),
            next_shown: 0,
            counts: Counts::default(),
            last_status: None,
        }
    }

    /// Answers queries without waiting for the model's refit: each demonstration is recorded
    /// and answered, and the model refitted with it is published when its refit, run by the
    /// shell ([`Action::StartRefit`]), ends.
    pub fn refit_in_background(&mut self) {
        self.core.defer_refits();
    }

    /// The refit [`Action::StartRefit`] asked for (`None` if nothing is owed any more or one is
    /// out already).
    pub fn take_refit_job(&mut self) -> Option<RefitJob> {
        self.core.refit_job()
    }

    /// A refit ended: its model is published (while this expert answers), and the next refit
    /// started if demonstrations arrived meanwhile.
    pub fn refitted(&mut self, r: Refitted) -> Vec<Action<Q>> {
        if let Err(e) = self.core.finish_refit(r) {
            tracing::warn!(error = %e, "demonstration model not refitted");
        }
        if self.mode == Mode::Standby {
            return Vec::new();
        }
        let mut out = vec![Action::PublishModel];
        out.extend(self.next_refit());
        out
    }

    /// [`Action::StartRefit`] if refits run in the background, one is owed and none is out.
    fn next_refit(&self) -> Option<Action<Q>> {
        let c = &self.core;
        (c.refits_deferred() && !c.refit_out() && c.stale()).then_some(Action::StartRefit)
    }

    pub fn generation(&self) -> u16 {
        self.generation
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn core(&self) -> &ExpertCore {
        &self.core
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    pub fn counts(&self) -> Counts {
        self.counts
    }

    /// The queries waiting for the person, oldest first.
    pub fn waiting(&self) -> Vec<ShownQuery> {
        self.waiting.iter().map(|(s, _)| s.clone()).collect()
    }

    /// The start: report standing by.
    pub fn start(&mut self, now: Duration) -> Vec<Action<Q>> {
        self.last_status = Some(now);
        vec![Action::Status(process_state::STANDBY), Action::RingLauncher]
    }

    /// The launcher's control: which generation is active and which is the newest.
    pub fn control(&mut self, active_expert: u32, newest_expert: u32) -> Vec<Action<Q>> {
        let me = u32::from(self.generation);
        if me < newest_expert {
            return vec![Action::Exit("replaced by a newer expert")];
        }
        match (active_expert == me, self.mode) {
            // Make-before-break: the previous expert has exited; its demonstrations are final.
            (true, Mode::Standby) => vec![Action::LoadDemos],
            (false, Mode::Active) => {
                self.mode = Mode::Standby;
                let mut out = self.release();
                out.extend([
                    Action::CloseLog,
                    Action::Status(process_state::STANDBY),
                    Action::RingLauncher,
                ]);
                out
            }
            _ => Vec::new(),
        }
    }

    /// Becomes active on the demonstrations in `demos.jsonl` (every predecessor's): the budget
    /// counts them and the model is refitted on them.
    pub fn activate(&mut self, records: Vec<DemoRecord>) -> Result<Vec<Action<Q>>, DemoModelError> {
        self.core.restore(records)?;
        self.mode = Mode::Active;
        Ok(vec![
            Action::PublishModel,
            Action::Status(process_state::RUNNING),
            Action::RingLauncher,
        ])
    }

    /// A query from an actor.
    pub fn query(&mut self, query: Q, q: QueryIn) -> Vec<Action<Q>> {
        let asker = q.asker();
        if self.mode == Mode::Standby {
            return vec![Action::Drop {
                actor: q.actor,
                why: "standing by".into(),
            }];
        }
        if !q.connected {
            // The actor gave up waiting and acted on its own: spend no budget on it.
            self.counts.abandoned += 1;
            return Vec::new();
        }
        // A state of another size (or not finite) would break the demonstrator and the
        // demonstration model: refused, and the actor acts on its own after its timeout.
        let state = match q.state {
            Ok(state) => state,
            Err(why) => {
                return vec![Action::Drop {
                    actor: q.actor,
                    why,
                }]
            }
        };
        if self.core.budget().is_exhausted() {
            return vec![self.refuse(query, q.actor)];
        }
        if self.human {
            // For the person: shown on the page, answered when they decide.
            self.next_shown += 1;
            let shown = ShownQuery {
                id: self.next_shown,
                actor: q.actor,
                step: q.step,
                state,
            };
            self.waiting.push_back((shown, query));
            return Vec::new();
        }
        vec![Action::Ask {
            query,
            asker,
            state,
            step: q.step,
        }]
    }

    /// The demonstrator's `action` for a query [`Action::Ask`] named: recorded within the budget
    /// (or refused once it is spent).
    pub fn demonstrated(
        &mut self,
        query: Q,
        actor: u32,
        state: &[f32],
        step: u64,
        action: usize,
    ) -> Vec<Action<Q>> {
        if self.mode == Mode::Standby {
            return vec![Action::Drop {
                actor,
                why: "standing by".into(),
            }];
        }
        let step = step.max(self.core.last_demo_step());
        let name = self.name.clone();
        match self.core.answer(&mut Given(action), state, step, &name) {
            Some(action) => {
                let record = self
                    .core
                    .demos()
                    .last()
                    .expect("an answer records a demonstration")
                    .clone();
                self.answered(query, actor, action, vec![Action::Record(record)])
            }
            None => vec![self.refuse(query, actor)],
        }
    }

    /// With several experts (`[[experts]]`): `panel` routes the query to one of them (and on a
    /// double ask a second expert answers the same state); each answer is a demonstration
    /// recorded with its cost and its expert's quality, the first one's action the reply. An
    /// expert that fails is marked down and the state goes to another; when every expert is
    /// down the query is dropped, spending nothing. A query routed to a person waits on their
    /// page for [`ExpertMachine::decision`].
    pub fn panel_demonstrated(
        &mut self,
        (query, asker): (Q, Asker),
        state: &[f32],
        step: u64,
        panel: &mut PanelAsk<'_, [f32]>,
    ) -> Vec<Action<Q>> {
        let actor = asker.actor;
        if self.mode == Mode::Standby {
            return vec![Action::Drop {
                actor,
                why: "standing by".into(),
            }];
        }
        let step = step.max(self.core.last_demo_step());
        let before = (self.core.demos().len(), panel.log().rows.len());
        let x: Vec<f64> = state.iter().map(|&v| f64::from(v)).collect();
        let action = match panel.route_or_answer(&mut self.core, (state, &x), step, asker) {
            Ok(Routed::Answered(Some(action))) => action,
            Ok(Routed::Answered(None)) => return vec![self.refuse(query, actor)],
            Ok(Routed::Person(ask)) => {
                self.next_shown += 1;
                let shown = ShownQuery {
                    id: self.next_shown,
                    actor,
                    step,
                    state: state.to_vec(),
                };
                self.routed.insert(shown.id, (ask, asker));
                self.waiting.push_back((shown, query));
                return Vec::new();
            }
            Err(e) => {
                return vec![Action::Drop {
                    actor,
                    why: e.to_string(),
                }]
            }
        };
        let records = self.panel_records(panel, before);
        self.answered(query, actor, action, records)
    }

    /// The demonstrations `panel` recorded since the core held `demos` and its log `rows`, each
    /// with its cost, whether its state was double-asked, and its expert's quality row.
    fn panel_records(
        &self,
        panel: &PanelAsk<'_, [f32]>,
        (demos, rows): (usize, usize),
    ) -> Vec<Action<Q>> {
        let log = panel.log();
        self.core.demos()[demos..]
            .iter()
            .zip(&log.rows[rows..])
            .zip(&log.answers[rows..])
            .map(|((record, row), &(cost, double_asked))| {
                let note = PanelNote {
                    cost,
                    double_asked,
                    quality_line: log.csv_line(row),
                };
                Action::RecordOf(record.clone(), note)
            })
            .collect()
    }

    /// A query answered with `action`, its demonstrations recorded by `records` (the first the
    /// answer's): record, publish (or refit), reply, and once the budget is spent refuse the
    /// queries still waiting.
    fn answered(
        &mut self,
        query: Q,
        actor: u32,
        action: usize,
        records: Vec<Action<Q>>,
    ) -> Vec<Action<Q>> {
        let index = match records.first() {
            Some(Action::Record(r) | Action::RecordOf(r, _)) => r.index,
            _ => unreachable!("an answer records a demonstration"),
        };
        self.counts.answered += records.len() as u64;
        let response = QueryResponse {
            outcome: outcome::ANSWERED,
            action: action as u32,
            demo_index: index,
            budget_left: self.core.budget().remaining(),
            ..self.response()
        };
        let reply = Action::Reply {
            query,
            actor,
            response,
        };
        let mut out = records;
        if self.core.refits_deferred() {
            out.push(reply);
            out.extend(self.next_refit());
        } else {
            out.extend([Action::PublishModel, reply]);
        }
        // The last of the budget: nothing more to ask the person, the rest act on their own now.
        if self.core.budget().is_exhausted() {
            let waiting: Vec<_> = self.waiting.drain(..).collect();
            self.routed.clear();
            for (shown, query) in waiting {
                out.push(self.refuse(query, shown.actor));
            }
        }
        out
    }

    /// The person's decision on the waiting query `id`: an action, or `None` (declined: the actor
    /// acts on its own, no budget is spent, nothing is recorded). A query that several experts'
    /// `panel` routed to the person is recorded through it (with its second expert's answer on a
    /// double ask).
    pub fn decision(
        &mut self,
        id: u64,
        action: Option<usize>,
        panel: Option<&mut PanelAsk<'_, [f32]>>,
    ) -> Vec<Action<Q>> {
        let Some(i) = self.waiting.iter().position(|(s, _)| s.id == id) else {
            return Vec::new();
        };
        let (shown, query) = self.waiting.remove(i).expect("position is in range");
        let routed = self.routed.remove(&id);
        let Some(action) = action else {
            self.counts.declined += 1;
            let response = QueryResponse {
                outcome: outcome::DECLINED,
                budget_left: self.core.budget().remaining(),
                ..self.response()
            };
            return vec![Action::Reply {
                query,
                actor: shown.actor,
                response,
            }];
        };
        let out = match (routed, panel) {
            (Some((ask, asker)), Some(panel)) => {
                self.person_in_panel(panel, (query, &shown), (ask, asker), action)
            }
            _ => self.demonstrated(query, shown.actor, &shown.state, shown.step, action),
        };
        if matches!(out.first(), Some(Action::Record(_) | Action::RecordOf(..))) {
            self.counts.person_answered += 1;
        }
        out
    }

    /// The person's `action` on a state `panel` routed to them (`ask`, from `asker`).
    fn person_in_panel(
        &mut self,
        panel: &mut PanelAsk<'_, [f32]>,
        (query, shown): (Q, &ShownQuery),
        (ask, asker): (Ask, Asker),
        action: usize,
    ) -> Vec<Action<Q>> {
        if self.mode == Mode::Standby {
            return vec![Action::Drop {
                actor: shown.actor,
                why: "standing by".into(),
            }];
        }
        let step = shown.step.max(self.core.last_demo_step());
        let before = (self.core.demos().len(), panel.log().rows.len());
        let x: Vec<f64> = shown.state.iter().map(|&v| f64::from(v)).collect();
        let state = (shown.state.as_slice(), x.as_slice());
        match panel.person_answered(&mut self.core, state, (step, asker), ask, action) {
            Some(action) => {
                let records = self.panel_records(panel, before);
                self.answered(query, shown.actor, action, records)
            }
            None => vec![self.refuse(query, shown.actor)],
        }
    }

    /// Forgets the waiting queries whose actor stopped waiting (`still_waiting` says which): no
    /// answer is spent on them.
    pub fn prune(&mut self, still_waiting: impl Fn(&Q) -> bool) {
        let before = self.waiting.len();
        self.waiting.retain(|(_, q)| still_waiting(q));
        self.counts.abandoned += (before - self.waiting.len()) as u64;
        self.forget_routed();
    }

    /// The time: a status report every [`STATUS_EVERY`].
    pub fn tick(&mut self, now: Duration) -> Vec<Action<Q>> {
        let due = self
            .last_status
            .is_none_or(|t| now.saturating_sub(t) >= STATUS_EVERY);
        if !due {
            return Vec::new();
        }
        self.last_status = Some(now);
        let state = match self.mode {
            Mode::Active => process_state::RUNNING,
            Mode::Standby => process_state::STANDBY,
        };
        vec![Action::Status(state)]
    }

    /// The process stops: the queries waiting for the person are declined (their actors act on
    /// their own now rather than at their timeout), and the launcher hears it.
    pub fn stop(&mut self) -> Vec<Action<Q>> {
        let mut out = self.release();
        out.extend([Action::Status(process_state::EXITING), Action::RingLauncher]);
        out
    }

    /// Forgets the panel's asks of queries no longer waiting.
    fn forget_routed(&mut self) {
        let waiting = &self.waiting;
        self.routed
            .retain(|id, _| waiting.iter().any(|(s, _)| s.id == *id));
    }

    fn release(&mut self) -> Vec<Action<Q>> {
        let waiting: Vec<_> = self.waiting.drain(..).collect();
        self.routed.clear();
        waiting
            .into_iter()
            .map(|(shown, query)| Action::Reply {
                query,
                actor: shown.actor,
                response: QueryResponse {
                    outcome: outcome::DECLINED,
                    budget_total: 0,
                    ..self.response()
                },
            })
            .collect()
    }

    fn refuse(&mut self, query: Q, actor: u32) -> Action<Q> {
        self.counts.refused += 1;
        Action::Reply {
            query,
            actor,
            response: QueryResponse {
                outcome: outcome::BUDGET_EXHAUSTED,
                budget_left: 0,
                ..self.response()
            },
        }
    }

    /// A response of this expert, outcome not yet set.
    fn response(&self) -> QueryResponse {
        QueryResponse {
            expert: u32::from(self.generation),
            budget_total: self.core.budget().total(),
            expert_name: name_to_bytes(&self.name),
            ..QueryResponse::default()
        }
    }
}

/// The action a demonstrator gave, as the core's demonstrator (so the core records it as it
/// records any other).
struct Given(usize);

impl Demonstrator<[f32]> for Given {
    fn act(&mut self, _s: &[f32]) -> usize {
        self.0
    }
}

#[cfg(test)]
mod tests;
