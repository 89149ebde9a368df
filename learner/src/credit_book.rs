//! The credit protocol as a pure state machine: what each actor sent, what the learner has
//! learned from, and the grants that keep every actor within a window of the learner (see
//! `alfd_wire`'s crate doc on credits). The learner's I/O loop only moves its messages.

use std::collections::VecDeque;

use alfd_common::replay::Transition;
use alfd_wire::{Credits, TransitionBatch, MAX_ACTORS};
use tracing::{info, warn};

/// Where the credits of each actor stand.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct ActorBook {
    incarnation: u64,
    /// One past the highest sequence number received (lost steps count as received).
    received: u64,
    /// Steps received and not yet learned from.
    queued: u64,
    lost: u64,
    /// The actor is blocked until its grant exceeds this sequence number.
    blocked_until: Option<u64>,
}

/// What the learner's batches must hold: the environment's observation size and number of
/// actions, and the config's K.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchShape {
    pub obs_dim: usize,
    pub heads: usize,
    pub actions: usize,
}

/// The learner's accounts: what each actor sent, what is learned from, and the grants.
#[derive(Debug, Clone)]
pub struct CreditBook {
    window: u64,
    shape: BatchShape,
    actors: [ActorBook; MAX_ACTORS],
    env_steps: u64,
    refused: u64,
}

/// One step waiting in the learner's queue.
#[derive(Debug, Clone)]
pub struct Queued {
    pub actor: u16,
    pub incarnation: u64,
    /// The last step of its batch: its processing frees a batch worth of credit.
    pub last_of_batch: bool,
    /// The last step of its episode (where the learner may checkpoint).
    pub episode_end: bool,
    pub transition: Transition,
}

impl CreditBook {
    pub fn new(window: u64, shape: BatchShape) -> Self {
        Self {
            window,
            shape,
            actors: [ActorBook::default(); MAX_ACTORS],
            env_steps: 0,
            refused: 0,
        }
    }

    /// Batches refused because they did not fit (see [`TransitionBatch::check`]).
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// Environment steps received from all actors: the run's global step.
    /// How many actor ids have sent transitions.
    pub fn senders(&self) -> usize {
        self.actors.iter().filter(|a| a.incarnation != 0).count()
    }

    pub fn env_steps(&self) -> u64 {
        self.env_steps
    }

    /// A learner restored from a checkpoint: the run's global step as it was then. The actors'
    /// accounts start afresh with each one's next batch.
    pub fn restore_env_steps(&mut self, env_steps: u64) {
        self.env_steps = env_steps;
    }

    /// Steps of `actor` lost on the way (never expected; logged).
    pub fn lost(&self, actor: u16) -> u64 {
        self.actors.get(actor as usize).map_or(0, |a| a.lost)
    }

    /// Takes in a batch, appending its steps to `queue`; returns how many it appended.
    pub fn accept(&mut self, b: &TransitionBatch, queue: &mut VecDeque<Queued>) -> usize {
        let a = b.head.actor as usize;
        if a >= MAX_ACTORS {
            warn!(
                actor = a,
                "transitions from an actor id beyond the credit table; dropped"
            );
            return 0;
        }
        let BatchShape {
            obs_dim,
            heads,
            actions,
        } = self.shape;
        if let Err(e) = b.check(obs_dim, heads, actions) {
            warn!(actor = a, "{e}; batch dropped");
            self.refused = self.refused.saturating_add(1);
            return 0;
        }
        let book = &mut self.actors[a];
        let current = b.head.incarnation >= book.incarnation;
        if b.head.incarnation > book.incarnation {
            if book.incarnation != 0 {
                info!(
                    actor = a,
                    old = book.incarnation,
                    new = b.head.incarnation,
                    "actor restarted"
                );
            }
            // An incarnation's first batch sets its baseline: a learner restored from a
            // checkpoint meets actors in the middle of their sequence, which is no loss.
            *book = ActorBook {
                incarnation: b.head.incarnation,
                received: b.head.first_seq,
                ..ActorBook::default()
            };
        }
        if current {
            if b.head.first_seq > book.received {
                let gap = b.head.first_seq - book.received;
                warn!(
                    actor = a,
                    gap, "transitions lost on the way; counted as received"
                );
                book.lost = book.lost.saturating_add(gap);
            }
            book.received = book.received.max(b.end_seq());
            book.queued = book.queued.saturating_add(b.len() as u64);
            if b.head.blocked != 0 {
                book.blocked_until = Some(b.end_seq());
            }
        }
        let n = b.len();
        for (i, transition) in b.transitions().enumerate() {
            queue.push_back(Queued {
                actor: b.head.actor as u16,
                incarnation: b.head.incarnation,
                last_of_batch: i + 1 == n,
                episode_end: b.ends_episode(i),
                transition,
            });
        }
        self.env_steps = self.env_steps.saturating_add(n as u64);
        n
    }

    /// Records that a queued step of `actor` has been learned from.
    pub fn learned(&mut self, actor: u16, incarnation: u64) {
        if let Some(book) = self.actors.get_mut(actor as usize) {
            if book.incarnation == incarnation {
                book.queued = book.queued.saturating_sub(1);
            }
        }
    }

    /// Whether an actor waits for credits.
    pub fn any_blocked(&self) -> bool {
        self.actors.iter().any(|a| a.blocked_until.is_some())
    }

    /// How many steps a grant must let a blocked actor take before it is woken: half the
    /// window (at least one). A woken actor then runs that many steps before it blocks again,
    /// instead of one step per wake-up when the learner is the slower side (each wake-up is a
    /// doorbell, a context switch in both processes and, across cores, an interrupt).
    pub fn wake_after(&self) -> u64 {
        (self.window / 2).max(1)
    }

    /// Whether a blocked actor's grant, published now, would wake it ([`CreditBook::grant`]).
    pub fn any_wake_due(&self) -> bool {
        self.actors.iter().any(|b| self.wakes(b))
    }

    /// Whether `book`'s actor is blocked and its grant lets it take [`CreditBook::wake_after`]
    /// steps.
    fn wakes(&self, book: &ActorBook) -> bool {
        book.blocked_until
            .is_some_and(|until| self.granted(book) >= until.saturating_add(self.wake_after()))
    }

    /// An actor's grant: `window` steps beyond those learned from. Saturating: a batch sent
    /// twice (sequence numbers going back) queues steps that `received` does not count again.
    fn granted(&self, book: &ActorBook) -> u64 {
        book.received
            .saturating_sub(book.queued)
            .saturating_add(self.window)
    }

    /// The grants to publish now, and the actors to wake: those blocked for want of credits
    /// that the new grants let take [`CreditBook::wake_after`] steps.
    pub fn grant(&mut self, updates: u64) -> (Credits, Vec<u16>) {
        let c = self.credits(updates);
        let mut wake = Vec::new();
        for i in 0..MAX_ACTORS {
            if self.wakes(&self.actors[i]) {
                wake.push(i as u16);
                self.actors[i].blocked_until = None;
            }
        }
        (c, wake)
    }

    /// The grants: each actor may send up to `window` steps beyond those learned from.
    pub fn credits(&self, updates: u64) -> Credits {
        let mut c = Credits {
            env_steps: self.env_steps,
            updates,
            ..Credits::default()
        };
        for (i, b) in self.actors.iter().enumerate() {
            c.incarnation[i] = b.incarnation;
            c.received[i] = b.received;
            c.granted[i] = self.granted(b);
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_wire::TRANSITIONS_PER_BATCH;

    const SHAPE: BatchShape = BatchShape {
        obs_dim: 4,
        heads: 2,
        actions: 2,
    };

    fn batch(actor: u16, incarnation: u64, first_seq: u64, len: usize) -> TransitionBatch {
        let mut b = TransitionBatch::new(actor, incarnation, 4, 2, first_seq).unwrap();
        for i in 0..len {
            let t = Transition {
                state: vec![i as f32; 4],
                action: 0,
                reward: 1.0,
                next_state: vec![i as f32 + 1.0; 4],
                terminated: false,
                mask: vec![1.0, 1.0],
                demo: false,
                horizon: 1,
            };
            b.push(&t).unwrap();
        }
        b
    }

    #[test]
    fn grants_follow_what_is_learned_from() {
        let mut book = CreditBook::new(64, SHAPE);
        let mut q = VecDeque::new();
        // Before anything: nobody has a grant (actors start with an implicit one of `window`).
        assert_eq!(book.credits(0).granted_for(0, 1), None);

        assert_eq!(book.accept(&batch(0, 1, 0, 32), &mut q), 32);
        assert_eq!(book.accept(&batch(1, 1, 0, 10), &mut q), 10);
        assert_eq!(book.env_steps(), 42);
        let c = book.credits(0);
        assert_eq!(
            c.granted_for(0, 1),
            Some(64),
            "nothing learned yet: window only"
        );
        assert_eq!(c.received[0], 32);
        assert_eq!(c.global_step_for(0, 1, 40), 42 + 8);

        for _ in 0..20 {
            let s = q.pop_front().unwrap();
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.credits(0).granted_for(0, 1), Some(20 + 64));
        // The 32nd step of actor 0 ends its batch.
        let mut last = None;
        for _ in 0..12 {
            let s = q.pop_front().unwrap();
            book.learned(s.actor, s.incarnation);
            last = Some(s);
        }
        let last = last.unwrap();
        assert!(last.last_of_batch && last.actor == 0);
        assert_eq!(book.credits(0).granted_for(0, 1), Some(96));
        assert_eq!(book.credits(0).granted_for(1, 1), Some(64));
    }

    #[test]
    fn a_blocked_actor_is_woken_once_its_grant_lets_it_take_half_the_window() {
        let mut book = CreditBook::new(4, SHAPE);
        assert_eq!(book.wake_after(), 2);
        let mut q = VecDeque::new();
        let mut b = batch(1, 1, 0, 4);
        b.head.blocked = 1; // sent steps 0..4 with a grant of 4: blocked
        book.accept(&b, &mut q);
        book.accept(&batch(0, 1, 0, 2), &mut q);
        assert!(book.any_blocked());
        let (c, wake) = book.grant(0);
        assert_eq!(
            (c.granted_for(1, 1), wake),
            (Some(4), vec![]),
            "nothing learned yet"
        );
        let mut learn_one = |book: &mut CreditBook| {
            let s = q.pop_front().unwrap();
            book.learned(s.actor, s.incarnation);
        };
        learn_one(&mut book);
        assert!(
            !book.any_wake_due(),
            "one step free of a window of 4: not yet"
        );
        let (c, wake) = book.grant(1);
        assert_eq!((c.granted_for(1, 1), wake), (Some(5), vec![]));
        learn_one(&mut book);
        assert!(book.any_wake_due());
        let (c, wake) = book.grant(2);
        assert_eq!((c.granted_for(1, 1), wake), (Some(6), vec![1]));
        assert!(!book.any_blocked() && !book.any_wake_due(), "woken once");
        learn_one(&mut book);
        assert_eq!(book.grant(3).1, Vec::<u16>::new());
        // Actor 0 uses its grant of 4, then blocks with nothing batched: an empty flagged batch.
        book.accept(&batch(0, 1, 2, 2), &mut q);
        let mut empty = batch(0, 1, 4, 0);
        empty.head.blocked = 1;
        book.accept(&empty, &mut q);
        assert_eq!(
            book.grant(3).1,
            Vec::<u16>::new(),
            "granted 4, blocked at 4: not yet"
        );
        // Everything learned: the whole window is free, whatever `wake_after` says.
        while let Some(s) = q.pop_front() {
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.grant(8).1, vec![0]);
        // One that blocked on stale news (its grant is already beyond) is woken at once.
        let mut stale = batch(0, 1, 4, 1);
        stale.head.blocked = 1;
        book.accept(&stale, &mut q);
        assert!(book.any_wake_due());
        assert_eq!(book.grant(8).1, vec![0]);
    }

    #[test]
    fn in_lockstep_an_actor_is_woken_by_its_one_step_of_credit() {
        let mut book = CreditBook::new(1, SHAPE);
        assert_eq!(book.wake_after(), 1);
        let mut q = VecDeque::new();
        let mut b = batch(0, 1, 0, 1);
        b.head.blocked = 1;
        book.accept(&b, &mut q);
        assert_eq!(book.grant(0).1, Vec::<u16>::new());
        let s = q.pop_front().unwrap();
        book.learned(s.actor, s.incarnation);
        assert_eq!(book.grant(1).1, vec![0]);
    }

    #[test]
    fn a_restarted_actor_starts_a_new_account_and_old_steps_still_count() {
        let mut book = CreditBook::new(8, SHAPE);
        let mut q = VecDeque::new();
        book.accept(&batch(2, 1, 0, 5), &mut q);
        book.accept(&batch(2, 2, 0, 3), &mut q);
        let c = book.credits(0);
        assert_eq!(c.granted_for(2, 1), None);
        assert_eq!(c.granted_for(2, 2), Some(8));
        // A late batch of the dead incarnation is learned from but does not touch the account.
        book.accept(&batch(2, 1, 5, 4), &mut q);
        assert_eq!(q.len(), 12);
        assert_eq!(book.env_steps(), 12);
        while let Some(s) = q.pop_front() {
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.credits(0).granted_for(2, 2), Some(3 + 8));
    }

    #[test]
    fn lost_steps_count_as_received_so_credits_keep_flowing() {
        let mut book = CreditBook::new(4, SHAPE);
        let mut q = VecDeque::new();
        book.accept(&batch(0, 1, 0, 2), &mut q);
        book.accept(&batch(0, 1, 5, 2), &mut q); // steps 2..5 lost
        assert_eq!(book.lost(0), 3);
        while let Some(s) = q.pop_front() {
            book.learned(s.actor, s.incarnation);
        }
        assert_eq!(book.credits(0).granted_for(0, 1), Some(7 + 4));
        let mut q2 = VecDeque::new();
        let mut out_of_range = batch(0, 1, 0, 1);
        out_of_range.head.actor = MAX_ACTORS as u32;
        assert_eq!(book.accept(&out_of_range, &mut q2), 0);
    }

    #[test]
    fn a_restored_learner_takes_running_actors_from_where_they_are() {
        let mut book = CreditBook::new(4, SHAPE);
        book.restore_env_steps(1000);
        let mut q = VecDeque::new();
        // Actor 0 had sent 37 steps to the learner that died; it resends its blocked flag.
        let mut blocked = batch(0, 3, 37, 0);
        blocked.head.blocked = 1;
        book.accept(&blocked, &mut q);
        assert_eq!(book.lost(0), 0);
        let (credits, wake) = book.grant(0);
        assert_eq!(credits.granted_for(0, 3), Some(37 + 4));
        assert_eq!(wake, vec![0]);
        book.accept(&batch(0, 3, 37, 2), &mut q);
        assert_eq!((book.lost(0), book.env_steps()), (0, 1002));
        // A gap within a known incarnation is still a loss.
        book.accept(&batch(0, 3, 40, 1), &mut q);
        assert_eq!(book.lost(0), 1);
    }

    fn drain(book: &mut CreditBook, q: &mut VecDeque<Queued>) {
        while let Some(s) = q.pop_front() {
            book.learned(s.actor, s.incarnation);
        }
    }

    // Regression (fuzz): a batch sent twice made `received - queued` underflow in `credits`
    // (a panic with overflow checks, a grant near u64::MAX without).
    #[test]
    fn a_batch_received_twice_does_not_underflow_the_grant() {
        let mut book = CreditBook::new(4, SHAPE);
        let mut q = VecDeque::new();
        book.accept(&batch(0, 1, 0, 3), &mut q);
        book.accept(&batch(0, 1, 0, 3), &mut q);
        assert_eq!(book.credits(0).granted_for(0, 1), Some(4));
        drain(&mut book, &mut q);
        assert_eq!(book.credits(0).granted_for(0, 1), Some(3 + 4));
    }

    // Regression (fuzz): `len` beyond the batch's capacity was counted in full in `queued`
    // while only 32 steps were queued, and `first_seq + len` overflowed in `end_seq`.
    #[test]
    fn a_batch_that_does_not_fit_is_refused() {
        let mut book = CreditBook::new(4, SHAPE);
        let mut q = VecDeque::new();
        let mut cases = Vec::new();
        let mut b = batch(0, 1, 0, 2);
        b.head.len = TRANSITIONS_PER_BATCH as u32 + 1;
        cases.push(b);
        let mut b = batch(0, 1, u64::MAX - 1, 2);
        b.head.blocked = 1;
        cases.push(b);
        let mut b = batch(0, 1, 0, 2);
        b.head.obs_dim = 9;
        cases.push(b);
        let mut b = batch(0, 1, 0, 2);
        b.head.heads = 3;
        cases.push(b);
        let mut b = batch(0, 1, 0, 2);
        b.head.records[1].action = 2;
        cases.push(b);
        for (i, b) in cases.iter().enumerate() {
            assert_eq!(book.accept(b, &mut q), 0, "case {i}");
        }
        assert_eq!(book.refused(), cases.len() as u64);
        assert!(q.is_empty() && !book.any_blocked());
        assert_eq!(book.env_steps(), 0);
        assert_eq!(
            book.credits(0).granted_for(0, 1),
            None,
            "a refused batch opens no account"
        );
    }

    // Regression (fuzz): a grant near the top of the sequence numbers overflowed `+ window`.
    #[test]
    fn a_grant_saturates_at_the_top_of_the_sequence_numbers() {
        let mut book = CreditBook::new(64, SHAPE);
        let mut q = VecDeque::new();
        book.accept(&batch(0, 1, u64::MAX - 2, 2), &mut q);
        drain(&mut book, &mut q);
        assert_eq!(book.credits(0).granted_for(0, 1), Some(u64::MAX));
        assert_eq!(book.credits(0).global_step_for(0, 2, u64::MAX), u64::MAX);
    }

    mod fuzz {
        use super::*;
        use proptest::prelude::*;

        #[derive(Debug, Clone)]
        enum Op {
            Accept {
                actor: u32,
                incarnation: u64,
                first_seq: u64,
                len: u32,
                blocked: u32,
                obs_dim: u16,
                action: u32,
            },
            Learn(usize),
            Grant(u64),
        }

        fn op() -> impl Strategy<Value = Op> {
            let accept = (
                prop_oneof![0u32..3, Just(MAX_ACTORS as u32), any::<u32>()],
                prop_oneof![1u64..3, any::<u64>()],
                prop_oneof![0u64..80, any::<u64>(), Just(u64::MAX - 3)],
                prop_oneof![0u32..=TRANSITIONS_PER_BATCH as u32, any::<u32>()],
                0u32..3,
                prop_oneof![Just(4u16), any::<u16>()],
                prop_oneof![0u32..2, any::<u32>()],
            )
                .prop_map(
                    |(actor, incarnation, first_seq, len, blocked, obs_dim, action)| Op::Accept {
                        actor,
                        incarnation,
                        first_seq,
                        len,
                        blocked,
                        obs_dim,
                        action,
                    },
                );
            prop_oneof![
                3 => accept,
                2 => (0usize..40).prop_map(Op::Learn),
                1 => any::<u64>().prop_map(Op::Grant),
            ]
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(256))]

            /// Arbitrary batches (actor ids beyond the table, sequence numbers going back,
            /// lengths beyond capacity, wrong shapes, blocked flags): no panic, no wrapped grant.
            #[test]
            fn fuzz_credit_book(
                window in prop_oneof![1u64..=64, any::<u64>()],
                ops in proptest::collection::vec(op(), 1..24),
            ) {
                let mut book = CreditBook::new(window, SHAPE);
                let mut q = VecDeque::new();
                let mut total = 0u64;
                for op in ops {
                    match op {
                        Op::Accept { actor, incarnation, first_seq, len, blocked, obs_dim, action } => {
                            let mut b = batch(0, incarnation, first_seq, 2);
                            b.head.actor = actor;
                            b.head.len = len;
                            b.head.blocked = blocked;
                            b.head.obs_dim = obs_dim;
                            b.head.records[0].action = action;
                            let n = book.accept(&b, &mut q);
                            prop_assert!(n <= TRANSITIONS_PER_BATCH);
                            total += n as u64;
                        }
                        Op::Learn(k) => {
                            for _ in 0..k {
                                let Some(s) = q.pop_front() else { break };
                                prop_assert_eq!(s.transition.state.len(), SHAPE.obs_dim);
                                prop_assert!((s.transition.action as usize) < SHAPE.actions);
                                book.learned(s.actor, s.incarnation);
                            }
                        }
                        Op::Grant(updates) => {
                            let (c, wake) = book.grant(updates);
                            prop_assert!(wake.iter().all(|&a| usize::from(a) < MAX_ACTORS));
                            prop_assert_eq!(c.updates, updates);
                        }
                    }
                    prop_assert_eq!(book.env_steps(), total);
                    let c = book.credits(0);
                    for a in 0..MAX_ACTORS {
                        // A wrapped grant would fall below the window.
                        prop_assert!(c.granted[a] >= window);
                        prop_assert!(c.granted[a] >= c.received[a].saturating_sub(q.len() as u64));
                    }
                }
            }
        }
    }
}
