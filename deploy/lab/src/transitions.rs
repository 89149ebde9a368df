//! Every transition of a single-process run (`alfd local --transitions`): `transitions.jsonl`,
//! a header line (the environment's name, dimensions and step limit), then one line per
//! finished episode with its observations (the reset's, then one per step), actions, rewards,
//! whether it terminated or was truncated, and `first_step`, the run's step of its first action
//! (`demos.jsonl` names a demonstration by that step). Episodes are written as they end; an
//! episode cut short by the run's step limit is not. What Minari datasets are made from
//! ([`dataset`]), and what a Minari dataset gives a run ([`prior_demos`]).

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::Path;

use alfd_common::agent::DemoRecord;
use alfd_common::agent::PriorDemo;
use alfd_common::env::{Env, EnvError, EnvState, Step, VectorEnv};
use serde::{Deserialize, Serialize};

use crate::error::{usage, Context, Result};
use crate::minari::{Dataset, Episode};

/// The file's name in a run directory.
pub const FILE: &str = "transitions.jsonl";

/// The first line of [`FILE`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub env: String,
    pub obs_dim: usize,
    pub num_actions: usize,
    pub max_episode_steps: usize,
}

/// One finished episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Recorded {
    pub episode: u64,
    pub first_step: u64,
    pub observations: Vec<Vec<f32>>,
    pub actions: Vec<usize>,
    pub rewards: Vec<f64>,
    pub terminated: bool,
    pub truncated: bool,
}

/// An environment that writes its finished episodes to [`FILE`] as it plays them (the run's
/// training environment: one actor, so its steps are the run's).
pub struct Recorder {
    env: Box<VectorEnv>,
    out: BufWriter<File>,
    episode: Option<Recorded>,
    episodes: u64,
    steps: u64,
}

impl Recorder {
    /// Continues recording into `dir/transitions.jsonl` from a checkpoint of the run taken after
    /// `episodes` episodes and `steps` steps: the episodes written after it (the run went on
    /// past its checkpoint before it stopped) are taken off the file, which then grows again.
    pub fn resume(env: Box<VectorEnv>, dir: &Path, episodes: u32, steps: u64) -> Result<Self> {
        let path = dir.join(FILE);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let mut kept = String::new();
        for (n, line) in text.lines().enumerate() {
            let keep = n == 0
                || serde_json::from_str::<Recorded>(line)
                    .is_ok_and(|e| e.episode < u64::from(episodes));
            if keep {
                kept.push_str(line);
                kept.push('\n');
            }
        }
        alfd_harness::write_atomically(&path, kept.as_bytes())?;
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .with_context(|| format!("cannot open {}", path.display()))?;
        Ok(Self {
            env,
            out: BufWriter::new(file),
            episode: None,
            episodes: u64::from(episodes),
            steps,
        })
    }

    /// Records `env`'s episodes into `dir/transitions.jsonl` (made new, with its header).
    pub fn create(env: Box<VectorEnv>, dir: &Path, env_name: &str) -> Result<Self> {
        let path = dir.join(FILE);
        let file =
            File::create(&path).with_context(|| format!("cannot create {}", path.display()))?;
        let mut out = BufWriter::new(file);
        let header = Header {
            env: env_name.to_owned(),
            obs_dim: env.observation_dim(),
            num_actions: env.num_actions(),
            max_episode_steps: env.max_episode_steps(),
        };
        serde_json::to_writer(&mut out, &header)?;
        out.write_all(b"\n")?;
        out.flush()?;
        Ok(Self {
            env,
            out,
            episode: None,
            episodes: 0,
            steps: 0,
        })
    }

    fn write(&mut self, e: &Recorded) -> std::io::Result<()> {
        serde_json::to_writer(&mut self.out, e)?;
        self.out.write_all(b"\n")?;
        self.out.flush()
    }
}

impl Env for Recorder {
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
        let obs = self.env.reset(seed);
        self.episode = Some(Recorded {
            episode: self.episodes,
            first_step: self.steps,
            observations: vec![obs.clone()],
            actions: Vec::new(),
            rewards: Vec::new(),
            terminated: false,
            truncated: false,
        });
        obs
    }

    fn step(&mut self, action: usize) -> Result<Step<Vec<f32>>, EnvError> {
        let step = self.env.step(action)?;
        self.steps += 1;
        let Some(e) = self.episode.as_mut() else {
            return Ok(step);
        };
        e.observations.push(step.observation.clone());
        e.actions.push(action);
        e.rewards.push(step.reward);
        if step.done() {
            e.terminated = step.terminated;
            e.truncated = !step.terminated;
            let e = self.episode.take().expect("recorded above");
            self.write(&e)
                .map_err(|err| EnvError::Remote(format!("cannot write {FILE}: {err}")))?;
            self.episodes += 1;
        }
        Ok(step)
    }

    fn snapshot(&self) -> EnvState {
        self.env.snapshot()
    }

    fn restore(&mut self, state: &EnvState) -> Result<(), EnvError> {
        self.env.restore(state)
    }
}

/// The header and episodes of `dir/transitions.jsonl`.
pub fn read(dir: &Path) -> Result<(Header, Vec<Recorded>)> {
    let path = dir.join(FILE);
    let file = File::open(&path).map_err(|e| {
        usage(format!(
            "cannot read {}: {e} (a run records its transitions with `alfd local --transitions`)",
            path.display()
        ))
    })?;
    let mut lines = BufReader::new(file).lines().enumerate();
    let bad = |n: usize, e: &dyn std::fmt::Display| {
        usage(format!("{} line {}: {e}", path.display(), n + 1))
    };
    let header: Header = match lines.next() {
        Some((n, line)) => serde_json::from_str(&line?).map_err(|e| bad(n, &e))?,
        None => return Err(usage(format!("{} is empty", path.display()))),
    };
    let mut episodes = Vec::new();
    for (n, line) in lines {
        let e: Recorded = serde_json::from_str(&line?).map_err(|e| bad(n, &e))?;
        let consistent = e.observations.len() == e.actions.len() + 1
            && e.rewards.len() == e.actions.len()
            && e.observations.iter().all(|o| o.len() == header.obs_dim)
            && e.actions.iter().all(|&a| a < header.num_actions);
        if !consistent {
            return Err(bad(
                n,
                &"an episode whose lengths or values disagree with the header",
            ));
        }
        episodes.push(e);
    }
    Ok((header, episodes))
}

/// A Minari dataset `id` of recorded episodes, each step marked demonstrated when `demos` has
/// a demonstration asked at that step of the run.
pub fn dataset(
    header: &Header,
    episodes: Vec<Recorded>,
    demos: &[DemoRecord],
    id: &str,
) -> Dataset {
    let asked: std::collections::HashSet<u64> = demos.iter().map(|d| d.step).collect();
    let episodes = episodes
        .into_iter()
        .map(|e| {
            let steps = e.actions.len();
            let last = |flag: bool| (0..steps).map(|t| flag && t + 1 == steps).collect();
            Episode {
                demonstrated: Some(
                    (0..steps as u64)
                        .map(|t| asked.contains(&(e.first_step + t)))
                        .collect(),
                ),
                terminations: last(e.terminated),
                truncations: last(e.truncated),
                observations: e.observations,
                actions: e.actions,
                rewards: e.rewards,
            }
        })
        .collect();
    Dataset {
        id: id.to_owned(),
        obs_dim: header.obs_dim,
        num_actions: header.num_actions,
        episodes,
        algorithm: "alfd (active learning from demonstrations)".to_owned(),
        env_spec: crate::minari::gym_env_spec(&header.env, header.max_episode_steps),
    }
}

/// The expert steps of a Minari dataset for a run whose environment has `obs_dim` values and
/// `num_actions` actions: every step, or the steps it marks demonstrated when it marks them.
pub fn prior_demos(ds: &Dataset, obs_dim: usize, num_actions: usize) -> Result<Vec<PriorDemo>> {
    if ds.obs_dim != obs_dim || ds.num_actions != num_actions {
        return Err(usage(format!(
            "dataset {}: observations of {} values and {} actions; the config's environment has \
             {obs_dim} and {num_actions}",
            ds.id, ds.obs_dim, ds.num_actions
        )));
    }
    let mut out = Vec::new();
    for e in &ds.episodes {
        for t in 0..e.steps() {
            if e.demonstrated.as_ref().is_some_and(|m| !m[t]) {
                continue;
            }
            out.push(PriorDemo {
                state: e.observations[t].clone(),
                action: e.actions[t],
                reward: e.rewards[t],
                next_state: e.observations[t + 1].clone(),
                terminated: e.terminations[t],
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use alfd_common::config::EnvName;

    #[test]
    fn a_recorded_run_becomes_a_dataset_with_its_demonstrations_marked() {
        let dir = tempfile::tempdir().unwrap();
        let env = alfd_common::env::vector_env_named(EnvName::Cartpole, 30).unwrap();
        let mut rec = Recorder::create(env, dir.path(), "cartpole").unwrap();
        let mut played = Vec::new();
        for ep in 0..3u64 {
            let mut obs = vec![rec.reset(Some(ep))];
            let mut t = 0;
            loop {
                let s = rec.step(t % 2).unwrap();
                obs.push(s.observation.clone());
                t += 1;
                if s.done() {
                    played.push((obs, s.terminated));
                    break;
                }
            }
        }
        // An episode cut short (the run's step limit) is not written.
        rec.reset(None);
        rec.step(0).unwrap();
        drop(rec);
        let (header, episodes) = read(dir.path()).unwrap();
        assert_eq!(
            (header.obs_dim, header.num_actions, header.max_episode_steps),
            (4, 2, 30)
        );
        assert_eq!(episodes.len(), 3);
        let mut first = 0;
        for (e, (obs, terminated)) in episodes.iter().zip(&played) {
            assert_eq!((&e.observations, e.terminated), (obs, *terminated));
            assert_eq!(e.first_step, first);
            first += e.actions.len() as u64;
        }
        let demo = |step| DemoRecord {
            index: 0,
            state: vec![],
            action: 0,
            step,
            expert: "e".into(),
            weight: 1.0,
        };
        let second = episodes[1].first_step;
        let ds = dataset(
            &header,
            episodes.clone(),
            &[demo(1), demo(second)],
            "alfd/t-v0",
        );
        let marks = |i: usize| ds.episodes[i].demonstrated.clone().unwrap();
        assert_eq!(marks(0).iter().filter(|&&m| m).count(), 1);
        assert!(marks(0)[1] && marks(1)[0] && !marks(2).contains(&true));
        // As a prior: the marked steps only, with their transitions.
        let prior = prior_demos(&ds, 4, 2).unwrap();
        assert_eq!(prior.len(), 2);
        assert_eq!(prior[1].state, episodes[1].observations[0]);
        assert_eq!(prior[1].next_state, episodes[1].observations[1]);
        assert_eq!(prior[1].action, episodes[1].actions[0]);
        let e = prior_demos(&ds, 6, 3).unwrap_err();
        assert_eq!(alfd_harness::exit_code(&e), 2);
        assert!(e.to_string().contains("6 and 3"), "{e}");
    }
}
