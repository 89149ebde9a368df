//! One of several experts in a process of its own (`alfd-expert --member I`): the expert process
//! of a run with `[[experts]]` starts one per built-in expert and one for a person's page (see
//! `page_member`), as it starts a Python adapter per external one, and asks each through
//! `remote/expert-<generation>-<I>`. Budget, routing,
//! `demos.jsonl` and the demonstration model stay in the expert process; this one only answers.
//!
//! It stops on SIGINT or SIGTERM, and by itself once the process that started it is gone.

use std::time::Duration;

use alfd_common::agent::Demonstrator;
use alfd_common::restarts::{Ended, GiveUp, Restarts, Verdict};
use alfd_demonstrators::registry;
use alfd_harness::python::AdapterDemonstrator;
use alfd_wire::{remote_kind, RemoteRequest, RemoteResponse, RemoteServer};
use tracing::{info, warn};

use crate::Args;

/// How long one wait for a request lasts: how soon a gone parent is noticed.
const POLL: Duration = Duration::from_millis(200);

/// The name of `[[experts]]`' `member`-th expert's service and log (`expert-<generation>-<i>`).
pub fn member_name(generation: u16, member: usize) -> String {
    format!("expert-{generation}-{member}")
}

/// Serves the built-in expert at place `member` of the run's `[[experts]]` until a signal or the
/// end of its parent.
pub fn serve(args: &Args, member: usize, schema: u32) -> alfd_harness::Result<()> {
    let setup = args.process.load()?;
    let (_, actions) = setup.env_dims()?;
    let (_, cfg) = crate::process::roster(args, &setup.config)?;
    if cfg
        .experts
        .get(member)
        .is_some_and(|e| e.name == crate::human::HUMAN)
    {
        return crate::page_member::serve(args, member, schema);
    }
    let mut expert = registry::member(&cfg, member)?;
    let name = member_name(args.generation, member);
    let mut server = RemoteServer::create(&args.process.run_id, &name, schema)?;
    let parent = args
        .parent
        .unwrap_or_else(std::os::unix::process::parent_id);
    info!(expert = %cfg.experts[member].name, service = server.service(), "serving");
    let mut answered = 0;
    while !server.termination_requested() {
        answered += server.serve(POLL, &mut |r| act(expert.as_mut(), actions, r))?;
        if std::os::unix::process::parent_id() != parent {
            info!(answered, "the process that started it has gone: stopping");
            return Ok(());
        }
    }
    info!(answered, "stopping");
    Ok(())
}

/// The expert's answer to one request.
fn act(
    expert: &mut dyn Demonstrator<[f32]>,
    actions: usize,
    r: &RemoteRequest,
) -> Result<RemoteResponse, String> {
    if r.kind != remote_kind::ACT {
        return Err(format!(
            "an expert answers ACT ({}), not {}",
            remote_kind::ACT,
            r.kind
        ));
    }
    let len = (r.len as usize).min(r.values.len());
    let obs: Vec<f32> = r.values[..len].iter().map(|&v| v as f32).collect();
    let action = expert.try_act(&obs)?;
    if action >= actions {
        return Err(format!("action {action} of {actions}"));
    }
    Ok(RemoteResponse {
        action: action as u32,
        ..RemoteResponse::default()
    })
}

/// Starts one of several experts' processes and connects to it.
pub type Start = Box<dyn FnMut() -> alfd_harness::Result<AdapterDemonstrator>>;

/// One of several experts answering from a process of its own, which the expert process
/// supervises: a process that has ended is started again before the next question, under the
/// run's restart rule (`--max-restarts`; never after it refused its input), and only then, or
/// when it does not answer in time, is the expert marked down by the panel.
pub struct Supervised {
    expert: AdapterDemonstrator,
    start: Start,
    restarts: Restarts<()>,
    name: String,
    run_id: String,
}

impl Supervised {
    /// Starts the expert `name` with `start`, to restart it at most `max_restarts` times.
    pub fn start(
        mut start: Start,
        name: &str,
        run_id: &str,
        max_restarts: u32,
    ) -> alfd_harness::Result<Self> {
        Ok(Self {
            expert: start()?,
            start,
            restarts: Restarts::new(max_restarts),
            name: name.to_owned(),
            run_id: run_id.to_owned(),
        })
    }

    /// Starts the process again if it ended and the restart rule allows; why not otherwise.
    fn revive(&mut self) -> Result<(), String> {
        let exited = self.expert.exited();
        match restart_due(&mut self.restarts, exited, &self.run_id) {
            Ok(None) => Ok(()),
            Ok(Some(nth)) => {
                warn!(expert = %self.name, nth, code = ?exited.flatten(), "its process ended: starting it again");
                self.expert = (self.start)()
                    .map_err(|e| format!("{} cannot be started again: {e}", self.name))?;
                Ok(())
            }
            Err(why) => Err(format!("{} {why}", self.name)),
        }
    }
}

/// Whether a member's process, `exited` as [`alfd_harness::python::Adapter::exited`] says, is
/// to be started again under `restarts`: `Ok(None)` while it runs (or once it finished),
/// `Ok(Some(nth))` for its `nth` restart (what the dead process held in the run's shared memory,
/// its server of the service, is removed first), or why not.
pub(crate) fn restart_due(
    restarts: &mut Restarts<()>,
    exited: Option<Option<i32>>,
    run_id: &str,
) -> Result<Option<u32>, GiveUp> {
    let Some(code) = exited else {
        return Ok(None);
    };
    match restarts.ended(&(), Ended::of(code, false)) {
        Verdict::Restart { nth } => {
            let _ = alfd_wire::cleanup_dead_nodes(run_id);
            Ok(Some(nth))
        }
        Verdict::GiveUp(why) => Err(why),
        Verdict::Done => Ok(None),
    }
}

impl Demonstrator<[f32]> for Supervised {
    fn act(&mut self, s: &[f32]) -> usize {
        self.try_act(s).unwrap_or_else(|e| {
            tracing::error!("{e}");
            0
        })
    }

    fn try_act(&mut self, s: &[f32]) -> Result<usize, String> {
        self.revive()?;
        match self.expert.try_act(s) {
            // Killed while it was asked: started again, it is asked again.
            Err(_) if self.expert.exited().is_some() => {
                self.revive()?;
                self.expert.try_act(s)
            }
            answer => answer,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Sign;

    impl Demonstrator<[f32]> for Sign {
        fn act(&mut self, s: &[f32]) -> usize {
            usize::from(s[0] > 0.0) + usize::from(s[0] > 10.0) * 5
        }
    }

    #[test]
    fn a_member_answers_act_with_its_experts_action_and_refuses_anything_else() {
        let ask = |kind, values: &[f64]| {
            let r = RemoteRequest::new(kind, 0).with_values(values).unwrap();
            act(&mut Sign, 2, &r)
        };
        assert_eq!(ask(remote_kind::ACT, &[0.5]).unwrap().action, 1);
        assert_eq!(ask(remote_kind::ACT, &[-0.5]).unwrap().action, 0);
        let e = ask(remote_kind::STEP, &[0.5]).unwrap_err();
        assert!(e.contains("ACT (7), not 3"), "{e}");
        let e = ask(remote_kind::ACT, &[50.0]).unwrap_err();
        assert!(e.contains("action 6 of 2"), "{e}");
    }
}
