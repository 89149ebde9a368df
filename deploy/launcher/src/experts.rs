//! The launcher's part in the expert's lifecycle: carrying out what
//! [`ExpertLifecycle`](crate::expert_lifecycle::ExpertLifecycle) decides (start, kill, publish,
//! answer a swap), and taking `alfd swap-expert`'s requests.

use super::*;

impl<'a, 'w> Launcher<'a, 'w> {
    /// Carries out what the expert lifecycle decided.
    pub(super) fn apply(&mut self, actions: Vec<Action>) -> Result<()> {
        for action in actions {
            debug!(?action, "expert lifecycle");
            match action {
                Action::Spawn { generation, name } => {
                    if self.spawn_remote_expert(generation, &name) {
                        continue;
                    }
                    if generation > 1 {
                        info!(generation, expert = %name, "starting a new expert generation");
                    }
                    self.spawn(Kind::Expert { generation, name })?;
                }
                Action::Kill { generation } => {
                    self.kill_remote_expert(generation);
                    for p in &mut self.procs {
                        if matches!(&p.kind, Kind::Expert { generation: g, .. } if *g == generation)
                        {
                            warn!(process = %p.name, "killing");
                            let _ = p.child.kill();
                        }
                    }
                }
                Action::Control { newest, active } => {
                    self.control.newest_expert = u32::from(newest);
                    self.control.active_expert = u32::from(active);
                    self.publish_control()?;
                }
                Action::Respond {
                    request,
                    ok,
                    message,
                    from,
                    generation,
                } => {
                    if ok {
                        info!(generation, expert = %request.expert, "expert swapped");
                    }
                    if self.answer_remote_expert(&request, ok, &message) {
                        continue;
                    }
                    self.respond(request, ok, message, from, generation)?;
                }
                Action::Recovered {
                    generation,
                    died,
                    took,
                } => warn!(
                    "expert-{generation} answers again, {} ms after expert-{died} died",
                    took.as_millis()
                ),
                Action::NoExpert {
                    generation,
                    message,
                } => self.no_expert(generation, &message),
                Action::Fail {
                    generation,
                    message,
                } => bail!(
                    "{message}; see {}",
                    self.log_of(&format!("expert-{generation}"))
                ),
            }
        }
        Ok(())
    }

    pub(super) fn log_of(&self, name: &str) -> String {
        self.plan
            .run_dir
            .join(format!("{name}.log"))
            .display()
            .to_string()
    }

    /// Takes a swap request, and lets the expert lifecycle's timeouts run.
    pub(super) fn check_swap(&mut self) -> Result<()> {
        let request_path = self.plan.run_dir.join(SWAP_REQUEST);
        if request_path.exists() {
            let text = std::fs::read_to_string(&request_path).unwrap_or_default();
            let _ = std::fs::remove_file(&request_path);
            match serde_json::from_str::<SwapRequest>(&text) {
                Err(e) => warn!("ignoring a malformed swap request: {e}"),
                Ok(request) => {
                    info!(expert = %request.expert, "expert swap requested");
                    let actions = self.experts.swap(request, Instant::now());
                    self.apply(actions)?;
                }
            }
        }
        let actions = self.experts.tick(Instant::now());
        self.apply(actions)
    }

    pub(super) fn respond(
        &self,
        request: SwapRequest,
        ok: bool,
        message: String,
        from: String,
        generation: u16,
    ) -> Result<()> {
        let r = SwapResponse {
            id: request.id,
            ok,
            message,
            from,
            to: request.expert,
            generation: u32::from(generation),
            at_episode: self.recorded,
        };
        if !ok {
            warn!(message = %r.message, "expert swap failed");
        }
        // A response a full disk refuses is lost to the asker (its `alfd swap-expert` times
        // out and says so), never the run's end: the swap itself is done or refused already.
        let written = write(
            &self.plan.run_dir,
            SWAP_RESPONSE,
            serde_json::to_string_pretty(&r)?.as_bytes(),
        );
        if let Err(e) = written {
            warn!(
                "the swap's response was not written ({}): its alfd swap-expert will time out",
                alfd_harness::describe(&e)
            );
        }
        Ok(())
    }

    /// The replacement of a lost expert cannot serve: the run goes on, the actors act on their
    /// own (their queries cost nothing while no expert is active).
    pub(super) fn no_expert(&self, generation: u16, message: &str) {
        warn!(
            "{message}; see {}. The run goes on without an expert: the actors act on their \
             own (a host may offer one with `alfd join --expert`, or `alfd swap-expert`)",
            self.log_of(&format!("expert-{generation}"))
        );
    }
}
