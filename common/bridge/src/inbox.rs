//! What zenoh hands a bridge: zenoh calls back on its own threads, while iceoryx2 ports stay on
//! the bridge's thread. A callback puts what arrived into the [`Inbox`] and asks a small ringer
//! thread to ring the bridge's doorbell (`Doorbell::Bridge`), so that the bridge, blocked in its
//! WaitSet, wakes at once: nothing polls.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

use alfd_wire::{Doorbell, Process, Role, Wire};
use tracing::warn;

/// Something for the bridge's thread.
#[derive(Debug)]
pub(crate) enum Mail {
    /// A frame's bytes.
    Frame(Vec<u8>),
    /// A frame's bytes from the joined host `from` (the key it came on).
    Up { from: String, bytes: Vec<u8> },
    /// A remote host joined: the hub sends it the newest of every down service again.
    Joined,
    /// The launcher's order to a remote expert (the hub sends it down).
    Order(crate::frame::ExpertOrder),
    /// A joined host left or its link dropped (its liveliness token went): the hub takes
    /// nothing more from its expert.
    Left(String),
    /// `alfd join`: the expert process here ended (the mirror sends it up after its answers).
    Exited {
        generation: u16,
        how: String,
        code: Option<i32>,
    },
}

/// The sending side, cloned into zenoh's callbacks.
#[derive(Debug, Clone)]
pub(crate) struct Post {
    mail: mpsc::Sender<Mail>,
    ring: mpsc::SyncSender<()>,
}

impl Post {
    pub(crate) fn send(&self, mail: Mail) {
        if self.mail.send(mail).is_ok() {
            // A full channel means a ring is on its way already.
            let _ = self.ring.try_send(());
        }
    }
}

/// The receiving side, on the bridge's thread, and the ringer.
pub(crate) struct Inbox {
    pub(crate) mail: mpsc::Receiver<Mail>,
    ringer: Option<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
}

impl std::fmt::Debug for Inbox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Inbox")
    }
}

/// An inbox whose ringer rings `Doorbell::Bridge` of run `run_id` (as bridge `ringer_id`).
pub(crate) fn inbox(run_id: &str, ringer_id: u16) -> (Post, Inbox) {
    let (mail_tx, mail_rx) = mpsc::channel();
    let (ring_tx, ring_rx) = mpsc::sync_channel::<()>(1);
    let stop = Arc::new(AtomicBool::new(false));
    let run_id = run_id.to_owned();
    let stopped = Arc::clone(&stop);
    let ringer = std::thread::Builder::new()
        .name("bridge-ringer".to_owned())
        .spawn(move || {
            let wire = match Wire::connect(
                &run_id,
                Process::new(Role::Bridge, ringer_id),
                alfd_wire::SCHEMA_VERSION,
            ) {
                Ok(w) => w,
                Err(e) => return warn!("bridge ringer: {e}"),
            };
            let bell = match wire.bell(Doorbell::Bridge) {
                Ok(b) => b,
                Err(e) => return warn!("bridge ringer: {e}"),
            };
            while !stopped.load(Ordering::Relaxed) {
                match ring_rx.recv_timeout(Duration::from_millis(100)) {
                    Ok(()) => {
                        if let Err(e) = bell.ring() {
                            warn!("bridge ringer: {e}");
                        }
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    Err(mpsc::RecvTimeoutError::Disconnected) => break,
                }
            }
        })
        .expect("a thread starts");
    (
        Post {
            mail: mail_tx,
            ring: ring_tx,
        },
        Inbox {
            mail: mail_rx,
            ringer: Some(ringer),
            stop,
        },
    )
}

impl Drop for Inbox {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.ringer.take() {
            let _ = t.join();
        }
    }
}
