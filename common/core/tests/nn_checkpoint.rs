//! Network checkpoints as safetensors: the round trip, the layout a PyTorch user sees, and a clear
//! error for each kind of bad file.

use std::collections::HashMap;

use alfd_common::nn::{Mlp, NnError, FORMAT_VERSION, PARAM_NAMES};
use safetensors::{Dtype, SafeTensors};

fn net() -> Mlp {
    Mlp::new(4, 64, 2, 2, &mut alfd_common::rng::seeded(11))
}

/// One tensor of a hand-made file: name, dtype, shape, raw bytes.
type Raw = (String, Dtype, Vec<usize>, Vec<u8>);

/// The tensors of `net` as raw entries, to be damaged by a test.
fn raw_tensors(net: &Mlp) -> Vec<Raw> {
    PARAM_NAMES
        .iter()
        .zip(net.params().shapes())
        .zip(net.params().tensors())
        .map(|((name, shape), data)| {
            let bytes = data.iter().flat_map(|v| v.to_le_bytes()).collect();
            (name.to_string(), Dtype::F32, shape, bytes)
        })
        .collect()
}

fn metadata(heads: &str, actions: &str, version: &str) -> HashMap<String, String> {
    HashMap::from([
        ("heads".to_string(), heads.to_string()),
        ("actions".to_string(), actions.to_string()),
        ("format_version".to_string(), version.to_string()),
    ])
}

fn write(tensors: &[Raw], meta: Option<HashMap<String, String>>) -> Vec<u8> {
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = tensors
        .iter()
        .map(|(name, dtype, shape, bytes)| {
            let view = safetensors::tensor::TensorView::new(*dtype, shape.clone(), bytes)
                .expect("a consistent view");
            (name.clone(), view)
        })
        .collect();
    safetensors::serialize(views, meta).expect("serialise")
}

fn load_err(bytes: &[u8]) -> NnError {
    match Mlp::from_safetensors_bytes(bytes) {
        Ok(_) => panic!("a bad file was accepted"),
        Err(e) => e,
    }
}

#[test]
fn round_trip_gives_the_same_network() {
    let a = net();
    let bytes = a.to_safetensors_bytes();
    let b = Mlp::from_safetensors_bytes(&bytes).expect("load");
    assert_eq!(a, b);
    assert_eq!(b.heads(), 2);
    assert_eq!(b.actions(), 2);
    // A file written by the safetensors crate itself (as PyTorch would) loads too.
    let other = write(&raw_tensors(&a), Some(metadata("2", "2", FORMAT_VERSION)));
    assert_eq!(Mlp::from_safetensors_bytes(&other).expect("load"), a);
}

#[test]
fn file_has_pytorch_names_shapes_and_metadata() {
    let a = net();
    let bytes = a.to_safetensors_bytes();
    let file = SafeTensors::deserialize(&bytes).expect("valid safetensors");
    let mut names = file.names();
    names.sort();
    let mut expected = PARAM_NAMES.to_vec();
    expected.sort();
    assert_eq!(names, expected);
    let shapes: Vec<Vec<usize>> = PARAM_NAMES
        .iter()
        .map(|n| file.tensor(n).expect("tensor").shape().to_vec())
        .collect();
    assert_eq!(
        shapes,
        vec![
            vec![64, 4],
            vec![64],
            vec![64, 64],
            vec![64],
            vec![4, 64],
            vec![4]
        ]
    );
    // torso.0.weight[r][c] (row-major) is the weight from input c to hidden unit r.
    let w = file.tensor("torso.0.weight").expect("tensor");
    assert_eq!(w.dtype(), Dtype::F32);
    let value = |r: usize, c: usize| {
        let i = 4 * (r * 4 + c);
        f32::from_le_bytes(w.data()[i..i + 4].try_into().expect("4 bytes"))
    };
    // Our (in, out) matrix holds the same value at (c, r).
    assert_eq!(value(5, 2), a.params().w0[(2, 5)]);
    assert_eq!(value(63, 0), a.params().w0[(0, 63)]);
    let (_, header) = SafeTensors::read_metadata(&bytes).expect("header");
    let meta = header.metadata().as_ref().expect("metadata");
    assert_eq!(meta.get("heads").map(String::as_str), Some("2"));
    assert_eq!(meta.get("actions").map(String::as_str), Some("2"));
    assert_eq!(
        meta.get("format_version").map(String::as_str),
        Some(FORMAT_VERSION)
    );
    // Serialising twice gives the same bytes.
    assert_eq!(bytes, a.to_safetensors_bytes());
}

#[test]
fn truncated_files_are_refused() {
    let bytes = net().to_safetensors_bytes();
    for cut in [0, 5, 40, bytes.len() - 1] {
        let err = load_err(&bytes[..cut]);
        assert!(
            matches!(err, NnError::Safetensors(_)),
            "cut at {cut}: {err}"
        );
        assert!(
            err.to_string().starts_with("invalid safetensors data"),
            "{err}"
        );
    }
}

#[test]
fn missing_and_unexpected_tensors_are_named() {
    let a = net();
    let mut raw = raw_tensors(&a);
    raw.retain(|t| t.0 != "heads.bias");
    let err = load_err(&write(&raw, Some(metadata("2", "2", "1"))));
    assert!(
        matches!(&err, NnError::MissingTensor(n) if n == "heads.bias"),
        "{err}"
    );
    assert!(err.to_string().contains("heads.bias"));

    let mut raw = raw_tensors(&a);
    raw.push(("torso.2.weight".into(), Dtype::F32, vec![1], vec![0; 4]));
    let err = load_err(&write(&raw, Some(metadata("2", "2", "1"))));
    assert!(err.to_string().contains("torso.2.weight"), "{err}");
}

#[test]
fn wrong_shapes_are_named() {
    let a = net();
    // heads.weight as [2, 128]: the right number of values in the wrong shape.
    let mut raw = raw_tensors(&a);
    raw[4].2 = vec![2, 128];
    let err = load_err(&write(&raw, Some(metadata("2", "2", "1"))));
    assert!(
        matches!(&err, NnError::Shape { name, expected, found }
            if name == "heads.weight" && expected == &vec![4, 64] && found == &vec![2, 128]),
        "{err}"
    );
    // Metadata that disagrees with the output layer: 3 heads of 2 actions need 6 outputs.
    let err = load_err(&write(&raw_tensors(&a), Some(metadata("3", "2", "1"))));
    assert!(err.to_string().contains("heads.weight"), "{err}");
    // A 3-D first layer.
    let mut raw = raw_tensors(&a);
    raw[0].2 = vec![64, 2, 2];
    let err = load_err(&write(&raw, Some(metadata("2", "2", "1"))));
    assert!(err.to_string().contains("torso.0.weight"), "{err}");
}

#[test]
fn wrong_dtype_is_named() {
    let a = net();
    let mut raw = raw_tensors(&a);
    // torso.1.bias as F64: 64 values of 8 bytes.
    raw[3].1 = Dtype::F64;
    raw[3].3 = a
        .params()
        .b1
        .iter()
        .flat_map(|&v| f64::from(v).to_le_bytes())
        .collect();
    let err = load_err(&write(&raw, Some(metadata("2", "2", "1"))));
    assert!(
        matches!(&err, NnError::Dtype { name, found } if name == "torso.1.bias" && found == "F64"),
        "{err}"
    );
}

#[test]
fn missing_or_bad_metadata_is_named() {
    let raw = raw_tensors(&net());
    let err = load_err(&write(&raw, None));
    assert!(
        matches!(&err, NnError::Metadata { key, .. } if key == "format_version"),
        "{err}"
    );
    let mut meta = metadata("2", "2", "1");
    meta.remove("heads");
    let err = load_err(&write(&raw, Some(meta)));
    assert!(
        matches!(&err, NnError::Metadata { key, .. } if key == "heads"),
        "{err}"
    );
    let err = load_err(&write(&raw, Some(metadata("2", "two", "1"))));
    assert!(
        matches!(&err, NnError::Metadata { key, .. } if key == "actions"),
        "{err}"
    );
    let err = load_err(&write(&raw, Some(metadata("2", "2", "99"))));
    assert!(err.to_string().contains("format_version"), "{err}");
    assert!(err.to_string().contains("99"), "{err}");
}
