//! numpy's legacy `np.random.RandomState(seed)`, as far as DeepSea's action mapping needs it:
//! MT19937 seeded from one integer, its 53-bit doubles (`random_sample`) and the legacy binomial
//! by inversion, each draw the same as numpy's.
//!
//! # What numpy does (numpy/random: `_mt19937.pyx`, `mt19937.c`, `legacy-distributions.c`,
//! `distributions.c`)
//! - `RandomState(seed)` with an integer seed in `0..2^32` fills the 624-word key with Knuth's
//!   recurrence of the reference MT19937 (`init_genrand`: `key[0] = seed`,
//!   `key[i] = 1812433253 · (key[i-1] ^ (key[i-1] >> 30)) + i`, modulo 2^32) and sets the read
//!   position to 624, so the first draw regenerates the whole key.
//! - A double is `genrand_res53`: two outputs `a >> 5` (27 bits) and `b >> 6` (26 bits) make
//!   `(a · 2^26 + b) / 2^53`, in `[0, 1)`.
//! - `binomial(n, p)` draws by inversion when `n · min(p, 1 - p) ≤ 30` (for `p > 0.5` it draws
//!   `n - X` with `X ~ binomial(n, 1 - p)`), else by BTPE, which is not ported here. Inversion
//!   starts at `X = 0` with `P(X = 0) = exp(n · ln q)` and one uniform `U`; while `U` exceeds the
//!   current probability it subtracts it and moves to the next `X`, the probability following
//!   `P(X) = P(X-1) · (n - X + 1) p / (X q)`; past `min(n, np + 10 √(npq + 1))` it starts again
//!   with a new `U`. So `binomial(1, 0.5)` takes one double and gives `1` exactly when it
//!   exceeds `0.5`.
//!
//! The logarithm and exponential come from [`crate::math`] (musl's), numpy's from the platform's
//! libm; for `binomial(1, p)` both give `q` exactly, for other `n` they can differ in the last bit,
//! which changes a draw only when `U` falls within that bit of a cumulative probability.

use crate::math::{exp, ln};

/// The words of MT19937's key.
pub const STATE_LEN: usize = 624;
/// The recurrence of the key's regeneration reaches this many words ahead.
const SHIFT: usize = 397;
const MATRIX_A: u32 = 0x9908_b0df;
const UPPER_MASK: u32 = 0x8000_0000;
const LOWER_MASK: u32 = 0x7fff_ffff;

/// The Mersenne Twister MT19937 with numpy's legacy integer seeding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mt19937 {
    key: [u32; STATE_LEN],
    pos: usize,
}

impl Mt19937 {
    /// The generator of `np.random.RandomState(seed)` (the reference `init_genrand`).
    pub fn new(seed: u32) -> Self {
        let mut key = [0u32; STATE_LEN];
        key[0] = seed;
        for i in 1..STATE_LEN {
            let prev = key[i - 1];
            key[i] = 1_812_433_253u32
                .wrapping_mul(prev ^ (prev >> 30))
                .wrapping_add(i as u32);
        }
        Self {
            key,
            pos: STATE_LEN,
        }
    }

    /// The key (numpy's `get_state()[1]`).
    pub fn key(&self) -> &[u32; STATE_LEN] {
        &self.key
    }

    /// The index of the next key word to read (numpy's `get_state()[2]`).
    pub fn pos(&self) -> usize {
        self.pos
    }

    /// The next 32-bit output (numpy's `random_raw` of this bit generator).
    pub fn next_u32(&mut self) -> u32 {
        if self.pos == STATE_LEN {
            self.regenerate();
        }
        let mut y = self.key[self.pos];
        self.pos += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^ (y >> 18)
    }

    /// The next double in `[0, 1)` from two outputs (`genrand_res53`).
    pub fn next_f64(&mut self) -> f64 {
        let a = self.next_u32() >> 5;
        let b = self.next_u32() >> 6;
        (f64::from(a) * 67_108_864.0 + f64::from(b)) / 9_007_199_254_740_992.0
    }

    /// The next 624 words of the key, all at once, as the reference implementation does.
    fn regenerate(&mut self) {
        for i in 0..STATE_LEN {
            let y = (self.key[i] & UPPER_MASK) | (self.key[(i + 1) % STATE_LEN] & LOWER_MASK);
            let twist = if y & 1 == 1 { MATRIX_A } else { 0 };
            self.key[i] = self.key[(i + SHIFT) % STATE_LEN] ^ (y >> 1) ^ twist;
        }
        self.pos = 0;
    }
}

/// A binomial draw numpy's legacy generator makes by an algorithm not ported here, or with
/// parameters numpy refuses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BinomialError {
    #[error("binomial p must be in [0, 1], got {0}")]
    Probability(f64),
    #[error(
        "binomial({n}, {p}) is drawn by numpy's BTPE algorithm (n·min(p, 1 - p) > 30), which is \
         not ported; only inversion is"
    )]
    NeedsBtpe { n: u32, p: f64 },
}

/// numpy's legacy `RandomState`: the draws DeepSea needs, each the same as numpy's.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RandomState {
    mt: Mt19937,
}

impl RandomState {
    /// `np.random.RandomState(seed)`.
    pub fn new(seed: u32) -> Self {
        Self {
            mt: Mt19937::new(seed),
        }
    }

    /// The bit generator.
    pub fn mt19937(&self) -> &Mt19937 {
        &self.mt
    }

    /// `random_sample()`: one double in `[0, 1)`.
    pub fn random_sample(&mut self) -> f64 {
        self.mt.next_f64()
    }

    /// `binomial(n, p)` of the legacy generator, for `n · min(p, 1 - p) ≤ 30` (inversion).
    pub fn binomial(&mut self, n: u32, p: f64) -> Result<u32, BinomialError> {
        // Written so that NaN is refused too.
        if !(0.0..=1.0).contains(&p) {
            return Err(BinomialError::Probability(p));
        }
        let n_f = f64::from(n);
        if p <= 0.5 {
            if p * n_f > 30.0 {
                return Err(BinomialError::NeedsBtpe { n, p });
            }
            Ok(self.binomial_inversion(n, p))
        } else {
            let q = 1.0 - p;
            if q * n_f > 30.0 {
                return Err(BinomialError::NeedsBtpe { n, p });
            }
            Ok(n - self.binomial_inversion(n, q))
        }
    }

    /// Inversion for `p ≤ 0.5`: walks the probabilities `P(X = 0), P(X = 1), ...` down from one
    /// uniform draw, with a fresh draw past the bound (see the module's docs).
    fn binomial_inversion(&mut self, n: u32, p: f64) -> u32 {
        let q = 1.0 - p;
        let n_f = f64::from(n);
        let p_zero = exp(n_f * ln(q));
        let np = n_f * p;
        // numpy's `(long)MIN(n, ...)`: the smaller as a double, truncated.
        let bound = n_f.min(np + 10.0 * (np * q + 1.0).sqrt()) as u32;
        let mut x = 0u32;
        let mut px = p_zero;
        let mut u = self.random_sample();
        while u > px {
            x += 1;
            if x > bound {
                x = 0;
                px = p_zero;
                u = self.random_sample();
            } else {
                u -= px;
                px = (f64::from(n - x + 1) * p * px) / (f64::from(x) * q);
            }
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_mt19937_gives_its_published_10000th_output() {
        // C++'s std::mt19937 (default seed 5489) is required to give 4123659995 as its 10000th
        // output; the first is the reference implementation's 3499211612.
        let mut mt = Mt19937::new(5489);
        assert_eq!(mt.next_u32(), 3_499_211_612);
        let last = (1..10_000).map(|_| mt.next_u32()).last();
        assert_eq!(last, Some(4_123_659_995));
    }

    #[test]
    fn seeding_fills_the_key_by_knuths_recurrence_and_defers_the_regeneration() {
        let mt = Mt19937::new(1);
        assert_eq!(mt.pos(), STATE_LEN);
        assert_eq!(mt.key()[0], 1);
        assert_eq!(mt.key()[1], 1_812_433_253u32.wrapping_mul(1) + 1);
    }

    #[test]
    fn random_sample_of_seed_zero_is_numpys() {
        // np.random.RandomState(0).random_sample(2)
        let mut rs = RandomState::new(0);
        assert_eq!(rs.random_sample(), 0.548_813_503_927_324_8);
        assert_eq!(rs.random_sample(), 0.715_189_366_372_419_5);
    }

    #[test]
    fn a_fair_coin_takes_one_double_and_is_one_above_a_half() {
        let mut coins = RandomState::new(7);
        let mut doubles = RandomState::new(7);
        for _ in 0..1000 {
            let u = doubles.random_sample();
            assert_eq!(coins.binomial(1, 0.5), Ok(u32::from(u > 0.5)));
        }
        assert_eq!(coins, doubles);
    }

    #[test]
    fn degenerate_probabilities_give_the_bounds_and_bad_ones_are_refused() {
        let mut rs = RandomState::new(3);
        assert_eq!(rs.binomial(20, 0.0), Ok(0));
        assert_eq!(rs.binomial(20, 1.0), Ok(20));
        assert_eq!(rs.binomial(0, 0.3), Ok(0));
        for p in [-0.1, 1.5, f64::NAN] {
            assert!(matches!(
                rs.binomial(3, p),
                Err(BinomialError::Probability(_))
            ));
        }
        assert_eq!(
            rs.binomial(61, 0.5),
            Err(BinomialError::NeedsBtpe { n: 61, p: 0.5 })
        );
        assert_eq!(
            rs.binomial(400, 0.9),
            Err(BinomialError::NeedsBtpe { n: 400, p: 0.9 })
        );
        assert!(rs.binomial(60, 0.5).is_ok());
    }
}
