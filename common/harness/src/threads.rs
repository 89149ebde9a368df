//! [`Threads`]: the demonstration model's lanes (`alfd_common::demo_model::lanes`) on the
//! machine's cores, for the processes whose large fits should use them (the expert process and
//! `alfd demo-model`). The model is the same, bit for bit, on any lanes.

use alfd_common::demo_model::lanes::Lanes;

/// Runs a batch of jobs at once on scoped threads, one of them on the caller's.
#[derive(Debug, Clone, Copy)]
pub struct Threads {
    width: usize,
}

impl Threads {
    /// As many lanes as the process may use cores (1 when that cannot be told).
    pub fn machine() -> Threads {
        Threads::new(std::thread::available_parallelism().map_or(1, |n| n.get()))
    }

    /// `width` lanes (at least 1).
    pub fn new(width: usize) -> Threads {
        Threads {
            width: width.max(1),
        }
    }
}

impl Lanes for Threads {
    fn width(&self) -> usize {
        self.width
    }

    fn run<'a>(&self, jobs: Vec<Box<dyn FnOnce() + Send + 'a>>) {
        std::thread::scope(|scope| {
            let mut jobs = jobs.into_iter();
            let first = jobs.next();
            for job in jobs {
                scope.spawn(job);
            }
            if let Some(job) = first {
                job();
            }
        });
    }

    fn concurrent(&self) -> bool {
        true
    }

    fn pause(&self) {
        std::thread::yield_now();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_common::demo_model::krr::KrrFactor;
    use alfd_common::demo_model::{DemoModel, DemoModelKind};

    #[test]
    fn jobs_run_on_threads_of_their_own_and_all_finish() {
        let ids = std::sync::Mutex::new(Vec::new());
        let jobs: Vec<Box<dyn FnOnce() + Send + '_>> = (0..3)
            .map(|_| {
                Box::new(|| ids.lock().unwrap().push(std::thread::current().id()))
                    as Box<dyn FnOnce() + Send + '_>
            })
            .collect();
        Threads::new(3).run(jobs);
        let mut ids = ids.into_inner().unwrap();
        assert_eq!(ids.len(), 3);
        ids.sort_by_key(|id| format!("{id:?}"));
        ids.dedup();
        assert_eq!(ids.len(), 3, "three jobs on three threads");
        assert_eq!(Threads::new(0).width(), 1);
    }

    #[test]
    fn models_fitted_on_threads_are_the_ones_fitted_in_turn() {
        let (states, actions) = cartpole_like(1300);
        for kind in [DemoModelKind::Krr, DemoModelKind::Svm] {
            let n = if kind == DemoModelKind::Svm {
                300
            } else {
                states.len()
            };
            let serial = DemoModel::fit(kind, &states[..n], &actions[..n], 2).unwrap();
            let threaded =
                DemoModel::fit_on(kind, &states[..n], &actions[..n], 2, &Threads::new(2)).unwrap();
            assert!(threaded == serial, "{kind:?}");
        }
    }

    /// `n` CartPole-like demonstrations of two actions.
    fn cartpole_like(n: usize) -> (Vec<[f64; 4]>, Vec<usize>) {
        let states: Vec<[f64; 4]> = (0..n)
            .map(|i| {
                let t = i as f64;
                [
                    (t * 0.37).sin() * 2.0,
                    (t * 0.11).cos() * 3.0,
                    (t * 0.05).sin() * 0.2,
                    (t * 0.73).cos(),
                ]
            })
            .collect();
        let actions = states
            .iter()
            .map(|s| usize::from(s[2] + 0.1 * s[3] > 0.0))
            .collect();
        (states, actions)
    }

    #[test]
    fn a_krr_factor_grown_and_solved_on_threads_is_the_fitted_one() {
        // Past the size from which the solves are split between two threads, and past two
        // steps of the split (every 128 rows).
        let n = 2048 + 2 * 128 + 5;
        let (states, actions) = cartpole_like(n);
        let mut grown = KrrFactor::fit(&states[..n - 3], &actions[..n - 3], 2).unwrap();
        for i in n - 3..n {
            grown
                .push_on(&states[i], actions[i], &Threads::new(2))
                .unwrap();
        }
        let fitted = KrrFactor::fit(&states, &actions, 2).unwrap();
        assert!(grown == fitted, "the grown factor");
        assert!(
            grown.model_on(&Threads::new(2)) == fitted.model(),
            "the model"
        );
    }
}
