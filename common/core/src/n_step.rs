//! n-step transitions, made on the actor's side as Acme's `NStepTransitionAdder` makes them: the
//! one-step transitions of an episode go in, in order; out comes, for each, the transition from
//! its state over the next `n` steps,
//!
//! ```text
//! (s_t, a_t, r_t + γ r_{t+1} + … + γ^{n-1} r_{t+n-1}, s_{t+n}, terminated_{t+n-1}), horizon n,
//! ```
//!
//! with the first step's action, bootstrap mask and demonstration flag (so a demonstration stays
//! a demonstration for the batch fraction and the large-margin loss). At the end of an episode the
//! last `n - 1` transitions go out with the steps that are left (horizon < n): a terminal one
//! bootstraps from nothing, a truncated one from the state where the episode was cut, with
//! `γ^horizon`. Rewards come in already shaped, so potential-based shaping's bonuses telescope to
//! `γ^n Φ(s_{t+n}) − Φ(s_t)`, still potential-based. With `n = 1` a transition goes out at once,
//! unchanged.
//!
//! Pure: no I/O; the caller says where the transitions go.

use std::collections::VecDeque;

use crate::replay::Transition;

/// The window of one-step transitions not yet handed on.
#[derive(Debug, Clone, PartialEq)]
pub struct NStep {
    n: usize,
    gamma: f64,
    window: VecDeque<Transition>,
}

impl NStep {
    /// n-step transitions with discount `gamma`; `n` in `1..=255` (the config allows fewer:
    /// `agent.n_step` is checked against its own maximum).
    pub fn new(n: u32, gamma: f64) -> Self {
        assert!(
            (1..=u32::from(u8::MAX)).contains(&n),
            "n-step returns need 1 <= n <= 255, got {n}"
        );
        Self {
            n: n as usize,
            gamma,
            window: VecDeque::with_capacity(n as usize),
        }
    }

    /// Takes the one-step transition `t` of the episode's next step (`episode_end`: it is the
    /// episode's last) and hands every n-step transition that is complete now to `emit`, in
    /// order, with whether it is the last of the episode. Stops at `emit`'s first error.
    pub fn push<E>(
        &mut self,
        t: Transition,
        episode_end: bool,
        mut emit: impl FnMut(Transition, bool) -> Result<(), E>,
    ) -> Result<(), E> {
        assert_eq!(t.horizon, 1, "n-step transitions are made of one-step ones");
        self.window.push_back(t);
        if episode_end {
            while !self.window.is_empty() {
                let out = self.first();
                self.window.pop_front();
                emit(out, self.window.is_empty())?;
            }
        } else if self.window.len() == self.n {
            let out = self.first();
            self.window.pop_front();
            emit(out, false)?;
        }
        Ok(())
    }

    /// Transitions waiting for the steps after them (at most `n - 1`).
    pub fn waiting(&self) -> usize {
        self.window.len()
    }

    /// The transition from the window's first state over the whole window.
    fn first(&self) -> Transition {
        let first = &self.window[0];
        if self.window.len() == 1 {
            return first.clone();
        }
        let last = &self.window[self.window.len() - 1];
        let mut reward = 0.0f64;
        let mut discount = 1.0f64;
        for t in &self.window {
            reward += discount * f64::from(t.reward);
            discount *= self.gamma;
        }
        Transition {
            state: first.state.clone(),
            action: first.action,
            reward: reward as f32,
            next_state: last.next_state.clone(),
            terminated: last.terminated,
            mask: first.mask.clone(),
            demo: first.demo,
            horizon: self.window.len() as u8,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The one-step transition from state `x` to `x + 1` with reward `r`.
    fn step(x: f32, r: f32, terminated: bool, demo: bool) -> Transition {
        Transition {
            state: vec![x],
            action: x as u32 % 2,
            reward: r,
            next_state: vec![x + 1.0],
            terminated,
            mask: vec![x, 1.0],
            demo,
            horizon: 1,
        }
    }

    fn run(n: u32, steps: &[Transition], ends: &[bool]) -> Vec<(Transition, bool)> {
        let mut acc = NStep::new(n, 0.5);
        let mut out = Vec::new();
        for (t, &end) in steps.iter().zip(ends) {
            acc.push(t.clone(), end, |t, last| {
                out.push((t, last));
                Ok::<(), ()>(())
            })
            .unwrap();
        }
        out
    }

    #[test]
    fn three_step_transitions_by_hand_then_the_tail_at_a_terminal_step() {
        // Rewards 1, 2, 4, 8 with γ = 0.5; the episode terminates on the fourth step.
        let steps = [
            step(0.0, 1.0, false, true),
            step(1.0, 2.0, false, false),
            step(2.0, 4.0, false, false),
            step(3.0, 8.0, true, false),
        ];
        let out = run(3, &steps, &[false, false, false, true]);
        let got: Vec<(f32, f32, f32, bool, u8, bool)> = out
            .iter()
            .map(|(t, last)| {
                (
                    t.state[0],
                    t.reward,
                    t.next_state[0],
                    t.terminated,
                    t.horizon,
                    *last,
                )
            })
            .collect();
        assert_eq!(
            got,
            vec![
                // 1 + 0.5·2 + 0.25·4 = 3, from s0 to s3.
                (0.0, 3.0, 3.0, false, 3, false),
                // 2 + 0.5·4 + 0.25·8 = 6, to the terminal s4.
                (1.0, 6.0, 4.0, true, 3, false),
                // The tail: 4 + 0.5·8 = 8 over two steps, then 8 over one.
                (2.0, 8.0, 4.0, true, 2, false),
                (3.0, 8.0, 4.0, true, 1, true),
            ]
        );
        // The first step's action, mask and demonstration flag.
        assert!(out[0].0.demo && !out[1].0.demo);
        assert_eq!(out[1].0.mask, vec![1.0, 1.0]);
        assert_eq!(out[2].0.action, 0);
    }

    #[test]
    fn a_truncated_episode_keeps_bootstrapping_from_where_it_was_cut() {
        let steps = [step(0.0, 1.0, false, false), step(1.0, 1.0, false, false)];
        let out = run(5, &steps, &[false, true]);
        assert_eq!(out.len(), 2);
        assert_eq!(
            (out[0].0.reward, out[0].0.horizon, out[0].0.terminated),
            (1.5, 2, false)
        );
        assert_eq!(out[0].0.next_state, vec![2.0]);
        assert_eq!((out[1].0.reward, out[1].0.horizon), (1.0, 1));
        assert!(!out[0].1 && out[1].1, "only the last is the episode's end");
    }

    #[test]
    fn one_step_hands_every_transition_on_at_once_unchanged() {
        let steps = [step(0.0, 0.3, false, false), step(1.0, 0.7, true, true)];
        let out = run(1, &steps, &[false, true]);
        assert_eq!(
            out,
            vec![(steps[0].clone(), false), (steps[1].clone(), true)]
        );
    }

    #[test]
    fn transitions_wait_for_n_steps_and_an_error_stops_the_flush() {
        let mut acc = NStep::new(4, 0.9);
        let mut n = 0;
        for x in 0..3 {
            acc.push(step(x as f32, 1.0, false, false), false, |_, _| {
                n += 1;
                Ok::<(), ()>(())
            })
            .unwrap();
        }
        assert_eq!((n, acc.waiting()), (0, 3));
        let e = acc.push(step(3.0, 1.0, true, false), true, |_, _| Err("link down"));
        assert_eq!(e, Err("link down"));
        // The error stopped the flush after the first transition went.
        assert_eq!(acc.waiting(), 3);
    }
}
