//! Minari datasets in the `arrow` data format, read and written (the format of the `minari`
//! Python package, 0.4-0.5): a dataset directory holds `data/metadata.json` (the dataset's
//! metadata, its spaces as JSON strings) and one directory per episode, `data/<id>/`, with the
//! episode's `metadata.json` and one Arrow IPC file of one record batch. The batch's columns:
//! `observations` (a fixed-size list per row: the reset observation, then one per step),
//! `actions`, `rewards`, `terminations`, `truncations` (one per step, then one padding row), and
//! optionally `infos`, a struct of one row per observation.
//!
//! alfd writes one field in `infos`: `demonstrated`, true in row t + 1 when the action of step t
//! came from the expert (row 0 is the reset's). Only Box observations of one dimension and
//! Discrete actions are read and written: the spaces of the neural agents' environments.

use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use crate::error::{usage, Context, Result};

#[cfg(feature = "minari")]
mod arrow_io;
#[cfg(feature = "minari")]
use arrow_io::{read_episode, write_episode};

/// Whether this build reads and writes the Arrow files (the `minari` feature); exit 2 saying
/// how to build it when not (as `deploy/run.sh` builds the main job).
fn available() -> Result<()> {
    if cfg!(feature = "minari") {
        Ok(())
    } else {
        Err(without_minari())
    }
}

fn without_minari() -> crate::error::LabError {
    usage(
        "Minari datasets need the `minari` feature, and this alfd was built without it (as \
         deploy/run.sh builds the main job): build every feature with \
         `cargo build --release --workspace`",
    )
}

#[cfg(not(feature = "minari"))]
fn read_episode(_: &Path, _: usize, _: usize) -> Result<Episode> {
    Err(without_minari())
}

#[cfg(not(feature = "minari"))]
fn write_episode(_: &Path, _: usize, _: &Episode, _: usize) -> Result<u64> {
    Err(without_minari())
}

/// The `minari` version whose format the written datasets follow (`minari_version`).
pub const MINARI_VERSION: &str = "0.5.3";

/// The versions of `minari` whose datasets are read (their `arrow` format is this one).
const READ_VERSIONS: [&str; 8] = [
    "0.4.0", "0.4.1", "0.4.2", "0.4.3", "0.5.0", "0.5.1", "0.5.2", "0.5.3",
];

/// One episode: `observations` has one more row than the steps.
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    pub observations: Vec<Vec<f32>>,
    pub actions: Vec<usize>,
    pub rewards: Vec<f64>,
    pub terminations: Vec<bool>,
    pub truncations: Vec<bool>,
    /// Per step: the action came from the expert (`None`: the dataset does not say).
    pub demonstrated: Option<Vec<bool>>,
}

impl Episode {
    pub fn steps(&self) -> usize {
        self.actions.len()
    }
}

/// A dataset of episodes of one environment.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Minari's id, `namespace/name-vN`.
    pub id: String,
    pub obs_dim: usize,
    pub num_actions: usize,
    pub episodes: Vec<Episode>,
    /// Written to the metadata as `algorithm_name`.
    pub algorithm: String,
    /// Gymnasium's `EnvSpec` of the environment as JSON (`env_spec`: what
    /// `recover_environment` makes), when the environment is one of Gymnasium's.
    pub env_spec: Option<String>,
}

impl Dataset {
    pub fn total_steps(&self) -> usize {
        self.episodes.iter().map(Episode::steps).sum()
    }
}

/// Whether `id` has Minari's form `namespace/name-vN` (the namespace optional).
pub fn valid_id(id: &str) -> bool {
    // The namespace may have parts of its own (`D4RL/door`).
    let name = id.rsplit_once('/').map_or(id, |(ns, name)| {
        let part_ok = |p: &str| !p.is_empty() && p.chars().all(id_char);
        if ns.split('/').all(part_ok) {
            name
        } else {
            ""
        }
    });
    let Some((stem, version)) = name.rsplit_once("-v") else {
        return false;
    };
    !stem.is_empty()
        && stem.chars().all(id_char)
        && !version.is_empty()
        && version.bytes().all(|b| b.is_ascii_digit())
}

fn id_char(c: char) -> bool {
    c.is_alphanumeric() || matches!(c, '_' | ':' | '.' | '-')
}

/// The directory holding `metadata.json`: `dir/data` (a dataset's directory, as Minari keeps
/// it under its root), or `dir` itself.
fn data_dir(dir: &Path) -> PathBuf {
    let nested = dir.join("data");
    if nested.join("metadata.json").is_file() {
        nested
    } else {
        dir.to_path_buf()
    }
}

/// Reads the Minari dataset in `dir` (the dataset's directory, or its `data` directory).
pub fn read(dir: &Path) -> Result<Dataset> {
    available()?;
    let data = data_dir(dir);
    let meta_path = data.join("metadata.json");
    let text = std::fs::read_to_string(&meta_path).map_err(|e| {
        usage(format!(
            "{} is not a Minari dataset: cannot read {}: {e}",
            dir.display(),
            meta_path.display()
        ))
    })?;
    let meta: Value = serde_json::from_str(&text)
        .map_err(|e| usage(format!("{}: not JSON: {e}", meta_path.display())))?;
    let bad = |what: String| usage(format!("{}: {what}", meta_path.display()));
    let format = meta["data_format"].as_str().unwrap_or("?");
    if format != "arrow" {
        return Err(bad(format!(
            "data_format is \"{format}\": only \"arrow\" datasets are read (convert one with \
             minari: `minari.create_dataset_from_buffers(..., data_format=\"arrow\")`)"
        )));
    }
    let version = meta["minari_version"].as_str().unwrap_or("?");
    if !READ_VERSIONS.contains(&version) {
        return Err(bad(format!(
            "minari_version \"{version}\" is not one of {READ_VERSIONS:?}"
        )));
    }
    let obs_dim = box_dim(&meta["observation_space"]).map_err(&bad)?;
    let num_actions = discrete_n(&meta["action_space"]).map_err(&bad)?;
    let total = meta["total_episodes"]
        .as_u64()
        .ok_or_else(|| bad("total_episodes is missing".into()))?;
    let episodes = (0..total)
        .map(|i| read_episode(&data.join(i.to_string()), obs_dim, num_actions))
        .collect::<Result<Vec<_>>>()?;
    Ok(Dataset {
        id: meta["dataset_id"].as_str().unwrap_or("").to_owned(),
        obs_dim,
        num_actions,
        episodes,
        algorithm: meta["algorithm_name"].as_str().unwrap_or("").to_owned(),
        env_spec: meta["env_spec"].as_str().map(str::to_owned),
    })
}

/// A space as the metadata holds it: a JSON string (as Minari writes it) or an object.
fn space(v: &Value) -> std::result::Result<Value, String> {
    match v {
        Value::String(s) => serde_json::from_str(&python_json(s))
            .map_err(|e| format!("a space that is not JSON ({e}): {s}")),
        Value::Object(_) => Ok(v.clone()),
        _ => Err("a space is missing (observation_space, action_space)".into()),
    }
}

/// Python's `json` writes ±∞ as `Infinity`/`-Infinity`, which JSON does not have: as numbers
/// too large for an `f64`, they read back as ±∞... but `serde_json` refuses those, so they
/// become ±1e308 (only the shape of a Box is read here, never its bounds).
fn python_json(s: &str) -> String {
    s.replace("-Infinity", "-1e308")
        .replace("Infinity", "1e308")
        .replace("NaN", "0")
}

/// The dimension of a one-dimensional Box space.
fn box_dim(v: &Value) -> std::result::Result<usize, String> {
    let s = space(v)?;
    let shape = s["shape"].as_array();
    match (s["type"].as_str(), shape.map(Vec::as_slice)) {
        (Some("Box"), Some([n])) => n
            .as_u64()
            .filter(|&n| n > 0)
            .map(|n| n as usize)
            .ok_or_else(|| format!("a Box of shape {n}")),
        _ => Err(format!(
            "the observation space is {s}: only a one-dimensional Box is read"
        )),
    }
}

/// The actions of a Discrete space starting at 0.
fn discrete_n(v: &Value) -> std::result::Result<usize, String> {
    let s = space(v)?;
    let start = s["start"].as_i64().unwrap_or(0);
    match (s["type"].as_str(), s["n"].as_u64()) {
        (Some("Discrete"), Some(n)) if n > 0 && start == 0 => Ok(n as usize),
        _ => Err(format!(
            "the action space is {s}: only a Discrete space starting at 0 is read"
        )),
    }
}

/// Writes `ds` as a Minari dataset in `dir` (it must not hold one): `dir/data/...`, so that with
/// `dir` = `<root>/<id>`, `minari.load_dataset(id)` finds it under `MINARI_DATASETS_PATH=<root>`.
pub fn write(dir: &Path, ds: &Dataset) -> Result<()> {
    available()?;
    if !valid_id(&ds.id) {
        return Err(usage(format!(
            "dataset id `{}` is not of Minari's form NAMESPACE/NAME-vN (e.g. alfd/cartpole-v0)",
            ds.id
        )));
    }
    let data = dir.join("data");
    if data.join("metadata.json").exists() {
        return Err(usage(format!(
            "{} holds a dataset already: choose another directory",
            dir.display()
        )));
    }
    std::fs::create_dir_all(&data).with_context(|| format!("cannot create {}", data.display()))?;
    let mut bytes = 0u64;
    for (i, ep) in ds.episodes.iter().enumerate() {
        bytes += write_episode(&data.join(i.to_string()), i, ep, ds.obs_dim)?;
    }
    let box_space = format!(
        "{{\"type\": \"Box\", \"dtype\": \"float32\", \"shape\": [{d}], \"low\": [{lo}], \
         \"high\": [{hi}]}}",
        d = ds.obs_dim,
        lo = vec!["-Infinity"; ds.obs_dim].join(", "),
        hi = vec!["Infinity"; ds.obs_dim].join(", "),
    );
    let discrete = json!({"type": "Discrete", "dtype": "int64", "start": 0, "n": ds.num_actions});
    let mut meta = json!({
        "dataset_id": ds.id,
        "minari_version": MINARI_VERSION,
        "data_format": "arrow",
        "jpeg_encoding": false,
        "total_episodes": ds.episodes.len(),
        "total_steps": ds.total_steps(),
        "dataset_size": (bytes as f64 / 1e6 * 1000.0).round() / 1000.0,
        "observation_space": box_space,
        "action_space": discrete.to_string(),
        "algorithm_name": ds.algorithm,
        "author": ["alfd"],
    });
    if let Some(spec) = &ds.env_spec {
        meta["env_spec"] = Value::String(spec.clone());
    }
    let path = data.join("metadata.json");
    std::fs::write(&path, serde_json::to_string(&meta)?)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Gymnasium's `EnvSpec` as JSON (`EnvSpec.to_json()` of gymnasium 1.4) for alfd's environment
/// `name` with episodes of at most `max_episode_steps`, if it is one of Gymnasium's.
pub fn gym_env_spec(name: &str, max_episode_steps: usize) -> Option<String> {
    let (id, module, class, threshold) = match name {
        "cartpole" => ("CartPole-v1", "cartpole", "CartPole", "475.0"),
        "mountaincar" => ("MountainCar-v0", "mountain_car", "MountainCar", "-110.0"),
        "acrobot" => ("Acrobot-v1", "acrobot", "Acrobot", "-100.0"),
        _ => return None,
    };
    let entry = format!("gymnasium.envs.classic_control.{module}:{class}");
    // Gymnasium's own specs name a vector entry point for CartPole only.
    let vector = match name {
        "cartpole" => format!("\"{entry}VectorEnv\""),
        _ => "null".to_owned(),
    };
    Some(format!(
        "{{\"id\": \"{id}\", \"entry_point\": \"{entry}Env\", \"reward_threshold\": {threshold}, \
         \"nondeterministic\": false, \"max_episode_steps\": {max_episode_steps}, \
         \"order_enforce\": true, \"disable_env_checker\": false, \"kwargs\": {{}}, \
         \"additional_wrappers\": [], \"vector_entry_point\": {vector}}}"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn episode(steps: usize, marks: bool) -> Episode {
        Episode {
            observations: (0..=steps)
                .map(|t| vec![t as f32, -0.5 * t as f32, 1e-3, 7.25])
                .collect(),
            actions: (0..steps).map(|t| t % 2).collect(),
            rewards: vec![1.0; steps],
            terminations: (0..steps).map(|t| t + 1 == steps).collect(),
            truncations: vec![false; steps],
            demonstrated: marks.then(|| (0..steps).map(|t| t % 3 == 0).collect()),
        }
    }

    #[test]
    fn a_written_dataset_reads_back_the_same() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset {
            id: "alfd/cartpole-test-v0".into(),
            obs_dim: 4,
            num_actions: 2,
            episodes: vec![episode(5, true), episode(1, true), episode(9, true)],
            algorithm: "alfd".into(),
            env_spec: Some(gym_env_spec("cartpole", 200).unwrap()),
        };
        write(dir.path(), &ds).unwrap();
        assert!(dir.path().join("data/2/part-0.arrow").is_file());
        assert_eq!(read(dir.path()).unwrap(), ds);
        assert_eq!(read(&dir.path().join("data")).unwrap(), ds);
        // A second export into the same directory is refused, and nothing is overwritten.
        let again = write(dir.path(), &ds).unwrap_err();
        assert_eq!(alfd_harness::exit_code(&again), 2);
        assert!(again.to_string().contains("holds a dataset already"));
    }

    #[test]
    fn minari_ids_are_checked() {
        for ok in [
            "alfd/cartpole-v0",
            "cartpole-v12",
            "D4RL/door/human-v1",
            "a.b:c/x_y-v3",
        ] {
            assert!(valid_id(ok), "{ok}");
        }
        for bad in [
            "cartpole",
            "alfd/cartpole",
            "alfd/-v0",
            "/x-v0",
            "x-v",
            "x-v1a",
            "a b-v0",
        ] {
            assert!(!valid_id(bad), "{bad}");
        }
    }

    #[test]
    fn what_is_not_a_readable_dataset_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let e = read(dir.path()).unwrap_err();
        assert_eq!(alfd_harness::exit_code(&e), 2);
        assert!(e.to_string().contains("is not a Minari dataset"), "{e}");
        let meta = |m: Value| std::fs::write(dir.path().join("metadata.json"), m.to_string());
        meta(json!({"data_format": "hdf5", "minari_version": "0.5.3"})).unwrap();
        assert!(read(dir.path())
            .unwrap_err()
            .to_string()
            .contains("only \"arrow\""));
        let image =
            r#"{"type": "Box", "dtype": "uint8", "shape": [84, 84, 3], "low": 0, "high": 255}"#;
        meta(json!({"data_format": "arrow", "minari_version": "0.5.3",
            "observation_space": image, "action_space": r#"{"type": "Discrete", "n": 2}"#}))
        .unwrap();
        let e = read(dir.path()).unwrap_err().to_string();
        assert!(e.contains("only a one-dimensional Box"), "{e}");
        meta(json!({"data_format": "arrow", "minari_version": "0.3.0"})).unwrap();
        assert!(read(dir.path())
            .unwrap_err()
            .to_string()
            .contains("minari_version"));
    }
}
