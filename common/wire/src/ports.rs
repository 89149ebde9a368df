//! The ports a process holds on the services of its run: senders and receivers of messages
//! (stamped with and checked against the schema version), the weights and demonstration-model
//! slices, and both sides of a query.

use std::fmt;

use iceoryx2::active_request::ActiveRequest;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;

use crate::connection::{Transport, Wire};
use crate::error::{transport, Result};
use crate::messages::{
    DemoModelHeader, Message, QueryHeader, QueryRequest, QueryResponse, TransitionBatch,
    TransitionHeader, WeightsHeader,
};
use crate::stream;

/// Sends messages of type `T`, stamping each with the schema version, the sender and a sequence
/// number.
pub struct Sender<'w, T: Message> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Publisher<Transport, T, ()>,
    pub(crate) seq: u64,
}

impl<T: Message> fmt::Debug for Sender<'_, T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Sender<{}>(seq {})", T::SERVICE, self.seq)
    }
}

impl<T: Message> Sender<'_, T> {
    /// Sends `msg`; returns the sequence number it got.
    pub fn send(&mut self, mut msg: T) -> Result<u64> {
        let seq = self.seq;
        *msg.header_mut() = self.wire.header(seq);
        self.port
            .send_copy(msg)
            .map_err(transport("send on", T::SERVICE))?;
        self.seq += 1;
        Ok(seq)
    }

    /// Messages sent so far (the next one's sequence number).
    pub fn sent(&self) -> u64 {
        self.seq
    }

    /// Sends `msg` as it is, its header (sender, sequence number) untouched: a bridge passes on
    /// what another process sent. The schema version is checked like a received message's.
    pub fn forward(&mut self, msg: T) -> Result<()> {
        self.wire.check(T::SERVICE, msg.header())?;
        self.port
            .send_copy(msg)
            .map_err(transport("send on", T::SERVICE))?;
        Ok(())
    }

    /// Delivers the history to subscribers that connected since the last send.
    pub fn update_connections(&self) -> Result<()> {
        self.port
            .update_connections()
            .map_err(transport("update connections of", T::SERVICE))
    }
}

/// Receives messages of type `T`, refusing other schema versions.
pub struct Receiver<'w, T: Message> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Subscriber<Transport, T, ()>,
}

impl<T: Message> fmt::Debug for Receiver<'_, T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Receiver<{}>", T::SERVICE)
    }
}

impl<T: Message> Receiver<'_, T> {
    /// The next message, if any. A message of another schema version is consumed and reported
    /// as [`WireError::SchemaMismatch`](crate::WireError::SchemaMismatch); the next call goes on
    /// with the following one.
    pub fn receive(&self) -> Result<Option<T>> {
        match self
            .port
            .receive()
            .map_err(transport("receive on", T::SERVICE))?
        {
            None => Ok(None),
            Some(sample) => {
                let msg = *sample.payload();
                self.wire.check(T::SERVICE, msg.header())?;
                Ok(Some(msg))
            }
        }
    }

    /// The newest message waiting, dropping older ones.
    pub fn latest(&self) -> Result<Option<T>> {
        let mut last = None;
        while let Some(m) = self.receive()? {
            last = Some(m);
        }
        Ok(last)
    }
}

/// An actor's side of `transitions` (or a bridge's, for the actors of another host).
pub struct TransitionSender<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Publisher<Transport, [f32], TransitionHeader>,
    pub(crate) seq: u64,
}

impl fmt::Debug for TransitionSender<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "TransitionSender(seq {})", self.seq)
    }
}

impl TransitionSender<'_> {
    /// Sends `batch`, stamped with this process's header; returns the sequence number it got.
    pub fn send(&mut self, batch: &TransitionBatch) -> Result<u64> {
        let seq = self.seq;
        let mut header = batch.head;
        header.header = self.wire.header(seq);
        self.put(header, &batch.values)?;
        self.seq += 1;
        Ok(seq)
    }

    /// Sends `batch` under its own header (a bridge passes on what another process sent). The
    /// schema version is checked like a received message's.
    pub fn forward(&mut self, batch: &TransitionBatch) -> Result<()> {
        self.wire.check("transitions", &batch.head.header)?;
        self.put(batch.head, &batch.values)
    }

    /// Sends `values` under `header` (an empty batch as one value: iceoryx2 loans no empty
    /// slice; `len` says how many steps there are).
    fn put(&mut self, header: TransitionHeader, values: &[f32]) -> Result<()> {
        let mut sample = self
            .port
            .loan_slice_uninit(values.len().max(1))
            .map_err(transport("loan on", "transitions"))?;
        *sample.user_header_mut() = header;
        let payload = if values.is_empty() {
            &[0.0][..]
        } else {
            values
        };
        sample
            .write_from_slice(payload)
            .send()
            .map_err(transport("send on", "transitions"))?;
        Ok(())
    }
}

/// The learner's side of `transitions`.
pub struct TransitionReceiver<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Subscriber<Transport, [f32], TransitionHeader>,
}

impl fmt::Debug for TransitionReceiver<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "TransitionReceiver")
    }
}

impl TransitionReceiver<'_> {
    /// The next batch, if any. A batch of another schema version is consumed and reported as
    /// [`WireError::SchemaMismatch`](crate::WireError::SchemaMismatch).
    pub fn receive(&self) -> Result<Option<TransitionBatch>> {
        let Some(sample) = self
            .port
            .receive()
            .map_err(transport("receive on", "transitions"))?
        else {
            return Ok(None);
        };
        let header = sample.user_header();
        self.wire.check("transitions", &header.header)?;
        Ok(Some(TransitionBatch::from_wire(header, sample.payload())))
    }
}

/// Publishes the learner's weights.
pub struct WeightsSender<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Publisher<Transport, [f32], WeightsHeader>,
    pub(crate) seq: u64,
}

impl fmt::Debug for WeightsSender<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "WeightsSender(seq {})", self.seq)
    }
}

impl WeightsSender<'_> {
    /// Publishes weights another process published, under their header as it is (a bridge).
    pub fn forward(&mut self, header: WeightsHeader, weights: &[f32]) -> Result<()> {
        self.wire.check("weights", &header.header)?;
        self.send(header, &[weights])
    }

    /// Publishes the weights in `parts` (the network's tensors, one after another) as version
    /// `version`.
    pub fn publish(
        &mut self,
        version: u64,
        updates: u64,
        env_steps: u64,
        parts: &[&[f32]],
    ) -> Result<()> {
        let header = WeightsHeader {
            header: self.wire.header(self.seq),
            version,
            updates,
            env_steps,
            len: parts.iter().map(|p| p.len() as u64).sum(),
        };
        self.send(header, parts)?;
        self.seq += 1;
        Ok(())
    }

    /// Loans a sample as long as `parts` together, streams them into it (see [`crate::stream`])
    /// and sends it under `header`.
    fn send(&mut self, header: WeightsHeader, parts: &[&[f32]]) -> Result<()> {
        let len = parts.iter().map(|p| p.len()).sum();
        let mut sample = self
            .port
            .loan_slice_uninit(len)
            .map_err(transport("loan on", "weights"))?;
        *sample.user_header_mut() = header;
        stream::copy_parts(sample.payload_mut(), parts);
        // SAFETY: `copy_parts` wrote every element of the payload (it panics unless the parts
        // fill it exactly, and the payload is `len` long).
        #[allow(unsafe_code)]
        let sample = unsafe { sample.assume_init() };
        sample.send().map_err(transport("send on", "weights"))?;
        Ok(())
    }

    /// Delivers the history to subscribers that connected since the last publication.
    pub fn update_connections(&self) -> Result<()> {
        self.port
            .update_connections()
            .map_err(transport("update connections of", "weights"))
    }
}

/// Receives the learner's weights.
pub struct WeightsReceiver<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Subscriber<Transport, [f32], WeightsHeader>,
}

impl fmt::Debug for WeightsReceiver<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "WeightsReceiver")
    }
}

impl WeightsReceiver<'_> {
    /// Copies the newest weights waiting into `out`, if any, and returns their header.
    pub fn latest_into(&self, out: &mut Vec<f32>) -> Result<Option<WeightsHeader>> {
        let mut newest = None;
        while let Some(sample) = self
            .port
            .receive()
            .map_err(transport("receive on", "weights"))?
        {
            newest = Some(sample);
        }
        let Some(sample) = newest else {
            return Ok(None);
        };
        let h = *sample.user_header();
        self.wire.check("weights", &h.header)?;
        out.clear();
        out.extend_from_slice(sample.payload());
        Ok(Some(h))
    }
}

/// Publishes the expert's fitted demonstration model.
pub struct DemoModelSender<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Publisher<Transport, [u8], DemoModelHeader>,
    pub(crate) seq: u64,
}

impl fmt::Debug for DemoModelSender<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "DemoModelSender(seq {})", self.seq)
    }
}

impl DemoModelSender<'_> {
    /// Publishes a model another process published, under its header as it is (a bridge).
    pub fn forward(&mut self, header: DemoModelHeader, bytes: &[u8]) -> Result<()> {
        self.wire.check("demo-model", &header.header)?;
        self.send(header, bytes)
    }

    /// Publishes `bytes` (the model, serialized) under `header` (whose `header` and `len` are
    /// filled in here).
    pub fn publish(&mut self, mut header: DemoModelHeader, bytes: &[u8]) -> Result<()> {
        header.header = self.wire.header(self.seq);
        header.len = bytes.len() as u64;
        self.send(header, bytes)?;
        self.seq += 1;
        Ok(())
    }

    /// Sends `bytes` under `header` (an empty model as one byte: iceoryx2 loans no empty slice).
    fn send(&mut self, header: DemoModelHeader, bytes: &[u8]) -> Result<()> {
        let mut sample = self
            .port
            .loan_slice_uninit(bytes.len().max(1))
            .map_err(transport("loan on", "demo-model"))?;
        *sample.user_header_mut() = header;
        let payload = if bytes.is_empty() { &[0u8][..] } else { bytes };
        sample
            .write_from_slice(payload)
            .send()
            .map_err(transport("send on", "demo-model"))?;
        Ok(())
    }

    /// Delivers the history to subscribers that connected since the last publication.
    pub fn update_connections(&self) -> Result<()> {
        self.port
            .update_connections()
            .map_err(transport("update connections of", "demo-model"))
    }
}

/// Receives the expert's demonstration model.
pub struct DemoModelReceiver<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Subscriber<Transport, [u8], DemoModelHeader>,
}

impl fmt::Debug for DemoModelReceiver<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "DemoModelReceiver")
    }
}

impl DemoModelReceiver<'_> {
    /// Copies the newest model waiting into `out`, if any, and returns its header. Newest is
    /// the highest version (the later one among equals), not the last received: while experts
    /// are swapped, the old and the new one both publish, and samples of several publishers
    /// arrive in no set order. Across calls a lower version is taken as it comes: generations
    /// start at 1 again in each launch of a run, so a version below the one held may be the
    /// newest (an old expert's publication after the new one's is replaced by the new one's
    /// next).
    pub fn latest_into(&self, out: &mut Vec<u8>) -> Result<Option<DemoModelHeader>> {
        let mut newest = None;
        while let Some(sample) = self
            .port
            .receive()
            .map_err(transport("receive on", "demo-model"))?
        {
            let version = sample.user_header().version;
            if newest.as_ref().is_none_or(|(v, _)| *v <= version) {
                newest = Some((version, sample));
            }
        }
        let Some((_, sample)) = newest else {
            return Ok(None);
        };
        let h = *sample.user_header();
        self.wire.check("demo-model", &h.header)?;
        let len = (h.len as usize).min(sample.payload().len());
        out.clear();
        out.extend_from_slice(&sample.payload()[..len]);
        Ok(Some(h))
    }
}

/// An actor's side of `query`.
pub struct QueryClient<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Client<Transport, [f32], QueryHeader, QueryResponse, ()>,
    pub(crate) seq: u64,
}

impl fmt::Debug for QueryClient<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "QueryClient(seq {})", self.seq)
    }
}

impl<'w> QueryClient<'w> {
    /// Sends `request`. With no expert connected it still succeeds, and
    /// [`PendingQuery::servers`] is 0: no answer will come.
    pub fn ask(&mut self, request: &QueryRequest) -> Result<PendingQuery<'w>> {
        let seq = self.seq;
        let mut header = request.wire_header();
        header.header = self.wire.header(seq);
        let mut loan = self
            .port
            .loan_slice_uninit(request.state.len().max(1))
            .map_err(transport("loan on", "query"))?;
        *loan.user_header_mut() = header;
        let payload = if request.state.is_empty() {
            &[0.0][..]
        } else {
            &request.state[..]
        };
        let pending = loan
            .write_from_slice(payload)
            .send()
            .map_err(transport("send on", "query"))?;
        self.seq += 1;
        Ok(PendingQuery {
            wire: self.wire,
            pending,
            seq,
            duplicates: 0,
            answered: false,
        })
    }
}

/// A query on its way; poll it for the answer.
pub struct PendingQuery<'w> {
    wire: &'w Wire,
    pending: PendingResponse<Transport, [f32], QueryHeader, QueryResponse, ()>,
    seq: u64,
    duplicates: u32,
    answered: bool,
}

impl fmt::Debug for PendingQuery<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PendingQuery(seq {})", self.seq)
    }
}

impl PendingQuery<'_> {
    /// The request's sequence number.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// How many expert servers received the request.
    pub fn servers(&self) -> usize {
        self.pending.number_of_server_connections()
    }

    /// The answer, once. Any further response to the same request (two experts up during a
    /// swap), or a response to another request, is dropped and counted in
    /// `PendingQuery::duplicates`.
    pub fn poll(&mut self) -> Result<Option<QueryResponse>> {
        while let Some(r) = self
            .pending
            .receive()
            .map_err(transport("receive on", "query"))?
        {
            let resp = *r.payload();
            self.wire.check("query", &resp.header)?;
            if resp.request_seq != self.seq || self.answered {
                self.duplicates += 1;
                continue;
            }
            self.answered = true;
            return Ok(Some(resp));
        }
        Ok(None)
    }

    /// Whether an expert still holds the request: false once every expert that received it has
    /// answered it or let it go (an expert standing by, one that stopped), and when none did.
    pub fn held(&self) -> bool {
        self.pending.is_connected()
    }

    #[cfg(test)]
    pub(crate) fn duplicates(&self) -> u32 {
        self.duplicates
    }
}

/// The expert's side of `query`.
pub struct QueryServer<'w> {
    pub(crate) wire: &'w Wire,
    pub(crate) port: Server<Transport, [f32], QueryHeader, QueryResponse, ()>,
}

impl fmt::Debug for QueryServer<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "QueryServer")
    }
}

impl<'w> QueryServer<'w> {
    /// The next request, if any. A request of another schema version is dropped unanswered and
    /// reported as [`WireError::SchemaMismatch`](crate::WireError::SchemaMismatch).
    pub fn receive(&self) -> Result<Option<IncomingQuery<'w>>> {
        match self
            .port
            .receive()
            .map_err(transport("receive on", "query"))?
        {
            None => Ok(None),
            Some(active) => {
                let request = QueryRequest::from_wire(active.user_header(), active.payload());
                self.wire.check("query", &request.header)?;
                Ok(Some(IncomingQuery {
                    wire: self.wire,
                    active,
                    request,
                }))
            }
        }
    }
}

/// A request the expert holds; answer it or drop it.
pub struct IncomingQuery<'w> {
    wire: &'w Wire,
    active: ActiveRequest<Transport, [f32], QueryHeader, QueryResponse, ()>,
    request: QueryRequest,
}

impl fmt::Debug for IncomingQuery<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "IncomingQuery({:?})", self.request)
    }
}

impl IncomingQuery<'_> {
    pub fn request(&self) -> &QueryRequest {
        &self.request
    }

    /// Whether the actor still waits for the answer (it gives up after its timeout).
    pub fn is_connected(&self) -> bool {
        self.active.is_connected()
    }

    /// Sends `response` (its header and `request_seq` are filled in here).
    pub fn answer(self, mut response: QueryResponse) -> Result<()> {
        response.header = self.wire.header(self.request.header.seq);
        response.request_seq = self.request.header.seq;
        response.actor = self.request.actor;
        self.active
            .send_copy(response)
            .map_err(transport("answer on", "query"))
    }
}

#[cfg(test)]
mod tests {
    use alfd_common::replay::Transition;

    use crate::test_support::{transition, wire, with_run};
    use crate::*;

    #[test]
    fn a_bridge_forwards_a_message_under_its_senders_header_and_refuses_another_schema() {
        with_run("forward", |run| {
            let bridge = wire(run, Role::Bridge, 0);
            let launcher = wire(run, Role::Launcher, 0);
            let rx = launcher.progress_receiver().unwrap();
            let mut tx = bridge.progress_sender().unwrap();
            // As a remote actor 7 sent it, its 41st progress message.
            let mut p = Progress {
                header: Header {
                    schema: SCHEMA_VERSION,
                    role: Role::Actor as u16,
                    id: 7,
                    seq: 41,
                },
                ..Progress::default()
            };
            tx.forward(p).unwrap();
            let got = rx.receive().unwrap().unwrap();
            assert_eq!(
                got.header, p.header,
                "the header arrives as the actor wrote it"
            );
            assert_eq!(got.header.sender(), "actor-7");
            p.header.schema = SCHEMA_VERSION + 1;
            assert!(matches!(
                tx.forward(p),
                Err(WireError::SchemaMismatch { theirs, .. }) if theirs == SCHEMA_VERSION + 1
            ));
            assert!(
                rx.receive().unwrap().is_none(),
                "nothing of the other schema went out"
            );
        });
    }

    #[test]
    fn transitions_arrive_in_order_with_header_and_flags() {
        with_run("transitions", |run| {
            let actor = wire(run, Role::Actor, 3);
            let learner = wire(run, Role::Learner, 0);
            let rx = learner.transitions_receiver().unwrap();
            let mut tx = actor.transitions_sender(4, 2).unwrap();

            let sent = [
                transition(1.0, false, false),
                transition(2.0, true, false),
                transition(3.0, false, true),
            ];
            let mut batch = TransitionBatch::new(3, 77, 4, 2, 10).unwrap();
            for (i, t) in sent.iter().enumerate() {
                batch.push(t).unwrap();
                assert_eq!(batch.len(), i + 1);
            }
            assert_eq!(batch.end_seq(), 13);
            assert_eq!(tx.send(&batch).unwrap(), 0);
            assert_eq!(
                tx.send(&TransitionBatch::new(3, 77, 4, 2, 13).unwrap())
                    .unwrap(),
                1
            );

            let got = rx.receive().unwrap().expect("a batch");
            assert_eq!(got.head.header.schema, SCHEMA_VERSION);
            assert_eq!(got.head.header.sender(), "actor-3");
            assert_eq!(got.head.header.seq, 0);
            assert_eq!(
                (got.head.actor, got.head.incarnation, got.head.first_seq),
                (3, 77, 10)
            );
            let back: Vec<Transition> = got.transitions().collect();
            assert_eq!(back, sent);
            assert_eq!(got.head.records[1].flags, flags::DEMO);
            assert_eq!(got.head.records[2].flags, flags::TERMINATED);
            let second = rx.receive().unwrap().expect("the empty batch");
            assert_eq!(second.head.header.seq, 1);
            assert!(second.is_empty());
            assert!(rx.receive().unwrap().is_none());
        });
    }

    /// A step of `obs_dim` values and `heads` mask values, each value telling where it is.
    fn wide_step(k: usize, obs_dim: usize, heads: usize) -> Transition {
        let values = |base: usize, n: usize| (0..n).map(|i| (base + i) as f32).collect();
        Transition {
            state: values(k * 10_000, obs_dim),
            action: 1,
            reward: k as f32,
            next_state: values(k * 10_000 + 5_000, obs_dim),
            terminated: false,
            mask: values(k, heads),
            demo: k.is_multiple_of(2),
            horizon: 1,
        }
    }

    #[test]
    fn batches_and_queries_as_large_as_the_run_needs_arrive_whole() {
        with_run("wide", |run| {
            let actor = wire(run, Role::Actor, 0);
            let learner = wire(run, Role::Learner, 0);
            let expert = wire(run, Role::Expert, 1);
            let rx = learner.transitions_receiver().unwrap();
            // Sized for DeepSea(50)'s one-hot grid and 20 heads; then a sender sized for less
            // than it sends, which allocates anew.
            for (sized, (obs_dim, heads)) in [((2500, 20), (2500, 20)), ((4, 2), (300, 12))] {
                let mut tx = actor.transitions_sender(sized.0, sized.1).unwrap();
                let sent: Vec<Transition> = (0..TRANSITIONS_PER_BATCH)
                    .map(|k| wide_step(k, obs_dim, heads))
                    .collect();
                let mut batch = TransitionBatch::new(0, 1, obs_dim, heads, 0).unwrap();
                sent.iter().for_each(|t| batch.push(t).unwrap());
                tx.send(&batch).unwrap();
                let got = rx.receive().unwrap().expect("a batch");
                got.check(obs_dim, heads, 2).unwrap();
                assert_eq!(got.transitions().collect::<Vec<_>>(), sent);
            }
            let server = expert.query_server().unwrap();
            let mut client = actor.query_client(2500).unwrap();
            let state: Vec<f32> = (0..2500).map(|i| i as f32 / 7.0).collect();
            let _pending = client
                .ask(&QueryRequest::new(0, 1, 3, &state).unwrap())
                .unwrap();
            let q = server.receive().unwrap().expect("the query");
            assert_eq!(q.request().checked_state(2500).unwrap(), &state[..]);
            assert!(q.request().checked_state(2499).is_err());
        });
    }

    #[test]
    fn another_schema_version_is_refused_naming_both_versions() {
        with_run("schema", |run| {
            let launcher = wire(run, Role::Launcher, 0);
            let stranger = Wire::connect(run, Process::new(Role::Actor, 1), 999).unwrap();
            let rx = stranger.control_receiver().unwrap();
            let mut tx = launcher.control_sender().unwrap();
            tx.send(Control {
                command: command::RUN,
                ..Control::default()
            })
            .unwrap();
            let err = rx.receive().unwrap_err();
            assert_eq!(
                err,
                WireError::SchemaMismatch {
                    service: "control",
                    ours: 999,
                    theirs: SCHEMA_VERSION,
                    sender: "launcher".to_owned(),
                }
            );
            let text = err.to_string();
            assert!(
                text.contains("999") && text.contains(&format!("version {SCHEMA_VERSION}")),
                "{text}"
            );
            // The bad message was consumed; the receiver goes on.
            assert!(rx.receive().unwrap().is_none());

            // The same on a slice service.
            let mut weights = stranger.weights_sender(3).unwrap();
            let learner_rx = launcher.weights_receiver().unwrap();
            weights.publish(1, 0, 0, &[&[1.0, 2.0], &[3.0]]).unwrap();
            let mut out = Vec::new();
            assert!(matches!(
                learner_rx.latest_into(&mut out),
                Err(WireError::SchemaMismatch {
                    ours: SCHEMA_VERSION,
                    theirs: 999,
                    ..
                })
            ));
        });
    }

    #[test]
    fn weights_reach_a_late_subscriber_and_only_the_newest_is_kept() {
        with_run("weights", |run| {
            let learner = wire(run, Role::Learner, 0);
            let actor = wire(run, Role::Actor, 0);
            let mut tx = learner.weights_sender(4500).unwrap();
            let w1: Vec<f32> = (0..4500).map(|i| i as f32 * 0.5).collect();
            tx.publish(1, 10, 20, &[&w1]).unwrap();

            // Subscribes after the publication: gets it from the history once the publisher updates.
            let rx = actor.weights_receiver().unwrap();
            tx.update_connections().unwrap();
            let mut out = Vec::new();
            let h = rx.latest_into(&mut out).unwrap().expect("history sample");
            assert_eq!(
                (h.version, h.updates, h.env_steps, h.len),
                (1, 10, 20, 4500)
            );
            assert_eq!(out, w1);

            for v in 2..=4 {
                let w: Vec<f32> = vec![v as f32; 4500];
                tx.publish(v, 0, 0, &[&w]).unwrap();
            }
            let h = rx.latest_into(&mut out).unwrap().unwrap();
            assert_eq!(h.version, 4);
            assert!(out.iter().all(|&x| x == 4.0));
            assert!(rx.latest_into(&mut out).unwrap().is_none());
        });
    }

    #[test]
    fn demo_model_bytes_round_trip() {
        with_run("demo-model", |run| {
            let expert = wire(run, Role::Expert, 2);
            let actor = wire(run, Role::Actor, 0);
            let rx = actor.demo_model_receiver().unwrap();
            let mut tx = expert.demo_model_sender().unwrap();
            // Larger than the initial 4 KiB: the publisher grows its segment.
            let bytes: Vec<u8> = (0..10_000u32).map(|i| (i % 251) as u8).collect();
            let header = DemoModelHeader {
                version: 7,
                last_demo_step: 1234,
                demos: 12,
                budget_total: 100,
                budget_left: 88,
                expert: 2,
                expert_name: name_to_bytes("cartpole-1000"),
                ..DemoModelHeader::default()
            };
            tx.publish(header, &bytes).unwrap();
            let mut out = Vec::new();
            let h = rx.latest_into(&mut out).unwrap().unwrap();
            assert_eq!(out, bytes);
            assert_eq!(
                (h.version, h.last_demo_step, h.demos, h.budget_left),
                (7, 1234, 12, 88)
            );
            assert_eq!(h.expert_name(), "cartpole-1000");
            assert_eq!(h.len, 10_000);
        });
    }

    #[test]
    fn of_two_experts_publishing_the_highest_model_version_is_kept_whatever_the_order() {
        with_run("demo-model-two", |run| {
            let old = wire(run, Role::Expert, 1);
            let new = wire(run, Role::Expert, 2);
            let actor = wire(run, Role::Actor, 0);
            let rx = actor.demo_model_receiver().unwrap();
            // A subscriber drains one publisher after another, not in the order sent: with the
            // new expert's publisher connected first, the old one's sample comes last.
            let mut tx_new = new.demo_model_sender().unwrap();
            let mut tx_old = old.demo_model_sender().unwrap();
            let header = |generation: u64, v: u64| DemoModelHeader {
                version: (generation << 32) | v,
                expert: generation as u32,
                ..DemoModelHeader::default()
            };
            // The new expert publishes first, the old one's last model after it; then the other
            // way round.
            for (first, second) in [(true, false), (false, true)] {
                for new_first in [first, second] {
                    if new_first {
                        tx_new.publish(header(2, 1), &[2]).unwrap();
                    } else {
                        tx_old.publish(header(1, 9), &[1]).unwrap();
                    }
                }
                let mut out = Vec::new();
                let h = rx.latest_into(&mut out).unwrap().expect("a model");
                assert_eq!(
                    (h.expert, h.version & 0xffff_ffff, &out[..]),
                    (2, 1, &[2u8][..])
                );
                assert!(rx.latest_into(&mut out).unwrap().is_none());
            }
            // Alone in a later call, a lower version is taken (it may be a new launch's).
            tx_old.publish(header(1, 10), &[1]).unwrap();
            let mut out = Vec::new();
            let h = rx.latest_into(&mut out).unwrap().expect("a model");
            assert_eq!(h.version, (1 << 32) | 10);
        });
    }

    #[test]
    fn a_query_without_expert_reaches_nobody() {
        with_run("query-none", |run| {
            let actor = wire(run, Role::Actor, 1);
            let mut client = actor.query_client(4).unwrap();
            assert_eq!(actor.query_servers().unwrap(), 0);
            let mut pending = client
                .ask(&QueryRequest::new(1, 9, 0, &[0.1, 0.2, 0.3, 0.4]).unwrap())
                .unwrap();
            assert_eq!(pending.servers(), 0);
            assert!(pending.poll().unwrap().is_none());
        });
    }

    #[test]
    fn a_query_is_answered_once_and_duplicates_are_dropped() {
        with_run("query", |run| {
            let actor = wire(run, Role::Actor, 1);
            let old = wire(run, Role::Expert, 1);
            let new = wire(run, Role::Expert, 2);
            let s1 = old.query_server().unwrap();
            let s2 = new.query_server().unwrap();
            let mut client = actor.query_client(4).unwrap();
            assert_eq!(actor.query_servers().unwrap(), 2);

            // A first request, answered by nobody, then a second one answered by both experts.
            drop(
                client
                    .ask(&QueryRequest::new(1, 9, 5, &[0.0; 4]).unwrap())
                    .unwrap(),
            );
            let mut pending = client
                .ask(&QueryRequest::new(1, 9, 42, &[0.1, 0.2, 0.3, 0.4]).unwrap())
                .unwrap();
            assert_eq!(pending.seq(), 2);
            assert_eq!(pending.servers(), 2);
            for (server, expert, action) in [(&s1, 1u32, 0u32), (&s2, 2, 1)] {
                // The dropped first request may or may not still be queued; skip it.
                let mut q = server.receive().unwrap().expect("a request");
                if q.request().header.seq == 1 {
                    q = server.receive().unwrap().expect("the second request");
                }
                assert_eq!(q.request().state(), &[0.1, 0.2, 0.3, 0.4]);
                assert_eq!(q.request().global_step, 42);
                assert_eq!(q.request().header.sender(), "actor-1");
                assert!(q.is_connected());
                q.answer(QueryResponse {
                    outcome: outcome::ANSWERED,
                    action,
                    expert,
                    demo_index: 3,
                    expert_name: name_to_bytes(&format!("expert-{expert}")),
                    ..QueryResponse::default()
                })
                .unwrap();
            }
            let first = pending.poll().unwrap().expect("an answer");
            assert_eq!(
                (first.request_seq, first.actor, first.action, first.expert),
                (2, 1, 0, 1)
            );
            assert_eq!(first.expert_name(), "expert-1");
            assert!(
                pending.poll().unwrap().is_none(),
                "the second answer is dropped"
            );
            assert_eq!(pending.duplicates(), 1);
        });
    }

    #[test]
    fn an_abandoned_query_is_seen_by_the_expert() {
        with_run("query-abandoned", |run| {
            let actor = wire(run, Role::Actor, 0);
            let expert = wire(run, Role::Expert, 1);
            let server = expert.query_server().unwrap();
            let mut client = actor.query_client(4).unwrap();
            let pending = client
                .ask(&QueryRequest::new(0, 1, 0, &[0.0; 4]).unwrap())
                .unwrap();
            let q = server.receive().unwrap().unwrap();
            assert!(q.is_connected());
            drop(pending); // the actor timed out
            assert!(!q.is_connected(), "the expert must not spend budget on it");
        });
    }

    #[test]
    fn credits_and_progress_carry_their_fields() {
        with_run("credits", |run| {
            let learner = wire(run, Role::Learner, 0);
            let actor = wire(run, Role::Actor, 2);
            let launcher = wire(run, Role::Launcher, 0);
            let mut credits = learner.credits_sender().unwrap();
            let crx = actor.credits_receiver().unwrap();
            let mut c = Credits {
                env_steps: 500,
                updates: 480,
                ..Credits::default()
            };
            c.incarnation[2] = 11;
            c.granted[2] = 96;
            credits.send(c).unwrap();
            c.granted[2] = 128;
            credits.send(c).unwrap();
            let got = crx.latest().unwrap().unwrap();
            assert_eq!(got.granted_for(2, 11), Some(128));
            assert_eq!(
                got.granted_for(2, 12),
                None,
                "a grant for another incarnation"
            );
            assert_eq!(got.granted_for(99, 11), None);
            assert_eq!(got.env_steps, 500);

            let prx = launcher.progress_receiver().unwrap();
            let mut ptx = actor.progress_sender().unwrap();
            for e in 0..3u32 {
                let record = alfd_common::record::EpisodeRecord {
                    episode: e,
                    ret: 10.0 + f64::from(e),
                    length: 10 + e,
                    actor: 3,
                    ..Default::default()
                };
                ptx.send(Progress::episode(1, record)).unwrap();
            }
            let mut seen = Vec::new();
            while let Some(p) = prx.receive().unwrap() {
                assert_eq!(p.kind, progress_kind::EPISODE);
                let r = p.episode.0;
                assert_eq!(r.actor, 3, "the record arrives whole");
                seen.push((p.header.seq, r.episode, r.ret, r.length));
            }
            assert_eq!(
                seen,
                vec![(0, 0, 10.0, 10), (1, 1, 11.0, 11), (2, 2, 12.0, 12)]
            );
        });
    }
}
