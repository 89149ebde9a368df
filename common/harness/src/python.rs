//! The Python side of alfd: finding (and on first use installing) the adapter's virtual
//! environment, probing a Gymnasium environment's spaces, and starting adapters
//! (`deploy/python/alfd_adapter.py`) as child processes that stop with their [`Adapter`].

use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use alfd_common::agent::Demonstrator;
use alfd_common::config::EnvConfig;
use alfd_common::env::{Env, EnvError, EnvState, Step};
use alfd_wire::{Process, RemoteClient, RemoteDemonstrator, RemoteEnv};
use serde::{Deserialize, Serialize};

use crate::bad_input::{BadInput, HarnessError, Result, What as _};

/// Where the adapter and its requirements are: `$ALFD_PYTHON_DIR`, else `deploy/python` of the
/// sources this binary was built from.
pub fn python_dir() -> PathBuf {
    match std::env::var_os("ALFD_PYTHON_DIR") {
        Some(d) => PathBuf::from(d),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/python"),
    }
}

/// The Python interpreter of the adapter: `$ALFD_PYTHON`, else the project's virtual
/// environment, made on first use by `deploy/python/setup-venv.sh`. No Python is bad input
/// (the message says what to install).
pub fn interpreter() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os("ALFD_PYTHON") {
        return Ok(PathBuf::from(p));
    }
    let script = python_dir().join("setup-venv.sh");
    let out = Command::new("bash")
        .arg(&script)
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .what(|| format!("cannot run {}", script.display()))?;
    if !out.status.success() {
        return Err(BadInput(format!(
            "{} could not set up Python for the Gymnasium adapter ({}); see the message above",
            script.display(),
            out.status
        ))
        .into());
    }
    let path = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    Ok(PathBuf::from(path))
}

/// A Gymnasium environment's spaces and limit, as the adapter reported them at start-up
/// (recorded in `runtime.toml` so that the learner and the expert know the sizes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvSpec {
    pub obs_dim: usize,
    pub num_actions: usize,
    /// The step limit (the config's, or the registration's).
    pub max_episode_steps: usize,
}

fn env_args(env: &EnvConfig) -> Result<Vec<String>> {
    let id = env
        .id
        .clone()
        .ok_or_else(|| BadInput("env.id is needed for gymnasium".into()))?;
    let kwargs = serde_json::to_string(&env.kwargs.clone().unwrap_or_default())
        .what(|| "cannot write env.kwargs as JSON".to_owned())?;
    Ok(vec![
        "env".into(),
        format!("--id={id}"),
        format!("--kwargs={kwargs}"),
        format!("--max-episode-steps={}", env.max_episode_steps.unwrap_or(0)),
    ])
}

/// Makes the config's Gymnasium environment once in Python and returns its spec; a wrong space,
/// an unknown id or bad kwargs is [`BadInput`] with the adapter's message.
pub fn probe_env(env: &EnvConfig) -> Result<EnvSpec> {
    let python = interpreter()?;
    let adapter = python_dir().join("alfd_adapter.py");
    let out = Command::new(&python)
        .arg(&adapter)
        .args(env_args(env)?)
        .arg("--check")
        .stdin(Stdio::null())
        .output()
        .what(|| format!("cannot run {} {}", python.display(), adapter.display()))?;
    let stderr = String::from_utf8_lossy(&out.stderr).trim().to_owned();
    match out.status.code() {
        Some(0) => serde_json::from_slice(&out.stdout)
            .what(|| format!("the adapter's spec is not JSON: {stderr}")),
        Some(2) => Err(BadInput(stderr).into()),
        _ => Err(HarnessError::Child(format!(
            "the Gymnasium adapter failed ({}): {stderr}",
            out.status
        ))),
    }
}

/// An adapter process; stopped (SIGTERM, then SIGKILL after 5 s) when dropped.
#[derive(Debug)]
pub struct Adapter {
    child: Mutex<Child>,
    name: String,
    log: PathBuf,
}

impl Adapter {
    fn spawn(args: Vec<String>, run_id: &str, name: &str, schema: u32, log: &Path) -> Result<Self> {
        let python = interpreter()?;
        let adapter = python_dir().join("alfd_adapter.py");
        let mut command = Command::new(&python);
        command
            .arg(&adapter)
            .args(args)
            .arg(format!("--run-id={run_id}"))
            .arg(format!("--name={name}"))
            .arg(format!("--schema={schema}"));
        let what = || format!("cannot start {} {}", python.display(), adapter.display());
        Self::start(command, name, log, what)
    }

    /// Starts `command` with its output appended to `log`, telling it the pid to watch.
    fn start(
        mut command: Command,
        name: &str,
        log: &Path,
        what: impl FnOnce() -> String,
    ) -> Result<Self> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(log)
            .what(|| format!("cannot open {}", log.display()))?;
        let child = command
            // Killed while the adapter starts up, this process would leave it an orphan that
            // cannot tell its parent has gone: it is told which pid to watch.
            .arg(format!("--parent={}", std::process::id()))
            .stdin(Stdio::null())
            .stdout(file.try_clone()?)
            .stderr(file)
            .spawn()
            .what(what)?;
        tracing::info!(adapter = name, pid = child.id(), "adapter started");
        Ok(Self {
            child: Mutex::new(child),
            name: name.to_owned(),
            log: log.to_owned(),
        })
    }

    /// Starts `program` (this workspace's `alfd-expert`) serving the built-in expert at place
    /// `member` of `[[experts]]` as `remote/<name>`; `expert` is the joined name the expert
    /// process was started under, so that both read the same list. Its process name is
    /// `alfd-expert-member`, so that nothing looking for the expert process finds it.
    pub fn member(
        program: &Path,
        process: &crate::ProcessArgs,
        (expert, generation, member): (&str, u16, usize),
        name: &str,
        log: &Path,
    ) -> Result<Self> {
        use std::os::unix::process::CommandExt as _;
        let mut command = Command::new(program);
        command
            .arg0("alfd-expert-member")
            .arg(format!("--run-dir={}", process.run_dir.display()))
            .arg(format!("--run-id={}", process.run_id))
            .arg(format!("--expert={expert}"))
            .arg(format!("--generation={generation}"))
            .arg(format!("--member={member}"))
            .arg(format!("--name={name}"));
        Self::start(command, name, log, || {
            format!("cannot start {}", program.display())
        })
    }

    /// Starts the adapter serving the config's Gymnasium environment as `remote/<name>`.
    pub fn env(env: &EnvConfig, run_id: &str, name: &str, schema: u32, log: &Path) -> Result<Self> {
        Self::spawn(env_args(env)?, run_id, name, schema, log)
    }

    /// Starts the adapter answering with the external demonstrator `policy`
    /// (`python:MODULE:FUNCTION` or `sb3:ALGO:PATH`) as `remote/<name>`.
    pub fn expert(policy: &str, run_id: &str, name: &str, schema: u32, log: &Path) -> Result<Self> {
        let args = vec!["expert".to_owned(), format!("--policy={policy}")];
        Self::spawn(args, run_id, name, schema, log)
    }

    /// Why the adapter will not answer: it exited (with its status and the last lines of its
    /// log), or `None` while it runs.
    pub fn gone(&self) -> Option<String> {
        let mut child = self.child.lock().ok()?;
        match child.try_wait() {
            Ok(Some(status)) => Some(format!(
                "the adapter `{}` exited ({status}); its log {} ends with: {}",
                self.name,
                self.log.display(),
                tail(&self.log)
            )),
            _ => None,
        }
    }

    /// Connects a client to this adapter, waiting while it starts (at most 60 s).
    pub fn connect(&self, run_id: &str, me: Process, schema: u32) -> Result<RemoteClient> {
        let client = RemoteClient::connect(
            run_id,
            &self.name,
            me,
            schema,
            Duration::from_secs(60),
            &mut || self.gone(),
        );
        match client {
            Ok(c) => Ok(c),
            // A refused start-up (a wrong space, a policy that does not load) is bad input.
            Err(e) if self.exit_code() == Some(2) => Err(BadInput(e.to_string()).into()),
            Err(e) => Err(e.into()),
        }
    }

    /// How the adapter exited, once it has: its exit code, or `None` when a signal ended it.
    pub fn exited(&self) -> Option<Option<i32>> {
        let mut child = self.child.lock().ok()?;
        child.try_wait().ok().flatten().map(|s| s.code())
    }

    fn exit_code(&self) -> Option<i32> {
        self.exited().flatten()
    }
}

/// The last line of a log file, for a message.
fn tail(path: &Path) -> String {
    let mut text = String::new();
    if let Ok(mut f) = std::fs::File::open(path) {
        let _ = f.read_to_string(&mut text);
    }
    text.lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("(empty)")
        .to_owned()
}

impl Drop for Adapter {
    fn drop(&mut self) {
        let Ok(child) = self.child.get_mut() else {
            return;
        };
        if matches!(child.try_wait(), Ok(None)) {
            let _ = Command::new("kill")
                .arg("-TERM")
                .arg(child.id().to_string())
                .status();
            let deadline = Instant::now() + Duration::from_secs(5);
            while matches!(child.try_wait(), Ok(None)) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = child.kill();
        }
        let _ = child.wait();
    }
}

/// An external demonstrator (`python:`, `sb3:`) answering from its adapter process:
/// [`Demonstrator::try_act`] asks it, waiting at most its timeout, and fails at once once the
/// adapter has exited; `act` gives action 0 when that fails.
#[derive(Debug)]
pub struct AdapterDemonstrator {
    remote: RemoteDemonstrator,
    adapter: Adapter,
    timeout: Duration,
}

impl AdapterDemonstrator {
    /// Starts the adapter of `policy` as `remote/<name>` (logging to `log`) and connects to it.
    pub fn start(
        policy: &str,
        (run_id, name): (&str, &str),
        me: Process,
        schema: u32,
        actions: usize,
        log: &Path,
        timeout: Duration,
    ) -> Result<Self> {
        let adapter = Adapter::expert(policy, run_id, name, schema, log)?;
        Self::connect(adapter, run_id, me, schema, actions, timeout)
    }

    /// Connects to `adapter`, started already, as `me`.
    pub fn connect(
        adapter: Adapter,
        run_id: &str,
        me: Process,
        schema: u32,
        actions: usize,
        timeout: Duration,
    ) -> Result<Self> {
        let remote = RemoteDemonstrator::new(adapter.connect(run_id, me, schema)?, actions);
        Ok(Self {
            remote,
            adapter,
            timeout,
        })
    }
}

impl AdapterDemonstrator {
    /// How its adapter exited, once it has (see [`Adapter::exited`]).
    pub fn exited(&self) -> Option<Option<i32>> {
        self.adapter.exited()
    }
}

impl Demonstrator<[f32]> for AdapterDemonstrator {
    fn act(&mut self, s: &[f32]) -> usize {
        self.try_act(s).unwrap_or_else(|e| {
            tracing::error!("{e}");
            0
        })
    }

    fn try_act(&mut self, s: &[f32]) -> std::result::Result<usize, String> {
        if let Some(why) = self.adapter.gone() {
            return Err(why);
        }
        self.remote
            .act(s, self.timeout)
            .map_err(|e| match self.adapter.gone() {
                Some(why) => format!("{e}: {why}"),
                None => e.to_string(),
            })
    }
}

/// A [`RemoteEnv`] that keeps its adapter alive (several environments may share one).
#[derive(Debug)]
pub struct AdapterEnv {
    // Closed before the adapter stops.
    pub env: RemoteEnv,
    _adapter: Arc<Adapter>,
}

impl AdapterEnv {
    /// Opens a session of `adapter`'s environment as `me`.
    pub fn open(
        adapter: Arc<Adapter>,
        env: &EnvConfig,
        run_id: &str,
        me: Process,
        schema: u32,
    ) -> Result<Self> {
        // A wait for an answer ends as soon as the adapter exits, naming why.
        let alive = adapter.clone();
        let client = adapter
            .connect(run_id, me, schema)?
            .with_liveness(Box::new(move || alive.gone()));
        let label = format!("gymnasium:{}", env.id.as_deref().unwrap_or("?"));
        let remote = RemoteEnv::open(client, env.max_episode_steps.unwrap_or(0), &label)?;
        Ok(Self {
            env: remote,
            _adapter: adapter,
        })
    }
}

impl Env for AdapterEnv {
    type Observation = Vec<f32>;

    fn num_actions(&self) -> usize {
        self.env.num_actions()
    }
    fn observation_dim(&self) -> usize {
        self.env.observation_dim()
    }
    fn max_episode_steps(&self) -> usize {
        self.env.max_episode_steps()
    }
    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        self.env.reset(seed)
    }
    fn step(&mut self, action: usize) -> Result<Step<Vec<f32>>, EnvError> {
        self.env.step(action)
    }
    fn snapshot(&self) -> EnvState {
        self.env.snapshot()
    }
    fn restore(&mut self, state: &EnvState) -> Result<(), EnvError> {
        self.env.restore(state)
    }
}
