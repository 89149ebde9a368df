//! A process's view of the launcher's [`Control`] messages: the schema handshake, the expert
//! generations, shutdown, and the launcher's heartbeat.

use std::fmt;
use std::time::Duration;

use crate::connection::Wire;
use crate::error::{Result, WireError};
use crate::messages::{command, Control};
use crate::ports::Receiver;
use crate::wakeups::{Waiter, Wake};

/// A process's view of the launcher's [`Control`]: the first message is the schema handshake,
/// later ones carry the expert generations and shutdown, and their arrival is the launcher's
/// heartbeat.
pub struct ControlWatch<'w> {
    rx: Receiver<'w, Control>,
    current: Control,
    seen: bool,
    last_seen: std::time::Instant,
}

impl fmt::Debug for ControlWatch<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ControlWatch({:?})", self.current)
    }
}

/// How often the launcher republishes [`Control`] (its heartbeat).
pub const CONTROL_PERIOD: Duration = Duration::from_millis(200);

impl<'w> ControlWatch<'w> {
    pub fn new(wire: &'w Wire) -> Result<Self> {
        Ok(Self {
            rx: wire.control_receiver()?,
            current: Control::default(),
            seen: false,
            last_seen: std::time::Instant::now(),
        })
    }

    /// Waits (blocking on `waiter`) for the launcher's first message, up to `timeout`. This is
    /// where a process of another schema version learns it does not belong: it gets
    /// [`WireError::SchemaMismatch`].
    pub fn handshake(&mut self, waiter: &Waiter, timeout: Duration) -> Result<Control> {
        let start = std::time::Instant::now();
        loop {
            if self.poll()? {
                return Ok(self.current);
            }
            if start.elapsed() >= timeout {
                return Err(WireError::NoLauncher {
                    waited_ms: timeout.as_millis() as u64,
                });
            }
            if waiter.wait(CONTROL_PERIOD / 4)? == Wake::Signal {
                return Err(WireError::Interrupted);
            }
        }
    }

    /// Takes in what the launcher sent since the last call; `true` if anything came.
    pub fn poll(&mut self) -> Result<bool> {
        let mut any = false;
        while let Some(c) = self.rx.receive()? {
            self.current = c;
            any = true;
        }
        if any {
            self.seen = true;
            self.last_seen = std::time::Instant::now();
        }
        Ok(any)
    }

    /// The newest control message (all zero before the handshake).
    pub fn current(&self) -> Control {
        self.current
    }

    pub fn shutdown_requested(&self) -> bool {
        self.current.command == command::SHUTDOWN
    }

    /// Time since the launcher was last heard of.
    pub fn silence(&self) -> Duration {
        self.last_seen.elapsed()
    }
}
