//! `alfd join`: actors on this host for a run on another (`alfd run --listen`). It asks the run
//! for actor ids, starts a mirror of the run's services here (see `alfd_bridge`), and the actor
//! processes, unchanged, against the mirror; it ends when they have stopped: at the run's end,
//! on Ctrl-C, or when the link to the learner's host is lost.

use std::os::unix::process::CommandExt as _;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use alfd_wire::{Process, Role, Wire, MAX_ACTORS, SCHEMA_VERSION};
use anyhow::{bail, Context as _};
use tracing::{info, warn};

use crate::launcher;
use crate::usage::usage;

/// The learner's host silent for this long (no control message through the link; it sends one
/// every `alfd_wire::CONTROL_PERIOD`): the link is lost, and the actors here are stopped.
const LINK_SILENCE: Duration = Duration::from_secs(5);

#[derive(Debug, clap::Args)]
pub struct JoinArgs {
    /// The learner's host: the endpoint its `alfd run --listen` listens on.
    #[arg(long, value_name = "tcp/ADDR:PORT")]
    pub connect: String,
    /// Actor processes to start on this host (1..=16; the run gives them free actor ids).
    #[arg(long, default_value_t = 1)]
    pub actors: usize,
    /// Where this host keeps its actors' logs and checkpoints; default
    /// `runs/join-<run id>-<pid>`.
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// Seconds to wait for the run to answer.
    #[arg(long, default_value_t = 20)]
    pub wait_s: u64,
}

pub fn run(args: JoinArgs) -> anyhow::Result<()> {
    let endpoint = alfd_bridge::Endpoint::parse(&args.connect)
        .map_err(|e| usage(format!("--connect: {e}")))?;
    if !(1..=MAX_ACTORS).contains(&args.actors) {
        return Err(usage(format!(
            "--actors must be in 1..={MAX_ACTORS}, got {}",
            args.actors
        )));
    }
    let bin_dir = launcher::bin_dir()?;
    let actor_bin = bin_dir.join("alfd-actor");
    anyhow::ensure!(
        actor_bin.is_file(),
        "alfd-actor not found in {} (build every binary: `cargo build --release`)",
        bin_dir.display()
    );
    let host = hostname();
    let pid = std::process::id();
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let request = alfd_bridge::JoinRequest {
        join_id: format!("{host}-{pid}-{nanos}"),
        host: host.clone(),
        actors: args.actors as u16,
    };
    let schema = alfd_harness::schema_version_from_env().map_err(usage)?;
    let remote = alfd_bridge::join(
        &endpoint,
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
    })?;
    let joined = remote.joined.clone();
    let dir = args
        .dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("join-{}-{pid}", joined.run_id)));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    crate::cmd_local::write(&dir, "config.toml", joined.config_toml.as_bytes())?;
    crate::cmd_local::write(
        &dir,
        alfd_harness::RUNTIME_FILE,
        joined.runtime_toml.as_bytes(),
    )?;
    // This host's copy of the run: a run id (so an iceoryx2 prefix) of its own.
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let mirror_id = format!("j{secs}-{pid}");
    // How to find this host's part of the run afterwards (`alfd clean` takes the mirror's id).
    let record = serde_json::json!({
        "run_id": joined.run_id,
        "mirror_run_id": mirror_id,
        "connect": endpoint.to_string(),
        "actors": joined.actors,
    });
    crate::cmd_local::write(
        &dir,
        "join.json",
        serde_json::to_string_pretty(&record)?.as_bytes(),
    )?;
    let result = {
        let mirror = alfd_bridge::Mirror::start(remote, &mirror_id)
            .context("cannot start this host's mirror of the run")?;
        let wire = Wire::connect(&mirror_id, Process::new(Role::Tool, 0), SCHEMA_VERSION)
            .context("cannot create this host's iceoryx2 node")?;
        let r = host_actors(&mirror, &wire, &joined, &dir, &actor_bin, &mirror_id);
        drop(wire);
        if let Err(e) = mirror.stop() {
            warn!("the mirror: {e}");
        }
        r
    };
    if let Err(e) = alfd_wire::close_run(&mirror_id) {
        warn!("cannot close this host's iceoryx2 resources: {e}");
    }
    result
}

/// Starts the actors once the run's control message came through, and waits for them.
fn host_actors(
    mirror: &alfd_bridge::Mirror,
    wire: &Wire,
    joined: &alfd_bridge::Joined,
    dir: &std::path::Path,
    actor_bin: &std::path::Path,
    mirror_id: &str,
) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(20);
    while mirror.silence().is_none() {
        anyhow::ensure!(
            Instant::now() < deadline && !mirror.ended(),
            "no word from the run {} through the link within 20 s",
            joined.run_id
        );
        if wire.termination_requested() {
            bail!("interrupted before the actors started");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut actors: Vec<(u16, Child)> = Vec::new();
    for &(id, incarnation) in &joined.actors {
        let log_path = dir.join(format!("actor-{id}.log"));
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .with_context(|| format!("cannot open {}", log_path.display()))?;
        let child = Command::new(actor_bin)
            .args([
                format!("--actor-id={id}"),
                format!("--incarnation={incarnation}"),
                format!("--run-id={mirror_id}"),
                format!("--run-dir={}", dir.display()),
            ])
            .stdin(Stdio::null())
            .stdout(log.try_clone()?)
            .stderr(log)
            .process_group(0)
            .spawn()
            .context("cannot start alfd-actor")?;
        info!(actor = id, incarnation, pid = child.id(), "started");
        actors.push((id, child));
    }
    eprintln!(
        "joined run {}: actors {:?} here (logs in {})",
        joined.run_id,
        joined.actors.iter().map(|a| a.0).collect::<Vec<_>>(),
        dir.display()
    );
    let mut failed = Vec::new();
    let mut stopping: Option<&str> = None;
    while !actors.is_empty() {
        std::thread::sleep(Duration::from_millis(50));
        let mut i = 0;
        while i < actors.len() {
            match actors[i].1.try_wait()? {
                None => i += 1,
                Some(status) => {
                    let (id, _) = actors.remove(i);
                    if status.success() {
                        info!(actor = id, "stopped");
                    } else {
                        warn!(actor = id, "exited: {status}");
                        failed.push(format!(
                            "actor-{id} ({status}; see {})",
                            dir.join(format!("actor-{id}.log")).display()
                        ));
                    }
                }
            }
        }
        let why = if wire.termination_requested() {
            Some("interrupted")
        } else if mirror.ended() || mirror.silence().is_some_and(|s| s >= LINK_SILENCE) {
            Some("lost the link to the learner's host")
        } else {
            None
        };
        if let (Some(why), None) = (why, stopping) {
            warn!("{why}: stopping the actors here");
            stopping = Some(why);
            for (_, c) in &actors {
                let _ = Command::new("kill")
                    .args(["-TERM", &c.id().to_string()])
                    .status();
            }
        }
    }
    if let Some(why) = stopping {
        bail!("{why}");
    }
    anyhow::ensure!(failed.is_empty(), "{}", failed.join("; "));
    Ok(())
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
