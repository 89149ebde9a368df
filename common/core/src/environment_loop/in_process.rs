//! The in-memory transports of the loop, for a run in one process (`alfd local`, `alfd sweep`):
//! the expert is an [`ExpertCore`] with a [`Demonstrator`] beside the actor, and the learner is a
//! [`NeuralLearner`] that the actor's adder feeds and whose network the actor reads.

use std::borrow::Borrow;
use std::cell::RefCell;

use super::panel_expert::{PanelAsk, PanelLog};
use super::{Adder, ExpertClient, LoopError, Result, VariableSource};
use crate::agent::{Demonstrator, ExpertCore, NeuralActor, NeuralLearner};
use crate::demo_model::DemoModel;
use crate::panel::EpisodeCount;
use crate::replay::Transition;

/// An observation as the expert records it in `demos.jsonl` and fits its model on.
pub trait Features {
    fn features(&self) -> Vec<f64>;
}

impl Features for usize {
    fn features(&self) -> Vec<f64> {
        vec![*self as f64]
    }
}

impl Features for Vec<f32> {
    fn features(&self) -> Vec<f64> {
        self.iter().map(|&x| f64::from(x)).collect()
    }
}

impl<const N: usize> Features for [f32; N] {
    fn features(&self) -> Vec<f64> {
        self.iter().map(|&x| f64::from(x)).collect()
    }
}

/// The expert in the actor's own process: a demonstrator answers, the [`ExpertCore`] keeps the
/// budget, the demonstrations and the model.
pub struct LocalExpert<'d, S: ?Sized> {
    pub core: ExpertCore,
    demonstrator: &'d mut dyn Demonstrator<S>,
    name: String,
    shaping: bool,
    /// Several experts (`[[experts]]`): they answer instead of `demonstrator`.
    panel: Option<PanelAsk<'d, S>>,
    /// The episodes this actor finished, and the last one's return, for the panel.
    episodes: EpisodeCount,
}

impl<S: ?Sized> std::fmt::Debug for LocalExpert<'_, S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LocalExpert")
            .field("name", &self.name)
            .field("shaping", &self.shaping)
            .field("demos", &self.core.demos().len())
            .finish()
    }
}

impl<'d, S: ?Sized> LocalExpert<'d, S> {
    /// `name` is recorded with each demonstration; `shaping` says whether the reward is shaped
    /// with the model at all.
    pub fn new(
        core: ExpertCore,
        demonstrator: &'d mut dyn Demonstrator<S>,
        name: &str,
        shaping: bool,
    ) -> Self {
        Self {
            core,
            demonstrator,
            name: name.to_owned(),
            shaping,
            panel: None,
            episodes: EpisodeCount::default(),
        }
    }

    /// Several experts answer, as `panel` routes each query.
    pub fn with_panel(mut self, panel: PanelAsk<'d, S>) -> Self {
        self.panel = Some(panel);
        self
    }

    /// The expert's core, and with several experts what they did.
    pub fn into_parts(self) -> (ExpertCore, Option<PanelLog>) {
        (self.core, self.panel.map(PanelAsk::into_log))
    }
}

impl<S: ?Sized, O: Borrow<S> + Features> ExpertClient<O> for LocalExpert<'_, S> {
    fn budget_left(&self) -> bool {
        !self.core.budget().is_exhausted() && self.panel.as_ref().is_none_or(PanelAsk::can_pay)
    }

    fn ask(&mut self, obs: &O, step: u64) -> Result<Option<usize>> {
        if let Some(panel) = &mut self.panel {
            let asker = self.episodes.asker(0);
            return panel.ask(&mut self.core, (obs.borrow(), &obs.features()), step, asker);
        }
        if self.core.budget().is_exhausted() {
            return Ok(None);
        }
        let action = self
            .demonstrator
            .try_act(obs.borrow())
            .map_err(|e| LoopError::link(format!("the expert `{}`: {e}", self.name)))?;
        Ok(self
            .core
            .record(&obs.features(), action, step, &self.name)
            .map(|d| d.action))
    }

    fn shaping(&self, step: u64) -> Option<(&DemoModel, f64)> {
        if self.shaping {
            self.core.shaping_model(step)
        } else {
            None
        }
    }

    fn demos_used(&self) -> u32 {
        self.core.budget().used()
    }

    fn episode_ended(&mut self, ret: f64) {
        self.episodes.ended(ret);
    }
}

/// A learner in the actor's own process. [`LearnerHandle::adder`] learns from each transition as
/// it is added (insert, then `U` updates); [`LearnerHandle::variables`] gives the actor the
/// learner's newest weights before each step, so the actor always acts on the newest weights.
#[derive(Debug)]
pub struct LearnerHandle {
    learner: RefCell<NeuralLearner>,
}

impl LearnerHandle {
    pub fn new(learner: NeuralLearner) -> Self {
        Self {
            learner: RefCell::new(learner),
        }
    }

    pub fn adder(&self) -> LocalAdder<'_> {
        LocalAdder { handle: self }
    }

    pub fn variables(&self) -> LocalVariables<'_> {
        LocalVariables {
            handle: self,
            version: None,
        }
    }

    /// The learner (not while the adder is adding).
    pub fn learner(&self) -> std::cell::Ref<'_, NeuralLearner> {
        self.learner.borrow()
    }

    pub fn into_inner(self) -> NeuralLearner {
        self.learner.into_inner()
    }
}

/// [`Adder`] into a [`LearnerHandle`].
#[derive(Debug)]
pub struct LocalAdder<'h> {
    handle: &'h LearnerHandle,
}

impl Adder for LocalAdder<'_> {
    fn add(&mut self, transition: Transition, _episode_end: bool) -> Result<()> {
        self.handle.learner.borrow_mut().learn(&transition);
        Ok(())
    }
}

/// [`VariableSource`] from a [`LearnerHandle`].
#[derive(Debug)]
pub struct LocalVariables<'h> {
    handle: &'h LearnerHandle,
    /// The learner's update count when the actor last took its weights.
    version: Option<u64>,
}

impl VariableSource for LocalVariables<'_> {
    fn update(&mut self, actor: &mut NeuralActor) -> Result<()> {
        let learner = self.handle.learner.borrow();
        if self.version != Some(learner.updates()) {
            actor.copy_weights_from(learner.network(), learner.updates());
            self.version = Some(learner.updates());
        }
        Ok(())
    }
}
