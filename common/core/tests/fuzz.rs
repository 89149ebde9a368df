//! A bounded fuzz pass (proptest) over every input of the core a user or another process hands
//! us: experiment configs and `--set` overrides, CliffWalk maps, network weights and checkpoints.
//! Each decoder must never panic, refuse a bad input with an error, and round-trip a good one.
//! The case counts keep the whole pass well under a minute in the release test profile.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::OnceLock;

use alfd_common::agent::BalancingController;

use alfd_common::checkpoint::{self, CheckpointError, HEADER_LEN};
use alfd_common::config::ExperimentConfig;
use alfd_common::env::cliffwalk::CliffMap;
use alfd_common::nn::Mlp;
use alfd_common::runner::{run_neural_checkpointed, Checkpoints, RunState};
use proptest::prelude::*;

/// The shipped configs, read from the repository at test time.
fn shipped_configs() -> Vec<(PathBuf, String)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../deploy/configs");
    let mut out = Vec::new();
    for dir in [root.clone(), root.join("recommended")] {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        paths.sort();
        for p in paths {
            let text = std::fs::read_to_string(&p).unwrap();
            out.push((p, text));
        }
    }
    assert!(out.len() >= 10, "the shipped configs are found");
    out
}

/// One edit of a text: delete a span, insert a snippet, or replace a span by a snippet.
#[derive(Debug, Clone)]
enum Edit {
    Delete(usize, usize),
    Insert(usize, String),
    Replace(usize, usize, String),
}

fn edits(snippet: BoxedStrategy<String>) -> impl Strategy<Value = Vec<Edit>> {
    let edit = prop_oneof![
        (any::<usize>(), 1usize..12).prop_map(|(at, n)| Edit::Delete(at, n)),
        (any::<usize>(), snippet.clone()).prop_map(|(at, s)| Edit::Insert(at, s)),
        (any::<usize>(), 1usize..8, snippet).prop_map(|(at, n, s)| Edit::Replace(at, n, s)),
    ];
    proptest::collection::vec(edit, 1..4)
}

/// `text` with `edits` applied, on character boundaries.
fn mutate(text: &str, edits: &[Edit]) -> String {
    let mut chars: Vec<char> = text.chars().collect();
    for e in edits {
        let len = chars.len();
        let at = |i: usize| if len == 0 { 0 } else { i % (len + 1) };
        match e {
            Edit::Delete(i, n) => {
                let a = at(*i);
                chars.drain(a..(a + n).min(len));
            }
            Edit::Insert(i, s) => {
                let a = at(*i);
                chars.splice(a..a, s.chars());
            }
            Edit::Replace(i, n, s) => {
                let a = at(*i);
                chars.splice(a..(a + n).min(len), s.chars());
            }
        }
    }
    chars.into_iter().collect()
}

/// Snippets that tend to make TOML that parses but holds odd values.
fn toml_snippet() -> BoxedStrategy<String> {
    prop_oneof![
        "[ -~\n]{0,12}",
        Just("0".to_owned()),
        Just("-1".to_owned()),
        Just("nan".to_owned()),
        Just("inf".to_owned()),
        Just("-inf".to_owned()),
        Just("1e308".to_owned()),
        Just("4294967296".to_owned()),
        Just("9223372036854775807".to_owned()),
        Just("\n[agent]\n".to_owned()),
        Just("\"\"".to_owned()),
        Just("true".to_owned()),
        Just("[1, 2]".to_owned()),
    ]
    .boxed()
}

const KEYS: &[&str] = &[
    "seed",
    "episodes",
    "steps",
    "env.name",
    "env.p_success",
    "env.max_episode_steps",
    "env.map",
    "agent.kind",
    "agent.heads",
    "agent.gamma",
    "agent.temperature",
    "agent.learning_rate",
    "agent.epsilon_start",
    "agent.epsilon_end",
    "agent.epsilon_decay_steps",
    "agent.bootstrap_probability",
    "agent.replay_capacity",
    "agent.batch_size",
    "agent.hidden",
    "agent.updates_per_step",
    "agent.target_update_every",
    "agent.tau",
    "agent.max_grad_norm",
    "agent.demo_fraction",
    "agent.learning_rate_end",
    "agent.margin",
    "query.queue_len",
    "query.percentile",
    "budget.total",
    "shaping.lambda",
    "shaping.stop_multiple",
    "expert.name",
    "expert.model",
    "evaluation.every",
    "evaluation.episodes",
];

fn override_item() -> impl Strategy<Value = String> {
    let key = prop_oneof![
        proptest::sample::select(KEYS).prop_map(str::to_owned),
        "[a-z._]{0,12}",
    ];
    let value = prop_oneof![toml_snippet(), any::<i64>().prop_map(|v| v.to_string()),];
    prop_oneof![
        (key, value).prop_map(|(k, v)| format!("{k}={v}")),
        "[ -~]{0,16}",
    ]
}

/// A config that parses must validate and come back equal from its own TOML.
fn check_config(text: &str, overrides: &[String]) -> Result<(), TestCaseError> {
    if let Ok(cfg) = ExperimentConfig::from_toml_with_overrides(text, overrides) {
        prop_assert!(cfg.validate().is_ok());
        let back = ExperimentConfig::from_toml(&cfg.to_toml());
        prop_assert_eq!(back.as_ref().ok(), Some(&cfg), "{:?}", back);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn fuzz_config_arbitrary_text(text in "[ -~\n]{0,200}") {
        check_config(&text, &[])?;
    }

    #[test]
    fn fuzz_config_mutated_shipped(
        which in any::<prop::sample::Index>(),
        edits in edits(toml_snippet()),
    ) {
        let configs = shipped_configs();
        let (_, text) = &configs[which.index(configs.len())];
        check_config(&mutate(text, &edits), &[])?;
    }

    #[test]
    fn fuzz_config_overrides(
        which in any::<prop::sample::Index>(),
        overrides in proptest::collection::vec(override_item(), 1..4),
    ) {
        let configs = shipped_configs();
        let (_, text) = &configs[which.index(configs.len())];
        check_config(text, &overrides)?;
    }

    #[test]
    fn fuzz_cliff_map(
        text in "[SGX.\n \tA]{0,80}",
        edits in edits("[SGX.\n ]{0,6}".boxed()),
        arbitrary in any::<bool>(),
    ) {
        let text = if arbitrary {
            text
        } else {
            mutate(&CliffMap::default_map().to_string(), &edits)
        };
        if let Ok(map) = CliffMap::parse(&text) {
            let back = CliffMap::parse(&map.to_string());
            prop_assert_eq!(back.as_ref(), Ok(&map));
            prop_assert_eq!(map.num_states(), map.width() * map.height());
            prop_assert!(map.start() < map.num_states() && map.goal() < map.num_states());
        }
    }
}

fn weights() -> Vec<u8> {
    Mlp::new(4, 8, 2, 3, &mut alfd_common::rng::seeded(5)).to_safetensors_bytes()
}

/// Byte-level damage to a valid file: flips, truncation, arbitrary bytes spliced in.
#[derive(Debug, Clone)]
enum Damage {
    Flip(usize, u8),
    Truncate(usize),
    Splice(usize, Vec<u8>),
}

fn damage() -> impl Strategy<Value = Vec<Damage>> {
    let d = prop_oneof![
        (any::<usize>(), 1u8..=255).prop_map(|(at, x)| Damage::Flip(at, x)),
        any::<usize>().prop_map(Damage::Truncate),
        (
            any::<usize>(),
            proptest::collection::vec(any::<u8>(), 0..16)
        )
            .prop_map(|(at, b)| Damage::Splice(at, b)),
    ];
    proptest::collection::vec(d, 1..4)
}

/// `bytes` damaged; positions below `focus` are hit twice as often (the header).
fn apply(bytes: &[u8], damage: &[Damage], focus: usize) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for d in damage {
        let pos = |i: usize, len: usize| {
            if len == 0 {
                0
            } else if i.is_multiple_of(2) {
                (i / 2) % focus.clamp(1, len)
            } else {
                (i / 2) % len
            }
        };
        match d {
            Damage::Flip(i, x) => {
                if !out.is_empty() {
                    let p = pos(*i, out.len());
                    out[p] ^= x;
                }
            }
            Damage::Truncate(i) => {
                let p = pos(*i, out.len() + 1);
                out.truncate(p);
            }
            Damage::Splice(i, b) => {
                let p = pos(*i, out.len() + 1).min(out.len());
                out.splice(p..p, b.iter().copied());
            }
        }
    }
    out
}

/// A valid safetensors file whose JSON header is rewritten by `edit` (lengths fixed up).
fn with_header(bytes: &[u8], edit: impl FnOnce(String) -> String) -> Vec<u8> {
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let json = String::from_utf8(bytes[8..8 + n].to_vec()).unwrap();
    let mut json = edit(json.trim_end().to_owned()).into_bytes();
    json.resize(json.len().next_multiple_of(8), b' ');
    let mut out = (json.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&json);
    out.extend_from_slice(&bytes[8 + n..]);
    out
}

/// The checkpoint bytes of a short CartPole run, made once.
fn good_checkpoint() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| {
        let text = std::fs::read_to_string(
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../deploy/configs/cartpole-bdqn.toml"),
        )
        .unwrap();
        let overrides = [
            "episodes=2",
            "agent.replay_capacity=200",
            "agent.batch_size=16",
        ]
        .map(str::to_owned);
        let cfg = ExperimentConfig::from_toml_with_overrides(&text, &overrides).unwrap();
        let mut saved = None;
        run_neural_checkpointed(
            &cfg,
            &mut BalancingController,
            Checkpoints {
                from: None,
                every: Some(1),
            },
            |s| {
                saved = Some(s.clone());
                ControlFlow::Break(())
            },
            |_, _| ControlFlow::Continue(()),
        )
        .unwrap();
        checkpoint::encode(&RunState::Neural(Box::new(saved.unwrap())), 7)
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn fuzz_weights_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
        let _ = Mlp::from_safetensors_bytes(&bytes);
        // A header length that claims anything, followed by a little JSON.
        let mut b = (bytes.len() as u64).to_le_bytes().to_vec();
        b.extend_from_slice(&bytes);
        let _ = Mlp::from_safetensors_bytes(&b);
    }

    #[test]
    fn fuzz_weights_damaged(damage in damage()) {
        let good = weights();
        let n = 8 + u64::from_le_bytes(good[..8].try_into().unwrap()) as usize;
        let bad = apply(&good, &damage, n);
        match Mlp::from_safetensors_bytes(&bad) {
            Ok(net) => prop_assert_eq!(net.to_safetensors_bytes().len(), good.len()),
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }

    #[test]
    fn fuzz_weights_metadata(
        heads in prop_oneof![Just("0".to_owned()), "[0-9]{1,20}", "[ -~]{0,6}"],
        actions in prop_oneof![Just("0".to_owned()), "[0-9]{1,20}", "[ -~]{0,6}"],
    ) {
        let good = weights();
        let bad = with_header(&good, |j| {
            j.replace("\"heads\":\"2\"", &format!("\"heads\":{}", serde_json::json!(heads)))
                .replace("\"actions\":\"3\"", &format!("\"actions\":{}", serde_json::json!(actions)))
        });
        let ok = heads == "2" && actions == "3";
        prop_assert_eq!(Mlp::from_safetensors_bytes(&bad).is_ok(), ok);
    }
}

/// Regression (fuzz): metadata `heads` × `actions` overflowing `usize` panicked with overflow
/// checks on (and wrapped without); it is refused naming the metadata.
#[test]
fn weights_whose_heads_times_actions_overflow_are_refused() {
    let bad = with_header(&weights(), |j| {
        j.replace("\"heads\":\"2\"", "\"heads\":\"9223372036854775808\"")
            .replace("\"actions\":\"3\"", "\"actions\":\"4\"")
    });
    let e = Mlp::from_safetensors_bytes(&bad).unwrap_err().to_string();
    // The overflow itself is named (a wrapped product would fail later, on a tensor's shape).
    assert!(
        e.contains("heads 9223372036854775808 times actions 4 does not fit"),
        "{e}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn fuzz_checkpoint(
        damage in damage(),
        arbitrary in proptest::collection::vec(any::<u8>(), 0..128),
    ) {
        let good = good_checkpoint();
        // Bytes, not `==`: records hold NaN (no evaluation) and NaN != NaN.
        let back = checkpoint::decode::<RunState>(good, 7).unwrap();
        prop_assert!(checkpoint::encode(&back, 7) == good);
        let bad = apply(good, &damage, HEADER_LEN);
        match checkpoint::decode::<RunState>(&bad, 7) {
            Ok(s) => prop_assert!(bad == good && checkpoint::encode(&s, 7) == good),
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
        // Arbitrary bytes, alone and as an intact checkpoint's payload (what postcard decodes).
        prop_assert!(checkpoint::decode::<RunState>(&arbitrary, 7).is_err());
        let wrapped = checkpoint::encode(&serde_bytes_like(&arbitrary), 7);
        let r = checkpoint::decode::<RunState>(&wrapped, 7);
        let refused_or_decoded = matches!(r, Err(CheckpointError::Undecodable(_))) || r.is_ok();
        prop_assert!(refused_or_decoded);
    }
}

/// Postcard of a tuple of raw bytes is the bytes themselves: a checkpoint whose payload is
/// `bytes`, checksummed right.
fn serde_bytes_like(bytes: &[u8]) -> RawPayload {
    RawPayload(bytes.to_vec())
}

struct RawPayload(Vec<u8>);

impl serde::Serialize for RawPayload {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(self.0.len())?;
        for b in &self.0 {
            t.serialize_element(b)?;
        }
        t.end()
    }
}
