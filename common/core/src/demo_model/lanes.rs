//! How the demonstration model's independent jobs run: one after another ([`Serial`], what the
//! core does on its own) or at once on threads the caller owns (`alfd_harness::Threads`, which
//! the expert process and `alfd demo-model` pass in). A job's arithmetic is its own, so the
//! model's bits never depend on the lanes it ran on.

/// Runs batches of independent jobs.
pub trait Lanes: Sync {
    /// How many jobs run at once (at least 1).
    fn width(&self) -> usize;

    /// Runs every job, returning when all have finished.
    fn run<'a>(&self, jobs: Vec<Box<dyn FnOnce() + Send + 'a>>);

    /// Whether the jobs of a batch (no more than [`Lanes::width`] of them) run at the same
    /// time, each on a thread of its own, so that one may wait for another's progress. Work
    /// split that way is given only to lanes that say so.
    fn concurrent(&self) -> bool {
        false
    }

    /// What a job does while it waits for another's progress, after a while of spinning:
    /// nothing more here; lanes on threads give the core away.
    fn pause(&self) {
        std::hint::spin_loop();
    }
}

/// Every job in turn, on the caller's thread.
#[derive(Debug, Clone, Copy, Default)]
pub struct Serial;

impl Lanes for Serial {
    fn width(&self) -> usize {
        1
    }

    fn run<'a>(&self, jobs: Vec<Box<dyn FnOnce() + Send + 'a>>) {
        for job in jobs {
            job();
        }
    }
}

/// Lanes an owner keeps and clones with itself: [`Serial`] unless given others.
#[derive(Clone)]
pub struct SharedLanes(std::sync::Arc<dyn Lanes + Send>);

impl SharedLanes {
    pub fn new(lanes: impl Lanes + Send + 'static) -> SharedLanes {
        SharedLanes(std::sync::Arc::new(lanes))
    }

    pub fn get(&self) -> &dyn Lanes {
        &*self.0
    }
}

impl Default for SharedLanes {
    fn default() -> SharedLanes {
        SharedLanes::new(Serial)
    }
}

impl std::fmt::Debug for SharedLanes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SharedLanes({} wide)", self.0.width())
    }
}

/// Calls `f` once per lane of `lanes` on its share of `items` (item i in lane `i % width`), the
/// lanes at once when there are several.
pub fn share<T: Send>(items: &mut [T], lanes: &dyn Lanes, f: impl Fn(&mut [&mut T]) + Sync) {
    let width = lanes.width().clamp(1, items.len().max(1));
    let mut shares: Vec<Vec<&mut T>> = (0..width).map(|_| Vec::new()).collect();
    for (i, item) in items.iter_mut().enumerate() {
        shares[i % width].push(item);
    }
    if width == 1 {
        f(&mut shares[0]);
        return;
    }
    let f = &f;
    let jobs = shares
        .into_iter()
        .map(|mut share| Box::new(move || f(&mut share)) as Box<dyn FnOnce() + Send + '_>)
        .collect();
    lanes.run(jobs);
}

/// Calls `f` once on every item of `items`, the lanes taking the next item in order as each
/// finishes its last (for jobs of unequal and unknown length; put the longest first).
pub fn queue<T: Send>(items: &mut [T], lanes: &dyn Lanes, f: impl Fn(&mut T) + Sync) {
    let width = lanes.width().clamp(1, items.len().max(1));
    if width == 1 {
        items.iter_mut().for_each(f);
        return;
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let items: Vec<std::sync::Mutex<&mut T>> =
        items.iter_mut().map(std::sync::Mutex::new).collect();
    let take = || {
        while let Some(item) = items.get(next.fetch_add(1, std::sync::atomic::Ordering::Relaxed)) {
            // Each item is taken once: its lock is never contended.
            f(&mut item
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner));
        }
    };
    let take = &take;
    let jobs = (0..width)
        .map(|_| Box::new(take) as Box<dyn FnOnce() + Send + '_>)
        .collect();
    lanes.run(jobs);
}

/// Lanes that run their jobs last to first: for tests of code whose results must not depend on
/// the lanes.
#[cfg(test)]
pub(crate) struct Backwards(pub usize);

#[cfg(test)]
impl Lanes for Backwards {
    fn width(&self) -> usize {
        self.0
    }
    fn run<'a>(&self, jobs: Vec<Box<dyn FnOnce() + Send + 'a>>) {
        for job in jobs.into_iter().rev() {
            job();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_queue_visits_every_item_once() {
        for width in [1, 2, 3, 7] {
            let mut items: Vec<usize> = vec![0; 10];
            queue(&mut items, &Backwards(width), |visits| *visits += 1);
            assert_eq!(items, vec![1; 10], "width {width}");
        }
    }

    #[test]
    fn every_item_is_visited_once_in_the_lane_of_its_index() {
        for width in [1, 2, 3, 7] {
            let mut items: Vec<(usize, usize)> = (0..10).map(|i| (i, 0)).collect();
            share(&mut items, &Backwards(width), |lane| {
                let residue = lane[0].0 % width;
                for item in lane.iter_mut() {
                    assert_eq!(item.0 % width, residue, "width {width}");
                    item.1 += 1;
                }
            });
            assert!(
                items.iter().all(|&(_, visits)| visits == 1),
                "width {width}"
            );
        }
    }
}
