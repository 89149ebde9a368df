//! The hub's side of a remote expert, as a state machine: which generations remote hosts serve,
//! which one is active, how many lines of `demos.jsonl` are written, the newest model waiting for
//! its demonstrations to be written, and the actors' queries held for the remote expert. No I/O
//! inside: the hub's thread (`hub.rs`) appends, publishes, answers and sends what it says.
//!
//! The rules a fault must not break:
//! - every line a remote expert appends to its host's `demos.jsonl` is appended here, in order,
//!   whether or not its answer is still awaited: lines come up on their own
//!   ([`ExpertDesk::demos`]), a line the file already holds is skipped, and lines that start past
//!   the file's end are asked for again from its end (never taken out of order);
//! - a demonstration is on disk here before its answer reaches an actor (an answer whose line is
//!   not here is dropped), and a model that counts demonstrations not yet written here waits
//!   until they are;
//! - nothing more is taken from a generation whose host left or whose expert exited, nor from one
//!   the control no longer names active (its lines are refused and counted, its answers neither
//!   written nor answered): one writer of `demos.jsonl` at a time;
//! - an answer goes only to the query it answers (an actor's newer query replaces its older one;
//!   an answer with a demonstration that comes too late for its query is counted late).

use std::collections::HashMap;

use alfd_wire::{outcome, DemoModelHeader, QueryResponse, Role};

use crate::frame::Frame;
use crate::link::{HasSeq, HeldQueries};

/// What the hub's thread does with a remote expert's answer.
#[derive(Debug, PartialEq)]
pub(crate) enum Answer<Q> {
    /// Dropped, and why.
    Dropped(String),
    /// Answer `query` with the response (its demonstration, if any, is written).
    Deliver { query: Q, response: QueryResponse },
}

/// What the hub's thread does with lines of a remote expert's `demos.jsonl`.
#[derive(Debug, PartialEq)]
pub(crate) enum Intake {
    /// Append these lines, the file's next, then call [`ExpertDesk::appended`].
    Append(Vec<String>),
    /// Nothing to do: the file holds these lines already.
    Nothing,
    /// The lines start past the file's end: ask the host of `generation` for its lines again
    /// from line `from` (the file's end).
    Resend { generation: u16, from: u32 },
    /// A gap already asked about: wait for the lines sent again.
    Wait,
    /// Not taken (counted in [`ExpertDesk::refused`]), and why.
    Refused(String),
}

/// The remote expert's side of a run on the hub.
#[derive(Debug)]
pub(crate) struct ExpertDesk<Q> {
    /// Generation → the joined host serving it.
    hosts: HashMap<u16, String>,
    /// The generation the launcher's control names active.
    active: u32,
    /// Lines of the run's `demos.jsonl`.
    written: usize,
    /// The newest model of a remote expert, while it counts demonstrations not yet written.
    early_model: Option<(DemoModelHeader, Vec<u8>)>,
    /// Queries held for the remote expert.
    held: HeldQueries<Q>,
    /// The file's length when the last [`Intake::Resend`] was asked (asked once per length).
    resend_asked: Option<usize>,
    /// Lines a remote expert wrote that the run's file did not take.
    refused: u64,
    /// Answers with a demonstration that came after their query stopped waiting.
    late: u64,
}

impl<Q> Default for ExpertDesk<Q> {
    fn default() -> Self {
        Self {
            hosts: HashMap::new(),
            active: 0,
            written: 0,
            early_model: None,
            held: HeldQueries::default(),
            resend_asked: None,
            refused: 0,
            late: 0,
        }
    }
}

impl<Q> ExpertDesk<Q> {
    /// The launcher ordered the host `join_id` to start generation `generation`.
    pub(crate) fn started(&mut self, generation: u16, join_id: &str) {
        self.hosts.insert(generation, join_id.to_owned());
    }

    /// The host `join_id` left (or its link dropped): the generations it served are gone.
    /// Returns them.
    pub(crate) fn host_left(&mut self, join_id: &str) -> Vec<u16> {
        let gone: Vec<u16> = self
            .hosts
            .iter()
            .filter(|(_, j)| *j == join_id)
            .map(|(g, _)| *g)
            .collect();
        for g in &gone {
            self.hosts.remove(g);
        }
        gone
    }

    /// Generation `generation`'s expert process ended.
    pub(crate) fn exited(&mut self, generation: u16) {
        self.hosts.remove(&generation);
        self.early_model = None;
    }

    fn serves(&self, generation: u32) -> bool {
        u16::try_from(generation).is_ok_and(|g| self.hosts.contains_key(&g))
    }

    /// Whether a query goes to the remote expert (one serves the active generation).
    pub(crate) fn holds_queries(&self) -> bool {
        self.serves(self.active)
    }

    /// A query of `actor` held for the remote expert (it replaces the actor's older one).
    pub(crate) fn hold(&mut self, actor: u32, query: Q) {
        self.held.hold(actor, query);
    }

    /// Forgets the held queries whose actors stopped waiting.
    pub(crate) fn prune(&mut self, still_waiting: impl Fn(&Q) -> bool) {
        self.held.prune(still_waiting);
    }

    /// The control names `active` the active generation. Returns the generation whose host must
    /// get `demos.jsonl` now (a remote one just made active: every expert before it has exited
    /// and its answers are written); the hub calls [`ExpertDesk::log_sent`] with its lines.
    pub(crate) fn control(&mut self, active: u32) -> Option<u16> {
        if active == self.active {
            return None;
        }
        self.active = active;
        let g = u16::try_from(active).ok()?;
        self.hosts.contains_key(&g).then_some(g)
    }

    /// The file sent to the remote expert holds `lines` demonstrations.
    pub(crate) fn log_sent(&mut self, lines: usize) {
        self.written = lines;
        self.early_model = None;
        self.resend_asked = None;
    }

    /// A remote expert's model. Returns it when it may be published now; one that counts a
    /// demonstration not yet written here waits for it (and one of a generation no host serves
    /// is dropped).
    pub(crate) fn model(
        &mut self,
        header: DemoModelHeader,
        bytes: Vec<u8>,
    ) -> Option<(DemoModelHeader, Vec<u8>)> {
        if !self.serves(header.expert) {
            return None;
        }
        if header.demos as usize > self.written {
            self.early_model = Some((header, bytes));
            return None;
        }
        Some((header, bytes))
    }

    /// Why a frame about a remote expert (its answer, its status, its exit) from the joined host
    /// `from` is refused, if it is: its generation is not one `from` was told to start.
    pub(crate) fn refusal(&self, f: &Frame, from: &str) -> Option<String> {
        let generation = match f {
            Frame::ExpertAnswer(r) => r.expert,
            Frame::ExpertExited { generation, .. }
            | Frame::ExpertDemos { generation, .. }
            | Frame::DemosLost { generation, .. } => u32::from(*generation),
            Frame::Progress(p) if p.header.role == Role::Expert as u16 => u32::from(p.header.id),
            _ => return None,
        };
        let host = u16::try_from(generation)
            .ok()
            .and_then(|g| self.hosts.get(&g));
        match host {
            Some(h) if h == from => None,
            Some(h) => Some(format!(
                "a message from host {from} for the expert of generation {generation}, which \
                 host {h} serves"
            )),
            None => Some(format!(
                "a message from host {from} for the expert of generation {generation}, which no \
                 joined host serves"
            )),
        }
    }

    /// Lines of a remote expert's `demos.jsonl`, the first of them line `first`: what to append.
    pub(crate) fn demos(&mut self, generation: u16, first: u32, mut lines: Vec<String>) -> Intake {
        if !self.serves(u32::from(generation)) {
            self.refused += lines.len() as u64;
            return Intake::Refused(format!(
                "{} demonstrations of generation {generation}, which no joined host serves",
                lines.len()
            ));
        }
        // Only the active generation writes: a generation the control has moved on from (its
        // successor may have written at the same indices) is not taken.
        if self.active != 0 && self.active != u32::from(generation) {
            self.refused += lines.len() as u64;
            return Intake::Refused(format!(
                "{} demonstrations of generation {generation}, which is not the active one ({})",
                lines.len(),
                self.active
            ));
        }
        let first = first as usize;
        if first > self.written {
            if self.resend_asked == Some(self.written) {
                return Intake::Wait;
            }
            self.resend_asked = Some(self.written);
            return Intake::Resend {
                generation,
                from: self.written as u32,
            };
        }
        lines.drain(..(self.written - first).min(lines.len()));
        if lines.is_empty() {
            Intake::Nothing
        } else {
            Intake::Append(lines)
        }
    }

    /// `n` lines are on disk: returns the model that waited for them, if any, to publish now.
    pub(crate) fn appended(&mut self, n: usize) -> Option<(DemoModelHeader, Vec<u8>)> {
        self.written += n;
        self.early_model
            .take_if(|(h, _)| h.demos as usize <= self.written)
    }

    /// `n` lines could not be appended (the hub's disk): they are asked for again with the next
    /// lines that come.
    pub(crate) fn append_failed(&mut self, n: usize) {
        self.refused += n as u64;
        self.resend_asked = None;
    }

    /// A remote expert's lines this run's file did not take, and those lost with a host
    /// (reported at its next activation).
    pub(crate) fn lost(&mut self, n: u32) {
        self.refused += u64::from(n);
    }

    /// Lines of remote experts the run's file did not take.
    pub(crate) fn refused(&self) -> u64 {
        self.refused
    }

    /// Answers with a demonstration that came after their query stopped waiting.
    pub(crate) fn late(&self) -> u64 {
        self.late
    }

    /// Checks a remote expert's answer: `Err` with why it is dropped (its generation gone, or
    /// its demonstration's line not in the run's file).
    pub(crate) fn check_answer(&self, r: &QueryResponse) -> Result<(), String> {
        if !self.serves(r.expert) {
            return Err(format!(
                "an answer (demonstration {}) of generation {}, which no joined host serves",
                r.demo_index, r.expert
            ));
        }
        if r.outcome == outcome::ANSWERED && r.demo_index as usize >= self.written {
            return Err(format!(
                "an answer with demonstration {} where demos.jsonl holds {}",
                r.demo_index, self.written
            ));
        }
        Ok(())
    }

    /// What to do with a checked answer: deliver it to the query it answers, or drop it (an
    /// answer with a demonstration dropped so is counted late).
    pub(crate) fn answered(&mut self, r: QueryResponse) -> Answer<Q>
    where
        Q: HasSeq,
    {
        match self.held.take(&r) {
            Ok(query) => Answer::Deliver { query, response: r },
            Err(why) => {
                if r.outcome == outcome::ANSWERED {
                    self.late += 1;
                }
                Answer::Dropped(why)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_of_a_generation_the_control_moved_on_from_are_refused() {
        let mut d = ExpertDesk::<u8>::default();
        d.started(2, "a");
        assert_eq!(d.control(2), Some(2));
        d.log_sent(136);
        let line = || vec!["{\"index\":136}".to_owned()];
        assert_eq!(d.demos(2, 136, line()), Intake::Append(line()));
        d.appended(1);
        // A local generation 3 is made active (it reads the file and writes at 137 on); a late
        // line of generation 2 must not follow its lines.
        assert_eq!(d.control(3), None);
        assert!(
            matches!(d.demos(2, 137, line()), Intake::Refused(why) if why.contains("not the active one"))
        );
        assert_eq!(d.refused(), 1);
    }

    #[test]
    fn only_the_host_serving_a_generation_speaks_for_its_expert() {
        let mut d = ExpertDesk::<u8>::default();
        d.started(3, "a");
        let answer = |g: u32| {
            Frame::ExpertAnswer(QueryResponse {
                expert: g,
                ..Default::default()
            })
        };
        let exited = |g: u16| Frame::ExpertExited {
            generation: g,
            how: "exit status: 0".into(),
            code: Some(0),
        };
        assert_eq!(d.refusal(&answer(3), "a"), None);
        assert_eq!(d.refusal(&exited(3), "a"), None);
        let demos = |g: u16| Frame::ExpertDemos {
            generation: g,
            first: 0,
            lines: vec![],
        };
        assert_eq!(d.refusal(&demos(3), "a"), None);
        assert!(d.refusal(&demos(3), "b").is_some());
        let lost = Frame::DemosLost {
            generation: 3,
            lines: 1,
        };
        assert!(d.refusal(&lost, "b").is_some());
        let other = d.refusal(&answer(3), "b").unwrap();
        assert!(other.contains("which host a serves"), "{other}");
        assert!(d.refusal(&exited(3), "b").is_some());
        assert!(d
            .refusal(&answer(5), "a")
            .unwrap()
            .contains("no joined host serves"));
        let status = |g: u16| {
            let mut p = alfd_wire::Progress::default();
            p.header.role = Role::Expert as u16;
            p.header.id = g;
            Frame::Progress(p)
        };
        assert_eq!(d.refusal(&status(3), "a"), None);
        assert!(d.refusal(&status(3), "b").is_some());
        // Frames about actors are the roster's to check.
        assert_eq!(d.refusal(&Frame::Progress(Default::default()), "b"), None);
    }

    /// A held query: its sequence number.
    #[derive(Debug, PartialEq)]
    struct Held(u64);

    impl HasSeq for Held {
        fn seq(&self) -> u64 {
            self.0
        }
    }

    fn answer(generation: u32, actor: u32, seq: u64, index: u32) -> QueryResponse {
        QueryResponse {
            outcome: outcome::ANSWERED,
            expert: generation,
            actor,
            request_seq: seq,
            demo_index: index,
            ..QueryResponse::default()
        }
    }

    fn lines(n: usize) -> Vec<String> {
        (0..n).map(|i| format!("l{i}")).collect()
    }

    fn model(generation: u32, demos: u32) -> DemoModelHeader {
        DemoModelHeader {
            expert: generation,
            demos,
            ..DemoModelHeader::default()
        }
    }

    /// A desk whose generation 2 is served by host "h" and active, with `lines` written.
    fn active_desk(lines: usize) -> ExpertDesk<Held> {
        let mut d = ExpertDesk::default();
        d.started(2, "h");
        assert_eq!(d.control(2), Some(2));
        d.log_sent(lines);
        d
    }

    #[test]
    fn queries_are_held_only_while_a_remote_generation_is_active() {
        let mut d: ExpertDesk<Held> = ExpertDesk::default();
        assert!(!d.holds_queries());
        d.started(2, "h");
        assert!(!d.holds_queries(), "started, not active yet");
        assert_eq!(d.control(1), None, "generation 1 is this host's own");
        assert!(!d.holds_queries());
        assert_eq!(d.control(2), Some(2));
        assert!(d.holds_queries());
        assert_eq!(d.control(2), None, "the same control again sends nothing");
    }

    #[test]
    fn an_answer_is_delivered_once_its_line_is_written() {
        let mut d = active_desk(3);
        d.hold(5, Held(10));
        let r = answer(2, 5, 10, 3);
        // Its line (demonstration 3) has not come: dropped.
        let e = d.check_answer(&r).unwrap_err();
        assert!(
            e.contains("demonstration 3 where demos.jsonl holds 3"),
            "{e}"
        );
        assert_eq!(d.demos(2, 3, lines(1)), Intake::Append(lines(1)));
        assert_eq!(d.appended(1), None);
        assert_eq!(d.check_answer(&r), Ok(()));
        assert_eq!(
            d.answered(r),
            Answer::Deliver {
                query: Held(10),
                response: r
            }
        );
        // An answer without a demonstration (budget spent) needs no line.
        let mut spent = answer(2, 5, 11, 0);
        spent.outcome = outcome::BUDGET_EXHAUSTED;
        assert_eq!(d.check_answer(&spent), Ok(()));
        assert_eq!(d.late(), 0);
    }

    #[test]
    fn lines_are_taken_in_order_once_and_a_gap_is_asked_for_again_once() {
        let mut d = active_desk(3);
        // Lines 1-4: the file holds 0-2, so only 3 and 4 are appended.
        let l = |v: &[&str]| v.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>();
        assert_eq!(
            d.demos(2, 1, l(&["a", "b", "c", "d"])),
            Intake::Append(l(&["c", "d"]))
        );
        d.appended(2);
        assert_eq!(d.demos(2, 0, lines(5)), Intake::Nothing, "all held already");
        // Lines from 7 on while the file holds 5: asked again from 5, once.
        assert_eq!(
            d.demos(2, 7, lines(1)),
            Intake::Resend {
                generation: 2,
                from: 5
            }
        );
        assert_eq!(d.demos(2, 8, lines(1)), Intake::Wait);
        // The host sends again from 5: taken, and a later gap is asked about again.
        assert_eq!(d.demos(2, 5, lines(4)), Intake::Append(lines(4)));
        d.appended(4);
        assert!(matches!(
            d.demos(2, 10, lines(1)),
            Intake::Resend { from: 9, .. }
        ));
        // Lines the disk refused are counted, and the next gap is asked about at once.
        d.append_failed(1);
        assert!(matches!(
            d.demos(2, 10, lines(1)),
            Intake::Resend { from: 9, .. }
        ));
        assert_eq!(d.refused(), 1);
    }

    #[test]
    fn an_answer_to_an_older_query_keeps_the_newer_one_held_and_is_counted_late() {
        let mut d = active_desk(0);
        d.demos(2, 0, lines(3));
        d.appended(3);
        d.hold(1, Held(7));
        // The actor gave up on query 6 and asked again (7): the late answer to 6 is dropped,
        // its demonstration kept.
        let a = d.answered(answer(2, 1, 6, 0));
        assert!(matches!(a, Answer::Dropped(why) if why.contains("older")));
        let a = d.answered(answer(2, 1, 7, 1));
        assert!(matches!(a, Answer::Deliver { query: Held(7), .. }));
        // Nothing held any more.
        let a = d.answered(answer(2, 1, 7, 2));
        assert!(matches!(a, Answer::Dropped(why) if why.contains("no longer waits")));
        assert_eq!(d.late(), 2);
    }

    #[test]
    fn a_model_waits_for_the_demonstrations_it_counts() {
        let mut d = active_desk(3);
        assert_eq!(d.model(model(2, 3), vec![1]), Some((model(2, 3), vec![1])));
        // It counts demonstration 3 (the 4th), whose line is on its way: held.
        assert_eq!(d.model(model(2, 4), vec![2]), None);
        assert_eq!(d.demos(2, 3, lines(1)), Intake::Append(lines(1)));
        assert_eq!(
            d.appended(1),
            Some((model(2, 4), vec![2])),
            "published first"
        );
        // Lines that bring it no nearer free no model.
        assert_eq!(d.model(model(2, 6), vec![3]), None);
        assert_eq!(d.appended(1), None);
        assert_eq!(d.appended(1), Some((model(2, 6), vec![3])));
    }

    #[test]
    fn nothing_is_taken_from_a_host_that_left_or_an_expert_that_exited() {
        let mut d = active_desk(0);
        d.started(3, "other");
        assert_eq!(d.host_left("h"), vec![2]);
        assert!(!d.holds_queries());
        let e = d.check_answer(&answer(2, 0, 1, 0)).unwrap_err();
        assert!(e.contains("no joined host serves"), "{e}");
        // Its lines are refused and counted.
        assert!(matches!(d.demos(2, 0, lines(2)), Intake::Refused(_)));
        assert_eq!(d.refused(), 2);
        assert_eq!(d.model(model(2, 0), vec![]), None);
        // Generation 3 exits: its late model is dropped, and the waiting one forgotten.
        assert_eq!(d.control(3), Some(3));
        d.log_sent(0);
        assert_eq!(d.model(model(3, 1), vec![9]), None);
        d.exited(3);
        assert_eq!(d.model(model(3, 1), vec![9]), None);
        assert!(d.check_answer(&answer(3, 0, 1, 0)).is_err());
    }

    #[test]
    fn held_queries_of_actors_that_stopped_waiting_are_forgotten() {
        let mut d = active_desk(0);
        d.hold(1, Held(1));
        d.hold(2, Held(2));
        d.prune(|q| q.0 != 1);
        assert!(matches!(d.answered(answer(2, 1, 1, 0)), Answer::Dropped(_)));
        assert!(matches!(
            d.answered(answer(2, 2, 2, 1)),
            Answer::Deliver { .. }
        ));
    }
}
