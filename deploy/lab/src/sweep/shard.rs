//! Sweeps split over machines: `alfd sweep --shard I/N` runs only its share of a training sweep's
//! runs, and `alfd sweep --collect DIR...` merges the shards' run directories and writes the usual
//! outputs.
//!
//! The runs of a sweep, in its fixed order, are method-major: run `k` is method `k / seeds` (in
//! the experiment file's order) with seed `first_seed + k % seeds`. Shard `I` of `N` (1-based) owns the runs
//! with `k % N == I - 1`, so that every shard gets runs of every method when there are more
//! seeds than shards. A shard writes its runs as a sweep does (`OUT/runs/METHOD/SEED/`, resumable
//! the same way) and `OUT/shard.json`: the experiment's name and fingerprint (a hash of its
//! resolved settings and of each method's resolved config, so of `--seeds` and `--episodes`
//! too), `I`, `N`, its runs and whether they are all complete; it writes no curves, plot or
//! summary.
//!
//! `--collect` checks that the shards are of the experiment given with `--config` (same
//! fingerprint, same `N`), that each is complete, and that together they are every shard exactly
//! once; it then copies their run directories into `OUT/runs/` and finishes as a sweep of `OUT`
//! whose runs are all complete already: the curves, plot and summary come from the same code as an
//! unsharded sweep's, so they are the same numbers.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::Context as _;
use alfd_common::checkpoint::fnv1a64;
use alfd_common::config::ExperimentConfig;
use serde::{Deserialize, Serialize};

use super::experiment::Experiment;
use super::{is_complete, run_dir};
use crate::error::usage;
use crate::output::write;
use crate::report::Output;

/// The most shards a sweep is split into.
pub const MAX_SHARDS: u64 = 10_000;

/// The file that makes a directory a shard's.
pub const SHARD_FILE: &str = "shard.json";

/// Shard `index` (1-based) of `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: u64,
    pub count: u64,
}

impl Shard {
    /// Parses `--shard I/N`: bad input (exit code 2) naming the flag unless 1 ≤ I ≤ N ≤ 10,000.
    pub fn parse(s: &str) -> crate::Result<Self> {
        let bad = |why: &str| usage(format!("--shard {s}: {why}"));
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| bad("expected I/N, say 1/4 (shard I of N, 1-based)"))?;
        let i: u64 = i
            .trim()
            .parse()
            .map_err(|_| bad("I (before the '/') is not a whole number"))?;
        let n: u64 = n
            .trim()
            .parse()
            .map_err(|_| bad("N (after the '/') is not a whole number"))?;
        if n == 0 {
            return Err(bad("N must be at least 1"));
        }
        if n > MAX_SHARDS {
            return Err(bad(&format!("N must be at most {MAX_SHARDS}")));
        }
        if i == 0 || i > n {
            return Err(bad(&format!(
                "I must be from 1 to N = {n} (shards are 1-based)"
            )));
        }
        Ok(Self { index: i, count: n })
    }

    /// Whether this shard owns run `k` of the sweep's fixed order (see the module's doc).
    pub fn owns(self, k: u64) -> bool {
        k % self.count == self.index - 1
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// Run `k` of the sweep's fixed order: its method's index and its seed.
pub fn run_at(exp: &Experiment, k: u64) -> (usize, u64) {
    (
        usize::try_from(k / exp.seeds).expect("a method index"),
        exp.first_seed + k % exp.seeds,
    )
}

/// The index of (method `m`, `seed`) in the sweep's fixed order.
pub fn index_of(exp: &Experiment, m: usize, seed: u64) -> u64 {
    m as u64 * exp.seeds + (seed - exp.first_seed)
}

/// One run, as `shard.json` lists it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunId {
    pub method: String,
    pub seed: u64,
}

/// A method's name and the hash of its resolved config (seed 0).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MethodHash {
    pub name: String,
    pub config_hash: String,
}

/// `shard.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ShardFile {
    /// The experiment file's stem.
    pub experiment: String,
    /// The experiment's fingerprint ([`fingerprint`]).
    pub experiment_hash: String,
    pub methods: Vec<MethodHash>,
    pub seeds: u64,
    pub episodes: Option<u32>,
    pub shard: u64,
    pub shards: u64,
    /// Every run of the shard is complete.
    pub complete: bool,
    pub runs: Vec<RunId>,
}

fn hex(h: u64) -> String {
    format!("{h:016x}")
}

/// The experiment's fingerprint and each method's config hash. Covers everything that makes the
/// runs and the outputs (settings, seeds, episodes, methods and their resolved configs), not
/// where the files are.
pub fn fingerprint(exp: &Experiment) -> crate::Result<(String, Vec<MethodHash>)> {
    let mut text = String::new();
    let _ = writeln!(
        text,
        "experiment {:?}\ntitle {:?}\nkind {:?}\nseeds {}\nepisodes {:?}\nlog_y {}\nthresholds {:?}\n\
         last {}\nsmooth {}\ny_range {:?}\nlegend {:?}\nx {:?}",
        exp.name,
        exp.title,
        exp.kind,
        exp.seeds,
        exp.episodes,
        exp.log_y,
        exp.thresholds,
        exp.last,
        exp.smooth,
        exp.y_range,
        exp.legend,
        exp.x
    );
    // Only when set, so that the fingerprints of sweeps from seed 0 stay what they were.
    if exp.first_seed != 0 {
        let _ = writeln!(text, "first_seed {}", exp.first_seed);
    }
    let mut methods = Vec::with_capacity(exp.methods.len());
    for m in &exp.methods {
        let config_hash = hex(fnv1a64(m.config(0, exp.episodes)?.to_toml().as_bytes()));
        let _ = writeln!(
            text,
            "method {:?} label {:?} config {config_hash}",
            m.name, m.label
        );
        methods.push(MethodHash {
            name: m.name.clone(),
            config_hash,
        });
    }
    Ok((hex(fnv1a64(text.as_bytes())), methods))
}

/// The runs shard `shard` owns, in the sweep's fixed order.
pub fn runs_of(exp: &Experiment, shard: Shard) -> Vec<RunId> {
    let total = exp.seeds * exp.methods.len() as u64;
    (0..total)
        .filter(|&k| shard.owns(k))
        .map(|k| {
            let (m, seed) = run_at(exp, k);
            RunId {
                method: exp.methods[m].name.clone(),
                seed,
            }
        })
        .collect()
}

fn shard_file(exp: &Experiment, shard: Shard, complete: bool) -> crate::Result<ShardFile> {
    let (experiment_hash, methods) = fingerprint(exp)?;
    Ok(ShardFile {
        experiment: exp.name.clone(),
        experiment_hash,
        methods,
        seeds: exp.seeds,
        episodes: exp.episodes,
        shard: shard.index,
        shards: shard.count,
        complete,
        runs: runs_of(exp, shard),
    })
}

/// Reads `DIR/shard.json`: `Ok(None)` when there is none; bad input naming the file when it
/// cannot be read or parsed.
fn read_shard_file(dir: &Path) -> crate::Result<Option<ShardFile>> {
    let path = dir.join(SHARD_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(usage(format!("cannot read {}: {e}", path.display()))),
    };
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| usage(format!("{} is not a shard file: {e}", path.display())))
}

/// Before a shard runs: `OUT/shard.json` is written (not complete yet), after checking that `OUT`
/// is not the directory of another shard or another experiment's.
pub fn begin(exp: &Experiment, shard: Shard, out: &Path) -> crate::Result<()> {
    let file = shard_file(exp, shard, false)?;
    if let Some(old) = read_shard_file(out)? {
        if old.experiment_hash != file.experiment_hash
            || (old.shard, old.shards) != (shard.index, shard.count)
        {
            return Err(usage(format!(
                "{} holds shard {}/{} of experiment `{}` (hash {}), not shard {shard} of `{}` \
                 (hash {}): use another --out, or delete that directory",
                out.display(),
                old.shard,
                old.shards,
                old.experiment,
                old.experiment_hash,
                exp.name,
                file.experiment_hash
            )));
        }
    }
    write(out, SHARD_FILE, &serde_json::to_vec_pretty(&file)?)
}

/// After a shard's runs: `OUT/shard.json` says it is complete, and the shard's end is printed
/// (a JSON line with `--json`, a line on a stdout that is not a terminal, a summary on stderr).
pub fn finish(
    exp: &Experiment,
    shard: Shard,
    out: &Path,
    output: Output,
    run_now: usize,
    resumed: u64,
    wall: f64,
) -> crate::Result<()> {
    let file = shard_file(exp, shard, true)?;
    write(out, SHARD_FILE, &serde_json::to_vec_pretty(&file)?)?;
    let line = format!(
        "sweep {} shard {shard}: {} runs, {run_now} run now, {resumed} resumed (complete \
         already), {wall:.1} s; merge the shards with `alfd sweep --collect`",
        exp.name,
        file.runs.len()
    );
    if output.json {
        let json = serde_json::json!({
            "sweep": exp.name,
            "shard": shard.index,
            "shards": shard.count,
            "out": out.display().to_string(),
            "runs": file.runs.len(),
            "run_now": run_now,
            "resumed": resumed,
            "wall_clock_s": wall,
            "files": [SHARD_FILE],
        });
        println!("{json}");
    } else if output.machine_line() {
        println!("{line}");
    }
    if output.human() {
        eprintln!(
            "Shard {shard} of sweep {} finished: {} of its {} runs ({run_now} run now, {resumed} \
             complete already) in {}; when every shard is done: alfd sweep --config ... --collect \
             SHARD_DIRS... --out DIR",
            exp.name,
            file.runs.len(),
            exp.seeds * exp.methods.len() as u64,
            out.display()
        );
    }
    Ok(())
}

/// `--collect`: checks the shard directories (see the module's doc) and copies their runs into
/// `OUT/runs/`. Anything wrong with a shard is bad input naming its directory.
pub fn collect(exp: &Experiment, dirs: &[PathBuf], out: &Path) -> crate::Result<()> {
    let (n, seen) = check_shards(exp, dirs)?;
    let copies = checked_copies(exp, n, &seen, out)?;
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create output directory {}", out.display()))?;
    for (src, dst, cfg) in copies {
        if is_complete(&dst, &cfg)? {
            continue; // Collected before, or `OUT` is this shard's directory.
        }
        let _lock = alfd_harness::run_dir::lock(&dst)?;
        copy_run(&src, &dst)?;
    }
    Ok(())
}

/// Checks that `dirs` are complete shards of `exp`, each shard of the split exactly once;
/// returns the number of shards and each one's directory by index.
fn check_shards<'d>(
    exp: &Experiment,
    dirs: &'d [PathBuf],
) -> crate::Result<(u64, BTreeMap<u64, &'d Path>)> {
    let (hash, _) = fingerprint(exp)?;
    let mut count = None;
    let mut seen: BTreeMap<u64, &Path> = BTreeMap::new();
    for dir in dirs {
        let (file, shard) = read_shard(exp, &hash, dir, &mut count)?;
        if let Some(other) = seen.insert(shard.index, dir) {
            return Err(usage(format!(
                "--collect {}: shard {shard} is given twice (also {})",
                dir.display(),
                other.display()
            )));
        }
        if file.runs != runs_of(exp, shard) {
            return Err(usage(format!(
                "--collect {}: shard {shard} lists other runs than shard {shard} of `{}` has",
                dir.display(),
                exp.name
            )));
        }
        if !file.complete {
            return Err(usage(format!(
                "--collect {}: shard {shard} is not complete (run its `alfd sweep --shard` again \
                 to finish it)",
                dir.display()
            )));
        }
    }
    let n = count.ok_or_else(|| usage("--collect: no shard directories given"))?;
    let missing: Vec<String> = (1..=n)
        .filter(|i| !seen.contains_key(i))
        .map(|i| format!("{i}/{n}"))
        .collect();
    if !missing.is_empty() {
        let given: Vec<String> = seen
            .iter()
            .map(|(i, d)| format!("{i}/{n} in {}", d.display()))
            .collect();
        return Err(usage(format!(
            "--collect: shard {} missing (given: {}): give every shard's directory",
            missing.join(", "),
            given.join(", ")
        )));
    }
    Ok((n, seen))
}

/// Reads the shard file of `dir` and checks that it is a shard of `exp` (whose fingerprint is
/// `hash`) in a split into as many shards as `count` (set by the first shard read).
fn read_shard(
    exp: &Experiment,
    hash: &str,
    dir: &Path,
    count: &mut Option<u64>,
) -> crate::Result<(ShardFile, Shard)> {
    if !dir.is_dir() {
        return Err(usage(format!(
            "--collect {}: no such directory",
            dir.display()
        )));
    }
    let file = read_shard_file(dir)?.ok_or_else(|| {
        usage(format!(
            "--collect {}: not a shard (no {SHARD_FILE}; shards are made by `alfd sweep \
             --shard I/N`)",
            dir.display()
        ))
    })?;
    if file.experiment != exp.name || file.experiment_hash != hash {
        return Err(usage(format!(
            "--collect {}: a shard of another experiment (`{}`, hash {}) than the --config \
             one (`{}`, hash {hash}; give --seeds, --first-seed and --episodes as the shards had them)",
            dir.display(),
            file.experiment,
            file.experiment_hash,
            exp.name
        )));
    }
    let n = *count.get_or_insert(file.shards);
    if file.shards != n {
        return Err(usage(format!(
            "--collect {}: shard {}/{} of a split into {} shards, the others are of {n}",
            dir.display(),
            file.shard,
            file.shards,
            file.shards
        )));
    }
    let shard = Shard::parse(&format!("{}/{}", file.shard, file.shards)).map_err(|e| {
        usage(format!(
            "--collect {}: {}",
            dir.display(),
            alfd_harness::describe(&e)
        ))
    })?;
    Ok((file, shard))
}

/// The copies (source, destination in `out`, config) of every run of the `n` shards in `seen`,
/// after checking that each is complete and of this experiment's config: nothing is copied
/// before every run is checked.
fn checked_copies(
    exp: &Experiment,
    n: u64,
    seen: &BTreeMap<u64, &Path>,
    out: &Path,
) -> crate::Result<Vec<(PathBuf, PathBuf, ExperimentConfig)>> {
    let mut copies = Vec::new();
    for (&i, dir) in seen {
        for run in runs_of(exp, Shard { index: i, count: n }) {
            let m = exp
                .methods
                .iter()
                .find(|m| m.name == run.method)
                .expect("a method of the experiment");
            let src = run_dir(dir, &run.method, run.seed);
            let cfg = m.config(run.seed, exp.episodes)?;
            if !is_complete(&src, &cfg)
                .map_err(|e| usage(format!("--collect: {}", alfd_harness::describe(&e))))?
            {
                return Err(usage(format!(
                    "--collect {}: run {} seed {} is not complete ({} has no summary.json)",
                    dir.display(),
                    run.method,
                    run.seed,
                    src.display()
                )));
            }
            copies.push((src, run_dir(out, &run.method, run.seed), cfg));
        }
    }
    Ok(copies)
}

/// Copies a complete run's files from `src` into `dst` (created), `summary.json` last so that the
/// copy is complete only once every file is in; the locks are not copied.
fn copy_run(src: &Path, dst: &Path) -> crate::Result<()> {
    copy_tree(src, dst, true)?;
    std::fs::copy(src.join("summary.json"), dst.join("summary.json"))
        .with_context(|| format!("cannot copy {}", src.join("summary.json").display()))?;
    Ok(())
}

fn copy_tree(src: &Path, dst: &Path, top: bool) -> crate::Result<()> {
    std::fs::create_dir_all(dst).with_context(|| format!("cannot create {}", dst.display()))?;
    let entries =
        std::fs::read_dir(src).with_context(|| format!("cannot read {}", src.display()))?;
    for entry in entries {
        let entry = entry.with_context(|| format!("cannot read {}", src.display()))?;
        let name = entry.file_name();
        let skip = [
            alfd_harness::run_dir::LOCK_FILE,
            alfd_harness::run_dir::SWAP_LOCK_FILE,
            "summary.json",
        ];
        if top && skip.iter().any(|s| name == *s) {
            continue;
        }
        let (from, to) = (entry.path(), dst.join(&name));
        if entry.file_type()?.is_dir() {
            copy_tree(&from, &to, false)?;
        } else {
            std::fs::copy(&from, &to)
                .with_context(|| format!("cannot copy {} to {}", from.display(), to.display()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_specs_are_checked() {
        assert_eq!(Shard::parse("2/3").unwrap(), Shard { index: 2, count: 3 });
        for bad in [
            "0/2", "3/2", "1/0", "1", "a/2", "1/b", "1/10001", "-1/2", "",
        ] {
            let e = Shard::parse(bad).unwrap_err();
            assert!(alfd_harness::exit_code(&e) == 2, "{bad}");
            assert!(format!("{e}").contains("--shard"), "{bad}: {e}");
        }
    }

    #[test]
    fn shards_split_the_runs_exactly_once() {
        for n in 1..8 {
            for total in 0..20u64 {
                let mut owners = vec![0; total as usize];
                for i in 1..=n {
                    let s = Shard { index: i, count: n };
                    for k in 0..total {
                        if s.owns(k) {
                            owners[k as usize] += 1;
                        }
                    }
                }
                assert!(owners.iter().all(|&o| o == 1), "{n} {total}");
            }
        }
    }
}
