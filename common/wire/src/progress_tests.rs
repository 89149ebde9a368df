//! The `progress` channel under a launcher that falls behind: an actor's episode records wait
//! for room, statuses are dropped.

use crate::test_support::{wire, with_run};
use crate::*;

/// An episode record numbered `e`, of actor 2.
fn episode(e: u32) -> Progress {
    let record = alfd_common::record::EpisodeRecord {
        episode: e,
        actor: 2,
        ..Default::default()
    };
    Progress::episode(1, record)
}

/// The episode numbers `rx` holds now, in order.
fn drain(rx: &Receiver<'_, Progress>) -> Vec<u32> {
    std::iter::from_fn(|| rx.receive().unwrap())
        .map(|p| p.episode.0.episode)
        .collect()
}

/// A launcher whose buffer holds 4 records and that reads one every 5 ms: an actor's 40
/// records all arrive, in order (they wait for room); status messages sent the same way
/// into a full buffer are dropped, which shows the buffer was full. (A subscriber connects
/// to a new publisher when it next receives: a publisher waits only on a connected one.)
#[test]
fn an_actors_episode_records_wait_for_room_in_a_full_launcher_buffer_and_none_is_lost() {
    with_run("episodes-wait", |run| {
        let launcher = wire(run, Role::Launcher, 0);
        let rx = launcher.progress_receiver_holding(4).unwrap();
        let statuses = wire(run, Role::Expert, 1);
        let mut tx = statuses.progress_sender().unwrap();
        assert!(rx.receive().unwrap().is_none());
        for e in 0..10 {
            tx.send(episode(e)).unwrap();
        }
        assert_eq!(drain(&rx), vec![0, 1, 2, 3], "a full buffer drops statuses");
        let connected = std::sync::Barrier::new(2);
        let got = std::thread::scope(|s| {
            s.spawn(|| {
                let actor = wire(run, Role::Actor, 2);
                let mut tx = actor.episode_sender().unwrap();
                connected.wait();
                connected.wait();
                for e in 0..40 {
                    tx.send(episode(e)).unwrap();
                }
            });
            connected.wait();
            assert!(rx.receive().unwrap().is_none());
            connected.wait();
            // Bounded, so that a lost record fails the test rather than hangs it.
            let mut got = Vec::new();
            for _ in 0..2000 {
                std::thread::sleep(std::time::Duration::from_millis(5));
                got.extend(rx.receive().unwrap().map(|p| p.episode.0.episode));
                if got.len() == 40 {
                    break;
                }
            }
            got
        });
        assert_eq!(got, (0..40).collect::<Vec<_>>());
    });
}

/// A launcher that reads nothing (stalled, or dead and not cleaned up yet) holds an actor
/// up for a while per record, never for ever: the record past the full buffer is dropped.
#[test]
fn an_episode_record_a_stalled_launcher_has_no_room_for_is_dropped_after_a_while() {
    with_run("episodes-stalled", |run| {
        let launcher = wire(run, Role::Launcher, 0);
        let rx = launcher.progress_receiver_holding(2).unwrap();
        let actor = wire(run, Role::Actor, 2);
        let mut tx = actor.episode_sender().unwrap();
        assert!(rx.receive().unwrap().is_none());
        for e in 0..3 {
            assert_eq!(tx.send(episode(e)).unwrap(), u64::from(e));
        }
        assert_eq!(drain(&rx), vec![0, 1]);
    });
}
