//! The prior demonstrations of a multi-process run (`demos.prior`): `alfd run` reads the Minari
//! dataset once and writes its expert steps to `RUN_DIR/prior-demos.jsonl`, one JSON object per
//! line ([`PriorDemo`]); the learner puts them in its replay buffer when it starts a run from
//! scratch (a restored learner's buffer holds them already), and every expert process fits its
//! demonstration model on them before the run's own demonstrations.

use std::path::Path;

use alfd_common::agent::PriorDemo;

use crate::{BadInput, Result};

/// The file's name in a run directory.
pub const PRIOR_FILE: &str = "prior-demos.jsonl";

/// Writes `demos` to `run_dir/prior-demos.jsonl` (whole, or not at all).
pub fn write_prior(run_dir: &Path, demos: &[PriorDemo]) -> Result<()> {
    let mut text = Vec::new();
    for d in demos {
        serde_json::to_writer(&mut text, d).map_err(std::io::Error::other)?;
        text.push(b'\n');
    }
    crate::write_atomically(&run_dir.join(PRIOR_FILE), &text)
}

/// The prior demonstrations of the run in `run_dir` (none when it has no such file); a line that
/// is not one, or one whose sizes differ from the environment's, is refused by its number.
pub fn read_prior(run_dir: &Path, obs_dim: usize, num_actions: usize) -> Result<Vec<PriorDemo>> {
    let path = run_dir.join(PRIOR_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e.into()),
    };
    let bad = |n: usize, why: String| BadInput(format!("{} line {}: {why}", path.display(), n + 1));
    let mut demos = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let d: PriorDemo = serde_json::from_str(line).map_err(|e| bad(n, e.to_string()))?;
        if d.state.len() != obs_dim || d.next_state.len() != obs_dim || d.action >= num_actions {
            return Err(bad(n, format!(
                "a demonstration that does not fit {obs_dim} observation values and {num_actions} actions"
            ))
            .into());
        }
        demos.push(d);
    }
    Ok(demos)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prior_demonstrations_round_trip_and_a_bad_line_is_named() {
        let dir = crate::test_dir("prior");
        assert!(
            read_prior(dir.path(), 2, 2).unwrap().is_empty(),
            "no file: none"
        );
        let d = |x: f32, a: usize| PriorDemo {
            state: vec![x, -x],
            action: a,
            reward: -1.0,
            next_state: vec![x + 0.5, 0.25],
            terminated: a == 1,
        };
        let demos = vec![d(0.1, 0), d(1e-7, 1)];
        write_prior(dir.path(), &demos).unwrap();
        assert_eq!(read_prior(dir.path(), 2, 2).unwrap(), demos);
        let e = read_prior(dir.path(), 3, 2).unwrap_err();
        assert!(e.is_bad_input() && e.to_string().contains("line 1"), "{e}");
        let e = read_prior(dir.path(), 2, 1).unwrap_err();
        assert!(e.to_string().contains("line 2"), "{e}");
    }
}
