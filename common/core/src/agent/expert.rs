//! The expert's side: demonstrators (who answers a query), and [`ExpertCore`], which enforces the
//! budget B, keeps the demonstration set `D_dem`, and refits the demonstration model on it
//! (Algorithm 1 lines 8-10 and 21).

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::demo::DemoRecord;
use super::refit::{RefitJob, RefitOutcome, Refitted};
use crate::checkpoint::StateMismatch;
use crate::config::DemoModelChoice;
use crate::demo_model::krr::KrrFactor;
use crate::demo_model::lanes::SharedLanes;
use crate::demo_model::nystrom::NystromFactor;
use crate::demo_model::{DemoModel, DemoModelError};
use crate::nn::Mlp;
use crate::policy::argmax;
use crate::query::Budget;
use crate::shaping::ShapingSchedule;

/// Anything that answers "which action would you take in state `s`?".
pub trait Demonstrator<S: ?Sized> {
    fn act(&mut self, s: &S) -> usize;
    /// The action, or why none could be had (a demonstrator in another process that failed or
    /// did not answer); what the in-process expert asks. By default [`Demonstrator::act`].
    fn try_act(&mut self, s: &S) -> Result<usize, String> {
        Ok(self.act(s))
    }
}

/// The demonstrator of a run that never asks one (B = 0, no oracle): asking it is a bug.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoExpert;

impl<S: ?Sized> Demonstrator<S> for NoExpert {
    fn act(&mut self, _: &S) -> usize {
        unreachable!("a run with a budget of 0 asked its expert")
    }

    fn try_act(&mut self, _: &S) -> Result<usize, String> {
        Err("the run has no expert (budget.total = 0)".to_owned())
    }
}

/// One demonstrator for its first `after` answers and another from then on: an expert whose
/// quality changes behind the same name (`[[experts]]`' `becomes`).
pub struct Becomes<'d, S: ?Sized> {
    pub first: Box<dyn Demonstrator<S> + Send + 'd>,
    pub then: Box<dyn Demonstrator<S> + Send + 'd>,
    pub after: u64,
    answers: u64,
}

impl<'d, S: ?Sized> Becomes<'d, S> {
    pub fn new(
        first: Box<dyn Demonstrator<S> + Send + 'd>,
        then: Box<dyn Demonstrator<S> + Send + 'd>,
        after: u64,
    ) -> Self {
        Self {
            first,
            then,
            after,
            answers: 0,
        }
    }
}

impl<S: ?Sized> Demonstrator<S> for Becomes<'_, S> {
    fn act(&mut self, s: &S) -> usize {
        self.answers += 1;
        if self.answers > self.after {
            self.then.act(s)
        } else {
            self.first.act(s)
        }
    }
}

/// A deterministic policy table (CliffWalk experts).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TablePolicy {
    pub actions: Vec<usize>,
}

impl Demonstrator<usize> for TablePolicy {
    fn act(&mut self, s: &usize) -> usize {
        self.actions[*s]
    }
}

/// The analytic CartPole controller: push towards the side the pole falls to, with damping and a
/// weak pull of the cart back to the centre. Balances for the whole 1000-step episode from
/// Gymnasium's initial states (tested), so it serves as a perfect expert.
#[derive(Debug, Clone, Copy, Default)]
pub struct BalancingController;

impl Demonstrator<[f32]> for BalancingController {
    fn act(&mut self, s: &[f32]) -> usize {
        let (x, x_dot, theta, theta_dot) = (s[0], s[1], s[2], s[3]);
        let u = theta + 0.5 * theta_dot + 0.03 * x + 0.1 * x_dot;
        usize::from(u > 0.0)
    }
}

/// A trained Q-network acting greedily on the mean of its heads (CartPole experts of known quality).
#[derive(Debug, Clone)]
pub struct NetworkDemonstrator {
    net: Mlp,
    q: Vec<f32>,
    mean: Vec<f32>,
}

impl NetworkDemonstrator {
    pub fn new(net: Mlp) -> Self {
        let q = vec![0.0; net.heads() * net.actions()];
        let mean = vec![0.0; net.actions()];
        Self { net, q, mean }
    }

    pub fn network(&self) -> &Mlp {
        &self.net
    }

    /// Every head's Q-values at the state last passed to `act` (head-major).
    pub fn last_q(&self) -> &[f32] {
        &self.q
    }
}

impl Demonstrator<[f32]> for NetworkDemonstrator {
    fn act(&mut self, s: &[f32]) -> usize {
        self.net.forward_one(s, &mut self.q);
        let a = self.mean.len();
        let k = self.q.len() / a;
        self.mean.iter_mut().for_each(|m| *m = 0.0);
        for h in 0..k {
            for i in 0..a {
                self.mean[i] += self.q[h * a + i];
            }
        }
        argmax(&self.mean)
    }
}

/// What an [`ExpertCore`] must remember: the demonstrations (the budget spent is their number,
/// and the model is refitted on them) and how many times the model was fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExpertSnapshot {
    pub demos: Vec<DemoRecord>,
    pub model_version: u64,
}

/// The budget, the demonstration set and the demonstration model.
#[derive(Debug, Clone)]
pub struct ExpertCore {
    budget: Budget,
    /// Demonstrations the run started with (`demos.prior`): in the model, not in the budget;
    /// shared with the refits that take them, never copied.
    prior: Arc<[DemoRecord]>,
    demos: Vec<DemoRecord>,
    choice: DemoModelChoice,
    num_actions: usize,
    model: Option<DemoModel>,
    /// With KRR: the kernel matrix's factor over `demos`, grown by a row per demonstration.
    krr: Option<KrrFactor>,
    /// With the Nyström model: its sums over `demos`, grown by each demonstration.
    nystrom: Option<NystromFactor>,
    model_version: u64,
    schedule: ShapingSchedule,
    /// Where a model fitted anew does its independent work ([`Serial`] unless set).
    lanes: SharedLanes,
    /// Demonstrations (prior and the run's) the last refit was fitted on, or tried to be.
    fitted: usize,
    /// Whether [`ExpertCore::record`] leaves the refit to the caller.
    deferred: bool,
    /// Incremented whenever the demonstrations are replaced (a refit out for the old ones is
    /// then dropped).
    epoch: u64,
    /// The epoch of the refit out, if one is.
    out: Option<u64>,
}

impl ExpertCore {
    pub fn new(
        budget: u32,
        choice: DemoModelChoice,
        num_actions: usize,
        schedule: ShapingSchedule,
    ) -> Self {
        Self {
            budget: Budget::new(budget),
            prior: Arc::from([]),
            demos: Vec::new(),
            choice,
            num_actions,
            model: None,
            krr: None,
            nystrom: None,
            model_version: 0,
            schedule,
            lanes: SharedLanes::default(),
            fitted: 0,
            deferred: false,
            epoch: 0,
            out: None,
        }
    }

    /// Fits models anew with their independent work on `lanes` (the same models, bit for bit):
    /// for a process with cores of its own, such as the expert process.
    pub fn set_lanes(&mut self, lanes: SharedLanes) {
        self.lanes = lanes;
    }

    /// The expert's side of a config: budget B, demonstration model, shaping schedule.
    pub fn for_config(cfg: &crate::config::ExperimentConfig, num_actions: usize) -> Self {
        Self::new(
            cfg.budget(),
            cfg.expert.model,
            num_actions,
            cfg.shaping.schedule(),
        )
    }

    /// Starts the model from `prior`, demonstrations given before the run (they spend no
    /// budget and are not among [`ExpertCore::demos`]); the model is fitted on them, then on
    /// them and the run's demonstrations.
    pub fn set_prior(&mut self, prior: Vec<DemoRecord>) -> Result<(), DemoModelError> {
        self.prior = prior.into();
        self.replaced();
        self.refit()
    }

    /// Restores the demonstrations of an earlier expert process (its `demos.jsonl`): the budget
    /// left and the model are those they imply. Demonstrations the model already covers (no
    /// run's demonstrations yet after [`ExpertCore::set_prior`], say) keep it as it is: a refit
    /// would give the same model.
    pub fn restore(&mut self, records: Vec<DemoRecord>) -> Result<(), DemoModelError> {
        self.budget = Budget::with_used(self.budget.total(), records.len() as u32);
        if records == self.demos && self.out.is_none() && !self.stale() {
            return Ok(());
        }
        self.demos = records;
        self.replaced();
        self.refit()
    }

    /// The demonstrations were replaced: the grown factors and any refit out are of old ones.
    fn replaced(&mut self) {
        self.krr = None;
        self.nystrom = None;
        self.epoch += 1;
    }

    pub fn snapshot(&self) -> ExpertSnapshot {
        ExpertSnapshot {
            demos: self.demos.clone(),
            model_version: self.model_version,
        }
    }

    /// Restores [`ExpertCore::snapshot`]: the demonstrations, the budget they spent, the model
    /// refitted on them (deterministic: the model the run had).
    pub fn restore_snapshot(&mut self, s: &ExpertSnapshot) -> Result<(), StateMismatch> {
        if s.demos.len() > self.budget.total() as usize {
            return Err(StateMismatch(format!(
                "{} demonstrations against a budget of {}",
                s.demos.len(),
                self.budget.total()
            )));
        }
        self.restore(s.demos.clone())
            .map_err(|e| StateMismatch(format!("demonstration model: {e}")))?;
        self.model_version = s.model_version;
        Ok(())
    }

    /// Spends one unit of budget on `action`, the demonstrator's answer at `state` (global step
    /// `step`), records it and refits the model (unless refits are deferred:
    /// [`ExpertCore::defer_refits`]). `None` when the budget is exhausted.
    pub fn record(
        &mut self,
        state: &[f64],
        action: usize,
        step: u64,
        expert: &str,
    ) -> Option<&DemoRecord> {
        self.record_weighted(state, action, step, expert, 1.0)
    }

    /// [`ExpertCore::record`] with the demonstration's weight in the model (KRR weighs it;
    /// see [`DemoRecord::weight`]).
    pub fn record_weighted(
        &mut self,
        state: &[f64],
        action: usize,
        step: u64,
        expert: &str,
        weight: f64,
    ) -> Option<&DemoRecord> {
        if !self.budget.try_spend() {
            return None;
        }
        self.demos.push(DemoRecord {
            index: self.demos.len() as u32,
            state: state.to_vec(),
            action,
            step,
            expert: expert.to_owned(),
            weight,
        });
        if !self.deferred {
            if let Err(e) = self.refit() {
                tracing::warn!(error = %e, "demonstration model not refitted");
            }
        }
        self.demos.last()
    }

    /// Asks `demonstrator` at `obs` if budget remains (Algorithm 1 lines 8-10).
    pub fn answer(
        &mut self,
        demonstrator: &mut dyn Demonstrator<[f32]>,
        obs: &[f32],
        step: u64,
        expert: &str,
    ) -> Option<usize> {
        if self.budget.is_exhausted() {
            return None;
        }
        let action = demonstrator.act(obs);
        let state: Vec<f64> = obs.iter().map(|&x| f64::from(x)).collect();
        self.record(&state, action, step, expert).map(|d| d.action)
    }

    /// The model refitted on every demonstration now, here.
    fn refit(&mut self) -> Result<(), DemoModelError> {
        let job = self.take_refit_job();
        self.finish_refit(job.run())
    }

    /// From now on [`ExpertCore::record`] leaves the refit to the caller, who takes it out with
    /// [`ExpertCore::refit_job`], runs it where it likes, and gives it back with
    /// [`ExpertCore::finish_refit`]: the expert process answers while the model fits.
    pub fn defer_refits(&mut self) {
        self.deferred = true;
    }

    /// Whether [`ExpertCore::record`] leaves the refit to the caller.
    pub fn refits_deferred(&self) -> bool {
        self.deferred
    }

    /// Whether a refit is out ([`ExpertCore::refit_job`] taken, not yet given back).
    pub fn refit_out(&self) -> bool {
        self.out.is_some()
    }

    /// Whether the model is older than the demonstrations (a deferred refit is owed).
    pub fn stale(&self) -> bool {
        self.choice != DemoModelChoice::None && self.fitted != self.model_demos()
    }

    /// The refit the model owes, taken out of the core to run elsewhere (its grown factor goes
    /// with it); `None` when the model is up to date or a refit is out already.
    pub fn refit_job(&mut self) -> Option<RefitJob> {
        (self.out.is_none() && self.stale()).then(|| self.take_refit_job())
    }

    fn take_refit_job(&mut self) -> RefitJob {
        self.out = Some(self.epoch);
        // The prior demonstrations first, so that the grown factors keep their rows; none to
        // copy when no model is kept.
        let (prior, run) = if self.choice == DemoModelChoice::None {
            (Arc::from([]), Vec::new())
        } else {
            (Arc::clone(&self.prior), self.demos.clone())
        };
        RefitJob::new(
            self.epoch,
            self.choice,
            (prior, run),
            self.num_actions,
            (self.krr.take(), self.nystrom.take()),
            self.lanes.clone(),
        )
    }

    /// Takes back a refit ([`ExpertCore::refit_job`]): its model and grown factor become the
    /// core's, unless the demonstrations were replaced since it went out (then it is dropped).
    /// The model stays as it was if the refit failed.
    pub fn finish_refit(&mut self, r: Refitted) -> Result<(), DemoModelError> {
        if self.out == Some(r.epoch) {
            self.out = None;
        }
        if r.epoch != self.epoch {
            return Ok(());
        }
        let (krr, nystrom) = r.factors;
        (self.krr, self.nystrom) = (krr, nystrom);
        // Tried on these: a failed refit is tried again at the next demonstration, not at once.
        self.fitted = r.covers;
        match r.outcome? {
            RefitOutcome::Unchanged => {}
            RefitOutcome::Cleared => self.model = None,
            RefitOutcome::Fitted(model) => {
                self.model = Some(model);
                self.model_version += 1;
            }
        }
        Ok(())
    }

    /// The actions the environment offers (and the demonstration model chooses among).
    pub fn num_actions(&self) -> usize {
        self.num_actions
    }

    pub fn budget(&self) -> Budget {
        self.budget
    }

    pub fn demos(&self) -> &[DemoRecord] {
        &self.demos
    }

    pub fn model(&self) -> Option<&DemoModel> {
        self.model.as_ref()
    }

    /// Incremented on every refit.
    pub fn model_version(&self) -> u64 {
        self.model_version
    }

    /// The global step of the last demonstration (0 before any).
    pub fn last_demo_step(&self) -> u64 {
        self.demos.last().map_or(0, |d| d.step)
    }

    /// The run's demonstrations (not the prior ones) the current model was fitted on: every one
    /// recorded, unless a deferred refit is still owed. With no model kept, every one recorded.
    pub fn model_run_demos(&self) -> u32 {
        if self.choice == DemoModelChoice::None {
            return self.budget.used();
        }
        self.fitted.saturating_sub(self.prior.len()) as u32
    }

    /// The demonstrations the model is fitted on: the prior ones and the run's.
    pub fn model_demos(&self) -> usize {
        self.prior.len() + self.demos.len()
    }

    /// The model to shape the reward of global step `step` with, if shaping is on then.
    pub fn shaping_model(&self, step: u64) -> Option<(&DemoModel, f64)> {
        self.schedule.model_for(
            step,
            self.model_demos(),
            self.last_demo_step(),
            self.model.as_ref(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Demonstration `i` of a scattered two-dimensional set.
    fn demo(i: usize) -> (Vec<f64>, usize) {
        let t = i as f64;
        (vec![(t * 0.7).sin() * 2.0, (t * 1.3).cos()], i % 2)
    }

    #[test]
    fn an_expert_that_becomes_another_answers_as_it_after_its_first_answers() {
        let table = |a| Box::new(TablePolicy { actions: vec![a] });
        let mut e = Becomes::new(table(1), table(3), 2);
        let answers: Vec<usize> = (0..4).map(|_| e.act(&0)).collect();
        assert_eq!(answers, [1, 1, 3, 3]);
    }

    #[test]
    fn deferred_refits_run_outside_and_give_the_inline_model() {
        let schedule = crate::config::ShapingConfig::default().schedule();
        for choice in [
            DemoModelChoice::Krr,
            DemoModelChoice::Nystrom,
            DemoModelChoice::Svm,
        ] {
            let mut inline = ExpertCore::new(10, choice, 2, schedule);
            let mut deferred = ExpertCore::new(10, choice, 2, schedule);
            deferred.defer_refits();
            let record = |core: &mut ExpertCore, i: usize| {
                let (s, a) = demo(i);
                core.record(&s, a, i as u64, "e").unwrap();
            };
            for i in 0..4 {
                record(&mut inline, i);
                record(&mut deferred, i);
            }
            assert!(deferred.model().is_none() && deferred.stale(), "{choice:?}");
            let job = deferred.refit_job().expect("a refit is owed");
            assert_eq!(job.covers(), 4);
            assert!(deferred.refit_job().is_none(), "one refit out at a time");
            // Two more demonstrations arrive while it runs: the model it gives is of four.
            for i in 4..6 {
                record(&mut inline, i);
                record(&mut deferred, i);
            }
            assert_eq!(deferred.model_run_demos(), 0);
            deferred.finish_refit(job.run()).unwrap();
            assert_eq!(deferred.model_version(), 1);
            assert!(deferred.stale());
            assert_eq!(
                (deferred.model_run_demos(), inline.model_run_demos()),
                (4, 6)
            );
            let job = deferred.refit_job().expect("the two newcomers are owed");
            assert_eq!(job.covers(), 6);
            // Grown on one lane, as beside the query path: the same model.
            deferred.finish_refit(job.in_background().run()).unwrap();
            assert!(!deferred.stale() && deferred.refit_job().is_none());
            assert_eq!(deferred.model(), inline.model(), "{choice:?}");
        }
    }

    #[test]
    fn a_refit_out_when_the_demonstrations_are_replaced_is_dropped() {
        let schedule = crate::config::ShapingConfig::default().schedule();
        let mut core = ExpertCore::new(10, DemoModelChoice::Krr, 2, schedule);
        core.defer_refits();
        for i in 0..3 {
            let (s, a) = demo(i);
            core.record(&s, a, 0, "e").unwrap();
        }
        let job = core.refit_job().unwrap();
        let kept: Vec<DemoRecord> = core.demos()[..1].to_vec();
        core.restore(kept).unwrap();
        let version = core.model_version();
        assert_eq!(core.model().unwrap().num_actions(), 2);
        core.finish_refit(job.run()).unwrap();
        assert_eq!(
            core.model_version(),
            version,
            "the old refit changed nothing"
        );
        assert!(!core.stale(), "the restore refitted at once");
        let (s, a) = demo(7);
        core.record(&s, a, 0, "e").unwrap();
        assert!(core.refit_job().is_some(), "a new refit may go out");
    }

    #[test]
    fn prior_demonstrations_shape_the_model_but_spend_no_budget() {
        let schedule = crate::config::ShapingConfig::default().schedule();
        let record = |i: usize| DemoRecord {
            index: i as u32,
            state: vec![i as f64 * 0.3 - 1.0, (i as f64).sin()],
            action: i % 2,
            step: 0,
            expert: "prior".into(),
            weight: 1.0,
        };
        let prior: Vec<DemoRecord> = (0..6).map(record).collect();
        for choice in [
            DemoModelChoice::Krr,
            DemoModelChoice::Nystrom,
            DemoModelChoice::Svm,
        ] {
            let mut core = ExpertCore::new(2, choice, 2, schedule);
            core.set_prior(prior.clone()).unwrap();
            assert!(core.model().is_some() && core.demos().is_empty());
            assert_eq!(core.budget().used(), 0);
            // Becoming active with no run's demonstrations keeps the prior's model, unrefitted.
            let (model, version) = (core.model().cloned(), core.model_version());
            core.restore(Vec::new()).unwrap();
            assert_eq!(
                (core.model().cloned(), core.model_version()),
                (model, version)
            );
            for i in 6..9 {
                let d = record(i);
                let given = core
                    .record(&d.state, d.action, 10 + i as u64, "e")
                    .is_some();
                assert_eq!(given, i < 8, "budget 2: the prior spent none of it");
            }
            assert_eq!(core.demos().len(), 2);
            // The same model as one fitted on the prior and the run's demonstrations at once.
            let mut all = ExpertCore::new(8, choice, 2, schedule);
            all.restore((0..8).map(record).collect()).unwrap();
            let s = [0.1, -0.4];
            assert_eq!(
                core.model().unwrap().probs(&s),
                all.model().unwrap().probs(&s),
                "{choice:?}"
            );
        }
    }

    /// The model after each demonstration, grown, against the model of the same demonstrations
    /// restored at once (as a restarted expert fits it).
    fn grown_and_restored(choice: DemoModelChoice, n: usize) -> (DemoModel, DemoModel) {
        let schedule = crate::config::ShapingConfig::default().schedule();
        let mut core = ExpertCore::new(n as u32, choice, 2, schedule);
        for i in 0..n {
            let x = i as f64;
            let state = [(x * 0.37).sin() * 3.0, (x * 0.11).cos() * 3.0];
            core.record(&state, usize::from(state[0] > 0.0), i as u64, "e")
                .expect("budget left");
        }
        let mut restored = ExpertCore::new(n as u32, choice, 2, schedule);
        restored.restore(core.demos().to_vec()).unwrap();
        (
            core.model().cloned().unwrap(),
            restored.model().cloned().unwrap(),
        )
    }

    #[test]
    fn the_kernel_models_grown_a_demonstration_at_a_time_are_those_fitted_on_restore() {
        for choice in [DemoModelChoice::Krr, DemoModelChoice::Nystrom] {
            let n = crate::demo_model::nystrom::LANDMARKS + 20;
            let (grown, restored) = grown_and_restored(choice, n);
            assert_eq!(grown, restored, "{choice:?}");
            assert_eq!(grown.num_demos(), n);
        }
    }

    #[test]
    fn a_demonstration_s_weight_reaches_the_model_and_weight_zero_leaves_it_out() {
        let schedule = crate::config::ShapingConfig::default().schedule();
        let probs = |second_weight: f64| {
            let mut core = ExpertCore::new(10, DemoModelChoice::Krr, 2, schedule);
            core.record_weighted(&[0.0, 0.0], 0, 1, "a", 1.0).unwrap();
            core.record_weighted(&[0.0, 0.0], 1, 2, "b", second_weight)
                .unwrap();
            core.model().unwrap().probs(&[0.0, 0.0])
        };
        // Contradicting answers at one state: even odds at equal weights; the zero-weight answer
        // counts for nothing, as if only the first had been given.
        let even = probs(1.0);
        assert!((even[0] - even[1]).abs() < 1e-12, "{even:?}");
        let mut alone = ExpertCore::new(10, DemoModelChoice::Krr, 2, schedule);
        alone.record(&[0.0, 0.0], 0, 1, "a").unwrap();
        assert_eq!(probs(0.0), alone.model().unwrap().probs(&[0.0, 0.0]));
        let half = probs(0.5);
        assert!(half[0] > half[1] && half[1] > 0.0, "{half:?}");
    }
}
