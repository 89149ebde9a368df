//! Tests of the wire, in one process: every test uses its own run id, hence its own iceoryx2
//! prefix, so tests running in parallel never see each other.

use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use super::*;

fn run_id(test: &str) -> String {
    static N: AtomicU32 = AtomicU32::new(0);
    format!(
        "t{}-{}-{}",
        std::process::id(),
        test,
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// Runs `test` on a fresh run id, then checks that the run leaves nothing behind.
fn with_run(name: &str, test: impl FnOnce(&str)) {
    let run = run_id(name);
    test(&run);
    close_run(&run).expect("every node of the test was dropped");
    assert_eq!(leftover_files(&run), Vec::<std::path::PathBuf>::new());
}

fn wire(run: &str, role: Role, id: u16) -> Wire {
    Wire::connect(run, Process::new(role, id), SCHEMA_VERSION).expect("connect")
}

fn transition(x: f32, demo: bool, terminated: bool) -> Transition {
    Transition {
        state: vec![x, x + 0.5, -x, 0.25],
        action: (x as u32) % 2,
        reward: x * 2.0,
        next_state: vec![x + 1.0, x + 1.5, -x - 1.0, 0.5],
        terminated,
        mask: vec![1.0, 0.0],
        demo,
    }
}

#[test]
fn transitions_arrive_in_order_with_header_and_flags() {
    with_run("transitions", |run| {
        let actor = wire(run, Role::Actor, 3);
        let learner = wire(run, Role::Learner, 0);
        let rx = learner.transitions_receiver().unwrap();
        let mut tx = actor.transitions_sender().unwrap();

        let sent = [
            transition(1.0, false, false),
            transition(2.0, true, false),
            transition(3.0, false, true),
        ];
        let mut batch = TransitionBatch::new(3, 77, 4, 2, 10).unwrap();
        for (i, t) in sent.iter().enumerate() {
            batch.push(t, 5, false).unwrap();
            assert_eq!(batch.len(), i + 1);
        }
        assert_eq!(batch.end_seq(), 13);
        assert_eq!(tx.send(batch).unwrap(), 0);
        assert_eq!(
            tx.send(TransitionBatch::new(3, 77, 4, 2, 13).unwrap())
                .unwrap(),
            1
        );

        let got = rx.receive().unwrap().expect("a batch");
        assert_eq!(got.header.schema, SCHEMA_VERSION);
        assert_eq!(got.header.sender(), "actor-3");
        assert_eq!(got.header.seq, 0);
        assert_eq!((got.actor, got.incarnation, got.first_seq), (3, 77, 10));
        let back: Vec<Transition> = got.transitions().collect();
        assert_eq!(back, sent);
        assert_eq!(got.records[1].flags, flags::DEMO);
        assert_eq!(got.records[2].flags, flags::TERMINATED | flags::EPISODE_END);
        let second = rx.receive().unwrap().expect("the empty batch");
        assert_eq!(second.header.seq, 1);
        assert!(second.is_empty());
        assert!(rx.receive().unwrap().is_none());
    });
}

#[test]
fn a_batch_refuses_what_it_cannot_carry() {
    assert!(matches!(
        TransitionBatch::new(0, 1, MAX_OBS_DIM + 1, 2, 0),
        Err(WireError::TooLarge {
            max: MAX_OBS_DIM,
            ..
        })
    ));
    assert!(matches!(
        TransitionBatch::new(0, 1, 4, MAX_HEADS + 1, 0),
        Err(WireError::TooLarge { max: MAX_HEADS, .. })
    ));
    let mut b = TransitionBatch::new(0, 1, 4, 2, 0).unwrap();
    let mut wrong = transition(1.0, false, false);
    wrong.state.push(9.0);
    assert!(b.push(&wrong, 0, false).is_err());
    assert!(b.is_empty(), "a refused step is not stored");
    for i in 0..TRANSITIONS_PER_BATCH {
        b.push(&transition(i as f32, false, false), 0, false)
            .unwrap();
    }
    assert!(b.is_full());
    assert!(b.push(&transition(0.0, false, false), 0, false).is_err());
    let truncated = {
        let mut b = TransitionBatch::new(0, 1, 4, 2, 0).unwrap();
        b.push(&transition(1.0, false, false), 0, true).unwrap();
        b.records[0].flags
    };
    assert_eq!(truncated, flags::TRUNCATED | flags::EPISODE_END);
    assert!(QueryRequest::new(0, 1, 0, &[0.0; MAX_OBS_DIM + 1]).is_err());
}

#[test]
fn another_schema_version_is_refused_naming_both_versions() {
    with_run("schema", |run| {
        let launcher = wire(run, Role::Launcher, 0);
        let stranger = Wire::connect(run, Process::new(Role::Actor, 1), 999).unwrap();
        let rx = stranger.control_receiver().unwrap();
        let mut tx = launcher.control_sender().unwrap();
        tx.send(Control {
            command: command::RUN,
            ..Control::default()
        })
        .unwrap();
        let err = rx.receive().unwrap_err();
        assert_eq!(
            err,
            WireError::SchemaMismatch {
                service: "control",
                ours: 999,
                theirs: SCHEMA_VERSION,
                sender: "launcher".to_owned(),
            }
        );
        let text = err.to_string();
        assert!(
            text.contains("999") && text.contains(&format!("version {SCHEMA_VERSION}")),
            "{text}"
        );
        // The bad message was consumed; the receiver goes on.
        assert!(rx.receive().unwrap().is_none());

        // The same on a slice service.
        let mut weights = stranger.weights_sender(3).unwrap();
        let learner_rx = launcher.weights_receiver().unwrap();
        weights.publish(1, 0, 0, &[1.0, 2.0, 3.0]).unwrap();
        let mut out = Vec::new();
        assert!(matches!(
            learner_rx.latest_into(&mut out),
            Err(WireError::SchemaMismatch {
                ours: SCHEMA_VERSION,
                theirs: 999,
                ..
            })
        ));
    });
}

#[test]
fn weights_reach_a_late_subscriber_and_only_the_newest_is_kept() {
    with_run("weights", |run| {
        let learner = wire(run, Role::Learner, 0);
        let actor = wire(run, Role::Actor, 0);
        let mut tx = learner.weights_sender(4500).unwrap();
        let w1: Vec<f32> = (0..4500).map(|i| i as f32 * 0.5).collect();
        tx.publish(1, 10, 20, &w1).unwrap();

        // Subscribes after the publication: gets it from the history once the publisher updates.
        let rx = actor.weights_receiver().unwrap();
        tx.update_connections().unwrap();
        let mut out = Vec::new();
        let h = rx.latest_into(&mut out).unwrap().expect("history sample");
        assert_eq!(
            (h.version, h.updates, h.env_steps, h.len),
            (1, 10, 20, 4500)
        );
        assert_eq!(out, w1);

        for v in 2..=4 {
            let w: Vec<f32> = vec![v as f32; 4500];
            tx.publish(v, 0, 0, &w).unwrap();
        }
        let h = rx.latest_into(&mut out).unwrap().unwrap();
        assert_eq!(h.version, 4);
        assert!(out.iter().all(|&x| x == 4.0));
        assert!(rx.latest_into(&mut out).unwrap().is_none());
    });
}

#[test]
fn demo_model_bytes_round_trip() {
    with_run("demo-model", |run| {
        let expert = wire(run, Role::Expert, 2);
        let actor = wire(run, Role::Actor, 0);
        let rx = actor.demo_model_receiver().unwrap();
        let mut tx = expert.demo_model_sender().unwrap();
        // Larger than the initial 4 KiB: the publisher grows its segment.
        let bytes: Vec<u8> = (0..10_000u32).map(|i| (i % 251) as u8).collect();
        let header = DemoModelHeader {
            version: 7,
            last_demo_step: 1234,
            demos: 12,
            budget_total: 100,
            budget_left: 88,
            expert: 2,
            expert_name: name_to_bytes("cartpole-1000"),
            ..DemoModelHeader::default()
        };
        tx.publish(header, &bytes).unwrap();
        let mut out = Vec::new();
        let h = rx.latest_into(&mut out).unwrap().unwrap();
        assert_eq!(out, bytes);
        assert_eq!(
            (h.version, h.last_demo_step, h.demos, h.budget_left),
            (7, 1234, 12, 88)
        );
        assert_eq!(h.expert_name(), "cartpole-1000");
        assert_eq!(h.len, 10_000);
    });
}

#[test]
fn a_query_without_expert_reaches_nobody() {
    with_run("query-none", |run| {
        let actor = wire(run, Role::Actor, 1);
        let mut client = actor.query_client().unwrap();
        assert_eq!(actor.query_servers().unwrap(), 0);
        let mut pending = client
            .ask(QueryRequest::new(1, 9, 0, &[0.1, 0.2, 0.3, 0.4]).unwrap())
            .unwrap();
        assert_eq!(pending.servers(), 0);
        assert!(pending.poll().unwrap().is_none());
    });
}

#[test]
fn a_query_is_answered_once_and_duplicates_are_dropped() {
    with_run("query", |run| {
        let actor = wire(run, Role::Actor, 1);
        let old = wire(run, Role::Expert, 1);
        let new = wire(run, Role::Expert, 2);
        let s1 = old.query_server().unwrap();
        let s2 = new.query_server().unwrap();
        let mut client = actor.query_client().unwrap();
        assert_eq!(actor.query_servers().unwrap(), 2);

        // A first request, answered by nobody, then a second one answered by both experts.
        drop(
            client
                .ask(QueryRequest::new(1, 9, 5, &[0.0; 4]).unwrap())
                .unwrap(),
        );
        let mut pending = client
            .ask(QueryRequest::new(1, 9, 42, &[0.1, 0.2, 0.3, 0.4]).unwrap())
            .unwrap();
        assert_eq!(pending.seq(), 1);
        assert_eq!(pending.servers(), 2);
        for (server, expert, action) in [(&s1, 1u32, 0u32), (&s2, 2, 1)] {
            // The dropped first request may or may not still be queued; skip it.
            let mut q = server.receive().unwrap().expect("a request");
            if q.request().header.seq == 0 {
                q = server.receive().unwrap().expect("the second request");
            }
            assert_eq!(q.request().state(), &[0.1, 0.2, 0.3, 0.4]);
            assert_eq!(q.request().global_step, 42);
            assert_eq!(q.request().header.sender(), "actor-1");
            assert!(q.is_connected());
            q.answer(QueryResponse {
                outcome: outcome::ANSWERED,
                action,
                expert,
                demo_index: 3,
                expert_name: name_to_bytes(&format!("expert-{expert}")),
                ..QueryResponse::default()
            })
            .unwrap();
        }
        let first = pending.poll().unwrap().expect("an answer");
        assert_eq!(
            (first.request_seq, first.actor, first.action, first.expert),
            (1, 1, 0, 1)
        );
        assert_eq!(first.expert_name(), "expert-1");
        assert!(
            pending.poll().unwrap().is_none(),
            "the second answer is dropped"
        );
        assert_eq!(pending.duplicates(), 1);
    });
}

#[test]
fn an_abandoned_query_is_seen_by_the_expert() {
    with_run("query-abandoned", |run| {
        let actor = wire(run, Role::Actor, 0);
        let expert = wire(run, Role::Expert, 1);
        let server = expert.query_server().unwrap();
        let mut client = actor.query_client().unwrap();
        let pending = client
            .ask(QueryRequest::new(0, 1, 0, &[0.0; 4]).unwrap())
            .unwrap();
        let q = server.receive().unwrap().unwrap();
        assert!(q.is_connected());
        drop(pending); // the actor timed out
        assert!(!q.is_connected(), "the expert must not spend budget on it");
    });
}

#[test]
fn credits_and_progress_carry_their_fields() {
    with_run("credits", |run| {
        let learner = wire(run, Role::Learner, 0);
        let actor = wire(run, Role::Actor, 2);
        let launcher = wire(run, Role::Launcher, 0);
        let mut credits = learner.credits_sender().unwrap();
        let crx = actor.credits_receiver().unwrap();
        let mut c = Credits {
            env_steps: 500,
            updates: 480,
            ..Credits::default()
        };
        c.incarnation[2] = 11;
        c.granted[2] = 96;
        credits.send(c).unwrap();
        c.granted[2] = 128;
        credits.send(c).unwrap();
        let got = crx.latest().unwrap().unwrap();
        assert_eq!(got.granted_for(2, 11), Some(128));
        assert_eq!(
            got.granted_for(2, 12),
            None,
            "a grant for another incarnation"
        );
        assert_eq!(got.granted_for(99, 11), None);
        assert_eq!(got.env_steps, 500);

        let prx = launcher.progress_receiver().unwrap();
        let mut ptx = actor.progress_sender().unwrap();
        for e in 0..3u64 {
            ptx.send(Progress {
                kind: progress_kind::EPISODE,
                episode: e,
                episode_return: 10.0 + e as f64,
                length: 10 + e,
                ..Progress::default()
            })
            .unwrap();
        }
        let mut seen = Vec::new();
        while let Some(p) = prx.receive().unwrap() {
            seen.push((p.header.seq, p.episode, p.episode_return, p.length));
        }
        assert_eq!(
            seen,
            vec![(0, 0, 10.0, 10), (1, 1, 11.0, 11), (2, 2, 12.0, 12)]
        );
    });
}

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
fn two_runs_do_not_see_each_other_and_leave_nothing_behind() {
    let run_a = run_id("iso-a");
    let run_b = run_id("iso-b");
    {
        let a_launcher = wire(&run_a, Role::Launcher, 0);
        let b_launcher = wire(&run_b, Role::Launcher, 0);
        let a_actor = wire(&run_a, Role::Actor, 0);
        let b_actor = wire(&run_b, Role::Actor, 0);
        let mut a_tx = a_launcher.control_sender().unwrap();
        let mut b_tx = b_launcher.control_sender().unwrap();
        let a_rx = a_actor.control_receiver().unwrap();
        let b_rx = b_actor.control_receiver().unwrap();
        a_tx.send(Control {
            command: command::SHUTDOWN,
            ..Control::default()
        })
        .unwrap();
        assert_eq!(a_rx.receive().unwrap().unwrap().command, command::SHUTDOWN);
        assert!(
            b_rx.receive().unwrap().is_none(),
            "run b saw run a's control"
        );
        b_tx.send(Control {
            command: command::RUN,
            active_expert: 4,
            ..Control::default()
        })
        .unwrap();
        assert!(a_rx.receive().unwrap().is_none());
        assert_eq!(b_rx.receive().unwrap().unwrap().active_expert, 4);
        assert!(!leftover_files(&run_a).is_empty(), "a live run has files");
        assert!(leftover_files(&run_a)
            .iter()
            .all(|p| p.to_string_lossy().contains(&run_prefix(&run_a))));
        assert!(matches!(close_run(&run_a), Err(WireError::RunAlive { .. })));
        assert_eq!(alive_nodes(&run_b).unwrap().len(), 2);
    }
    assert_eq!(cleanup_dead_nodes(&run_a).unwrap(), Vec::<String>::new());
    assert_eq!(alive_nodes(&run_a).unwrap(), Vec::<String>::new());
    close_run(&run_a).unwrap();
    close_run(&run_b).unwrap();
    assert_eq!(leftover_files(&run_a), Vec::<std::path::PathBuf>::new());
    assert_eq!(leftover_files(&run_b), Vec::<std::path::PathBuf>::new());
}

#[test]
fn run_ids_and_names_are_checked() {
    assert!(validate_run_id("20250101-120000_ab12").is_ok());
    for bad in ["", "a/b", "a b", "ü", &"x".repeat(65)] {
        assert_eq!(
            validate_run_id(bad),
            Err(WireError::InvalidRunId(bad.to_owned()))
        );
    }
    assert!(Wire::connect("bad/id", Process::new(Role::Tool, 0), SCHEMA_VERSION).is_err());
    assert_eq!(
        name_from_bytes(&name_to_bytes("cartpole-200")),
        "cartpole-200"
    );
    let long = "é".repeat(20); // 40 bytes: cut on a character boundary
    assert_eq!(name_from_bytes(&name_to_bytes(&long)), "é".repeat(16));
    assert_eq!(Process::new(Role::Actor, 3).to_string(), "actor-3");
    assert_eq!(Process::new(Role::Learner, 0).to_string(), "learner");
    assert_eq!(Role::from_u16(Role::Expert as u16), Some(Role::Expert));
    assert_eq!(Role::from_u16(0), None);
}
