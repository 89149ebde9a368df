//! Several experts at once, as a pure state machine: which expert a query goes to (the route),
//! whether a second expert is asked the same state too (a double ask, the run's only way to
//! compare experts without a gold one), each expert's quality learned from what the run sees,
//! and the cost spent.
//!
//! Quality, after IEThresh (Donmez, Carbonell and Schneider, KDD 2009): each answer earns its
//! expert a reward, the share of the other opinions on that state it agrees with (a second
//! expert's answer on a double ask, the demonstration model fitted on the others' answers); an
//! expert's quality is the mean of its last `window` rewards, with a 95% interval (mean ± 1.96
//! standard errors, within [0, 1]; [0, 1] before two rewards). A change of an expert's quality
//! shows once its window has turned over.
//!
//! Routes: `best-known` always asks the expert named best in advance (for comparison);
//! `cheapest` the cheapest; `round-robin` each in turn; `interval` the cheapest expert whose
//! interval can still hold the best quality (its upper end at least every other expert's lower
//! end, IEThresh's rule); `upper-per-cost` the expert whose interval's upper end per unit of cost
//! is highest (optimism under uncertainty, paid for); `escalate` the cheapest, and, where its
//! answer disagrees with the demonstration model fitted so far (or there is none yet), the next
//! expert up the cost ladder too, whose answer the actor then acts on and which, when it
//! differs, overrules the first (kept at weight 0): pay for a better opinion only where the
//! cheap one is in doubt, after proactive learning's reliable and unreliable oracles;
//! `signal-per-cost` the expert with the most signal per unit of cost, signal being the square of
//! its agreement above chance (the upper end of its interval, rescaled so that agreeing by
//! chance with one of K actions is 0 and always agreeing 1). An answer that is right with
//! probability a and otherwise one of the other K - 1 actions at random carries
//! b = (K a - 1) / (K - 1) above chance; the answers needed to outvote such noise grow as 1 / b²,
//! so cost / b² is what one unit of agreement beyond chance costs. Agreement with other opinions
//! is b times theirs, so the rescaled quality orders experts as b does.
//!
//! With `expert.quality_from_returns`, the returns of the episodes that followed each expert's
//! advice are a third signal ([`Returns`]): when an episode in which experts answered ends, each
//! of them earns the episode's percentile rank among the returns of the episodes before it (one
//! reward per expert per episode, whatever its share of the episode's answers).
//!
//! An expert that fails to answer (its process gone, no answer in time) is marked down: the query
//! goes to the others, and no route asks it for the next [`RETRY_AFTER`] routed queries (twice
//! as many after each further failure); then it is up again, on trial (a process paused for a
//! while answers again). `best-known` with its expert down asks the cheapest expert up.

use std::collections::{BTreeMap, VecDeque};

use rand::Rng as _;
use serde::{Deserialize, Serialize};

use crate::rng::Rng;

/// Routed queries an expert marked down waits before it is asked again, after its first failure
/// (each further failure doubles its wait).
pub const RETRY_AFTER: u64 = 100;

/// How a query picks its expert.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Route {
    /// Always the expert named best in advance.
    BestKnown,
    /// The cheapest.
    Cheapest,
    /// Each in turn.
    RoundRobin,
    /// The cheapest whose quality interval can still hold the best quality.
    Interval,
    /// The highest upper end of the quality interval per unit of cost.
    UpperPerCost,
    /// The cheapest; where its answer disagrees with the demonstration model, the next expert
    /// up the cost ladder as well, whose answer is acted on.
    Escalate,
    /// The most agreement above chance, squared, per unit of cost (the upper end of the
    /// quality interval).
    SignalPerCost,
}

/// One expert of the panel: its name and what one answer costs.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    pub name: String,
    pub cost: f64,
}

/// Whom to ask about one state: `first` answers it; `second`, if any, is asked the same state to
/// compare (its answer costs too, and is a demonstration like any other).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ask {
    pub first: usize,
    pub second: Option<usize>,
}

/// An expert's quality as the run sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quality {
    pub answers: u64,
    pub quality: f64,
    pub low: f64,
    pub high: f64,
}

/// The panel: its experts, the route, and what was learned of them.
#[derive(Debug, Clone)]
pub struct Panel {
    members: Vec<Member>,
    route: Route,
    best_known: usize,
    double_ask: f64,
    window: usize,
    answers: Vec<u64>,
    rewards: Vec<VecDeque<f64>>,
    up: Vec<bool>,
    /// For an expert marked down: the routed query from which it is up again, and its wait.
    back_at: Vec<Option<u64>>,
    wait: Vec<u64>,
    /// Queries routed so far.
    routed: u64,
    /// Whether expert `i` may be the second of a double ask (a person is asked first or not
    /// at all: a second ask would hold the first answer up).
    second_ok: Vec<bool>,
    next: usize,
    spent: f64,
    /// The actions an expert chooses among (agreement by chance is one in this many).
    actions: usize,
}

impl Panel {
    /// A panel of `members` (at least one), routed by `route`; `best_known` is the expert
    /// `best-known` asks; a query is also asked of a second expert with probability
    /// `double_ask`; qualities are over each expert's last `window` rewards (at least 2).
    pub fn new(
        members: Vec<Member>,
        route: Route,
        best_known: usize,
        double_ask: f64,
        window: usize,
    ) -> Self {
        assert!(!members.is_empty() && best_known < members.len());
        let n = members.len();
        Self {
            members,
            route,
            best_known,
            double_ask: double_ask.clamp(0.0, 1.0),
            window: window.max(2),
            answers: vec![0; n],
            rewards: vec![VecDeque::new(); n],
            up: vec![true; n],
            back_at: vec![None; n],
            wait: vec![0; n],
            routed: 0,
            second_ok: vec![true; n],
            next: 0,
            spent: 0.0,
            actions: 2,
        }
    }

    /// The panel of experts choosing among `actions` actions (2 unless set; at least 2).
    pub fn with_actions(mut self, actions: usize) -> Self {
        self.actions = actions.max(2);
        self
    }

    pub fn members(&self) -> &[Member] {
        &self.members
    }

    /// The cost spent on answers so far.
    pub fn spent(&self) -> f64 {
        self.spent
    }

    /// Marks expert `i` down: no route asks it for the next [`RETRY_AFTER`] routed queries,
    /// twice as many as the last time after a further failure; the number of them.
    pub fn set_down(&mut self, i: usize) -> u64 {
        self.up[i] = false;
        self.wait[i] = (self.wait[i] * 2).max(RETRY_AFTER);
        self.back_at[i] = Some(self.routed + self.wait[i]);
        self.wait[i]
    }

    /// Brings the experts whose wait is over up again.
    fn retry(&mut self) {
        for i in 0..self.members.len() {
            if self.back_at[i].is_some_and(|at| self.routed >= at) {
                self.back_at[i] = None;
                self.up[i] = true;
            }
        }
    }

    /// Expert `i` is never the second of a double ask.
    pub fn never_second(&mut self, i: usize) {
        self.second_ok[i] = false;
    }

    /// Whether expert `i` is still asked.
    pub fn is_up(&self, i: usize) -> bool {
        self.up[i]
    }

    /// Whom to ask about the next state; `None` when every expert is down.
    pub fn route(&mut self, rng: &mut Rng) -> Option<Ask> {
        self.routed += 1;
        self.retry();
        if !self.up.contains(&true) {
            return None;
        }
        let first = match self.route {
            Route::BestKnown if self.up[self.best_known] => self.best_known,
            Route::BestKnown | Route::Cheapest | Route::Escalate => self.cheapest(|_| true),
            Route::RoundRobin => self.next_in_turn(),
            Route::Interval => {
                let q: Vec<Quality> = (0..self.members.len()).map(|i| self.quality(i)).collect();
                let best_low = (0..q.len())
                    .filter(|&i| self.up[i])
                    .map(|i| q[i].low)
                    .fold(0.0, f64::max);
                self.cheapest(|i| q[i].high >= best_low)
            }
            Route::UpperPerCost => {
                let value = |i: usize| self.quality(i).high / self.members[i].cost.max(1e-12);
                (0..self.members.len())
                    .filter(|&i| self.up[i])
                    .max_by(|&a, &b| value(a).total_cmp(&value(b)).then(b.cmp(&a)))
                    .expect("an expert is up")
            }
            Route::SignalPerCost => self.most_signal_per_cost(),
        };
        let second = (self.members.len() > 1 && rng.random::<f64>() < self.double_ask)
            .then(|| self.least_answered_but(first))
            .flatten();
        Some(Ask { first, second })
    }

    /// Whether an answer in doubt is checked by the next expert up the cost ladder
    /// ([`Route::Escalate`]).
    pub fn escalates(&self) -> bool {
        self.route == Route::Escalate
    }

    /// The expert a doubtful answer of `first` goes up to: the cheapest expert up that costs
    /// more than `first` and may be a second (the first of equal costs); `None` at the top.
    pub fn above(&self, first: usize) -> Option<usize> {
        let cost = self.members[first].cost;
        (0..self.members.len())
            .filter(|&i| self.up[i] && self.second_ok[i] && self.members[i].cost > cost)
            .min_by(|&a, &b| self.members[a].cost.total_cmp(&self.members[b].cost))
    }

    /// The expert up with the most agreement above chance, squared, per unit of cost (the upper
    /// end of its interval; the first of equals).
    fn most_signal_per_cost(&self) -> usize {
        let k = self.actions as f64;
        let value = |i: usize| {
            let above_chance = ((k * self.quality(i).high - 1.0) / (k - 1.0)).max(0.0);
            above_chance.powi(2) / self.members[i].cost.max(1e-12)
        };
        (0..self.members.len())
            .filter(|&i| self.up[i])
            .max_by(|&a, &b| value(a).total_cmp(&value(b)).then(b.cmp(&a)))
            .expect("an expert is up")
    }

    /// The next expert up in turn.
    fn next_in_turn(&mut self) -> usize {
        loop {
            let i = self.next % self.members.len();
            self.next = i + 1;
            if self.up[i] {
                return i;
            }
        }
    }

    /// Expert `expert` answered; `agreed` of the `opinions` other opinions on the state agree
    /// with its answer (no opinion: the answer counts, but earns no reward).
    pub fn answered(&mut self, expert: usize, agreed: usize, opinions: usize) {
        self.answers[expert] += 1;
        self.spent += self.members[expert].cost;
        if opinions > 0 {
            self.reward(expert, agreed.min(opinions) as f64 / opinions as f64);
        }
    }

    /// Expert `expert` earned `reward` (in [0, 1]): an answer's share of agreeing opinions, or
    /// a signal other than an answer of its own (an episode's return), into its quality window.
    pub fn reward(&mut self, expert: usize, reward: f64) {
        let r = &mut self.rewards[expert];
        r.push_back(reward.clamp(0.0, 1.0));
        if r.len() > self.window {
            r.pop_front();
        }
    }

    /// Expert `i`'s quality and its interval.
    pub fn quality(&self, i: usize) -> Quality {
        let r = &self.rewards[i];
        let n = r.len();
        let mean = if n == 0 {
            0.5
        } else {
            r.iter().sum::<f64>() / n as f64
        };
        let (low, high) = if n < 2 {
            (0.0, 1.0)
        } else {
            let var = r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            let half = 1.96 * (var / n as f64).sqrt();
            ((mean - half).max(0.0), (mean + half).min(1.0))
        };
        Quality {
            answers: self.answers[i],
            quality: mean,
            low,
            high,
        }
    }

    /// The cheapest expert up among those `ok` keeps (the first of equal costs); the cheapest
    /// up when `ok` keeps none.
    fn cheapest(&self, ok: impl Fn(usize) -> bool) -> usize {
        let pick = |keep: &dyn Fn(usize) -> bool| {
            (0..self.members.len())
                .filter(|&i| self.up[i] && keep(i))
                .min_by(|&a, &b| self.members[a].cost.total_cmp(&self.members[b].cost))
        };
        pick(&ok)
            .or_else(|| pick(&|_| true))
            .expect("an expert is up")
    }

    /// The expert up other than `first` with the fewest answers (the first of equals), among
    /// those that may be a second.
    fn least_answered_but(&self, first: usize) -> Option<usize> {
        (0..self.members.len())
            .filter(|&i| i != first && self.up[i] && self.second_ok[i])
            .min_by_key(|&i| self.answers[i])
    }
}

/// Where a query comes from: its actor, the actor's episode (its count of episodes finished),
/// and the return of the actor's episode before it (`None` in its first).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Asker {
    pub actor: u32,
    pub episode: u64,
    pub last_return: Option<f64>,
}

/// An actor's count of finished episodes and the last one's return: what its queries tell
/// several experts ([`Asker`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EpisodeCount {
    pub finished: u64,
    pub last_return: Option<f64>,
}

impl EpisodeCount {
    pub fn ended(&mut self, ret: f64) {
        self.finished += 1;
        self.last_return = Some(ret);
    }

    /// The asker `actor` is, with this count.
    pub fn asker(&self, actor: u32) -> Asker {
        Asker {
            actor,
            episode: self.finished,
            last_return: self.last_return,
        }
    }
}

/// Which experts answered in each actor's current episode, and the returns of the episodes that
/// ended since: when an actor's next episode asks, the episode before it is over and its return
/// known, and each expert that answered in it earns the return's percentile rank among the last
/// `window` such returns (the share of them below it, ties counting half; no reward for the
/// first). An episode whose return never comes (the actor asked nothing in the episode after it,
/// or restarted) earns nothing.
#[derive(Debug, Clone)]
pub struct Returns {
    window: usize,
    returns: VecDeque<f64>,
    open: BTreeMap<u32, (u64, Vec<usize>)>,
}

impl Returns {
    pub fn new(window: usize) -> Self {
        Self {
            window: window.max(1),
            returns: VecDeque::new(),
            open: BTreeMap::new(),
        }
    }

    /// A query from `asker`: closes the actor's episode before it if experts answered there; the
    /// rewards earned, as (expert, reward), each expert once.
    pub fn asked(&mut self, asker: Asker) -> Vec<(usize, f64)> {
        if self
            .open
            .get(&asker.actor)
            .is_some_and(|(episode, _)| *episode == asker.episode)
        {
            return Vec::new();
        }
        let closed = self.open.insert(asker.actor, (asker.episode, Vec::new()));
        // Only the episode just before this one has its return in the query.
        let Some((_, experts)) = closed.filter(|(episode, _)| episode + 1 == asker.episode) else {
            return Vec::new();
        };
        let Some(ret) = asker.last_return.filter(|r| r.is_finite()) else {
            return Vec::new();
        };
        let earned = self.rank(ret).map_or_else(Vec::new, |rank| {
            experts.into_iter().map(|e| (e, rank)).collect()
        });
        self.returns.push_back(ret);
        if self.returns.len() > self.window {
            self.returns.pop_front();
        }
        earned
    }

    /// `expert` answered a query of `actor` in its current episode.
    pub fn answered(&mut self, actor: u32, expert: usize) {
        if let Some((_, experts)) = self.open.get_mut(&actor) {
            if !experts.contains(&expert) {
                experts.push(expert);
            }
        }
    }

    /// The percentile rank of `ret` among the returns kept; `None` with none kept.
    fn rank(&self, ret: f64) -> Option<f64> {
        let n = self.returns.len();
        (n > 0).then(|| {
            let below = self.returns.iter().filter(|&&r| r < ret).count();
            let equal = self.returns.iter().filter(|&&r| r == ret).count();
            (below as f64 + 0.5 * equal as f64) / n as f64
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::seeded;

    fn asker(actor: u32, episode: u64, last_return: Option<f64>) -> Asker {
        Asker {
            actor,
            episode,
            last_return,
        }
    }

    #[test]
    fn an_episode_s_return_rewards_each_expert_that_answered_in_it_with_its_rank() {
        let mut r = Returns::new(3);
        assert!(r.asked(asker(0, 0, None)).is_empty());
        r.answered(0, 2);
        r.answered(0, 2);
        // The first return known: no earlier one to rank it against.
        assert!(r.asked(asker(0, 1, Some(-200.0))).is_empty());
        r.answered(0, 1);
        r.answered(0, 2);
        // A second query in the same episode closes nothing.
        assert!(r.asked(asker(0, 1, Some(-200.0))).is_empty());
        // -150 beats the one return kept (-200): rank 1, once for each of its two experts.
        assert_eq!(r.asked(asker(0, 2, Some(-150.0))), [(1, 1.0), (2, 1.0)]);
        r.answered(0, 0);
        // -200 against [-200, -150]: half a tie of two: 0.25.
        assert_eq!(r.asked(asker(0, 3, Some(-200.0))), [(0, 0.25)]);
        // An episode with no query in between (3 asked, then 5): its return is not 4's.
        r.answered(0, 0);
        assert!(r.asked(asker(0, 5, Some(-100.0))).is_empty());
        // Actors are apart: actor 1's episode 0 is its own; the window keeps the last 3.
        assert!(r.asked(asker(1, 0, None)).is_empty());
        r.answered(1, 0);
        // Kept: [-200, -150, -200]; -160 is above two: 2/3.
        let got = r.asked(asker(1, 1, Some(-160.0)));
        assert_eq!(got.len(), 1);
        assert!((got[0].1 - 2.0 / 3.0).abs() < 1e-12, "{got:?}");
        // Kept now [-150, -200, -160]: a NaN return is no return.
        r.answered(1, 1);
        assert!(r.asked(asker(1, 2, Some(f64::NAN))).is_empty());
    }

    #[test]
    fn a_reward_from_returns_enters_the_window_without_an_answer_or_a_cost() {
        let mut p = panel(Route::Interval, 0.0);
        p.reward(1, 1.0);
        p.reward(1, 0.0);
        p.reward(1, 7.0);
        let q = p.quality(1);
        assert_eq!(q.answers, 0);
        assert!((q.quality - 2.0 / 3.0).abs() < 1e-12, "{q:?}");
        assert_eq!(p.spent(), 0.0);
    }

    fn panel(route: Route, double_ask: f64) -> Panel {
        let m = |name: &str, cost| Member {
            name: name.into(),
            cost,
        };
        Panel::new(
            vec![m("good", 10.0), m("fair", 2.0), m("poor", 1.0)],
            route,
            0,
            double_ask,
            50,
        )
    }

    #[test]
    fn fixed_routes_ask_the_best_known_the_cheapest_or_each_in_turn() {
        let mut rng = seeded(1);
        let mut p = panel(Route::BestKnown, 0.0);
        assert_eq!(
            p.route(&mut rng).unwrap(),
            Ask {
                first: 0,
                second: None
            }
        );
        let mut p = panel(Route::Cheapest, 0.0);
        assert_eq!(p.route(&mut rng).unwrap().first, 2);
        let mut p = panel(Route::RoundRobin, 0.0);
        let firsts: Vec<usize> = (0..4).map(|_| p.route(&mut rng).unwrap().first).collect();
        assert_eq!(firsts, [0, 1, 2, 0]);
    }

    #[test]
    fn escalate_asks_the_cheapest_and_goes_up_the_cost_ladder_one_rung() {
        let mut rng = seeded(1);
        let mut p = panel(Route::Escalate, 0.0);
        assert!(p.escalates() && !panel(Route::Cheapest, 0.0).escalates());
        assert_eq!(p.route(&mut rng).unwrap().first, 2);
        // poor (1) goes up to fair (2), fair to good (10); good is the top.
        assert_eq!(
            (p.above(2), p.above(1), p.above(0)),
            (Some(1), Some(0), None)
        );
        // An expert down, or never a second, is passed over.
        p.set_down(1);
        assert_eq!(p.above(2), Some(0));
        p.never_second(0);
        assert_eq!(p.above(2), None);
    }

    #[test]
    fn answers_cost_and_earn_the_share_of_opinions_they_agree_with() {
        let mut p = panel(Route::Cheapest, 0.0);
        p.answered(2, 1, 2);
        p.answered(2, 0, 1);
        p.answered(1, 0, 0);
        assert_eq!(p.spent(), 1.0 + 1.0 + 2.0);
        // Rewards 0.5 and 0: mean 0.25, sample sd 0.3536, half-width 1.96 * 0.3536 / sqrt 2 = 0.49.
        let q = p.quality(2);
        assert_eq!((q.answers, q.quality), (2, 0.25));
        assert!((q.high - 0.74).abs() < 1e-9 && q.low == 0.0, "{q:?}");
        // No opinion: counted, unrated, the interval all of [0, 1].
        let q = p.quality(1);
        assert_eq!((q.answers, q.low, q.high), (1, 0.0, 1.0));
    }

    #[test]
    fn the_interval_route_asks_the_cheapest_expert_that_can_still_be_the_best() {
        let mut rng = seeded(2);
        let mut p = panel(Route::Interval, 0.0);
        // Nothing known: every interval is [0, 1], so the cheapest.
        assert_eq!(p.route(&mut rng).unwrap().first, 2);
        // The poor one disagrees always, the fair one half the time, the good one never.
        for _ in 0..20 {
            p.answered(2, 0, 1);
            p.answered(1, 0, 1);
            p.answered(1, 1, 1);
            p.answered(0, 1, 1);
        }
        // poor: [0, 0]; fair: 0.5 ± 1.96 * 0.5064 / sqrt 40 = [0.343, 0.657]; good: [1, 1].
        // Only the good one's upper end reaches the best lower end (1).
        assert_eq!(p.route(&mut rng).unwrap().first, 0);
        // Value per cost: good 1/10, fair 0.657/2, poor 0/1: the fair one.
        p.route = Route::UpperPerCost;
        assert_eq!(p.route(&mut rng).unwrap().first, 1);
    }

    #[test]
    fn signal_per_cost_asks_the_expert_whose_squared_agreement_above_chance_costs_least() {
        let mut rng = seeded(4);
        let mut p = panel(Route::SignalPerCost, 0.0).with_actions(3);
        // Nothing known: every upper end is 1 (all signal), so the cheapest.
        assert_eq!(p.route(&mut rng).unwrap().first, 2);
        // good agrees 9 times in 10, fair 8 in 10, poor 6 in 10 (100 answers each).
        let agree = |p: &mut Panel, expert, share: usize| {
            for k in 0..100 {
                p.answered(expert, usize::from(k % 10 < share), 1);
            }
        };
        agree(&mut p, 0, 9);
        agree(&mut p, 1, 8);
        agree(&mut p, 2, 6);
        let value = |p: &Panel, i: usize, cost: f64| {
            ((3.0 * p.quality(i).high - 1.0) / 2.0).max(0.0).powi(2) / cost
        };
        let (good, fair, poor) = (value(&p, 0, 10.0), value(&p, 1, 2.0), value(&p, 2, 1.0));
        // Upper ends 0.959, 0.879, 0.697: signal 0.939², 0.818², 0.546² per cost 10, 2, 1.
        assert!(fair > poor && poor > good, "{good} {fair} {poor}");
        assert_eq!(p.route(&mut rng).unwrap().first, 1);
        // The same agreements among two actions (chance 1/2): fair 0.758² / 2 = 0.29 against
        // poor 0.394² = 0.16; among many actions the poor one's signal nears its agreement,
        // 0.697² against fair's 0.879² / 2: the poor one.
        assert_eq!(p.clone().with_actions(2).route(&mut rng).unwrap().first, 1);
        assert_eq!(
            p.clone().with_actions(1000).route(&mut rng).unwrap().first,
            2
        );
        // An expert down is passed over.
        p.set_down(1);
        assert_eq!(p.route(&mut rng).unwrap().first, 2);
    }

    #[test]
    fn double_asks_go_to_the_least_answered_other_expert_at_their_rate() {
        let mut rng = seeded(3);
        let mut p = panel(Route::Cheapest, 0.25);
        let mut doubles = 0;
        for _ in 0..4000 {
            let ask = p.route(&mut rng).unwrap();
            if let Some(s) = ask.second {
                assert_ne!(s, ask.first);
                doubles += 1;
                p.answered(s, 0, 0);
            }
            p.answered(ask.first, 0, 0);
        }
        assert!((900..1100).contains(&doubles), "{doubles}");
        // The second asks alternate between the two others as their answers even out.
        let (good, fair) = (p.quality(0).answers, p.quality(1).answers);
        assert!(good.abs_diff(fair) <= 1, "{good} {fair}");
    }

    #[test]
    fn an_expert_that_is_never_second_is_asked_first_only() {
        let mut rng = seeded(5);
        let mut p = panel(Route::RoundRobin, 1.0);
        p.never_second(0);
        let asks: Vec<Ask> = (0..6).map(|_| p.route(&mut rng).unwrap()).collect();
        assert!(asks.iter().all(|a| a.second != Some(0)), "{asks:?}");
        assert_eq!(asks[0].first, 0, "asked first in its turn");
        // With the other two down, it answers alone.
        p.set_down(1);
        p.set_down(2);
        assert_eq!(
            p.route(&mut rng).map(|a| (a.first, a.second)),
            Some((0, None))
        );
    }

    #[test]
    fn a_quality_follows_a_change_once_its_window_turns_over() {
        let mut p = panel(Route::Interval, 0.0);
        for _ in 0..50 {
            p.answered(0, 1, 1);
        }
        assert_eq!(p.quality(0).quality, 1.0);
        for _ in 0..50 {
            p.answered(0, 0, 1);
        }
        assert_eq!(
            p.quality(0).quality,
            0.0,
            "the window holds the last 50 only"
        );
    }

    #[test]
    fn an_expert_down_is_not_asked_and_every_route_goes_on_with_the_others() {
        let mut rng = seeded(4);
        let mut p = panel(Route::RoundRobin, 1.0);
        p.set_down(1);
        assert!(!p.is_up(1) && p.is_up(0));
        let asks: Vec<Ask> = (0..4).map(|_| p.route(&mut rng).unwrap()).collect();
        // In turn without `fair`; the second ask goes to the one other expert up.
        let firsts: Vec<usize> = asks.iter().map(|a| a.first).collect();
        assert_eq!(firsts, [0, 2, 0, 2]);
        assert!(asks.iter().all(|a| a.second == Some(2 - a.first)));
        let mut p = panel(Route::BestKnown, 0.0);
        p.set_down(0);
        assert_eq!(p.route(&mut rng).unwrap().first, 2, "the cheapest up");
        let mut p = panel(Route::Cheapest, 1.0);
        p.set_down(2);
        assert_eq!(
            p.route(&mut rng).unwrap(),
            Ask {
                first: 1,
                second: Some(0)
            }
        );
        let mut p = panel(Route::UpperPerCost, 0.0);
        p.set_down(2);
        assert_eq!(p.route(&mut rng).unwrap().first, 1, "1/2 beats 1/10");
        let mut p = panel(Route::Interval, 1.0);
        p.set_down(1);
        p.set_down(2);
        // One expert up: it answers alone, with no second ask.
        assert_eq!(
            p.route(&mut rng).unwrap(),
            Ask {
                first: 0,
                second: None
            }
        );
        p.set_down(0);
        assert_eq!(p.route(&mut rng), None, "every expert down");
    }

    #[test]
    fn an_expert_down_is_asked_again_after_its_wait_which_doubles_with_each_failure() {
        let mut rng = seeded(5);
        let mut p = panel(Route::RoundRobin, 0.0);
        let firsts = |p: &mut Panel, rng: &mut Rng, n: u64| -> Vec<usize> {
            (0..n).map(|_| p.route(rng).unwrap().first).collect()
        };
        assert_eq!(p.set_down(1), RETRY_AFTER);
        let waiting = firsts(&mut p, &mut rng, RETRY_AFTER - 1);
        assert!(!waiting.contains(&1) && !p.is_up(1), "down for its wait");
        let back = firsts(&mut p, &mut rng, 3);
        assert!(
            p.is_up(1) && back.contains(&1),
            "up again, on trial: {back:?}"
        );
        // A second failure: twice the wait, from then on.
        assert_eq!(p.set_down(1), 2 * RETRY_AFTER);
        let waiting = firsts(&mut p, &mut rng, 2 * RETRY_AFTER - 1);
        assert!(!waiting.contains(&1));
        assert!(firsts(&mut p, &mut rng, 3).contains(&1));
        // Every expert down: no one is asked until the first wait is over.
        let mut p = panel(Route::Cheapest, 0.0);
        for i in 0..3 {
            p.set_down(i);
        }
        for _ in 0..RETRY_AFTER - 1 {
            assert_eq!(p.route(&mut rng), None);
        }
        assert!(p.route(&mut rng).is_some(), "back after the wait");
    }
}
