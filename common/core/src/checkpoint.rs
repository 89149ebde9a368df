//! The checkpoint format, as bytes (no I/O: writing and reading the file is the caller's): a
//! small header — magic, format version, the hash of the config the state belongs to, the
//! payload's length and its FNV-1a checksum — then the state as postcard bytes. Decoding refuses
//! a truncated, corrupt, other-version or other-config checkpoint with an error saying which.

use serde::de::DeserializeOwned;
use serde::Serialize;

/// The first bytes of every checkpoint.
pub const MAGIC: [u8; 8] = *b"ALFDCKPT";
/// The version of the format and of the state's layout; bumped whenever either changes.
pub const FORMAT_VERSION: u32 = 3;
/// Magic, version, config hash, payload length, checksum.
pub const HEADER_LEN: usize = 8 + 4 + 8 + 8 + 8;

/// Why a checkpoint was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CheckpointError {
    #[error("truncated checkpoint: {found} bytes where {expected} were expected")]
    Truncated { found: usize, expected: usize },
    #[error("not a checkpoint of alfd (bad magic bytes)")]
    NotACheckpoint,
    #[error("checkpoint of another format version ({found}; this alfd reads version {expected})")]
    OtherVersion { found: u32, expected: u32 },
    #[error(
        "checkpoint of another config (config hash {found:016x}, the run's config.toml hashes to \
         {expected:016x})"
    )]
    OtherConfig { found: u64, expected: u64 },
    #[error("corrupt checkpoint: checksum {found:016x} where the header says {expected:016x}")]
    Corrupt { found: u64, expected: u64 },
    #[error("corrupt checkpoint: the state does not decode: {0}")]
    Undecodable(String),
    #[error("checkpoint does not fit the run: {0}")]
    Mismatch(String),
}

/// A saved state that does not fit what it is restored into (other sizes, other kind of run).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct StateMismatch(pub String);

impl From<StateMismatch> for CheckpointError {
    fn from(e: StateMismatch) -> Self {
        Self::Mismatch(e.0)
    }
}

/// When the processes of a run checkpoint: at the first episode end once `every` environment
/// steps have passed since the last checkpoint. The learner applies it to every actor's episode
/// ends (flagged on their last transitions), an actor to its own, both with the run's global
/// step; with one actor in lockstep (window 1) both see the same episode ends at the same global
/// steps, so their checkpoints pair up, and a run resumed from such a pair is the uninterrupted
/// run to the byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cadence {
    every: u64,
    last: u64,
}

impl Cadence {
    /// Every `every` steps (0: never), the last checkpoint at global step `last` (0 at the start,
    /// the checkpoint's step when restored).
    pub fn new(every: u64, last: u64) -> Self {
        Self { every, last }
    }

    /// The steps between checkpoints for a learner that checkpoints every `updates` updates and
    /// makes `updates_per_step` per step (at least 1; 0 updates: never).
    pub fn steps_for_updates(updates: u64, updates_per_step: u32) -> u64 {
        match updates {
            0 => 0,
            u => (u / u64::from(updates_per_step.max(1))).max(1),
        }
    }

    /// An episode ended at global step `step` (the steps taken by then): whether to checkpoint
    /// now (and count from here).
    pub fn episode_end(&mut self, step: u64) -> bool {
        if self.every == 0 || step < self.last.saturating_add(self.every) {
            return false;
        }
        self.last = step;
        true
    }

    /// The global step of the last checkpoint.
    pub fn last(&self) -> u64 {
        self.last
    }
}

/// 64-bit FNV-1a.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The hash a checkpoint records of its config: FNV-1a of the config's TOML text as the run
/// directory holds it (`config.toml`).
pub fn config_hash(config_toml: &str) -> u64 {
    fnv1a64(config_toml.as_bytes())
}

/// The checkpoint bytes of `state`, belonging to the config of hash `config_hash`.
pub fn encode<T: Serialize>(state: &T, config_hash: u64) -> Vec<u8> {
    let payload = postcard::to_stdvec(state).expect("a state always serialises");
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&config_hash.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&fnv1a64(&payload).to_le_bytes());
    out.extend_from_slice(&payload);
    out
}

/// The state in checkpoint `bytes`, if they are whole, intact, of this format version and of the
/// config of hash `config_hash`.
pub fn decode<T: DeserializeOwned>(bytes: &[u8], config_hash: u64) -> Result<T, CheckpointError> {
    let truncated = |expected| CheckpointError::Truncated {
        found: bytes.len(),
        expected,
    };
    if bytes.len() < MAGIC.len() {
        return Err(truncated(HEADER_LEN));
    }
    if bytes[..8] != MAGIC {
        return Err(CheckpointError::NotACheckpoint);
    }
    if bytes.len() < HEADER_LEN {
        return Err(truncated(HEADER_LEN));
    }
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if version != FORMAT_VERSION {
        return Err(CheckpointError::OtherVersion {
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    let (hash, len, sum) = (u64_at(12), u64_at(20), u64_at(28));
    let expected = (HEADER_LEN as u64).saturating_add(len);
    if (bytes.len() as u64) < expected {
        return Err(truncated(usize::try_from(expected).unwrap_or(usize::MAX)));
    }
    let payload = &bytes[HEADER_LEN..];
    let found = fnv1a64(payload);
    if payload.len() as u64 != len || found != sum {
        return Err(CheckpointError::Corrupt {
            found,
            expected: sum,
        });
    }
    if hash != config_hash {
        return Err(CheckpointError::OtherConfig {
            found: hash,
            expected: config_hash,
        });
    }
    postcard::from_bytes(payload).map_err(|e| CheckpointError::Undecodable(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    type State = (Vec<f32>, u64, String);

    fn state() -> State {
        (vec![1.5, -2.0, 3.25], 42, "replay".to_owned())
    }

    #[test]
    fn the_cadence_waits_for_an_episode_end_past_every_steps() {
        // Every 100 steps: episodes ending at 40, 90, 130, 150, 229, 230, 400.
        let mut c = Cadence::new(100, 0);
        let due: Vec<bool> = [40, 90, 130, 150, 229, 230, 400]
            .iter()
            .map(|&s| c.episode_end(s))
            .collect();
        assert_eq!(due, [false, false, true, false, false, true, true]);
        assert_eq!(c.last(), 400);
        // Restored at 130: the same decisions from there on.
        let mut r = Cadence::new(100, 130);
        assert_eq!(
            [150, 229, 230, 400].map(|s| r.episode_end(s)),
            [false, false, true, true]
        );
        // 0: never.
        let mut never = Cadence::new(0, 0);
        assert!(!never.episode_end(u64::MAX));
        assert_eq!(Cadence::steps_for_updates(10_000, 2), 5_000);
        assert_eq!(Cadence::steps_for_updates(1, 4), 1);
        assert_eq!(Cadence::steps_for_updates(0, 1), 0);
        assert_eq!(Cadence::steps_for_updates(7, 0), 7);
    }

    #[test]
    fn a_checkpoint_round_trips() {
        let bytes = encode(&state(), 7);
        assert_eq!(&bytes[..8], b"ALFDCKPT");
        assert_eq!(decode::<State>(&bytes, 7).unwrap(), state());
    }

    #[test]
    fn a_truncated_checkpoint_is_refused_as_truncated() {
        let bytes = encode(&state(), 7);
        for cut in [4, 20, bytes.len() - 1] {
            let e = decode::<State>(&bytes[..cut], 7).unwrap_err();
            assert!(matches!(e, CheckpointError::Truncated { .. }), "{cut}: {e}");
            assert!(e.to_string().contains("truncated"), "{e}");
        }
    }

    #[test]
    fn a_flipped_byte_is_refused_as_corrupt() {
        let bytes = encode(&state(), 7);
        for at in [HEADER_LEN, bytes.len() - 1] {
            let mut bad = bytes.clone();
            bad[at] ^= 0x10;
            let e = decode::<State>(&bad, 7).unwrap_err();
            assert!(matches!(e, CheckpointError::Corrupt { .. }), "{e}");
            assert!(e.to_string().starts_with("corrupt checkpoint"), "{e}");
        }
        let mut bad = bytes.clone();
        bad[0] ^= 1;
        let e = decode::<State>(&bad, 7).unwrap_err();
        assert_eq!(e, CheckpointError::NotACheckpoint);
        assert!(e.to_string().contains("magic"));
    }

    #[test]
    fn another_version_is_refused_naming_both_versions() {
        let mut bytes = encode(&state(), 7);
        bytes[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
        let e = decode::<State>(&bytes, 7).unwrap_err();
        assert_eq!(
            e,
            CheckpointError::OtherVersion {
                found: FORMAT_VERSION + 1,
                expected: FORMAT_VERSION
            }
        );
        assert!(e.to_string().contains("another format version"), "{e}");
    }

    #[test]
    fn another_config_is_refused_as_such() {
        let bytes = encode(&state(), config_hash("seed = 1\n"));
        let e = decode::<State>(&bytes, config_hash("seed = 2\n")).unwrap_err();
        assert!(matches!(e, CheckpointError::OtherConfig { .. }), "{e}");
        assert!(e.to_string().contains("another config"), "{e}");
    }

    #[test]
    fn fnv1a_matches_its_reference_values() {
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
