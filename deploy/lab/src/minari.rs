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

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::builder::{BooleanBuilder, FixedSizeListBuilder, Float32Builder};
use arrow_array::cast::AsArray;
use arrow_array::{
    Array, ArrayRef, BooleanArray, FixedSizeListArray, Float32Array, Float64Array, Int64Array,
    RecordBatch, StructArray,
};
use arrow_schema::{DataType, Field, Fields, Schema};
use serde_json::{json, Value};

use crate::error::{usage, Context, Result};

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

/// The one record batch of the Arrow files in an episode's directory.
fn read_batch(dir: &Path) -> Result<RecordBatch> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| usage(format!("episode directory {}: {e}", dir.display())))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
            name.is_some_and(|n| !n.starts_with(['_', '.']) && n != "metadata.json")
        })
        .collect();
    files.sort();
    let bad = |what: String| usage(format!("{}: {what}", dir.display()));
    let [file] = files.as_slice() else {
        return Err(bad(format!("{} data files, not one", files.len())));
    };
    let reader = arrow_ipc::reader::FileReader::try_new(File::open(file)?, None)
        .map_err(|e| bad(format!("{}: not an Arrow IPC file: {e}", file.display())))?;
    let batches: Vec<RecordBatch> = reader
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| bad(format!("{}: {e}", file.display())))?;
    match <[RecordBatch; 1]>::try_from(batches) {
        Ok([batch]) => Ok(batch),
        Err(b) => Err(bad(format!("{} record batches, not one", b.len()))),
    }
}

fn read_episode(dir: &Path, obs_dim: usize, num_actions: usize) -> Result<Episode> {
    let batch = read_batch(dir)?;
    let bad = |what: String| usage(format!("{}: {what}", dir.display()));
    let column = |name: &str| {
        batch
            .column_by_name(name)
            .cloned()
            .ok_or_else(|| bad(format!("no column `{name}`")))
    };
    let rows = batch.num_rows();
    if rows == 0 {
        return Err(bad("an episode without its reset observation".into()));
    }
    let steps = rows - 1;
    let observations = observations(&column("observations")?, obs_dim).map_err(&bad)?;
    let actions = ints(&column("actions")?, steps)
        .map_err(&bad)?
        .into_iter()
        .map(|a| {
            usize::try_from(a)
                .ok()
                .filter(|&a| a < num_actions)
                .ok_or_else(|| bad(format!("action {a} outside 0..{num_actions}")))
        })
        .collect::<Result<Vec<_>>>()?;
    let rewards = floats(&column("rewards")?, steps).map_err(&bad)?;
    let terminations = bools(&column("terminations")?, steps).map_err(&bad)?;
    let truncations = bools(&column("truncations")?, steps).map_err(&bad)?;
    let demonstrated = match batch.column_by_name("infos") {
        Some(infos) => demonstrated(infos, steps).map_err(&bad)?,
        None => None,
    };
    Ok(Episode {
        observations,
        actions,
        rewards,
        terminations,
        truncations,
        demonstrated,
    })
}

fn observations(col: &ArrayRef, dim: usize) -> std::result::Result<Vec<Vec<f32>>, String> {
    let list = col
        .as_any()
        .downcast_ref::<FixedSizeListArray>()
        .ok_or_else(|| format!("observations are {}, not a list", col.data_type()))?;
    if list.value_length() as usize != dim {
        return Err(format!(
            "observations of {} values, the observation space has {dim}",
            list.value_length()
        ));
    }
    let values = list.values();
    let flat: Vec<f32> = if let Some(v) = values.as_any().downcast_ref::<Float32Array>() {
        v.values().to_vec()
    } else if let Some(v) = values.as_any().downcast_ref::<Float64Array>() {
        v.values().iter().map(|&x| x as f32).collect()
    } else {
        return Err(format!(
            "observations of {}, not floats",
            values.data_type()
        ));
    };
    let start = list.offset() * dim;
    Ok(flat[start..start + list.len() * dim]
        .chunks(dim)
        .map(<[f32]>::to_vec)
        .collect())
}

/// The first `n` values of a primitive column whose type is one of `$t` (`DataType` variant,
/// arrow type), as `$out`.
macro_rules! first_n {
    ($col:expr, $n:expr, $out:ty, $what:literal, [$($t:ident => $ty:ty),*]) => {{
        let col: &ArrayRef = $col;
        if col.len() < $n || col.slice(0, $n).null_count() > 0 {
            return Err(format!("{} short of {} values, or null", $what, $n));
        }
        match col.data_type() {
            $(DataType::$t => Ok(col.as_primitive::<$ty>().values()[..$n]
                .iter()
                .map(|&x| x as $out)
                .collect()),)*
            t => Err(format!("{} of {t}", $what)),
        }
    }};
}

/// The first `n` values of an integer column.
fn ints(col: &ArrayRef, n: usize) -> std::result::Result<Vec<i64>, String> {
    use arrow_array::types::*;
    first_n!(col, n, i64, "actions", [
        Int64 => Int64Type, Int32 => Int32Type, Int16 => Int16Type, Int8 => Int8Type,
        UInt64 => UInt64Type, UInt32 => UInt32Type, UInt16 => UInt16Type, UInt8 => UInt8Type
    ])
}

/// The first `n` values of a float column.
fn floats(col: &ArrayRef, n: usize) -> std::result::Result<Vec<f64>, String> {
    use arrow_array::types::*;
    first_n!(col, n, f64, "rewards", [Float64 => Float64Type, Float32 => Float32Type])
}

/// The first `n` values of a boolean column.
fn bools(col: &ArrayRef, n: usize) -> std::result::Result<Vec<bool>, String> {
    let v = col
        .as_any()
        .downcast_ref::<BooleanArray>()
        .ok_or_else(|| format!("a column of {}, not booleans", col.data_type()))?;
    if v.len() < n {
        return Err(format!("a column of {} booleans, not {n}", v.len()));
    }
    Ok((0..n).map(|i| v.value(i)).collect())
}

/// `infos.demonstrated`, row t + 1 for step t, if the infos have it.
fn demonstrated(infos: &ArrayRef, steps: usize) -> std::result::Result<Option<Vec<bool>>, String> {
    let Some(s) = infos.as_any().downcast_ref::<StructArray>() else {
        return Ok(None);
    };
    let Some(col) = s.column_by_name("demonstrated") else {
        return Ok(None);
    };
    let all = bools(col, steps + 1)?;
    Ok(Some(all[1..].to_vec()))
}

/// Writes `ds` as a Minari dataset in `dir` (it must not hold one): `dir/data/...`, so that with
/// `dir` = `<root>/<id>`, `minari.load_dataset(id)` finds it under `MINARI_DATASETS_PATH=<root>`.
pub fn write(dir: &Path, ds: &Dataset) -> Result<()> {
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

/// One episode's directory; the bytes of its data file.
fn write_episode(dir: &Path, id: usize, ep: &Episode, dim: usize) -> Result<u64> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let batch = episode_batch(ep, dim)?;
    let path = dir.join("part-0.arrow");
    let file = File::create(&path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = arrow_ipc::writer::FileWriter::try_new(file, &batch.schema())
        .with_context(|| format!("cannot write {}", path.display()))?;
    w.write(&batch)
        .and_then(|()| w.finish())
        .with_context(|| format!("cannot write {}", path.display()))?;
    let meta = json!({"id": id, "total_steps": ep.steps()});
    std::fs::write(dir.join("metadata.json"), meta.to_string())?;
    Ok(std::fs::metadata(&path)?.len())
}

/// The record batch of an episode: step columns padded by one row, as Minari pads them.
fn episode_batch(ep: &Episode, dim: usize) -> Result<RecordBatch> {
    let rows = ep.observations.len();
    crate::error::ensure!(
        rows == ep.steps() + 1,
        "an episode of {} steps has {rows} observations",
        ep.steps()
    );
    let mut obs = FixedSizeListBuilder::new(Float32Builder::new(), dim as i32);
    for o in &ep.observations {
        crate::error::ensure!(o.len() == dim, "an observation of {} values", o.len());
        obs.values().append_slice(o);
        obs.append(true);
    }
    let padded = |v: &[bool]| BooleanArray::from([v, &[false]].concat());
    let actions: Vec<i64> = ep.actions.iter().map(|&a| a as i64).chain([0]).collect();
    let rewards: Vec<f64> = ep.rewards.iter().copied().chain([0.0]).collect();
    let mut columns: Vec<(&str, ArrayRef)> = vec![
        ("observations", Arc::new(obs.finish())),
        ("actions", Arc::new(Int64Array::from(actions))),
        ("rewards", Arc::new(Float64Array::from(rewards))),
        ("terminations", Arc::new(padded(&ep.terminations))),
        ("truncations", Arc::new(padded(&ep.truncations))),
    ];
    if let Some(marks) = &ep.demonstrated {
        let mut b = BooleanBuilder::new();
        b.append_value(false);
        b.append_slice(marks);
        let field = Field::new("demonstrated", DataType::Boolean, true);
        let infos = StructArray::new(
            Fields::from(vec![field]),
            vec![Arc::new(b.finish()) as ArrayRef],
            None,
        );
        columns.push(("infos", Arc::new(infos)));
    }
    let schema = Schema::new(
        columns
            .iter()
            .map(|(name, a)| Field::new(*name, a.data_type().clone(), true))
            .collect::<Vec<_>>(),
    );
    let arrays = columns.into_iter().map(|(_, a)| a).collect();
    RecordBatch::try_new(Arc::new(schema), arrays).context("an episode's record batch")
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
