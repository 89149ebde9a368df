//! The chaos run's slow link: a TCP relay on 127.0.0.1 between a joined host and the run's
//! listening port that, while a delay fault lasts, holds every byte for that delay before it goes
//! on (in order, in both directions). [`Held`] is the relay's schedule with no I/O (time passed
//! in); [`Relay`] is the thin shell of threads around it.

use std::collections::VecDeque;
use std::io::{Read as _, Write as _};
use std::net::{Ipv4Addr, Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

/// The bytes read from one side of a link and not yet passed on: each piece leaves at the time
/// it was read plus the delay in force when it was read, and never before a piece read earlier.
#[derive(Debug, Default)]
pub struct Held {
    pieces: VecDeque<(Duration, Vec<u8>)>,
}

impl Held {
    /// `bytes` read at `now` (time since any fixed start) while `delay` is in force.
    pub fn read(&mut self, bytes: Vec<u8>, now: Duration, delay: Duration) {
        let due = now + delay;
        // A shorter delay after a longer one cannot overtake: the link keeps its order.
        let due = self.pieces.back().map_or(due, |(last, _)| due.max(*last));
        self.pieces.push_back((due, bytes));
    }

    /// The pieces due at `now`, in the order they were read.
    pub fn due(&mut self, now: Duration) -> Vec<Vec<u8>> {
        let n = self.pieces.iter().take_while(|(t, _)| *t <= now).count();
        self.pieces.drain(..n).map(|(_, b)| b).collect()
    }

    /// When the next piece is due (none held: `None`).
    pub fn next_due(&self) -> Option<Duration> {
        self.pieces.front().map(|(t, _)| *t)
    }
}

/// A relay listening on a free port of 127.0.0.1 that forwards every connection to `upstream`,
/// holding bytes for the delay set with [`Relay::set_delay`].
pub struct Relay {
    port: u16,
    delay_ms: Arc<AtomicU64>,
}

impl Relay {
    /// Listens, and relays each connection to `127.0.0.1:upstream` on threads of its own.
    pub fn start(upstream: u16) -> std::io::Result<Self> {
        let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, 0))?;
        let port = listener.local_addr()?.port();
        let delay_ms = Arc::new(AtomicU64::new(0));
        let delay = Arc::clone(&delay_ms);
        std::thread::spawn(move || {
            for down in listener.incoming().flatten() {
                if let Ok(up) = TcpStream::connect((Ipv4Addr::LOCALHOST, upstream)) {
                    link(down, up, &delay);
                }
            }
        });
        Ok(Self { port, delay_ms })
    }

    /// The port the joined host connects to.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Bytes read from now on are held for `delay` (zero: passed on at once).
    pub fn set_delay(&self, delay: Duration) {
        self.delay_ms
            .store(delay.as_millis() as u64, Ordering::Relaxed);
    }
}

/// Relays one connection both ways.
fn link(down: TcpStream, up: TcpStream, delay: &Arc<AtomicU64>) {
    let pairs = [
        (down.try_clone(), up.try_clone()),
        (up.try_clone(), down.try_clone()),
    ];
    for (from, to) in pairs {
        if let (Ok(from), Ok(to)) = (from, to) {
            pump(from, to, Arc::clone(delay));
        }
    }
}

/// One direction: a reader thread hands what it reads, with its time, to a writer thread that
/// passes it on when [`Held`] says it is due.
fn pump(mut from: TcpStream, mut to: TcpStream, delay: Arc<AtomicU64>) {
    let start = Instant::now();
    let (tx, rx) = mpsc::channel::<(Duration, Vec<u8>)>();
    std::thread::spawn(move || {
        let mut buf = vec![0u8; 64 * 1024];
        while let Ok(n @ 1..) = from.read(&mut buf) {
            let d = Duration::from_millis(delay.load(Ordering::Relaxed));
            if tx.send((d, buf[..n].to_vec())).is_err() {
                break;
            }
        }
        let _ = from.shutdown(Shutdown::Read);
    });
    std::thread::spawn(move || {
        let mut held = Held::default();
        loop {
            let now = start.elapsed();
            let wait = held
                .next_due()
                .map_or(Duration::from_secs(3600), |t| t.saturating_sub(now));
            match rx.recv_timeout(wait) {
                Ok((d, bytes)) => held.read(bytes, start.elapsed(), d),
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) if held.next_due().is_none() => break,
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    std::thread::sleep(wait);
                }
            }
            for piece in held.due(start.elapsed()) {
                if to.write_all(&piece).is_err() {
                    return;
                }
            }
        }
        let _ = to.shutdown(Shutdown::Write);
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn bytes_leave_after_the_delay_in_force_when_they_were_read() {
        let mut h = Held::default();
        h.read(b"a".to_vec(), ms(0), ms(0));
        h.read(b"b".to_vec(), ms(10), ms(500));
        assert_eq!(h.due(ms(10)), vec![b"a".to_vec()]);
        assert_eq!(h.next_due(), Some(ms(510)));
        assert!(h.due(ms(509)).is_empty());
        assert_eq!(h.due(ms(510)), vec![b"b".to_vec()]);
        assert_eq!(h.next_due(), None);
    }

    #[test]
    fn nothing_overtakes_when_the_delay_ends() {
        let mut h = Held::default();
        h.read(b"slow".to_vec(), ms(0), ms(2000));
        // The fault is over: later bytes have no delay, yet wait for the ones held before them.
        h.read(b"fast".to_vec(), ms(100), ms(0));
        assert!(h.due(ms(1999)).is_empty());
        assert_eq!(h.due(ms(2000)), vec![b"slow".to_vec(), b"fast".to_vec()]);
    }

    #[test]
    fn a_relay_passes_bytes_both_ways_in_order() {
        let echo = TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        let upstream = echo.local_addr().unwrap().port();
        std::thread::spawn(move || {
            let (mut s, _) = echo.accept().unwrap();
            let mut buf = [0u8; 1024];
            while let Ok(n @ 1..) = s.read(&mut buf) {
                s.write_all(&buf[..n]).unwrap();
            }
        });
        let relay = Relay::start(upstream).unwrap();
        relay.set_delay(ms(20));
        let mut c = TcpStream::connect((Ipv4Addr::LOCALHOST, relay.port())).unwrap();
        let sent: Vec<u8> = (0..=255u8).cycle().take(10_000).collect();
        c.write_all(&sent).unwrap();
        let mut got = vec![0u8; sent.len()];
        c.read_exact(&mut got).unwrap();
        assert_eq!(got, sent);
    }
}
