//! The launcher's side of a run across hosts (`alfd run --listen`): starting the hub once the
//! learner is up, taking in remote hosts' joins and departures, and a remote host's expert
//! (`alfd join --expert`): the expert lifecycle decides as for a local one (a swap to it, make
//! before break); its process is started, killed and seen to exit through the hub.

use std::collections::HashMap;
use std::time::Instant;

use crate::Result;
use alfd_harness::What as _;
use tracing::{info, warn};

use alfd_harness::RUNTIME_FILE;
use alfd_wire::command;

use super::{Launcher, SwapRequest};
use crate::expert_lifecycle::Exit;

pub use alfd_bridge::{Endpoint, Hub};

/// The request id of a swap to a remote host's expert.
const JOIN_SWAP: &str = "join:";

/// Expert generations served by remote hosts.
#[derive(Debug, Default)]
pub(super) struct RemoteExperts {
    /// The host whose offer is being taken to the expert lifecycle now (its `Spawn` goes there).
    offering: Option<String>,
    /// Generation → the host serving it.
    hosts: HashMap<u16, String>,
}

impl RemoteExperts {
    /// Remote expert generations that have not exited.
    pub(super) fn serving(&self) -> usize {
        self.hosts.len()
    }
}

impl Launcher<'_, '_> {
    pub(super) fn start_hub(&self, endpoint: &Endpoint) -> Result<Hub> {
        let read = |name: &str| {
            std::fs::read_to_string(self.plan.run_dir.join(name))
                .what(|| format!("cannot read {name} of the run"))
        };
        let hub = alfd_bridge::Hub::start(alfd_bridge::HubOptions {
            endpoint: endpoint.clone(),
            run_id: self.plan.run_id.clone(),
            local_actors: self.plan.actors,
            first_incarnation: self.plan.first_incarnation(),
            max_restarts: self.plan.max_restarts,
            config_toml: read("config.toml")?,
            runtime_toml: read(RUNTIME_FILE)?,
            query_timeout: self.plan.runtime.query_timeout(),
            demos_path: self.plan.run_dir.join("demos.jsonl"),
        })
        .what(|| format!("cannot listen on {endpoint} for remote actors"))?;
        Ok(hub)
    }

    /// Takes in joins and departures of remote hosts. A host that left (its link dropped, its
    /// process died) took its actors with it: like crashed actors, their ids are free again and
    /// a host that joins gets them with new incarnations; the learner's credit book takes a new
    /// incarnation as a new actor.
    pub(super) fn check_hub(&mut self) -> Result<()> {
        let Some(hub) = &self.hub else { return Ok(()) };
        self.hub_counts = (hub.demos_refused(), hub.answers_late());
        let running = self.control.command != command::SHUTDOWN;
        for event in hub.events() {
            match event {
                alfd_bridge::HubEvent::Joined {
                    join_id,
                    host,
                    actors,
                    expert,
                } => {
                    self.remote_joins += 1;
                    info!(%host, %join_id, ?actors, ?expert, "remote host joined");
                    if let (Some(name), true) = (expert, running) {
                        // A swap to the remote host's expert, as `alfd swap-expert` asks.
                        self.remote_experts.offering = Some(join_id.clone());
                        let request = SwapRequest {
                            id: format!("{JOIN_SWAP}{join_id}"),
                            expert: name,
                            change: None,
                        };
                        let actions = self.experts.swap(request, Instant::now());
                        let r = self.apply(actions);
                        self.remote_experts.offering = None;
                        r?;
                    }
                }
                alfd_bridge::HubEvent::Left {
                    join_id,
                    actors,
                    expert,
                } => {
                    if running {
                        self.remote_losses += 1;
                        warn!(%join_id, ?actors, expert, "a remote host left or its link dropped: its actors are gone");
                    } else {
                        info!(%join_id, ?actors, "remote actors stopped");
                    }
                    let lost: Vec<u16> = self
                        .remote_experts
                        .hosts
                        .iter()
                        .filter(|(_, j)| **j == join_id)
                        .map(|(g, _)| *g)
                        .collect();
                    for generation in lost {
                        let how = "was lost with its host (it left or the link dropped)";
                        self.remote_expert_exited(generation, how.to_owned(), None, running)?;
                    }
                }
                alfd_bridge::HubEvent::Restarted {
                    join_id,
                    actor,
                    incarnation,
                } => {
                    // Counted with the launcher's own actors' restarts (the roster decided it).
                    self.remote_restarts += 1;
                    warn!(%join_id, actor, incarnation, "a remote actor died; its host restarts it");
                }
                alfd_bridge::HubEvent::ExpertExited {
                    generation,
                    how,
                    code,
                } => self.remote_expert_exited(generation, how, code, running)?,
            }
        }
        Ok(())
    }

    fn remote_expert_exited(
        &mut self,
        generation: u16,
        how: String,
        code: Option<i32>,
        running: bool,
    ) -> Result<()> {
        let Some(join_id) = self.remote_experts.hosts.remove(&generation) else {
            return Ok(());
        };
        if !running {
            return Ok(());
        }
        let exit = Exit {
            how: format!("{how} (on the remote host {join_id})"),
            code,
            reason: None,
        };
        if generation == self.experts.active() {
            warn!("remote expert-{generation} {}", exit.how);
        } else {
            info!("remote expert-{generation} {}", exit.how);
        }
        // Restarted here under the same name if it can be; else the run goes on without it.
        let actions = self.experts.lost(generation, &exit, Instant::now());
        self.apply(actions)
    }

    /// A `Spawn` of the lifecycle while a remote host's offer is taken: the host starts it.
    pub(super) fn spawn_remote_expert(&mut self, generation: u16, name: &str) -> bool {
        let (Some(join_id), Some(hub)) = (self.remote_experts.offering.clone(), &self.hub) else {
            return false;
        };
        info!(generation, expert = %name, %join_id, "starting the remote host's expert");
        hub.order(alfd_bridge::ExpertOrder::Start {
            join_id: join_id.clone(),
            generation,
            name: name.to_owned(),
        });
        self.remote_experts.hosts.insert(generation, join_id);
        true
    }

    /// A `Kill` of a remote generation: its host kills it (and reports it exited).
    pub(super) fn kill_remote_expert(&mut self, generation: u16) {
        if let (true, Some(hub)) = (
            self.remote_experts.hosts.contains_key(&generation),
            &self.hub,
        ) {
            hub.order(alfd_bridge::ExpertOrder::Kill { generation });
        }
    }

    /// The end of a swap to a remote host's expert: nothing to write for `alfd swap-expert`;
    /// a refusal goes to the host. Returns whether `request` was such a swap.
    pub(super) fn answer_remote_expert(
        &mut self,
        request: &SwapRequest,
        ok: bool,
        message: &str,
    ) -> bool {
        let Some(join_id) = request.id.strip_prefix(JOIN_SWAP) else {
            return false;
        };
        if ok {
            info!(%join_id, expert = %request.expert, "the remote host's expert answers");
        } else if let Some(hub) = &self.hub {
            warn!(%join_id, "the remote host's expert refused: {message}");
            hub.order(alfd_bridge::ExpertOrder::Refuse {
                join_id: join_id.to_owned(),
                why: message.to_owned(),
            });
        }
        true
    }
}
