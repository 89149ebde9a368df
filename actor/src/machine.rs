//! The actor process's decisions on the wire as pure state machines: the [`CreditGate`] (may the
//! next step be taken, under the learner's credits?), the [`CreditPoll`] (how long to poll the
//! doorbell before sleeping on it?) and the [`QueryWait`] (what came of a query to the
//! expert?). Events in (credits received, a step sent, the expert's answer or its
//! absence, the time), decisions out; no I/O, clock or socket inside: `links.rs` is the shell
//! that sends the batches, waits on the doorbell and polls the query.
//!
//! The rules a fault must not break:
//! - an actor never sends a step beyond its grant, or beyond the implicit `window` before the
//!   learner knows its incarnation (see `alfd_wire`'s crate doc on credits);
//! - an actor out of credits flags its batch `blocked` once, and again every [`RESYNC_AFTER`]
//!   while the learner's credits say nothing of it (a learner restarted from its checkpoint
//!   knows neither the actor nor that it waits);
//! - a query ends with the expert's answer, its refusal, at the deadline, or as soon as no
//!   expert holds it any more (an answer sent just before that is still taken).

use std::time::Duration;

use alfd_wire::{outcome, Credits, QueryResponse};

/// Control is looked at every this many steps (and during every wait).
pub const CHECK_EVERY: u32 = 64;

/// An actor out of credits that the learner does not know (a learner restarted from its
/// checkpoint) flags itself again after this long.
pub const RESYNC_AFTER: Duration = Duration::from_millis(250);

/// Who this actor is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    pub id: u16,
    pub incarnation: u64,
}

/// What the actor does before its next step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gate {
    /// Take the step.
    Go,
    /// Take the step after a look at the launcher's control (every [`CHECK_EVERY`] steps).
    CheckStopThenGo,
    /// Out of credits: send the batch flagged `blocked` (even empty) and wait for credits.
    Block,
}

/// What a blocked actor does after a wait.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Blocked {
    /// Credits arrived: go on.
    Resume,
    /// The learner does not know this actor: send a `blocked` batch again, then wait.
    Reflag,
    /// Wait on.
    Wait,
}

/// The credit protocol from the actor's side. Time is a `Duration` since any fixed instant.
#[derive(Debug, Clone)]
pub struct CreditGate {
    me: Identity,
    window: u64,
    credits: Option<Credits>,
    /// Sequence number of the next transition (= transitions this incarnation produced).
    next_seq: u64,
    since_check: u32,
    /// When the actor last flagged itself blocked, while it is.
    flagged: Option<Duration>,
}

impl CreditGate {
    pub fn new(me: Identity, window: u64) -> Self {
        Self {
            me,
            window,
            credits: None,
            next_seq: 0,
            since_check: 0,
            flagged: None,
        }
    }

    /// The learner's newest credits arrived.
    pub fn credits(&mut self, c: Credits) {
        self.credits = Some(c);
    }

    /// The learner's newest credits, if any arrived.
    pub fn latest(&self) -> Option<&Credits> {
        self.credits.as_ref()
    }

    /// Transitions produced by this incarnation (the next one's sequence number).
    pub fn next_seq(&self) -> u64 {
        self.next_seq
    }

    /// Steps this actor may send: its grant, or the implicit window before any grant.
    pub fn granted(&self) -> u64 {
        self.credits
            .as_ref()
            .and_then(|c| c.granted_for(self.me.id, self.me.incarnation))
            .unwrap_or(0)
            .max(self.window)
    }

    /// Whether the learner's newest credits say nothing of this incarnation.
    pub fn unknown_to_learner(&self) -> bool {
        self.credits
            .as_ref()
            .is_none_or(|c| c.granted_for(self.me.id, self.me.incarnation).is_none())
    }

    /// Before a step, at time `now`: go, look at control and go, or block.
    pub fn reserve(&mut self, now: Duration) -> Gate {
        if self.next_seq >= self.granted() {
            self.flagged = Some(now);
            return Gate::Block;
        }
        self.gone()
    }

    /// A step is taken (after [`Gate::Go`], or [`Blocked::Resume`]): counts toward the next look
    /// at control.
    fn gone(&mut self) -> Gate {
        self.since_check += 1;
        if self.since_check >= CHECK_EVERY {
            self.since_check = 0;
            Gate::CheckStopThenGo
        } else {
            Gate::Go
        }
    }

    /// A blocked actor after a wait, at time `now` (with the credits taken in before).
    pub fn after_wait(&mut self, now: Duration) -> Blocked {
        let Some(flagged) = self.flagged else {
            return Blocked::Resume;
        };
        if self.next_seq < self.granted() {
            self.flagged = None;
            return Blocked::Resume;
        }
        if self.unknown_to_learner() && now.saturating_sub(flagged) >= RESYNC_AFTER {
            self.flagged = Some(now);
            return Blocked::Reflag;
        }
        Blocked::Wait
    }

    /// Once resumed: the step goes (counted like any other); `CheckStopThenGo` every
    /// [`CHECK_EVERY`] steps.
    pub fn resumed(&mut self) -> Gate {
        self.gone()
    }

    /// The transition with sequence number [`next_seq`](Self::next_seq) went into the batch.
    pub fn added(&mut self) {
        self.next_seq += 1;
    }

    /// The global step as this actor sees it after `produced` of its own steps.
    pub fn global_step(&self, produced: u64, own_steps: u64) -> u64 {
        self.credits.as_ref().map_or(own_steps, |c| {
            c.global_step_for(self.me.id, self.me.incarnation, produced)
        })
    }
}

/// How long a blocked actor polls its doorbell before it sleeps on it (unless
/// [`CREDIT_POLL_VAR`] says otherwise).
pub const CREDIT_POLL: Duration = Duration::from_millis(2);

/// How often a polling actor looks at its doorbell.
pub const CREDIT_POLL_EVERY: Duration = Duration::from_micros(200);

/// The environment variable that sets [`CREDIT_POLL`] in microseconds (`0`: sleep on the
/// doorbell at once).
pub const CREDIT_POLL_VAR: &str = "ALFD_CREDIT_POLL_US";

/// How long a blocked actor polls its doorbell (every [`CREDIT_POLL_EVERY`]) before it sleeps
/// on it. The learner rings a blocked actor when its credits come; ringing an actor asleep
/// costs the learner the wake-up of the actor's core (an interrupt between cores), ringing one
/// that polls only the message, which the actor's next look takes. That pays where the learner
/// has another actor's steps to learn from while this one waits, so an actor polls only when
/// the learner's credits name other actors too: alone, its poll's delay (up to a look's
/// interval) would be the learner's idle time. It polls while its waits end within the poll:
/// after a longer wait (many actors taking turns at the learner, a window that lets it run far
/// ahead, a learner busy elsewhere) it sleeps at once, since its looks would find nothing and
/// take the core from the other processes; the next wait that ends within the poll turns
/// polling back on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CreditPoll {
    poll: Duration,
    last_wait: Option<Duration>,
}

impl CreditPoll {
    /// Polls for up to `poll` (zero: never).
    pub fn new(poll: Duration) -> Self {
        Self {
            poll,
            last_wait: None,
        }
    }

    /// How long to poll in the next wait, in a run whose learner grants steps to `actors`
    /// actors (this one among them).
    pub fn poll_for(&self, actors: usize) -> Duration {
        if actors < 2 || self.last_wait.is_some_and(|w| w > self.poll) {
            Duration::ZERO
        } else {
            self.poll
        }
    }

    /// A wait for credits took `waited`.
    pub fn waited(&mut self, waited: Duration) {
        self.last_wait = Some(waited);
    }
}

/// The poll given [`CREDIT_POLL_VAR`]'s value: microseconds, `0` none; anything else (logged)
/// or nothing is [`CREDIT_POLL`].
pub fn credit_poll(var: Option<&str>) -> Duration {
    alfd_harness::micros_var(CREDIT_POLL_VAR, var, CREDIT_POLL)
}

/// What came of a query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Answer {
    Demo(QueryResponse),
    BudgetExhausted,
    /// No expert is active or connected: the actor acts on its own at once.
    NoExpert,
    /// The expert did not answer in time: the actor acted on its own.
    Timeout,
    /// The expert (a person) declined: the actor acts on its own; no budget was spent.
    Declined,
    /// No expert holds the query any more and no answer came: the actor acts on its own.
    Dropped,
}

impl Answer {
    /// The answer a response carries.
    pub fn of(r: QueryResponse) -> Self {
        match r.outcome {
            outcome::ANSWERED => Answer::Demo(r),
            outcome::DECLINED => Answer::Declined,
            _ => Answer::BudgetExhausted,
        }
    }
}

/// A query in flight, until its deadline.
#[derive(Debug, Clone, Copy)]
pub struct QueryWait {
    deadline: Duration,
}

/// What one look at a query in flight found, and what to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Poll {
    /// The query ended.
    Done(Answer),
    /// Wait at most this long, then look again.
    Wait(Duration),
}

impl QueryWait {
    /// A query sent at `now`, waiting at most `timeout`.
    pub fn new(now: Duration, timeout: Duration) -> Self {
        Self {
            deadline: now.saturating_add(timeout),
        }
    }

    /// One look at time `now`: `response` is what the query's port held, `held` whether an expert
    /// still holds the query, `then` the response read after seeing it let go (one sent just
    /// before is taken), `interrupted` whether a signal cut the last wait short.
    pub fn poll(
        &self,
        now: Duration,
        response: Option<QueryResponse>,
        held: bool,
        then: impl FnOnce() -> Option<QueryResponse>,
        interrupted: bool,
    ) -> Poll {
        if let Some(r) = response {
            return Poll::Done(Answer::of(r));
        }
        if !held {
            return Poll::Done(then().map_or(Answer::Dropped, Answer::of));
        }
        if interrupted || now >= self.deadline {
            return Poll::Done(Answer::Timeout);
        }
        Poll::Wait((self.deadline - now).min(Duration::from_millis(50)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_wire::Header;

    const ME: Identity = Identity {
        id: 2,
        incarnation: 3,
    };

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    fn credits(incarnation: u64, granted: u64) -> Credits {
        let mut c = Credits {
            header: Header::default(),
            env_steps: 100,
            updates: 0,
            received: [0; alfd_wire::MAX_ACTORS],
            incarnation: [0; alfd_wire::MAX_ACTORS],
            granted: [0; alfd_wire::MAX_ACTORS],
        };
        c.incarnation[ME.id as usize] = incarnation;
        c.granted[ME.id as usize] = granted;
        c.received[ME.id as usize] = granted.saturating_sub(4);
        c
    }

    fn response(outcome: u32) -> QueryResponse {
        QueryResponse {
            outcome,
            ..QueryResponse::default()
        }
    }

    /// Takes `n` steps through the gate, asserting none blocks.
    fn take(gate: &mut CreditGate, n: u64) {
        for _ in 0..n {
            assert_ne!(gate.reserve(ms(0)), Gate::Block);
            gate.added();
        }
    }

    #[test]
    fn an_actor_polls_while_its_waits_end_within_the_poll() {
        let mut p = CreditPoll::new(ms(2));
        assert_eq!(p.poll_for(2), ms(2), "the first wait polls");
        p.waited(Duration::from_micros(900));
        assert_eq!(p.poll_for(2), ms(2));
        p.waited(ms(2));
        assert_eq!(
            p.poll_for(2),
            ms(2),
            "a wait of exactly the poll was caught by it"
        );
        p.waited(ms(9));
        assert_eq!(
            p.poll_for(2),
            Duration::ZERO,
            "after a longer wait it sleeps at once"
        );
        p.waited(ms(1));
        assert_eq!(p.poll_for(8), ms(2), "a short wait turns polling back on");
        let mut never = CreditPoll::new(Duration::ZERO);
        assert_eq!(never.poll_for(2), Duration::ZERO);
        never.waited(Duration::ZERO);
        assert_eq!(never.poll_for(2), Duration::ZERO);
    }

    #[test]
    fn an_actor_the_learner_serves_alone_sleeps_at_once() {
        let mut p = CreditPoll::new(ms(2));
        assert_eq!(p.poll_for(1), Duration::ZERO);
        assert_eq!(p.poll_for(0), Duration::ZERO, "before any credits");
        p.waited(Duration::from_micros(500));
        assert_eq!(p.poll_for(1), Duration::ZERO);
        assert_eq!(p.poll_for(2), ms(2), "a second actor turns polling on");
    }

    #[test]
    fn the_learners_credits_count_the_actors_it_grants_to() {
        let mut c = credits(ME.incarnation, 6);
        assert_eq!(c.actors(), 1);
        c.incarnation[0] = 1;
        c.incarnation[alfd_wire::MAX_ACTORS - 1] = 1_000_001;
        assert_eq!(c.actors(), 3);
        assert_eq!(Credits::default().actors(), 0);
    }

    #[test]
    fn the_variable_sets_the_poll_in_microseconds_and_zero_turns_it_off() {
        assert_eq!(credit_poll(None), CREDIT_POLL);
        assert_eq!(credit_poll(Some("500")), Duration::from_micros(500));
        assert_eq!(credit_poll(Some(" 0 ")), Duration::ZERO);
        assert_eq!(credit_poll(Some("fast")), CREDIT_POLL);
        assert_eq!(credit_poll(Some("-1")), CREDIT_POLL);
    }

    #[test]
    fn before_any_grant_the_window_is_the_limit() {
        let mut gate = CreditGate::new(ME, 4);
        take(&mut gate, 4);
        assert_eq!(gate.reserve(ms(0)), Gate::Block);
        assert_eq!(gate.next_seq(), 4);
    }

    #[test]
    fn a_grant_lets_the_actor_go_and_never_beyond_it() {
        let mut gate = CreditGate::new(ME, 4);
        take(&mut gate, 4);
        assert_eq!(gate.reserve(ms(0)), Gate::Block);
        gate.credits(credits(ME.incarnation, 6));
        assert_eq!(gate.after_wait(ms(10)), Blocked::Resume);
        assert_ne!(gate.resumed(), Gate::Block);
        gate.added();
        take(&mut gate, 1);
        assert_eq!(gate.next_seq(), 6);
        assert_eq!(gate.reserve(ms(20)), Gate::Block);
    }

    #[test]
    fn a_grant_for_an_earlier_incarnation_is_not_this_ones() {
        let mut gate = CreditGate::new(ME, 2);
        gate.credits(credits(ME.incarnation - 1, 50));
        assert!(gate.unknown_to_learner());
        assert_eq!(gate.granted(), 2);
        take(&mut gate, 2);
        assert_eq!(gate.reserve(ms(0)), Gate::Block);
    }

    #[test]
    fn a_blocked_actor_unknown_to_the_learner_flags_itself_again_every_resync_period() {
        let mut gate = CreditGate::new(ME, 1);
        take(&mut gate, 1);
        assert_eq!(gate.reserve(ms(1000)), Gate::Block);
        assert_eq!(gate.after_wait(ms(1100)), Blocked::Wait);
        assert_eq!(gate.after_wait(ms(1250)), Blocked::Reflag);
        // The period counts from the last flag.
        assert_eq!(gate.after_wait(ms(1400)), Blocked::Wait);
        assert_eq!(gate.after_wait(ms(1500)), Blocked::Reflag);
    }

    #[test]
    fn a_blocked_actor_the_learner_knows_waits_without_flagging_again() {
        let mut gate = CreditGate::new(ME, 1);
        gate.credits(credits(ME.incarnation, 1));
        take(&mut gate, 1);
        assert_eq!(gate.reserve(ms(0)), Gate::Block);
        assert_eq!(gate.after_wait(ms(10_000)), Blocked::Wait);
        // A learner restarted from its checkpoint publishes credits without this incarnation.
        gate.credits(credits(0, 0));
        assert_eq!(gate.after_wait(ms(10_100)), Blocked::Reflag);
    }

    #[test]
    fn control_is_looked_at_every_check_every_steps_blocked_or_not() {
        let mut gate = CreditGate::new(ME, u64::MAX);
        let mut checks = Vec::new();
        for step in 1..=(3 * CHECK_EVERY as u64) {
            if gate.reserve(ms(0)) == Gate::CheckStopThenGo {
                checks.push(step);
            }
            gate.added();
        }
        let every = u64::from(CHECK_EVERY);
        assert_eq!(checks, vec![every, 2 * every, 3 * every]);
    }

    #[test]
    fn the_global_step_is_the_actors_own_count_until_credits_arrive() {
        let mut gate = CreditGate::new(ME, 8);
        assert_eq!(gate.global_step(5, 17), 17);
        gate.credits(credits(ME.incarnation, 10));
        // 100 received by the learner in all, 6 of them this actor's, 9 produced: 3 in flight.
        assert_eq!(gate.global_step(9, 17), 103);
    }

    #[test]
    fn a_query_ends_with_its_answer_refusal_or_the_budget() {
        let q = QueryWait::new(ms(0), ms(100));
        let done = |o| q.poll(ms(10), Some(response(o)), true, || None, false);
        assert!(matches!(
            done(outcome::ANSWERED),
            Poll::Done(Answer::Demo(_))
        ));
        assert_eq!(done(outcome::DECLINED), Poll::Done(Answer::Declined));
        assert_eq!(
            done(outcome::BUDGET_EXHAUSTED),
            Poll::Done(Answer::BudgetExhausted)
        );
    }

    #[test]
    fn a_query_waits_in_short_steps_until_its_deadline() {
        let q = QueryWait::new(ms(1000), ms(120));
        assert_eq!(
            q.poll(ms(1000), None, true, || None, false),
            Poll::Wait(ms(50))
        );
        assert_eq!(
            q.poll(ms(1100), None, true, || None, false),
            Poll::Wait(ms(20))
        );
        assert_eq!(
            q.poll(ms(1120), None, true, || None, false),
            Poll::Done(Answer::Timeout)
        );
        // A signal during the wait ends it as a timeout (the actor then acts on its own).
        assert_eq!(
            q.poll(ms(1001), None, true, || None, true),
            Poll::Done(Answer::Timeout)
        );
    }

    #[test]
    fn a_query_no_expert_holds_ends_at_once_but_takes_an_answer_sent_just_before() {
        let q = QueryWait::new(ms(0), ms(60_000));
        assert_eq!(
            q.poll(ms(5), None, false, || None, false),
            Poll::Done(Answer::Dropped)
        );
        assert!(matches!(
            q.poll(
                ms(5),
                None,
                false,
                || Some(response(outcome::ANSWERED)),
                false
            ),
            Poll::Done(Answer::Demo(_))
        ));
    }
}
