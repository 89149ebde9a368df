//! A bounded fuzz pass (proptest) over what a remote peer hands a bridge: frames, join and
//! restart requests and replies, as arbitrary bytes and as valid frames with bytes overwritten,
//! cut or added. Decoding must never panic, and a decoded frame must go through the hub's checks
//! (`refusal`) and the wire's (`TransitionBatch::check`, `QueryRequest::checked_state`) without
//! panicking, whatever its sizes and ids say.

use alfd_wire::{
    Control, Header, Progress, QueryRequest, QueryResponse, Role, TransitionBatch, SCHEMA_VERSION,
};
use proptest::prelude::*;

use crate::frame::{decode, encode, ExpertOrder, Frame};
use crate::roster::{JoinReply, JoinRequest, RestartReply, RestartRequest};

/// Valid frames of every kind a remote peer sends or receives.
fn valid_frames() -> Vec<Vec<u8>> {
    let mut batch = TransitionBatch::new(1, 7, 4, 2, 100).unwrap();
    batch.len = 3;
    // As the wire's port stamps it when an actor sends the batch.
    batch.header.schema = SCHEMA_VERSION;
    let query = QueryRequest::new(1, 7, 55, &[0.1, -0.2, 0.3, 0.4]).unwrap();
    let progress = Progress {
        header: Header {
            schema: SCHEMA_VERSION,
            role: Role::Actor as u16,
            id: 1,
            seq: 9,
        },
        ..Progress::default()
    };
    let frames = [
        Frame::Transitions(batch),
        Frame::Query(query),
        Frame::Progress(progress),
        Frame::Control(Control::default()),
        Frame::Answer(QueryResponse::default()),
        Frame::Weights(Default::default(), vec![0.5; 16]),
        Frame::DemoLog {
            generation: 2,
            text: "{\"index\":0}\n".to_owned(),
        },
        Frame::ExpertAnswer(QueryResponse::default(), Some("{}".to_owned())),
        Frame::Order(ExpertOrder::Start {
            join_id: "h-1".to_owned(),
            generation: 3,
            name: "cartpole-1000".to_owned(),
        }),
    ];
    let mut out: Vec<Vec<u8>> = frames
        .iter()
        .map(|f| encode(SCHEMA_VERSION, f).unwrap())
        .collect();
    let join = JoinRequest {
        join_id: "h-1".to_owned(),
        host: "h".to_owned(),
        actors: 2,
        expert: None,
    };
    out.push(encode(SCHEMA_VERSION, &join).unwrap());
    let restart = RestartRequest {
        join_id: "h-1".to_owned(),
        actor: 1,
    };
    out.push(encode(SCHEMA_VERSION, &restart).unwrap());
    out.push(encode(SCHEMA_VERSION, &JoinReply::Refused("no".to_owned())).unwrap());
    out
}

/// Everything a bridge does with bytes from a peer before they touch the run.
fn take_in(bytes: &[u8]) {
    if let Ok(f) = decode::<Frame>(SCHEMA_VERSION, bytes) {
        let _ = f.service();
        let _ = crate::hub::refusal(&f, "a", |id| id < 4);
        match &f {
            Frame::Transitions(b) => {
                let _ = b.check(4, 2, 2);
                let _ = b.transitions().count();
            }
            Frame::Query(q) => {
                let _ = q.checked_state(4);
            }
            _ => {}
        }
    }
    let _ = decode::<JoinRequest>(SCHEMA_VERSION, bytes);
    let _ = decode::<JoinReply>(SCHEMA_VERSION, bytes);
    let _ = decode::<RestartRequest>(SCHEMA_VERSION, bytes);
    let _ = decode::<RestartReply>(SCHEMA_VERSION, bytes);
    let mut refused = 0;
    let before = refused;
    if crate::link::take_in(bytes, &mut refused, "a fuzzer").is_none() {
        assert_eq!(refused, before + 1, "a frame not taken is counted");
    }
}

/// A valid frame with one edit: bytes overwritten, the end cut, or bytes added.
#[derive(Debug, Clone)]
enum Edit {
    Overwrite(usize, Vec<u8>),
    Cut(usize),
    Append(Vec<u8>),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..6))
            .prop_map(|(at, b)| Edit::Overwrite(at, b)),
        any::<usize>().prop_map(Edit::Cut),
        prop::collection::vec(any::<u8>(), 1..32).prop_map(Edit::Append),
    ]
}

fn apply(mut bytes: Vec<u8>, e: &Edit) -> Vec<u8> {
    match e {
        // Never the magic and schema version: those are refused first, the rest is the point.
        Edit::Overwrite(at, b) => {
            for (k, v) in b.iter().enumerate() {
                let i = 8 + (at + k) % (bytes.len() - 8).max(1);
                if i < bytes.len() {
                    bytes[i] = *v;
                }
            }
        }
        Edit::Cut(at) => bytes.truncate(8 + at % (bytes.len() - 7)),
        Edit::Append(b) => bytes.extend_from_slice(b),
    }
    bytes
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn arbitrary_bytes_from_a_peer_never_panic_a_bridge(
        body in prop::collection::vec(any::<u8>(), 0..512),
        framed in any::<bool>(),
    ) {
        let mut bytes = Vec::new();
        if framed {
            bytes.extend_from_slice(b"alfz");
            bytes.extend_from_slice(&SCHEMA_VERSION.to_le_bytes());
        }
        bytes.extend_from_slice(&body);
        take_in(&bytes);
    }

    #[test]
    fn valid_frames_with_bytes_changed_never_panic_a_bridge(
        which in any::<usize>(),
        edits in prop::collection::vec(edit(), 1..4),
    ) {
        let frames = valid_frames();
        let mut bytes = frames[which % frames.len()].clone();
        for e in &edits {
            bytes = apply(bytes, e);
        }
        take_in(&bytes);
    }
}

#[test]
fn the_valid_frames_are_taken_in_whole() {
    for bytes in valid_frames() {
        take_in(&bytes);
    }
    let f = decode::<Frame>(SCHEMA_VERSION, &valid_frames()[0]).unwrap();
    // Actor 1 is held by a remote host here; actor 9 is not.
    assert_eq!(crate::hub::refusal(&f, "a", |id| id == 1), None);
    assert!(crate::hub::refusal(&f, "a", |id| id == 9).is_some());
}
