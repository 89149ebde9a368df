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
