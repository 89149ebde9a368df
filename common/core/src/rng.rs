//! The one random number generator of the core, and how seeds are derived from one another.

use rand::SeedableRng;

/// The generator used everywhere in the core: ChaCha8, portable and reproducible across platforms.
pub type Rng = rand_chacha::ChaCha8Rng;

/// A generator seeded from `seed`.
pub fn seeded(seed: u64) -> Rng {
    Rng::seed_from_u64(seed)
}

/// The exact position of a generator (its key, stream and word position), to save and restore it
/// in a checkpoint: the restored generator continues with the very next word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct RngState {
    pub seed: [u8; 32],
    pub stream: u64,
    pub word_pos: u128,
}

impl RngState {
    pub fn of(rng: &Rng) -> Self {
        Self {
            seed: rng.get_seed(),
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos(),
        }
    }

    /// The generator at this position.
    pub fn to_rng(&self) -> Rng {
        let mut rng = Rng::from_seed(self.seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(self.word_pos);
        rng
    }
}

/// Derives an independent seed for a named stream (`"env"`, `"agent"`, `"actor-1"`, ...) from a
/// run seed, so that adding a consumer of randomness does not shift the others.
pub fn derive_seed(seed: u64, stream: &str) -> u64 {
    // FNV-1a over the stream name, then SplitMix64 finalisation mixed with the seed.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in stream.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    let mut z = seed ^ h.rotate_left(17);
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derived_seeds_differ_by_stream_and_seed() {
        assert_ne!(derive_seed(1, "env"), derive_seed(1, "agent"));
        assert_ne!(derive_seed(1, "env"), derive_seed(2, "env"));
        assert_eq!(derive_seed(7, "actor-0"), derive_seed(7, "actor-0"));
    }

    #[test]
    fn a_restored_generator_continues_with_the_next_word() {
        use rand::Rng as _;
        let mut rng = seeded(3);
        let _: u32 = rng.random();
        let _: f64 = rng.random();
        let state = RngState::of(&rng);
        let mut copy = state.to_rng();
        let want: Vec<u32> = (0..100).map(|_| rng.random()).collect();
        let got: Vec<u32> = (0..100).map(|_| copy.random()).collect();
        assert_eq!(got, want);
    }
}
