//! How a launch ends: every process told to stop and waited for, and the run's summary.

use super::*;

impl<'a, 'w> Launcher<'a, 'w> {
    /// Tells every process to stop and waits for them (the learner saves its weights).
    pub(super) fn shutdown(&mut self) -> Result<()> {
        info!(
            episodes = self.recorded,
            remote_joins = self.remote_joins,
            remote_losses = self.remote_losses,
            "stopping the run"
        );
        self.control.command = command::SHUTDOWN;
        self.publish_control()?;
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut failures = Vec::new();
        // Remote actors hear the shutdown through the hub; their hosts leave when they stopped.
        // A remote expert's last demonstrations come up before its exit: it is waited for too.
        let remote =
            |l: &Self| l.hub.as_ref().map_or(0, |h| h.remote_actors()) + l.remote_experts.serving();
        while (!self.procs.is_empty() || remote(self) > 0) && Instant::now() < deadline {
            let wake = self.waiter.wait(Duration::from_millis(50))?;
            self.drain_progress()?;
            self.check_hub()?;
            if self.last_control.elapsed() >= CONTROL_PERIOD {
                self.publish_control()?;
            }
            let mut i = 0;
            while i < self.procs.len() {
                match self.procs[i].child.try_wait()? {
                    None => i += 1,
                    Some(status) => {
                        let p = self.procs.remove(i);
                        let what = format!(
                            "{} {}; see {}",
                            proc_binary(&p.kind, &p.name),
                            describe(status),
                            self.log_of(&p.name)
                        );
                        match stopped_from_outside(status) {
                            // What it did is recorded already (rows with the launcher,
                            // demonstrations in demos.jsonl, checkpoints written whole); the
                            // learner's weights are checked below.
                            true => warn!("{what}, while the run was stopping"),
                            false if !status.success() => failures.push(what),
                            false => {}
                        }
                    }
                }
            }
            let _ = wake;
        }
        for p in &self.procs {
            failures.push(format!(
                "{} did not stop within 30 s and was killed",
                p.name
            ));
        }
        if remote(self) > 0 {
            warn!("remote actors or experts did not leave within 30 s; the run ends without them");
        }
        if let Some(hub) = self.hub.take() {
            self.hub_counts = (hub.demos_refused(), hub.answers_late());
            if let Err(e) = hub.stop() {
                warn!("the hub: {e}");
            }
        }
        self.stop_all();
        self.drain_progress()?;
        // Rows a full disk held back wait as long as the run's last files do.
        self.csv
            .flush_by(Instant::now() + alfd_harness::DISK_FULL_PATIENCE)?;
        if !failures.is_empty() {
            bail!("{}", failures.join("; "));
        }
        ensure!(
            self.plan.run_dir.join("weights.safetensors").is_file(),
            "the learner stopped without saving weights.safetensors; see {}",
            self.log_of("learner")
        );
        Ok(())
    }

    /// Kills whatever child is still running (used on errors) and reaps it.
    pub(super) fn stop_all(&mut self) {
        for p in &mut self.procs {
            if matches!(p.child.try_wait(), Ok(None)) {
                warn!(process = %p.name, "killing");
                let _ = p.child.kill();
            }
            let _ = p.child.wait();
        }
        self.procs.clear();
        let _ = wire::cleanup_dead_nodes(&self.plan.run_id);
    }

    pub(super) fn summary(&self, interrupted: bool) -> RunSummary {
        let wall = self.started.elapsed().as_secs_f64();
        let running = self.running_since.elapsed().as_secs_f64().max(1e-9);
        let demos = std::fs::read_to_string(self.plan.run_dir.join("demos.jsonl"))
            .map(|t| t.lines().count())
            .unwrap_or(0);
        RunSummary {
            episodes: self.all_returns.len(),
            mean_return_last_50: mean_return_last_50(&self.all_returns),
            demos_used: self.demos_used,
            wall_clock_s: wall,
            greedy_value_at_start: None,
            optimal_value_at_start: None,
            env_steps: Some(self.seen.learner_env_steps),
            updates: Some(self.seen.learner_updates),
            env_steps_per_s: Some(self.seen.learner_env_steps as f64 / running),
            updates_per_s: Some(self.seen.learner_updates as f64 / running),
            runtime: Some(RuntimeSummary {
                run_id: self.plan.run_id.clone(),
                demos,
                actor_restarts: self.restarts.total() - self.restarts.of(&Supervised::Learner)
                    + self.remote_restarts,
                expert_swaps: self.experts.swaps(),
                expert_restarts: self.experts.restarts(),
                learner_restarts: self.restarts.of(&Supervised::Learner),
                interrupted,
                demos_refused: self.hub_counts.0,
                answers_late: self.answers_late(),
                demos_experts_wrote: self.demos_experts_wrote,
                episodes_lost: self.arrivals.lost(),
            }),
        }
    }
}

/// Whether a process was ended by a signal from outside (SIGKILL, SIGTERM: an operator, the OOM
/// killer), not by a fault of its own (an exit code, a panic's abort, a segmentation fault).
fn stopped_from_outside(status: ExitStatus) -> bool {
    use std::os::unix::process::ExitStatusExt as _;
    matches!(status.signal(), Some(9 | 15))
}

#[cfg(test)]
mod tests {
    use std::os::unix::process::ExitStatusExt as _;

    use super::*;

    #[test]
    fn only_a_kill_or_a_termination_from_outside_is_not_the_process_s_own_failure() {
        let signal = |s: i32| ExitStatus::from_raw(s);
        let code = |c: i32| ExitStatus::from_raw(c << 8);
        assert!(stopped_from_outside(signal(9)) && stopped_from_outside(signal(15)));
        // An abort (a panic's, say), a segmentation fault, an exit code: its own.
        for status in [signal(6), signal(11), code(1), code(101), code(0)] {
            assert!(!stopped_from_outside(status), "{status:?}");
        }
    }
}
