//! The learner's conversations in domain types, and their conversion to
//! and from `crossroads_proto`, validating what comes in: network specs,
//! weights ([`Weights`]) and checkpoint descriptions
//! ([`CheckpointSummary`]). An [`ObservationLayout`] has one wire form
//! ([`layout_to_wire`], [`layout_from_wire`]), for network specs and
//! transition batches (`crate::wire`) alike.

use crossroads_proto::v1 as pb;
use crossroads_types::{NetworkSpec, ObservationLayout, TrunkKind, Weights};

/// A checkpoint as the API describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointSummary {
    /// Folder name.
    pub id: String,
    /// Update step.
    pub update_step: u64,
    /// Weights version.
    pub weights_version: u64,
    /// Unix milliseconds.
    pub created_unix_ms: i64,
    /// Total bytes.
    pub size_bytes: u64,
    /// Scenario of the run.
    pub scenario: String,
    /// Latest evaluation when it was taken.
    pub eval_metrics: std::collections::BTreeMap<String, f64>,
    /// Kept as the best by evaluation.
    pub best: bool,
    /// Its files.
    pub files: Vec<String>,
}

/// To the wire.
pub fn checkpoint_to_wire(c: &CheckpointSummary) -> pb::CheckpointInfo {
    pb::CheckpointInfo {
        id: c.id.clone(),
        update_step: c.update_step,
        weights_version: c.weights_version,
        created_unix_ms: c.created_unix_ms,
        size_bytes: c.size_bytes,
        scenario: c.scenario.clone(),
        eval_metrics: c.eval_metrics.clone().into_iter().collect(),
        best: c.best,
        files: c.files.clone(),
    }
}

/// From the wire.
pub fn checkpoint_from_wire(c: pb::CheckpointInfo) -> CheckpointSummary {
    CheckpointSummary {
        id: c.id,
        update_step: c.update_step,
        weights_version: c.weights_version,
        created_unix_ms: c.created_unix_ms,
        size_bytes: c.size_bytes,
        scenario: c.scenario,
        eval_metrics: c.eval_metrics.into_iter().collect(),
        best: c.best,
        files: c.files,
    }
}

/// An observation layout on the wire: its kind, `shape` `[channels, rows,
/// cols]` and `extra_features`.
pub fn layout_to_wire(l: &ObservationLayout) -> pb::ObservationSpec {
    pb::ObservationSpec {
        kind: l.kind.clone(),
        shape: [l.channels, l.rows, l.cols]
            .iter()
            .map(|&d| d as u32)
            .collect(),
        extra_features: l.extra as u32,
    }
}

/// An observation layout from the wire, not checked beyond its form (the
/// batch's or the spec's validation checks its values). The error says
/// what is wrong with `shape`, for the caller to name the field: a shape
/// that is not `[channels, rows, cols]`, such as the flat `[len]` of
/// earlier builds.
pub fn layout_from_wire(o: pb::ObservationSpec) -> Result<ObservationLayout, String> {
    let [channels, rows, cols] = o.shape[..] else {
        let flat = if o.shape.len() == 1 {
            "; a flat [len] is what builds before the layout travelled send: \
             run actors, replay server and learner of the same build"
        } else {
            ""
        };
        return Err(format!(
            "must be [channels, rows, cols] (then extra_features dense values), got {:?}{flat}",
            o.shape
        ));
    };
    Ok(ObservationLayout::new(
        o.kind,
        i64::from(channels),
        i64::from(rows),
        i64::from(cols),
        i64::from(o.extra_features),
    ))
}

/// A network spec on the wire: its observation layout
/// ([`layout_to_wire`]), with the dense features also in the spec's own
/// `extra_features`, where builds before the layout travelled read them.
pub fn spec_to_wire(s: &NetworkSpec) -> pb::NetworkSpec {
    pb::NetworkSpec {
        observation: Some(layout_to_wire(&s.observation)),
        action_set: s.action_set.clone(),
        num_actions: s.num_actions as u32,
        trunk: s.trunk.name().to_owned(),
        hidden: s.hidden.iter().map(|&h| h as u32).collect(),
        extra_features: s.observation.extra as u32,
    }
}

/// A network spec from the wire, checked. The dense features are read
/// from the layout or, from a build that wrote them only there, from the
/// spec's own `extra_features`; set in both, they must agree.
pub fn spec_from_wire(s: pb::NetworkSpec) -> Result<NetworkSpec, String> {
    let o = s.observation.ok_or("spec.observation is missing")?;
    let mut observation = layout_from_wire(o).map_err(|e| format!("spec.observation.shape {e}"))?;
    match (observation.extra, i64::from(s.extra_features)) {
        (_, 0) => {}
        (0, theirs) => observation.extra = theirs,
        (ours, theirs) if ours != theirs => {
            return Err(format!(
                "spec.observation.extra_features is {ours}, spec.extra_features {theirs}; \
                 they must agree"
            ));
        }
        _ => {}
    }
    let spec = NetworkSpec {
        observation,
        action_set: s.action_set,
        num_actions: i64::from(s.num_actions),
        trunk: TrunkKind::parse(&s.trunk).map_err(|e| e.to_string())?,
        hidden: s.hidden.iter().map(|&h| i64::from(h)).collect(),
    };
    spec.validate().map_err(|e| e.to_string())?;
    Ok(spec)
}

/// Weights to the wire.
pub fn weights_to_wire(w: &Weights) -> pb::Weights {
    pb::Weights {
        version: w.version,
        update_step: w.update_step,
        spec: Some(spec_to_wire(&w.spec)),
        safetensors: w.safetensors.clone(),
        published_unix_ms: w.published_unix_ms,
    }
}

/// Weights from the wire, checked: a valid spec, the same spec and version
/// in the safetensors metadata as in the message. Reads the safetensors
/// header only; the tensors are checked where they are loaded
/// (`crossroads_model::QNetwork::load_safetensors`).
pub fn weights_from_wire(w: pb::Weights) -> Result<Weights, String> {
    let spec = spec_from_wire(w.spec.ok_or("weights.spec is missing")?)?;
    let weights = Weights::from_safetensors(w.safetensors, w.update_step, w.published_unix_ms)
        .map_err(|e| e.to_string())?;
    if weights.spec != spec || weights.version != w.version {
        return Err(format!(
            "the message says version {} of {spec:?}, its safetensors version {} of {:?}",
            w.version, weights.version, weights.spec
        ));
    }
    Ok(weights)
}
