//! Runs across hosts: a bridge between a run's iceoryx2 services and zenoh.
//!
//! iceoryx2 is shared memory, so every process of a run sits on one host. To put actors on
//! other hosts, the learner's host runs a [`Hub`] (`alfd run --listen quic/ADDR:PORT`) and each
//! other host a [`Mirror`] (`alfd join --connect quic/ADDR:PORT --actors N`): a local copy of the
//! run's services under a run id of its own, in which the actor processes run unchanged. The
//! two bridges carry every message whole over zenoh ([`Frame`]: the wire's own message with its
//! header, sender, sequence number and schema version, behind the frame's schema version).
//!
//! # Keys of one run
//! | key                          | what                                               |
//! |------------------------------|----------------------------------------------------|
//! | `alfd/<run>/join`            | queryable: a remote host asks for actor ids        |
//! | `alfd/<run>/restart`         | queryable: a remote host restarts a crashed actor (a new incarnation) |
//! | `alfd/<run>/up/<join>`       | a remote host → hub: transitions, progress, queries, a remote expert's answers |
//! | `alfd/<run>/down`            | hub → remote hosts: credits, weights, model, control, answers; to a remote expert: orders, queries, `demos.jsonl` |
//! | `alfd/<run>/hub`             | liveliness: the hub                                |
//! | `alfd/<run>/member/<join>`   | liveliness: a joined host (gone = its actors crashed) |
//!
//! A remote host may also serve the run's expert (`alfd join --expert NAME`, an [`ExpertHost`]):
//! every line its expert appends to that host's `demos.jsonl` comes up in order, and the hub
//! appends it to the run's before any actor hears the answer that gives it, so the two files
//! hold the same demonstrations whatever the answers' fate (an answer that comes after its
//! actor stopped waiting is counted late, its demonstration kept).
//!
//! One run id is one key prefix, so two runs never see each other's messages. Peers prove who
//! they are with certificates of the run's CA (mutual TLS, see [`TlsFiles`]); plain TCP only
//! when the user says so ([`Security::Insecure`]).

//!
//! # Design
//!
//! Why a bridge, not remote transports in the actor. The alternative, new `Adder`,
//! `VariableSource` and `ExpertClient` implementations speaking zenoh inside `alfd-actor`, would
//! give the actor a second set of links, a second credit wait and a second query path to keep in
//! step with the first. With the bridge the actor, the learner and the expert do not know hosts
//! exist: the one environment loop, the one credit protocol (`CreditBook`), the one query path and
//! the one control/heartbeat path serve both cases, and everything tested on one host holds on two.
//! It is also the shape of iceoryx2's own gateway (not published for 0.10, and without
//! request-response: the query travels here as a request frame and an answer frame, matched by the
//! actor's own request number). The cost is a hop through shared memory on each side (microseconds)
//! beside the network's.
//!
//! Waking, not polling. Each bridge blocks in one WaitSet on several doorbells
//! (`Wire::waiter_on`): the hub on every actor's (the learner rings them for credits, the expert for
//! answers) and its own, the mirror on the learner's, the expert's and the launcher's (its actors
//! ring those) and its own. zenoh's callbacks run on zenoh's threads while iceoryx2 ports stay on
//! the bridge's thread: a callback posts the frame and a small ringer thread rings the bridge's own
//! doorbell (`Doorbell::Bridge`). The learner rings nobody when it publishes weights or credits an
//! unblocked actor: the hub looks at those at least every 5 ms (`TICK`).
//!
//! Late joiners. zenoh keeps no history: the hub keeps the newest frame of each down service and
//! sends them again when a joined host's liveliness token appears (declared after the mirror
//! subscribed), and the mirror republishes them into its services with history 1.
//!
//! Faults. A joined host holds a liveliness token; when it goes (the process died, the TCP link
//! closed) the hub frees its actor ids (`Roster::leave`) and the launcher logs the loss; the
//! learner's credit book already treats the next holder of an id, a new incarnation, as a new actor
//! process. On the remote side the launcher's control messages (every 200 ms) stop coming: `alfd
//! join` stops its actors after 5 s of silence, and an actor whose `alfd join` died sees its parent
//! gone, as on one host. A remote actor that crashes is restarted by its `alfd join`, as the
//! launcher restarts its own: it asks the hub (`alfd/<run>/restart`, a zenoh query) for a new
//! incarnation of the id it holds; `Roster::restart` gives one while the id's restarts since the
//! host joined are under the run's `--max-restarts`, and the launcher counts it in
//! `actor_restarts` (`HubEvent::Restarted`). A remote expert unreachable is a query that times out (the actor acts on
//! its own); demonstrations are written on the learner's host before they are answered, so no link
//! loss can lose one. An expert host lost is its generation's exit, told to the `ExpertLifecycle`
//! as `lost`: the expert is restarted on the learner's host under the same name, as after a crash,
//! but a replacement that cannot start there (a `python:` module only the lost host had) or no
//! restart left is `Action::NoExpert`, not `Fail`: the run goes on without an expert until a swap
//! brings one. The hub takes nothing more from a generation whose host left (an answer still in
//! its inbox is neither written nor answered), and it publishes a remote expert's model only once
//! the demonstrations the model counts are written here (the model travels before its answer), so
//! the run's `demos_used` never counts a line its `demos.jsonl` lacks. Remote actors have no per-actor episode shares: with `--listen` every actor
//! plays until the run's limit, and the launcher records episodes up to it.
//!
//! An expert on another host. `alfd join --expert NAME` offers the run an expert; the launcher
//! takes the offer to its `ExpertLifecycle` as a swap, unchanged: the lifecycle's `Spawn`, `Kill`
//! and the process's exit go through the hub (an order down, `ExpertExited` up; a host that leaves
//! is an exit) instead of `fork` and `waitpid`. The remote expert runs on an expert host (its own
//! iceoryx2 copy of the run, apart from the host's actors, so that their queries too go through the
//! learner's host). While its generation is active the hub serves the learner's host's query
//! service: it holds each query, sends it down, and answers it when the expert's answer comes up.
//! *Where demonstrations are written, and why:* on one host the expert appends a demonstration to
//! `RUN_DIR/demos.jsonl` before it answers, and its successor reads the file back when it becomes
//! active. Across hosts the same two rules hold on the learner's host: the remote expert's answer
//! travels up with its demonstration (the line it appended on its own host first), and the hub
//! appends that line to `RUN_DIR/demos.jsonl` (fsync'd, only as the file's next index) before it
//! answers the actor; and the hub sends `RUN_DIR/demos.jsonl` whole down before the control
//! message that makes a remote generation active (one publisher, in order), so the remote expert
//! reads the run's demonstrations back as a local one would. The other choice, the remote host
//! holding the file and the learner's host copying it, would leave demonstrations that actors have
//! used only on the host that can be lost; with this one a lost link loses only an answer no actor
//! saw (the remote copy may then hold one line more than the run's, never fewer). The expert host
//! sends its reports last in each pass and its exit after everything before it, so the launcher
//! makes the next expert active only once every answer of the old one is written; the budget is
//! the file's, on either host.
//!
//! Why not iceoryx2's own link. iceoryx2 0.10 has a cross-host link (`iceoryx2-link`,
//! `iceoryx2-link-tunnel`, the zenoh carrier `iceoryx2-integrations-zenoh-link-carrier`, the tool
//! `iox2 link tunnel zenoh`; `iceoryx2-link-tunnel` 0.10.0 and the carrier 0.10.0 are on crates.io);
//! read at the 0.10.0 crate's sources and the release notes, it lacks what the bridges above give a
//! run, so they stay (its own documentation: "publish-subscribe and event services are relayed",
//! and it "assumes systems that trust each other, over a carrier they trust" that "neither
//! corrupts, loses, repeats nor reorders a frame"):
//! - it relays publish-subscribe and event services only: request-response (the `query` service,
//!   and an actor seeing whether an expert still holds its query) is not carried (iceoryx2 issue
//!   #818), so neither is "written to `demos.jsonl` before the answer is visible";
//! - it puts the header and payload bytes on zenoh with no sender, sequence number or
//!   acknowledgement, and its receiving queue drops when full (64 samples): nothing detects a gap or
//!   a duplicate, and a never-dropped channel under credits (`transitions`) is not one over it;
//!   its documentation assumes a carrier that "neither corrupts, loses, repeats nor reorders";
//! - a mirrored service gets the local defaults (history 0), so a host joining late does not get
//!   the newest weights or model until the next publication;
//! - it has no notion of an active expert: two experts offering the service are both mirrored, so
//!   make-before-break swaps across hosts need the hub's `ExpertDesk` anyway;
//! - it adds no authentication (left to zenoh's configuration) and calls itself a prototype.
//!
//! It could carry the weights, the demonstration model and the doorbells; the bridges would still
//! need their sequence numbers, credits, answers and roster on top, so it would replace little.

mod demos;
mod desk;
mod endpoint;
mod error;
mod expert_host;
mod frame;
#[cfg(test)]
mod fuzz;
mod hub;
mod inbox;
mod link;
mod mirror;
#[doc(hidden)]
pub mod peer_bytes;
mod roster;
mod shipper;
mod tls;
mod worker;

use std::time::Duration;

pub use endpoint::Endpoint;
pub use error::{BridgeError, Result};
pub use expert_host::{ExpertHost, ExpertHostOrder};
pub use frame::{decode, encode, ExpertOrder, Frame};
pub use hub::{Hub, HubEvent, HubOptions};
pub use mirror::{join, Mirror, Remote};
pub use roster::{JoinReply, JoinRequest, Joined, Left, RestartReply, RestartRequest, Roster};
pub use tls::{make_ca, make_host, tls_reason, valid_for, CaMade, Security, TlsFiles};

/// The longest a bridge sleeps between two looks at what this host published (the learner's
/// weights and credits ring nobody); rings wake it sooner.
pub(crate) const TICK: Duration = Duration::from_millis(5);

/// The zenoh keys of a run.
pub(crate) mod keys {
    pub fn join(run: &str) -> String {
        format!("alfd/{run}/join")
    }
    pub fn restart(run: &str) -> String {
        format!("alfd/{run}/restart")
    }
    /// Where the joined host `join` sends its frames up: the hub knows the sender by the key.
    pub fn up(run: &str, join: &str) -> String {
        format!("alfd/{run}/up/{join}")
    }
    /// Every joined host's up key.
    pub fn up_all(run: &str) -> String {
        format!("alfd/{run}/up/*")
    }
    /// The joined host whose up key `key` is.
    pub fn up_sender(key: &str) -> Option<&str> {
        key.rsplit_once("/up/")
            .map(|(_, join)| join)
            .filter(|j| !j.contains('/'))
    }
    pub fn down(run: &str) -> String {
        format!("alfd/{run}/down")
    }
    pub fn hub(run: &str) -> String {
        format!("alfd/{run}/hub")
    }
    pub fn member(run: &str, join: &str) -> String {
        format!("alfd/{run}/member/{join}")
    }
}
