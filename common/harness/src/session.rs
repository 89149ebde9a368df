//! A process's membership of a run: its doorbell, the launcher's control messages, and the one
//! place that decides whether the process should stop.

use std::cell::RefCell;
use std::time::Duration;

use alfd_common::environment_loop::Stop;
use alfd_wire::{Control, ControlWatch, Doorbell, Waiter, Wake, Wire, WireError};

/// How long the launcher may stay silent before a process gives up on the run (the launcher
/// republishes its control message every `alfd_wire::CONTROL_PERIOD`).
pub const LAUNCHER_SILENCE: Duration = Duration::from_secs(10);

/// The launcher said stop.
pub const STOP_REQUESTED: Stop = Stop("the launcher said stop");
/// SIGINT or SIGTERM arrived.
pub const TERMINATION_SIGNAL: Stop = Stop("termination signal");

/// Why a session failed.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    #[error(transparent)]
    Wire(#[from] WireError),
    #[error("no word from the launcher for {0:?}: giving up")]
    LauncherSilent(Duration),
    #[error("the launcher (pid {0}) is gone: giving up")]
    LauncherGone(u32),
    #[error("no handshake with the launcher")]
    NoHandshake(#[source] WireError),
}

impl SessionError {
    /// The run's launcher is gone or hung: the process should save what it must and exit.
    pub fn orphaned(&self) -> bool {
        matches!(self, Self::LauncherSilent(_) | Self::LauncherGone(_))
    }
}

/// A process joined to a run, after the schema handshake with the launcher.
pub struct Session<'w> {
    wire: &'w Wire,
    waiter: Waiter,
    control: RefCell<ControlWatch<'w>>,
    /// The process that started this one (the launcher): when it dies, the process is
    /// re-parented and knows at once, without waiting out [`LAUNCHER_SILENCE`].
    parent: u32,
}

impl std::fmt::Debug for Session<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("wire", &self.wire)
            .field("control", &self.control)
            .finish()
    }
}

impl<'w> Session<'w> {
    /// Listens on `bell` and waits up to `handshake` for the launcher's first control message
    /// (where a process of another schema version is refused).
    pub fn join(wire: &'w Wire, bell: Doorbell, handshake: Duration) -> Result<Self, SessionError> {
        let waiter = wire.waiter(bell)?;
        let mut control = ControlWatch::new(wire)?;
        control
            .handshake(&waiter, handshake)
            .map_err(SessionError::NoHandshake)?;
        Ok(Self {
            wire,
            waiter,
            control: RefCell::new(control),
            parent: std::os::unix::process::parent_id(),
        })
    }

    pub fn wire(&self) -> &'w Wire {
        self.wire
    }

    /// The launcher's newest control message.
    pub fn control(&self) -> Control {
        self.control.borrow().current()
    }

    /// Takes in the launcher's news and says whether to stop: the launcher said so, or a
    /// termination signal arrived. A launcher silent for [`LAUNCHER_SILENCE`], or gone (this
    /// process re-parented), is an error ([`SessionError::orphaned`]).
    pub fn should_stop(&self) -> Result<Option<Stop>, SessionError> {
        let mut control = self.control.borrow_mut();
        control.poll()?;
        if control.shutdown_requested() {
            return Ok(Some(STOP_REQUESTED));
        }
        if self.wire.termination_requested() {
            return Ok(Some(TERMINATION_SIGNAL));
        }
        if std::os::unix::process::parent_id() != self.parent {
            return Err(SessionError::LauncherGone(self.parent));
        }
        if control.silence() >= LAUNCHER_SILENCE {
            return Err(SessionError::LauncherSilent(control.silence()));
        }
        Ok(None)
    }

    /// Sleeps on the doorbell for at most `timeout`; `Some` if a termination signal woke it.
    pub fn wait(&self, timeout: Duration) -> Result<Option<Stop>, SessionError> {
        self.poll_then_wait(Duration::ZERO, Duration::ZERO, timeout)
    }

    /// Like [`Session::wait`], after looking at the doorbell every `every` for up to `poll`
    /// ([`alfd_wire::Waiter::poll_then_wait`]).
    pub fn poll_then_wait(
        &self,
        poll: Duration,
        every: Duration,
        timeout: Duration,
    ) -> Result<Option<Stop>, SessionError> {
        Ok(match self.waiter.poll_then_wait(poll, every, timeout)? {
            Wake::Signal => Some(TERMINATION_SIGNAL),
            _ => None,
        })
    }

    /// Like [`Session::wait`], and also says which wake-up it was.
    pub fn wait_for(&self, timeout: Duration) -> Result<Wake, SessionError> {
        Ok(self.waiter.wait(timeout)?)
    }
}
