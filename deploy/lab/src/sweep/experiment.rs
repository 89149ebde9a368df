//! Experiment files (`deploy/experiments/*.toml`): which methods a sweep runs, over how many seeds,
//! and how its results are summarised. Parsed and validated in full before anything runs.
//!
//! ```toml
//! title = "Figure 4: CartPole"
//! seeds = 50                 # runs use seeds 0..seeds
//! episodes = 300             # optional: overrides every method's config
//! log_y = true               # plot the return on a log scale (as the paper does)
//! thresholds = [100, 200, 500]
//! last = 50                  # the summary's "mean over the last episodes"
//! smooth = 1                 # the plot's moving average, in episodes or step-grid points
//!                            # (tables are never smoothed)
//! y_range = [5, 1500]        # optional: the plot's y range
//! legend = "upper-left"      # or upper-right, lower-left, lower-right
//! x = "episodes"             # or "steps": the x axis of the plot, the curves and the crossings
//!
//! [[method]]
//! name = "bdqn-krr"                           # the run directory name: letters, digits, - _ .
//! label = "BDQN+KRR"                          # optional: the legend entry
//! config = "../configs/cartpole-bdqn-krr.toml" # relative to this file's directory
//! set = ["budget.total=50"]                   # optional `--set` overrides
//! ```
//!
//! An experiment of `kind = "demo-model-policy"` instead evaluates demonstration models as
//! policies (`alfd demo-model-policy`); its methods name `expert`, `demos` (default 100) and `model`
//! (default `krr`), and optionally a training `config` (with `set`) whose queries give the
//! demonstrations instead of the expert's own trajectory.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::error::Context as _;
use alfd_common::config::ExperimentConfig;
use alfd_common::demo_model::DemoModelKind;
use serde::Deserialize;

use crate::error::usage;
use crate::policy::{queries_config, DemoSource};
use crate::Trainer;

/// What an experiment does with its methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExperimentKind {
    /// Train every method over the seeds and compare their learning curves.
    #[default]
    Training,
    /// Fit a demonstration model on an expert's demonstrations and play it as a policy, once per
    /// seed (`alfd demo-model-policy`).
    DemoModelPolicy,
}

/// Where a plot's legend goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LegendPosition {
    #[default]
    UpperLeft,
    UpperRight,
    LowerLeft,
    LowerRight,
}

/// The x axis of a training experiment's curves, plot and crossings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum XAxis {
    /// Training episodes (0-based).
    #[default]
    Episodes,
    /// Environment steps (`total_steps` of `episodes.csv`), on a grid common to the seeds.
    Steps,
}

/// The experiment file as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ExperimentFile {
    /// The plot's caption and the summary's heading.
    title: String,
    #[serde(default)]
    kind: ExperimentKind,
    /// Number of seeds; runs use seeds `0..seeds`.
    seeds: u64,
    /// Training episodes of every run (overrides the configs').
    #[serde(default)]
    episodes: Option<u32>,
    /// Plot the return on a log scale.
    #[serde(default)]
    log_y: bool,
    /// The summary reports the first episode at which the mean return reaches each of these.
    #[serde(default = "default_thresholds")]
    thresholds: Vec<f64>,
    /// The summary reports, per method, the demonstrations used when greedy evaluation first
    /// reaches this return.
    #[serde(default)]
    eval_threshold: Option<f64>,
    /// The method every other one is compared with, seed by seed (paired bootstrap intervals
    /// of the differences in `summary.md`).
    #[serde(default)]
    baseline: Option<String>,
    /// The summary also reads the methods as query rules × budgets (each method's `query.rule`
    /// and `budget.total`): tables and plots against B.
    #[serde(default)]
    by_budget: bool,
    /// The training-return curves leave out the episodes in which the expert acted (the
    /// learner's own play only).
    #[serde(default)]
    learner_episodes_only: bool,
    /// The sweep also writes the learning curves of greedy evaluation (`eval_return`):
    /// `eval-curves.csv`, `NAME-eval.svg` and their table in the summary.
    #[serde(default)]
    eval_curves: bool,
    /// The summary reports the mean return over this many final episodes.
    #[serde(default = "default_last")]
    last: u32,
    /// The plotted curves are smoothed by a centred moving average of this many episodes (the
    /// tables never are).
    #[serde(default = "default_smooth")]
    smooth: usize,
    /// The plot's y range (default: fitted to the curves).
    #[serde(default)]
    y_range: Option<[f64; 2]>,
    /// Where the plot's legend goes.
    #[serde(default)]
    legend: LegendPosition,
    /// Training: the x axis of the curves, the plot and the crossings (default: episodes).
    #[serde(default)]
    x: Option<XAxis>,
    #[serde(rename = "method")]
    methods: Vec<MethodFile>,
}

fn default_thresholds() -> Vec<f64> {
    vec![100.0, 200.0, 500.0]
}
fn default_last() -> u32 {
    50
}
fn default_smooth() -> usize {
    1
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct MethodFile {
    name: String,
    #[serde(default)]
    label: Option<String>,
    /// Training: the base config, relative to the experiment file's directory. Demo-model-policy:
    /// the training config whose queries give the demonstrations.
    #[serde(default)]
    config: Option<String>,
    /// Training: `key=value` overrides of the config, as `alfd local --set`.
    #[serde(default)]
    set: Vec<String>,
    /// Demo-model-policy: the demonstrator (`alfd expert list`).
    #[serde(default)]
    expert: Option<String>,
    /// Demo-model-policy: how many demonstrations the model is fitted on.
    #[serde(default)]
    demos: Option<usize>,
    /// Demo-model-policy: `krr` or `svm`.
    #[serde(default)]
    model: Option<String>,
}

/// A validated experiment.
#[derive(Debug, Clone)]
pub struct Experiment {
    /// The file stem (`fig4-cartpole`): names the plot files.
    pub name: String,
    pub title: String,
    pub kind: ExperimentKind,
    /// Number of seeds; runs use seeds `first_seed..first_seed + seeds` ([`Experiment::seed_range`]).
    pub seeds: u64,
    /// The first seed (0 unless `alfd sweep --first-seed` says otherwise: tuning seeds, say).
    pub first_seed: u64,
    pub episodes: Option<u32>,
    pub log_y: bool,
    pub thresholds: Vec<f64>,
    pub eval_threshold: Option<f64>,
    /// The method the others are compared with seed by seed.
    pub baseline: Option<String>,
    pub by_budget: bool,
    pub learner_episodes_only: bool,
    pub eval_curves: bool,
    pub last: u32,
    pub smooth: usize,
    pub y_range: Option<(f64, f64)>,
    pub legend: LegendPosition,
    pub x: XAxis,
    pub methods: Vec<Method>,
}

/// One method of an experiment.
#[derive(Debug, Clone)]
pub struct Method {
    pub name: String,
    pub label: String,
    pub spec: MethodSpec,
}

#[derive(Debug, Clone)]
pub enum MethodSpec {
    /// A training config and its overrides.
    Training {
        config_path: PathBuf,
        config_text: String,
        set: Vec<String>,
    },
    /// A demonstration model played as a policy; its demonstrations come from the expert's own
    /// trajectory, or from the queries of a training config (`config` given).
    DemoModelPolicy {
        expert: String,
        demos: usize,
        model: DemoModelKind,
        source: DemoSource,
        /// Where the demonstrations come from, for the summary.
        source_desc: String,
    },
}

impl Method {
    /// The config of this method's run with `seed`: the base config, then the method's `set`,
    /// then the episodes override, then the seed.
    pub fn config(&self, seed: u64, episodes: Option<u32>) -> crate::Result<ExperimentConfig> {
        let MethodSpec::Training {
            config_path,
            config_text,
            set,
        } = &self.spec
        else {
            crate::error::bail!("method `{}` is not a training method", self.name);
        };
        let mut overrides = set.clone();
        if let Some(e) = episodes {
            overrides.push(format!("episodes={e}"));
        }
        overrides.push(format!("seed={seed}"));
        ExperimentConfig::from_toml_with_overrides(config_text, &overrides)
            .with_context(|| format!("method `{}` (config {})", self.name, config_path.display()))
    }
}

/// The most seeds a sweep runs (the paper's figures use 10 to 50).
pub const MAX_SEEDS: u64 = 10_000;

impl Experiment {
    /// The seeds of the sweep's runs, in order.
    pub fn seed_range(&self) -> std::ops::Range<u64> {
        self.first_seed..self.first_seed + self.seeds
    }

    /// The last seed of the sweep.
    pub fn last_seed(&self) -> u64 {
        self.first_seed + self.seeds - 1
    }

    /// Starts the sweep's seeds at `first` (`--first-seed`); refused when the last would not fit.
    pub fn with_first_seed(mut self, first: u64) -> crate::Result<Self> {
        if first.checked_add(self.seeds).is_none() {
            return Err(usage(format!(
                "--first-seed {first} with {} seeds: the last seed would pass {}",
                self.seeds,
                u64::MAX
            )));
        }
        self.first_seed = first;
        Ok(self)
    }

    /// Reads and validates an experiment file; `seeds` and `episodes` override the file's.
    /// Every method's config is loaded and checked, and its expert looked up, so that a bad entry
    /// is refused before anything runs.
    pub fn load(
        path: &Path,
        seeds: Option<u64>,
        episodes: Option<u32>,
        trainer: &dyn Trainer,
    ) -> crate::Result<Self> {
        let (name, file) = read_file(path)?;
        let Checked {
            seeds,
            episodes,
            y_range,
        } = check(&file, path, seeds, episodes)?;
        let methods = load_methods(&file, path, episodes, trainer)?;
        if let Some(b) = &file.baseline {
            if !methods.iter().any(|m| &m.name == b) {
                return Err(usage(format!(
                    "experiment file {}: baseline `{b}` is not one of its methods",
                    path.display()
                )));
            }
        }
        Ok(Self {
            name,
            title: file.title,
            kind: file.kind,
            seeds,
            first_seed: 0,
            episodes,
            log_y: file.log_y,
            thresholds: file.thresholds,
            eval_threshold: file.eval_threshold,
            baseline: file.baseline,
            by_budget: file.by_budget,
            learner_episodes_only: file.learner_episodes_only,
            eval_curves: file.eval_curves,
            last: file.last,
            smooth: file.smooth,
            y_range,
            legend: file.legend,
            x: file.x.unwrap_or_default(),
            methods,
        })
    }
}

/// The experiment file at `path` as parsed, with the experiment's name (the file stem).
fn read_file(path: &Path) -> crate::Result<(String, ExperimentFile)> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        usage(format!(
            "cannot read experiment file {}: {e}",
            path.display()
        ))
    })?;
    let file: ExperimentFile = toml::from_str(&text).map_err(|e| {
        usage(format!(
            "invalid experiment file {}: {}",
            path.display(),
            e.to_string().trim()
        ))
    })?;
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| valid_name(s))
        .ok_or_else(|| {
            usage(format!(
                "experiment file {}: its name must be made of letters, digits, '-', '_' or '.'",
                path.display()
            ))
        })?
        .to_owned();
    Ok((name, file))
}

/// A usage error about the experiment file at `path`.
fn invalid(path: &Path, msg: String) -> crate::LabError {
    usage(format!("experiment file {}: {msg}", path.display()))
}

/// The experiment's settings that [`check`] resolves.
struct Checked {
    seeds: u64,
    episodes: Option<u32>,
    y_range: Option<(f64, f64)>,
}

/// Validates the settings of `file` (at `path`) other than its methods; `seeds` and `episodes`
/// override the file's.
fn check(
    file: &ExperimentFile,
    path: &Path,
    seeds: Option<u64>,
    episodes: Option<u32>,
) -> crate::Result<Checked> {
    let bad = |msg: String| invalid(path, msg);
    let seeds = seeds.unwrap_or(file.seeds);
    if seeds == 0 {
        return Err(bad("`seeds` (or --seeds) must be at least 1, got 0".into()));
    }
    if seeds > MAX_SEEDS {
        return Err(bad(format!(
            "`seeds` (or --seeds) is {seeds}; at most {MAX_SEEDS} are allowed (every run's config is prepared before the first starts)"
        )));
    }
    let episodes = episodes.or(file.episodes);
    if episodes == Some(0) {
        return Err(bad("`episodes` must be at least 1, got 0".into()));
    }
    if file.methods.is_empty() {
        return Err(bad("no [[method]] entries".into()));
    }
    if let Some(t) = file.thresholds.iter().find(|t| !t.is_finite()) {
        return Err(bad(format!("threshold {t} is not a finite number")));
    }
    if file.last == 0 {
        return Err(bad("`last` must be at least 1".into()));
    }
    if file.smooth == 0 {
        return Err(bad("`smooth` must be at least 1".into()));
    }
    let y_range = match file.y_range {
        None => None,
        Some([lo, hi]) if lo.is_finite() && hi.is_finite() && lo < hi => {
            if file.log_y && lo <= 0.0 {
                return Err(bad("`y_range` must be positive with `log_y`".into()));
            }
            Some((lo, hi))
        }
        Some([lo, hi]) => return Err(bad(format!("`y_range` [{lo}, {hi}] is not a range"))),
    };
    if file.x.is_some() && file.kind != ExperimentKind::Training {
        return Err(bad("`x` belongs to training experiments".into()));
    }
    Ok(Checked {
        seeds,
        episodes,
        y_range,
    })
}

/// The methods of `file` (at `path`), each validated; a training method's config is built (with
/// `episodes`) and its demonstrator checked.
fn load_methods(
    file: &ExperimentFile,
    path: &Path,
    episodes: Option<u32>,
    trainer: &dyn Trainer,
) -> crate::Result<Vec<Method>> {
    let bad = |msg: String| invalid(path, msg);
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut names = BTreeSet::new();
    let mut methods = Vec::with_capacity(file.methods.len());
    for m in &file.methods {
        if !valid_name(&m.name) {
            return Err(bad(format!(
                "method name `{}` must be made of letters, digits, '-', '_' or '.' (it names a directory)",
                m.name
            )));
        }
        if !names.insert(m.name.clone()) {
            return Err(bad(format!("method `{}` is listed twice", m.name)));
        }
        let spec = match file.kind {
            ExperimentKind::Training => training_spec(m, dir),
            ExperimentKind::DemoModelPolicy => policy_spec(m, dir),
        }
        .map_err(|e| {
            bad(format!(
                "method `{}`: {}",
                m.name,
                alfd_harness::describe(&e)
            ))
        })?;
        let method = Method {
            name: m.name.clone(),
            label: m.label.clone().unwrap_or_else(|| m.name.clone()),
            spec,
        };
        if file.kind == ExperimentKind::Training {
            let cfg = method
                .config(0, episodes)
                .map_err(|e| bad(alfd_harness::describe(&e)))?;
            trainer.check(&cfg).map_err(|e| {
                let why = alfd_harness::describe(e.as_ref());
                bad(format!("method `{}`: {why}", m.name))
            })?;
        }
        methods.push(method);
    }
    Ok(methods)
}

fn training_spec(m: &MethodFile, dir: &Path) -> crate::Result<MethodSpec> {
    if m.expert.is_some() || m.demos.is_some() || m.model.is_some() {
        crate::error::bail!("`expert`, `demos` and `model` belong to demo-model-policy experiments; a training method takes `config` and `set`");
    }
    let config = m
        .config
        .as_deref()
        .ok_or_else(|| crate::error::msg!("`config` is missing"))?;
    let config_path = dir.join(config);
    let config_text = std::fs::read_to_string(&config_path)
        .with_context(|| format!("cannot read config {}", config_path.display()))?;
    if let Some(s) = m
        .set
        .iter()
        .find(|s| s.split('=').next().map(str::trim) == Some("seed"))
    {
        crate::error::bail!("`set` entry `{s}`: the sweep sets the seed of each run");
    }
    Ok(MethodSpec::Training {
        config_path,
        config_text,
        set: m.set.clone(),
    })
}

fn policy_spec(m: &MethodFile, dir: &Path) -> crate::Result<MethodSpec> {
    let expert = m
        .expert
        .clone()
        .ok_or_else(|| crate::error::msg!("`expert` is missing"))?;
    alfd_demonstrators::registry::cartpole(&expert)?;
    let demos = m.demos.unwrap_or(100);
    if demos == 0 {
        crate::error::bail!("`demos` must be at least 1");
    }
    if demos > alfd_common::demo_model::MAX_DEMOS {
        crate::error::bail!(
            "`demos` = {demos}: a demonstration model is fitted on at most {} demonstrations",
            alfd_common::demo_model::MAX_DEMOS
        );
    }
    let model = m
        .model
        .as_deref()
        .unwrap_or("krr")
        .parse::<DemoModelKind>()?;
    let source_desc = match &m.config {
        None => "the expert's trajectory".to_owned(),
        Some(c) => format!("the queries of `{c}`"),
    };
    let source = match &m.config {
        None if !m.set.is_empty() => crate::error::bail!("`set` needs a `config`"),
        None => DemoSource::ExpertTrajectory,
        Some(config) => {
            let path = dir.join(config);
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("cannot read config {}", path.display()))?;
            let cfg = ExperimentConfig::from_toml_with_overrides(&text, &m.set)
                .with_context(|| format!("in config {}", path.display()))?;
            queries_config(&cfg, &expert, demos, 0)?;
            DemoSource::Queries(Box::new(cfg))
        }
    };
    Ok(MethodSpec::DemoModelPolicy {
        expert,
        demos,
        model,
        source,
        source_desc,
    })
}

/// A name usable as a directory name.
fn valid_name(s: &str) -> bool {
    !s.is_empty()
        && s != "."
        && s != ".."
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

#[cfg(test)]
mod fuzz {
    use super::*;
    use proptest::prelude::*;
    use std::path::PathBuf;

    /// A scratch tree `experiments/` beside a link to the shipped `configs/`, so that a mutated
    /// experiment file still finds the configs it names; removed when the guard is dropped.
    fn scratch() -> (tempfile::TempDir, PathBuf) {
        let root = alfd_harness::test_dir("fuzz-experiment");
        let experiments = root.path().join("experiments");
        std::fs::create_dir_all(&experiments).unwrap();
        let configs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs");
        std::os::unix::fs::symlink(configs, root.path().join("configs")).unwrap();
        (root, experiments)
    }

    fn shipped() -> Vec<String> {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../experiments");
        let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        paths.sort();
        paths
            .iter()
            .map(|p| std::fs::read_to_string(p).unwrap())
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Arbitrary text and shipped experiment files with a few edits: `load` never panics.
        #[test]
        fn fuzz_experiment_file(
            which in any::<prop::sample::Index>(),
            edits in proptest::collection::vec(
                (any::<prop::sample::Index>(), 0usize..6, prop_oneof![
                    "[ -~\n]{0,8}",
                    Just("0".to_owned()),
                    Just("nan".to_owned()),
                    Just("-1".to_owned()),
                    Just("\n[[method]]\n".to_owned()),
                ]),
                0..4,
            ),
            arbitrary in "[ -~\n]{0,80}",
            seeds in proptest::option::of(0u64..3),
        ) {
            let files = shipped();
            let mut text: Vec<char> = files[which.index(files.len())].chars().collect();
            for (at, del, ins) in edits {
                let a = at.index(text.len() + 1);
                let b = (a + del).min(text.len());
                text.splice(a..b, ins.chars());
            }
            let (_root, dir) = scratch();
            for (name, t) in [("mutated", text.into_iter().collect::<String>()), ("arbitrary", arbitrary)] {
                let path = dir.join(format!("{name}.toml"));
                std::fs::write(&path, &t).unwrap();
                if let Err(e) = Experiment::load(&path, seeds, None, &crate::testing::AnyDemonstrator) {
                    let message = alfd_harness::describe(&e);
                    prop_assert!(!message.is_empty());
                }
            }
        }
    }
}
