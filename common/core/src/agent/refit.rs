//! A refit of the demonstration model as a value: taken out of [`super::ExpertCore`] with the
//! demonstrations and grown factor it needs ([`RefitJob`]), run anywhere ([`RefitJob::run`]:
//! pure computation), and given back ([`Refitted`]). The core refits inline this way; the expert
//! process can run it on a thread of its own and answer queries meanwhile.

use std::sync::Arc;

use super::demo::DemoRecord;
use crate::config::DemoModelChoice;
use crate::demo_model::krr::KrrFactor;
use crate::demo_model::lanes::{Lanes, Serial, SharedLanes};
use crate::demo_model::nystrom::NystromFactor;
use crate::demo_model::{DemoModel, DemoModelError, DemoModelKind};

/// The grown factors a refit takes with it and gives back.
pub(crate) type Factors = (Option<KrrFactor>, Option<NystromFactor>);

/// The demonstrations of a refit: the prior ones (shared with the core, not copied), then the
/// run's.
pub(crate) type DemoSet = (Arc<[DemoRecord]>, Vec<DemoRecord>);

/// A refit to run: the demonstrations (prior first), the model's choice and its grown factor.
#[derive(Debug)]
pub struct RefitJob {
    epoch: u64,
    choice: DemoModelChoice,
    set: DemoSet,
    num_actions: usize,
    factors: Factors,
    lanes: SharedLanes,
    /// Whether a grown factor's solves run on one lane ([`RefitJob::in_background`]).
    grow_alone: bool,
}

/// What a refit gives back to the core.
#[derive(Debug)]
pub struct Refitted {
    pub(crate) epoch: u64,
    /// Demonstrations the refit covers.
    pub(crate) covers: usize,
    pub(crate) factors: Factors,
    pub(crate) outcome: Result<RefitOutcome, DemoModelError>,
}

impl Refitted {
    /// The model the refit fitted, if it fitted one.
    pub fn model(&self) -> Option<&DemoModel> {
        match &self.outcome {
            Ok(RefitOutcome::Fitted(model)) => Some(model),
            _ => None,
        }
    }
}

/// The model after a refit.
#[derive(Debug)]
pub(crate) enum RefitOutcome {
    /// No model is kept (`expert.model = "none"`).
    Unchanged,
    /// No demonstrations: no model.
    Cleared,
    Fitted(DemoModel),
}

impl RefitJob {
    pub(crate) fn new(
        epoch: u64,
        choice: DemoModelChoice,
        set: DemoSet,
        num_actions: usize,
        factors: Factors,
        lanes: SharedLanes,
    ) -> RefitJob {
        RefitJob {
            epoch,
            choice,
            set,
            num_actions,
            factors,
            lanes,
            grow_alone: false,
        }
    }

    /// The refit runs beside the query path: a grown factor's solves stay on one lane (split
    /// between two, each of its refits would take both cores from the query path and the
    /// learner for tens of milliseconds at 10,000 demonstrations); a fit anew still shares its
    /// work among the lanes.
    pub fn in_background(mut self) -> RefitJob {
        self.grow_alone = true;
        self
    }

    /// Demonstrations the refit covers.
    pub fn covers(&self) -> usize {
        self.set.0.len() + self.set.1.len()
    }

    /// Fits the model (growing the factor where it can: the same bits as a fit anew).
    pub fn run(mut self) -> Refitted {
        let outcome = self.fit();
        Refitted {
            epoch: self.epoch,
            covers: self.covers(),
            factors: self.factors,
            outcome,
        }
    }

    fn fit(&mut self) -> Result<RefitOutcome, DemoModelError> {
        let kind = match self.choice {
            DemoModelChoice::None => return Ok(RefitOutcome::Unchanged),
            DemoModelChoice::Krr => DemoModelKind::Krr,
            DemoModelChoice::Svm => DemoModelKind::Svm,
            DemoModelChoice::Nystrom => DemoModelKind::Nystrom,
        };
        let set: Vec<&DemoRecord> = self.set.0.iter().chain(&self.set.1).collect();
        if set.is_empty() {
            self.factors = (None, None);
            return Ok(RefitOutcome::Cleared);
        }
        let (set, m, lanes) = (&set[..], self.num_actions, self.lanes.get());
        let solves: &dyn Lanes = if self.grow_alone { &Serial } else { lanes };
        let (krr, nystrom) = &mut self.factors;
        Ok(RefitOutcome::Fitted(match kind {
            DemoModelKind::Krr => {
                DemoModel::Krr(grown(krr, set, m, lanes, solves)?.model_on(solves))
            }
            DemoModelKind::Nystrom => {
                DemoModel::Nystrom(grown(nystrom, set, m, lanes, solves)?.model()?)
            }
            DemoModelKind::Svm => {
                let (states, actions) = columns(set);
                DemoModel::fit_on(kind, &states, &actions, m, lanes)?
            }
        }))
    }
}

/// A model's state kept across demonstrations and grown by each: KRR's factor (each
/// demonstration at its weight), the Nyström sums (every demonstration alike).
trait Grows: Sized {
    fn len(&self) -> usize;
    fn push(&mut self, demo: &DemoRecord, lanes: &dyn Lanes) -> Result<(), DemoModelError>;
    fn fit(
        demos: &[&DemoRecord],
        num_actions: usize,
        lanes: &dyn Lanes,
    ) -> Result<Self, DemoModelError>;
}

/// The states and actions of `demos`.
fn columns<'d>(demos: &[&'d DemoRecord]) -> (Vec<&'d [f64]>, Vec<usize>) {
    let states = demos.iter().map(|d| d.state.as_slice()).collect();
    (states, demos.iter().map(|d| d.action).collect())
}

impl Grows for KrrFactor {
    fn len(&self) -> usize {
        KrrFactor::len(self)
    }
    fn push(&mut self, d: &DemoRecord, lanes: &dyn Lanes) -> Result<(), DemoModelError> {
        KrrFactor::push_weighted(self, &d.state, d.action, d.weight, lanes)
    }
    fn fit(demos: &[&DemoRecord], m: usize, lanes: &dyn Lanes) -> Result<Self, DemoModelError> {
        let (states, actions) = columns(demos);
        let weights: Vec<f64> = demos.iter().map(|d| d.weight).collect();
        KrrFactor::fit_weighted(&states, &actions, &weights, m, lanes)
    }
}

impl Grows for NystromFactor {
    fn len(&self) -> usize {
        NystromFactor::len(self)
    }
    fn push(&mut self, d: &DemoRecord, _: &dyn Lanes) -> Result<(), DemoModelError> {
        NystromFactor::push(self, &d.state, d.action)
    }
    fn fit(demos: &[&DemoRecord], m: usize, _: &dyn Lanes) -> Result<Self, DemoModelError> {
        let (states, actions) = columns(demos);
        NystromFactor::fit(&states, &actions, m)
    }
}

/// A factor grows by one demonstration, or by at most one in this many it holds; more newcomers
/// are cheaper fitted anew (KRR: each costs O(n²), a fit O(n³)).
const GROW_AT_MOST_ONE_IN: usize = 8;

/// The state in `slot` over every demonstration of `demos`: the one held, grown by the
/// demonstrations after its own (KRR: O(n²) each, on `solves`), or made anew (KRR: O(n³), on
/// `lanes`) when it holds none or too few of them; the same bits either way. The factor's rows are the first of `demos`
/// (demonstrations are only appended; replacing them empties the slot).
fn grown<'a, G: Grows>(
    slot: &'a mut Option<G>,
    demos: &[&DemoRecord],
    num_actions: usize,
    lanes: &dyn Lanes,
    solves: &dyn Lanes,
) -> Result<&'a G, DemoModelError> {
    let n = demos.len();
    match slot.as_mut() {
        Some(f)
            if f.len() <= n
                && (n - f.len() <= 1 || (n - f.len()) * GROW_AT_MOST_ONE_IN <= f.len()) =>
        {
            for d in &demos[f.len()..] {
                f.push(d, solves)?;
            }
        }
        _ => {
            *slot = None;
            *slot = Some(G::fit(demos, num_actions, lanes)?);
        }
    }
    Ok(slot.as_ref().expect("made above"))
}
