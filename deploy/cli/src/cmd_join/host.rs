//! `alfd join`'s work: joining the run's hub, the mirror and expert host here, and the
//! processes on this host, restarted as the run's restart rule says.

use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use alfd_common::restarts::{Ended, GiveUp};
use alfd_wire::{Process, Role, Wire, MAX_ACTORS, SCHEMA_VERSION};
use anyhow::{bail, Context as _};
use tracing::{info, warn};

use super::JoinArgs;
use crate::usage::usage;
use alfd_launcher as launcher;

/// The learner's host silent for this long (no control message through the link; it sends one
/// every `alfd_wire::CONTROL_PERIOD`): the link is lost, and the actors here are stopped.
const LINK_SILENCE: Duration = Duration::from_secs(5);

/// How long the run may take to give a crashed actor a new incarnation.
const RESTART_WAIT: Duration = Duration::from_secs(5);

/// `alfd join`: joins the run, serves it from this host until its processes here stop.
pub fn run(args: JoinArgs) -> anyhow::Result<()> {
    let (endpoint, actors) = checked(&args)?;
    let bin_dir = launcher::bin_dir()?;
    for bin in ["alfd-actor", "alfd-expert"] {
        anyhow::ensure!(
            bin_dir.join(bin).is_file(),
            "{bin} not found in {} (build every binary: `cargo build --release`)",
            bin_dir.display()
        );
    }
    let pid = std::process::id();
    let remote = join_hub(&args, &endpoint, actors)?;
    let joined = remote.joined.clone();
    let dir = args
        .dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("join-{}-{pid}", joined.run_id)));
    // This host's copy of the run: a run id (so an iceoryx2 prefix) of its own; the expert's
    // copy apart from the actors' (their queries go through the learner's host, where its
    // demonstrations are written first).
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let ids = CopyIds {
        mirror: format!("j{secs}-{pid}"),
        expert_host: format!("k{secs}-{pid}"),
    };
    write_join_files(
        &args,
        &endpoint,
        &joined,
        &dir,
        &ids.mirror,
        &ids.expert_host,
    )?;
    let result = serve(&args, remote, actors, &ids, (&dir, &bin_dir));
    for id in [&ids.mirror, &ids.expert_host] {
        if let Err(e) = alfd_wire::close_run(id) {
            warn!("cannot close this host's iceoryx2 resources: {e}");
        }
    }
    result
}

/// The run ids of this host's copies of the run: the actors' mirror's and the expert's.
struct CopyIds {
    mirror: String,
    expert_host: String,
}

/// Asks the learner's host to take this one in; a refusal of what was asked is bad input.
fn join_hub(
    args: &JoinArgs,
    endpoint: &alfd_bridge::Endpoint,
    actors: usize,
) -> anyhow::Result<alfd_bridge::Remote> {
    let request = join_request(args, actors);
    let schema = alfd_harness::schema_version_from_env().map_err(usage)?;
    alfd_bridge::join(
        endpoint,
        request,
        Duration::from_secs(args.wait_s.max(1)),
        schema,
    )
    .map_err(|e| {
        if e.is_bad_input() {
            usage(e.to_string())
        } else {
            anyhow::Error::new(e)
        }
    })
}

/// Runs this host's part of the run until it ends: the expert's copy (with `--expert`), the
/// actors' mirror (with actors), and the host's processes; both copies stopped after.
fn serve(
    args: &JoinArgs,
    remote: alfd_bridge::Remote,
    actors: usize,
    ids: &CopyIds,
    (dir, bin_dir): (&Path, &Path),
) -> anyhow::Result<()> {
    let joined = remote.joined.clone();
    let expert_host = match &args.expert {
        Some(_) => Some(
            alfd_bridge::ExpertHost::start(&remote, &ids.expert_host, dir, actors == 0)
                .context("cannot start this host's copy of the run for its expert")?,
        ),
        None => None,
    };
    // The actors' mirror (it announces this host); without actors, the connection stays.
    let (mirror, _remote) = if actors > 0 {
        let m = alfd_bridge::Mirror::start(remote, &ids.mirror)
            .context("cannot start this host's mirror of the run")?;
        (Some(m), None)
    } else {
        (None, Some(remote))
    };
    let own = if actors > 0 {
        &ids.mirror
    } else {
        &ids.expert_host
    };
    let wire = Wire::connect(own, Process::new(Role::Tool, 0), SCHEMA_VERSION)
        .context("cannot create this host's iceoryx2 node")?;
    let host = Host {
        mirror: mirror.as_ref(),
        expert_host: expert_host.as_ref(),
        wire: &wire,
        joined: &joined,
        dir,
        bin_dir,
        mirror_id: &ids.mirror,
        expert_host_id: &ids.expert_host,
    };
    let r = host.run();
    drop(wire);
    if let Some(e) = expert_host {
        if let Err(e) = e.stop() {
            warn!("the expert host: {e}");
        }
    }
    if let Some(m) = mirror {
        if let Err(e) = m.stop() {
            warn!("the mirror: {e}");
        }
    }
    r
}

/// The endpoint and the number of actors `args` ask for, checked.
fn checked(args: &JoinArgs) -> anyhow::Result<(alfd_bridge::Endpoint, usize)> {
    let endpoint = args.link.endpoint("--connect", &args.connect)?;
    let actors = args
        .actors
        .unwrap_or(if args.expert.is_some() { 0 } else { 1 });
    if actors > MAX_ACTORS || (actors == 0 && args.expert.is_none()) {
        return Err(usage(format!(
            "--actors must be in 1..={MAX_ACTORS} (0 only with --expert), got {actors}"
        )));
    }
    if args.expert.as_deref().is_some_and(|e| e.trim().is_empty()) {
        return Err(usage("--expert: an empty name"));
    }
    Ok((endpoint, actors))
}

/// This host's request to join: an id unique to this process, its actors and its expert.
fn join_request(args: &JoinArgs, actors: usize) -> alfd_bridge::JoinRequest {
    let host = hostname();
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    alfd_bridge::JoinRequest {
        join_id: format!("{host}-{}-{nanos}", std::process::id()),
        host,
        actors: actors as u16,
        expert: args.expert.clone(),
    }
}

/// The run's `config.toml` and `runtime.toml` in `dir`, and `join.json`: how to find this
/// host's part of the run afterwards (`alfd clean` takes the mirror's id).
fn write_join_files(
    args: &JoinArgs,
    endpoint: &alfd_bridge::Endpoint,
    joined: &alfd_bridge::Joined,
    dir: &std::path::Path,
    mirror_id: &str,
    expert_host_id: &str,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    alfd_lab::output::write(dir, "config.toml", joined.config_toml.as_bytes())?;
    alfd_lab::output::write(
        dir,
        alfd_harness::RUNTIME_FILE,
        joined.runtime_toml.as_bytes(),
    )?;
    let record = serde_json::json!({
        "run_id": joined.run_id,
        "mirror_run_id": mirror_id,
        "expert_host_run_id": args.expert.as_ref().map(|_| expert_host_id),
        "expert": args.expert,
        "connect": endpoint.to_string(),
        "actors": joined.actors,
    });
    alfd_lab::output::write(
        dir,
        "join.json",
        serde_json::to_string_pretty(&record)?.as_bytes(),
    )?;
    Ok(())
}

/// This host's part of a run: its bridges and where its processes go.
struct Host<'a> {
    mirror: Option<&'a alfd_bridge::Mirror>,
    expert_host: Option<&'a alfd_bridge::ExpertHost>,
    wire: &'a Wire,
    joined: &'a alfd_bridge::Joined,
    dir: &'a std::path::Path,
    bin_dir: &'a std::path::Path,
    mirror_id: &'a str,
    expert_host_id: &'a str,
}

impl Host<'_> {
    /// How long since the learner's host was last heard of through either bridge.
    fn silence(&self) -> Option<Duration> {
        [
            self.mirror.and_then(|m| m.silence()),
            self.expert_host.and_then(|e| e.silence()),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    fn ended(&self) -> bool {
        self.mirror.is_some_and(|m| m.ended()) || self.expert_host.is_some_and(|e| e.ended())
    }

    fn start(&self, bin: &str, name: &str, args: &[String]) -> anyhow::Result<Child> {
        let log_path = self.dir.join(format!("{name}.log"));
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .with_context(|| format!("cannot open {}", log_path.display()))?;
        Command::new(self.bin_dir.join(bin))
            .args(args)
            .arg(format!("--run-dir={}", self.dir.display()))
            .stdin(Stdio::null())
            .stdout(log.try_clone()?)
            .stderr(log)
            .process_group(0)
            .spawn()
            .with_context(|| format!("cannot start {bin}"))
    }

    /// Starts actor `id` as incarnation `incarnation` against the mirror.
    fn start_actor(&self, id: u16, incarnation: u64) -> anyhow::Result<Child> {
        let child = self.start(
            "alfd-actor",
            &format!("actor-{id}"),
            &[
                format!("--actor-id={id}"),
                format!("--incarnation={incarnation}"),
                format!("--run-id={}", self.mirror_id),
            ],
        )?;
        info!(actor = id, incarnation, pid = child.id(), "started");
        Ok(child)
    }

    /// Actor `id` crashed: the run gives it a new incarnation, and it starts again (none while
    /// this host is stopping).
    fn restart_actor(&self, id: u16, stopping: bool) -> anyhow::Result<Option<Child>> {
        let Some(mirror) = self.mirror.filter(|_| !stopping) else {
            return Ok(None);
        };
        let incarnation = mirror
            .restart(id, RESTART_WAIT)
            .context("the run gives no new incarnation")?;
        warn!(actor = id, incarnation, "restarting the actor");
        self.start_actor(id, incarnation).map(Some)
    }

    /// Starts the actors once the run's control message came through, the expert when the run
    /// says so, and waits for them.
    fn run(&self) -> anyhow::Result<()> {
        self.wait_for_the_link()?;
        let mut here = Processes::default();
        for &(id, incarnation) in &self.joined.actors {
            here.actors.push((id, self.start_actor(id, incarnation)?));
        }
        if !here.actors.is_empty() {
            eprintln!(
                "joined run {}: actors {:?} here (logs in {})",
                self.joined.run_id,
                self.joined.actors.iter().map(|a| a.0).collect::<Vec<_>>(),
                self.dir.display()
            );
        }
        loop {
            std::thread::sleep(Duration::from_millis(50));
            self.reap_actors(&mut here)?;
            self.reap_expert(&mut here)?;
            for order in self.expert_host.map(|e| e.orders()).unwrap_or_default() {
                self.carry_out(order, &mut here)?;
            }
            if let (Some(why), None) = (self.reason_to_stop(), &here.stopping) {
                warn!("{why}: stopping the processes here");
                here.stopping = Some(why);
            }
            if here.stopping.is_some() && !here.signalled {
                here.signal_all();
            }
            // Done when nothing runs here and nothing more will: the actors stopped, and this
            // host's expert served and stopped (or none was asked for).
            let expert_done = self.expert_host.is_none() || (here.served && here.expert.is_none());
            if here.actors.is_empty()
                && here.expert.is_none()
                && (expert_done || here.stopping.is_some())
            {
                break;
            }
        }
        if let Some(why) = here.stopping {
            if let Some(refusal) = why.strip_prefix("refused: ") {
                return Err(usage(format!(
                    "the run does not take this host's expert: {refusal}"
                )));
            }
            bail!("{why}");
        }
        anyhow::ensure!(here.failed.is_empty(), "{}", here.failed.join("; "));
        Ok(())
    }

    /// Waits (at most 20 s) until the learner's host is heard of through a bridge.
    fn wait_for_the_link(&self) -> anyhow::Result<()> {
        let deadline = Instant::now() + Duration::from_secs(20);
        while self.silence().is_none() {
            anyhow::ensure!(
                Instant::now() < deadline && !self.ended(),
                "no word from the run {} through the link within 20 s",
                self.joined.run_id
            );
            if self.wire.termination_requested() {
                bail!("interrupted before the actors started");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        Ok(())
    }

    /// The actors that ended: a crashed one is restarted (within the run's restarts).
    fn reap_actors(&self, here: &mut Processes) -> anyhow::Result<()> {
        let mut i = 0;
        while i < here.actors.len() {
            let Some(status) = here.actors[i].1.try_wait()? else {
                i += 1;
                continue;
            };
            let (id, _) = here.actors.remove(i);
            let how = alfd_launcher::describe_status(status);
            // The run's restart rule (`alfd_common::restarts`); the run counts the restarts.
            match Ended::of(status.code(), status.success()) {
                Ended::Finished => {
                    info!(actor = id, "stopped");
                    continue;
                }
                Ended::Refused => {
                    here.failed.push(format!(
                        "actor-{id} {how}, and {}; see {}",
                        GiveUp::Refused,
                        self.dir.join(format!("actor-{id}.log")).display()
                    ));
                    continue;
                }
                Ended::Crashed => warn!(actor = id, "{how}"),
            }
            match self.restart_actor(id, here.stopping.is_some()) {
                Ok(Some(child)) => {
                    here.actors.insert(i, (id, child));
                    i += 1;
                }
                Ok(None) => {}
                Err(e) => here.failed.push(format!(
                    "actor-{id} {how}, not restarted: {e:#}; see {}",
                    self.dir.join(format!("actor-{id}.log")).display()
                )),
            }
        }
        Ok(())
    }

    /// This host's expert, if it ended: the run hears it through the expert host.
    fn reap_expert(&self, here: &mut Processes) -> anyhow::Result<()> {
        let Some((generation, child)) = &mut here.expert else {
            return Ok(());
        };
        if let Some(status) = child.try_wait()? {
            let generation = *generation;
            let how = alfd_launcher::describe_status(status);
            info!(generation, "this host's expert {how}");
            if let Some(e) = self.expert_host {
                e.exited(generation, how, status.code());
            }
            here.expert = None;
        }
        Ok(())
    }

    /// The run's order about this host's expert.
    fn carry_out(
        &self,
        order: alfd_bridge::ExpertHostOrder,
        here: &mut Processes,
    ) -> anyhow::Result<()> {
        match order {
            alfd_bridge::ExpertHostOrder::Start { .. } if here.stopping.is_some() => {}
            alfd_bridge::ExpertHostOrder::Start { generation, name } => {
                if let Some((_, mut old)) = here.expert.take() {
                    let _ = old.kill();
                    let _ = old.wait();
                }
                let child = self.start(
                    "alfd-expert",
                    &format!("expert-{generation}"),
                    &[
                        format!("--generation={generation}"),
                        format!("--expert={name}"),
                        format!("--run-id={}", self.expert_host_id),
                    ],
                )?;
                info!(generation, expert = %name, pid = child.id(), "expert started");
                eprintln!(
                    "serving as the expert of run {} ({name}, generation {generation}; log in {})",
                    self.joined.run_id,
                    self.dir.join(format!("expert-{generation}.log")).display()
                );
                here.expert = Some((generation, child));
                here.served = true;
            }
            alfd_bridge::ExpertHostOrder::Kill { generation } => {
                if let Some((g, child)) = &mut here.expert {
                    if *g == generation {
                        warn!(generation, "the run kills this host's expert");
                        let _ = child.kill();
                    }
                }
            }
            alfd_bridge::ExpertHostOrder::Refused(why) => {
                here.stopping
                    .get_or_insert_with(|| format!("refused: {why}"));
            }
        }
        Ok(())
    }

    /// Why the processes here must stop now, if they must.
    fn reason_to_stop(&self) -> Option<String> {
        if self.wire.termination_requested() {
            Some("interrupted".to_owned())
        } else if self.ended() || self.silence().is_some_and(|s| s >= LINK_SILENCE) {
            Some("lost the link to the learner's host".to_owned())
        } else {
            None
        }
    }
}

/// The processes of this host's part of the run, and how it stands.
#[derive(Default)]
struct Processes {
    actors: Vec<(u16, Child)>,
    /// This host's expert: the generation running here.
    expert: Option<(u16, Child)>,
    /// Whether an expert ever ran here.
    served: bool,
    failed: Vec<String>,
    stopping: Option<String>,
    signalled: bool,
}

impl Processes {
    /// SIGTERM to every process here, once.
    fn signal_all(&mut self) {
        self.signalled = true;
        let children = self
            .actors
            .iter()
            .map(|a| &a.1)
            .chain(self.expert.as_ref().map(|e| &e.1));
        for c in children {
            let _ = Command::new("kill")
                .args(["-TERM", &c.id().to_string()])
                .status();
        }
    }
}

/// This host's name, as a zenoh key chunk (letters, digits, `-`).
fn hostname() -> String {
    let raw = std::fs::read_to_string("/etc/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "host".to_owned());
    let clean: String = raw
        .trim()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    if clean.is_empty() {
        "host".to_owned()
    } else {
        clean
    }
}
