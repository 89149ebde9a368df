//! How the scheduler treats a thread: its nice value and, on Linux's EEVDF scheduler (6.12 and
//! later), its slice.
//!
//! A busy thread keeps its core for its slice (about 1.5 ms on a 2-core machine) against a woken
//! thread of the same weight. The query path (an actor waiting for its answer, the expert
//! answering) sleeps between queries and runs a few microseconds each time it wakes, so it asks
//! for a short slice: EEVDF then lets it preempt the learner or a refit at once (the kernel's
//! `PREEMPT_SHORT`), and its share of the core is unchanged. A refit in the background asks for a
//! higher nice value and the default slice. Where the system refuses, or is not Linux, the
//! thread keeps what it has; nothing else depends on it.

use std::time::Duration;

use tracing::debug;

/// The slice the query path's threads ask for: the shortest EEVDF grants.
pub const QUERY_SLICE: Duration = Duration::from_micros(100);

/// The environment variable that sets the query path's slice in microseconds (`0`: the
/// system's default, as for any other thread).
pub const QUERY_SLICE_VAR: &str = "ALFD_QUERY_SLICE_US";

/// A thread's scheduling: `nice` (`None`: the one it has), and `slice` (`None`: the system's
/// default).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sched {
    pub nice: Option<i32>,
    pub slice: Option<Duration>,
}

impl Sched {
    /// The query path: the short [`QUERY_SLICE`] (or what `QUERY_SLICE_VAR` says), the nice
    /// value the thread has (lowering it would need a privilege).
    pub fn query_path() -> Sched {
        Sched {
            nice: None,
            slice: query_slice(std::env::var(QUERY_SLICE_VAR).ok().as_deref()),
        }
    }

    /// Work that yields to everything else: `nice`, the default slice.
    pub fn background(nice: i32) -> Sched {
        Sched {
            nice: Some(nice),
            slice: None,
        }
    }

    /// Applies to the calling thread (and the threads it starts later), logging at debug
    /// level what the system refused.
    pub fn apply(self) {
        if let Err(e) = set_thread(self) {
            debug!(sched = ?self, error = %e, "the system refused the thread's scheduling, or part of it");
        }
    }
}

/// The query path's slice given [`QUERY_SLICE_VAR`]'s value: a number of microseconds, `0` the
/// default slice; anything else (logged) or nothing is [`QUERY_SLICE`].
fn query_slice(var: Option<&str>) -> Option<Duration> {
    let slice = micros_var(QUERY_SLICE_VAR, var, QUERY_SLICE);
    (!slice.is_zero()).then_some(slice)
}

/// The duration an environment variable `name` gives in microseconds, from its value `var`:
/// `default` when it is unset, or (logged) when it is not a whole number of microseconds.
pub fn micros_var(name: &str, var: Option<&str>, default: Duration) -> Duration {
    let Some(v) = var else {
        return default;
    };
    match v.trim().parse::<u64>() {
        Ok(us) => Duration::from_micros(us),
        Err(_) => {
            tracing::warn!(
                value = v,
                "{name} is not a number of microseconds: {default:?} is kept"
            );
            default
        }
    }
}

/// `sched_attr` of `sched_setattr(2)`, its first version (48 bytes).
#[cfg(target_os = "linux")]
#[repr(C)]
#[derive(Debug, Default)]
struct SchedAttr {
    size: u32,
    policy: u32,
    flags: u64,
    nice: i32,
    priority: u32,
    /// For `SCHED_OTHER`: the slice in nanoseconds (0: the default), on kernels that read it.
    runtime: u64,
    deadline: u64,
    period: u64,
}

#[cfg(target_os = "linux")]
fn attr(s: Sched) -> SchedAttr {
    SchedAttr {
        size: std::mem::size_of::<SchedAttr>() as u32,
        policy: libc::SCHED_OTHER as u32,
        nice: s.nice.unwrap_or_else(current_nice),
        runtime: s
            .slice
            .map_or(0, |d| d.as_nanos().min(u64::MAX as u128) as u64),
        ..SchedAttr::default()
    }
}

/// The calling thread's nice value (0 where it cannot be read).
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn current_nice() -> i32 {
    // SAFETY: errno's location is this thread's and valid while it runs; getpriority writes no
    // memory of ours (`who` 0 with PRIO_PROCESS is the calling thread on Linux). -1 is both a
    // nice value and the error return: errno, cleared before, tells them apart.
    unsafe {
        *libc::__errno_location() = 0;
        let nice = libc::getpriority(libc::PRIO_PROCESS, 0);
        if nice == -1 && *libc::__errno_location() != 0 {
            0
        } else {
            nice
        }
    }
}

#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn set_thread(s: Sched) -> std::io::Result<()> {
    let a = attr(s);
    // SAFETY: `a` is a valid, fully initialised sched_attr of the size its `size` field gives,
    // alive for the call; pid 0 is the calling thread and flags 0 asks for nothing else.
    let r = unsafe { libc::syscall(libc::SYS_sched_setattr, 0, &a as *const SchedAttr, 0) };
    if r == 0 {
        return Ok(());
    }
    let e = std::io::Error::last_os_error();
    // Kernels before 6.12 take no slice; some refuse a runtime for SCHED_OTHER: the nice
    // value alone, then.
    if s.slice.is_some() {
        let a = attr(Sched { slice: None, ..s });
        // SAFETY: as above.
        let r = unsafe { libc::syscall(libc::SYS_sched_setattr, 0, &a as *const SchedAttr, 0) };
        if r == 0 {
            return Err(e);
        }
    }
    Err(e)
}

/// Asks that the calling thread's timed sleeps end within `slack` of their deadline (Linux's
/// timer slack, `PR_SET_TIMERSLACK`, 50 µs unless set): a thread that polls in sleeps of tens
/// of microseconds would otherwise sleep up to twice as long as it asks. Where the system
/// refuses, or is not Linux, the thread keeps its slack (logged at debug level).
pub fn set_timer_slack(slack: Duration) {
    if let Err(e) = set_slack(slack) {
        debug!(?slack, error = %e, "the system refused the thread's timer slack");
    }
}

#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn set_slack(slack: Duration) -> std::io::Result<()> {
    // PR_SET_TIMERSLACK takes nanoseconds; 0 would mean "the thread's default" again.
    let ns = slack.as_nanos().clamp(1, u128::from(u32::MAX)) as libc::c_ulong;
    // SAFETY: prctl with PR_SET_TIMERSLACK reads its second argument as a number and touches no
    // memory of ours; it applies to the calling thread.
    let r = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, ns, 0, 0, 0) };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn set_slack(_: Duration) -> std::io::Result<()> {
    Err(std::io::Error::new(
        std::io::ErrorKind::Unsupported,
        "the timer slack is set on Linux only",
    ))
}

#[cfg(not(target_os = "linux"))]
fn set_thread(_: Sched) -> std::io::Result<()> {
    Err(std::io::Error::new(
        std::io::ErrorKind::Unsupported,
        "scheduling attributes are set on Linux only",
    ))
}

#[cfg(test)]
mod slice_tests {
    use super::*;

    #[cfg(target_os = "linux")]
    #[test]
    #[allow(unsafe_code)]
    fn the_timer_slack_is_the_calling_threads() {
        let read = || {
            // SAFETY: PR_GET_TIMERSLACK reads nothing of ours and returns the slack in ns.
            unsafe { libc::prctl(libc::PR_GET_TIMERSLACK, 0, 0, 0, 0) }
        };
        let before = read();
        let after = std::thread::spawn(move || {
            set_timer_slack(Duration::from_micros(1));
            read()
        })
        .join()
        .unwrap();
        assert_eq!(after, 1_000);
        assert_eq!(read(), before, "another thread's slack is left alone");
    }

    #[test]
    fn the_variable_sets_the_slice_in_microseconds_and_zero_leaves_the_default() {
        assert_eq!(query_slice(None), Some(QUERY_SLICE));
        assert_eq!(query_slice(Some("250")), Some(Duration::from_micros(250)));
        assert_eq!(query_slice(Some("0")), None);
        assert_eq!(query_slice(Some("fast")), Some(QUERY_SLICE));
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    const SHORT: Sched = Sched {
        nice: None,
        slice: Some(QUERY_SLICE),
    };

    /// The calling thread's (nice, slice in ns) from `sched_getattr(2)`.
    #[allow(unsafe_code)]
    fn current() -> (i32, u64) {
        let mut a = SchedAttr::default();
        // SAFETY: `a` is writable and as large as the size passed; pid 0 is this thread.
        let r = unsafe {
            libc::syscall(
                libc::SYS_sched_getattr,
                0,
                &mut a as *mut SchedAttr,
                std::mem::size_of::<SchedAttr>() as u32,
                0,
            )
        };
        assert_eq!(r, 0, "{}", std::io::Error::last_os_error());
        (a.nice, a.runtime)
    }

    #[test]
    fn the_attribute_is_the_kernels_first_version() {
        assert_eq!(std::mem::size_of::<SchedAttr>(), 48);
        let a = attr(SHORT);
        assert_eq!((a.size, a.policy, a.runtime), (48, 0, 100_000));
        assert_eq!(a.nice, current_nice());
        assert_eq!(attr(Sched::background(10)).runtime, 0);
    }

    #[test]
    fn a_thread_gets_the_nice_value_and_the_slice_it_asks_for() {
        // On a thread of its own: the test runner's threads keep theirs.
        std::thread::spawn(|| {
            Sched::background(7).apply();
            assert_eq!(current().0, 7);
            let (_, default_slice) = current();
            // The query path's slice keeps the nice value (lowering it would need a
            // privilege); a kernel that takes no slice (before 6.12) refuses it.
            if set_thread(SHORT).is_ok() {
                assert_eq!(current(), (7, 100_000));
                Sched::background(7).apply();
                assert_eq!(current(), (7, default_slice));
            }
        })
        .join()
        .unwrap();
    }
}
