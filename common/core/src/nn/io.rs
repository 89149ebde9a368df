//! Network checkpoints as safetensors bytes, in PyTorch's `nn.Linear` layout and names, so that a
//! PyTorch user can `load_state_dict(safetensors.torch.load_file(path))`. Bytes in, bytes out: the
//! caller does the file I/O.
//!
//! The file holds the six tensors of [`PARAM_NAMES`] as F32 with their PyTorch shapes, and the
//! metadata `heads`, `actions` and `format_version` (decimal strings); a network with a
//! randomized prior function adds `prior_scale` and `prior_seed`, from which the prior is drawn
//! again on reading (a PyTorch reader gets the trained part only); a network whose heads have
//! separate torsos adds `torsos` (K), its `torso.1` and `heads` weights block-diagonal. The header is written
//! here with sorted keys so that the same network always gives the same bytes; reading goes
//! through the `safetensors` crate, which validates the container.

use std::collections::{BTreeMap, HashMap};

use safetensors::{Dtype, SafeTensors};
use serde::Serialize;

use super::{torch_shapes, Mlp, NnError, Params, Result, PARAM_NAMES};

/// The version of the checkpoint layout, stored in the metadata as `format_version`.
pub const FORMAT_VERSION: &str = "1";

#[derive(Serialize)]
struct TensorInfo {
    dtype: &'static str,
    shape: Vec<usize>,
    data_offsets: [usize; 2],
}

#[derive(Serialize)]
#[serde(untagged)]
enum HeaderEntry {
    Metadata(BTreeMap<&'static str, String>),
    Tensor(TensorInfo),
}

impl Mlp {
    /// The network as a safetensors file (see the module docs). Deterministic: the same network
    /// gives the same bytes.
    pub fn to_safetensors_bytes(&self) -> Vec<u8> {
        let shapes = self.params.shapes();
        let tensors = self.params.tensors();
        let mut header: BTreeMap<&'static str, HeaderEntry> = BTreeMap::new();
        let mut metadata = BTreeMap::from([
            ("heads", self.heads().to_string()),
            ("actions", self.actions().to_string()),
            ("format_version", FORMAT_VERSION.to_string()),
        ]);
        if self.torsos() > 1 {
            metadata.insert("torsos", self.torsos().to_string());
        }
        if let Some(prior) = self.prior() {
            metadata.insert("prior_scale", prior.scale().to_string());
            metadata.insert("prior_seed", prior.seed().to_string());
        }
        header.insert("__metadata__", HeaderEntry::Metadata(metadata));
        let mut offset = 0;
        for ((name, shape), data) in PARAM_NAMES.iter().zip(shapes).zip(tensors) {
            let n = data.len() * 4;
            header.insert(
                name,
                HeaderEntry::Tensor(TensorInfo {
                    dtype: "F32",
                    shape,
                    data_offsets: [offset, offset + n],
                }),
            );
            offset += n;
        }
        let mut json = serde_json::to_vec(&header)
            .expect("a map of strings, integers and string maps always serialises");
        // The format pads the header with spaces so that the data starts 8-byte aligned.
        json.resize(json.len().next_multiple_of(8), b' ');
        let mut out = Vec::with_capacity(8 + json.len() + offset);
        out.extend_from_slice(&(json.len() as u64).to_le_bytes());
        out.extend_from_slice(&json);
        for data in tensors {
            for v in data {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    /// Reads a network written by [`Mlp::to_safetensors_bytes`] (or by PyTorch with the same
    /// names and metadata). Every problem is an error naming the tensor or metadata key at fault:
    /// a damaged container, a missing or unexpected tensor, a dtype other than F32, a shape that
    /// does not fit, missing or bad metadata.
    pub fn from_safetensors_bytes(bytes: &[u8]) -> Result<Mlp> {
        let (_, header) = SafeTensors::read_metadata(bytes)?;
        let file = SafeTensors::deserialize(bytes)?;
        let meta = header.metadata().as_ref();
        check_format_version(meta)?;
        let heads = read_count(meta, "heads")?;
        let actions = read_count(meta, "actions")?;
        let prior = read_prior(meta)?;

        if let Some(name) = file.names().into_iter().find(|n| !PARAM_NAMES.contains(n)) {
            return Err(NnError::UnexpectedTensor(name.to_string()));
        }
        let data = PARAM_NAMES
            .iter()
            .map(|name| read_f32_tensor(&file, name))
            .collect::<Result<Vec<_>>>()?;
        // torso.0.weight is [hidden, obs_dim]; every other shape follows from it and K * A.
        let (hidden, obs_dim) = match data[0].0[..] {
            [h, d] => (h, d),
            _ => {
                return Err(NnError::Dims(format!(
                    "tensor `{}` has shape {:?}, expected two dimensions [hidden, obs_dim]",
                    PARAM_NAMES[0], data[0].0
                )))
            }
        };
        if heads == 0 || actions == 0 || hidden == 0 || obs_dim == 0 {
            return Err(NnError::Dims(format!(
                "obs_dim {obs_dim}, hidden {hidden}, heads {heads}, actions {actions} must all be positive"
            )));
        }
        // The metadata is the file's word: K * A may not fit (a fuzzed file once overflowed here).
        let outputs = heads
            .checked_mul(actions)
            .ok_or_else(|| NnError::Metadata {
                key: "heads".to_string(),
                reason: format!("heads {heads} times actions {actions} does not fit in memory"),
            })?;
        let expected = torch_shapes(obs_dim, hidden, outputs);
        for ((name, (shape, _)), e) in PARAM_NAMES.iter().zip(&data).zip(&expected) {
            if shape != e {
                return Err(NnError::Shape {
                    name: (*name).to_string(),
                    expected: e.clone(),
                    found: shape.clone(),
                });
            }
        }
        let mut params = Params::zeros(obs_dim, hidden, outputs);
        for (dst, (_, src)) in params.tensors_mut().into_iter().zip(&data) {
            dst.copy_from_slice(src);
        }
        let torsos = match meta.and_then(|m| m.get("torsos")) {
            Some(_) => read_count(meta, "torsos")?,
            None => 1,
        };
        let net = Mlp::from_params(params, heads, actions)?
            .with_torsos(torsos)
            .map_err(|e| NnError::Metadata {
                key: "torsos".to_string(),
                reason: e.to_string(),
            })?;
        Ok(match prior {
            Some((scale, seed)) => net.with_prior(scale, seed),
            None => net,
        })
    }
}

/// The file's `format_version`, refused unless it is [`FORMAT_VERSION`].
fn check_format_version(meta: Option<&HashMap<String, String>>) -> Result<()> {
    let version = meta
        .and_then(|m| m.get("format_version"))
        .ok_or_else(|| NnError::Metadata {
            key: "format_version".to_string(),
            reason: "missing".to_string(),
        })?;
    if version != FORMAT_VERSION {
        return Err(NnError::Metadata {
            key: "format_version".to_string(),
            reason: format!("version `{version}` is not supported (expected {FORMAT_VERSION})"),
        });
    }
    Ok(())
}

/// The metadata `key` as a count (a non-negative integer).
fn read_count(meta: Option<&HashMap<String, String>>, key: &str) -> Result<usize> {
    let value = meta
        .and_then(|m| m.get(key))
        .ok_or_else(|| NnError::Metadata {
            key: key.to_string(),
            reason: "missing".to_string(),
        })?;
    value.parse::<usize>().map_err(|e| NnError::Metadata {
        key: key.to_string(),
        reason: format!("`{value}` is not a non-negative integer: {e}"),
    })
}

/// The shape and values of the F32 tensor `name` of `file`.
fn read_f32_tensor(file: &SafeTensors<'_>, name: &str) -> Result<(Vec<usize>, Vec<f32>)> {
    let view = file
        .tensor(name)
        .map_err(|_| NnError::MissingTensor(name.to_string()))?;
    if view.dtype() != Dtype::F32 {
        return Err(NnError::Dtype {
            name: name.to_string(),
            found: format!("{:?}", view.dtype()),
        });
    }
    let values = view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok((view.shape().to_vec(), values))
}

/// `prior_scale` and `prior_seed`, both or neither.
fn read_prior(meta: Option<&HashMap<String, String>>) -> Result<Option<(f32, u64)>> {
    let get = |key: &str| meta.and_then(|m| m.get(key));
    let bad = |key: &str, reason: String| NnError::Metadata {
        key: key.to_owned(),
        reason,
    };
    match (get("prior_scale"), get("prior_seed")) {
        (None, None) => Ok(None),
        (Some(scale), Some(seed)) => {
            let s: f32 = scale
                .parse()
                .ok()
                .filter(|s: &f32| s.is_finite())
                .ok_or_else(|| bad("prior_scale", format!("`{scale}` is not a finite number")))?;
            let n: u64 = seed
                .parse()
                .map_err(|e| bad("prior_seed", format!("`{seed}` is not a seed: {e}")))?;
            Ok(Some((s, n)))
        }
        (Some(_), None) => Err(bad("prior_seed", "missing (prior_scale is given)".into())),
        (None, Some(_)) => Err(bad("prior_scale", "missing (prior_seed is given)".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_deterministic_and_aligned() {
        let net = Mlp::new(4, 8, 2, 2, &mut crate::rng::seeded(3));
        let a = net.to_safetensors_bytes();
        let b = net.clone().to_safetensors_bytes();
        assert_eq!(a, b);
        let n = u64::from_le_bytes(a[..8].try_into().unwrap()) as usize;
        assert_eq!(n % 8, 0);
        assert_eq!(a.len(), 8 + n + 4 * net.num_params());
    }

    #[test]
    fn a_prior_is_stored_as_its_scale_and_seed_and_drawn_again() {
        let net = Mlp::new(4, 8, 2, 2, &mut crate::rng::seeded(3)).with_prior(3.0, 42);
        let back = Mlp::from_safetensors_bytes(&net.to_safetensors_bytes()).unwrap();
        assert_eq!(back, net);
        let plain = Mlp::new(4, 8, 2, 2, &mut crate::rng::seeded(3));
        let back = Mlp::from_safetensors_bytes(&plain.to_safetensors_bytes()).unwrap();
        assert!(back.prior().is_none());
    }

    #[test]
    fn separate_torsos_are_stored_as_their_count_and_read_back() {
        let net = Mlp::separate(4, 8, 3, 2, &mut crate::rng::seeded(3)).with_prior(2.0, 7);
        let bytes = net.to_safetensors_bytes();
        let back = Mlp::from_safetensors_bytes(&bytes).unwrap();
        assert_eq!(back, net);
        assert_eq!((back.torsos(), back.hidden()), (3, 24));
        assert_eq!(back.prior().unwrap().network().torsos(), 3);
        // A count that does not fit the heads is refused, naming the key.
        let mut bad = bytes.clone();
        let key = b"\"torsos\":\"3\"";
        let at = bad.windows(key.len()).position(|w| w == key).unwrap();
        bad[at + key.len() - 2] = b'5';
        let err = Mlp::from_safetensors_bytes(&bad).unwrap_err();
        assert!(err.to_string().contains("torsos"), "{err}");
    }
}
