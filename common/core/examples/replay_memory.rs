//! `cargo run --release -p alfd-common --example replay_memory`: the resident memory a replay
//! buffer of a million CartPole transitions (4 observations, 4 heads) adds, filled, from
//! `/proc/self/status` before and after. Prints one JSON line.

use alfd_common::replay::{ReplayBuffer, Transition};

const TRANSITIONS: usize = 1_000_000;
const OBS: usize = 4;
const HEADS: usize = 4;

fn rss_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .expect("VmRSS");
    kib * 1024
}

fn main() {
    let before = rss_bytes();
    let mut replay = ReplayBuffer::new(TRANSITIONS, OBS, HEADS);
    let mut t = Transition {
        state: vec![0.5; OBS],
        action: 1,
        reward: 1.0,
        next_state: vec![0.25; OBS],
        terminated: false,
        mask: vec![1.0; HEADS],
        demo: false,
        horizon: 1,
    };
    for i in 0..TRANSITIONS {
        t.state[0] = i as f32;
        replay.push(&t);
    }
    let after = rss_bytes();
    // states and next states, action, reward, terminated, masks (4 bytes each), demo and
    // horizon (1 byte each).
    let layout = 4 * (2 * OBS + 3 + HEADS) + 2;
    println!(
        "{{\"transitions\":{TRANSITIONS},\"heads\":{HEADS},\"rss_bytes\":{},\"layout_bytes_per_transition\":{layout},\"len\":{}}}",
        after.saturating_sub(before),
        replay.len()
    );
}
