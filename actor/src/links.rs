//! The actor's transports over the wire, as the environment loop wants them: the learner process
//! as an [`Adder`] (transitions in batches, under credits) and a [`VariableSource`] (the newest
//! published weights), and the expert process as an [`ExpertClient`] (a query with a timeout, the
//! published demonstration model). The step of Algorithm 1 itself is the core's
//! [`alfd_common::environment_loop`].

use std::ops::ControlFlow;
use std::time::{Duration, Instant};

use alfd_common::agent::NeuralActor;
use alfd_common::demo_model::DemoModel;
use alfd_common::environment_loop::{Adder, ExpertClient, LoopError, Result, Stop, VariableSource};
use alfd_common::panel::EpisodeCount;
use alfd_common::replay::Transition;
use alfd_common::shaping::ShapingSchedule;
use alfd_harness::{Session, What as _};
use alfd_wire::{
    Bell, Credits, DemoModelReceiver, QueryClient, QueryRequest, Receiver, TransitionBatch,
    TransitionSender, WeightsReceiver,
};
use tracing::{debug, warn};

use crate::machine::{
    Answer, Blocked, CreditGate, CreditPoll, Gate, Identity, Poll, QueryWait, CREDIT_POLL_EVERY,
};

/// How long a blocked actor sleeps on its doorbell at most before it looks at control.
const WAIT_AT_MOST: Duration = Duration::from_millis(100);

/// The learner as the actor's adder: transitions go out in batches, never beyond the credits the
/// learner granted (see `alfd_wire`'s crate doc on credits).
pub struct WireAdder<'s, 'w> {
    session: &'s Session<'w>,
    me: Identity,
    gate: CreditGate,
    poll: CreditPoll,
    tx: TransitionSender<'w>,
    learner: Bell,
    credits_rx: Receiver<'w, Credits>,
    batch: TransitionBatch,
    obs_dim: usize,
    heads: usize,
    /// The actor's own steps before this incarnation (an actor restored from its checkpoint).
    steps_before: u64,
    /// The shell's clock: the gate's time is measured from here.
    epoch: Instant,
    pub credit_waits: u64,
    pub credit_wait: Duration,
}

impl<'s, 'w> WireAdder<'s, 'w> {
    pub fn new(
        session: &'s Session<'w>,
        me: Identity,
        window: u64,
        poll: CreditPoll,
        obs_dim: usize,
        heads: usize,
    ) -> alfd_harness::Result<Self> {
        let wire = session.wire();
        Ok(Self {
            session,
            me,
            gate: CreditGate::new(me, window),
            poll,
            tx: wire.transitions_sender(obs_dim, heads)?,
            learner: wire.bell(alfd_wire::Doorbell::Learner)?,
            credits_rx: wire.credits_receiver()?,
            batch: TransitionBatch::new(me.id, me.incarnation, obs_dim, heads, 0)?,
            obs_dim,
            heads,
            steps_before: 0,
            epoch: Instant::now(),
            credit_waits: 0,
            credit_wait: Duration::ZERO,
        })
    }

    /// Transitions produced by this incarnation.
    /// An actor restored from its checkpoint had taken `steps` steps before this incarnation.
    pub fn restored(&mut self, steps: u64) {
        self.steps_before = steps;
    }

    pub fn produced(&self) -> u64 {
        self.gate.next_seq()
    }

    fn now(&self) -> Duration {
        self.epoch.elapsed()
    }

    fn take_credits(&mut self) -> Result<()> {
        if let Some(c) = self.credits_rx.latest().map_err(LoopError::link)? {
            self.gate.credits(c);
        }
        Ok(())
    }

    /// Sends the batch (flagged `blocked` if asked, even empty) and starts the next one.
    fn flush(&mut self, blocked: bool) -> Result<()> {
        if blocked || !self.batch.is_empty() {
            self.batch.head.blocked = u32::from(blocked);
            self.tx.send(&self.batch).map_err(LoopError::link)?;
            self.learner.ring().map_err(LoopError::link)?;
        }
        self.batch = TransitionBatch::new(
            self.me.id,
            self.me.incarnation,
            self.obs_dim,
            self.heads,
            self.gate.next_seq(),
        )
        .map_err(LoopError::link)?;
        Ok(())
    }
}

impl WireAdder<'_, '_> {
    /// Out of credits: sends what is batched, flagged so that the learner rings when new credits
    /// are there, and waits for them (flagging again as the gate says), polling the doorbell
    /// first as the [`CreditPoll`] says.
    fn wait_for_credits(&mut self) -> Result<ControlFlow<Stop>> {
        self.flush(true)?;
        let blocked = Instant::now();
        self.credit_waits += 1;
        let actors = self.gate.latest().map_or(0, Credits::actors);
        // The poll's end, not its length: a ring that was waiting already (rung before this
        // wait) ends a poll early, and the rest of the poll goes on in the next round.
        let poll_until = blocked + self.poll.poll_for(actors);
        loop {
            self.take_credits()?;
            match self.gate.after_wait(self.now()) {
                Blocked::Resume => break,
                Blocked::Reflag => self.flush(true)?,
                Blocked::Wait => {}
            }
            let poll = poll_until.saturating_duration_since(Instant::now());
            if let Some(stop) = self
                .session
                .poll_then_wait(poll, CREDIT_POLL_EVERY, WAIT_AT_MOST)
                .map_err(LoopError::link)?
            {
                return Ok(ControlFlow::Break(stop));
            }
            if let Some(stop) = self.session.should_stop().map_err(LoopError::link)? {
                return Ok(ControlFlow::Break(stop));
            }
        }
        self.credit_wait += blocked.elapsed();
        self.poll.waited(blocked.elapsed());
        if blocked.elapsed() > Duration::from_millis(5) {
            debug!(
                waited_ms = blocked.elapsed().as_millis() as u64,
                next_seq = self.gate.next_seq(),
                granted = self.gate.granted(),
                "long credit wait"
            );
        }
        Ok(ControlFlow::Continue(()))
    }
}

impl Adder for WireAdder<'_, '_> {
    fn reserve(&mut self) -> Result<ControlFlow<Stop>> {
        if self.gate.next_seq() >= self.gate.granted() {
            self.take_credits()?;
        }
        let mut gate = self.gate.reserve(self.now());
        if gate == Gate::Block {
            if let ControlFlow::Break(stop) = self.wait_for_credits()? {
                return Ok(ControlFlow::Break(stop));
            }
            gate = self.gate.resumed();
        }
        self.take_credits()?;
        if gate == Gate::CheckStopThenGo {
            if let Some(stop) = self.session.should_stop().map_err(LoopError::link)? {
                return Ok(ControlFlow::Break(stop));
            }
        }
        Ok(ControlFlow::Continue(()))
    }

    fn add(&mut self, transition: Transition, episode_end: bool) -> Result<()> {
        self.batch.push(&transition).map_err(LoopError::link)?;
        if episode_end {
            self.batch.mark_episode_end();
        }
        self.gate.added();
        if self.batch.is_full() {
            self.flush(false)?;
        }
        Ok(())
    }

    fn end_episode(&mut self) -> Result<()> {
        self.flush(false)
    }

    fn global_step(&self, own_steps: u64) -> u64 {
        let produced = own_steps.saturating_sub(self.steps_before);
        self.gate.global_step(produced, own_steps)
    }
}

/// The learner's published weights as the actor's variable source.
pub struct WireVariables<'w> {
    rx: WeightsReceiver<'w>,
    params: Vec<f32>,
}

impl<'w> WireVariables<'w> {
    pub fn new(session: &Session<'w>) -> alfd_harness::Result<Self> {
        Ok(Self {
            rx: session.wire().weights_receiver()?,
            params: Vec::new(),
        })
    }

    /// Waits for the learner's first weights (the learner's initial network, as the
    /// single-process run starts from it) and puts them into `actor`; the stop, if the launcher
    /// said stop (or a termination signal came) first.
    pub fn first(
        &mut self,
        session: &Session<'_>,
        actor: &mut NeuralActor,
        timeout: Duration,
    ) -> alfd_harness::Result<Option<Stop>> {
        let start = Instant::now();
        loop {
            if let Some(h) = self.rx.latest_into(&mut self.params)? {
                actor
                    .set_weights(&self.params, h.version)
                    .what(|| "the learner's first weights".into())?;
                return Ok(None);
            }
            if let Some(stop) = session.should_stop()? {
                return Ok(Some(stop));
            }
            if start.elapsed() >= timeout {
                let why = format!("no weights from the learner within {timeout:?}");
                return Err(alfd_harness::HarnessError::Run(why));
            }
            if let Some(stop) = session.wait(Duration::from_millis(50))? {
                return Ok(Some(stop));
            }
        }
    }
}

impl VariableSource for WireVariables<'_> {
    fn update(&mut self, actor: &mut NeuralActor) -> Result<()> {
        if let Some(h) = self
            .rx
            .latest_into(&mut self.params)
            .map_err(LoopError::link)?
        {
            actor
                .set_weights(&self.params, h.version)
                .map_err(LoopError::link)?;
        }
        Ok(())
    }
}

/// What the actor knows of the expert's side: the budget, the demonstrations, the model (saved
/// in the actor's checkpoint).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExpertView {
    pub budget_left: u32,
    /// Demonstrations in the run, as far as known (the lines of `demos.jsonl` they are).
    pub demos: u64,
    pub model: Option<DemoModel>,
    pub model_demos: usize,
    pub last_demo_step: u64,
}

/// The expert process as the actor's expert client: a query with a client-side timeout (no
/// expert, or none in time: the actor acts on its own), and the published demonstration model.
pub struct WireExpert<'s, 'w> {
    session: &'s Session<'w>,
    me: Identity,
    client: QueryClient<'w>,
    expert: Bell,
    model_rx: DemoModelReceiver<'w>,
    model_bytes: Vec<u8>,
    view: ExpertView,
    timeout: Duration,
    /// The timeout while a person is the expert (the newest model's header names the expert).
    human_timeout: Duration,
    human_active: bool,
    /// A person is among the run's several experts: every query may wait for them.
    person_among_experts: bool,
    /// `Some` when the config shapes the reward.
    schedule: Option<ShapingSchedule>,
    /// The run's prior demonstrations (`demos.prior`): in every published model, not in the
    /// budget.
    prior_demos: usize,
    pub timeouts: u64,
    /// The number of the last query this actor stopped waiting for with no answer in hand (0:
    /// none), told with the next request so that the expert counts an answer sent to it late.
    gave_up: u64,
    /// The episodes this actor finished and the last one's return, told with each query.
    episodes: EpisodeCount,
    /// How long each answered query waited for its answer, from asking to the answer in hand.
    pub answer_waits: Vec<Duration>,
}

impl<'s, 'w> WireExpert<'s, 'w> {
    pub fn new(
        session: &'s Session<'w>,
        me: Identity,
        (budget, obs_dim): (u32, usize),
        schedule: Option<ShapingSchedule>,
        timeout: Duration,
    ) -> alfd_harness::Result<Self> {
        let wire = session.wire();
        Ok(Self {
            session,
            me,
            client: wire.query_client(obs_dim)?,
            expert: wire.bell(alfd_wire::Doorbell::Expert)?,
            model_rx: wire.demo_model_receiver()?,
            model_bytes: Vec::new(),
            view: ExpertView {
                budget_left: budget,
                demos: 0,
                model: None,
                model_demos: 0,
                last_demo_step: 0,
            },
            timeout,
            human_timeout: timeout,
            human_active: false,
            person_among_experts: false,
            schedule,
            prior_demos: 0,
            timeouts: 0,
            gave_up: 0,
            episodes: EpisodeCount::default(),
            answer_waits: Vec::new(),
        })
    }

    /// The models it receives are fitted on `n` prior demonstrations too (shaping counts them).
    pub fn with_prior_demos(mut self, n: usize) -> Self {
        self.prior_demos = n;
        self
    }

    /// A person is among the run's several experts (`[[experts]]`): every query waits the
    /// person's timeout, since the panel may route it to them.
    pub fn with_person_among_experts(mut self, person: bool) -> Self {
        self.person_among_experts = person;
        self
    }

    /// Waits `timeout` for the answer while a person is the expert.
    pub fn with_human_timeout(mut self, timeout: Duration) -> Self {
        self.human_timeout = timeout;
        self
    }

    /// What this actor knows of the expert, for its checkpoint.
    pub fn view(&self) -> &ExpertView {
        &self.view
    }

    /// Continues from a checkpoint's view (the expert then publishes the same model again).
    pub fn restore_view(&mut self, view: ExpertView) {
        self.view = view;
    }

    /// Takes in the newest demonstration model, if one arrived.
    fn take_model(&mut self) -> Result<()> {
        if let Some(h) = self
            .model_rx
            .latest_into(&mut self.model_bytes)
            .map_err(LoopError::link)?
        {
            let v = &mut self.view;
            v.model =
                if h.len == 0 {
                    None
                } else {
                    Some(postcard::from_bytes(&self.model_bytes).map_err(|e| {
                        LoopError::link(format!("malformed demonstration model: {e}"))
                    })?)
                };
            v.model_demos = h.demos as usize + self.prior_demos;
            v.last_demo_step = h.last_demo_step;
            v.budget_left = h.budget_left;
            v.demos = v.demos.max(u64::from(h.demos));
            self.human_active = h.expert_name() == alfd_harness::HUMAN_EXPERT;
            debug!(version = h.version, demos = h.demos, "demonstration model");
        }
        Ok(())
    }

    /// Before it leaves, the actor tells the expert the last query it stopped waiting for, if
    /// no later request told it: an answer sent to it is then counted late. The report asks
    /// nothing and is sent as a query is; the expert lets it go unanswered.
    pub fn leave(&mut self) -> Result<()> {
        if self.gave_up == 0 {
            return Ok(());
        }
        let report = QueryRequest::report(self.me.id, self.me.incarnation, self.gave_up);
        self.query(report).map(|_| ())
    }

    /// One query (Algorithm 1 line 9), waiting at most the timeout for the answer.
    fn query(&mut self, mut request: QueryRequest) -> Result<Answer> {
        if self.session.control().active_expert == 0 {
            return Ok(Answer::NoExpert);
        }
        request.gave_up = self.gave_up;
        let mut pending = self.client.ask(&request).map_err(LoopError::link)?;
        if pending.servers() == 0 {
            return Ok(Answer::NoExpert);
        }
        self.gave_up = 0;
        self.expert.ring().map_err(LoopError::link)?;
        // The expert publishes its model (its name in the header) when it becomes active: a
        // person just swapped in gets the person's timeout from the first query on.
        self.take_model()?;
        let timeout = if self.human_active || self.person_among_experts {
            self.human_timeout
        } else {
            self.timeout
        };
        let epoch = Instant::now();
        let wait = QueryWait::new(Duration::ZERO, timeout);
        let mut interrupted = false;
        loop {
            let response = pending.poll().map_err(LoopError::link)?;
            let held = response.is_some() || pending.held();
            // No expert holds the query any more (it stopped, or stood by): an answer sent just
            // before is taken, else nothing will come (a person's expert swapped out would
            // otherwise keep the actor waiting minutes).
            let mut late = Ok(None);
            let then = || {
                late = pending.poll();
                late.as_ref().ok().copied().flatten()
            };
            let poll = wait.poll(epoch.elapsed(), response, held, then, interrupted);
            late.map_err(LoopError::link)?;
            match poll {
                Poll::Done(answer) => {
                    match answer {
                        Answer::Demo(_) => self.answer_waits.push(epoch.elapsed()),
                        // Let go below, once this returns: the next request says so.
                        Answer::Timeout => self.gave_up = pending.seq(),
                        _ => {}
                    }
                    return Ok(answer);
                }
                Poll::Wait(d) => {
                    interrupted = self.session.wait(d).map_err(LoopError::link)?.is_some();
                }
            }
        }
    }
}

impl<O: AsRef<[f32]>> ExpertClient<O> for WireExpert<'_, '_> {
    fn update(&mut self) -> Result<()> {
        self.take_model()
    }

    fn budget_left(&self) -> bool {
        self.view.budget_left > 0
    }

    fn ask(&mut self, obs: &O, step: u64) -> Result<Option<usize>> {
        let request = QueryRequest::new(self.me.id, self.me.incarnation, step, obs.as_ref())
            .map_err(LoopError::link)?
            .in_episode(self.episodes.finished, self.episodes.last_return);
        match self.query(request)? {
            Answer::Demo(r) => {
                // With inline refits (`--refit inline`) the expert published the model refitted
                // with this demonstration before answering: shape this very step with it, as
                // Algorithm 1 does. In the background, the newest model the expert has.
                self.take_model()?;
                self.view.budget_left = r.budget_left;
                self.view.demos = self.view.demos.max(u64::from(r.demo_index) + 1);
                Ok(Some(r.action as usize))
            }
            Answer::BudgetExhausted => {
                self.view.budget_left = 0;
                Ok(None)
            }
            Answer::NoExpert | Answer::Declined => Ok(None),
            Answer::Dropped => {
                debug!("the expert let the query go unanswered; acting alone");
                Ok(None)
            }
            Answer::Timeout => {
                self.timeouts += 1;
                warn!(
                    timeouts = self.timeouts,
                    "the expert did not answer in time; acting alone"
                );
                Ok(None)
            }
        }
    }

    fn shaping(&self, step: u64) -> Option<(&DemoModel, f64)> {
        let v = &self.view;
        self.schedule?
            .model_for(step, v.model_demos, v.last_demo_step, v.model.as_ref())
    }

    fn demos_used(&self) -> u32 {
        self.view.demos as u32
    }

    fn episode_ended(&mut self, ret: f64) {
        self.episodes.ended(ret);
    }
}
