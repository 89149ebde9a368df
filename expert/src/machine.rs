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

use std::collections::VecDeque;
use std::time::Duration;

use alfd_common::agent::{DemoRecord, Demonstrator, ExpertCore, RefitJob, Refitted};
use alfd_common::demo_model::DemoModelError;
use alfd_common::environment_loop::panel_expert::PanelAsk;
use alfd_common::panel::Asker;
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
    /// down the query is dropped, spending nothing.
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
        let (demos, rows) = (self.core.demos().len(), panel.log().rows.len());
        let x: Vec<f64> = state.iter().map(|&v| f64::from(v)).collect();
        let action = match panel.ask(&mut self.core, (state, &x), step, asker) {
            Ok(Some(action)) => action,
            Ok(None) => return vec![self.refuse(query, actor)],
            Err(e) => {
                return vec![Action::Drop {
                    actor,
                    why: e.to_string(),
                }]
            }
        };
        let log = panel.log();
        let records = self.core.demos()[demos..]
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
            .collect();
        self.answered(query, actor, action, records)
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
            for (shown, query) in waiting {
                out.push(self.refuse(query, shown.actor));
            }
        }
        out
    }

    /// The person's decision on the waiting query `id`: an action, or `None` (declined: the actor
    /// acts on its own, no budget is spent, nothing is recorded).
    pub fn decision(&mut self, id: u64, action: Option<usize>) -> Vec<Action<Q>> {
        let Some(i) = self.waiting.iter().position(|(s, _)| s.id == id) else {
            return Vec::new();
        };
        let (shown, query) = self.waiting.remove(i).expect("position is in range");
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
        let out = self.demonstrated(query, shown.actor, &shown.state, shown.step, action);
        if matches!(out.first(), Some(Action::Record(_))) {
            self.counts.person_answered += 1;
        }
        out
    }

    /// Forgets the waiting queries whose actor stopped waiting (`still_waiting` says which): no
    /// answer is spent on them.
    pub fn prune(&mut self, still_waiting: impl Fn(&Q) -> bool) {
        let before = self.waiting.len();
        self.waiting.retain(|(_, q)| still_waiting(q));
        self.counts.abandoned += (before - self.waiting.len()) as u64;
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

    fn release(&mut self) -> Vec<Action<Q>> {
        let waiting: Vec<_> = self.waiting.drain(..).collect();
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
mod tests {
    use super::*;
    use alfd_common::config::{DemoModelChoice, ShapingConfig};

    /// A machine of generation 2 with budget `budget`; queries are numbered.
    fn machine(budget: u32, human: bool) -> ExpertMachine<u32> {
        let core = ExpertCore::new(
            budget,
            DemoModelChoice::Krr,
            2,
            ShapingConfig::default().schedule(),
        );
        ExpertMachine::new(2, "scripted", human, core)
    }

    fn record(index: u32) -> DemoRecord {
        DemoRecord {
            index,
            state: vec![f64::from(index), 0.5],
            action: (index % 2) as usize,
            step: u64::from(index) * 10,
            expert: "earlier".into(),
            weight: 1.0,
        }
    }

    fn active(budget: u32, human: bool, earlier: u32) -> ExpertMachine<u32> {
        let mut m = machine(budget, human);
        assert_eq!(m.control(2, 2), vec![Action::LoadDemos]);
        m.activate((0..earlier).map(record).collect()).unwrap();
        m
    }

    fn q(actor: u32, step: u64) -> QueryIn {
        QueryIn {
            actor,
            step,
            episode: 0,
            last_return: None,
            connected: true,
            state: Ok(vec![0.25, -1.0]),
        }
    }

    /// The outcome of each reply in `actions`, with the query it answers.
    fn replies(actions: &[Action<u32>]) -> Vec<(u32, u32)> {
        actions
            .iter()
            .filter_map(|a| match a {
                Action::Reply {
                    query, response, ..
                } => Some((*query, response.outcome)),
                _ => None,
            })
            .collect()
    }

    /// Asks and answers query `id` with `action`, as the shell does with a built-in demonstrator.
    fn ask_and_answer(m: &mut ExpertMachine<u32>, id: u32, action: usize) -> Vec<Action<u32>> {
        let asked = m.query(id, q(7, 100 + u64::from(id)));
        let [Action::Ask {
            query,
            asker,
            state,
            step,
        }] = asked.as_slice()
        else {
            panic!("expected one Ask, got {asked:?}");
        };
        m.demonstrated(*query, asker.actor, &state.clone(), *step, action)
    }

    #[test]
    fn a_standby_expert_answers_nothing_and_spends_nothing() {
        let mut m = machine(5, false);
        assert_eq!(m.control(1, 2), vec![]);
        let out = m.query(1, q(0, 10));
        assert!(matches!(out.as_slice(), [Action::Drop { actor: 0, .. }]));
        // An answer arriving after it stood by (a slow demonstrator) is not recorded.
        let out = m.demonstrated(1, 0, &[0.0, 0.0], 10, 1);
        assert!(matches!(out.as_slice(), [Action::Drop { .. }]));
        assert_eq!(m.core().budget().used(), 0);
        assert_eq!(m.counts(), Counts::default());
    }

    #[test]
    fn a_newer_generation_makes_it_exit_whatever_its_mode() {
        let mut m = active(5, false, 0);
        assert_eq!(
            m.control(2, 3),
            vec![Action::Exit("replaced by a newer expert")]
        );
        let mut m = machine(5, false);
        assert_eq!(
            m.control(0, 3),
            vec![Action::Exit("replaced by a newer expert")]
        );
    }

    #[test]
    fn activation_counts_the_predecessors_demonstrations() {
        let mut m = machine(5, false);
        assert_eq!(m.control(2, 2), vec![Action::LoadDemos]);
        let out = m.activate((0..3).map(record).collect()).unwrap();
        assert_eq!(
            out,
            vec![
                Action::PublishModel,
                Action::Status(process_state::RUNNING),
                Action::RingLauncher
            ]
        );
        assert_eq!(m.mode(), Mode::Active);
        assert_eq!(m.core().budget().used(), 3);
        assert_eq!(m.core().budget().remaining(), 2);
        // Control repeating the same generation does not load again.
        assert_eq!(m.control(2, 2), vec![]);
    }

    #[test]
    fn with_refits_in_the_background_answers_wait_for_the_disk_not_the_model() {
        let mut m = machine(10, false);
        m.refit_in_background();
        assert_eq!(m.control(2, 2), vec![Action::LoadDemos]);
        m.activate((0..3).map(record).collect()).unwrap();
        let version = m.core().model_version();
        let out = ask_and_answer(&mut m, 1, 1);
        assert!(
            matches!(
                out.as_slice(),
                [
                    Action::Record(_),
                    Action::Reply { query: 1, .. },
                    Action::StartRefit
                ]
            ),
            "{out:?}"
        );
        let job = m.take_refit_job().expect("the refit owed");
        assert_eq!(job.covers(), 4);
        // Two more queries while it runs: answered, and no second refit goes out.
        for id in [2, 3] {
            let out = ask_and_answer(&mut m, id, 0);
            assert!(
                matches!(out.as_slice(), [Action::Record(_), Action::Reply { .. }]),
                "{out:?}"
            );
        }
        assert_eq!(
            m.core().model_version(),
            version,
            "nothing refitted on the query path"
        );
        // Its end publishes the model of four, and starts the refit of the two newcomers.
        let out = m.refitted(job.run());
        assert_eq!(out, vec![Action::PublishModel, Action::StartRefit]);
        assert_eq!(m.core().model_version(), version + 1);
        let job = m.take_refit_job().unwrap();
        assert_eq!(job.covers(), 6);
        assert_eq!(m.refitted(job.run()), vec![Action::PublishModel]);
        assert!(!m.core().stale());
        assert_eq!(m.counts().answered, 3);
    }

    #[test]
    fn a_refit_ending_after_the_expert_stood_by_publishes_nothing() {
        let mut m = machine(5, false);
        m.refit_in_background();
        m.control(2, 2);
        m.activate(Vec::new()).unwrap();
        ask_and_answer(&mut m, 1, 1);
        let job = m.take_refit_job().unwrap();
        m.control(0, 2);
        assert_eq!(m.mode(), Mode::Standby);
        assert_eq!(m.refitted(job.run()), vec![]);
    }

    #[test]
    fn a_demonstration_is_recorded_then_published_then_answered() {
        let mut m = active(5, false, 3);
        let out = ask_and_answer(&mut m, 1, 1);
        let [Action::Record(rec), Action::PublishModel, Action::Reply {
            query: 1,
            actor: 7,
            response,
        }] = out.as_slice()
        else {
            panic!("wrong order: {out:?}");
        };
        assert_eq!(rec.index, 3);
        assert_eq!(rec.action, 1);
        assert_eq!(rec.expert, "scripted");
        assert_eq!(rec.state, vec![0.25, -1.0]);
        assert_eq!(response.outcome, outcome::ANSWERED);
        assert_eq!(response.demo_index, 3);
        assert_eq!(response.action, 1);
        assert_eq!(response.budget_left, 1);
        assert_eq!(response.budget_total, 5);
        assert_eq!(response.expert, 2);
        assert_eq!(response.expert_name(), "scripted");
        assert_eq!(m.counts().answered, 1);
    }

    #[test]
    fn a_demonstration_is_never_dated_before_the_last_one() {
        // The predecessor's last demonstration was at step 20 (record 2); a late query of step 5
        // is dated 20, so the shaping window never shrinks.
        let mut m = active(5, false, 3);
        let out = m.demonstrated(9, 1, &[0.0, 0.0], 5, 0);
        let Some(Action::Record(rec)) = out.first() else {
            panic!("{out:?}");
        };
        assert_eq!(rec.step, 20);
    }

    #[test]
    fn the_budget_is_never_overspent() {
        let mut m = active(2, false, 1);
        assert_eq!(
            replies(&ask_and_answer(&mut m, 1, 0)),
            vec![(1, outcome::ANSWERED)]
        );
        // Spent: the next query is refused without asking the demonstrator.
        let out = m.query(2, q(3, 200));
        assert_eq!(replies(&out), vec![(2, outcome::BUDGET_EXHAUSTED)]);
        // An answer racing the last one (asked before the budget ran out) is refused too.
        let out = m.demonstrated(3, 3, &[0.0, 0.0], 300, 1);
        assert_eq!(replies(&out), vec![(3, outcome::BUDGET_EXHAUSTED)]);
        assert_eq!(m.core().budget().used(), 2);
        assert_eq!(m.counts().refused, 2);
    }

    #[test]
    fn an_abandoned_or_malformed_query_spends_nothing() {
        let mut m = active(5, false, 0);
        let gone = QueryIn {
            connected: false,
            ..q(1, 10)
        };
        assert_eq!(m.query(1, gone), vec![]);
        assert_eq!(m.counts().abandoned, 1);
        let bad = QueryIn {
            state: Err("query obs_dim 3 out of range".into()),
            ..q(1, 10)
        };
        let out = m.query(2, bad);
        assert!(
            matches!(out.as_slice(), [Action::Drop { actor: 1, why }] if why.contains("obs_dim"))
        );
        assert_eq!(m.core().budget().used(), 0);
    }

    #[test]
    fn the_person_answers_declines_and_duplicates_are_ignored() {
        let mut m = active(5, true, 0);
        assert_eq!(m.query(10, q(0, 1)), vec![]);
        assert_eq!(m.query(11, q(1, 2)), vec![]);
        let shown: Vec<u64> = m.waiting().iter().map(|s| s.id).collect();
        assert_eq!(shown, vec![1, 2]);
        let out = m.decision(2, Some(1));
        assert_eq!(replies(&out), vec![(11, outcome::ANSWERED)]);
        assert!(matches!(out.first(), Some(Action::Record(r)) if r.action == 1 && r.step == 2));
        // The same decision twice (a double click) is ignored: one demonstration.
        assert_eq!(m.decision(2, Some(1)), vec![]);
        let out = m.decision(1, None);
        assert_eq!(replies(&out), vec![(10, outcome::DECLINED)]);
        assert_eq!(m.core().budget().used(), 1);
        let c = m.counts();
        assert_eq!((c.person_answered, c.declined, c.answered), (1, 1, 1));
        assert!(m.waiting().is_empty());
    }

    #[test]
    fn a_decision_after_a_swap_is_ignored_and_the_waiting_are_declined() {
        let mut m = active(5, true, 0);
        m.query(10, q(0, 1));
        m.query(11, q(1, 2));
        // Another generation becomes active: the waiting queries are declined at once.
        let out = m.control(3, 3);
        assert_eq!(out, vec![Action::Exit("replaced by a newer expert")]);
        let out = m.control(1, 2);
        assert_eq!(
            replies(&out),
            vec![(10, outcome::DECLINED), (11, outcome::DECLINED)]
        );
        assert!(out.contains(&Action::CloseLog));
        assert_eq!(m.mode(), Mode::Standby);
        // The person's click on the old page arrives late: nothing is recorded.
        assert_eq!(m.decision(1, Some(0)), vec![]);
        assert_eq!(m.core().budget().used(), 0);
    }

    #[test]
    fn waiting_queries_are_pruned_and_refused_once_the_budget_is_spent() {
        let mut m = active(1, true, 0);
        m.query(10, q(0, 1));
        m.query(11, q(1, 2));
        m.query(12, q(2, 3));
        // Actor 0 stopped waiting: forgotten, counted as abandoned, nothing sent.
        m.prune(|&id| id != 10);
        assert_eq!(m.counts().abandoned, 1);
        let shown: Vec<u64> = m.waiting().iter().map(|s| s.id).collect();
        assert_eq!(shown, vec![2, 3]);
        // The answer that spends the budget refuses the rest rather than leave them waiting.
        assert_eq!(
            replies(&m.decision(2, Some(0))),
            vec![(11, outcome::ANSWERED), (12, outcome::BUDGET_EXHAUSTED)]
        );
        assert!(m.waiting().is_empty());
        // A query arriving now is refused, not shown.
        assert_eq!(
            replies(&m.query(13, q(3, 4))),
            vec![(13, outcome::BUDGET_EXHAUSTED)]
        );
    }

    #[test]
    fn status_reports_follow_the_clock_passed_in() {
        let mut m = machine(5, false);
        let start = m.start(Duration::from_secs(10));
        assert_eq!(
            start,
            vec![Action::Status(process_state::STANDBY), Action::RingLauncher]
        );
        assert_eq!(m.tick(Duration::from_millis(10_499)), vec![]);
        assert_eq!(
            m.tick(Duration::from_millis(10_500)),
            vec![Action::Status(process_state::STANDBY)]
        );
        assert_eq!(m.tick(Duration::from_millis(10_600)), vec![]);
        m.control(2, 2);
        m.activate(Vec::new()).unwrap();
        assert_eq!(
            m.tick(Duration::from_secs(11)),
            vec![Action::Status(process_state::RUNNING)]
        );
    }

    #[test]
    fn stopping_declines_the_waiting_and_tells_the_launcher() {
        let mut m = active(5, true, 0);
        m.query(10, q(4, 1));
        let out = m.stop();
        assert_eq!(replies(&out), vec![(10, outcome::DECLINED)]);
        assert_eq!(
            &out[1..],
            &[Action::Status(process_state::EXITING), Action::RingLauncher]
        );
    }

    /// A built-in expert that always answers its action.
    struct Always(usize);

    impl Demonstrator<[f32]> for Always {
        fn act(&mut self, _: &[f32]) -> usize {
            self.0
        }
    }

    /// Actor `actor` in its first episode.
    fn asker(actor: u32) -> Asker {
        Asker {
            actor,
            episode: 0,
            last_return: None,
        }
    }

    /// Three experts answering 2, 1 and 0 at costs 10, 2 and 1, asked in turn, every state asked
    /// of a second expert too.
    fn panel() -> PanelAsk<'static, [f32]> {
        let cfg = alfd_common::config::ExperimentConfig::from_toml(
            "seed = 1\nepisodes = 3\n[env]\nname = \"mountaincar\"\n[agent]\nkind = \"bdqn\"\n\
             [expert]\nroute = \"round-robin\"\ndouble_ask = 1.0\n\
             [[experts]]\nname = \"mountaincar-energy\"\ncost = 10\n\
             [[experts]]\nname = \"mountaincar-fair\"\ncost = 2\n\
             [[experts]]\nname = \"mountaincar-poor\"\ncost = 1\n",
        )
        .unwrap();
        let members: Vec<Box<dyn Demonstrator<[f32]>>> = vec![
            Box::new(Always(2)),
            Box::new(Always(1)),
            Box::new(Always(0)),
        ];
        PanelAsk::new(&cfg, members)
    }

    #[test]
    fn several_experts_record_each_answer_with_its_cost_then_reply_with_the_first() {
        let mut m = active(3, false, 0);
        let mut p = panel();
        let out = m.panel_demonstrated((1, asker(7)), &[0.25, -1.0], 30, &mut p);
        let [Action::RecordOf(first, a), Action::RecordOf(second, b), Action::PublishModel, Action::Reply {
            query: 1,
            actor: 7,
            response,
        }] = out.as_slice()
        else {
            panic!("expected two records, a publication and a reply: {out:?}");
        };
        // Round-robin starts with energy (2); fair, the least answered other, is asked too.
        assert_eq!(
            (first.expert.as_str(), first.action),
            ("mountaincar-energy", 2)
        );
        assert_eq!(
            (second.expert.as_str(), second.action),
            ("mountaincar-fair", 1)
        );
        assert_eq!((a.cost, a.double_asked, b.cost), (10.0, true, 2.0));
        assert!(
            a.quality_line.starts_with("30,mountaincar-energy,1,"),
            "{}",
            a.quality_line
        );
        assert_eq!((response.action, response.demo_index), (2, 0));
        assert_eq!((response.budget_left, m.counts().answered), (1, 2));
        // The last of the budget: one answer recorded, its double ask not; then refused.
        let out = m.panel_demonstrated((2, asker(7)), &[0.25, -1.0], 40, &mut p);
        assert_eq!(
            out.iter()
                .filter(|a| matches!(a, Action::RecordOf(..)))
                .count(),
            1
        );
        let out = m.panel_demonstrated((3, asker(7)), &[0.25, -1.0], 50, &mut p);
        assert_eq!(replies(&out), [(3, outcome::BUDGET_EXHAUSTED)]);
        // A standby expert asks nobody.
        let mut standby = machine(3, false);
        let out = standby.panel_demonstrated((4, asker(7)), &[0.25, -1.0], 60, &mut p);
        assert!(matches!(out.as_slice(), [Action::Drop { actor: 7, .. }]));
        assert!(standby.core().demos().is_empty());
    }
}
