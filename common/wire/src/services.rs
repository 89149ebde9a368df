//! The run's channels ([`CHANNELS`], the table every process builds its services from), one
//! builder function per service (so that every process creates a service with the same
//! settings) and the constructors of the ports.

use std::fmt;
use std::time::{Duration, Instant};

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::builder::request_response::{
    RequestResponseOpenError, RequestResponseOpenOrCreateError,
};

use crate::connection::{Transport, Wire};
use crate::error::{transport, Result, WireError};
use crate::messages::{
    Control, Credits, DemoModelHeader, Message, Progress, QueryHeader, QueryResponse,
    TransitionHeader, WeightsHeader, MAX_ACTORS, MAX_NODES, TRANSITIONS_BUFFER,
    TRANSITIONS_PER_BATCH,
};
use crate::ports::{
    DemoModelReceiver, DemoModelSender, QueryClient, QueryServer, Receiver, Sender,
    TransitionReceiver, TransitionSender, WeightsReceiver, WeightsSender,
};
use crate::wakeups::{Bell, Doorbell, Waiter};

/// A publish-subscribe channel of a run: its service's name and limits, the same in every
/// process (a process opening a service with other limits would be refused).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channel {
    /// The service's name within the run.
    pub name: &'static str,
    pub publishers: usize,
    pub subscribers: usize,
    /// Samples a new subscriber gets on connecting (the newest ones).
    pub history: usize,
    /// Samples a subscriber's buffer holds.
    pub buffer: usize,
    /// A full buffer drops its oldest sample (else the publisher is refused).
    pub safe_overflow: bool,
}

/// Actors' transitions to the learner: never dropped (credits keep them within the buffer).
pub const TRANSITIONS: Channel = Channel {
    name: "transitions",
    publishers: 2 * MAX_ACTORS + 4,
    subscribers: 4,
    history: 0,
    buffer: TRANSITIONS_BUFFER,
    safe_overflow: false,
};

/// The learner's grants to the actors: only the newest matters.
pub const CREDITS: Channel = Channel {
    name: "credits",
    publishers: 2,
    subscribers: 2 * MAX_ACTORS + 4,
    history: 1,
    buffer: 2,
    safe_overflow: true,
};

/// The learner's weights: only the newest matters.
pub const WEIGHTS: Channel = Channel {
    name: "weights",
    publishers: 2,
    subscribers: 2 * MAX_ACTORS + 4,
    history: 1,
    buffer: 2,
    safe_overflow: true,
};

/// The expert's demonstration model: only the newest matters (a swap makes a second publisher).
pub const DEMO_MODEL: Channel = Channel {
    name: "demo-model",
    publishers: 4,
    subscribers: 2 * MAX_ACTORS + 4,
    history: 1,
    buffer: 2,
    safe_overflow: true,
};

/// Every process's episodes and status to the launcher. An actor's episode records wait for
/// room in a full buffer (at most [`PROGRESS_PATIENCE`] each), so the launcher falling behind
/// slows the actors rather than losing their episodes; a status message is dropped by a full
/// buffer (the next one supersedes it). The launcher drains the buffer every 100 ms or sooner.
pub const PROGRESS: Channel = Channel {
    name: "progress",
    publishers: MAX_NODES,
    subscribers: 4,
    history: 0,
    buffer: PROGRESS_BUFFER,
    safe_overflow: false,
};

/// Progress messages the launcher's subscriber holds.
const PROGRESS_BUFFER: usize = 8192;

/// How long an actor's episode record waits for room in the launcher's full buffer before it
/// is dropped (the launcher then counts it lost, by the gap in the actor's numbers): a full
/// buffer of 8192 means a launcher stalled, and an actor must not wait for ever on a launcher
/// that died.
pub const PROGRESS_PATIENCE: Duration = Duration::from_secs(2);

/// What an episode record's sender does with a full buffer, `elapsed` into its wait.
fn episode_backpressure(elapsed: Duration) -> iceoryx2::port::BackpressureAction {
    if elapsed < PROGRESS_PATIENCE {
        iceoryx2::port::BackpressureAction::Retry
    } else {
        iceoryx2::port::BackpressureAction::DiscardData
    }
}

/// The launcher's control (stop, the active expert): only the newest matters.
pub const CONTROL: Channel = Channel {
    name: "control",
    publishers: 2,
    subscribers: MAX_NODES,
    history: 1,
    buffer: 4,
    safe_overflow: true,
};

/// Every publish-subscribe channel of a run.
pub const CHANNELS: [Channel; 6] = [TRANSITIONS, CREDITS, WEIGHTS, DEMO_MODEL, PROGRESS, CONTROL];

/// Values of a full batch of steps with observations of `obs_dim` values and masks of `heads`.
fn batch_values(obs_dim: usize, heads: usize) -> usize {
    TRANSITIONS_PER_BATCH * (2 * obs_dim + heads)
}

/// Bytes of shared memory one actor's `transitions` publisher reserves for batches of
/// observations of `obs_dim` values and masks of `heads` values: a sample for every place a
/// subscriber may hold one (iceoryx2 reserves the worst case up front: each subscriber's buffer
/// and borrowed samples, and the publisher's own loans).
pub fn transitions_bytes(obs_dim: usize, heads: usize) -> u64 {
    const BORROWED_PER_SUBSCRIBER: usize = 2;
    const LOANS: usize = 2;
    let samples = TRANSITIONS.subscribers * (TRANSITIONS.buffer + BORROWED_PER_SUBSCRIBER) + LOANS;
    let sample = batch_values(obs_dim, heads) * std::mem::size_of::<f32>()
        + std::mem::size_of::<TransitionHeader>();
    (samples as u64).saturating_mul(sample as u64)
}

/// Bytes of shared memory the learner's `weights` publisher reserves for a network of `params`
/// parameters: a sample for every place a subscriber may hold one, its history and its loans.
pub fn weights_bytes(params: usize) -> u64 {
    const BORROWED_PER_SUBSCRIBER: usize = 2;
    const LOANS: usize = 2;
    let samples =
        WEIGHTS.subscribers * (WEIGHTS.buffer + BORROWED_PER_SUBSCRIBER) + WEIGHTS.history + LOANS;
    let sample = params * std::mem::size_of::<f32>() + std::mem::size_of::<WeightsHeader>();
    (samples as u64).saturating_mul(sample as u64)
}

/// How long a process keeps opening a service that another process is still creating. iceoryx2
/// gives up after its `creation_timeout` (1 s) with `HangsInCreation`; a creator slowed down, or
/// stopped (SIGSTOP) in the middle of creating it, can take longer, and the service is whole
/// once it goes on. A creator that died leaves the error standing after this long.
pub const CREATION_PATIENCE: Duration = Duration::from_secs(10);

/// An open-or-create failure because another process has not finished creating the service.
pub(crate) trait StillInCreation {
    fn still_in_creation(&self) -> bool;
}

impl StillInCreation for PublishSubscribeOpenOrCreateError {
    fn still_in_creation(&self) -> bool {
        matches!(
            self,
            Self::PublishSubscribeOpenError(PublishSubscribeOpenError::HangsInCreation)
        )
    }
}

impl StillInCreation for RequestResponseOpenOrCreateError {
    fn still_in_creation(&self) -> bool {
        matches!(
            self,
            Self::RequestResponseOpenError(RequestResponseOpenError::HangsInCreation)
        )
    }
}

impl StillInCreation for EventOpenOrCreateError {
    fn still_in_creation(&self) -> bool {
        matches!(self, Self::EventOpenError(EventOpenError::HangsInCreation))
    }
}

/// `open` (an open-or-create of the service `name`) again while it fails because another
/// process is still creating the service, for at most [`CREATION_PATIENCE`].
pub(crate) fn patiently<T, E: StillInCreation>(
    name: &dyn fmt::Display,
    open: impl FnMut() -> std::result::Result<T, E>,
) -> std::result::Result<T, E> {
    patiently_for(name, CREATION_PATIENCE, open)
}

/// [`patiently`] for at most `patience`.
fn patiently_for<T, E: StillInCreation>(
    name: &dyn fmt::Display,
    patience: Duration,
    mut open: impl FnMut() -> std::result::Result<T, E>,
) -> std::result::Result<T, E> {
    let start = Instant::now();
    loop {
        match open() {
            Err(e) if e.still_in_creation() && start.elapsed() < patience => {
                tracing::debug!(service = %name, "another process is still creating the service");
                std::thread::sleep(Duration::from_millis(50));
            }
            opened => return opened,
        }
    }
}

type PubSubFactory<P, H> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Transport, P, H>;
type PubSubBuilder<P, H> = iceoryx2::service::builder::publish_subscribe::Builder<P, H, Transport>;

impl Wire {
    // --- one builder per service: every process opens it with these settings ---------------

    /// A builder of the service `name` with `c`'s limits (the payload `P` and user header `H`
    /// are the caller's).
    fn pubsub<P, H>(&self, name: &ServiceName, c: &Channel) -> PubSubBuilder<P, H>
    where
        P: fmt::Debug + IceoryxSend + ?Sized,
        H: fmt::Debug + ZeroCopySend,
    {
        self.node
            .service_builder(name)
            .publish_subscribe::<P>()
            .user_header::<H>()
            .max_publishers(c.publishers)
            .max_subscribers(c.subscribers)
            .max_nodes(MAX_NODES)
            .history_size(c.history)
            .subscriber_max_buffer_size(c.buffer)
            .enable_safe_overflow(c.safe_overflow)
    }

    fn transitions_service(&self) -> Result<PubSubFactory<[f32], TransitionHeader>> {
        let name = self.service_name(TRANSITIONS.name)?;
        patiently(&name, || {
            self.pubsub::<[f32], TransitionHeader>(&name, &TRANSITIONS)
                .open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    fn credits_service(&self) -> Result<PubSubFactory<Credits, ()>> {
        let name = self.service_name(CREDITS.name)?;
        patiently(&name, || {
            self.pubsub::<Credits, ()>(&name, &CREDITS).open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    fn weights_service(&self) -> Result<PubSubFactory<[f32], WeightsHeader>> {
        let name = self.service_name(WEIGHTS.name)?;
        patiently(&name, || {
            self.pubsub::<[f32], WeightsHeader>(&name, &WEIGHTS)
                .open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    fn demo_model_service(&self) -> Result<PubSubFactory<[u8], DemoModelHeader>> {
        let name = self.service_name(DEMO_MODEL.name)?;
        patiently(&name, || {
            self.pubsub::<[u8], DemoModelHeader>(&name, &DEMO_MODEL)
                .open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    fn query_service(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::request_response::PortFactory<
            Transport,
            [f32],
            QueryHeader,
            QueryResponse,
            (),
        >,
    > {
        let name = self.service_name("query")?;
        patiently(&name, || {
            self.node
                .service_builder(&name)
                .request_response::<[f32], QueryResponse>()
                .request_user_header::<QueryHeader>()
                .max_servers(4)
                .max_clients(2 * MAX_ACTORS + 4)
                .max_nodes(MAX_NODES)
                .max_active_requests_per_client(2)
                .max_response_buffer_size(2)
                .enable_safe_overflow_for_requests(true)
                .enable_safe_overflow_for_responses(true)
                .open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    fn progress_service(&self) -> Result<PubSubFactory<Progress, ()>> {
        let name = self.service_name(PROGRESS.name)?;
        patiently(&name, || {
            self.pubsub::<Progress, ()>(&name, &PROGRESS)
                .open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    fn control_service(&self) -> Result<PubSubFactory<Control, ()>> {
        let name = self.service_name(CONTROL.name)?;
        patiently(&name, || {
            self.pubsub::<Control, ()>(&name, &CONTROL).open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    fn doorbell_service(
        &self,
        bell: Doorbell,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Transport>> {
        let name = self.service_name(&bell.topic())?;
        patiently(&name, || {
            self.node
                .service_builder(&name)
                .event()
                .max_listeners(MAX_NODES)
                .max_notifiers(MAX_NODES)
                .max_nodes(MAX_NODES)
                .event_id_max_value(255)
                .open_or_create()
        })
        .map_err(transport("open", name.to_string()))
    }

    // --- ports ------------------------------------------------------------------------------

    fn sender<T: Message>(&self, port: Publisher<Transport, T, ()>) -> Sender<'_, T> {
        Sender {
            wire: self,
            port,
            seq: 0,
        }
    }

    fn receiver<T: Message>(&self, port: Subscriber<Transport, T, ()>) -> Receiver<'_, T> {
        Receiver { wire: self, port }
    }

    /// Actor side of `transitions`, its samples sized for batches of observations of `obs_dim`
    /// values and masks of `heads` (a larger batch makes it allocate anew, a power of two).
    pub fn transitions_sender(&self, obs_dim: usize, heads: usize) -> Result<TransitionSender<'_>> {
        let port = self
            .transitions_service()?
            .publisher_builder()
            .initial_max_slice_len(batch_values(obs_dim, heads).max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(transport("create a publisher on", "transitions"))?;
        Ok(TransitionSender {
            wire: self,
            port,
            seq: 0,
        })
    }

    /// Learner side of `transitions`.
    pub fn transitions_receiver(&self) -> Result<TransitionReceiver<'_>> {
        let port = self
            .transitions_service()?
            .subscriber_builder()
            .buffer_size(TRANSITIONS_BUFFER)
            .create()
            .map_err(transport("create a subscriber on", "transitions"))?;
        Ok(TransitionReceiver { wire: self, port })
    }

    /// Learner side of `credits`.
    pub fn credits_sender(&self) -> Result<Sender<'_, Credits>> {
        let port = self
            .credits_service()?
            .publisher_builder()
            .create()
            .map_err(transport("create a publisher on", "credits"))?;
        Ok(self.sender(port))
    }

    /// Actor side of `credits`.
    pub fn credits_receiver(&self) -> Result<Receiver<'_, Credits>> {
        let port = self
            .credits_service()?
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(transport("create a subscriber on", "credits"))?;
        Ok(self.receiver(port))
    }

    /// Learner side of `weights`, for a network of `len` parameters.
    pub fn weights_sender(&self, len: usize) -> Result<WeightsSender<'_>> {
        let port = self
            .weights_service()?
            .publisher_builder()
            .initial_max_slice_len(len.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(transport("create a publisher on", "weights"))?;
        Ok(WeightsSender {
            wire: self,
            port,
            seq: 0,
        })
    }

    /// Actor side of `weights`.
    pub fn weights_receiver(&self) -> Result<WeightsReceiver<'_>> {
        let port = self
            .weights_service()?
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(transport("create a subscriber on", "weights"))?;
        Ok(WeightsReceiver { wire: self, port })
    }

    /// Expert side of `demo-model`.
    pub fn demo_model_sender(&self) -> Result<DemoModelSender<'_>> {
        let port = self
            .demo_model_service()?
            .publisher_builder()
            .initial_max_slice_len(4096)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(transport("create a publisher on", "demo-model"))?;
        Ok(DemoModelSender {
            wire: self,
            port,
            seq: 0,
        })
    }

    /// Actor side of `demo-model`.
    pub fn demo_model_receiver(&self) -> Result<DemoModelReceiver<'_>> {
        let port = self
            .demo_model_service()?
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(transport("create a subscriber on", "demo-model"))?;
        Ok(DemoModelReceiver { wire: self, port })
    }

    /// Actor side of `query`, its requests sized for states of `obs_dim` values (a larger one
    /// makes it allocate anew, a power of two).
    pub fn query_client(&self, obs_dim: usize) -> Result<QueryClient<'_>> {
        let port = self
            .query_service()?
            .client_builder()
            .initial_max_slice_len(obs_dim.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(transport("create a client on", "query"))?;
        // From 1: a request's `gave_up` names an earlier query by its number, 0 naming none.
        Ok(QueryClient {
            wire: self,
            port,
            seq: 1,
        })
    }

    /// Expert side of `query`.
    pub fn query_server(&self) -> Result<QueryServer<'_>> {
        let port = self
            .query_service()?
            .server_builder()
            .create()
            .map_err(transport("create a server on", "query"))?;
        Ok(QueryServer { wire: self, port })
    }

    /// An actor's side of `progress`, for its episode records: a full buffer is waited on (see
    /// [`PROGRESS_PATIENCE`]).
    pub fn episode_sender(&self) -> Result<Sender<'_, Progress>> {
        let port = self
            .progress_service()?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .set_backpressure_handler(|info: &iceoryx2::port::BackpressureInfo| {
                episode_backpressure(info.elapsed_time)
            })
            .create()
            .map_err(transport("create a publisher on", "progress"))?;
        Ok(self.sender(port))
    }

    /// Every process's side of `progress` for status messages (and a bridge's forwarding): a
    /// full buffer drops the message.
    pub fn progress_sender(&self) -> Result<Sender<'_, Progress>> {
        let port = self
            .progress_service()?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(transport("create a publisher on", "progress"))?;
        Ok(self.sender(port))
    }

    /// The launcher's side of `progress`.
    pub fn progress_receiver(&self) -> Result<Receiver<'_, Progress>> {
        self.progress_receiver_holding(PROGRESS_BUFFER)
    }

    /// A subscriber to `progress` whose buffer holds `n` messages.
    pub(crate) fn progress_receiver_holding(&self, n: usize) -> Result<Receiver<'_, Progress>> {
        let port = self
            .progress_service()?
            .subscriber_builder()
            .buffer_size(n)
            .create()
            .map_err(transport("create a subscriber on", "progress"))?;
        Ok(self.receiver(port))
    }

    /// The launcher's side of `control`.
    pub fn control_sender(&self) -> Result<Sender<'_, Control>> {
        let port = self
            .control_service()?
            .publisher_builder()
            .create()
            .map_err(transport("create a publisher on", "control"))?;
        Ok(self.sender(port))
    }

    /// Every process's side of `control`.
    pub fn control_receiver(&self) -> Result<Receiver<'_, Control>> {
        let port = self
            .control_service()?
            .subscriber_builder()
            .buffer_size(4)
            .create()
            .map_err(transport("create a subscriber on", "control"))?;
        Ok(self.receiver(port))
    }

    /// Rings `bell` to wake whoever waits on it.
    pub fn bell(&self, bell: Doorbell) -> Result<Bell> {
        let port = self
            .doorbell_service(bell)?
            .notifier_builder()
            .create()
            .map_err(transport("create a notifier on", bell.topic()))?;
        Ok(Bell { port, bell })
    }

    /// Waits on `bell` (the process's own doorbell).
    pub fn waiter(&self, bell: Doorbell) -> Result<Waiter> {
        self.waiter_on(&[bell])
    }

    /// Waits on any of `bells` (a bridge stands in for several processes). At least one bell.
    pub fn waiter_on(&self, bells: &[Doorbell]) -> Result<Waiter> {
        let bell = *bells.first().ok_or(WireError::OutOfRange {
            what: "doorbells to wait on",
            value: 0,
            expected: "at least one",
        })?;
        let listeners = bells
            .iter()
            .map(|b| {
                self.doorbell_service(*b)?
                    .listener_builder()
                    .create()
                    .map_err(transport("create a listener on", b.topic()))
            })
            .collect::<Result<Vec<_>>>()?;
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Transport>()
            .map_err(transport("create a waitset for", bell.topic()))?;
        Ok(Waiter {
            listeners,
            waitset,
            bell,
        })
    }

    /// How many expert servers are connected to `query` right now.
    #[cfg(test)]
    pub(crate) fn query_servers(&self) -> Result<usize> {
        Ok(self.query_service()?.dynamic_config().number_of_servers())
    }
}

#[cfg(test)]
mod channel_tests {
    use super::*;

    #[test]
    fn every_channel_has_its_own_name_and_room_for_every_process() {
        let mut names: Vec<&str> = CHANNELS.iter().map(|c| c.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), CHANNELS.len());
        for c in CHANNELS {
            // Every actor (and its restart) on one side, the learner, launcher, expert and
            // bridge on the other.
            assert!(
                c.publishers.max(c.subscribers) >= 2 * MAX_ACTORS + 4,
                "{c:?}"
            );
            assert!(c.buffer >= 1 && c.history <= c.buffer, "{c:?}");
        }
        // The channels that must never drop a sample do not overflow: the learner's
        // transitions (held within the credits) and the launcher's episodes.
        for c in [TRANSITIONS, PROGRESS] {
            assert!(!c.safe_overflow && c.history == 0, "{c:?}");
        }
    }

    /// An open's failure: a service still in creation (true) or another failure (false).
    #[derive(Debug)]
    struct Fake(bool);

    impl StillInCreation for Fake {
        fn still_in_creation(&self) -> bool {
            self.0
        }
    }

    #[test]
    fn a_service_still_in_creation_is_opened_again_and_other_failures_are_not() {
        let name = ServiceName::new("alfd/test/patiently").unwrap();
        let mut calls = 0;
        let opened = patiently_for(&name, Duration::from_secs(5), || {
            calls += 1;
            if calls < 3 {
                Err(Fake(true))
            } else {
                Ok(7)
            }
        });
        assert_eq!((opened.unwrap(), calls), (7, 3));

        let mut calls = 0;
        let refused = patiently_for(&name, Duration::from_secs(5), || {
            calls += 1;
            Err::<u8, _>(Fake(false))
        });
        assert_eq!(calls, 1, "another failure is not tried again");
        assert!(
            !refused.unwrap_err().0,
            "the other failure is the one returned"
        );

        // A creator that never finishes: the error stands once the patience is spent.
        let start = Instant::now();
        let hangs = patiently_for(&name, Duration::from_millis(120), || {
            Err::<u8, _>(Fake(true))
        });
        assert!(hangs.unwrap_err().0, "the creation's failure stands");
        assert!(start.elapsed() >= Duration::from_millis(120));
    }
}
