//! The replay buffer `D_buff`: a ring of transitions, each with its bootstrap mask and a flag
//! saying whether it is a demonstration, sampled uniformly.

use rand::Rng as _;

use crate::rng::Rng;

/// One transition as stored, with its Bernoulli bootstrap mask (which heads it trains).
#[derive(Debug, Clone, PartialEq)]
pub struct Transition {
    pub state: Vec<f32>,
    pub action: u32,
    /// The reward learned from (shaped when shaping is on).
    pub reward: f32,
    pub next_state: Vec<f32>,
    /// Terminal: no bootstrapping from `next_state`. A truncated step is not terminal.
    pub terminated: bool,
    /// `mask[k]` is 1.0 if head k trains on this transition, else 0.0.
    pub mask: Vec<f32>,
    /// The action came from the expert.
    pub demo: bool,
    /// Environment steps from `state` to `next_state`: 1 for a one-step transition; n for an
    /// n-step one, whose `reward` is the discounted sum `Σ_{i<n} γ^i r_i` of the n rewards and
    /// whose target bootstraps with `γ^n` (the n-step window makes them).
    pub horizon: u8,
}

/// A sampled mini-batch in flat, row-major arrays, ready for the network.
#[derive(Debug, Clone, Default)]
pub struct Batch {
    pub size: usize,
    pub obs_dim: usize,
    pub heads: usize,
    pub states: Vec<f32>,
    pub actions: Vec<u32>,
    pub rewards: Vec<f32>,
    pub next_states: Vec<f32>,
    /// 1.0 where the transition is terminal.
    pub terminated: Vec<f32>,
    /// `size * heads` values.
    pub masks: Vec<f32>,
    /// 1.0 where the transition is a demonstration (empty: none known).
    pub demos: Vec<f32>,
    /// Each transition's [`Transition::horizon`] (empty: all one-step).
    pub horizons: Vec<u8>,
}

/// Fixed-capacity ring buffer in structure-of-arrays layout.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReplayBuffer {
    capacity: usize,
    obs_dim: usize,
    heads: usize,
    len: usize,
    next: usize,
    states: Vec<f32>,
    actions: Vec<u32>,
    rewards: Vec<f32>,
    next_states: Vec<f32>,
    terminated: Vec<f32>,
    masks: Vec<f32>,
    demo: Vec<bool>,
    horizons: Vec<u8>,
    /// The slots holding demonstrations, in no particular order.
    demo_slots: Vec<usize>,
}

impl ReplayBuffer {
    pub fn new(capacity: usize, obs_dim: usize, heads: usize) -> Self {
        assert!(capacity > 0 && obs_dim > 0 && heads > 0);
        Self {
            capacity,
            obs_dim,
            heads,
            len: 0,
            next: 0,
            states: vec![0.0; capacity * obs_dim],
            actions: vec![0; capacity],
            rewards: vec![0.0; capacity],
            next_states: vec![0.0; capacity * obs_dim],
            terminated: vec![0.0; capacity],
            masks: vec![0.0; capacity * heads],
            demo: vec![false; capacity],
            horizons: vec![1; capacity],
            demo_slots: Vec::new(),
        }
    }

    /// Adds a transition, overwriting the oldest one when full.
    pub fn push(&mut self, t: &Transition) {
        assert_eq!(t.state.len(), self.obs_dim, "state has the wrong dimension");
        assert_eq!(
            t.next_state.len(),
            self.obs_dim,
            "next state has the wrong dimension"
        );
        assert_eq!(
            t.mask.len(),
            self.heads,
            "mask has the wrong number of heads"
        );
        assert!(t.horizon >= 1, "a transition spans at least one step");
        let i = self.next;
        let d = self.obs_dim;
        self.states[i * d..(i + 1) * d].copy_from_slice(&t.state);
        self.next_states[i * d..(i + 1) * d].copy_from_slice(&t.next_state);
        self.actions[i] = t.action;
        self.rewards[i] = t.reward;
        self.terminated[i] = if t.terminated { 1.0 } else { 0.0 };
        self.masks[i * self.heads..(i + 1) * self.heads].copy_from_slice(&t.mask);
        if self.demo[i] && i < self.len {
            // A demonstration leaves the buffer.
            let at = self
                .demo_slots
                .iter()
                .position(|&slot| slot == i)
                .expect("every demonstration slot is listed");
            self.demo_slots.swap_remove(at);
        }
        if t.demo {
            self.demo_slots.push(i);
        }
        self.demo[i] = t.demo;
        self.horizons[i] = t.horizon;
        self.next = (self.next + 1) % self.capacity;
        self.len = (self.len + 1).min(self.capacity);
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether `other` has this buffer's capacity and layout, and whole columns (a restored
    /// checkpoint must).
    pub fn same_shape(&self, other: &ReplayBuffer) -> bool {
        let c = self.capacity;
        (self.capacity, self.obs_dim, self.heads) == (other.capacity, other.obs_dim, other.heads)
            && other.len <= c
            && other.next < c.max(1)
            && other.states.len() == self.states.len()
            && other.next_states.len() == self.next_states.len()
            && other.actions.len() == self.actions.len()
            && other.rewards.len() == self.rewards.len()
            && other.terminated.len() == self.terminated.len()
            && other.masks.len() == self.masks.len()
            && other.demo.len() == self.demo.len()
            && other.horizons.len() == self.horizons.len()
            && other.demo_slots.iter().all(|&i| i < c)
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// How many stored transitions are demonstrations.
    pub fn demos(&self) -> usize {
        self.demo_slots.len()
    }

    /// Samples `size` transitions uniformly with replacement into `batch` (reusing its storage).
    pub fn sample_into(&self, size: usize, rng: &mut Rng, batch: &mut Batch) {
        self.sample_with_demos_into(size, 0.0, rng, batch);
    }

    /// Samples `size` transitions: `round(demo_fraction * size)` of them uniformly among the
    /// stored demonstrations (none if there are none), the rest uniformly among all, each with
    /// replacement, into `batch` (reusing its storage). With `demo_fraction = 0` this is
    /// [`ReplayBuffer::sample_into`], draw for draw.
    pub fn sample_with_demos_into(
        &self,
        size: usize,
        demo_fraction: f64,
        rng: &mut Rng,
        batch: &mut Batch,
    ) {
        assert!(self.len > 0, "cannot sample from an empty replay buffer");
        let d = self.obs_dim;
        let h = self.heads;
        batch.size = size;
        batch.obs_dim = d;
        batch.heads = h;
        batch.states.clear();
        batch.actions.clear();
        batch.rewards.clear();
        batch.next_states.clear();
        batch.terminated.clear();
        batch.masks.clear();
        batch.demos.clear();
        batch.horizons.clear();
        let from_demos = if self.demo_slots.is_empty() {
            0
        } else {
            ((demo_fraction * size as f64).round() as usize).min(size)
        };
        for j in 0..size {
            let i = if j < from_demos {
                self.demo_slots[rng.random_range(0..self.demo_slots.len())]
            } else {
                rng.random_range(0..self.len)
            };
            push_row(&mut batch.states, &self.states, d, i);
            push_row(&mut batch.next_states, &self.next_states, d, i);
            batch.actions.push(self.actions[i]);
            batch.rewards.push(self.rewards[i]);
            batch.terminated.push(self.terminated[i]);
            push_row(&mut batch.masks, &self.masks, h, i);
            batch.demos.push(if self.demo[i] { 1.0 } else { 0.0 });
            batch.horizons.push(self.horizons[i]);
        }
    }
}

/// Appends row `i` of `src` (rows of `width` values) to `dst`. Rows of up to 8 values (every
/// observation and head count the wire carries) are copied as arrays of that size, in
/// registers, rather than by a call to `memcpy` per row.
#[inline(always)]
fn push_row(dst: &mut Vec<f32>, src: &[f32], width: usize, i: usize) {
    #[inline(always)]
    fn fixed<const W: usize>(dst: &mut Vec<f32>, src: &[f32], i: usize) {
        let row: [f32; W] = src[i * W..(i + 1) * W]
            .try_into()
            .expect("a row of W values");
        dst.extend_from_slice(&row);
    }
    match width {
        1 => fixed::<1>(dst, src, i),
        2 => fixed::<2>(dst, src, i),
        3 => fixed::<3>(dst, src, i),
        4 => fixed::<4>(dst, src, i),
        5 => fixed::<5>(dst, src, i),
        6 => fixed::<6>(dst, src, i),
        7 => fixed::<7>(dst, src, i),
        8 => fixed::<8>(dst, src, i),
        _ => dst.extend_from_slice(&src[i * width..(i + 1) * width]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(x: f32, demo: bool) -> Transition {
        Transition {
            state: vec![x, x],
            action: 1,
            reward: x,
            next_state: vec![x + 1.0, x + 1.0],
            terminated: x > 5.0,
            mask: vec![1.0, 0.0],
            demo,
            horizon: 1,
        }
    }

    #[test]
    fn rows_of_every_width_are_pushed_whole_and_in_order() {
        for width in 1..=10 {
            let src: Vec<f32> = (0..5 * width).map(|v| v as f32).collect();
            let mut dst = vec![-1.0];
            for i in [3, 0, 4, 4] {
                push_row(&mut dst, &src, width, i);
            }
            let mut expected = vec![-1.0];
            for i in [3, 0, 4, 4] {
                expected.extend_from_slice(&src[i * width..(i + 1) * width]);
            }
            assert_eq!(dst, expected, "width {width}");
        }
    }

    #[test]
    fn ring_overwrites_oldest_and_samples_stored_rows() {
        let mut rb = ReplayBuffer::new(4, 2, 2);
        for i in 0..6 {
            rb.push(&t(i as f32, i == 5));
        }
        assert_eq!(rb.len(), 4);
        assert_eq!(rb.demos(), 1);
        let mut rng = crate::rng::seeded(3);
        let mut batch = Batch::default();
        rb.sample_into(64, &mut rng, &mut batch);
        assert_eq!(batch.states.len(), 128);
        assert_eq!(batch.masks.len(), 128);
        for j in 0..64 {
            let x = batch.states[2 * j];
            assert!((2.0..=5.0).contains(&x), "sampled an overwritten row {x}");
            assert_eq!(batch.rewards[j], x);
            assert_eq!(batch.next_states[2 * j], x + 1.0);
            assert_eq!(batch.terminated[j], if x > 5.0 { 1.0 } else { 0.0 });
        }
        // All four rows get sampled.
        let mut seen: Vec<i32> = batch.rewards.iter().map(|&r| r as i32).collect();
        seen.sort();
        seen.dedup();
        assert_eq!(seen, vec![2, 3, 4, 5]);
        assert_eq!(
            batch.demos.iter().sum::<f32>() as usize,
            batch.rewards.iter().filter(|&&r| r == 5.0).count()
        );
    }

    #[test]
    fn a_fixed_fraction_of_each_batch_comes_from_the_demonstrations() {
        let mut rb = ReplayBuffer::new(100, 2, 2);
        for i in 0..100 {
            rb.push(&t(i as f32, i % 25 == 0)); // demonstrations at 0, 25, 50, 75
        }
        assert_eq!(rb.demos(), 4);
        let mut rng = crate::rng::seeded(4);
        let mut batch = Batch::default();
        rb.sample_with_demos_into(64, 0.25, &mut rng, &mut batch);
        // round(0.25 * 64) = 16 demonstrations first, then uniform draws (about 4% demos).
        assert!(batch.demos[..16].iter().all(|&d| d == 1.0));
        assert!(batch.rewards[..16].iter().all(|&r| r as i32 % 25 == 0));
        let rest = batch.demos[16..].iter().filter(|&&d| d == 1.0).count();
        assert!(rest <= 8, "{rest} demonstrations among 48 uniform draws");
        // Overwritten demonstrations leave the list: after 100 more plain steps none is left.
        for i in 0..100 {
            rb.push(&t(i as f32, false));
        }
        assert_eq!(rb.demos(), 0);
        rb.sample_with_demos_into(8, 0.5, &mut rng, &mut batch);
        assert!(
            batch.demos.iter().all(|&d| d == 0.0),
            "no demonstrations to draw from"
        );
        // Fraction 0 is plain uniform sampling, draw for draw.
        let (mut a, mut b) = (Batch::default(), Batch::default());
        rb.sample_into(32, &mut crate::rng::seeded(9), &mut a);
        rb.sample_with_demos_into(32, 0.0, &mut crate::rng::seeded(9), &mut b);
        assert_eq!(a.states, b.states);
    }
}
