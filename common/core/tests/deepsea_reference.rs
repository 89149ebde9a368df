//! DeepSea against bsuite 0.3.6 and numpy's legacy `RandomState`, from the fixtures
//! `deploy/python/fixtures/deepsea_fixtures.py` writes to `tests/data/deepsea/`: the action
//! mappings, every step of every recorded episode (position, reward to the bit, end flags,
//! observation), and the MT19937 outputs, doubles and binomial draws behind the mappings.

use std::collections::BTreeMap;

use alfd_common::env::deepsea::numpy_legacy::{Mt19937, RandomState, STATE_LEN};
use alfd_common::env::{DeepSea, Env, EnvError};
use serde::de::DeserializeOwned;
use serde::Deserialize;

/// The (N, mapping seed) pairs recorded: bsuite's sweep uses mapping seed 42 for N = 10..=50.
const PAIRS: [(usize, u32); 12] = [
    (5, 0),
    (5, 1),
    (5, 42),
    (10, 0),
    (10, 1),
    (10, 42),
    (20, 0),
    (20, 1),
    (20, 42),
    (50, 0),
    (50, 1),
    (50, 42),
];

#[derive(Debug, Deserialize)]
struct Fixture {
    size: usize,
    mapping_seed: u32,
    mapping: Vec<Vec<u8>>,
    optimal_return_bits: u64,
    initial_hot: usize,
    episodes: BTreeMap<String, Episode>,
}

/// One episode from a reset: per step, the position after it (`None` past the last row), the
/// hot index of the observation, the reward's bits, dm_env's discount and LAST flag.
#[derive(Debug, Deserialize)]
struct Episode {
    actions: Vec<usize>,
    positions: Vec<Option<(usize, usize)>>,
    hot: Vec<Option<usize>>,
    reward_bits: Vec<u64>,
    discounts: Vec<f64>,
    last: Vec<bool>,
    return_bits: u64,
}

fn read<T: DeserializeOwned>(file: &str) -> T {
    let path = format!("{}/tests/data/deepsea/{file}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

fn fixture(size: usize, seed: u32) -> Fixture {
    let f: Fixture = read(&format!("n{size}_mapping_seed{seed}.json"));
    assert_eq!((f.size, f.mapping_seed), (size, seed));
    f
}

/// The observation with a 1 at `hot` (all zeros for `None`).
fn one_hot(size: usize, hot: Option<usize>) -> Vec<f32> {
    let mut grid = vec![0.0; size * size];
    if let Some(i) = hot {
        grid[i] = 1.0;
    }
    grid
}

#[test]
fn the_action_mappings_are_bsuites() {
    for (size, seed) in PAIRS {
        let f = fixture(size, seed);
        let env = DeepSea::new(size, seed).expect("valid size");
        let theirs: Vec<u8> = f.mapping.concat();
        assert_eq!(theirs.len(), size * size);
        assert_eq!(
            env.action_mapping(),
            &theirs[..],
            "N {size} mapping seed {seed}"
        );
        assert_eq!(env.optimal_return().to_bits(), f.optimal_return_bits);
    }
}

/// Replays one recorded episode on `env`; returns its number of steps.
fn replay(env: &mut DeepSea, name: &str, e: &Episode, initial_hot: usize) -> usize {
    let size = env.size();
    let n = e.actions.len();
    assert_eq!(n, size, "{name}: bsuite's episodes last N steps");
    let columns = (
        e.positions.len(),
        e.hot.len(),
        e.reward_bits.len(),
        e.last.len(),
    );
    assert_eq!(columns, (n, n, n, n), "{name}");
    assert_eq!(
        env.reset(Some(9)),
        one_hot(size, Some(initial_hot)),
        "{name}"
    );
    let mut ret = 0.0;
    for (k, &action) in e.actions.iter().enumerate() {
        let at = format!("{name} step {k}");
        let step = env.step(action).expect("the episode is running");
        assert_eq!(env.position(), e.positions[k], "{at} position");
        assert_eq!(
            step.observation,
            one_hot(size, e.hot[k]),
            "{at} observation"
        );
        assert_eq!(
            step.reward.to_bits(),
            e.reward_bits[k],
            "{at} reward {}",
            step.reward
        );
        assert_eq!(step.terminated, e.last[k], "{at} terminated");
        assert_eq!(step.terminated, e.discounts[k] == 0.0, "{at} discount");
        assert_eq!(
            step.truncated,
            k + 1 == size,
            "{at}: the default limit is N"
        );
        ret += step.reward;
    }
    assert_eq!(ret.to_bits(), e.return_bits, "{name} return {ret}");
    assert_eq!(env.step(0), Err(EnvError::EpisodeOver), "{name}");
    n
}

#[test]
fn every_recorded_episode_replays_step_by_step() {
    let (mut episodes, mut steps, mut treasures) = (0, 0, 0);
    for (size, seed) in PAIRS {
        let f = fixture(size, seed);
        let mut env = DeepSea::new(size, seed).expect("valid size");
        for (name, e) in &f.episodes {
            let name = format!("N {size} mapping seed {seed} {name}");
            steps += replay(&mut env, &name, e, f.initial_hot);
            episodes += 1;
            treasures += usize::from(f64::from_bits(*e.reward_bits.last().unwrap()) > 0.5);
        }
        assert!(f.episodes.contains_key("optimal"));
    }
    // 8 sequences for N 5, 10 and 20, 4 for N 50; the optimal one finds the treasure each time.
    assert_eq!((episodes, steps), (84, 1440));
    assert_eq!(treasures, 12);
}

#[test]
fn the_optimal_action_follows_the_recorded_optimal_sequence() {
    for (size, seed) in PAIRS {
        let f = fixture(size, seed);
        let mut env = DeepSea::new(size, seed).expect("valid size");
        let mut obs = env.reset(None);
        let mut chosen = Vec::new();
        while let Some(action) = env.optimal_action_for(&obs) {
            assert_eq!(action, env.optimal_action());
            chosen.push(action);
            obs = env.step(action).expect("running").observation;
        }
        assert_eq!(
            chosen, f.episodes["optimal"].actions,
            "N {size} seed {seed}"
        );
    }
}

#[derive(Debug, Deserialize)]
struct NumpyFixture {
    seeds: Vec<NumpySeed>,
}

#[derive(Debug, Deserialize)]
struct NumpySeed {
    seed: u32,
    key_after_seeding: Vec<u32>,
    pos_after_seeding: usize,
    raw32_first: Vec<u32>,
    raw32_from_620: Vec<u32>,
    raw32_from_1240: Vec<u32>,
    random_sample_times_2_53: Vec<u64>,
    binomial: Vec<Binomial>,
    binomial_1_half_then_random_sample: Mixed,
}

#[derive(Debug, Deserialize)]
struct Binomial {
    n: u32,
    p: f64,
    values: Vec<u32>,
}

#[derive(Debug, Deserialize)]
struct Mixed {
    binomial: Vec<u32>,
    random_sample_times_2_53: Vec<u64>,
}

/// A double of `random_sample` as the integer `value · 2^53` (exact for these doubles).
fn scaled(v: f64) -> u64 {
    let k = v * 9_007_199_254_740_992.0;
    assert_eq!(k.fract(), 0.0, "{v} is a multiple of 2^-53");
    k as u64
}

#[test]
fn mt19937_seeds_and_draws_as_numpys_random_state() {
    let fixture: NumpyFixture = read("numpy_legacy.json");
    assert_eq!(fixture.seeds.len(), 5);
    for s in &fixture.seeds {
        let mt = Mt19937::new(s.seed);
        let mut key: Vec<u32> = mt.key()[..8].to_vec();
        key.push(mt.key()[STATE_LEN - 1]);
        assert_eq!(key, s.key_after_seeding, "seed {}", s.seed);
        assert_eq!(mt.pos(), s.pos_after_seeding);
        let raw: Vec<u32> = {
            let mut mt = mt.clone();
            (0..1250).map(|_| mt.next_u32()).collect()
        };
        assert_eq!(raw[..16], s.raw32_first[..], "seed {}", s.seed);
        assert_eq!(raw[620..632], s.raw32_from_620[..], "seed {}", s.seed);
        assert_eq!(raw[1240..], s.raw32_from_1240[..], "seed {}", s.seed);
        let mut rs = RandomState::new(s.seed);
        let doubles: Vec<u64> = s
            .random_sample_times_2_53
            .iter()
            .map(|_| scaled(rs.random_sample()))
            .collect();
        assert_eq!(doubles, s.random_sample_times_2_53, "seed {}", s.seed);
    }
}

#[test]
fn legacy_binomial_draws_as_numpys_random_state() {
    let fixture: NumpyFixture = read("numpy_legacy.json");
    let mut cases = 0;
    for s in &fixture.seeds {
        for b in &s.binomial {
            let mut rs = RandomState::new(s.seed);
            let ours: Vec<u32> = b
                .values
                .iter()
                .map(|_| rs.binomial(b.n, b.p).expect("inversion"))
                .collect();
            assert_eq!(ours, b.values, "seed {} binomial({}, {})", s.seed, b.n, b.p);
            cases += 1;
        }
        // Each fair coin takes exactly one double: the doubles after them are numpy's.
        let mixed = &s.binomial_1_half_then_random_sample;
        let mut rs = RandomState::new(s.seed);
        let coins: Vec<u32> = mixed
            .binomial
            .iter()
            .map(|_| rs.binomial(1, 0.5).expect("inversion"))
            .collect();
        assert_eq!(coins, mixed.binomial);
        let after: Vec<u64> = (0..3).map(|_| scaled(rs.random_sample())).collect();
        assert_eq!(after, mixed.random_sample_times_2_53, "seed {}", s.seed);
    }
    assert_eq!(cases, 30);
}
