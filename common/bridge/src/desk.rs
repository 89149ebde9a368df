//! The hub's side of a remote expert, as a state machine: which generations remote hosts serve,
//! which one is active, how many lines of `demos.jsonl` are written, the newest model waiting for
//! its demonstrations to be written, and the actors' queries held for the remote expert. No I/O
//! inside: the hub's thread (`hub.rs`) appends, publishes, answers and sends what it says.
//!
//! The rules a fault must not break:
//! - a demonstration is on disk here before its answer reaches an actor, and a model that counts
//!   demonstrations not yet written here waits until they are;
//! - nothing more is taken from a generation whose host left or whose expert exited (its answers
//!   are neither written nor answered);
//! - a demonstration is written only as the file's next line (a repeated or skipped index is
//!   refused, and its answer not sent);
//! - an answer goes only to the query it answers (an actor's newer query replaces its older one).

use std::collections::HashMap;

use alfd_wire::{DemoModelHeader, QueryResponse, Role};

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
}

impl<Q> Default for ExpertDesk<Q> {
    fn default() -> Self {
        Self {
            hosts: HashMap::new(),
            active: 0,
            written: 0,
            early_model: None,
            held: HeldQueries::default(),
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
            Frame::ExpertAnswer(r, _) => r.expert,
            Frame::ExpertExited { generation, .. } => u32::from(*generation),
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

    /// Checks a remote expert's answer before its demonstration (if any) is written: `Err` with
    /// why it is dropped (its generation gone, or not the file's next line).
    pub(crate) fn check_answer(&self, r: &QueryResponse, demo: Option<&str>) -> Result<(), String> {
        if !self.serves(r.expert) {
            return Err(format!(
                "an answer (demonstration {}) of generation {}, which no joined host serves",
                r.demo_index, r.expert
            ));
        }
        if demo.is_some() && r.demo_index as usize != self.written {
            return Err(format!(
                "demonstration {} where demos.jsonl holds {}",
                r.demo_index, self.written
            ));
        }
        Ok(())
    }

    /// The answer's demonstration is on disk (or it had none): returns the model that waited
    /// for it, if any, to publish first, and what to do with the answer.
    pub(crate) fn answered(
        &mut self,
        r: QueryResponse,
        wrote: bool,
    ) -> (Option<(DemoModelHeader, Vec<u8>)>, Answer<Q>)
    where
        Q: HasSeq,
    {
        let mut model = None;
        if wrote {
            self.written = r.demo_index as usize + 1;
            model = self
                .early_model
                .take_if(|(h, _)| h.demos as usize <= self.written);
        }
        let answer = match self.held.take(&r) {
            Ok(query) => Answer::Deliver { query, response: r },
            Err(why) => Answer::Dropped(why),
        };
        (model, answer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_host_serving_a_generation_speaks_for_its_expert() {
        let mut d = ExpertDesk::<u8>::default();
        d.started(3, "a");
        let answer = |g: u32| {
            Frame::ExpertAnswer(
                QueryResponse {
                    expert: g,
                    ..Default::default()
                },
                None,
            )
        };
        let exited = |g: u16| Frame::ExpertExited {
            generation: g,
            how: "exit status: 0".into(),
            code: Some(0),
        };
        assert_eq!(d.refusal(&answer(3), "a"), None);
        assert_eq!(d.refusal(&exited(3), "a"), None);
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
            expert: generation,
            actor,
            request_seq: seq,
            demo_index: index,
            ..QueryResponse::default()
        }
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
    fn an_answer_is_delivered_to_the_query_it_answers() {
        let mut d = active_desk(3);
        d.hold(5, Held(10));
        let r = answer(2, 5, 10, 3);
        assert_eq!(d.check_answer(&r, Some("{}")), Ok(()));
        let (m, a) = d.answered(r, true);
        assert_eq!(m, None);
        assert_eq!(
            a,
            Answer::Deliver {
                query: Held(10),
                response: r
            }
        );
        // The next demonstration must be line 4.
        assert!(d.check_answer(&answer(2, 5, 11, 3), Some("{}")).is_err());
        assert_eq!(d.check_answer(&answer(2, 5, 11, 4), Some("{}")), Ok(()));
    }

    #[test]
    fn a_repeated_or_skipped_demonstration_is_refused() {
        let d = active_desk(3);
        let repeated = d.check_answer(&answer(2, 0, 1, 2), Some("{}")).unwrap_err();
        assert!(
            repeated.contains("demonstration 2 where demos.jsonl holds 3"),
            "{repeated}"
        );
        assert!(d.check_answer(&answer(2, 0, 1, 4), Some("{}")).is_err());
        // An answer without a demonstration (budget spent) writes nothing: any index passes.
        assert_eq!(d.check_answer(&answer(2, 0, 1, 0), None), Ok(()));
    }

    #[test]
    fn an_answer_to_an_older_query_keeps_the_newer_one_held() {
        let mut d = active_desk(0);
        d.hold(1, Held(7));
        // The actor gave up on query 6 and asked again (7): the late answer to 6 is dropped.
        let (_, a) = d.answered(answer(2, 1, 6, 0), true);
        assert!(matches!(a, Answer::Dropped(why) if why.contains("older")));
        let (_, a) = d.answered(answer(2, 1, 7, 1), true);
        assert!(matches!(a, Answer::Deliver { query: Held(7), .. }));
        // Nothing held any more.
        let (_, a) = d.answered(answer(2, 1, 7, 2), true);
        assert!(matches!(a, Answer::Dropped(why) if why.contains("no longer waits")));
    }

    #[test]
    fn a_model_waits_for_the_demonstrations_it_counts() {
        let mut d = active_desk(3);
        assert_eq!(d.model(model(2, 3), vec![1]), Some((model(2, 3), vec![1])));
        // It counts demonstration 3 (the 4th), whose answer is on its way: held.
        assert_eq!(d.model(model(2, 4), vec![2]), None);
        d.hold(0, Held(1));
        let (m, a) = d.answered(answer(2, 0, 1, 3), true);
        assert_eq!(
            m,
            Some((model(2, 4), vec![2])),
            "published before the answer"
        );
        assert!(matches!(a, Answer::Deliver { .. }));
        // An answer that wrote nothing frees no model.
        assert_eq!(d.model(model(2, 5), vec![3]), None);
        let (m, _) = d.answered(answer(2, 0, 2, 0), false);
        assert_eq!(m, None);
    }

    #[test]
    fn nothing_is_taken_from_a_host_that_left_or_an_expert_that_exited() {
        let mut d = active_desk(0);
        d.started(3, "other");
        assert_eq!(d.host_left("h"), vec![2]);
        assert!(!d.holds_queries());
        let e = d.check_answer(&answer(2, 0, 1, 0), Some("{}")).unwrap_err();
        assert!(e.contains("no joined host serves"), "{e}");
        assert_eq!(d.model(model(2, 0), vec![]), None);
        // Generation 3 exits: its late model is dropped, and the waiting one forgotten.
        assert_eq!(d.control(3), Some(3));
        d.log_sent(0);
        assert_eq!(d.model(model(3, 1), vec![9]), None);
        d.exited(3);
        assert_eq!(d.model(model(3, 1), vec![9]), None);
        assert!(d.check_answer(&answer(3, 0, 1, 0), Some("{}")).is_err());
    }

    #[test]
    fn held_queries_of_actors_that_stopped_waiting_are_forgotten() {
        let mut d = active_desk(0);
        d.hold(1, Held(1));
        d.hold(2, Held(2));
        d.prune(|q| q.0 != 1);
        let (_, a) = d.answered(answer(2, 1, 1, 0), true);
        assert!(matches!(a, Answer::Dropped(_)));
        let (_, a) = d.answered(answer(2, 2, 2, 1), true);
        assert!(matches!(a, Answer::Deliver { .. }));
    }
}
