//! safetensors files of f32 tensors read and written without a tensor
//! library: every check that untrusted bytes need happens here, so
//! `crossroads_model` only turns checked [`F32Tensor`]s into tch tensors,
//! and the checks can be fuzzed without libtorch.
//!
//! [`read_f32`] refuses what the safetensors crate would panic on or what
//! tch could not shape (a data offset beyond the file, whose sum with the
//! header length overflows in safetensors 0.3; a dimension above
//! `i64::MAX`), besides what safetensors itself refuses.

use std::collections::HashMap;

use safetensors::tensor::{Dtype, SafeTensors, TensorView};

/// One named f32 tensor, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct F32Tensor {
    /// Its name in the file.
    pub name: String,
    /// Dimensions, each at most `i64::MAX` (what tch takes).
    pub shape: Vec<i64>,
    /// `shape`'s product of values.
    pub values: Vec<f32>,
}

/// Why bytes are not a safetensors file of f32 tensors.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("not a safetensors file of f32 tensors: {0}")]
pub struct TensorsError(pub String);

/// Bytes of the length prefix of a safetensors file.
const N_LEN: usize = 8;

/// Checks what safetensors 0.3 trusts in the JSON header before it parses
/// it: that no tensor's data offsets lie beyond the file (its check adds
/// them to the header length unchecked, which overflows). Anything else
/// malformed is left for safetensors to report.
fn check_offsets(bytes: &[u8]) -> Result<(), TensorsError> {
    let Some(prefix) = bytes.get(..N_LEN) else {
        return Ok(());
    };
    let mut n = [0u8; N_LEN];
    n.copy_from_slice(prefix);
    let n = u64::from_le_bytes(n);
    let Some(header) = usize::try_from(n)
        .ok()
        .and_then(|n| bytes.get(N_LEN..N_LEN.checked_add(n)?))
    else {
        return Ok(());
    };
    let Ok(serde_json::Value::Object(entries)) = serde_json::from_slice(header) else {
        return Ok(());
    };
    let data_len = (bytes.len() - N_LEN - header.len()) as u64;
    for (name, entry) in &entries {
        let offsets = entry
            .get("data_offsets")
            .and_then(|o| o.as_array())
            .into_iter()
            .flatten();
        for offset in offsets {
            if offset.as_u64().is_some_and(|o| o > data_len) {
                return Err(TensorsError(format!(
                    "tensor {name}: data offset {offset} is beyond the {data_len} data bytes"
                )));
            }
        }
    }
    Ok(())
}

/// The string metadata of a safetensors file, from its header alone (no
/// tensor is read or checked).
pub fn read_metadata(bytes: &[u8]) -> Result<HashMap<String, String>, TensorsError> {
    check_offsets(bytes)?;
    let (_, header) =
        SafeTensors::read_metadata(bytes).map_err(|e| TensorsError(format!("{e:?}")))?;
    Ok(header.metadata().clone().unwrap_or_default())
}

/// Parses a safetensors file whose tensors are all f32: its metadata and
/// every tensor, sorted by name (the file's own order is its data
/// offsets, which say nothing).
pub fn read_f32(bytes: &[u8]) -> Result<(HashMap<String, String>, Vec<F32Tensor>), TensorsError> {
    let metadata = read_metadata(bytes)?;
    let file = SafeTensors::deserialize(bytes).map_err(|e| TensorsError(format!("{e:?}")))?;
    let mut out = Vec::new();
    for (name, view) in file.tensors() {
        if view.dtype() != Dtype::F32 {
            return Err(TensorsError(format!(
                "tensor {name} is {:?}; expected F32",
                view.dtype()
            )));
        }
        let shape = view
            .shape()
            .iter()
            .map(|&d| i64::try_from(d))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|_| TensorsError(format!("tensor {name}: a dimension is above 2^63")))?;
        let values = view
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        out.push(F32Tensor {
            name,
            shape,
            values,
        });
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok((metadata, out))
}

/// Serializes f32 tensors under their names, with `metadata`. Fails when
/// a tensor's values are not its shape's product, a dimension is
/// negative, or two tensors share a name.
pub fn write_f32(
    tensors: &[F32Tensor],
    metadata: &HashMap<String, String>,
) -> Result<Vec<u8>, TensorsError> {
    let data: Vec<(&str, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|t| {
            let shape = t
                .shape
                .iter()
                .map(|&d| usize::try_from(d))
                .collect::<Result<Vec<_>, _>>()
                .map_err(|_| TensorsError(format!("tensor {}: a negative dimension", t.name)))?;
            let bytes = t.values.iter().flat_map(|v| v.to_le_bytes()).collect();
            Ok((t.name.as_str(), shape, bytes))
        })
        .collect::<Result<_, TensorsError>>()?;
    let mut names: Vec<&str> = data.iter().map(|(n, _, _)| *n).collect();
    names.sort_unstable();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(TensorsError(format!("tensor {} appears twice", w[0])));
    }
    let views = data
        .iter()
        .map(|(name, shape, bytes)| {
            TensorView::new(Dtype::F32, shape.clone(), bytes).map(|v| (*name, v))
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| TensorsError(format!("{e:?}")))?;
    safetensors::tensor::serialize(views, &Some(metadata.clone()))
        .map_err(|e| TensorsError(format!("{e:?}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file_with_header(header: &str, data: &[u8]) -> Vec<u8> {
        let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(data);
        bytes
    }

    #[test]
    fn f32_tensors_round_trip() {
        let tensors = vec![
            F32Tensor {
                name: "a".into(),
                shape: vec![2, 1],
                values: vec![1.0, -2.5],
            },
            F32Tensor {
                name: "b".into(),
                shape: vec![0, 3],
                values: vec![],
            },
        ];
        let metadata = HashMap::from([("k".to_owned(), "v".to_owned())]);
        let bytes = write_f32(&tensors, &metadata).expect("written");
        assert_eq!(read_f32(&bytes), Ok((metadata, tensors)));
    }

    /// An end offset of 2^64 - 1 made safetensors 0.3 overflow adding it
    /// to the header length (a panic in debug builds, where this test
    /// runs).
    #[test]
    fn an_offset_beyond_the_file_is_an_error_not_an_overflow() {
        let header = r#"{"t":{"dtype":"U8","shape":[18446744073709551615],"data_offsets":[0,18446744073709551615]}}"#;
        let bytes = file_with_header(header, &[]);
        let err = read_metadata(&bytes).expect_err("offset beyond the file");
        assert!(err.0.contains("beyond"), "{err}");
        assert!(read_f32(&bytes).is_err());
    }

    /// A zero-sized tensor may have any other dimension; one above
    /// `i64::MAX` cannot become a tch shape.
    #[test]
    fn a_dimension_above_i64_is_an_error() {
        let header =
            r#"{"t":{"dtype":"F32","shape":[0,18446744073709551615],"data_offsets":[0,0]}}"#;
        let err = read_f32(&file_with_header(header, &[])).expect_err("huge dimension");
        assert!(err.0.contains("above 2^63"), "{err}");
    }
}
