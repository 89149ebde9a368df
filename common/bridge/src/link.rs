//! What every bridge does with the frames and ports it moves: send a frame over zenoh, take one
//! in (counting those refused), see what a port made of one forwarded, empty a port, and hold
//! the queries waiting for another host's answer.

use std::collections::HashMap;

use alfd_wire::{QueryResponse, WireError, SCHEMA_VERSION};
use tracing::warn;
use zenoh::Wait as _;

use crate::error::{zenoh_error, Result};
use crate::frame::{self, Frame};

/// Sends encoded frame bytes over `link`.
pub(crate) fn put_bytes(link: &zenoh::pubsub::Publisher<'static>, bytes: Vec<u8>) -> Result<()> {
    link.put(bytes).wait().map_err(zenoh_error)
}

/// Sends `f` over `link`.
pub(crate) fn put(link: &zenoh::pubsub::Publisher<'static>, f: &Frame) -> Result<()> {
    put_bytes(link, frame::encode(SCHEMA_VERSION, f)?)
}

/// The frame in `bytes` from `from`, or `None` when it cannot be read: counted in `refused` and
/// warned about at the 1st, 2nd, 4th, 8th, ... (so a stream of bad frames cannot flood the log).
pub(crate) fn take_in(bytes: &[u8], refused: &mut u64, from: &str) -> Option<Frame> {
    match frame::decode::<Frame>(SCHEMA_VERSION, bytes) {
        Ok(f) => Some(f),
        Err(e) => {
            *refused += 1;
            if refused.is_power_of_two() {
                warn!(refused = *refused, "frame from {from} dropped: {e}");
            }
            None
        }
    }
}

/// What a port made of a message forwarded to it: its value, `None` for a message of another
/// schema version (dropped with a warning), or the port's failure.
pub(crate) fn forwarded<T>(r: std::result::Result<T, WireError>) -> Result<Option<T>> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(e @ WireError::SchemaMismatch { .. }) => {
            warn!("{e}; dropped");
            Ok(None)
        }
        Err(e) => Err(e.into()),
    }
}

/// Queries held for an answer from another host, one per actor (an actor's newer query
/// replaces its older one: it gave up on that).
#[derive(Debug)]
pub(crate) struct HeldQueries<Q>(HashMap<u32, Q>);

impl<Q> Default for HeldQueries<Q> {
    fn default() -> Self {
        Self(HashMap::new())
    }
}

impl<Q> HeldQueries<Q> {
    pub(crate) fn hold(&mut self, actor: u32, query: Q) {
        self.0.insert(actor, query);
    }

    /// Forgets the queries whose actors stopped waiting.
    pub(crate) fn prune(&mut self, still_waiting: impl Fn(&Q) -> bool) {
        self.0.retain(|_, q| still_waiting(q));
    }

    /// The query `r` answers, or why there is none (its actor no longer waits, or `r` answers
    /// an older query of that actor: the newer one stays held).
    pub(crate) fn take(&mut self, r: &QueryResponse) -> Result<Q, String>
    where
        Q: HasSeq,
    {
        match self.0.remove(&r.actor) {
            None => Err(format!("actor {} no longer waits", r.actor)),
            Some(q) if q.seq() != r.request_seq => {
                self.0.insert(r.actor, q);
                Err(format!("an answer to an older query of actor {}", r.actor))
            }
            Some(q) => Ok(q),
        }
    }
}

/// Every message waiting on a port (`next` takes one), each handed to `each`; a message of
/// another schema version is dropped with a warning.
pub(crate) fn drain<T>(
    mut next: impl FnMut() -> std::result::Result<Option<T>, WireError>,
    mut each: impl FnMut(T) -> Result<()>,
) -> Result<()> {
    loop {
        match next() {
            Ok(Some(x)) => each(x)?,
            Ok(None) => return Ok(()),
            Err(e @ WireError::SchemaMismatch { .. }) => warn!("{e}; dropped"),
            Err(e) => return Err(e.into()),
        }
    }
}

/// A held query's sequence number (what an answer names).
pub(crate) trait HasSeq {
    fn seq(&self) -> u64;
}

impl HasSeq for alfd_wire::IncomingQuery<'_> {
    fn seq(&self) -> u64 {
        self.request().header.seq
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unreadable_frame_is_counted_and_a_readable_one_taken_in() {
        let mut refused = 0;
        assert!(take_in(b"not a frame", &mut refused, "a test").is_none());
        assert!(take_in(&[], &mut refused, "a test").is_none());
        assert_eq!(refused, 2);
        let good = frame::encode(SCHEMA_VERSION, &Frame::Query(Default::default())).unwrap();
        assert!(matches!(
            take_in(&good, &mut refused, "a test"),
            Some(Frame::Query(_))
        ));
        assert_eq!(refused, 2);
    }

    #[test]
    fn a_message_of_another_schema_is_dropped_and_other_failures_are_errors() {
        assert_eq!(forwarded::<u8>(Ok(3)).unwrap(), Some(3));
        let other = WireError::SchemaMismatch {
            service: "query",
            ours: 1,
            theirs: 2,
            sender: "actor/0".into(),
        };
        assert_eq!(forwarded::<u8>(Err(other)).unwrap(), None);
        let broken = WireError::OutOfRange {
            what: "x",
            value: 1,
            expected: "y",
        };
        assert!(forwarded::<u8>(Err(broken)).is_err());
    }
}
