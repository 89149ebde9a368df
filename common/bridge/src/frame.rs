//! What travels over zenoh: one [`Frame`] per message of the run's services, as bytes that start
//! with a magic number and the sender's schema version, so that a bridge of another build is
//! refused by name before anything else of the frame is read.

use alfd_wire::{
    Control, Credits, DemoModelHeader, Progress, QueryRequest, QueryResponse, TransitionBatch,
    WeightsHeader,
};
use serde::{Deserialize, Serialize};

use crate::error::{BridgeError, Result};

/// The first bytes of every frame.
const MAGIC: [u8; 4] = *b"alfz";

/// One message between the learner's host (the hub) and a remote host (a mirror). The wire's
/// messages travel whole, headers included: sender, sequence number, schema version.
// A frame lives only between its arrival and its encoding or forwarding, one at a time: its
// size does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Frame {
    // --- up: a remote host → the learner's host -----------------------------------------------
    Transitions(TransitionBatch),
    Progress(Progress),
    /// A remote actor's query; `header.seq` is the actor's own request number.
    Query(QueryRequest),
    // --- down: the learner's host → every remote host -----------------------------------------
    Credits(Credits),
    Weights(WeightsHeader, Vec<f32>),
    DemoModel(DemoModelHeader, Vec<u8>),
    Control(Control),
    /// The expert's answer to [`Frame::Query`] (`request_seq` and `actor` as the actor asked).
    Answer(QueryResponse),
    // --- an expert on a remote host (`alfd join --expert`) -------------------------------------
    /// Down: the hub's orders to the joined hosts' experts.
    Order(ExpertOrder),
    /// Down: `RUN_DIR/demos.jsonl` as it is when `generation` is made active, sent before the
    /// control message that makes it active, so that it reads the run's demonstrations back.
    DemoLog {
        generation: u16,
        text: String,
    },
    /// Up: a remote expert's answer (`request_seq` and `actor` as the hub asked); a
    /// demonstration's line goes up before it in [`Frame::ExpertDemos`].
    ExpertAnswer(QueryResponse),
    /// Up: lines the remote expert of `generation` appended to its host's `demos.jsonl`, the
    /// first of them line `first`, every one in order whether or not its answer is still awaited.
    ExpertDemos {
        generation: u16,
        first: u32,
        lines: Vec<String>,
    },
    /// Up: when `generation` became active, its host's `demos.jsonl` held `lines` demonstrations
    /// the run's did not (its host died before they went up); the run's file replaced them.
    DemosLost {
        generation: u16,
        lines: u32,
    },
    /// Up: the remote expert of `generation` ended (after every answer it sent).
    ExpertExited {
        generation: u16,
        how: String,
        code: Option<i32>,
    },
}

/// What the learner's host tells a joined host about its expert.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum ExpertOrder {
    /// Start `alfd-expert` as `generation` with demonstrator `name` (the host `join_id`).
    Start {
        join_id: String,
        generation: u16,
        name: String,
    },
    /// Kill the expert of `generation` (it did not come up or leave in time).
    Kill { generation: u16 },
    /// The run does not take the expert of `join_id` now: `why`.
    Refuse { join_id: String, why: String },
    /// Send the demonstrations of `generation` again from line `from`: the run's file stops
    /// there (a line it could not take).
    Resend { generation: u16, from: u32 },
}

impl Frame {
    /// The service the frame belongs to (for messages).
    pub fn service(&self) -> &'static str {
        match self {
            Frame::Transitions(_) => "transitions",
            Frame::Progress(_) => "progress",
            Frame::Query(_) | Frame::Answer(_) => "query",
            Frame::Credits(_) => "credits",
            Frame::Weights(..) => "weights",
            Frame::DemoModel(..) => "demo-model",
            Frame::Control(_) => "control",
            Frame::Order(_) | Frame::ExpertExited { .. } => "expert-order",
            Frame::DemoLog { .. } | Frame::ExpertDemos { .. } | Frame::DemosLost { .. } => "demos",
            Frame::ExpertAnswer(..) => "query",
        }
    }
}

/// `value` as a frame's bytes: magic, schema version (little endian), postcard payload.
pub fn encode<T: Serialize>(schema: u32, value: &T) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(64);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&schema.to_le_bytes());
    postcard::to_extend(value, out).map_err(|e| BridgeError::Malformed(e.to_string()))
}

/// The schema version a frame was written with (checked before the rest is read).
pub fn schema_of(bytes: &[u8]) -> Result<u32> {
    if bytes.len() < 8 || bytes[..4] != MAGIC {
        return Err(BridgeError::Malformed(format!(
            "{} bytes that are not an alfd frame",
            bytes.len()
        )));
    }
    let mut v = [0u8; 4];
    v.copy_from_slice(&bytes[4..8]);
    Ok(u32::from_le_bytes(v))
}

/// Reads a frame written by [`encode`], refusing another schema version than `ours`.
pub fn decode<T: for<'de> Deserialize<'de>>(ours: u32, bytes: &[u8]) -> Result<T> {
    let theirs = schema_of(bytes)?;
    if theirs != ours {
        return Err(BridgeError::SchemaMismatch { ours, theirs });
    }
    postcard::from_bytes(&bytes[8..]).map_err(|e| BridgeError::Malformed(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_wire::{Header, SCHEMA_VERSION};

    #[test]
    fn a_frame_comes_back_whole_with_its_header() {
        let mut c = Credits {
            header: Header {
                schema: SCHEMA_VERSION,
                role: 2,
                id: 0,
                seq: 41,
            },
            env_steps: 7,
            ..Credits::default()
        };
        c.granted[3] = 99;
        let frames = [
            Frame::Credits(c),
            Frame::Weights(WeightsHeader::default(), vec![1.0, -2.5]),
            Frame::DemoModel(DemoModelHeader::default(), vec![]),
        ];
        for f in frames {
            let bytes = encode(SCHEMA_VERSION, &f).unwrap();
            assert_eq!(schema_of(&bytes).unwrap(), SCHEMA_VERSION);
            assert_eq!(decode::<Frame>(SCHEMA_VERSION, &bytes).unwrap(), f);
        }
    }

    #[test]
    fn another_schema_version_is_refused_by_name_and_garbage_is_malformed() {
        let bytes = encode(SCHEMA_VERSION + 1, &Frame::Control(Control::default())).unwrap();
        let e = decode::<Frame>(SCHEMA_VERSION, &bytes).unwrap_err();
        assert_eq!(
            e,
            BridgeError::SchemaMismatch {
                ours: SCHEMA_VERSION,
                theirs: SCHEMA_VERSION + 1
            }
        );
        assert!(e.to_string().contains(&format!("{}", SCHEMA_VERSION + 1)));
        assert!(matches!(
            decode::<Frame>(SCHEMA_VERSION, b"alfd"),
            Err(BridgeError::Malformed(_))
        ));
        let mut cut = encode(SCHEMA_VERSION, &Frame::Control(Control::default())).unwrap();
        cut.truncate(10);
        assert!(matches!(
            decode::<Frame>(SCHEMA_VERSION, &cut),
            Err(BridgeError::Malformed(_))
        ));
    }
}
