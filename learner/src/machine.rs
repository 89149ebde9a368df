//! The learner process's decisions as a state machine: batches in, learned steps, the time; out,
//! what to do now (checkpoint, publish weights, return credits, report). No I/O, clock or socket
//! inside: `lib.rs` is the shell that moves the messages and writes the files.
//!
//! The rules a fault must not break:
//! - every step received is learned from once, in order (the [`CreditBook`] drops a duplicate or
//!   out-of-date batch's accounting and counts lost steps);
//! - weights are published every `weights_every` updates and whenever the queue drains, so an
//!   idle learner never holds back its newest weights;
//! - credits go back after at most [`CREDITS_EVERY`] learned steps, at the end of every batch, and
//!   at once when they let a blocked actor take half its window ([`CreditBook::wake_after`]);
//! - checkpoints are taken at an actor's episode end, every `every` steps counted from the last
//!   one (from the restored checkpoint's step after a restart); in lockstep with one actor the
//!   last of them is the one kept at the end, since it pairs with the actor's.

use std::collections::VecDeque;
use std::time::Duration;

use alfd_common::agent::NeuralLearner;
use alfd_common::checkpoint::Cadence;
use alfd_common::replay::Transition;
use alfd_wire::{Credits, TransitionBatch};

use crate::credit_book::{CreditBook, Queued};

/// Credits are returned after at most this many learned steps.
pub const CREDITS_EVERY: u64 = 8;

/// How often the learner reports its status.
pub const STATUS_EVERY: Duration = Duration::from_millis(500);

/// What learns from a step: the core's [`NeuralLearner`] (or, in tests, a counter).
pub trait Learns {
    /// Learns from one transition (Algorithm 1 lines 19-20); the loss of the last update made.
    fn learn(&mut self, t: &Transition) -> Option<f32>;
    /// Gradient updates made so far (the weights' version).
    fn updates(&self) -> u64;
}

impl Learns for NeuralLearner {
    fn learn(&mut self, t: &Transition) -> Option<f32> {
        NeuralLearner::learn(self, t)
    }

    fn updates(&self) -> u64 {
        NeuralLearner::updates(self)
    }
}

/// What the shell does after an event, in this order: publish the weights, write a checkpoint,
/// return the credits ([`LearnerMachine::grant`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Todo {
    pub publish: bool,
    pub checkpoint: bool,
    pub credits: bool,
}

/// The learner's state: the learner, the credit book, the queue of steps received and not yet
/// learned from, and when it last published, returned credits, checkpointed and reported.
pub struct LearnerMachine<L> {
    learner: L,
    book: CreditBook,
    queue: VecDeque<Queued>,
    weights_every: u64,
    published: u64,
    credits_dirty: bool,
    learned_since_credits: u64,
    cadence: Cadence,
    checkpoints: u64,
    restored_step: u64,
    loss: f64,
    last_status: Option<Duration>,
}

impl<L: Learns> LearnerMachine<L> {
    /// A learner publishing every `weights_every` updates and checkpointing every
    /// `checkpoint_steps` steps (0: never), restored at global step `restored_step` (0 for a
    /// fresh run; the book must hold the same step).
    pub fn new(
        learner: L,
        book: CreditBook,
        weights_every: u64,
        checkpoint_steps: u64,
        restored_step: u64,
    ) -> Self {
        Self {
            learner,
            book,
            queue: VecDeque::new(),
            weights_every,
            published: 0,
            credits_dirty: false,
            learned_since_credits: 0,
            cadence: Cadence::new(checkpoint_steps, restored_step),
            checkpoints: 0,
            restored_step,
            loss: f64::NAN,
            last_status: None,
        }
    }

    pub fn learner(&self) -> &L {
        &self.learner
    }

    pub fn book(&self) -> &CreditBook {
        &self.book
    }

    /// The loss of the last update (NaN before the first).
    pub fn loss(&self) -> f64 {
        self.loss
    }

    /// Checkpoints asked for so far.
    pub fn checkpoints(&self) -> u64 {
        self.checkpoints
    }

    pub fn queue_is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// A batch arrived.
    pub fn accept(&mut self, batch: &TransitionBatch) {
        self.book.accept(batch, &mut self.queue);
    }

    /// Whether the grants, published now, would wake a blocked actor (they go back at once:
    /// the actor may have blocked on stale news, or been let go on by the steps just learned).
    pub fn any_wake_due(&self) -> bool {
        self.book.any_wake_due()
    }

    /// Learns from the oldest queued step; `None` when nothing is queued.
    pub fn step(&mut self) -> Option<Todo> {
        let q = self.queue.pop_front()?;
        if let Some(loss) = self.learner.learn(&q.transition) {
            self.loss = f64::from(loss);
        }
        self.book.learned(q.actor, q.incarnation);
        let updates = self.learner.updates();
        let publish = updates >= self.published.saturating_add(self.weights_every);
        if publish {
            self.published = updates;
        }
        // At an actor's episode end, every `every` steps: in lockstep with one actor, where that
        // actor checkpoints too.
        let checkpoint = q.episode_end && self.cadence.episode_end(self.book.env_steps());
        if checkpoint {
            self.checkpoints += 1;
        }
        self.credits_dirty = true;
        self.learned_since_credits += 1;
        // Credits go back every few steps (so an actor refills its batch while the learner
        // works through the rest of the queue) and at the end of every batch.
        let credits = q.last_of_batch || self.learned_since_credits >= CREDITS_EVERY;
        if credits {
            self.credits_dirty = false;
            self.learned_since_credits = 0;
        }
        Some(Todo {
            publish,
            checkpoint,
            credits,
        })
    }

    /// The queue is empty: the newest weights and the pending credits go out.
    pub fn drained(&mut self) -> Todo {
        if !self.queue.is_empty() {
            return Todo::default();
        }
        let updates = self.learner.updates();
        let publish = updates > self.published;
        if publish {
            self.published = updates;
        }
        let credits = std::mem::take(&mut self.credits_dirty);
        Todo {
            publish,
            checkpoint: false,
            credits,
        }
    }

    /// The grants to send now and the actors to wake.
    pub fn grant(&mut self) -> (Credits, Vec<u16>) {
        self.book.grant(self.learner.updates())
    }

    /// Whether a status report is due at `now` (every [`STATUS_EVERY`]; the first at once).
    pub fn tick(&mut self, now: Duration) -> bool {
        let due = self
            .last_status
            .is_none_or(|t| now.saturating_sub(t) >= STATUS_EVERY);
        if due {
            self.last_status = Some(now);
        }
        due
    }

    /// Whether to write a checkpoint at the end. In lockstep with one actor (`window` 1) the
    /// last checkpoint is the one taken at an episode end, from which `alfd resume` continues
    /// as the uninterrupted run; a final one would not pair with the actor's.
    pub fn final_checkpoint(&self, window: u64) -> bool {
        let lockstep = window == 1 && self.book.senders() <= 1;
        !(lockstep && (self.checkpoints > 0 || self.restored_step > 0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::credit_book::BatchShape;

    /// A learner that makes one update per step.
    #[derive(Default)]
    struct Counter {
        seen: Vec<f32>,
    }

    impl Learns for Counter {
        fn learn(&mut self, t: &Transition) -> Option<f32> {
            self.seen.push(t.state[0]);
            Some(t.state[0])
        }
        fn updates(&self) -> u64 {
            self.seen.len() as u64
        }
    }

    const SHAPE: BatchShape = BatchShape {
        obs_dim: 2,
        heads: 2,
        actions: 2,
    };

    /// A batch of `len` steps of `actor` from `first_seq`, the steps numbered from `first_seq`
    /// in their state; `ends` marks the steps (0-based in the batch) that end an episode.
    fn batch(
        actor: u16,
        incarnation: u64,
        first_seq: u64,
        len: usize,
        ends: &[usize],
    ) -> TransitionBatch {
        let mut b = TransitionBatch::new(actor, incarnation, 2, 2, first_seq).unwrap();
        for i in 0..len {
            let x = (first_seq + i as u64) as f32;
            b.push(&Transition {
                state: vec![x, 0.0],
                action: 0,
                reward: 1.0,
                next_state: vec![x + 1.0, 0.0],
                terminated: false,
                mask: vec![1.0, 1.0],
                demo: false,
                horizon: 1,
            })
            .unwrap();
            if ends.contains(&i) {
                b.mark_episode_end();
            }
        }
        b
    }

    fn machine(
        weights_every: u64,
        checkpoint_steps: u64,
        restored: u64,
    ) -> LearnerMachine<Counter> {
        let mut book = CreditBook::new(16, SHAPE);
        book.restore_env_steps(restored);
        LearnerMachine::new(
            Counter::default(),
            book,
            weights_every,
            checkpoint_steps,
            restored,
        )
    }

    fn run_all(m: &mut LearnerMachine<Counter>) -> Vec<Todo> {
        std::iter::from_fn(|| m.step()).collect()
    }

    #[test]
    fn every_step_is_learned_once_in_order_with_credits_at_most_every_eight() {
        let mut m = machine(1000, 0, 0);
        m.accept(&batch(0, 1, 0, 20, &[]));
        assert!(!m.book().any_blocked());
        let todos = run_all(&mut m);
        assert_eq!(
            m.learner().seen,
            (0..20).map(|x| x as f32).collect::<Vec<_>>()
        );
        let credits: Vec<usize> = (0..20).filter(|&i| todos[i].credits).collect();
        // After the 8th and 16th learned steps, and at the batch's last.
        assert_eq!(credits, vec![7, 15, 19]);
        assert_eq!(m.loss(), 19.0);
        assert!(m.step().is_none());
    }

    #[test]
    fn a_duplicate_batch_does_not_inflate_the_grant() {
        let mut m = machine(1000, 0, 0);
        m.accept(&batch(0, 1, 0, 4, &[]));
        // The same batch again (a resend after a stall).
        m.accept(&batch(0, 1, 0, 4, &[]));
        run_all(&mut m);
        let (credits, _) = m.grant();
        // Received 4, learned 8 queued steps: the grant never exceeds received + window.
        assert_eq!(credits.granted_for(0, 1), Some(4 + 16));
    }

    #[test]
    fn weights_are_published_every_n_updates_and_when_the_queue_drains() {
        let mut m = machine(5, 0, 0);
        m.accept(&batch(0, 1, 0, 12, &[]));
        let todos = run_all(&mut m);
        let published: Vec<usize> = (0..12).filter(|&i| todos[i].publish).collect();
        assert_eq!(published, vec![4, 9]);
        // Two updates since the last publication: the drained queue publishes them.
        let d = m.drained();
        assert!(d.publish);
        // Nothing new: nothing to publish or grant.
        assert_eq!(m.drained(), Todo::default());
    }

    #[test]
    fn drained_credits_go_back_only_when_owed() {
        let mut m = machine(1000, 0, 0);
        m.accept(&batch(0, 1, 0, 20, &[]));
        m.accept(&batch(1, 1, 0, 3, &[]));
        for _ in 0..21 {
            m.step();
        }
        // Not drained yet: nothing.
        assert_eq!(m.drained(), Todo::default());
        m.step();
        m.step();
        // The last step ended actor 1's batch: its credits went with it.
        assert!(!m.drained().credits);
    }

    #[test]
    fn a_blocked_actor_gets_credits_at_once() {
        let mut m = machine(1000, 0, 0);
        let mut b = batch(3, 1, 0, 4, &[]);
        b.head.blocked = 1;
        m.accept(&b);
        // Blocked at 4 on stale news: the grant, 4 received - 4 queued + 16, is there.
        assert!(m.book().any_blocked() && m.any_wake_due());
        run_all(&mut m);
        let (_, wake) = m.grant();
        assert_eq!(wake, vec![3]);
    }

    #[test]
    fn checkpoints_at_episode_ends_every_n_steps() {
        let mut m = machine(1000, 10, 0);
        // Episodes end at steps 4, 9, 14 and 19 (1-based: 5, 10, 15, 20 steps taken).
        m.accept(&batch(0, 1, 0, 20, &[4, 9, 14, 19]));
        let todos = run_all(&mut m);
        let at: Vec<usize> = (0..20).filter(|&i| todos[i].checkpoint).collect();
        // The cadence reads the steps received (20 by then): the first episode end once 10
        // steps are in, then every 10 from there.
        assert_eq!(at, vec![4]);
        assert_eq!(m.checkpoints(), 1);
    }

    #[test]
    fn a_learner_restored_mid_run_counts_from_its_checkpoint() {
        // Restored at step 100 with checkpoints every 50 steps.
        let mut m = machine(1000, 50, 100);
        // Actors meet it mid-sequence: no loss, and the run's step goes on from 100.
        m.accept(&batch(0, 2, 300, 30, &[29]));
        assert_eq!(m.book().env_steps(), 130);
        assert_eq!(m.book().lost(0), 0);
        let todos = run_all(&mut m);
        assert!(todos.iter().all(|t| !t.checkpoint), "130 < 100 + 50");
        m.accept(&batch(0, 2, 330, 30, &[29]));
        let todos = run_all(&mut m);
        assert!(todos[29].checkpoint, "160 >= 150");
    }

    #[test]
    fn in_lockstep_the_last_episode_end_checkpoint_is_kept() {
        let mut m = machine(1000, 5, 0);
        assert!(
            m.final_checkpoint(1),
            "no checkpoint yet: write one at the end"
        );
        m.accept(&batch(0, 1, 0, 6, &[5]));
        run_all(&mut m);
        assert_eq!(m.checkpoints(), 1);
        assert!(
            !m.final_checkpoint(1),
            "lockstep with one actor: keep the episode-end one"
        );
        assert!(
            m.final_checkpoint(4),
            "a window: the final state is written"
        );
        m.accept(&batch(1, 1, 0, 1, &[]));
        assert!(
            m.final_checkpoint(1),
            "two actors: the final state is written"
        );
        // Restored and nothing checkpointed since: the restored checkpoint is kept too.
        assert!(!machine(1000, 5, 40).final_checkpoint(1));
    }

    #[test]
    fn status_follows_the_clock_passed_in() {
        let mut m = machine(1000, 0, 0);
        assert!(m.tick(Duration::from_secs(3)));
        assert!(!m.tick(Duration::from_millis(3_499)));
        assert!(m.tick(Duration::from_millis(3_500)));
    }
}
