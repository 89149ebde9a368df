//! The Arrow IPC files of a Minari dataset's episodes, read and written (the `minari` feature:
//! `arrow-array`, `arrow-schema`, `arrow-ipc`).

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
use serde_json::json;

use super::Episode;
use crate::error::{usage, Context, Result};

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

pub(super) fn read_episode(dir: &Path, obs_dim: usize, num_actions: usize) -> Result<Episode> {
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

/// One episode's directory; the bytes of its data file.
pub(super) fn write_episode(dir: &Path, id: usize, ep: &Episode, dim: usize) -> Result<u64> {
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
