//! Tests of the wire's messages: layouts, round trips, refusals and a fuzz pass.

use crate::test_support::transition;
use crate::*;

#[test]
fn a_batch_refuses_what_it_cannot_carry() {
    assert!(TransitionBatch::new(0, 1, 2500, 20, 0).is_ok());
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
    assert!(b.push(&wrong).is_err());
    assert!(b.is_empty(), "a refused step is not stored");
    for i in 0..TRANSITIONS_PER_BATCH {
        b.push(&transition(i as f32, false, false)).unwrap();
    }
    assert!(b.is_full());
    assert!(b.push(&transition(0.0, false, false)).is_err());
    let flagged = {
        let mut b = TransitionBatch::new(0, 1, 4, 2, 0).unwrap();
        b.push(&transition(1.0, true, true)).unwrap();
        b.head.records[0].flags
    };
    assert_eq!(flagged, flags::TERMINATED | flags::DEMO);
    assert!(QueryRequest::new(0, 1, 0, &[0.0; MAX_OBS_DIM + 1]).is_err());
}

#[test]
fn an_episode_record_has_the_layout_the_wire_expects() {
    use crate::messages::Episode;
    use alfd_common::record::EpisodeRecord;
    // Changing this layout changes the message: bump SCHEMA_VERSION with it.
    assert_eq!(std::mem::size_of::<Episode>(), 56);
    assert_eq!(std::mem::align_of::<Episode>(), 8);
    assert_eq!(std::mem::offset_of!(EpisodeRecord, actor), 52);
    let r = EpisodeRecord {
        ret: 21.0,
        mean_js: 0.25,
        total_steps: 99,
        eval_return: 500.0,
        episode: 3,
        length: 21,
        demos_used: 5,
        queries: 2,
        shaped_steps: 7,
        actor: 11,
    };
    assert_eq!(Progress::episode(4, r).episode.0, r);
}

#[test]
fn names_and_identities_are_checked() {
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

mod fuzz {
    use super::super::*;
    use proptest::prelude::*;

    fn record() -> impl Strategy<Value = TransitionRecord> {
        (any::<u32>(), any::<u32>(), any::<f32>()).prop_map(|(action, flags, reward)| {
            TransitionRecord {
                action,
                reward,
                flags,
            }
        })
    }

    /// A batch as another process may have filled it: any field, any record.
    fn any_batch() -> impl Strategy<Value = TransitionBatch> {
        (
            (any::<u32>(), 0u32..4),
            (any::<u16>(), any::<u16>(), 0u16..=10),
            (any::<u64>(), any::<u64>(), 0u64..4),
            (
                any::<u32>(),
                0u32..=TRANSITIONS_PER_BATCH as u32 + 2,
                any::<u32>(),
            ),
            proptest::collection::vec(record(), 4),
            (proptest::collection::vec(any::<f32>(), 0..64), any::<u8>()),
        )
            .prop_map(
                |(
                    (actor, a),
                    (od, hd, od_small),
                    (inc, seq, inc_small),
                    (len, len_small, blocked),
                    recs,
                    (values, repeat),
                )| {
                    let mut b = TransitionBatch {
                        head: TransitionHeader {
                            actor: if a == 0 { actor } else { a - 1 },
                            obs_dim: if od % 2 == 0 { od } else { od_small },
                            heads: if hd % 2 == 0 { hd } else { hd % 22 },
                            incarnation: if inc % 2 == 0 { inc } else { inc_small },
                            first_seq: if seq % 3 == 0 { seq } else { seq % 100 },
                            len: if len % 4 == 0 { len } else { len_small },
                            blocked,
                            ..TransitionHeader::default()
                        },
                        values: Vec::new(),
                    };
                    for (i, r) in b.head.records.iter_mut().enumerate() {
                        *r = recs[i % recs.len()];
                    }
                    // As many values as the steps need, or any other number.
                    let want = b
                        .len()
                        .min(TRANSITIONS_PER_BATCH)
                        .saturating_mul(b.stride());
                    b.values = if repeat % 2 == 0 && want <= 1 << 16 {
                        values.iter().copied().cycle().take(want).collect()
                    } else {
                        values
                    };
                    b
                },
            )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn fuzz_transition_batch(b in any_batch(), i in any::<usize>()) {
            let ts: Vec<Transition> = b.transitions().collect();
            prop_assert!(ts.len() <= TRANSITIONS_PER_BATCH && ts.len() <= b.len());
            for t in &ts {
                prop_assert_eq!(t.state.len(), usize::from(b.head.obs_dim));
                prop_assert_eq!(t.mask.len(), usize::from(b.head.heads));
            }
            prop_assert_eq!(b.transition(i).is_some(), i < ts.len());
            prop_assert!(b.end_seq() >= b.head.first_seq);
            let ok = b.check(usize::from(b.head.obs_dim), usize::from(b.head.heads), 3).is_ok();
            if ok {
                prop_assert_eq!(ts.len(), b.len());
                prop_assert_eq!(b.values.len(), b.len() * b.stride());
                prop_assert!(b.head.first_seq.checked_add(u64::from(b.head.len)).is_some());
            }
        }

        /// What `push` builds, the receiver reads back step for step.
        #[test]
        fn fuzz_transition_batch_round_trip(
            obs_dim in 0usize..=40,
            heads in 0usize..=20,
            n in 0usize..=TRANSITIONS_PER_BATCH,
            seed in any::<f32>(),
            action in 0u32..3,
        ) {
            let mut b = TransitionBatch::new(1, 2, obs_dim, heads, 5).unwrap();
            let mut sent = Vec::new();
            for k in 0..n {
                let t = Transition {
                    state: vec![seed + k as f32; obs_dim],
                    action,
                    reward: k as f32,
                    next_state: vec![seed - k as f32; obs_dim],
                    terminated: k % 2 == 0,
                    mask: vec![1.0; heads],
                    demo: k % 3 == 0,
                    horizon: (k % 7 + 1) as u8,
                };
                b.push(&t).unwrap();
                sent.push(t);
            }
            prop_assert!(b.check(obs_dim, heads, 3).is_ok());
            let got: Vec<Transition> = b.transitions().collect();
            prop_assert_eq!(got.len(), sent.len());
            for (g, s) in got.iter().zip(&sent) {
                prop_assert_eq!(&g.state, &s.state);
                prop_assert_eq!(&g.next_state, &s.next_state);
                prop_assert_eq!(&g.mask, &s.mask);
                prop_assert_eq!(g.action, s.action);
                prop_assert_eq!((g.terminated, g.demo), (s.terminated, s.demo));
                prop_assert_eq!(g.horizon, s.horizon);
            }
        }

        #[test]
        fn fuzz_query_request(
            obs_dim in prop_oneof![any::<u32>(), 0u32..=10],
            state in proptest::collection::vec(any::<f32>(), 0..10),
            expected in 0usize..=10,
        ) {
            let q = QueryRequest { obs_dim, state, ..QueryRequest::default() };
            prop_assert!(q.state().len() <= q.state.len());
            let back = QueryRequest::from_wire(&q.wire_header(), &q.state);
            prop_assert_eq!(back.state(), q.state());
            if let Ok(s) = q.checked_state(expected) {
                prop_assert_eq!(s.len(), expected);
                prop_assert!(s.iter().all(|x| x.is_finite()));
            }
        }

        #[test]
        fn fuzz_credits(
            received in any::<[u64; MAX_ACTORS]>(),
            incarnation in any::<[u64; MAX_ACTORS]>(),
            granted in any::<[u64; MAX_ACTORS]>(),
            env_steps in any::<u64>(),
            actor in any::<u16>(),
            inc in any::<u64>(),
            produced in any::<u64>(),
        ) {
            let c = Credits { env_steps, received, incarnation, granted, ..Credits::default() };
            let a = usize::from(actor);
            let mine = a < MAX_ACTORS && incarnation[a] == inc;
            prop_assert_eq!(c.granted_for(actor, inc), mine.then(|| granted[a]));
            let g = c.global_step_for(actor, inc, produced);
            prop_assert!(g >= env_steps);
            let own = produced.saturating_sub(if mine { received[a] } else { 0 });
            let expected = u128::from(env_steps) + u128::from(own);
            prop_assert_eq!(u128::from(g), expected.min(u128::from(u64::MAX)));
        }

        #[test]
        fn fuzz_names_and_headers(
            bytes in any::<[u8; NAME_LEN]>(),
            name in "\\PC{0,40}",
            role in any::<u16>(),
            id in any::<u16>(),
        ) {
            let s = name_from_bytes(&bytes);
            let no_nul = !s.contains('\0');
            prop_assert!(no_nul);
            let back = name_from_bytes(&name_to_bytes(&name));
            let prefix = name.starts_with(back.as_str());
            prop_assert!(prefix);
            let h = DemoModelHeader { expert_name: bytes, ..DemoModelHeader::default() };
            prop_assert_eq!(h.expert_name(), s);
            let header = Header { role, id, ..Header::default() };
            prop_assert!(!header.sender().is_empty());
            let p = Progress {
                header,
                kind: u32::from(role),
                state: u32::from(id),
                ..Progress::default()
            };
            prop_assert_eq!(p.header.sender(), header.sender());
        }
    }

    // Regression (fuzz): `transition(i)` indexed the records unchecked and panicked for
    // `i >= 32`; `end_seq` overflowed for `first_seq` near `u64::MAX`; `global_step_for`
    // overflowed for `env_steps` near `u64::MAX`.
    #[test]
    fn out_of_range_fields_do_not_panic() {
        let b = TransitionBatch {
            head: TransitionHeader {
                len: u32::MAX,
                first_seq: u64::MAX,
                obs_dim: u16::MAX,
                heads: u16::MAX,
                ..TransitionHeader::default()
            },
            values: Vec::new(),
        };
        assert_eq!(b.transition(TRANSITIONS_PER_BATCH), None);
        assert_eq!(b.transitions().count(), 0, "no values, no steps");
        assert_eq!(b.end_seq(), u64::MAX);
        let short = TransitionBatch::from_wire(&b.head, &[1.0; 10]);
        assert_eq!(short.transitions().count(), 0);
        assert!(short
            .check(usize::from(b.head.obs_dim), usize::from(b.head.heads), 2)
            .is_err());
        assert!(matches!(b.check(4, 2, 2), Err(WireError::TooLarge { .. })));
        let c = Credits {
            env_steps: u64::MAX,
            ..Credits::default()
        };
        assert_eq!(c.global_step_for(0, 0, 5), u64::MAX);
        let q = QueryRequest {
            obs_dim: u32::MAX,
            ..QueryRequest::default()
        };
        assert!(q.checked_state(4).is_err());
    }

    #[test]
    fn a_request_carries_the_query_its_asker_gave_up_on_and_a_report_asks_nothing() {
        let mut q = QueryRequest::new(3, 2, 40, &[0.5, -0.5]).unwrap();
        assert_eq!(q.gave_up(), None);
        q.gave_up = 17;
        let back = QueryRequest::from_wire(&q.wire_header(), &q.state);
        assert_eq!((back.gave_up(), back.is_report()), (Some(17), false));
        assert_eq!(
            (back.actor, back.global_step, back.state()),
            (3, 40, &[0.5, -0.5][..])
        );
        let r = QueryRequest::report(3, 2, 18);
        let back = QueryRequest::from_wire(&r.wire_header(), &[0.0]);
        assert_eq!((back.actor, back.incarnation), (3, 2));
        assert_eq!((back.gave_up(), back.is_report()), (Some(18), true));
        assert!(back.state().is_empty());
    }
}
