//! The launcher's side of a run across hosts (`alfd run --listen`): starting the hub once the
//! learner is up, and taking in remote hosts' joins and departures.

use anyhow::Context as _;
use tracing::{info, warn};

use alfd_harness::RUNTIME_FILE;
use alfd_wire::command;

use super::Launcher;

impl Launcher<'_, '_> {
    pub(super) fn start_hub(
        &self,
        endpoint: &alfd_bridge::Endpoint,
    ) -> anyhow::Result<alfd_bridge::Hub> {
        let read = |name: &str| {
            std::fs::read_to_string(self.plan.run_dir.join(name))
                .with_context(|| format!("cannot read {name} of the run"))
        };
        alfd_bridge::Hub::start(alfd_bridge::HubOptions {
            endpoint: endpoint.clone(),
            run_id: self.plan.run_id.clone(),
            local_actors: self.plan.actors,
            first_incarnation: self.plan.first_incarnation(),
            config_toml: read("config.toml")?,
            runtime_toml: read(RUNTIME_FILE)?,
            query_timeout: self.plan.runtime.query_timeout(),
        })
        .with_context(|| format!("cannot listen on {endpoint} for remote actors"))
    }

    /// Takes in joins and departures of remote hosts. A host that left (its link dropped, its
    /// process died) took its actors with it: like crashed actors, their ids are free again and
    /// a host that joins gets them with new incarnations; the learner's credit book takes a new
    /// incarnation as a new actor.
    pub(super) fn check_hub(&mut self) {
        let Some(hub) = &self.hub else { return };
        for event in hub.events() {
            match event {
                alfd_bridge::HubEvent::Joined {
                    join_id,
                    host,
                    actors,
                } => {
                    self.remote_joins += 1;
                    info!(%host, %join_id, ?actors, "remote actors joined");
                }
                alfd_bridge::HubEvent::Left { join_id, actors } => {
                    if self.control.command != command::SHUTDOWN {
                        self.remote_losses += 1;
                        warn!(%join_id, ?actors, "a remote host left or its link dropped: its actors are gone");
                    } else {
                        info!(%join_id, ?actors, "remote actors stopped");
                    }
                }
            }
        }
    }
}
