//! Which answers came late: sent with a demonstration (kept in `demos.jsonl`) but never read by
//! the actor that asked, because it had stopped waiting.
//!
//! An actor stops waiting when its timeout passes and lets go of its query. An answer sent after
//! that is late at once: the query is no longer held. An answer sent in the instant between the
//! actor's last look and its letting go is held when sent and still never read; only the actor
//! knows, and it says so in its next request (`gave_up`, the number of the query it let go with
//! no answer in hand) or, leaving, in a request that only reports. The book pairs the two, so
//! that every answer the actors did not use is counted late exactly once.

use std::collections::HashMap;

/// An asker: its actor id and incarnation (a restarted actor numbers its queries anew).
type Asker = (u32, u64);

/// The late answers so far, and for each asker the last query answered while it was held.
#[derive(Debug, Default)]
pub struct LateBook {
    held_when_answered: HashMap<Asker, u64>,
    late: u32,
}

impl LateBook {
    /// A demonstration was sent for `asker`'s query `seq`, which the asker still held
    /// (`held`) or had let go.
    pub fn answered(&mut self, asker: Asker, seq: u64, held: bool) {
        if held {
            self.held_when_answered.insert(asker, seq);
        } else {
            self.late += 1;
        }
    }

    /// `asker` let go of its query `seq` with no answer in hand: an answer sent while it held
    /// the query was never read.
    pub fn gave_up(&mut self, asker: Asker, seq: u64) {
        if self.held_when_answered.get(&asker) == Some(&seq) {
            self.held_when_answered.remove(&asker);
            self.late += 1;
        }
    }

    /// Answers with a demonstration that their actor never read.
    pub fn late(&self) -> u32 {
        self.late
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_answer_is_late_when_sent_after_the_actor_let_go_or_when_the_actor_says_it_never_read_it()
    {
        let mut b = LateBook::default();
        // Sent after the actor let go: late at once.
        b.answered((0, 1), 1, false);
        assert_eq!(b.late(), 1);
        // Sent while held and read: the actor's next query reports nothing.
        b.answered((0, 1), 2, true);
        assert_eq!(b.late(), 1);
        // Sent while held, but the actor had already given up: its next request says so.
        b.answered((0, 1), 3, true);
        b.gave_up((0, 1), 3);
        assert_eq!(b.late(), 2);
        // Said twice (a report after a query that carried it too): counted once.
        b.gave_up((0, 1), 3);
        assert_eq!(b.late(), 2);
        // The actor gave up on a query this expert did not answer (dropped, or answered
        // after the letting go and counted then): nothing.
        b.gave_up((0, 1), 4);
        assert_eq!(b.late(), 2);
    }

    #[test]
    fn askers_are_apart_and_a_restarted_actor_s_numbers_are_its_own() {
        let mut b = LateBook::default();
        b.answered((0, 1), 5, true);
        b.answered((1, 1), 5, true);
        // Actor 0 restarted (incarnation 2) numbers its queries from 1 again: its 5 is not the
        // answered 5 of incarnation 1.
        b.gave_up((0, 2), 5);
        assert_eq!(b.late(), 0);
        b.gave_up((1, 1), 5);
        assert_eq!(b.late(), 1);
        // A newer answer to the same asker replaces the older one.
        b.answered((0, 1), 6, true);
        b.gave_up((0, 1), 5);
        assert_eq!(b.late(), 1);
        b.gave_up((0, 1), 6);
        assert_eq!(b.late(), 2);
    }
}
