//! What a bridge does with a remote peer's bytes before they touch the run, as one function
//! ([`take_in`]): every decoder (frames, join and restart requests and replies), the hub's
//! check of who may send a frame, and the wire's checks of a batch's sizes and a query's state.
//! It must never panic, whatever the bytes. The body of the libFuzzer target
//! (`common/bridge/fuzz`, `bash deploy/fuzz.sh`) and of the proptest pass of the test suite;
//! [`valid_frames`] are the fuzzer's seeds.

use alfd_wire::{
    Control, Header, Progress, QueryRequest, QueryResponse, Role, TransitionBatch, SCHEMA_VERSION,
};

use crate::frame::{decode, encode, ExpertOrder, Frame};
use crate::roster::{JoinReply, JoinRequest, RestartReply, RestartRequest};

/// Valid frames of every kind a remote peer sends or receives.
pub fn valid_frames() -> Vec<Vec<u8>> {
    let mut batch = TransitionBatch::new(1, 7, 4, 2, 100).unwrap();
    for k in 0..3 {
        let step = alfd_common::replay::Transition {
            state: vec![k as f32; 4],
            action: 1,
            reward: 1.0,
            next_state: vec![k as f32 + 0.5; 4],
            terminated: false,
            mask: vec![1.0, 0.0],
            demo: k == 0,
            horizon: 1,
        };
        batch.push(&step).unwrap();
    }
    // As the wire's port stamps it when an actor sends the batch.
    batch.head.header.schema = SCHEMA_VERSION;
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
        Frame::ExpertAnswer(QueryResponse::default()),
        Frame::ExpertDemos {
            generation: 2,
            first: 0,
            lines: vec!["{}".to_owned()],
        },
        Frame::DemosLost {
            generation: 2,
            lines: 1,
        },
        Frame::Order(ExpertOrder::Start {
            join_id: "h-1".to_owned(),
            generation: 3,
            name: "cartpole-1000".to_owned(),
        }),
        Frame::Order(ExpertOrder::Resend {
            generation: 3,
            from: 7,
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
pub fn take_in(bytes: &[u8]) {
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
