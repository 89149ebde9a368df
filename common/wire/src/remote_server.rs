//! The serving side of `remote/<name>` in Rust: what `deploy/python/alfd_adapter.py` does for
//! a Python policy, [`RemoteServer`] does for a demonstrator of this workspace, so that each of
//! several experts can answer from a process of its own.

use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::SignalHandlingMode;

use crate::connection::Transport;
use crate::error::{transport, Result};
use crate::messages::{Header, Role};
use crate::remote::REMOTE_MESSAGE_LEN;
use crate::remote::{remote_status, RemoteRequest, RemoteResponse, RemoteServices};

/// A server of `remote/<name>`: it takes requests, answers each through a handler, and wakes the
/// clients.
pub struct RemoteServer {
    server: Server<Transport, RemoteRequest, (), RemoteResponse, ()>,
    requests: Listener<Transport>,
    reply: Notifier<Transport>,
    service: String,
    schema: u32,
    seq: u64,
    // Dropped last: the ports above belong to it.
    node: iceoryx2::node::Node<Transport>,
}

impl std::fmt::Debug for RemoteServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RemoteServer({}, {} answered)", self.service, self.seq)
    }
}

impl RemoteServer {
    /// Serves `remote/<name>` of run `run_id` (one server per service: a second one is an error
    /// naming the service). SIGINT and SIGTERM are caught from here on: see
    /// [`RemoteServer::termination_requested`].
    pub fn create(run_id: &str, name: &str, schema: u32) -> Result<Self> {
        let service = format!("remote/{name}");
        let ports = RemoteServices::open(
            run_id,
            name,
            &format!("server-{name}"),
            SignalHandlingMode::HandleTerminationRequests,
        )?;
        let server = ports
            .rr
            .server_builder()
            .create()
            .map_err(transport("create a server on", service.clone()))?;
        let requests = ports
            .request
            .listener_builder()
            .create()
            .map_err(transport("create a listener on", service.clone()))?;
        let reply = ports
            .reply
            .notifier_builder()
            .create()
            .map_err(transport("create a notifier on", service.clone()))?;
        Ok(Self {
            server,
            requests,
            reply,
            service,
            schema,
            seq: 0,
            node: ports.node,
        })
    }

    /// The service's name (`remote/<name>`), for messages.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Whether SIGINT or SIGTERM arrived (sticky).
    pub fn termination_requested(&self) -> bool {
        crate::connection::termination_requested(&self.node)
    }

    /// Waits up to `wait` for requests (a signal cuts the wait short), answers every one that
    /// came with `handle` (its `Err` is sent as a failed request with the message), and returns
    /// how many it answered.
    pub fn serve(
        &mut self,
        wait: Duration,
        handle: &mut dyn FnMut(&RemoteRequest) -> std::result::Result<RemoteResponse, String>,
    ) -> Result<usize> {
        let _ = self.requests.timed_wait(|_| {}, wait);
        let mut answered = 0;
        while let Some(active) = self
            .server
            .receive()
            .map_err(transport("receive on", self.service.clone()))?
        {
            let request = *active.payload();
            let response = self.respond(&request, handle);
            // A client gone meanwhile gets nothing: no error of the server's.
            let _ = active.send_copy(response);
            answered += 1;
        }
        if answered > 0 {
            self.reply
                .notify()
                .map_err(transport("notify", self.service.clone()))?;
        }
        Ok(answered)
    }

    fn respond(
        &mut self,
        request: &RemoteRequest,
        handle: &mut dyn FnMut(&RemoteRequest) -> std::result::Result<RemoteResponse, String>,
    ) -> RemoteResponse {
        let answer = if request.header.schema != self.schema {
            Err(format!(
                "schema version {}, the server speaks {}",
                request.header.schema, self.schema
            ))
        } else {
            handle(request)
        };
        let mut response = answer.unwrap_or_else(|message| failed(&message));
        response.header = Header {
            schema: self.schema,
            role: Role::Tool as u16,
            id: 0,
            seq: self.seq,
        };
        self.seq += 1;
        response.request_seq = request.header.seq;
        response.kind = request.kind;
        response.session = request.session;
        response
    }
}

/// A failed request's answer, its message cut to what the message field holds.
fn failed(message: &str) -> RemoteResponse {
    let mut response = RemoteResponse {
        status: remote_status::FAILED,
        ..RemoteResponse::default()
    };
    let mut end = message.len().min(REMOTE_MESSAGE_LEN - 1);
    while !message.is_char_boundary(end) {
        end -= 1;
    }
    response.message[..end].copy_from_slice(&message.as_bytes()[..end]);
    response
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    use super::*;
    use crate::messages::Process;
    use crate::remote::{remote_kind, RemoteClient, RemoteDemonstrator};
    use crate::test_support::with_run;

    #[test]
    fn a_rust_server_answers_a_remote_demonstrators_questions_and_names_what_it_refuses() {
        with_run("remote-server", |run| {
            let run_id = run.to_owned();
            let stop = Arc::new(AtomicBool::new(false));
            let stopped = stop.clone();
            let server = std::thread::spawn(move || {
                let mut server = RemoteServer::create(&run_id, "expert-1-0", 7).unwrap();
                // The action: how many values are above zero; none above zero is refused.
                let mut act = |r: &RemoteRequest| {
                    assert_eq!(r.kind, remote_kind::ACT);
                    let above = r.values[..r.len as usize]
                        .iter()
                        .filter(|&&v| v > 0.0)
                        .count();
                    match above {
                        0 => Err("nothing above zero".repeat(20)),
                        n => Ok(RemoteResponse {
                            action: n as u32,
                            ..RemoteResponse::default()
                        }),
                    }
                };
                while !stopped.load(Ordering::Relaxed) {
                    server.serve(Duration::from_millis(20), &mut act).unwrap();
                }
            });
            let me = Process::new(Role::Expert, 1);
            let client = RemoteClient::connect(
                run,
                "expert-1-0",
                me,
                7,
                Duration::from_secs(10),
                &mut || None,
            )
            .unwrap();
            let mut remote = RemoteDemonstrator::new(client, 4);
            let wait = Duration::from_secs(10);
            assert_eq!(remote.act(&[1.0, -1.0, 2.0], wait).unwrap(), 2);
            assert_eq!(remote.act(&[3.0, 0.5, 2.0], wait).unwrap(), 3);
            let refused = remote.act(&[-1.0], wait).unwrap_err().to_string();
            assert!(refused.contains("nothing above zero"), "{refused}");
            assert!(refused.contains("remote/expert-1-0"), "{refused}");
            // An action the environment does not have is refused by the client.
            let e = remote.act(&[1.0; 5], wait).unwrap_err().to_string();
            assert!(e.contains("action"), "{e}");
            stop.store(true, Ordering::Relaxed);
            server.join().unwrap();
        });
    }

    #[test]
    fn a_failed_answers_message_is_cut_on_a_character_boundary() {
        let long = "é".repeat(REMOTE_MESSAGE_LEN);
        let r = failed(&long);
        assert_eq!(r.status, remote_status::FAILED);
        let m = r.message();
        assert!(!m.is_empty() && m.len() < REMOTE_MESSAGE_LEN, "{}", m.len());
        assert!(m.chars().all(|c| c == 'é'), "{m}");
    }
}
