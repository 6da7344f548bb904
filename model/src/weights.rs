//! The weights format: safetensors (readable by Python's `safetensors` and
//! PyTorch), f32 tensors under the network's variable names, and in the
//! file's string metadata ([`WeightsMeta`], [`FORMAT`], [`FORMAT_VERSION`],
//! defined tch-free in `crossroads_types::weights` and re-exported here):
//!
//! | key | value |
//! | --- | --- |
//! | `format` | `crossroads.qnetwork` |
//! | `format_version` | [`FORMAT_VERSION`] |
//! | `weights_version` | the learner's monotonic version, decimal |
//! | `spec` | the [`NetworkSpec`](crate::NetworkSpec) as JSON |
//!
//! [`encode`] and [`decode`] are the generic halves, also used for other
//! named tensors (the learner's optimizer state).
//!
//! A network's tensors are named as its variables (`trunk.<i>.*`,
//! `trunk.fc.*` after convolutions, `value.*`, `advantage.*`), in PyTorch's
//! layout. [`assign`] checks every name, shape and value (finite) before
//! it changes anything.

use std::collections::{BTreeSet, HashMap};

use crossroads_types::tensors::{self, F32Tensor};
use safetensors::tensor::{Dtype, TensorView};
use tch::{Kind, Tensor};

use crate::ModelError;

pub use crossroads_types::weights::{FORMAT, FORMAT_VERSION, WeightsMeta};

/// Serializes f32 tensors under their names, with `metadata`.
pub fn encode(
    tensors: &[(String, Tensor)],
    metadata: &HashMap<String, String>,
) -> Result<Vec<u8>, ModelError> {
    let mut data = Vec::with_capacity(tensors.len());
    for (name, t) in tensors {
        if t.kind() != Kind::Float {
            return Err(ModelError::Format(format!(
                "tensor {name} is {:?}; only f32 is written",
                t.kind()
            )));
        }
        let values = Vec::<f32>::try_from(t.detach().contiguous().flatten(0, -1))?;
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let shape: Vec<usize> = t.size().iter().map(|&d| d as usize).collect();
        data.push((name.clone(), shape, bytes));
    }
    let views = data
        .iter()
        .map(|(name, shape, bytes)| {
            TensorView::new(Dtype::F32, shape.clone(), bytes).map(|v| (name.as_str(), v))
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| ModelError::Format(e.to_string()))?;
    safetensors::tensor::serialize(views, &Some(metadata.clone()))
        .map_err(|e| ModelError::Format(e.to_string()))
}

/// Parses safetensors bytes: the metadata and every tensor (f32 only),
/// sorted by name. Every check of the bytes is
/// `crossroads_types::tensors::read_f32`'s (tch-free, fuzzed); this only
/// makes tensors of what it returns.
#[allow(clippy::type_complexity)]
pub fn decode(
    bytes: &[u8],
) -> Result<(HashMap<String, String>, Vec<(String, Tensor)>), ModelError> {
    let (metadata, tensors) =
        tensors::read_f32(bytes).map_err(|e| ModelError::Format(e.to_string()))?;
    let tensors = tensors
        .into_iter()
        .map(|t| Ok((t.name.clone(), to_tensor(t)?)))
        .collect::<Result<_, ModelError>>()?;
    Ok((metadata, tensors))
}

/// A checked f32 tensor as a tch tensor of its shape.
pub fn to_tensor(t: F32Tensor) -> Result<Tensor, ModelError> {
    Ok(Tensor::from_slice(&t.values).f_reshape(t.shape)?)
}

/// Copies `tensors` into `vars` (name -> variable): every variable must be
/// named exactly once, with its shape and finite values. Checks everything
/// before changing anything.
pub fn assign(
    vars: &HashMap<String, Tensor>,
    tensors: Vec<(String, Tensor)>,
) -> Result<(), ModelError> {
    let have: BTreeSet<&str> = vars.keys().map(String::as_str).collect();
    let got: BTreeSet<&str> = tensors.iter().map(|(n, _)| n.as_str()).collect();
    if have != got || got.len() != tensors.len() {
        let missing: Vec<_> = have.difference(&got).collect();
        let unknown: Vec<_> = got.difference(&have).collect();
        return Err(ModelError::Format(format!(
            "tensor names do not match the network: missing {missing:?}, unknown {unknown:?}"
        )));
    }
    for (name, t) in &tensors {
        let var = &vars[name];
        if var.size() != t.size() {
            return Err(ModelError::Format(format!(
                "tensor {name} has shape {:?}, the network's is {:?}",
                t.size(),
                var.size()
            )));
        }
        let finite = t.isfinite().all().int64_value(&[]) == 1;
        if !finite {
            return Err(ModelError::NonFinite(format!("tensor {name}")));
        }
    }
    tch::no_grad(|| {
        for (name, t) in tensors {
            let mut var = vars[&name].shallow_clone();
            var.copy_(&t);
        }
    });
    Ok(())
}
