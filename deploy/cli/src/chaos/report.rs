//! The chaos run's report: the invariants checked, `RUN_DIR/chaos.json` (every fault with what
//! came of it) and `RUN_DIR/chaos.md` (the same in tables, for a person and for `alfd docs`).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Context as _;
use serde_json::Value;

use super::check::{self, Expected, Verdict};
use super::Chaos;

/// Checks the invariants, writes `chaos.json` and `chaos.md`, prints the verdicts; an error
/// when one fails.
pub(super) fn report(chaos: &Chaos<'_>, ended: Result<(), String>) -> anyhow::Result<()> {
    let dir = &chaos.args.out;
    let config_toml = std::fs::read_to_string(dir.join("config.toml"))
        .with_context(|| format!("cannot read {}", dir.join("config.toml").display()))?;
    let cfg = alfd_common::config::ExperimentConfig::for_multi_process(&config_toml)?;
    let want = Expected {
        episodes: cfg.episode_limit().map(|n| n as usize),
        steps: cfg.step_limit(),
        budget: cfg.budget(),
        actors: chaos.args.actors,
        min_last_50: chaos.args.min_last_50,
    };
    let mut verdicts = vec![Verdict {
        name: "ended",
        ok: ended.is_ok(),
        detail: ended
            .err()
            .unwrap_or_else(|| "the launcher finished the run".to_owned()),
    }];
    verdicts.extend(check::check(dir, &config_toml, want));
    if chaos.expert_host.is_some() {
        let host = dir.join("expert-host").join("demos.jsonl");
        let agrees = check::host_file_agrees(&dir.join("demos.jsonl"), &host);
        verdicts.push(check::verdict("expert host's file", agrees));
    }
    verdicts.push(nothing_left(&chaos.run_ids, chaos.swept));
    let mut counts = BTreeMap::<&str, usize>::new();
    for e in &chaos.events {
        *counts.entry(e.fault.kind()).or_default() += 1;
    }
    let report = serde_json::json!({
        "seed": chaos.args.seed,
        "duration_s": chaos.args.duration,
        "every_s": chaos.args.every,
        "faults_asked": chaos.args.faults.join(","),
        "actors": chaos.args.actors,
        "date": today(),
        "wall_clock_s": chaos.start.elapsed().as_secs_f64(),
        "launches": chaos.launches,
        "joined_host": chaos.joined.as_ref().map(|j| serde_json::json!({
            "actors": j.actors,
            "starts": j.starts,
        })),
        "expert_host": chaos.expert_host.as_ref().map(|j| serde_json::json!({
            "expert": j.expert,
            "starts": j.starts,
        })),
        "faults": counts,
        "events": chaos.events,
        "invariants": verdicts,
    });
    alfd_lab::output::write(
        dir,
        "chaos.json",
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    alfd_lab::output::write(
        dir,
        "chaos.md",
        markdown(&report, &summary_of(dir)).as_bytes(),
    )?;
    print_verdicts(chaos, &counts, &verdicts);
    let failed: Vec<&str> = verdicts.iter().filter(|v| !v.ok).map(|v| v.name).collect();
    anyhow::ensure!(
        failed.is_empty(),
        "invariants broken: {}",
        failed.join(", ")
    );
    Ok(())
}

/// The faults carried out and every invariant's verdict, on stderr.
fn print_verdicts(chaos: &Chaos<'_>, counts: &BTreeMap<&str, usize>, verdicts: &[Verdict]) {
    eprintln!(
        "chaos: {} faults in {:.0} s ({counts:?}), {} launches; {}",
        chaos.events.len(),
        chaos.start.elapsed().as_secs_f64(),
        chaos.launches,
        chaos.args.out.join("chaos.md").display()
    );
    for v in verdicts {
        eprintln!(
            "  {} {:<15} {}",
            if v.ok { "ok  " } else { "FAIL" },
            v.name,
            v.detail
        );
    }
}

/// `alfd chaos --summarize`: `chaos.md` re-made from `chaos.json`.
pub(super) fn summarize(dir: &Path) -> anyhow::Result<()> {
    let path = dir.join("chaos.json");
    let text = std::fs::read_to_string(&path)
        .map_err(|e| crate::usage::usage(format!("cannot read {}: {e}", path.display())))?;
    let report: Value = serde_json::from_str(&text)
        .map_err(|e| crate::usage::usage(format!("{}: {e}", path.display())))?;
    alfd_lab::output::write(
        dir,
        "chaos.md",
        markdown(&report, &summary_of(dir)).as_bytes(),
    )?;
    println!("{}", dir.join("chaos.md").display());
    Ok(())
}

fn summary_of(dir: &Path) -> Value {
    std::fs::read_to_string(dir.join("summary.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or(Value::Null)
}

/// The report as Markdown: the run, the faults by kind, the invariants.
fn markdown(report: &Value, summary: &Value) -> String {
    let mut by_kind = BTreeMap::<String, (usize, usize)>::new();
    for e in report["events"].as_array().into_iter().flatten() {
        let kind = match &e["fault"] {
            Value::String(s) => s.clone(),
            Value::Object(o) => o.keys().next().cloned().unwrap_or_default(),
            _ => String::new(),
        };
        let slot = by_kind.entry(kind).or_default();
        slot.0 += 1;
        slot.1 += usize::from(e["carried_out"] == true);
    }
    let n = |v: &Value| v.as_u64().map_or("?".to_owned(), |x| x.to_string());
    let mut lines = vec![
        "# Chaos run".to_owned(),
        String::new(),
        "Written by `alfd chaos`; every fault, with what came of it, is in `chaos.json`."
            .to_owned(),
        String::new(),
        "## Run".to_owned(),
        String::new(),
        format!(
            "{}; seed {}, faults `{}` for {} s, one every {} s on average; {} actors; \
             {:.0} s of wall-clock in all, {} launches (the first and one `alfd resume` per \
             launcher killed). The run: {} episodes, {} environment steps, {} demonstrations; \
             mean return of the last 50 episodes {}.",
            report["date"].as_str().unwrap_or("?"),
            n(&report["seed"]),
            report["faults_asked"].as_str().unwrap_or("?"),
            n(&report["duration_s"]),
            report["every_s"]
                .as_f64()
                .map_or("?".to_owned(), |x| x.to_string()),
            n(&report["actors"]),
            report["wall_clock_s"].as_f64().unwrap_or(f64::NAN),
            n(&report["launches"]),
            n(&summary["episodes"]),
            n(&summary["env_steps"]),
            n(&summary["demos"]),
            summary["mean_return_last_50"]
                .as_f64()
                .map_or("?".to_owned(), |x| format!("{x:.1}")),
        ) + &joined_host(&report["joined_host"])
            + &expert_host(&report["expert_host"], summary),
        String::new(),
        "## Faults".to_owned(),
        String::new(),
        "| fault | drawn | carried out |".to_owned(),
        "|---|---:|---:|".to_owned(),
    ];
    for (kind, (drawn, done)) in &by_kind {
        lines.push(format!("| {kind} | {drawn} | {done} |"));
    }
    lines.extend([
        String::new(),
        "\"Carried out\" leaves out the faults that found no process to hit (one restarting), a \
         swap while one was under way, a launcher kill before the first learner checkpoint."
            .to_owned(),
        String::new(),
        "## Invariants".to_owned(),
        String::new(),
        "| invariant | held | what was found |".to_owned(),
        "|---|:---:|---|".to_owned(),
    ]);
    for v in report["invariants"].as_array().into_iter().flatten() {
        lines.push(format!(
            "| {} | {} | {} |",
            v["name"].as_str().unwrap_or("?"),
            if v["ok"] == true { "yes" } else { "**no**" },
            v["detail"].as_str().unwrap_or("").replace('|', "\\|")
        ));
    }
    lines.join("\n") + "\n"
}

/// The joined host's sentence of the report (empty without one).
fn joined_host(host: &Value) -> String {
    match (host["actors"].as_u64(), host["starts"].as_u64()) {
        (Some(actors), Some(starts)) => format!(
            " A joined host (`alfd join` on 127.0.0.1) with {actors} actor(s), started {starts} \
             time(s)."
        ),
        _ => String::new(),
    }
}

/// The joined expert host's sentence of the report (empty without one).
fn expert_host(host: &Value, summary: &Value) -> String {
    match (host["expert"].as_str(), host["starts"].as_u64()) {
        (Some(expert), Some(starts)) => format!(
            " The expert `{expert}` on a joined host behind a relay that delay faults slow              down, started {starts} time(s); {} answers came after their actor stopped waiting.",
            summary["answers_late"]
                .as_u64()
                .map_or("?".to_owned(), |x| x.to_string())
        ),
        _ => String::new(),
    }
}

/// No process of any of the run's launches is alive, and none left iceoryx2 files: the system
/// alone removed what its launches left (`swept`, the files of dead launches the harness found
/// at the end, must be none). A killed joined host cannot clean up after itself: its copy's
/// files are removed by the harness, as `alfd clean` would, before the check.
pub(super) fn nothing_left(run_ids: &[String], swept: usize) -> Verdict {
    let mut left = Vec::new();
    if swept > 0 {
        left.push(format!(
            "{swept} files of dead launches were still there at the end (the run's last launcher \
             should have removed them)"
        ));
    }
    for id in run_ids {
        let alive = alfd_wire::alive_nodes(id).unwrap_or_default();
        let files = alfd_wire::leftover_files(id);
        if !alive.is_empty() || !files.is_empty() {
            let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
            left.push(format!(
                "{id}: nodes alive {alive:?}, files {}",
                names.join(", ")
            ));
        }
    }
    Verdict {
        name: "nothing left",
        ok: left.is_empty(),
        detail: if left.is_empty() {
            format!(
                "{} runs' processes gone (launches and joined hosts' copies), their files removed \
                 (the launches' by the run itself)",
                run_ids.len()
            )
        } else {
            left.join("; ")
        },
    }
}

/// Today's date (UTC) as `YYYY-MM-DD`.
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    civil_date(secs / 86_400)
}

/// The proleptic Gregorian date of `days` since 1970-01-01 (Howard Hinnant's days-to-civil).
fn civil_date(days: u64) -> String {
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates_of_known_days() {
        assert_eq!(civil_date(0), "1970-01-01");
        assert_eq!(civil_date(11_016), "2000-02-29");
        assert_eq!(civil_date(20_789), "2026-12-02");
    }

    #[test]
    fn the_markdown_counts_faults_by_kind_and_what_was_carried_out() {
        let report = serde_json::json!({
            "date": "2026-12-02", "seed": 3, "faults_asked": "kill", "duration_s": 10,
            "every_s": 2.0, "actors": 2, "wall_clock_s": 12.0, "launches": 2,
            "events": [
                {"fault": {"kill": "learner"}, "outcome": "killed pid 7", "carried_out": true},
                {"fault": {"kill": {"actor": 1}}, "outcome": "no such process", "carried_out": false},
                {"fault": "kill-launcher", "outcome": "killed launcher pid 9", "carried_out": true},
            ],
            "invariants": [{"name": "episodes", "ok": true, "detail": "a | b"}],
        });
        let md = markdown(&report, &serde_json::json!({"episodes": 5}));
        assert!(md.contains("| kill | 2 | 1 |"), "{md}");
        assert!(md.contains("| kill-launcher | 1 | 1 |"), "{md}");
        assert!(md.contains("| episodes | yes | a \\| b |"), "{md}");
        assert!(md.contains("5 episodes"), "{md}");
    }
}
