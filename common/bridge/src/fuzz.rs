//! A bounded fuzz pass (proptest) over what a remote peer hands a bridge (`peer_bytes.rs`, also
//! the body of the libFuzzer target in `common/bridge/fuzz`): frames, join and
//! restart requests and replies, as arbitrary bytes and as valid frames with bytes overwritten,
//! cut or added. Decoding must never panic, and a decoded frame must go through the hub's checks
//! (`refusal`) and the wire's (`TransitionBatch::check`, `QueryRequest::checked_state`) without
//! panicking, whatever its sizes and ids say.

use alfd_wire::SCHEMA_VERSION;
use proptest::prelude::*;

use crate::frame::{decode, Frame};
use crate::peer_bytes::{take_in, valid_frames};

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
