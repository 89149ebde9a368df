//! The one random number generator of the core, and how seeds are derived from one another.

use rand::SeedableRng;

/// The generator used everywhere in the core: ChaCha8, portable and reproducible across platforms.
pub type Rng = rand_chacha::ChaCha8Rng;

/// A generator seeded from `seed`.
pub fn seeded(seed: u64) -> Rng {
    Rng::seed_from_u64(seed)
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
}
