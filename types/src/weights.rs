//! The metadata of the weights format, readable without tch: a weights file
//! is safetensors (readable by Python's `safetensors` and PyTorch), f32
//! tensors under the network's variable names, and in the file's string
//! metadata:
//!
//! | key | value |
//! | --- | --- |
//! | `format` | `crossroads.qnetwork` |
//! | `format_version` | [`FORMAT_VERSION`] |
//! | `weights_version` | the learner's monotonic version, decimal |
//! | `spec` | the [`NetworkSpec`] as JSON |
//!
//! [`WeightsMeta::read`] reads and checks the metadata of a file from its
//! header alone, building no tensor; writing and loading the tensors is
//! `crossroads_model::weights`. [`Weights`] is one version as the learner
//! publishes it, the transports carry it and actors apply it.

use std::collections::HashMap;

use crate::spec::{NetworkSpec, SpecError};

/// Value of the `format` metadata key.
pub const FORMAT: &str = "crossroads.qnetwork";
/// Version of this layout; a reader refuses others.
pub const FORMAT_VERSION: u32 = 1;

/// What the metadata of a weights file says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WeightsMeta {
    /// The learner's version of these weights.
    pub version: u64,
    /// The network they belong to.
    pub spec: NetworkSpec,
}

impl WeightsMeta {
    /// The metadata map of a file.
    pub fn to_metadata(&self) -> Result<HashMap<String, String>, SpecError> {
        let spec = serde_json::to_string(&self.spec)
            .map_err(|e| SpecError::Format(format!("cannot write the spec: {e}")))?;
        Ok(HashMap::from([
            ("format".to_owned(), FORMAT.to_owned()),
            ("format_version".to_owned(), FORMAT_VERSION.to_string()),
            ("weights_version".to_owned(), self.version.to_string()),
            ("spec".to_owned(), spec),
        ]))
    }

    /// Reads and checks the metadata map of a file.
    pub fn from_metadata(metadata: &HashMap<String, String>) -> Result<Self, SpecError> {
        let get = |key: &str| {
            metadata
                .get(key)
                .ok_or_else(|| SpecError::Format(format!("metadata key {key:?} is missing")))
        };
        if get("format")? != FORMAT {
            return Err(SpecError::Format(format!(
                "format is {:?}, expected {FORMAT:?}",
                get("format")?
            )));
        }
        let format_version = get("format_version")?;
        if format_version != &FORMAT_VERSION.to_string() {
            return Err(SpecError::Format(format!(
                "format_version is {format_version:?}; this build reads {FORMAT_VERSION}"
            )));
        }
        let version = get("weights_version")?
            .parse::<u64>()
            .map_err(|e| SpecError::Format(format!("weights_version is not an integer: {e}")))?;
        let spec: NetworkSpec = serde_json::from_str(get("spec")?)
            .map_err(|e| SpecError::Format(format!("spec: {e}")))?;
        spec.validate()?;
        Ok(Self { version, spec })
    }

    /// The metadata map of safetensors bytes, read from the header only (no
    /// tensor is built or checked).
    pub fn read_metadata(bytes: &[u8]) -> Result<HashMap<String, String>, SpecError> {
        crate::tensors::read_metadata(bytes).map_err(|e| SpecError::Format(e.to_string()))
    }

    /// Reads and checks the metadata of safetensors bytes, from the header
    /// only.
    pub fn read(bytes: &[u8]) -> Result<Self, SpecError> {
        Self::from_metadata(&Self::read_metadata(bytes)?)
    }
}

/// One published version of the learner's online network: what the
/// learner broadcasts, gRPC and iceoryx2 carry, and actors apply.
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    /// Strictly increasing over the learner's life, across restores and
    /// restarts.
    pub version: u64,
    /// Learner update step the weights come from.
    pub update_step: u64,
    /// Unix milliseconds of publication (for staleness).
    pub published_unix_ms: i64,
    /// The network they belong to.
    pub spec: NetworkSpec,
    /// safetensors bytes, with the same version and spec in their metadata
    /// (load with `crossroads_model::QNetwork::load_safetensors`, which
    /// checks the tensors).
    pub safetensors: Vec<u8>,
}

impl Weights {
    /// Weights from safetensors bytes, taking version and spec from their
    /// metadata (read from the header only; no tensor is checked).
    pub fn from_safetensors(
        safetensors: Vec<u8>,
        update_step: u64,
        published_unix_ms: i64,
    ) -> Result<Self, SpecError> {
        let meta = WeightsMeta::read(&safetensors)?;
        Ok(Self {
            version: meta.version,
            update_step,
            published_unix_ms,
            spec: meta.spec,
            safetensors,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::{ObservationLayout, TrunkKind};

    fn file(metadata: &HashMap<String, String>) -> Vec<u8> {
        let bytes = [0u8; 8];
        let view =
            safetensors::tensor::TensorView::new(safetensors::tensor::Dtype::F32, vec![2], &bytes)
                .expect("view");
        safetensors::tensor::serialize([("w", view)], &Some(metadata.clone())).expect("serialize")
    }

    #[test]
    fn metadata_round_trips_through_the_header() {
        let meta = WeightsMeta {
            version: 7,
            spec: NetworkSpec::new(
                ObservationLayout::new("toy", 2, 3, 4, 1),
                "ttg",
                TrunkKind::Mlp,
                vec![16],
            )
            .expect("spec"),
        };
        let bytes = file(&meta.to_metadata().expect("metadata"));
        assert_eq!(WeightsMeta::read(&bytes), Ok(meta.clone()));
        let weights = Weights::from_safetensors(bytes.clone(), 70, 5).expect("weights");
        assert_eq!(
            weights,
            Weights {
                version: 7,
                update_step: 70,
                published_unix_ms: 5,
                spec: meta.spec,
                safetensors: bytes,
            }
        );
    }

    #[test]
    fn bad_metadata_names_the_problem() {
        let err = WeightsMeta::read(b"not safetensors").expect_err("garbage");
        assert!(err.to_string().contains("not a safetensors file"), "{err}");
        let mut metadata = WeightsMeta {
            version: 1,
            spec: NetworkSpec::new(
                ObservationLayout::new("toy", 1, 2, 2, 0),
                "creep",
                TrunkKind::Mlp,
                vec![8],
            )
            .expect("spec"),
        }
        .to_metadata()
        .expect("metadata");
        metadata.insert("format_version".to_owned(), "2".to_owned());
        let err = WeightsMeta::read(&file(&metadata)).expect_err("other version");
        assert!(err.to_string().contains("format_version is \"2\""), "{err}");
    }
}
