//! What must hold after a chaos run, read from its run directory: the run finished; every
//! episode is in `episodes.csv` once, in order; `demos.jsonl` is a gap-free sequence within the
//! budget that equals what the run counted; every checkpoint on disk loads; and, when asked,
//! the run still learned.

use std::path::Path;

/// One invariant, checked.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Verdict {
    pub name: &'static str,
    pub ok: bool,
    /// What was found (the numbers compared, or what went wrong).
    pub detail: String,
}

pub fn verdict(name: &'static str, result: Result<String, String>) -> Verdict {
    match result {
        Ok(detail) => Verdict {
            name,
            ok: true,
            detail,
        },
        Err(detail) => Verdict {
            name,
            ok: false,
            detail,
        },
    }
}

/// What the run was asked to do.
#[derive(Debug, Clone, Copy)]
pub struct Expected {
    /// The run's episode limit (none: only its step limit).
    pub episodes: Option<usize>,
    /// The run's step limit (environment steps the learner received).
    pub steps: Option<u64>,
    pub budget: u32,
    pub actors: usize,
    /// The least mean return over the last 50 episodes (none: not checked).
    pub min_last_50: Option<f64>,
}

/// Every invariant of the run in `dir` (its config's text is `config_toml`).
pub fn check(dir: &Path, config_toml: &str, want: Expected) -> Vec<Verdict> {
    let summary = read_json(&dir.join("summary.json"));
    let demos = demo_lines(&dir.join("demos.jsonl"));
    let cut = step_limit_cut(&dir.join("episodes.csv"), &summary, want);
    vec![
        verdict("finished", finished(&summary, want)),
        verdict(
            "episodes",
            episode_rows(&dir.join("episodes.csv"), &summary),
        ),
        verdict(
            "demonstrations",
            demos_agree(&demos, &summary, want.budget, cut),
        ),
        verdict(
            "checkpoints",
            checkpoints_load(dir, config_toml, want.actors),
        ),
        verdict("learned", learned(&summary, want.min_last_50)),
    ]
}

fn read_json(path: &Path) -> Result<serde_json::Value, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Not interrupted, and at the episode limit or past the step limit (whichever came first).
fn finished(summary: &Result<serde_json::Value, String>, want: Expected) -> Result<String, String> {
    let s = summary.as_ref().map_err(Clone::clone)?;
    let episodes = s["episodes"].as_u64().unwrap_or(0) as usize;
    let steps = s["env_steps"].as_u64().unwrap_or(0);
    let interrupted = s["interrupted"].as_bool().unwrap_or(true);
    let at_limit = want.episodes == Some(episodes) || want.steps.is_some_and(|n| steps >= n);
    let limits = format!(
        "limits: {:?} episodes, {:?} steps",
        want.episodes, want.steps
    );
    if at_limit && !interrupted {
        Ok(format!(
            "{episodes} episodes, {steps} steps, not interrupted ({limits})"
        ))
    } else {
        Err(format!(
            "summary.json: {episodes} episodes, {steps} steps, interrupted {interrupted} ({limits})"
        ))
    }
}

/// The episode numbers of `episodes.csv` are 0..n, each once, in order, and n is the episodes
/// `summary.json` counts.
fn episode_rows(
    path: &Path,
    summary: &Result<serde_json::Value, String>,
) -> Result<String, String> {
    let s = summary.as_ref().map_err(Clone::clone)?;
    let episodes = s["episodes"].as_u64().unwrap_or(0) as usize;
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut next = 0usize;
    for (n, line) in text.lines().enumerate().skip(1) {
        let episode: usize = line
            .split(',')
            .next()
            .and_then(|f| f.parse().ok())
            .ok_or_else(|| format!("episodes.csv line {}: not an episode row: {line:?}", n + 1))?;
        if episode != next {
            return Err(format!(
                "episodes.csv line {}: episode {episode} where {next} was due (lost or written \
                 twice)",
                n + 1
            ));
        }
        next += 1;
    }
    if next == episodes {
        Ok(format!("{next} rows, episodes 0..{next} once each"))
    } else {
        Err(format!(
            "episodes.csv holds {next} episodes; summary.json counts {episodes}"
        ))
    }
}

/// The `index` and `step` of every line of `demos.jsonl`, in file order.
fn demo_lines(path: &Path) -> Result<Vec<(u64, u64)>, String> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(format!("{}: {e}", path.display())),
    };
    text.lines()
        .enumerate()
        .map(|(n, line)| {
            serde_json::from_str::<serde_json::Value>(line)
                .ok()
                .and_then(|v| Some((v["index"].as_u64()?, v["step"].as_u64()?)))
                .ok_or_else(|| format!("demos.jsonl line {}: not a demonstration", n + 1))
        })
        .collect()
}

/// For a run the step limit stopped: the global step at which the first of the actors recorded
/// its last episode. A demonstration asked after it may be in an episode the limit cut (not
/// recorded), or reach the other actors' rows only with a model published after their last
/// one; `None` for a run the episode limit stopped (every actor's share is recorded whole).
fn step_limit_cut(
    episodes_csv: &Path,
    summary: &Result<serde_json::Value, String>,
    want: Expected,
) -> Option<u64> {
    let s = summary.as_ref().ok()?;
    let episodes = s["episodes"].as_u64()? as usize;
    if want.steps.is_none() || want.episodes == Some(episodes) {
        return None;
    }
    let text = std::fs::read_to_string(episodes_csv).ok()?;
    let rows = alfd_common::record::parse_episodes_csv(&text).ok()?;
    let mut last = std::collections::BTreeMap::new();
    for r in &rows {
        last.insert(r.actor, r.total_steps);
    }
    last.into_values().min()
}

/// `demos.jsonl` is 0..n without a gap or a repeat, n within the budget, and n is what
/// `summary.json` counts. A demonstration the episodes do not count as used came late to its
/// actor (`answers_late`) or, in a run the step limit stopped, was asked after `cut`
/// ([`step_limit_cut`]).
fn demos_agree(
    demos: &Result<Vec<(u64, u64)>, String>,
    summary: &Result<serde_json::Value, String>,
    budget: u32,
    cut: Option<u64>,
) -> Result<String, String> {
    let demos = demos.as_ref().map_err(Clone::clone)?;
    if let Some((line, (index, _))) = demos
        .iter()
        .enumerate()
        .find(|(i, (index, _))| *index != *i as u64)
    {
        return Err(format!(
            "demos.jsonl line {}: index {index} where {line} was due",
            line + 1
        ));
    }
    let n = demos.len() as u64;
    if n > u64::from(budget) {
        return Err(format!("{n} demonstrations against a budget of {budget}"));
    }
    let s = summary.as_ref().map_err(Clone::clone)?;
    let (counted, used) = (s["demos"].as_u64(), s["demos_used"].as_u64());
    let late = s["answers_late"].as_u64().unwrap_or(0);
    let unused = n.saturating_sub(used.unwrap_or(0));
    let at_end = demos
        .iter()
        .skip(used.unwrap_or(0) as usize)
        .filter(|(_, step)| cut.is_some_and(|c| *step > c))
        .count() as u64;
    if counted != Some(n) || used.is_none_or(|u| u > n) || unused > late + at_end {
        return Err(format!(
            "demos.jsonl holds {n}; summary.json counts demos {counted:?}, demos_used {used:?}, \
             answers_late {late}; {at_end} asked after the step limit's cut (step {cut:?})"
        ));
    }
    Ok(format!(
        "{n} of {budget}, indices 0..{n}, as summary.json counts ({unused} unused: of {late} \
         answers that came late and {at_end} asked after step {cut:?}, where the first actor \
         recorded its last episode)"
    ))
}

/// The expert host's `demos.jsonl` (`host`) is the start of the run's (`run`), line for line:
/// every demonstration its expert wrote reached the run's file, in its place.
pub fn host_file_agrees(run: &Path, host: &Path) -> Result<String, String> {
    let read = |p: &Path| std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()));
    let (run, host) = (read(run)?, read(host)?);
    let run_lines: Vec<&str> = run.lines().collect();
    let host_lines: Vec<&str> = host.lines().collect();
    if let Some(i) = host_lines.iter().zip(&run_lines).position(|(h, r)| h != r) {
        return Err(format!(
            "line {} differs: the host's {:?}, the run's {:?}",
            i + 1,
            host_lines[i],
            run_lines[i]
        ));
    }
    if host_lines.len() > run_lines.len() {
        return Err(format!(
            "the host's demos.jsonl holds {} lines, the run's {}: lines {}.. never reached the run",
            host_lines.len(),
            run_lines.len(),
            run_lines.len() + 1
        ));
    }
    Ok(format!(
        "the host's {} lines are the run's first {} (the run holds {})",
        host_lines.len(),
        host_lines.len(),
        run_lines.len()
    ))
}

/// `learner.ckpt` and every `actor-<id>.ckpt` on disk load.
fn checkpoints_load(dir: &Path, config_toml: &str, actors: usize) -> Result<String, String> {
    let mut loaded = Vec::new();
    match alfd_learner::checkpoint::load(dir, config_toml) {
        Ok(Some(_)) => loaded.push("learner.ckpt".to_owned()),
        Ok(None) => {}
        Err(e) => return Err(alfd_harness::describe(&e)),
    }
    for id in 0..actors as u16 {
        match alfd_actor::checkpoint::load(dir, id, config_toml) {
            Ok(Some(c)) => loaded.push(format!("actor-{id}.ckpt ({} states)", c.slots.len())),
            Ok(None) => {}
            Err(e) => return Err(alfd_harness::describe(&e)),
        }
    }
    if loaded.is_empty() {
        return Err("no checkpoint on disk".to_owned());
    }
    Ok(loaded.join(", "))
}

fn learned(
    summary: &Result<serde_json::Value, String>,
    min: Option<f64>,
) -> Result<String, String> {
    let Some(min) = min else {
        return Ok("not asked".to_owned());
    };
    let s = summary.as_ref().map_err(Clone::clone)?;
    let last = s["mean_return_last_50"].as_f64().unwrap_or(f64::NAN);
    if last >= min {
        Ok(format!("last 50 episodes' mean return {last:.1} ≥ {min}"))
    } else {
        Err(format!("last 50 episodes' mean return {last:.1} < {min}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(episodes: u64, demos: u64, interrupted: bool) -> Result<serde_json::Value, String> {
        Ok(serde_json::json!({
            "episodes": episodes, "env_steps": 1000, "demos": demos, "demos_used": demos,
            "interrupted": interrupted, "mean_return_last_50": 612.5,
        }))
    }

    fn limits(episodes: Option<usize>, steps: Option<u64>) -> Expected {
        Expected {
            episodes,
            steps,
            budget: 0,
            actors: 1,
            min_last_50: None,
        }
    }

    #[test]
    fn a_run_that_stopped_short_or_was_interrupted_has_not_finished() {
        let ten = limits(Some(10), None);
        assert!(finished(&summary(10, 0, false), ten).is_ok());
        assert!(finished(&summary(9, 0, false), ten).is_err());
        assert!(finished(&summary(10, 0, true), ten).is_err());
        assert!(finished(&Err("no summary.json".into()), ten).is_err());
        // The step limit came first (1,000 steps of 1,000).
        assert!(finished(&summary(9, 0, false), limits(Some(10), Some(1000))).is_ok());
        assert!(finished(&summary(9, 0, false), limits(Some(10), Some(1001))).is_err());
    }

    #[test]
    fn an_episode_lost_or_written_twice_is_named_by_its_line() {
        let dir = alfd_harness::test_dir("chaos-check");
        let path = dir.path().join("episodes.csv");
        let write = |rows: &[usize]| {
            let mut text = "episode,return\n".to_owned();
            for r in rows {
                text.push_str(&format!("{r},1.0\n"));
            }
            std::fs::write(&path, text).unwrap();
        };
        let three = summary(3, 0, false);
        write(&[0, 1, 2]);
        assert!(episode_rows(&path, &three).is_ok());
        write(&[0, 1, 1, 2]);
        let e = episode_rows(&path, &three).unwrap_err();
        assert!(e.contains("line 4: episode 1 where 2 was due"), "{e}");
        write(&[0, 2]);
        assert!(episode_rows(&path, &three).unwrap_err().contains("line 3"));
        write(&[0, 1]);
        let e = episode_rows(&path, &three).unwrap_err();
        assert!(e.contains("holds 2 episodes; summary.json counts 3"), "{e}");
    }

    #[test]
    fn demonstrations_must_be_gap_free_within_the_budget_and_as_counted() {
        // Indices 0..3, asked at steps 100, 200 and 300.
        let ok = Ok(vec![(0, 100), (1, 200), (2, 300)]);
        assert!(demos_agree(&ok, &summary(5, 3, false), 3, None).is_ok());
        assert!(demos_agree(&ok, &summary(5, 3, false), 2, None)
            .unwrap_err()
            .contains("budget of 2"));
        assert!(demos_agree(&ok, &summary(5, 2, false), 3, None)
            .unwrap_err()
            .contains("counts demos Some(2)"));
        // Unused demonstrations are only those whose answers came late...
        let late = |used: u64, late: u64| {
            Ok(serde_json::json!({"demos": 3, "demos_used": used, "answers_late": late}))
        };
        assert!(demos_agree(&ok, &late(1, 2), 3, None).is_ok());
        assert!(demos_agree(&ok, &late(1, 1), 3, None)
            .unwrap_err()
            .contains("answers_late 1"));
        assert!(demos_agree(&ok, &late(4, 0), 3, None).is_err());
        // ... or, in a run the step limit stopped, those asked after the step limit's cut.
        assert!(demos_agree(&ok, &late(2, 0), 3, Some(250)).is_ok());
        assert!(demos_agree(&ok, &late(1, 1), 3, Some(250)).is_ok());
        let e = demos_agree(&ok, &late(1, 0), 3, Some(250)).unwrap_err();
        assert!(e.contains("1 asked after the step limit's cut"), "{e}");
        assert!(demos_agree(&ok, &late(2, 0), 3, Some(300)).is_err());
        let gap = Ok(vec![(0, 100), (2, 200)]);
        assert!(demos_agree(&gap, &summary(5, 2, false), 3, None)
            .unwrap_err()
            .contains("line 2: index 2 where 1 was due"));
    }

    #[test]
    fn the_step_limits_cut_is_where_the_first_actor_recorded_its_last_episode() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("episodes.csv");
        let rows = "episode,return,length,demos_used,total_steps,actor\n\
                    0,1,10,0,100,0\n1,1,10,0,150,1\n2,1,10,1,400,0\n3,1,10,1,320,1\n";
        std::fs::write(&path, rows).unwrap();
        let ran = |episodes| Ok(serde_json::json!({"episodes": episodes}));
        let steps = Expected {
            episodes: Some(10),
            steps: Some(500),
            ..limits(None, None)
        };
        assert_eq!(step_limit_cut(&path, &ran(4), steps), Some(320));
        // The episode limit stopped it, or it has none: no cut.
        assert_eq!(step_limit_cut(&path, &ran(10), steps), None);
        assert_eq!(step_limit_cut(&path, &ran(4), limits(Some(10), None)), None);
    }

    #[test]
    fn the_expert_hosts_file_must_be_the_start_of_the_runs() {
        let dir = std::env::temp_dir().join(format!("alfd-chaos-host-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (run, host) = (dir.join("run.jsonl"), dir.join("host.jsonl"));
        std::fs::write(&run, "a\nb\nc\n").unwrap();
        for (text, ok) in [
            ("a\nb\n", true),
            ("a\nb\nc\n", true),
            ("", true),
            ("a\nx\n", false),
            ("a\nb\nc\nd\n", false),
        ] {
            std::fs::write(&host, text).unwrap();
            let got = host_file_agrees(&run, &host);
            assert_eq!(got.is_ok(), ok, "{text:?}: {got:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn learning_is_checked_only_when_asked() {
        assert!(learned(&summary(5, 0, false), None).is_ok());
        assert!(learned(&summary(5, 0, false), Some(500.0)).is_ok());
        assert!(learned(&summary(5, 0, false), Some(700.0)).is_err());
    }
}
