//! Wake-ups: doorbells (one iceoryx2 event service per process), the [`Bell`] that rings one,
//! and the [`Waiter`] a process blocks on, in a WaitSet, when it has nothing to do.

use std::fmt;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;

use crate::connection::{Transport, Wire, MAX_INTERRUPTED_CHECKS, TERMINATION_REQUESTED};
use crate::error::{transport, Result};
use crate::messages::MAX_ACTORS;

/// Whom a doorbell wakes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Doorbell {
    Learner,
    Expert,
    /// One actor (by id): the learner rings it when credits it waits for arrive, the expert when
    /// its answer is there.
    Actor(u16),
    Launcher,
    /// The bridge of a run across hosts: rung when something arrived over zenoh.
    Bridge,
}

impl Doorbell {
    pub(crate) fn topic(self) -> String {
        match self {
            Doorbell::Learner => "doorbell/learner".to_owned(),
            Doorbell::Expert => "doorbell/expert".to_owned(),
            Doorbell::Actor(id) => format!("doorbell/actor-{id}"),
            Doorbell::Launcher => "doorbell/launcher".to_owned(),
            Doorbell::Bridge => "doorbell/bridge".to_owned(),
        }
    }
}

/// Rings a doorbell.
pub struct Bell {
    pub(crate) port: Notifier<Transport>,
    pub(crate) bell: Doorbell,
}

impl fmt::Debug for Bell {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Bell({:?})", self.bell)
    }
}

impl Bell {
    /// Wakes every process waiting on this doorbell; returns how many listeners were notified.
    pub fn ring(&self) -> Result<usize> {
        self.port
            .notify()
            .map_err(transport("notify", self.bell.topic()))
    }
}

/// The doorbells of the actors, opened as needed.
pub struct ActorBells<'w> {
    wire: &'w Wire,
    bells: Vec<Option<Bell>>,
}

impl fmt::Debug for ActorBells<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ActorBells({})", self.bells.iter().flatten().count())
    }
}

impl<'w> ActorBells<'w> {
    pub fn new(wire: &'w Wire) -> Self {
        Self {
            wire,
            bells: (0..MAX_ACTORS).map(|_| None).collect(),
        }
    }

    /// Wakes actor `id` if it waits on its doorbell.
    pub fn ring(&mut self, id: u16) -> Result<()> {
        let Some(slot) = self.bells.get_mut(id as usize) else {
            return Ok(());
        };
        if slot.is_none() {
            *slot = Some(self.wire.bell(Doorbell::Actor(id))?);
        }
        if let Some(bell) = slot {
            bell.ring()?;
        }
        Ok(())
    }

    /// Wakes actors `0..n`.
    pub fn ring_all(&mut self, n: usize) -> Result<()> {
        for id in 0..n.min(MAX_ACTORS) {
            self.ring(id as u16)?;
        }
        Ok(())
    }
}

/// Why [`Waiter::wait`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// The doorbell rang.
    Rang,
    /// The timeout passed.
    Timeout,
    /// SIGINT or SIGTERM arrived.
    Signal,
}

/// A process's own doorbell (a bridge's: several), and a WaitSet to block on it.
pub struct Waiter {
    pub(crate) listeners: Vec<Listener<Transport>>,
    pub(crate) waitset: WaitSet<Transport>,
    pub(crate) bell: Doorbell,
}

impl fmt::Debug for Waiter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Waiter({:?})", self.bell)
    }
}

impl Waiter {
    /// Blocks until the doorbell rings, `timeout` passes or a termination signal (SIGINT,
    /// SIGTERM) arrives. Rings that arrived before the call return at once; all pending rings are
    /// consumed. Any other signal (SIGCONT after a SIGSTOP, SIGTSTP, ...) is a spurious wake-up:
    /// the wait goes on for the rest of `timeout`.
    pub fn wait(&self, timeout: Duration) -> Result<Wake> {
        if TERMINATION_REQUESTED.load(Ordering::Relaxed) {
            return Ok(Wake::Signal);
        }
        let deadline = Instant::now() + timeout;
        let mut rang = false;
        {
            let _guards = self
                .listeners
                .iter()
                .map(|l| self.waitset.attach_notification(l))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(transport("attach to a waitset", self.bell.topic()))?;
            for _ in 0..MAX_INTERRUPTED_CHECKS {
                let left = deadline.saturating_duration_since(Instant::now());
                let result = self
                    .waitset
                    .wait_and_process_once_with_timeout(
                        |_| {
                            rang = true;
                            CallbackProgression::Continue
                        },
                        left,
                    )
                    .map_err(transport("wait on", self.bell.topic()))?;
                match result {
                    // SIGINT or SIGTERM, caught before or while waiting.
                    WaitSetRunResult::TerminationRequest => {
                        TERMINATION_REQUESTED.store(true, Ordering::Relaxed);
                        return Ok(Wake::Signal);
                    }
                    // Some signal cut the wait short (despite its name, any signal iceoryx2
                    // catches, not only SIGINT). The next round's first check takes that signal
                    // and says whether it was SIGINT or SIGTERM; otherwise the wait goes on.
                    WaitSetRunResult::Interrupt => continue,
                    WaitSetRunResult::StopRequest | WaitSetRunResult::AllEventsHandled => break,
                }
            }
        }
        let n = self.drain()?;
        Ok(if rang || n > 0 {
            Wake::Rang
        } else {
            Wake::Timeout
        })
    }

    /// Like [`Waiter::wait`], after first looking at the doorbell every `every` for up to `poll`
    /// (sleeping in between, without the WaitSet): a ring that comes while this process polls
    /// finds no one waiting on the doorbell, so the ringer's system call wakes no core; the
    /// next look sees it. `poll` zero is
    /// [`Waiter::wait`]. A termination signal that arrives while polling is taken by the
    /// caller's next look at it ([`Wire::termination_requested`]) or by the wait after the poll.
    pub fn poll_then_wait(
        &self,
        poll: Duration,
        every: Duration,
        timeout: Duration,
    ) -> Result<Wake> {
        let start = Instant::now();
        let poll = poll.min(timeout);
        while start.elapsed() < poll {
            if TERMINATION_REQUESTED.load(Ordering::Relaxed) {
                return Ok(Wake::Signal);
            }
            if self.drain()? > 0 {
                return Ok(Wake::Rang);
            }
            std::thread::sleep(every);
        }
        self.wait(timeout.saturating_sub(start.elapsed()))
    }

    /// Consumes pending rings without blocking; returns how many there were.
    fn drain(&self) -> Result<u64> {
        let mut n = 0;
        for l in &self.listeners {
            n += l
                .try_wait(|_| {})
                .map_err(transport("drain", self.bell.topic()))?;
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use crate::test_support::{wire, with_run};
    use crate::*;

    #[test]
    fn a_doorbell_wakes_its_waiter_and_times_out_otherwise() {
        with_run("doorbell", |run| {
            let learner = wire(run, Role::Learner, 0);
            let actor = wire(run, Role::Actor, 0);
            let waiter = learner.waiter(Doorbell::Learner).unwrap();
            let bell = actor.bell(Doorbell::Learner).unwrap();
            let other = actor.bell(Doorbell::Expert).unwrap();
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout
            );
            other.ring().unwrap();
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout,
                "another role's bell does not wake the learner"
            );
            assert_eq!(bell.ring().unwrap(), 1);
            bell.ring().unwrap();
            assert_eq!(waiter.wait(Duration::from_secs(5)).unwrap(), Wake::Rang);
            // Both rings were consumed by the one wake-up.
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout
            );

            // A ring from another thread wakes a blocked waiter.
            let run2 = run.to_owned();
            let t = std::thread::spawn(move || {
                let w = wire(&run2, Role::Tool, 1);
                let b = w.bell(Doorbell::Learner).unwrap();
                std::thread::sleep(Duration::from_millis(50));
                b.ring().unwrap();
            });
            assert_eq!(waiter.wait(Duration::from_secs(10)).unwrap(), Wake::Rang);
            t.join().unwrap();
        });
    }

    #[test]
    fn a_polling_waiter_takes_a_ring_while_it_polls_and_sleeps_on_the_bell_after() {
        with_run("doorbell-poll", |run| {
            let learner = wire(run, Role::Learner, 0);
            let actor = wire(run, Role::Actor, 0);
            let waiter = actor.waiter(Doorbell::Actor(0)).unwrap();
            let bell = learner.bell(Doorbell::Actor(0)).unwrap();
            let ms = Duration::from_millis;
            let poll_then_wait = |poll, timeout| {
                let every = Duration::from_micros(30);
                waiter.poll_then_wait(poll, every, timeout).unwrap()
            };
            // Nothing rings: the poll ends and the wait times out, having waited the timeout.
            let t = std::time::Instant::now();
            assert_eq!(poll_then_wait(ms(5), ms(30)), Wake::Timeout);
            assert!(t.elapsed() >= ms(30));
            // A ring before the call is taken by the first look.
            bell.ring().unwrap();
            assert_eq!(poll_then_wait(ms(5_000), ms(10_000)), Wake::Rang);
            // Rings during the poll (from another process's thread) and after it, asleep.
            for delay_ms in [20, 150] {
                let run2 = run.to_owned();
                let t = std::thread::spawn(move || {
                    let w = wire(&run2, Role::Tool, 1);
                    let b = w.bell(Doorbell::Actor(0)).unwrap();
                    std::thread::sleep(Duration::from_millis(delay_ms));
                    b.ring().unwrap();
                });
                let wake = poll_then_wait(ms(100), ms(10_000));
                assert_eq!(wake, Wake::Rang, "rung after {delay_ms} ms");
                t.join().unwrap();
            }
            // Every ring was consumed.
            assert_eq!(poll_then_wait(ms(5), ms(20)), Wake::Timeout);
        });
    }

    #[test]
    fn a_bridge_waits_on_several_doorbells_at_once() {
        with_run("doorbells", |run| {
            let bridge = wire(run, Role::Bridge, 0);
            let other = wire(run, Role::Actor, 2);
            let waiter = bridge
                .waiter_on(&[Doorbell::Bridge, Doorbell::Actor(2), Doorbell::Actor(5)])
                .unwrap();
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout
            );
            other.bell(Doorbell::Learner).unwrap().ring().unwrap();
            assert_eq!(
                waiter.wait(Duration::from_millis(20)).unwrap(),
                Wake::Timeout,
                "a doorbell it does not wait on"
            );
            for bell in [Doorbell::Actor(5), Doorbell::Bridge, Doorbell::Actor(2)] {
                other.bell(bell).unwrap().ring().unwrap();
                assert_eq!(waiter.wait(Duration::from_secs(5)).unwrap(), Wake::Rang);
                assert_eq!(
                    waiter.wait(Duration::from_millis(20)).unwrap(),
                    Wake::Timeout,
                    "the ring of {bell:?} was consumed"
                );
            }
            assert!(bridge.waiter_on(&[]).is_err());
        });
    }

    /// Sends `signal` to one thread of this process (`tid`), with the `kill` command.
    fn signal_thread(signal: &str, tid: &str) {
        let ok = std::process::Command::new("kill")
            .args([&format!("-{signal}"), tid])
            .status()
            .expect("kill runs");
        assert!(ok.success(), "kill -{signal} {tid}");
    }

    #[test]
    fn a_stray_signal_is_a_spurious_wake_up_not_a_termination_request() {
        with_run("stray-signal", |run| {
            let expert = wire(run, Role::Expert, 1);
            let waiter = expert.waiter(Doorbell::Expert).unwrap();
            // This thread's id: a signal sent to it lands here, so it cuts this very wait short
            // (EINTR), as SIGCONT does to a single-threaded process resumed after SIGSTOP.
            let me = std::fs::read_link("/proc/thread-self").unwrap();
            let tid = me.file_name().unwrap().to_string_lossy().into_owned();
            let sender = std::thread::spawn(move || {
                for signal in ["CONT", "URG", "CONT"] {
                    std::thread::sleep(Duration::from_millis(60));
                    signal_thread(signal, &tid);
                }
            });
            let timeout = Duration::from_millis(400);
            let start = std::time::Instant::now();
            let wake = waiter.wait(timeout).unwrap();
            let waited = start.elapsed();
            sender.join().unwrap();
            assert_eq!(wake, Wake::Timeout, "a stray signal is not SIGINT/SIGTERM");
            assert!(waited >= timeout, "the wait went on to its end: {waited:?}");
            assert!(!expert.termination_requested());
            // The next wait is an ordinary one.
            let bell = expert.bell(Doorbell::Expert).unwrap();
            bell.ring().unwrap();
            assert_eq!(waiter.wait(Duration::from_secs(5)).unwrap(), Wake::Rang);
            assert!(!expert.termination_requested());
        });
    }
}
