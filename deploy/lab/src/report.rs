//! How a command says it is done: the human summary at the end of `alfd local`, `alfd run`,
//! `alfd resume` and `alfd sweep`, the machine-readable line, and each run's learning curve
//! (`curve.rs`: `RUN_DIR/curve.svg`, and `curve.png` when a font is found).
//!
//! Where things go: stdout carries the machine-readable line (a run's `RunSummary` as JSON)
//! when `--json` is given or stdout is not a terminal, so scripts and pipes read what they always
//! read; the human summary goes to stderr unless `--quiet` or `--json`, styled (bold) only when
//! stderr is a terminal and `NO_COLOR` is unset. Drawing the curve never fails a run: a failure
//! is a warning.

mod curve;
mod experts;

use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::path::Path;

use crate::error::Context as _;
use alfd_common::config::{EnvName, ExperimentConfig};
use alfd_common::record::{parse_episodes_csv, EpisodeRecord, RunSummary};
use alfd_demonstrators::registry::{self, ExpertEntry};

/// What a command prints at its end (`--json`, `--quiet`).
#[derive(Debug, Clone, Copy)]
pub struct Output {
    /// `--json`: only the machine-readable line (no progress, no summary).
    pub json: bool,
    /// `--quiet`: no progress and no summary; the machine-readable line as without it.
    pub quiet: bool,
}

impl Output {
    /// Whether stdout gets the machine-readable line: with `--json`, or when stdout is not a
    /// terminal (a pipe or a file, as scripts and tests read it).
    pub fn machine_line(self) -> bool {
        self.json || !std::io::stdout().is_terminal()
    }

    /// Whether stderr gets the human summary.
    pub fn human(self) -> bool {
        !self.json && !self.quiet
    }

    /// Whether a progress bar is shown (on a terminal).
    pub fn progress(self) -> bool {
        !self.json && !self.quiet
    }
}

/// Bold text, or plain text when the stream is not a terminal.
#[derive(Debug, Clone, Copy)]
pub struct Style {
    pub ansi: bool,
}

impl Style {
    /// Styled when stderr is a terminal and `NO_COLOR` is unset or empty.
    pub fn stderr() -> Self {
        let no_color = std::env::var_os("NO_COLOR").is_some_and(|v| !v.is_empty());
        Self {
            ansi: std::io::stderr().is_terminal() && !no_color,
        }
    }

    fn bold(self, s: &str) -> String {
        if self.ansi {
            format!("\x1b[1m{s}\x1b[0m")
        } else {
            s.to_owned()
        }
    }
}

/// Ends a finished run of `alfd local`, `alfd run` or `alfd resume` in `dir`: writes the learning
/// curve (a failure is a warning), then prints the machine-readable line and the summary as
/// `output` says.
pub fn finish_run(
    cfg: &ExperimentConfig,
    dir: &Path,
    summary: &RunSummary,
    output: Output,
) -> crate::Result<()> {
    let records = match read_records(dir) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("warning: {}; no learning curve", alfd_harness::describe(&e));
            Vec::new()
        }
    };
    if !records.is_empty() {
        if let Err(e) = curve::write(dir, cfg, &expert_reference(cfg), &records) {
            eprintln!(
                "warning: the learning curve was not drawn: {}",
                alfd_harness::describe(&e)
            );
        }
    }
    if let Err(e) = experts::write(dir) {
        eprintln!(
            "warning: the experts' qualities were not drawn: {}",
            alfd_harness::describe(&e)
        );
    }
    if output.machine_line() {
        println!("{}", serde_json::to_string(summary)?);
    }
    if output.human() {
        let report = RunReport {
            dir,
            cfg,
            summary,
            records: &records,
            files: files_in(dir),
            q_values: crate::q_values::summary_text(dir, cfg),
        };
        eprint!("{}", report.text(Style::stderr()));
    }
    Ok(())
}

/// The rows of `dir/episodes.csv`.
fn read_records(dir: &Path) -> crate::Result<Vec<EpisodeRecord>> {
    let path = dir.join("episodes.csv");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    parse_episodes_csv(&text).with_context(|| format!("in {}", path.display()))
}

/// The files a run directory may hold, in the order the summary lists them, with what each holds.
const RUN_FILES: [(&str, &str); 16] = [
    (
        "config.toml",
        "the experiment config as run, every default written out",
    ),
    (
        "runtime.toml",
        "the runtime settings every process read (credit window, timeouts)",
    ),
    (
        "run.json",
        "the run's id, actors and launches (for `alfd resume`)",
    ),
    (
        "episodes.csv",
        "one row per episode: return, length, demonstrations, shaped steps, steps, evaluation",
    ),
    (
        "demos.jsonl",
        "one line per demonstration: state, action, step, the expert that gave it",
    ),
    (
        "experts.csv",
        "several experts: each one's answers and quality interval after each of its answers",
    ),
    (
        "experts.svg",
        "several experts: each one's estimated quality against the step",
    ),
    ("experts.png", "the same picture as PNG"),
    (
        "tb/",
        "TensorBoard event files, written as the run goes (`tensorboard --logdir DIR`)",
    ),
    (
        "weights.safetensors",
        "the learned network (PyTorch nn.Linear layout)",
    ),
    (
        "policy.json",
        "the learned greedy policy, one action per state (CliffWalk's tiles, DeepSea's cells)",
    ),
    ("summary.json", "these numbers, as JSON"),
    (
        "learner.ckpt",
        "the learner's last checkpoint (`alfd resume` restarts it from there)",
    ),
    (
        "checkpoint.bin",
        "the run's last checkpoint (`alfd resume` continues from there)",
    ),
    (
        "curve.svg",
        "the learning curve: return, evaluation, expert, shaping window, demonstrations",
    ),
    ("curve.png", "the same picture as PNG"),
];

/// The files of [`RUN_FILES`] that `dir` holds, then its logs.
fn files_in(dir: &Path) -> Vec<String> {
    let mut files: Vec<String> = RUN_FILES
        .iter()
        .filter(|(name, _)| dir.join(name).is_file())
        .map(|(name, _)| (*name).to_owned())
        .collect();
    let mut logs: Vec<String> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".log"))
                .collect()
        })
        .unwrap_or_default();
    logs.sort();
    files.extend(logs);
    files
}

/// What a file of a run directory holds, in a few words.
fn describe(file: &str) -> String {
    if let Some((_, what)) = RUN_FILES.iter().find(|(name, _)| *name == file) {
        return (*what).to_owned();
    }
    match file.strip_suffix(".log") {
        Some("learner") => "the learner process's log".to_owned(),
        Some(name) => match name.split_once('-') {
            Some(("actor", n)) => format!("actor {n}'s log"),
            Some(("expert", n)) => format!("the log of the expert's generation {n}"),
            _ => "a log".to_owned(),
        },
        None => String::new(),
    }
}

/// The demonstrator a config names and how its measured quality compares with the run's returns.
#[derive(Debug, Clone)]
pub(crate) struct ExpertReference {
    pub name: String,
    pub entry: Option<ExpertEntry>,
    /// Why the expert's figure is not on the scale of the run's returns (none: it is).
    pub not_comparable: Vec<String>,
    /// What else to know about the figure.
    pub notes: Vec<String>,
}

impl ExpertReference {
    /// The measured mean return, if there is one on the run's scale (for the plot's line).
    pub fn comparable_mean(&self) -> Option<f64> {
        let mean = self.entry.as_ref()?.mean?;
        self.not_comparable.is_empty().then_some(mean)
    }
}

pub(crate) fn expert_reference(cfg: &ExperimentConfig) -> ExpertReference {
    let name = cfg.expert.name.clone();
    let entry = registry::list().into_iter().find(|e| e.name == name);
    let mut not_comparable = Vec::new();
    let mut notes = Vec::new();
    let default_limit = match cfg.env.name {
        // Every DeepSea episode is N steps long, and its experts' figures hold for any N.
        EnvName::Deepsea => cfg.env.deepsea_size(),
        other => other.default_max_episode_steps(),
    };
    let limit = cfg.env.max_episode_steps();
    if !cfg.experts.is_empty() {
        not_comparable.push("the run's `[[experts]]` answer it, not this expert".to_owned());
    }
    if limit != default_limit {
        not_comparable.push(format!(
            "measured with episodes of at most {default_limit} steps; this run's stop at {limit}"
        ));
    }
    if cfg.env.name == EnvName::Cliffwalk {
        if cfg.env.map.is_some() || cfg.env.p_success != 0.9 {
            not_comparable
                .push("measured on the default map with p_success 0.9, not this run's".to_owned());
        }
        notes.push(
            "an undiscounted return per episode, as the run's returns; V(S) is a discounted \
             value, another measure"
                .to_owned(),
        );
    }
    if !cfg.query.asks() || cfg.budget() == 0 {
        notes.push("for reference only: this run asks for no demonstrations".to_owned());
    }
    ExpertReference {
        name,
        entry,
        not_comparable,
        notes,
    }
}

/// A finished run, as its summary reports it.
pub(crate) struct RunReport<'a> {
    pub dir: &'a Path,
    pub cfg: &'a ExperimentConfig,
    pub summary: &'a RunSummary,
    pub records: &'a [EpisodeRecord],
    /// The files in `dir` to list.
    pub files: Vec<String>,
    /// The learned network's Q-values against the true values' range
    /// ([`crate::q_values::summary_text`]), for neural runs.
    pub q_values: Option<String>,
}

/// The width of the summary's labels.
const LABEL: usize = 16;

impl RunReport<'_> {
    /// The summary text, several lines each ending in a newline.
    pub fn text(&self, style: Style) -> String {
        let (cfg, s) = (self.cfg, self.summary);
        let mut out = String::new();
        let interrupted = s.runtime.as_ref().is_some_and(|r| r.interrupted);
        let what = format!("{}, {}, seed {}", cfg.env.name, agent_name(cfg), cfg.seed);
        let head = if interrupted {
            format!("Run interrupted ({what}): what it did before it was stopped")
        } else {
            format!("Run finished ({what})")
        };
        let _ = writeln!(out, "{}", style.bold(&head));
        let mut line = |label: &str, value: String| {
            let _ = writeln!(out, "  {label:<LABEL$} {value}");
        };
        line("run directory", style.bold(&self.dir.display().to_string()));
        let steps = self
            .records
            .iter()
            .map(|r| r.total_steps)
            .max()
            .unwrap_or(0);
        line(
            "episodes",
            format!(
                "{} ({} environment steps)",
                thousands(s.episodes as u64),
                thousands(steps)
            ),
        );
        line("mean return", self.return_text());
        if let Some(q) = &self.q_values {
            line("Q-values", q.clone());
        }
        if let (Some(greedy), Some(optimal)) = (s.greedy_value_at_start, s.optimal_value_at_start) {
            line(
                "greedy policy",
                format!(
                    "V(S) = {greedy:.3}, optimal V*(S) = {optimal:.3} (discounted values, γ = {})",
                    cfg.agent.gamma
                ),
            );
        }
        if cfg.experts.is_empty() {
            line("expert", expert_text(&expert_reference(cfg)));
        } else {
            line("experts", experts_text(cfg));
        }
        line("demonstrations", self.demos_text());
        if let Some(text) = self.shaping_text() {
            line("shaping", text);
        }
        if let Some(r) = &s.runtime {
            let rate = |v: Option<f64>| thousands(v.unwrap_or(0.0).round() as u64);
            let mut text = format!(
                "run id {}; {} environment steps/s, {} updates/s",
                r.run_id,
                rate(s.env_steps_per_s),
                rate(s.updates_per_s)
            );
            let events = [
                (r.actor_restarts, "actor restarts"),
                (r.expert_restarts, "expert restarts"),
                (r.learner_restarts, "learner restarts"),
                (r.expert_swaps, "expert swaps"),
            ];
            for (n, what) in events.into_iter().filter(|(n, _)| *n > 0) {
                let _ = write!(text, "; {n} {what}");
            }
            line("processes", text);
        }
        line("wall-clock", duration(s.wall_clock_s));
        let _ = writeln!(out, "  files");
        let width = self.files.iter().map(String::len).max().unwrap_or(0);
        for f in &self.files {
            let _ = writeln!(out, "    {f:<width$}  {}", describe(f));
        }
        out
    }

    fn return_text(&self) -> String {
        let s = self.summary;
        if s.episodes == 0 {
            return "no episode recorded".to_owned();
        }
        let n = s.episodes.min(50);
        let mut text = format!(
            "{:.1} over the last {}",
            s.mean_return_last_50,
            if n == 1 {
                "episode".to_owned()
            } else {
                format!("{n} episodes")
            }
        );
        let last_eval = self
            .records
            .iter()
            .filter(|r| r.eval_return.is_finite())
            .max_by_key(|r| r.episode);
        if let Some(r) = last_eval {
            let _ = write!(
                text,
                "; greedy evaluation {:.1} (mean of {} episodes after training episode {})",
                r.eval_return,
                self.cfg.evaluation.episodes,
                r.episode + 1
            );
        }
        text
    }

    fn demos_text(&self) -> String {
        let s = self.summary;
        let mut text = format!(
            "{} used of the budget of {}",
            s.demos_used,
            self.cfg.budget()
        );
        if let Some(r) = s
            .runtime
            .as_ref()
            .filter(|r| r.demos > s.demos_used as usize)
        {
            let _ = write!(
                text,
                " ({} in demos.jsonl: some were asked in episodes still running at the end)",
                r.demos
            );
        }
        if let Some(r) = &s.runtime {
            if r.answers_late > 0 {
                let _ = write!(
                    text,
                    "; {} answered after their actor stopped waiting (kept, the actor acted alone: \
                     a longer --query-timeout-ms may help)",
                    r.answers_late
                );
            }
            if r.demos_refused > 0 {
                let _ = write!(
                    text,
                    "; {} written by a remote expert and NOT taken into demos.jsonl",
                    r.demos_refused
                );
            }
        }
        text
    }

    /// The shaping window: episodes whose reward was shaped (`None`: no shaping configured).
    fn shaping_text(&self) -> Option<String> {
        if !self.cfg.shaping_enabled() {
            return None;
        }
        let shaped: Vec<u32> = self
            .records
            .iter()
            .filter(|r| r.shaped_steps > 0)
            .map(|r| r.episode)
            .collect();
        Some(match (shaped.iter().min(), shaped.iter().max()) {
            (Some(first), Some(last)) => format!(
                "reward shaped in {} episodes, from episode {} to {} (numbered as in episodes.csv)",
                shaped.len(),
                first,
                last
            ),
            _ => format!(
                "never on (it starts at {} demonstrations)",
                self.cfg.shaping.min_demos
            ),
        })
    }
}

/// The agent's kind as a config names it (`bdqn`, `qlearning`, ...).
fn agent_name(cfg: &ExperimentConfig) -> String {
    config_name(&cfg.agent.kind)
}

/// A config value's name as the config writes it (`bdqn`, `round-robin`, ...).
fn config_name<T: serde::Serialize + std::fmt::Debug>(value: &T) -> String {
    serde_json::to_value(value)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_else(|| format!("{value:?}"))
}

/// The expert's measured quality, with what it is and whether it compares with the run's returns
/// (continuation lines indented under the label's value).
fn expert_text(e: &ExpertReference) -> String {
    let indent = format!("\n  {:<LABEL$} ", "");
    let name = &e.name;
    let mut text = match &e.entry {
        None => format!("{name}: not in the manifest, so no measured return"),
        Some(entry) => match entry.mean {
            None => format!(
                "{name} ({}): no measured return in the manifest (`alfd expert eval {name}` \
                 measures one)",
                entry.kind
            ),
            Some(mean) => format!(
                "{mean:.1}, the mean return of {name}{indent}({})",
                entry
                    .evaluation
                    .as_deref()
                    .unwrap_or("how it was measured is not recorded")
            ),
        },
    };
    let measured = e.entry.as_ref().is_some_and(|x| x.mean.is_some());
    if measured {
        for why in &e.not_comparable {
            let _ = write!(text, "{indent}not the scale of this run's returns: {why}");
        }
        for note in &e.notes {
            let _ = write!(text, "{indent}{note}");
        }
    }
    text
}

/// Several experts: each one's name and cost, and the route that chose among them.
fn experts_text(cfg: &ExperimentConfig) -> String {
    let each: Vec<String> = cfg
        .experts
        .iter()
        .map(|e| format!("{} (cost {})", e.name, e.cost))
        .collect();
    format!(
        "{}; route {}; each one's estimated quality in experts.csv",
        each.join(", "),
        config_name(&cfg.expert.route)
    )
}

/// `1234567` as `1,234,567`.
fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// Seconds as `37 ms`, `4.2 s`, `3 min 12 s` or `1 h 05 min`.
fn duration(s: f64) -> String {
    if s < 1.0 {
        return format!("{:.0} ms", s * 1000.0);
    }
    if s < 60.0 {
        return format!("{s:.1} s");
    }
    let whole = s.round() as u64;
    if whole < 3600 {
        format!("{} min {} s", whole / 60, whole % 60)
    } else {
        format!("{} h {:02} min", whole / 3600, whole % 3600 / 60)
    }
}

/// A finished sweep, as its summary reports it.
#[derive(Debug, serde::Serialize)]
pub(crate) struct SweepReport {
    pub sweep: String,
    pub out: String,
    pub methods: Vec<String>,
    pub seeds: u64,
    pub runs: u64,
    pub run_now: usize,
    pub resumed: u64,
    pub wall_clock_s: f64,
    /// The files written in `out` (the plot's: one or two), beside `summary.md` and the curves.
    pub files: Vec<String>,
    /// `alfd sweep` prints this line on stdout when it is not a terminal and `--json` is not
    /// given.
    #[serde(skip)]
    pub line: String,
}

impl SweepReport {
    /// Prints the sweep's end as `output` says: the JSON line (`--json`), else the one line on
    /// a stdout that is not a terminal; the summary on stderr.
    pub fn print(&self, output: Output) -> crate::Result<()> {
        if output.json {
            println!("{}", serde_json::to_string(self)?);
        } else if output.machine_line() {
            println!("{}", self.line);
        }
        if output.human() {
            eprint!("{}", self.text(Style::stderr()));
        }
        Ok(())
    }

    pub fn text(&self, style: Style) -> String {
        let mut out = String::new();
        let unit = if self.files.iter().any(|f| f == "returns.csv") {
            "runs"
        } else {
            "seeds"
        };
        let head = format!(
            "Sweep {} finished: {} methods × {} {unit} = {} runs ({} run now, {} complete \
             already)",
            self.sweep,
            self.methods.len(),
            self.seeds,
            self.runs,
            self.run_now,
            self.resumed
        );
        let _ = writeln!(out, "{}", style.bold(&head));
        let mut line = |label: &str, value: String| {
            let _ = writeln!(out, "  {label:<LABEL$} {value}");
        };
        line("output directory", style.bold(&self.out));
        line("methods", self.methods.join(", "));
        line(
            "seeds",
            format!("{} (0..{})", self.seeds, self.seeds.saturating_sub(1)),
        );
        line("wall-clock", duration(self.wall_clock_s));
        let _ = writeln!(out, "  files");
        let mut files: Vec<(String, String)> = self
            .files
            .iter()
            .map(|f| {
                let training = unit == "seeds";
                let what = match f.rsplit_once('.').map(|(_, ext)| ext) {
                    _ if f == "summary.md" && training => {
                        "per method, with 95% intervals over seeds: final return, area under \
                         the curve, crossings, demonstrations, wall-clock"
                    }
                    _ if f == "summary.md" => {
                        "per method: median, mean, std, min and max of the return"
                    }
                    _ if f == "curves.csv" => {
                        "per method and x: mean, std, median and 95% interval of the return"
                    }
                    _ if f == "returns.csv" => "each run's return and length",
                    Some("svg") if training => {
                        "the plot: mean return per method with its 95% interval"
                    }
                    Some("svg") => "the plot: each run's return per method, sorted",
                    Some("png") => "the same plot as PNG",
                    _ => "",
                };
                (f.clone(), what.to_owned())
            })
            .collect();
        if unit == "seeds" {
            files.push((
                "runs/METHOD/SEED/".to_owned(),
                "each run's files, as `alfd local` writes them (no curve per run)".to_owned(),
            ));
        }
        let width = files.iter().map(|(f, _)| f.len()).max().unwrap_or(0);
        for (f, what) in files {
            let _ = writeln!(out, "    {f:<width$}  {what}");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(extra: &str) -> ExperimentConfig {
        cfg_with_env("", extra)
    }

    fn cfg_with_env(env: &str, extra: &str) -> ExperimentConfig {
        ExperimentConfig::from_toml(&format!(
            "seed = 3\nepisodes = 4\n[env]\nname = \"cartpole\"\n{env}[agent]\nkind = \"bdqn\"\n\
             [query]\nmode = \"active\"\n[budget]\ntotal = 20\n{extra}"
        ))
        .unwrap()
    }

    fn records() -> Vec<EpisodeRecord> {
        (0..4u32)
            .map(|i| EpisodeRecord {
                episode: i,
                ret: f64::from(10 * (i + 1)),
                length: 10 * (i + 1),
                demos_used: 3 * i,
                shaped_steps: if (1..3).contains(&i) { 5 } else { 0 },
                total_steps: u64::from(5 * (i + 1) * (i + 2)),
                eval_return: if i == 1 { 250.5 } else { f64::NAN },
                ..EpisodeRecord::default()
            })
            .collect()
    }

    #[test]
    fn the_summary_names_the_directory_the_numbers_the_expert_and_the_files() {
        let cfg = cfg("[expert]\nname = \"cartpole-1000\"\nmodel = \"krr\"\n");
        let records = records();
        let summary = RunSummary::of(&records, 75.4);
        let report = RunReport {
            dir: Path::new("/tmp/runs/r1"),
            cfg: &cfg,
            summary: &summary,
            records: &records,
            files: vec![
                "config.toml".into(),
                "curve.svg".into(),
                "actor-1.log".into(),
            ],
            q_values: Some("-3.0 to 201.0 on 3 greedy episodes".into()),
        };
        let text = report.text(Style { ansi: false });
        for needle in [
            "Run finished (cartpole, bdqn, seed 3)",
            "run directory    /tmp/runs/r1",
            "episodes         4 (100 environment steps)",
            "mean return      25.0 over the last 4 episodes; greedy evaluation 250.5 (mean of \
             10 episodes after training episode 2)",
            "1000.0, the mean return of cartpole-1000",
            "(greedy policy, 100 CartPole-1000 episodes from seed 2000003)",
            "demonstrations   9 used of the budget of 20",
            "reward shaped in 2 episodes, from episode 1 to 2",
            "wall-clock       1 min 15 s",
            "Q-values         -3.0 to 201.0 on 3 greedy episodes",
            "    config.toml  the experiment config as run",
            "    curve.svg    the learning curve",
            "    actor-1.log  actor 1's log",
        ] {
            assert!(text.contains(needle), "{needle:?} missing from\n{text}");
        }
        assert!(
            !text.contains('\x1b') && !text.contains("not the scale"),
            "{text}"
        );
        assert!(report.text(Style { ansi: true }).contains("\x1b[1m"));
    }

    #[test]
    fn an_expert_figure_of_another_kind_says_so() {
        // Another step limit than the expert was measured with.
        let short = cfg_with_env(
            "max_episode_steps = 500\n",
            "[expert]\nname = \"cartpole-200\"\n",
        );
        let e = expert_reference(&short);
        assert_eq!(e.comparable_mean(), None);
        let text = expert_text(&e);
        assert!(
            text.contains("201.5") && text.contains("at most 1000 steps"),
            "{text}"
        );
        // CliffWalk: undiscounted returns, unlike V(S); no queries: reference only.
        let cliff = ExperimentConfig::from_toml(
            "seed = 0\nepisodes = 1\n[env]\nname = \"cliffwalk\"\n[agent]\nkind = \"qlearning\"\n\
             [expert]\nname = \"cliffwalk-optimal\"\n",
        )
        .unwrap();
        let e = expert_reference(&cliff);
        assert!(e.comparable_mean().is_some());
        let text = expert_text(&e);
        assert!(
            text.contains("undiscounted") && text.contains("for reference only"),
            "{text}"
        );
        // No measured figure at all.
        let perfect = cfg("[expert]\nname = \"cartpole-perfect\"\n");
        assert!(expert_text(&expert_reference(&perfect)).contains("no measured return"));
        // DeepSea: every episode is N steps, as its experts' figures assume.
        let sea = ExperimentConfig::from_toml(
            "seed = 0\nepisodes = 1\n[env]\nname = \"deepsea\"\nsize = 12\n[agent]\n\
             kind = \"bootstrapped-q\"\n",
        )
        .unwrap();
        assert_eq!(expert_reference(&sea).comparable_mean(), Some(0.99));
        // Several experts: they are named with their costs, and the unasked expert drawn nowhere.
        let mut several = sea.clone();
        several.experts = serde_json::from_str(
            r#"[{"name": "deepsea-good", "cost": 10}, {"name": "deepsea-poor", "cost": 1.5}]"#,
        )
        .unwrap();
        several.expert.route = alfd_common::panel::Route::RoundRobin;
        assert_eq!(
            experts_text(&several),
            "deepsea-good (cost 10), deepsea-poor (cost 1.5); route round-robin; each one's \
             estimated quality in experts.csv"
        );
        assert_eq!(expert_reference(&several).comparable_mean(), None);
    }

    #[test]
    fn numbers_read_easily() {
        assert_eq!(thousands(0), "0");
        assert_eq!(thousands(999), "999");
        assert_eq!(thousands(1234567), "1,234,567");
        assert_eq!(duration(0.0374), "37 ms");
        assert_eq!(duration(4.25), "4.2 s");
        assert_eq!(duration(192.0), "3 min 12 s");
        assert_eq!(duration(3900.0), "1 h 05 min");
        assert_eq!(
            describe("expert-2.log"),
            "the log of the expert's generation 2"
        );
        assert_eq!(describe("learner.log"), "the learner process's log");
    }

    #[test]
    fn a_sweep_summary_says_where_everything_is() {
        let r = SweepReport {
            sweep: "fig4".into(),
            out: "/tmp/sweep".into(),
            methods: vec!["a".into(), "b".into()],
            seeds: 5,
            runs: 10,
            run_now: 8,
            resumed: 2,
            wall_clock_s: 12.0,
            files: vec![
                "summary.md".into(),
                "curves.csv".into(),
                "fig4.svg".into(),
                "fig4.png".into(),
            ],
            line: String::new(),
        };
        let text = r.text(Style { ansi: false });
        for needle in [
            "Sweep fig4 finished: 2 methods × 5 seeds = 10 runs (8 run now, 2 complete already)",
            "output directory /tmp/sweep",
            "methods          a, b",
            "wall-clock       12.0 s",
            "summary.md",
            "curves.csv",
            "fig4.svg",
            "fig4.png",
            "runs/METHOD/SEED/",
        ] {
            assert!(text.contains(needle), "{needle:?} missing from\n{text}");
        }
        let json: serde_json::Value = serde_json::to_value(&r).unwrap();
        assert_eq!(json["run_now"], 8);
        assert!(json.get("line").is_none());
    }
}
