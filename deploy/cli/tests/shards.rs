//! `alfd sweep --shard I/N` and `--collect`: a sweep split into two shards and merged gives the
//! unsharded sweep's `curves.csv` byte for byte; shards of another experiment, missing shards and
//! bad `--shard` values are refused (exit code 2) naming what is wrong.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::support::{alfd, text, timed, tmp};

/// A tiny experiment (2 CliffWalk methods × 3 seeds × `episodes` episodes, well under a second)
/// written as `DIR/NAME.toml`.
fn experiment(dir: &Path, name: &str, episodes: u32) -> PathBuf {
    let config = |f: &str| {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../configs")
            .join(f)
            .display()
            .to_string()
    };
    let path = dir.join(format!("{name}.toml"));
    let body = format!(
        "title = \"Tiny shards\"\nseeds = 3\nepisodes = {episodes}\n\n\
         [[method]]\nname = \"qlearning\"\nconfig = \"{}\"\n\n\
         [[method]]\nname = \"bootstrapped\"\nconfig = \"{}\"\n",
        config("cliffwalk-qlearning.toml"),
        config("cliffwalk-bootstrapped.toml")
    );
    std::fs::write(&path, body).unwrap();
    path
}

fn sweep(experiment: &Path, out: &Path, extra: &[&Path]) -> Output {
    let mut c = alfd();
    c.arg("sweep")
        .arg("--config")
        .arg(experiment)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .args(extra)
        .env("RUST_LOG", "warn");
    c.output().expect("alfd runs")
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", text(o));
}

/// Exit code 2, every one of `needles` in the message, no panic.
fn refused(o: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{}", text(o));
    for n in needles {
        assert!(stderr.contains(n), "`{n}` not in: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Whether shard or sweep directory `d` holds a complete run of method `m` with seed `s`.
fn has(d: &Path, m: &str, s: u64) -> bool {
    d.join("runs")
        .join(m)
        .join(s.to_string())
        .join("summary.json")
        .is_file()
}

#[test]
fn sharded_sweep_collects_to_the_unsharded_curves() {
    let _time = timed!();
    let dir = tmp("shards");
    let exp = experiment(&dir, "tiny", 20);
    let [whole, s1, s2, merged] = ["whole", "s1", "s2", "merged"].map(|d| dir.join(d));
    ok(&sweep(&exp, &whole, &[]));
    ok(&sweep(&exp, &s1, &[Path::new("--shard"), Path::new("1/2")]));
    ok(&sweep(&exp, &s2, &[Path::new("--shard"), Path::new("2/2")]));

    // Each shard ran its half of the runs (method-major order, k % 2), and wrote no curves.
    for (k, (m, s)) in [("qlearning", 0), ("qlearning", 1), ("qlearning", 2)]
        .into_iter()
        .chain([
            ("bootstrapped", 0),
            ("bootstrapped", 1),
            ("bootstrapped", 2),
        ])
        .enumerate()
    {
        assert_eq!(has(&s1, m, s), k % 2 == 0, "{m} {s}");
        assert_eq!(has(&s2, m, s), k % 2 == 1, "{m} {s}");
    }
    for s in [&s1, &s2] {
        assert!(s.join("shard.json").is_file());
        assert!(!s.join("curves.csv").exists() && !s.join("summary.md").exists());
    }

    let collect = |out: &Path, shards: &[&Path]| {
        let mut extra = vec![Path::new("--collect")];
        extra.extend_from_slice(shards);
        sweep(&exp, out, &extra)
    };
    let o = collect(&merged, &[&s1, &s2]);
    ok(&o);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("6 runs, 0 run now, 6 resumed"),
        "{}",
        text(&o)
    );
    let curves = |d: &Path| std::fs::read(d.join("curves.csv")).unwrap();
    assert_eq!(curves(&merged), curves(&whole), "curves.csv differ");
    assert!(merged.join("summary.md").is_file() && merged.join("tiny.svg").is_file());
    // Collecting again (everything there already) gives the same curves.
    ok(&collect(&merged, &[&s2, &s1]));
    assert_eq!(curves(&merged), curves(&whole));

    // A shard of another experiment (other episodes) is refused, naming its directory.
    let other = experiment(&dir, "other", 10);
    let o2 = dir.join("other-2");
    ok(&sweep(
        &other,
        &o2,
        &[Path::new("--shard"), Path::new("2/2")],
    ));
    let bad = dir.join("bad");
    let o = collect(&bad, &[&s1, &o2]);
    refused(&o, &[&o2.display().to_string(), "another experiment"]);
    assert!(
        !bad.exists(),
        "a refused collect leaves no output directory"
    );
    // So is a shard given with other --episodes than it was run with.
    let mut c = sweep(
        &exp,
        &bad,
        &[
            Path::new("--episodes"),
            Path::new("10"),
            Path::new("--collect"),
            &s1,
            &s2,
        ],
    );
    refused(&c, &[&s1.display().to_string(), "another experiment"]);
    // A missing shard: named, with the directories given.
    c = collect(&bad, &[&s1]);
    refused(&c, &["shard 2/2 missing", &s1.display().to_string()]);
    // A directory that is not a shard, or not there.
    c = collect(&bad, &[&s1, &whole]);
    refused(&c, &[&whole.display().to_string(), "not a shard"]);
    let nowhere = dir.join("nowhere");
    c = collect(&bad, &[&s1, &nowhere]);
    refused(&c, &[&nowhere.display().to_string()]);
    // The same shard twice.
    c = collect(&bad, &[&s1, &s1]);
    refused(&c, &[&s1.display().to_string(), "twice"]);
    assert!(
        !bad.exists(),
        "a refused collect leaves no output directory"
    );
}

#[test]
fn bad_shard_values_are_refused() {
    let _time = timed!();
    let dir = tmp("bad-shards");
    let exp = experiment(&dir, "tiny", 20);
    let out = dir.join("out");
    for s in ["0/2", "3/2", "1/0", "1/10001", "2", "a/b"] {
        let o = sweep(&exp, &out, &[Path::new("--shard"), Path::new(s)]);
        refused(&o, &["--shard", s]);
        assert!(!out.join("runs").exists(), "{s}: something ran");
    }
}

/// With `--first-seed 5` the shards split seeds 5-7 as they split 0-2, merge to the unsharded
/// sweep's curves, and a collect that forgets `--first-seed` is refused.
#[test]
fn sharded_sweep_from_a_first_seed_collects_to_the_unsharded_curves() {
    let _time = timed!();
    let dir = tmp("shards-first-seed");
    let exp = experiment(&dir, "tiny", 20);
    let [whole, s1, s2, merged] = ["whole", "s1", "s2", "merged"].map(|d| dir.join(d));
    fn with(more: &[&'static str]) -> Vec<&'static Path> {
        ["--first-seed", "5"]
            .iter()
            .chain(more)
            .map(|a| Path::new(*a))
            .collect()
    }
    ok(&sweep(&exp, &whole, &with(&[])));
    ok(&sweep(&exp, &s1, &with(&["--shard", "1/2"])));
    ok(&sweep(&exp, &s2, &with(&["--shard", "2/2"])));
    // Method-major order over seeds 5, 6, 7: k = 0 (qlearning 5), 2 (qlearning 7), 4
    // (bootstrapped 6) in shard 1; the others in shard 2.
    assert!(has(&s1, "qlearning", 5) && has(&s1, "qlearning", 7) && has(&s1, "bootstrapped", 6));
    assert!(has(&s2, "qlearning", 6) && has(&s2, "bootstrapped", 5) && has(&s2, "bootstrapped", 7));
    assert!(!has(&s1, "qlearning", 0) && !has(&s2, "qlearning", 0));
    let forgot = sweep(
        &exp,
        &dir.join("forgot"),
        &[Path::new("--collect"), &s1, &s2],
    );
    refused(&forgot, &["another experiment", "--first-seed"]);
    let mut args = with(&["--collect"]);
    args.push(&s1);
    args.push(&s2);
    ok(&sweep(&exp, &merged, &args));
    let read = |d: &Path| std::fs::read(d.join("curves.csv")).unwrap();
    assert_eq!(read(&whole), read(&merged));
}
