//! Helpers of the wire's unit tests. Every test uses its own run id, hence its own iceoryx2
//! prefix, so tests running in parallel in one process never see each other.

use std::sync::atomic::{AtomicU32, Ordering};

use alfd_common::replay::Transition;

use crate::{close_run, leftover_files, Process, Role, Wire, SCHEMA_VERSION};

/// A run id no other test (of this process or another) uses.
pub(crate) fn run_id(test: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "t{}-{}-{}",
        std::process::id(),
        test,
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// Runs `test` on a fresh run id, then checks that the run leaves nothing behind.
pub(crate) fn with_run(name: &str, test: impl FnOnce(&str)) {
    let run = run_id(name);
    test(&run);
    close_run(&run).expect("every node of the test was dropped");
    assert_eq!(leftover_files(&run), Vec::<std::path::PathBuf>::new());
}

/// Joins `run` as `role` `id`, speaking this build's schema version.
pub(crate) fn wire(run: &str, role: Role, id: u16) -> Wire {
    Wire::connect(run, Process::new(role, id), SCHEMA_VERSION).expect("connect")
}

/// A step of a 4-dimensional observation with 2 heads.
pub(crate) fn transition(x: f32, demo: bool, terminated: bool) -> Transition {
    Transition {
        state: vec![x, x + 0.5, -x, 0.25],
        action: (x as u32) % 2,
        reward: x * 2.0,
        next_state: vec![x + 1.0, x + 1.5, -x - 1.0, 0.5],
        terminated,
        mask: vec![1.0, 0.0],
        demo,
        horizon: 1,
    }
}
