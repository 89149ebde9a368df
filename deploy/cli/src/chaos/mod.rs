//! `alfd chaos`: a multi-process run (`alfd run`) under faults drawn from a seed ([`injector`]):
//! processes killed with SIGKILL or paused with SIGSTOP/SIGCONT, the expert swapped, the
//! launcher itself killed (then `alfd resume` continues the run), the run directory's file system
//! filled up and freed, the link to an expert on a joined host slowed below what the actors wait. When the faults end the run goes on to its end, and the invariants of
//! [`check`] are checked; everything is written to `RUN_DIR/chaos.json` and `RUN_DIR/chaos.md`.

mod check;
mod injector;
mod relay;
mod report;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context as _;

use crate::usage::usage;
use injector::{Fault, Injector, Mix, Target};

/// `alfd chaos`.
#[derive(Debug, clap::Args)]
pub struct ChaosArgs {
    /// The experiment config; default the recommended CartPole-1000 preset.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The run directory (it must not hold a run). For disk faults, put it on a small file
    /// system (a tmpfs of a few hundred MB): the filler stops at `--fill-cap-mb`.
    #[arg(long)]
    pub out: PathBuf,
    /// Actor processes.
    #[arg(long, default_value_t = 2)]
    pub actors: usize,
    /// Override a config value (repeatable), as `alfd run --set`.
    #[arg(long)]
    pub set: Vec<String>,
    /// The seed of the faults' schedule (the run's own seed is the config's).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Seconds during which faults are injected; the run then goes on to its end without them.
    #[arg(long, default_value_t = 120)]
    pub duration: u64,
    /// Mean seconds between two faults.
    #[arg(long, default_value_t = 4.0)]
    pub every: f64,
    /// The kinds of fault, with their weights: `kill`, `pause`, `swap`, `launcher`, `disk`,
    /// `delay` (with `--join-expert`) (`KIND` or `KIND=WEIGHT`, comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "kill=4,pause=3,swap=1,launcher=1"
    )]
    pub faults: Vec<String>,
    /// The demonstrators swaps choose among; default those of the config's environment.
    #[arg(long, value_delimiter = ',')]
    pub experts: Vec<String>,
    /// Checkpoint cadence of the run (`alfd run --checkpoint-every`).
    #[arg(long, default_value_t = 2000)]
    pub checkpoint_every: u64,
    /// Fail unless the run's last 50 episodes' mean return reaches this.
    #[arg(long)]
    pub min_last_50: Option<f64>,
    /// The most MB a disk fault writes before it gives up filling the file system.
    #[arg(long, default_value_t = 512)]
    pub fill_cap_mb: u64,
    /// Seconds the run may take after the faults end before it counts as hung.
    #[arg(long, default_value_t = 900)]
    pub grace: u64,
    /// Also play with this many actors on a joined host: the run listens on a free port of
    /// 127.0.0.1 (plain TCP, `--insecure`) and an `alfd join` with these actors connects to it;
    /// kills and pauses aim at that host too, and a killed host is started again. No launcher
    /// kills then (a resumed run listens on no port).
    #[arg(long, default_value_t = 0)]
    pub join_actors: usize,
    /// Also serve the run's expert from a joined host: `alfd join --expert NAME` in
    /// `RUN_DIR/expert-host`, connected through a relay that `delay` faults slow down (every
    /// byte held 1.2 to 3 s, longer than the actors wait for an answer). A host whose expert
    /// was swapped away is started again (its expert then becomes the run's again); its
    /// `demos.jsonl` must end as the start of the run's, line for line.
    #[arg(long, value_name = "NAME")]
    pub join_expert: Option<String>,
    /// Run nothing: re-make `RUN_DIR/chaos.md` from the `chaos.json` of an earlier chaos run.
    #[arg(long)]
    pub summarize: bool,
}

/// A fault carried out, for the report.
#[derive(Debug, Clone, serde::Serialize)]
struct Event {
    at_ms: u64,
    fault: Fault,
    outcome: String,
    /// Whether the fault was carried out: not when it found no process to hit (one
    /// restarting), a swap while another was under way, a launcher kill before the first
    /// learner checkpoint, a filler that could not be written.
    carried_out: bool,
}

/// The launcher's processes and what the chaos has done to them so far.
struct Chaos<'a> {
    args: &'a ChaosArgs,
    alfd: PathBuf,
    start: Instant,
    launcher: Child,
    /// Processes stopped with SIGSTOP, and when each gets SIGCONT.
    paused: Vec<(u32, Duration)>,
    /// The filler file and when it goes.
    filler: Option<(PathBuf, Duration)>,
    swap: Option<Child>,
    events: Vec<Event>,
    run_ids: Vec<String>,
    /// iceoryx2 files of dead processes of the run's launches removed at the end, as `alfd clean`
    /// would (a process of a killed launch can die after the last launch's own cleaning).
    swept: usize,
    launches: u32,
    /// The joined host of actors, if the run has one.
    joined: Option<Joined>,
    /// The joined host of the expert, if the run has one.
    expert_host: Option<Joined>,
    /// The slow link to the expert host, and when its delay ends.
    relay: Option<(relay::Relay, Option<Duration>)>,
}

/// The `alfd join` of a chaos run's joined host, started again whenever it is gone.
struct Joined {
    connect: String,
    /// Its actors (0 for the expert's host).
    actors: usize,
    /// The expert it serves, if it is the expert's host.
    expert: Option<String>,
    child: Option<Child>,
    /// Hosts started so far (each in a directory of its own).
    starts: u32,
    /// The process ids of the hosts started: their copies of the run's services are named by
    /// them (`j<secs>-<pid>`, `k<secs>-<pid>`).
    pids: Vec<u32>,
}

/// Runs `alfd chaos`.
pub fn run(args: ChaosArgs) -> anyhow::Result<()> {
    if args.summarize {
        return report::summarize(&args.out);
    }
    let mut mix = parse_mix(&args.faults)?;
    if args.every <= 0.0 || !args.every.is_finite() {
        return Err(usage(format!(
            "--every must be a positive number of seconds, got {}",
            args.every
        )));
    }
    let alfd = std::env::current_exe().context("cannot locate the running alfd binary")?;
    let listen = (args.join_actors > 0 || args.join_expert.is_some())
        .then(free_loopback_port)
        .transpose()?;
    let launcher = spawn_run(&alfd, &args, listen)?;
    let relay = match (listen, &args.join_expert) {
        (Some(port), Some(_)) => {
            Some(relay::Relay::start(port).context("cannot start the expert host's relay")?)
        }
        _ => None,
    };
    let joined = |port: u16, actors: usize, expert: Option<String>| Joined {
        connect: format!("tcp/127.0.0.1:{port}"),
        actors,
        expert,
        child: None,
        starts: 0,
        pids: Vec::new(),
    };
    let mut chaos = Chaos {
        args: &args,
        alfd,
        start: Instant::now(),
        launcher,
        paused: Vec::new(),
        filler: None,
        swap: None,
        events: Vec::new(),
        run_ids: Vec::new(),
        swept: 0,
        launches: 1,
        joined: listen
            .filter(|_| args.join_actors > 0)
            .map(|port| joined(port, args.join_actors, None)),
        expert_host: relay
            .as_ref()
            .map(|r| joined(r.port(), 0, args.join_expert.clone())),
        relay: relay.map(|r| (r, None)),
    };
    let cfg = run_config(&args.out);
    let experts = if args.experts.is_empty() {
        experts_of(cfg.as_ref())
    } else {
        args.experts.clone()
    };
    let members = apart_members(cfg.as_ref());
    let actors = u16::try_from(args.actors).map_err(|_| usage("--actors is too large"))?;
    let gap = Duration::from_secs_f64(args.every);
    // A Gymnasium environment is served by Python adapters, which are targets too.
    let adapters = cfg.is_some_and(|c| c.env.name.is_remote());
    if adapters && mix.launcher > 0 {
        // A Gymnasium environment's state lives in its adapter: such a run cannot be resumed.
        eprintln!("chaos: a Gymnasium run cannot be resumed: no launcher kills");
        mix.launcher = 0;
    }
    if listen.is_some() && mix.launcher > 0 {
        eprintln!("chaos: a resumed run listens on no port: no launcher kills with a joined host");
        mix.launcher = 0;
    }
    let mut injector = Injector::new(args.seed, gap, actors, experts, mix)
        .with_adapters(adapters)
        .with_host(chaos.joined.is_some())
        .with_expert_host(chaos.expert_host.is_some())
        .with_members(members);
    let ended = chaos.drive(&mut injector);
    chaos.settle();
    report::report(&chaos, ended)
}

/// The places in `[[experts]]` of the experts, each of which answers from a process of its own
/// (a built-in one and a person's page from `alfd-expert --member`, an external one from a
/// Python adapter).
fn apart_members(cfg: Option<&alfd_common::config::ExperimentConfig>) -> Vec<u16> {
    let Some(cfg) = cfg else { return Vec::new() };
    (0..cfg.experts.len())
        .filter_map(|i| u16::try_from(i).ok())
        .collect()
}

/// The adapter name of `[[experts]]`' `i`-th expert in the newest expert process of the run in
/// `out` (`expert-<generation>-<i>`, from its log's name), if one started.
fn member_adapter(out: &std::path::Path, i: u16) -> Option<String> {
    let suffix = format!("-{i}.log");
    std::fs::read_dir(out)
        .ok()?
        .flatten()
        .filter_map(|e| {
            let file = e.file_name().to_string_lossy().into_owned();
            let generation = file
                .strip_prefix("adapter-expert-")?
                .strip_suffix(&suffix)?
                .parse::<u64>()
                .ok()?;
            Some((generation, format!("expert-{generation}-{i}")))
        })
        .max()
        .map(|(_, name)| name)
}

/// `kill=4,pause` → the weights (a kind without one weighs 1); unknown kinds are refused.
fn parse_mix(faults: &[String]) -> anyhow::Result<Mix> {
    let mut mix = Mix {
        kill: 0,
        pause: 0,
        swap: 0,
        launcher: 0,
        disk: 0,
        delay: 0,
    };
    for f in faults.iter().filter(|f| !f.is_empty()) {
        let (kind, weight) = f.split_once('=').unwrap_or((f, "1"));
        let weight: u32 = weight
            .parse()
            .map_err(|_| usage(format!("--faults {f}: the weight must be a whole number")))?;
        let slot = match kind {
            "kill" => &mut mix.kill,
            "pause" => &mut mix.pause,
            "swap" => &mut mix.swap,
            "launcher" => &mut mix.launcher,
            "disk" => &mut mix.disk,
            "delay" => &mut mix.delay,
            other => {
                return Err(usage(format!(
                    "--faults: unknown fault {other:?} (kill, pause, swap, launcher, disk, delay)"
                )))
            }
        };
        *slot = weight;
    }
    Ok(mix)
}

/// A port of 127.0.0.1 free at this moment.
fn free_loopback_port() -> anyhow::Result<u16> {
    let probe = std::net::TcpListener::bind((std::net::Ipv4Addr::LOCALHOST, 0))
        .context("cannot find a free port on 127.0.0.1")?;
    Ok(probe.local_addr()?.port())
}

/// `alfd run` for the chaos: quiet, with restarts enough for every fault; listening on
/// `listen` of 127.0.0.1 for a joined host.
fn spawn_run(alfd: &Path, args: &ChaosArgs, listen: Option<u16>) -> anyhow::Result<Child> {
    let mut cmd = Command::new(alfd);
    if let Some(port) = listen {
        cmd.args([
            "run",
            "--listen",
            &format!("tcp/127.0.0.1:{port}"),
            "--insecure",
        ]);
    } else {
        cmd.arg("run");
    }
    cmd.args(["--out", &args.out.to_string_lossy()])
        .args(["--actors", &args.actors.to_string()])
        .args(["--checkpoint-every", &args.checkpoint_every.to_string()])
        .args(["--max-restarts", "100000", "--quiet"]);
    if let Some(c) = &args.config {
        cmd.args(["--config", &c.to_string_lossy()]);
    }
    for s in &args.set {
        cmd.args(["--set", s]);
    }
    cmd.stdin(Stdio::null()).stdout(Stdio::null());
    cmd.spawn().context("cannot start alfd run")
}

/// The demonstrators of the run's environment (none when its config could not be read).
fn experts_of(cfg: Option<&alfd_common::config::ExperimentConfig>) -> Vec<String> {
    let Some(cfg) = cfg else {
        return Vec::new();
    };
    let env = format!("{:?}", cfg.env.name).to_lowercase();
    alfd_demonstrators::registry::list()
        .into_iter()
        .filter(|e| e.env == env)
        .map(|e| e.name)
        .collect()
}

/// The run's `config.toml` once the launcher has written it (waited for up to 30 s).
fn run_config(dir: &Path) -> Option<alfd_common::config::ExperimentConfig> {
    let deadline = Instant::now() + Duration::from_secs(30);
    let text = loop {
        if let Ok(t) = std::fs::read_to_string(dir.join("config.toml")) {
            break t;
        }
        if Instant::now() > deadline {
            return None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    alfd_common::config::ExperimentConfig::for_multi_process(&text).ok()
}

impl Chaos<'_> {
    fn now(&self) -> Duration {
        self.start.elapsed()
    }

    fn log(&mut self, fault: Fault, (outcome, carried_out): (String, bool)) {
        let at_ms = self.now().as_millis() as u64;
        tracing::info!(at_ms, ?fault, %outcome, "chaos");
        self.events.push(Event {
            at_ms,
            fault,
            outcome,
            carried_out,
        });
    }

    /// Injects faults until `--duration`, then waits for the run's end; the run's end (`Ok`) or
    /// why it did not come (`Err`).
    fn drive(&mut self, injector: &mut Injector) -> Result<(), String> {
        let faults_end = Duration::from_secs(self.args.duration);
        let give_up = faults_end + Duration::from_secs(self.args.grace);
        loop {
            self.release(false);
            self.run_id();
            self.keep_host();
            if let Some(status) = self.launcher.try_wait().map_err(|e| e.to_string())? {
                self.release(true);
                if self.finished() {
                    return Ok(());
                }
                return Err(format!(
                    "the launcher ended ({status}) before the run's end"
                ));
            }
            let now = self.now();
            if now >= give_up {
                return Err(format!(
                    "the run had not ended {} s after the faults",
                    self.args.grace
                ));
            }
            if now < faults_end {
                if let Some(f) = injector.due(now) {
                    self.apply(f)?;
                }
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Whether `summary.json` says the run is complete.
    fn finished(&self) -> bool {
        std::fs::read_to_string(self.args.out.join("summary.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .is_some_and(|s| s["interrupted"].as_bool() == Some(false))
    }

    /// SIGCONT to the paused processes whose pause is over (all with `all`), and the filler
    /// removed when its time is up.
    fn release(&mut self, all: bool) {
        let now = self.now();
        self.paused.retain(|&(pid, until)| {
            let due = all || now >= until;
            if due {
                signal("CONT", pid);
            }
            !due
        });
        if let Some((file, until)) = &self.filler {
            if all || now >= *until {
                let _ = std::fs::remove_file(file);
                self.filler = None;
            }
        }
        if let Some((relay, until)) = &mut self.relay {
            if until.is_some_and(|u| all || now >= u) {
                relay.set_delay(Duration::ZERO);
                *until = None;
            }
        }
    }

    /// Every byte on the expert host's link held for `hold`, during `lasting` from now.
    fn delay_link(&mut self, hold: Duration, lasting: Duration) -> (String, bool) {
        let now = self.now();
        match &mut self.relay {
            Some((_, Some(_))) => ("skipped: the link is slow already".to_owned(), false),
            Some((relay, until)) => {
                relay.set_delay(hold);
                *until = Some(now + lasting);
                (
                    format!(
                        "the expert host's link holds every byte {} ms",
                        hold.as_millis()
                    ),
                    true,
                )
            }
            None => ("no expert host to slow down".to_owned(), false),
        }
    }

    /// The current run id (it changes with every launch).
    fn run_id(&mut self) -> Option<String> {
        let info = alfd_launcher::read_run_info(&self.args.out).ok()?;
        if !self.run_ids.contains(&info.run_id) {
            self.run_ids.push(info.run_id.clone());
        }
        Some(info.run_id)
    }

    fn pid_of(&mut self, target: Target) -> Option<u32> {
        if target == Target::Host {
            return self.joined.as_ref()?.child.as_ref().map(Child::id);
        }
        if let Target::Member(i) = target {
            let name = member_adapter(&self.args.out, i)?;
            let args = [
                format!("--run-id={}", self.run_id()?),
                format!("--name={name}"),
            ];
            return alfd_launcher::find_process("", &[&args[0], &args[1]]);
        }
        let mut args = vec![format!("--run-id={}", self.run_id()?)];
        match target {
            Target::Actor(id) => args.push(format!("--actor-id={id}")),
            Target::Adapter(id) => args.push(format!("--name=env-{id}")),
            _ => {}
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        alfd_launcher::find_process(target.binary(), &args)
    }

    fn apply(&mut self, fault: Fault) -> Result<(), String> {
        let missed = || {
            (
                "no such process at that moment (restarting)".to_owned(),
                false,
            )
        };
        let outcome = match &fault {
            Fault::Kill(t) => match self.pid_of(*t) {
                Some(pid) => {
                    signal("KILL", pid);
                    (format!("killed pid {pid}"), true)
                }
                None => missed(),
            },
            Fault::Pause(t, d) => match self.pid_of(*t) {
                Some(pid) => {
                    signal("STOP", pid);
                    self.paused.push((pid, self.now() + *d));
                    (format!("stopped pid {pid}"), true)
                }
                None => missed(),
            },
            Fault::SwapExpert(name) => self.swap(name),
            Fault::KillLauncher => self.kill_launcher()?,
            Fault::FillDisk(d) => self.fill_disk(*d),
            Fault::DelayLink(hold, lasting) => self.delay_link(*hold, *lasting),
        };
        self.log(fault, outcome);
        Ok(())
    }

    fn swap(&mut self, name: &str) -> (String, bool) {
        if let Some(child) = &mut self.swap {
            if matches!(child.try_wait(), Ok(None)) {
                return ("skipped: a swap is under way".to_owned(), false);
            }
        }
        let spawned = silent(
            Command::new(&self.alfd)
                .args(["swap-expert", "--run", &self.args.out.to_string_lossy()])
                .args(["--expert", name, "--timeout", "10"]),
        );
        match spawned {
            Ok(child) => {
                self.swap = Some(child);
                (format!("alfd swap-expert --expert {name} started"), true)
            }
            Err(e) => (format!("cannot start alfd swap-expert: {e}"), false),
        }
    }

    /// SIGKILL to the launcher, then `alfd resume` (once a learner checkpoint exists to resume
    /// from).
    fn kill_launcher(&mut self) -> Result<(String, bool), String> {
        if !self.args.out.join("learner.ckpt").is_file() {
            let skipped = "skipped: no learner checkpoint to resume from yet";
            return Ok((skipped.to_owned(), false));
        }
        self.release(true);
        let pid = self.launcher.id();
        signal("KILL", pid);
        let _ = self.launcher.wait();
        let resumed = Command::new(&self.alfd)
            .args(["resume", &self.args.out.to_string_lossy(), "--quiet"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start alfd resume: {e}"))?;
        self.launcher = resumed;
        self.launches += 1;
        let outcome = format!(
            "killed launcher pid {pid}; alfd resume started (launch {})",
            self.launches
        );
        Ok((outcome, true))
    }

    /// Fills the run directory's file system (up to `--fill-cap-mb`) until `d` from now.
    fn fill_disk(&mut self, d: Duration) -> (String, bool) {
        if self.filler.is_some() {
            return ("skipped: the disk is full already".to_owned(), false);
        }
        let file = self.args.out.join(".chaos-filler");
        let written = fill(&file, self.args.fill_cap_mb);
        let outcome = match written {
            Ok((mb, true)) => (format!("file system full after {mb} MB"), true),
            Ok((mb, false)) => (
                format!("wrote {mb} MB without filling the file system (cap)"),
                true,
            ),
            Err(e) => (format!("cannot write the filler: {e}"), false),
        };
        self.filler = Some((file, self.now() + d));
        outcome
    }

    /// Starts the joined hosts when they are not running (at first, after a kill, and the
    /// expert's after its expert was swapped away); they connect once the run has written its
    /// `run.json`. The expert's host keeps one directory, so that what it held is compared with
    /// the run's file whenever its expert becomes the run's again.
    fn keep_host(&mut self) {
        let out = self.args.out.clone();
        if self.finished() || !out.join("run.json").is_file() {
            return;
        }
        for j in [&mut self.joined, &mut self.expert_host]
            .into_iter()
            .flatten()
        {
            keep(&self.alfd, &out, j);
        }
    }

    /// Nothing left paused, filled or swapping; the joined hosts told to go.
    fn settle(&mut self) {
        self.release(true);
        if let Some(mut child) = self.swap.take() {
            let _ = child.wait();
        }
        for j in [&mut self.joined, &mut self.expert_host]
            .into_iter()
            .flatten()
        {
            if let Some(mut child) = j.child.take() {
                signal("TERM", child.id());
                let _ = child.wait();
            }
        }
        self.clean_hosts();
        self.sweep_launches();
    }

    /// Waits (up to 30 s) for the processes of the run's launches to be gone, then removes what
    /// dead ones left, as `alfd clean` would, counting the files: "nothing left" then checks
    /// that no process stayed and nothing stayed that `alfd clean` could not remove.
    fn sweep_launches(&mut self) {
        let deadline = Instant::now() + Duration::from_secs(30);
        for id in self.run_ids.iter().filter(|id| id.starts_with('r')) {
            loop {
                match alfd_wire::clean_run(id) {
                    Ok(alfd_wire::Cleaned::Live(_)) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(200));
                    }
                    Ok(alfd_wire::Cleaned::Removed(files)) => {
                        self.swept += files.len();
                        break;
                    }
                    _ => break,
                }
            }
        }
    }

    /// Removes what the killed hosts left in iceoryx2's directories, as `alfd clean` would,
    /// once their orphaned actors have seen their host gone and exited (up to 30 s); their
    /// copies' ids join the run's, for the "nothing left" invariant.
    fn clean_hosts(&mut self) {
        let pids: Vec<u32> = [&self.joined, &self.expert_host]
            .into_iter()
            .flatten()
            .flat_map(|j| j.pids.iter().copied())
            .collect();
        let ours = |id: &str| {
            alfd_wire::is_alfd_run_id(id)
                && !id.starts_with('r')
                && pids.iter().any(|pid| id.ends_with(&format!("-{pid}")))
        };
        let copies: Vec<String> = alfd_wire::runs_with_files()
            .into_iter()
            .filter(|id| ours(id))
            .collect();
        let deadline = Instant::now() + Duration::from_secs(30);
        for id in &copies {
            while matches!(alfd_wire::clean_run(id), Ok(alfd_wire::Cleaned::Live(_)))
                && Instant::now() < deadline
            {
                std::thread::sleep(Duration::from_millis(200));
            }
        }
        self.run_ids.extend(copies);
    }
}

/// Starts the joined host `j` (`alfd join`) unless it is running; an expert's host in
/// `out/expert-host`, a host of actors in a directory per start.
fn keep(alfd: &Path, out: &Path, j: &mut Joined) {
    if let Some(child) = &mut j.child {
        if matches!(child.try_wait(), Ok(None)) {
            return;
        }
    }
    j.starts += 1;
    let mut cmd = Command::new(alfd);
    cmd.args(["join", "--connect", &j.connect, "--insecure"]);
    let dir = match &j.expert {
        Some(name) => {
            cmd.args(["--expert", name]);
            out.join("expert-host")
        }
        None => {
            cmd.args(["--actors", &j.actors.to_string()]);
            out.join(format!("joined-{}", j.starts))
        }
    };
    match silent(cmd.args(["--dir", &dir.to_string_lossy()])) {
        Ok(child) => {
            j.pids.push(child.id());
            j.child = Some(child);
        }
        Err(e) => tracing::warn!("cannot start alfd join: {e}"),
    }
}

/// Writes zeros to `file` in 1 MB pieces until the file system is full or `cap_mb` are written;
/// the MB written and whether it filled up.
fn fill(file: &Path, cap_mb: u64) -> std::io::Result<(u64, bool)> {
    use std::io::Write as _;
    let mut f = std::fs::File::create(file)?;
    let block = vec![0u8; 1 << 20];
    for mb in 0..cap_mb {
        match f.write_all(&block).and_then(|()| f.sync_data()) {
            Ok(()) => {}
            Err(e) if alfd_harness::disk_full(&e) => return Ok((mb, true)),
            Err(e) => return Err(e),
        }
    }
    Ok((cap_mb, false))
}

/// Starts `cmd` with no input and its output dropped (a helper the chaos starts beside the run).
fn silent(cmd: &mut Command) -> std::io::Result<Child> {
    cmd.stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
}

/// `kill -SIG pid`, its failure ignored (the process may have gone).
fn signal(sig: &str, pid: u32) {
    let _ = Command::new("kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .stderr(Stdio::null())
        .status();
}
