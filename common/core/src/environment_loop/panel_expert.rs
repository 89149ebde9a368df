//! Several experts beside the actor (`[[experts]]`, in one process): each query goes where the
//! [`Panel`] routes it, a second expert is sometimes asked the same state, and every answer is
//! a demonstration of its expert at its cost. An answer's reward for the panel's quality
//! estimate is the share of the state's other opinions it agrees with: the second expert's
//! answer on a double ask, and the greedy action of the demonstration model fitted so far (on
//! every expert's demonstrations); with `expert.quality_from_returns`, also the rank of the
//! return of each episode an expert answered in ([`Returns`]).

use crate::agent::{Demonstrator, ExpertCore};
use crate::config::{ExperimentConfig, Weighting};
use crate::panel::{Ask, Asker, Member, Panel, Quality, Returns};
use crate::policy::argmax;
use crate::rng::{derive_seed, seeded, Rng};

use super::{LoopError, Result};

/// One row of `experts.csv`: an expert's quality as the run saw it after one of its answers.
#[derive(Debug, Clone, PartialEq)]
pub struct QualityRow {
    pub step: u64,
    pub expert: usize,
    pub quality: Quality,
}

/// What a run with several experts leaves: per demonstration, in order, its cost and whether its
/// state was asked twice; the quality rows; the experts' names, the cost spent, and the experts
/// marked down (failed to answer), in order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PanelLog {
    pub names: Vec<String>,
    pub answers: Vec<(f64, bool)>,
    pub rows: Vec<QualityRow>,
    pub spent: f64,
    pub down: Vec<String>,
}

impl PanelLog {
    /// `experts.csv`: `step,expert,answers,quality,low,high`, one row per answer.
    pub fn csv(&self) -> String {
        let mut out = Self::CSV_HEADER.to_owned();
        for r in &self.rows {
            out.push_str(&self.csv_line(r));
        }
        out
    }

    /// The header line of `experts.csv`.
    pub const CSV_HEADER: &'static str = "step,expert,answers,quality,low,high\n";

    /// One row of `experts.csv`, its line ending included.
    pub fn csv_line(&self, r: &QualityRow) -> String {
        let q = r.quality;
        format!(
            "{},{},{},{},{},{}\n",
            r.step, self.names[r.expert], q.answers, q.quality, q.low, q.high
        )
    }
}

/// What a query the panel routed leads to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Routed {
    /// Answered with the action to act on (the first expert's, or on an escalation the
    /// second's), or `None`: the budget or the cost budget is spent.
    Answered(Option<usize>),
    /// The person is asked first: the state is shown to them, and their answer given to
    /// [`PanelAsk::person_answered`] with this ask.
    Person(Ask),
}

/// The experts of a run and the panel that routes its queries among them.
pub struct PanelAsk<'d, S: ?Sized> {
    members: Vec<Box<dyn Demonstrator<S> + 'd>>,
    /// The member that is a person (answering on a page, later), if any.
    person: Option<usize>,
    panel: Panel,
    returns: Option<Returns>,
    rng: Rng,
    cost_budget: Option<f64>,
    weighted: bool,
    log: PanelLog,
}

impl<'d, S: ?Sized> PanelAsk<'d, S> {
    /// The panel of `cfg`'s `[[experts]]`, `members` their demonstrators in the same order,
    /// choosing among `actions` actions.
    pub fn new(
        cfg: &ExperimentConfig,
        members: Vec<Box<dyn Demonstrator<S> + 'd>>,
        actions: usize,
    ) -> Self {
        assert_eq!(
            members.len(),
            cfg.experts.len(),
            "one demonstrator per expert"
        );
        let panel_members = cfg
            .experts
            .iter()
            .map(|e| Member {
                name: e.name.clone(),
                cost: e.cost,
            })
            .collect();
        let e = &cfg.expert;
        Self {
            members,
            person: None,
            panel: Panel::new(
                panel_members,
                e.route,
                cfg.best_known(),
                e.double_ask,
                e.quality_window,
            )
            .with_actions(actions),
            returns: e
                .quality_from_returns
                .then(|| Returns::new(e.quality_window)),
            rng: seeded(derive_seed(cfg.seed, "panel")),
            cost_budget: cfg.budget.cost,
            weighted: cfg.demos.weighting == Weighting::Quality,
            log: PanelLog {
                names: cfg.experts.iter().map(|e| e.name.clone()).collect(),
                ..PanelLog::default()
            },
        }
    }

    /// What the experts did so far (its `spent` is set by [`PanelAsk::into_log`]).
    pub fn log(&self) -> &PanelLog {
        &self.log
    }

    pub fn into_log(mut self) -> PanelLog {
        self.log.spent = self.panel.spent();
        self.log
    }

    /// Whether the cost budget allows one more answer of `expert`.
    fn affordable(&self, expert: usize) -> bool {
        let cost = self.panel.members()[expert].cost;
        self.cost_budget
            .is_none_or(|b| self.panel.spent() + cost <= b + 1e-9)
    }

    /// Expert `i`'s quality as the run sees it now.
    pub fn quality(&self, i: usize) -> Quality {
        self.panel.quality(i)
    }

    /// Whether any expert can still be paid.
    pub fn can_pay(&self) -> bool {
        (0..self.panel.members().len()).any(|i| self.affordable(i))
    }

    /// Member `i` is a person: a query routed to them first is handed back
    /// ([`Routed::Person`]) instead of asked, and they are never the second of a double ask.
    pub fn with_person(mut self, i: usize) -> Self {
        self.person = Some(i);
        self.panel.never_second(i);
        self
    }

    /// Asks the state `obs` (features `x`) at global step `step`, from `asker`: the routed
    /// expert's action, recorded in `core` as a demonstration, and on a double ask a second
    /// expert's too; `None` when the budget or the cost budget is spent. An expert that fails
    /// to answer is marked down and the state goes to another; an error only when every expert
    /// is down, or when the state is routed to a person (who answers in `alfd run` only).
    pub fn ask(
        &mut self,
        core: &mut ExpertCore,
        state: (&S, &[f64]),
        step: u64,
        asker: Asker,
    ) -> Result<Option<usize>> {
        match self.route_or_answer(core, state, step, asker)? {
            Routed::Answered(action) => Ok(action),
            Routed::Person(_) => Err(LoopError::link(
                "a person among [[experts]] answers in `alfd run` only",
            )),
        }
    }

    /// [`PanelAsk::ask`], but a state routed to the person first comes back as
    /// [`Routed::Person`], unanswered. First, the return of the asker's episode before this one
    /// rewards the experts that answered in it (with `expert.quality_from_returns`).
    pub fn route_or_answer(
        &mut self,
        core: &mut ExpertCore,
        (obs, x): (&S, &[f64]),
        step: u64,
        asker: Asker,
    ) -> Result<Routed> {
        for (expert, reward) in self.returns.as_mut().map_or(Vec::new(), |r| r.asked(asker)) {
            self.panel.reward(expert, reward);
        }
        let mut failure = None;
        let (ask, first) = loop {
            let Some(ask) = self.panel.route(&mut self.rng) else {
                return Err(failure.unwrap_or_else(|| LoopError::link("every expert is down")));
            };
            if core.budget().is_exhausted() || !self.affordable(ask.first) {
                return Ok(Routed::Answered(None));
            }
            if Some(ask.first) == self.person {
                return Ok(Routed::Person(ask));
            }
            match self.act(ask.first, obs) {
                Ok(action) => break (ask, action),
                Err(e) => failure = Some(self.down(ask.first, e)),
            }
        };
        let action = self.answered(core, (obs, x), (step, asker), (ask, first));
        Ok(Routed::Answered(Some(action)))
    }

    /// The person's `action` on a state the panel routed to them (`ask`, from
    /// [`Routed::Person`]): recorded as their demonstration, with the second expert's on a
    /// double ask; `None` (nothing recorded) when the budget or the cost budget ran out while
    /// they decided.
    pub fn person_answered(
        &mut self,
        core: &mut ExpertCore,
        state: (&S, &[f64]),
        (step, asker): (u64, Asker),
        ask: Ask,
        action: usize,
    ) -> Option<usize> {
        if core.budget().is_exhausted() || !self.affordable(ask.first) {
            return None;
        }
        Some(self.answered(core, state, (step, asker), (ask, action)))
    }

    /// The first expert answered `first`: the second asked on a double ask or an escalation,
    /// both recorded; the action to act on (the second's on an escalation it answered).
    fn answered(
        &mut self,
        core: &mut ExpertCore,
        (obs, x): (&S, &[f64]),
        (step, asker): (u64, Asker),
        (ask, first): (Ask, usize),
    ) -> usize {
        // The demonstration model's opinion on the state, before either answer is recorded.
        let model = core.model().map(|m| argmax(&m.probs(x)));
        let escalated = self.escalation(model, ask, first);
        let second = match escalated.or(ask.second).filter(|&s| self.affordable(s)) {
            Some(s) => match self.act(s, obs) {
                Ok(action) => Some((s, action)),
                Err(e) => {
                    self.down(s, e);
                    None
                }
            },
            None => None,
        };
        // An escalation's second answer that differs overrules the first.
        let overruled = second.is_some_and(|(s, a)| escalated == Some(s) && a != first);
        let recorded = self.record(
            core,
            (x, step),
            model,
            (ask.first, first),
            second,
            overruled,
        );
        for &expert in &recorded {
            if let Some(r) = &mut self.returns {
                r.answered(asker.actor, expert);
            }
        }
        match second {
            Some((s, action)) if escalated == Some(s) && recorded.contains(&s) => action,
            _ => first,
        }
    }

    /// With [`Route::Escalate`](crate::panel::Route::Escalate): the expert above the first when
    /// the first's answer `first` disagrees with the demonstration model's greedy action `model`
    /// (or no model is fitted yet).
    fn escalation(&self, model: Option<usize>, ask: Ask, first: usize) -> Option<usize> {
        if !self.panel.escalates() {
            return None;
        }
        (model != Some(first))
            .then(|| self.panel.above(ask.first))
            .flatten()
    }

    /// Records each answer on the state `x` as a demonstration (while the budget lasts), rated
    /// against the other answer and the demonstration model's (`model`); the first at weight 0
    /// when `overruled` (an escalation's second answer differs: kept, and left out of the
    /// model); the experts recorded.
    fn record(
        &mut self,
        core: &mut ExpertCore,
        (x, step): (&[f64], u64),
        model: Option<usize>,
        first: (usize, usize),
        second: Option<(usize, usize)>,
        overruled: bool,
    ) -> Vec<usize> {
        let mut recorded = Vec::new();
        let double = second.is_some();
        let mut answers = vec![first];
        answers.extend(second);
        for (i, &(expert, action)) in answers.iter().enumerate() {
            let others = answers
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, &(_, a))| a)
                .chain(model);
            let (agreed, opinions) =
                others.fold((0, 0), |(g, n), a| (g + usize::from(a == action), n + 1));
            let name = self.panel.members()[expert].name.clone();
            // Weighted by what the run knew of the expert before this answer.
            let weight = match self.weighted {
                _ if i == 0 && overruled => 0.0,
                true => self.panel.quality(expert).quality,
                false => 1.0,
            };
            if core
                .record_weighted(x, action, step, &name, weight)
                .is_none()
            {
                break;
            }
            self.panel.answered(expert, agreed, opinions);
            recorded.push(expert);
            let cost = self.panel.members()[expert].cost;
            self.log.answers.push((cost, double));
            self.log.rows.push(QualityRow {
                step,
                expert,
                quality: self.panel.quality(expert),
            });
        }
        recorded
    }

    /// Marks `expert` down after its failure `e`, which it gives back.
    fn down(&mut self, expert: usize, e: LoopError) -> LoopError {
        let wait = self.panel.set_down(expert);
        tracing::warn!("{e}; its queries go to the other experts, for the next {wait} queries");
        self.log
            .down
            .push(self.panel.members()[expert].name.clone());
        e
    }

    fn act(&mut self, expert: usize, obs: &S) -> Result<usize> {
        self.members[expert].try_act(obs).map_err(|e| {
            let name = &self.panel.members()[expert].name;
            LoopError::link(format!("the expert `{name}`: {e}"))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An expert that always answers `0`: its action.
    struct Always(usize);

    impl Demonstrator<[f32]> for Always {
        fn act(&mut self, _: &[f32]) -> usize {
            self.0
        }
    }

    /// The one actor of these tests, in its first episode.
    const ME: Asker = Asker {
        actor: 0,
        episode: 0,
        last_return: None,
    };

    fn setup(extra: &str) -> (ExperimentConfig, ExpertCore, PanelAsk<'static, [f32]>) {
        setup_routed("route = \"round-robin\"\ndouble_ask = 1.0\n", extra)
    }

    /// [`setup`] with `[expert]` settings of one's own (`route`, `double_ask`).
    fn setup_routed(
        expert: &str,
        extra: &str,
    ) -> (ExperimentConfig, ExpertCore, PanelAsk<'static, [f32]>) {
        let cfg = ExperimentConfig::from_toml(&format!(
            "seed = 1\nepisodes = 3\n[env]\nname = \"mountaincar\"\n[agent]\nkind = \"bdqn\"\n\
             [expert]\n{expert}{extra}\
             [[experts]]\nname = \"mountaincar-energy\"\ncost = 10\n\
             [[experts]]\nname = \"mountaincar-fair\"\ncost = 2\n\
             [[experts]]\nname = \"mountaincar-poor\"\n"
        ))
        .unwrap();
        let core = ExpertCore::for_config(&cfg, 3);
        let members: Vec<Box<dyn Demonstrator<[f32]>>> = vec![
            Box::new(Always(2)),
            Box::new(Always(2)),
            Box::new(Always(0)),
        ];
        let ask = PanelAsk::new(&cfg, members, 2);
        (cfg, core, ask)
    }

    #[test]
    fn a_double_ask_records_both_answers_at_their_costs_and_rates_them_against_each_other() {
        let (_, mut core, mut ask) = setup("[budget]\ntotal = 5\n");
        let x = [0.5f32, 0.0];
        // Round-robin: energy first; the second is the least answered other (fair, the first of
        // equals). Both say 2: each agrees with its one opinion.
        assert_eq!(
            ask.ask(&mut core, (&x, &[0.5, 0.0]), 7, ME).unwrap(),
            Some(2)
        );
        // Then fair, with poor asked too (fewest answers): 2 against 0, both disagree.
        assert_eq!(
            ask.ask(&mut core, (&x, &[0.5, 0.0]), 9, ME).unwrap(),
            Some(2)
        );
        let names: Vec<&str> = core.demos().iter().map(|d| d.expert.as_str()).collect();
        assert_eq!(
            names,
            [
                "mountaincar-energy",
                "mountaincar-fair",
                "mountaincar-fair",
                "mountaincar-poor"
            ]
        );
        // The fifth answer is the budget's last: poor first, its second ask not recorded.
        assert_eq!(
            ask.ask(&mut core, (&x, &[0.5, 0.0]), 11, ME).unwrap(),
            Some(0)
        );
        assert_eq!(core.demos().len(), 5);
        assert_eq!(
            ask.ask(&mut core, (&x, &[0.5, 0.0]), 12, ME).unwrap(),
            None,
            "the budget is spent"
        );
        let log = ask.into_log();
        assert_eq!(
            log.answers[..4],
            [(10.0, true), (2.0, true), (2.0, true), (1.0, true)]
        );
        assert_eq!(log.spent, 10.0 + 2.0 + 2.0 + 1.0 + 1.0);
        // fair: rewards 1 (with energy) then 0 (with poor).
        let fair: Vec<f64> = log
            .rows
            .iter()
            .filter(|r| r.expert == 1)
            .map(|r| r.quality.quality)
            .collect();
        assert_eq!(fair, [1.0, 0.5]);
        let csv = log.csv();
        assert!(
            csv.starts_with("step,expert,answers,quality,low,high\n7,mountaincar-energy,1,1,0,1\n"),
            "{csv}"
        );
    }

    #[test]
    fn escalate_asks_above_the_cheapest_where_the_model_disagrees_and_acts_on_that_answer() {
        let escalate = "route = \"escalate\"\ndouble_ask = 0.0\nmodel = \"krr\"\n";
        let (_, mut core, mut ask) = setup_routed(escalate, "[budget]\ntotal = 7\n");
        let (x, xf) = ([0.5f32, 0.0], [0.5, 0.0]);
        // No model yet: poor's 0 goes up to fair, whose 2 is acted on and overrules it: poor's
        // answer is kept at weight 0, fair's at its quality before it (0.5, unrated).
        assert_eq!(ask.ask(&mut core, (&x, &xf), 1, ME).unwrap(), Some(2));
        let weights: Vec<f64> = core.demos().iter().map(|d| d.weight).collect();
        assert_eq!(weights, [0.0, 0.5]);
        // The model fitted on 0 and 2 at this state: wherever its greedy action is poor's 0 no
        // one else is asked; where it is not, fair is, and acted on.
        let greedy = argmax(&core.model().unwrap().probs(&xf));
        let before = core.demos().len();
        let want = if greedy == 0 { 0 } else { 2 };
        assert_eq!(ask.ask(&mut core, (&x, &xf), 2, ME).unwrap(), Some(want));
        let asked = core.demos().len() - before;
        assert_eq!(asked, if greedy == 0 { 1 } else { 2 });
        let names: Vec<&str> = core.demos().iter().map(|d| d.expert.as_str()).collect();
        assert_eq!(names[..2], ["mountaincar-poor", "mountaincar-fair"]);
        let log = ask.into_log();
        assert_eq!(log.answers[..2], [(1.0, true), (2.0, true)]);
    }

    #[test]
    fn escalate_asks_no_one_else_where_the_cheapest_agrees_with_the_model() {
        let escalate = "route = \"escalate\"\ndouble_ask = 0.0\nmodel = \"krr\"\n";
        let (_, mut core, mut ask) = setup_routed(escalate, "[budget]\ntotal = 20\n");
        let (x, xf) = ([0.5f32, 0.0], [0.5, 0.0]);
        // Four demonstrations of 0 at this state: the model says 0.
        for step in 0..4 {
            core.record(&xf, 0, step, "mountaincar-poor");
        }
        assert_eq!(argmax(&core.model().unwrap().probs(&xf)), 0);
        assert_eq!(ask.ask(&mut core, (&x, &xf), 9, ME).unwrap(), Some(0));
        assert_eq!(core.demos().len(), 5);
        assert_eq!(ask.into_log().answers, [(1.0, false)]);
    }

    #[test]
    fn the_cost_budget_stops_the_answers_it_cannot_pay() {
        let (_, mut core, mut ask) = setup("[budget]\ntotal = 100\ncost = 13\n");
        let x = [0.5f32, 0.0];
        // energy (10) and fair (2): 12 spent, 1 left.
        assert_eq!(
            ask.ask(&mut core, (&x, &[0.5, 0.0]), 1, ME).unwrap(),
            Some(2)
        );
        assert!(ask.can_pay(), "poor costs 1");
        // fair (2) cannot be paid any more: no answer.
        assert_eq!(ask.ask(&mut core, (&x, &[0.5, 0.0]), 2, ME).unwrap(), None);
        // poor (1) can, but not its second expert.
        assert_eq!(
            ask.ask(&mut core, (&x, &[0.5, 0.0]), 3, ME).unwrap(),
            Some(0)
        );
        assert!(!ask.can_pay());
        assert_eq!(ask.into_log().spent, 13.0);
        assert_eq!(core.demos().len(), 3);
    }

    #[test]
    fn each_answer_weighs_its_expert_s_quality_before_it_unless_weighting_is_off() {
        let x = [0.5f32, 0.0];
        let (_, mut core, mut ask) = setup("[budget]\ntotal = 6\n");
        for step in 0..3 {
            ask.ask(&mut core, (&x, &[0.5, 0.0]), step, ME).unwrap();
        }
        let log = ask.into_log();
        let weights: Vec<f64> = core.demos().iter().map(|d| d.weight).collect();
        // The quality an expert had before each of its answers: 0.5 before any rating.
        let mut before = [0.5; 3];
        let expected: Vec<f64> = log
            .rows
            .iter()
            .map(|r| std::mem::replace(&mut before[r.expert], r.quality.quality))
            .collect();
        assert_eq!(weights, expected);
        assert!(weights.iter().any(|&w| w != 0.5), "{weights:?}");
        let (_, mut core, mut ask) = setup("[budget]\ntotal = 6\n[demos]\nweighting = \"none\"\n");
        for step in 0..3 {
            ask.ask(&mut core, (&x, &[0.5, 0.0]), step, ME).unwrap();
        }
        assert!(core.demos().iter().all(|d| d.weight == 1.0));
    }

    #[test]
    fn with_returns_on_the_rank_of_an_episode_s_return_rewards_the_experts_that_answered_in_it() {
        let cfg = ExperimentConfig::from_toml(
            "seed = 1\nepisodes = 3\n[env]\nname = \"mountaincar\"\n[agent]\nkind = \"bdqn\"\n\
             [expert]\nroute = \"round-robin\"\ndouble_ask = 0.0\nquality_from_returns = true\n\
             [[experts]]\nname = \"mountaincar-energy\"\n[[experts]]\nname = \"mountaincar-fair\"\n\
             [[experts]]\nname = \"mountaincar-poor\"\n",
        )
        .unwrap();
        let mut core = ExpertCore::for_config(&cfg, 3);
        let members: Vec<Box<dyn Demonstrator<[f32]>>> = vec![
            Box::new(Always(2)),
            Box::new(Always(1)),
            Box::new(Always(0)),
        ];
        let mut ask = PanelAsk::new(&cfg, members, 2);
        let x = [0.5f32, 0.0];
        // No demonstration model and no double ask: answers alone earn no reward. In turn,
        // one query per episode, with the return of the episode before.
        let returns = [None, Some(-100.0), Some(-50.0), Some(-150.0)];
        for (episode, last_return) in returns.into_iter().enumerate() {
            let asker = Asker {
                actor: 0,
                episode: episode as u64,
                last_return,
            };
            ask.ask(&mut core, (&x, &[0.5, 0.0]), episode as u64, asker)
                .unwrap();
        }
        // Episode 0 (energy): the first return, nothing to rank it against. Episode 1 (fair):
        // -50 above -100, rank 1. Episode 2 (poor): -150 below both, rank 0.
        let q: Vec<(u64, f64)> = (0..3)
            .map(|i| (ask.quality(i).answers, ask.quality(i).quality))
            .collect();
        assert_eq!(q, [(2, 0.5), (1, 1.0), (1, 0.0)]);
    }

    /// A person: never asked as a demonstrator (their answer comes from the page).
    struct Person;

    impl Demonstrator<[f32]> for Person {
        fn act(&mut self, _: &[f32]) -> usize {
            panic!("a person is not asked as a demonstrator")
        }
    }

    #[test]
    fn a_state_routed_to_the_person_waits_for_their_answer_then_is_recorded_with_the_second() {
        let cfg = ExperimentConfig::from_toml(
            "seed = 1\nepisodes = 3\n[env]\nname = \"mountaincar\"\n[agent]\nkind = \"bdqn\"\n\
             [budget]\ntotal = 3\n[expert]\nroute = \"best-known\"\ndouble_ask = 1.0\n\
             [[experts]]\nname = \"human\"\ncost = 10\n\
             [[experts]]\nname = \"mountaincar-fair\"\ncost = 2\n\
             [[experts]]\nname = \"mountaincar-poor\"\n",
        )
        .unwrap();
        let mut core = ExpertCore::for_config(&cfg, 3);
        let members: Vec<Box<dyn Demonstrator<[f32]>>> =
            vec![Box::new(Person), Box::new(Always(1)), Box::new(Always(0))];
        let mut ask = PanelAsk::new(&cfg, members, 2).with_person(0);
        let (x, f) = ([0.5f32, 0.0], [0.5, 0.0]);
        // The person is the best known: handed back, nothing asked or recorded yet.
        let Routed::Person(routed) = ask.route_or_answer(&mut core, (&x, &f), 4, ME).unwrap()
        else {
            panic!("not routed to the person");
        };
        assert_eq!((routed.first, routed.second), (0, Some(1)));
        assert!(core.demos().is_empty());
        // They answer 2: recorded first, then the second expert's answer on the same state.
        let got = ask.person_answered(&mut core, (&x, &f), (4, ME), routed, 2);
        assert_eq!(got, Some(2));
        let demos: Vec<(&str, usize)> = core
            .demos()
            .iter()
            .map(|d| (d.expert.as_str(), d.action))
            .collect();
        assert_eq!(demos, [("human", 2), ("mountaincar-fair", 1)]);
        // `alfd local` has no page: a state routed to the person is an error there.
        assert!(ask.ask(&mut core, (&x, &f), 5, ME).is_err());
        // One answer of the budget is left: the person's next one is recorded, its second not.
        let Routed::Person(routed) = ask.route_or_answer(&mut core, (&x, &f), 6, ME).unwrap()
        else {
            panic!("not routed to the person");
        };
        assert_eq!(
            ask.person_answered(&mut core, (&x, &f), (6, ME), routed, 1),
            Some(1)
        );
        assert_eq!(core.demos().len(), 3);
        assert_eq!(
            ask.person_answered(&mut core, (&x, &f), (7, ME), routed, 1),
            None
        );
        let log = ask.into_log();
        assert_eq!(log.spent, 10.0 + 2.0 + 10.0);
    }
}
