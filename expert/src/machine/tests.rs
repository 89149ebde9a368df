//! The expert machine's tests: events in, actions out.

use super::*;
use alfd_common::config::{DemoModelChoice, ShapingConfig};

/// A machine of generation 2 with budget `budget`; queries are numbered.
fn machine(budget: u32, human: bool) -> ExpertMachine<u32> {
    let core = ExpertCore::new(
        budget,
        DemoModelChoice::Krr,
        2,
        ShapingConfig::default().schedule(),
    );
    ExpertMachine::new(2, "scripted", human, core)
}

fn record(index: u32) -> DemoRecord {
    DemoRecord {
        index,
        state: vec![f64::from(index), 0.5],
        action: (index % 2) as usize,
        step: u64::from(index) * 10,
        expert: "earlier".into(),
        weight: 1.0,
    }
}

fn active(budget: u32, human: bool, earlier: u32) -> ExpertMachine<u32> {
    let mut m = machine(budget, human);
    assert_eq!(m.control(2, 2), vec![Action::LoadDemos]);
    m.activate((0..earlier).map(record).collect()).unwrap();
    m
}

fn q(actor: u32, step: u64) -> QueryIn {
    QueryIn {
        actor,
        step,
        episode: 0,
        last_return: None,
        connected: true,
        state: Ok(vec![0.25, -1.0]),
    }
}

/// The outcome of each reply in `actions`, with the query it answers.
fn replies(actions: &[Action<u32>]) -> Vec<(u32, u32)> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Reply {
                query, response, ..
            } => Some((*query, response.outcome)),
            _ => None,
        })
        .collect()
}

/// Asks and answers query `id` with `action`, as the shell does with a built-in demonstrator.
fn ask_and_answer(m: &mut ExpertMachine<u32>, id: u32, action: usize) -> Vec<Action<u32>> {
    let asked = m.query(id, q(7, 100 + u64::from(id)));
    let [Action::Ask {
        query,
        asker,
        state,
        step,
    }] = asked.as_slice()
    else {
        panic!("expected one Ask, got {asked:?}");
    };
    m.demonstrated(*query, asker.actor, &state.clone(), *step, action)
}

#[test]
fn a_standby_expert_answers_nothing_and_spends_nothing() {
    let mut m = machine(5, false);
    assert_eq!(m.control(1, 2), vec![]);
    let out = m.query(1, q(0, 10));
    assert!(matches!(out.as_slice(), [Action::Drop { actor: 0, .. }]));
    // An answer arriving after it stood by (a slow demonstrator) is not recorded.
    let out = m.demonstrated(1, 0, &[0.0, 0.0], 10, 1);
    assert!(matches!(out.as_slice(), [Action::Drop { .. }]));
    assert_eq!(m.core().budget().used(), 0);
    assert_eq!(m.counts(), Counts::default());
}

#[test]
fn a_newer_generation_makes_it_exit_whatever_its_mode() {
    let mut m = active(5, false, 0);
    assert_eq!(
        m.control(2, 3),
        vec![Action::Exit("replaced by a newer expert")]
    );
    let mut m = machine(5, false);
    assert_eq!(
        m.control(0, 3),
        vec![Action::Exit("replaced by a newer expert")]
    );
}

#[test]
fn activation_counts_the_predecessors_demonstrations() {
    let mut m = machine(5, false);
    assert_eq!(m.control(2, 2), vec![Action::LoadDemos]);
    let out = m.activate((0..3).map(record).collect()).unwrap();
    assert_eq!(
        out,
        vec![
            Action::PublishModel,
            Action::Status(process_state::RUNNING),
            Action::RingLauncher
        ]
    );
    assert_eq!(m.mode(), Mode::Active);
    assert_eq!(m.core().budget().used(), 3);
    assert_eq!(m.core().budget().remaining(), 2);
    // Control repeating the same generation does not load again.
    assert_eq!(m.control(2, 2), vec![]);
}

#[test]
fn with_refits_in_the_background_answers_wait_for_the_disk_not_the_model() {
    let mut m = machine(10, false);
    m.refit_in_background();
    assert_eq!(m.control(2, 2), vec![Action::LoadDemos]);
    m.activate((0..3).map(record).collect()).unwrap();
    let version = m.core().model_version();
    let out = ask_and_answer(&mut m, 1, 1);
    assert!(
        matches!(
            out.as_slice(),
            [
                Action::Record(_),
                Action::Reply { query: 1, .. },
                Action::StartRefit
            ]
        ),
        "{out:?}"
    );
    let job = m.take_refit_job().expect("the refit owed");
    assert_eq!(job.covers(), 4);
    // Two more queries while it runs: answered, and no second refit goes out.
    for id in [2, 3] {
        let out = ask_and_answer(&mut m, id, 0);
        assert!(
            matches!(out.as_slice(), [Action::Record(_), Action::Reply { .. }]),
            "{out:?}"
        );
    }
    assert_eq!(
        m.core().model_version(),
        version,
        "nothing refitted on the query path"
    );
    // Its end publishes the model of four, and starts the refit of the two newcomers.
    let out = m.refitted(job.run());
    assert_eq!(out, vec![Action::PublishModel, Action::StartRefit]);
    assert_eq!(m.core().model_version(), version + 1);
    let job = m.take_refit_job().unwrap();
    assert_eq!(job.covers(), 6);
    assert_eq!(m.refitted(job.run()), vec![Action::PublishModel]);
    assert!(!m.core().stale());
    assert_eq!(m.counts().answered, 3);
}

#[test]
fn a_refit_ending_after_the_expert_stood_by_publishes_nothing() {
    let mut m = machine(5, false);
    m.refit_in_background();
    m.control(2, 2);
    m.activate(Vec::new()).unwrap();
    ask_and_answer(&mut m, 1, 1);
    let job = m.take_refit_job().unwrap();
    m.control(0, 2);
    assert_eq!(m.mode(), Mode::Standby);
    assert_eq!(m.refitted(job.run()), vec![]);
}

#[test]
fn a_demonstration_is_recorded_then_published_then_answered() {
    let mut m = active(5, false, 3);
    let out = ask_and_answer(&mut m, 1, 1);
    let [Action::Record(rec), Action::PublishModel, Action::Reply {
        query: 1,
        actor: 7,
        response,
    }] = out.as_slice()
    else {
        panic!("wrong order: {out:?}");
    };
    assert_eq!(rec.index, 3);
    assert_eq!(rec.action, 1);
    assert_eq!(rec.expert, "scripted");
    assert_eq!(rec.state, vec![0.25, -1.0]);
    assert_eq!(response.outcome, outcome::ANSWERED);
    assert_eq!(response.demo_index, 3);
    assert_eq!(response.action, 1);
    assert_eq!(response.budget_left, 1);
    assert_eq!(response.budget_total, 5);
    assert_eq!(response.expert, 2);
    assert_eq!(response.expert_name(), "scripted");
    assert_eq!(m.counts().answered, 1);
}

#[test]
fn a_demonstration_is_never_dated_before_the_last_one() {
    // The predecessor's last demonstration was at step 20 (record 2); a late query of step 5
    // is dated 20, so the shaping window never shrinks.
    let mut m = active(5, false, 3);
    let out = m.demonstrated(9, 1, &[0.0, 0.0], 5, 0);
    let Some(Action::Record(rec)) = out.first() else {
        panic!("{out:?}");
    };
    assert_eq!(rec.step, 20);
}

#[test]
fn the_budget_is_never_overspent() {
    let mut m = active(2, false, 1);
    assert_eq!(
        replies(&ask_and_answer(&mut m, 1, 0)),
        vec![(1, outcome::ANSWERED)]
    );
    // Spent: the next query is refused without asking the demonstrator.
    let out = m.query(2, q(3, 200));
    assert_eq!(replies(&out), vec![(2, outcome::BUDGET_EXHAUSTED)]);
    // An answer racing the last one (asked before the budget ran out) is refused too.
    let out = m.demonstrated(3, 3, &[0.0, 0.0], 300, 1);
    assert_eq!(replies(&out), vec![(3, outcome::BUDGET_EXHAUSTED)]);
    assert_eq!(m.core().budget().used(), 2);
    assert_eq!(m.counts().refused, 2);
}

#[test]
fn an_abandoned_or_malformed_query_spends_nothing() {
    let mut m = active(5, false, 0);
    let gone = QueryIn {
        connected: false,
        ..q(1, 10)
    };
    assert_eq!(m.query(1, gone), vec![]);
    assert_eq!(m.counts().abandoned, 1);
    let bad = QueryIn {
        state: Err("query obs_dim 3 out of range".into()),
        ..q(1, 10)
    };
    let out = m.query(2, bad);
    assert!(matches!(out.as_slice(), [Action::Drop { actor: 1, why }] if why.contains("obs_dim")));
    assert_eq!(m.core().budget().used(), 0);
}

#[test]
fn the_person_answers_declines_and_duplicates_are_ignored() {
    let mut m = active(5, true, 0);
    assert_eq!(m.query(10, q(0, 1)), vec![]);
    assert_eq!(m.query(11, q(1, 2)), vec![]);
    let shown: Vec<u64> = m.waiting().iter().map(|s| s.id).collect();
    assert_eq!(shown, vec![1, 2]);
    let out = m.decision(2, Some(1), None);
    assert_eq!(replies(&out), vec![(11, outcome::ANSWERED)]);
    assert!(matches!(out.first(), Some(Action::Record(r)) if r.action == 1 && r.step == 2));
    // The same decision twice (a double click) is ignored: one demonstration.
    assert_eq!(m.decision(2, Some(1), None), vec![]);
    let out = m.decision(1, None, None);
    assert_eq!(replies(&out), vec![(10, outcome::DECLINED)]);
    assert_eq!(m.core().budget().used(), 1);
    let c = m.counts();
    assert_eq!((c.person_answered, c.declined, c.answered), (1, 1, 1));
    assert!(m.waiting().is_empty());
}

#[test]
fn a_decision_after_a_swap_is_ignored_and_the_waiting_are_declined() {
    let mut m = active(5, true, 0);
    m.query(10, q(0, 1));
    m.query(11, q(1, 2));
    // Another generation becomes active: the waiting queries are declined at once.
    let out = m.control(3, 3);
    assert_eq!(out, vec![Action::Exit("replaced by a newer expert")]);
    let out = m.control(1, 2);
    assert_eq!(
        replies(&out),
        vec![(10, outcome::DECLINED), (11, outcome::DECLINED)]
    );
    assert!(out.contains(&Action::CloseLog));
    assert_eq!(m.mode(), Mode::Standby);
    // The person's click on the old page arrives late: nothing is recorded.
    assert_eq!(m.decision(1, Some(0), None), vec![]);
    assert_eq!(m.core().budget().used(), 0);
}

#[test]
fn waiting_queries_are_pruned_and_refused_once_the_budget_is_spent() {
    let mut m = active(1, true, 0);
    m.query(10, q(0, 1));
    m.query(11, q(1, 2));
    m.query(12, q(2, 3));
    // Actor 0 stopped waiting: forgotten, counted as abandoned, nothing sent.
    m.prune(|&id| id != 10);
    assert_eq!(m.counts().abandoned, 1);
    let shown: Vec<u64> = m.waiting().iter().map(|s| s.id).collect();
    assert_eq!(shown, vec![2, 3]);
    // The answer that spends the budget refuses the rest rather than leave them waiting.
    assert_eq!(
        replies(&m.decision(2, Some(0), None)),
        vec![(11, outcome::ANSWERED), (12, outcome::BUDGET_EXHAUSTED)]
    );
    assert!(m.waiting().is_empty());
    // A query arriving now is refused, not shown.
    assert_eq!(
        replies(&m.query(13, q(3, 4))),
        vec![(13, outcome::BUDGET_EXHAUSTED)]
    );
}

#[test]
fn status_reports_follow_the_clock_passed_in() {
    let mut m = machine(5, false);
    let start = m.start(Duration::from_secs(10));
    assert_eq!(
        start,
        vec![Action::Status(process_state::STANDBY), Action::RingLauncher]
    );
    assert_eq!(m.tick(Duration::from_millis(10_499)), vec![]);
    assert_eq!(
        m.tick(Duration::from_millis(10_500)),
        vec![Action::Status(process_state::STANDBY)]
    );
    assert_eq!(m.tick(Duration::from_millis(10_600)), vec![]);
    m.control(2, 2);
    m.activate(Vec::new()).unwrap();
    assert_eq!(
        m.tick(Duration::from_secs(11)),
        vec![Action::Status(process_state::RUNNING)]
    );
}

#[test]
fn stopping_declines_the_waiting_and_tells_the_launcher() {
    let mut m = active(5, true, 0);
    m.query(10, q(4, 1));
    let out = m.stop();
    assert_eq!(replies(&out), vec![(10, outcome::DECLINED)]);
    assert_eq!(
        &out[1..],
        &[Action::Status(process_state::EXITING), Action::RingLauncher]
    );
}

/// A built-in expert that always answers its action.
struct Always(usize);

impl Demonstrator<[f32]> for Always {
    fn act(&mut self, _: &[f32]) -> usize {
        self.0
    }
}

/// A demonstration recorded with several experts, and what was noted beside it.
type Noted<'a> = (&'a DemoRecord, &'a PanelNote);

/// Two demonstrations recorded, the model published, and query 1 of actor 7 answered.
fn two_records_and_the_reply(out: &[Action<u32>]) -> (Noted<'_>, Noted<'_>, &QueryResponse) {
    let [Action::RecordOf(first, a), Action::RecordOf(second, b), Action::PublishModel, Action::Reply {
        query: 1,
        actor: 7,
        response,
    }] = out
    else {
        panic!("expected two records, a publication and a reply: {out:?}");
    };
    ((first, a), (second, b), response)
}

/// Actor `actor` in its first episode.
fn asker(actor: u32) -> Asker {
    Asker {
        actor,
        episode: 0,
        last_return: None,
    }
}

/// Three experts answering 2, 1 and 0 at costs 10, 2 and 1, asked in turn, every state asked
/// of a second expert too.
fn panel() -> PanelAsk<'static, [f32]> {
    let cfg = alfd_common::config::ExperimentConfig::from_toml(
        "seed = 1\nepisodes = 3\n[env]\nname = \"mountaincar\"\n[agent]\nkind = \"bdqn\"\n\
         [expert]\nroute = \"round-robin\"\ndouble_ask = 1.0\n\
         [[experts]]\nname = \"mountaincar-energy\"\ncost = 10\n\
         [[experts]]\nname = \"mountaincar-fair\"\ncost = 2\n\
         [[experts]]\nname = \"mountaincar-poor\"\ncost = 1\n",
    )
    .unwrap();
    let members: Vec<Box<dyn Demonstrator<[f32]>>> = vec![
        Box::new(Always(2)),
        Box::new(Always(1)),
        Box::new(Always(0)),
    ];
    PanelAsk::new(&cfg, members, 2)
}

#[test]
fn several_experts_record_each_answer_with_its_cost_then_reply_with_the_first() {
    let mut m = active(3, false, 0);
    let mut p = panel();
    let out = m.panel_demonstrated((1, asker(7)), &[0.25, -1.0], 30, &mut p);
    let ((first, a), (second, b), response) = two_records_and_the_reply(&out);
    // Round-robin starts with energy (2); fair, the least answered other, is asked too.
    assert_eq!(
        (first.expert.as_str(), first.action),
        ("mountaincar-energy", 2)
    );
    assert_eq!(
        (second.expert.as_str(), second.action),
        ("mountaincar-fair", 1)
    );
    assert_eq!((a.cost, a.double_asked, b.cost), (10.0, true, 2.0));
    assert!(
        a.quality_line.starts_with("30,mountaincar-energy,1,"),
        "{}",
        a.quality_line
    );
    assert_eq!((response.action, response.demo_index), (2, 0));
    assert_eq!((response.budget_left, m.counts().answered), (1, 2));
    // The last of the budget: one answer recorded, its double ask not; then refused.
    let out = m.panel_demonstrated((2, asker(7)), &[0.25, -1.0], 40, &mut p);
    assert_eq!(
        out.iter()
            .filter(|a| matches!(a, Action::RecordOf(..)))
            .count(),
        1
    );
    let out = m.panel_demonstrated((3, asker(7)), &[0.25, -1.0], 50, &mut p);
    assert_eq!(replies(&out), [(3, outcome::BUDGET_EXHAUSTED)]);
    // A standby expert asks nobody.
    let mut standby = machine(3, false);
    let out = standby.panel_demonstrated((4, asker(7)), &[0.25, -1.0], 60, &mut p);
    assert!(matches!(out.as_slice(), [Action::Drop { actor: 7, .. }]));
    assert!(standby.core().demos().is_empty());
}

#[test]
fn a_query_the_panel_routes_to_the_person_waits_for_their_decision() {
    let cfg = alfd_common::config::ExperimentConfig::from_toml(
        "seed = 1\nepisodes = 3\n[env]\nname = \"mountaincar\"\n[agent]\nkind = \"bdqn\"\n\
         [expert]\nroute = \"best-known\"\ndouble_ask = 1.0\n\
         [[experts]]\nname = \"human\"\ncost = 10\n\
         [[experts]]\nname = \"mountaincar-fair\"\ncost = 2\n",
    )
    .unwrap();
    let members: Vec<Box<dyn Demonstrator<[f32]>>> = vec![
        Box::new(alfd_demonstrators::registry::PersonSlot),
        Box::new(Always(1)),
    ];
    let mut p = PanelAsk::new(&cfg, members, 2).with_person(0);
    let mut m = active(3, false, 0);
    // Routed to the person (the best known): shown on the page, nothing answered yet.
    let out = m.panel_demonstrated((1, asker(7)), &[0.25, -1.0], 30, &mut p);
    assert_eq!(out, vec![]);
    let shown = m.waiting();
    assert_eq!((shown.len(), shown[0].actor, shown[0].step), (1, 7, 30));
    // Their answer: recorded as theirs, then the second expert's on the same state, then
    // the reply with their action.
    let out = m.decision(shown[0].id, Some(2), Some(&mut p));
    let ((first, a), (second, b), response) = two_records_and_the_reply(&out);
    assert_eq!((first.expert.as_str(), first.action), ("human", 2));
    assert_eq!(
        (second.expert.as_str(), second.action),
        ("mountaincar-fair", 1)
    );
    assert_eq!((a.cost, a.double_asked, b.cost), (10.0, true, 2.0));
    assert_eq!((response.outcome, response.action), (outcome::ANSWERED, 2));
    assert_eq!(m.counts().person_answered, 1);
    // Declined: the actor acts on its own, nothing spent; a second decision is ignored.
    assert_eq!(
        m.panel_demonstrated((2, asker(7)), &[0.0, 0.0], 40, &mut p),
        vec![]
    );
    let id = m.waiting()[0].id;
    let out = m.decision(id, None, Some(&mut p));
    assert_eq!(replies(&out), [(2, outcome::DECLINED)]);
    assert_eq!(m.decision(id, Some(0), Some(&mut p)), vec![]);
    assert_eq!(m.core().budget().used(), 2);
    // An actor that stopped waiting: forgotten, with the panel's ask.
    assert_eq!(
        m.panel_demonstrated((3, asker(7)), &[0.0, 0.0], 50, &mut p),
        vec![]
    );
    m.prune(|_| false);
    assert!(m.waiting().is_empty() && m.routed.is_empty());
}
