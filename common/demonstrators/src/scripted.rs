//! Scripted demonstrators for the sparse-reward environments: an energy-pumping controller for
//! MountainCar and a swing-up controller for Acrobot, and weaker experts of graded quality made
//! from them by replacing a fixed share of their actions with random ones (a seeded generator,
//! so an expert answers the same queries the same way in every run).

use alfd_common::agent::Demonstrator;
use alfd_common::config::EnvName;
use alfd_common::rng::{derive_seed, seeded, Rng};
use rand::Rng as _;

/// MountainCar: push along the velocity, which pumps energy into the swing until the car
/// clears the hill. From rest, push right when left of [`Self::START_RIGHT_OF`]: with the
/// slope, which pulls towards the valley floor at -π/6.
#[derive(Debug, Clone, Copy, Default)]
pub struct EnergyPumping;

impl EnergyPumping {
    /// From rest, the car is first pushed right if it stands left of this position.
    pub const START_RIGHT_OF: f32 = -0.48;
}

impl Demonstrator<[f32]> for EnergyPumping {
    fn act(&mut self, s: &[f32]) -> usize {
        let (position, velocity) = (s[0], s[1]);
        let right = if velocity == 0.0 {
            position < Self::START_RIGHT_OF
        } else {
            velocity > 0.0
        };
        if right {
            2
        } else {
            0
        }
    }
}

/// Acrobot: torque against the swing of the first link (-1 while θ̇1 > 0, +1 otherwise). The
/// reaction of the joint torque on the first link then pushes it along its swing, so every
/// swing is higher than the last until the tip clears the bar.
#[derive(Debug, Clone, Copy, Default)]
pub struct SwingUp;

impl Demonstrator<[f32]> for SwingUp {
    fn act(&mut self, s: &[f32]) -> usize {
        // The observation is (cos θ1, sin θ1, cos θ2, sin θ2, θ̇1, θ̇2).
        if s[4] > 0.0 {
            0
        } else {
            2
        }
    }
}

/// A demonstrator whose action is replaced, with probability `epsilon`, by one drawn uniformly
/// from the `num_actions` actions.
#[derive(Debug, Clone)]
pub struct Noisy<D> {
    pub inner: D,
    pub epsilon: f64,
    pub num_actions: usize,
    rng: Rng,
}

impl<D> Noisy<D> {
    /// The generator is seeded from `stream` (the expert's name), so the expert is reproducible.
    pub fn new(inner: D, epsilon: f64, num_actions: usize, stream: &str) -> Self {
        Self {
            inner,
            epsilon,
            num_actions,
            rng: seeded(derive_seed(0, stream)),
        }
    }
}

impl<S: ?Sized, D: Demonstrator<S>> Demonstrator<S> for Noisy<D> {
    fn act(&mut self, s: &S) -> usize {
        let own = self.inner.act(s);
        if self.rng.random::<f64>() < self.epsilon {
            self.rng.random_range(0..self.num_actions)
        } else {
            own
        }
    }
}

/// A scripted expert: its name, environment, the controller it is made from and the share of
/// its actions replaced by random ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scripted {
    pub name: &'static str,
    pub env: EnvName,
    pub epsilon: f64,
}

/// Every scripted expert, best first for each environment. Keep in step with `manifest.json`
/// (a test checks it).
pub const SCRIPTED: &[Scripted] = &[
    Scripted {
        name: "mountaincar-energy",
        env: EnvName::Mountaincar,
        epsilon: 0.0,
    },
    Scripted {
        name: "mountaincar-good",
        env: EnvName::Mountaincar,
        epsilon: 0.1,
    },
    Scripted {
        name: "mountaincar-fair",
        env: EnvName::Mountaincar,
        epsilon: 0.25,
    },
    Scripted {
        name: "mountaincar-poor",
        env: EnvName::Mountaincar,
        epsilon: 0.5,
    },
    Scripted {
        name: "acrobot-energy",
        env: EnvName::Acrobot,
        epsilon: 0.0,
    },
    Scripted {
        name: "acrobot-good",
        env: EnvName::Acrobot,
        epsilon: 0.25,
    },
    Scripted {
        name: "acrobot-fair",
        env: EnvName::Acrobot,
        epsilon: 0.5,
    },
    Scripted {
        name: "acrobot-poor",
        env: EnvName::Acrobot,
        epsilon: 0.75,
    },
];

impl Scripted {
    /// The scripted expert called `name`, if any.
    pub fn named(name: &str) -> Option<Self> {
        SCRIPTED.iter().find(|s| s.name == name).copied()
    }

    /// The demonstrator (the controller alone when `epsilon` is 0).
    pub fn build(&self) -> Box<dyn Demonstrator<[f32]> + Send> {
        fn noisy<D: Demonstrator<[f32]> + Send + 'static>(
            d: D,
            s: &Scripted,
        ) -> Box<dyn Demonstrator<[f32]> + Send> {
            if s.epsilon == 0.0 {
                Box::new(d)
            } else {
                Box::new(Noisy::new(d, s.epsilon, 3, s.name))
            }
        }
        match self.env {
            EnvName::Mountaincar => noisy(EnergyPumping, self),
            EnvName::Acrobot => noisy(SwingUp, self),
            EnvName::Cartpole | EnvName::Cliffwalk | EnvName::Gymnasium | EnvName::Deepsea => {
                unreachable!("no scripted expert for {}", self.env)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_common::env::{Acrobot, MountainCar};
    use alfd_common::evaluate::evaluate;

    /// Mean return of `name` over `episodes` episodes from `seed` (as `alfd expert eval NAME
    /// --episodes EPISODES --seed SEED` prints it).
    fn mean_over(name: &str, episodes: usize, seed: u64) -> f64 {
        let s = Scripted::named(name).expect("a scripted expert");
        let mut d = s.build();
        let mut act = |o: &[f32]| d.act(o);
        let returns = match s.env {
            EnvName::Mountaincar => {
                evaluate(&mut MountainCar::default(), episodes, seed, |o| act(o))
            }
            EnvName::Acrobot => evaluate(&mut Acrobot::default(), episodes, seed, |o| act(o)),
            other => unreachable!("{other}"),
        }
        .expect("the native environments step every action of a live episode");
        returns.iter().sum::<f64>() / returns.len() as f64
    }

    fn mean_return(name: &str) -> f64 {
        mean_over(name, 20, 7)
    }

    #[test]
    fn the_manifest_records_what_the_scripted_experts_score() {
        for s in SCRIPTED {
            let entry = crate::registry::list()
                .into_iter()
                .find(|e| e.name == s.name)
                .expect("listed");
            let mean = mean_over(s.name, 100, 12345);
            assert!(
                (entry.mean.expect("measured") - mean).abs() < 1e-9,
                "{}: the manifest says {:?}, 100 episodes from seed 12345 give {mean}",
                s.name,
                entry.mean
            );
        }
    }

    #[test]
    fn the_best_scripted_experts_reach_the_goal_quickly() {
        // Measured: -111.45 and -80.95 (-109.0 and -84.6 over 100 episodes, see the manifest).
        let mountaincar = mean_return("mountaincar-energy");
        assert!(mountaincar >= -120.0, "mountaincar-energy: {mountaincar}");
        let acrobot = mean_return("acrobot-energy");
        assert!(acrobot >= -90.0, "acrobot-energy: {acrobot}");
    }

    #[test]
    fn the_graded_experts_are_ordered_by_quality() {
        // Measured: mountaincar -111.45, -123.45, -143.15, -195.0; acrobot -80.95, -113.2,
        // -166.45, -295.3.
        for env in ["mountaincar", "acrobot"] {
            let means: Vec<f64> = ["energy", "good", "fair", "poor"]
                .iter()
                .map(|q| mean_return(&format!("{env}-{q}")))
                .collect();
            assert!(
                means.windows(2).all(|w| w[0] > w[1] + 5.0),
                "{env}: {means:?}"
            );
        }
    }

    #[test]
    fn a_noisy_expert_is_reproducible_and_mixes_at_its_rate() {
        let obs = [-0.5_f32, 0.01];
        let act = |d: &mut Box<dyn Demonstrator<[f32]> + Send>| -> Vec<usize> {
            (0..2000).map(|_| d.act(&obs)).collect()
        };
        let fair = Scripted::named("mountaincar-fair").unwrap();
        let (a, b) = (act(&mut fair.build()), act(&mut fair.build()));
        assert_eq!(a, b);
        // The controller pushes right here; a random action differs from it 2 times in 3.
        let changed = a.iter().filter(|&&x| x != 2).count() as f64 / a.len() as f64;
        assert!((changed - 0.25 * 2.0 / 3.0).abs() < 0.03, "{changed}");
        assert!(
            act(&mut Scripted::named("mountaincar-energy").unwrap().build())
                .iter()
                .all(|&x| x == 2)
        );
    }
}
