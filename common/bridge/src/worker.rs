//! What the hub, the mirror and the expert host share: a forwarding thread told to stop by a
//! flag and joined with its result, and the time the learner's host was last heard of.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::{BridgeError, Result};

/// When the learner's host was last heard of (its control messages), shared between the
/// forwarding thread (which [`Heartbeat::beat`]s) and its owner (which asks for the
/// [`Heartbeat::silence`]). Clones share the same clock.
#[derive(Debug, Clone)]
pub(crate) struct Heartbeat {
    epoch: Instant,
    /// Milliseconds since `epoch` of the last beat (0: none yet).
    last: Arc<AtomicU64>,
}

impl Heartbeat {
    pub(crate) fn new() -> Self {
        Self {
            epoch: Instant::now(),
            last: Arc::new(AtomicU64::new(0)),
        }
    }

    /// The learner's host was heard of now.
    pub(crate) fn beat(&self) {
        let ms = (self.epoch.elapsed().as_millis() as u64).max(1);
        self.last.store(ms, Ordering::Relaxed);
    }

    /// How long since the last beat (`None`: never yet).
    pub(crate) fn silence(&self) -> Option<Duration> {
        match self.last.load(Ordering::Relaxed) {
            0 => None,
            ms => Some(
                self.epoch
                    .elapsed()
                    .saturating_sub(Duration::from_millis(ms)),
            ),
        }
    }
}

/// A forwarding thread with its stop flag, the heartbeat it keeps, and the liveliness token
/// that tells the other host this one is up (undeclared when the thread is halted).
pub(crate) struct ForwardingThread {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<()>>>,
    heard: Heartbeat,
    token: Option<zenoh::liveliness::LivelinessToken>,
    /// What the thread is, for its name and its messages ("mirror", "expert host").
    what: &'static str,
}

impl ForwardingThread {
    /// Starts `body` on a thread of its own, with the stop flag and the heartbeat it keeps; an
    /// error it ends with is logged ("the WHAT stopped: ...") and kept for [`ForwardingThread::halt`].
    pub(crate) fn spawn(
        what: &'static str,
        body: impl FnOnce(&AtomicBool, &Heartbeat) -> Result<()> + Send + 'static,
    ) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let heard = Heartbeat::new();
        let thread = {
            let stop = Arc::clone(&stop);
            let heard = heard.clone();
            std::thread::Builder::new()
                .name(what.replace(' ', "-"))
                .spawn(move || {
                    let r = body(&stop, &heard);
                    if let Err(e) = &r {
                        tracing::warn!("the {what} stopped: {e}");
                    }
                    r
                })
                .expect("a thread starts")
        };
        Self {
            stop,
            thread: Some(thread),
            heard,
            token: None,
            what,
        }
    }

    /// Keeps `token` until the thread is halted.
    pub(crate) fn announce(&mut self, token: zenoh::liveliness::LivelinessToken) {
        self.token = Some(token);
    }

    /// How long since the learner's host was last heard of (`None`: never yet).
    pub(crate) fn silence(&self) -> Option<Duration> {
        self.heard.silence()
    }

    /// Whether the thread ended (an error, said in the log).
    pub(crate) fn ended(&self) -> bool {
        self.thread.as_ref().is_none_or(|t| t.is_finished())
    }

    /// Tells the thread to stop, joins it (its result), and withdraws the token.
    pub(crate) fn halt(&mut self) -> Result<()> {
        self.stop.store(true, Ordering::Relaxed);
        let r = join(&mut self.thread, self.what);
        if let Some(t) = self.token.take() {
            let _ = zenoh::Wait::wait(t.undeclare());
        }
        r
    }
}

/// Joins a forwarding thread (if it was not joined already) and gives its result; a panic is
/// an error naming `what`.
pub(crate) fn join(thread: &mut Option<JoinHandle<Result<()>>>, what: &str) -> Result<()> {
    match thread.take() {
        Some(t) => t
            .join()
            .unwrap_or_else(|_| Err(BridgeError::Zenoh(format!("the {what} panicked")))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn silence_is_none_until_the_first_beat_then_counts_from_it() {
        let h = Heartbeat::new();
        assert_eq!(h.silence(), None);
        h.clone().beat();
        let s = h.silence().expect("a beat was heard");
        assert!(s < Duration::from_secs(60), "{s:?}");
    }

    #[test]
    fn a_panicked_thread_is_an_error_naming_it_and_a_second_join_is_ok() {
        let mut t: Option<JoinHandle<Result<()>>> =
            Some(std::thread::spawn(|| panic!("on purpose")));
        let e = join(&mut t, "mirror").unwrap_err();
        assert!(e.to_string().contains("the mirror panicked"), "{e}");
        assert!(join(&mut t, "mirror").is_ok());
    }
}
