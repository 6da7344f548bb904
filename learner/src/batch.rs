//! [`TrainingBatch`]: a sampled batch as the tensors an update needs,
//! checked against the network at the boundary.
//!
//! Checked here: the observation layout and the action count against the
//! network's spec, and the importance weights. An MLP's batches
//! go from the replay's sparse entries straight into sparse rows
//! (`crossroads_model::Observations::from_encoded`), with no dense rows in
//! between. The tensors are built on the CPU; a trainer on another device
//! moves them there ([`TrainingBatch::to_device`]).

use crossroads_model::{NetworkSpec, ObservationLayout, Observations};
use crossroads_types::{Sample, TransitionBatch};
use tch::{Device, Tensor};

use crate::LearnerError;

/// The tensors of one batch, in batch order, with the replay keys the
/// priority update names.
#[derive(Debug)]
pub struct TrainingBatch {
    /// States, `[batch, input]` f32, in the form the network reads fastest
    /// (sparse for an MLP trunk).
    pub obs: Observations,
    /// Actions taken, `[batch]` i64.
    pub actions: Tensor,
    /// Discounted rewards over each transition's steps, `[batch]`.
    pub rewards: Tensor,
    /// Bootstrap discounts gamma^k (0 at terminal), `[batch]`.
    pub discounts: Tensor,
    /// Next states, `[batch, input]`, like `obs`.
    pub next_obs: Observations,
    /// Importance weights, `[batch]`.
    pub weights: Tensor,
    /// Replay keys, for the priority update.
    pub keys: Vec<u64>,
}

impl TrainingBatch {
    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Whether the batch is empty.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// The same batch with its tensors on `device` (a CUDA learner's);
    /// the keys are copied.
    pub fn to_device(&self, device: Device) -> Self {
        Self {
            obs: self.obs.to_device(device),
            actions: self.actions.to_device(device),
            rewards: self.rewards.to_device(device),
            discounts: self.discounts.to_device(device),
            next_obs: self.next_obs.to_device(device),
            weights: self.weights.to_device(device),
            keys: self.keys.clone(),
        }
    }

    /// The tensors of a sampled batch. Fails, naming the problem, when the
    /// batch's observations or actions are not the network's, or weights
    /// are not finite and positive.
    pub fn from_sampled(sampled: &Sample, spec: &NetworkSpec) -> Result<Self, LearnerError> {
        if let Some((i, w)) = sampled
            .weights
            .iter()
            .enumerate()
            .find(|(_, w)| !(w.is_finite() && **w >= 0.0))
        {
            return Err(LearnerError::Batch(format!(
                "importance weight {i} is {w}; expected finite and >= 0"
            )));
        }
        // A sample's batch is a `ValidBatch`, checked once on arrival.
        Self::build(
            &sampled.batch,
            &sampled.weights,
            sampled.keys.clone(),
            spec,
            false,
        )
    }

    /// The tensors of `batch` with `weights` and `keys` (one each per
    /// transition); the batch is validated first.
    pub fn from_batch(
        batch: &TransitionBatch,
        weights: &[f32],
        keys: Vec<u64>,
        spec: &NetworkSpec,
    ) -> Result<Self, LearnerError> {
        Self::build(batch, weights, keys, spec, true)
    }

    /// The tensors, after the checks that `batch` fits `spec`; `validate`
    /// also checks the batch itself (unless it is already a `ValidBatch`).
    fn build(
        batch: &TransitionBatch,
        weights: &[f32],
        keys: Vec<u64>,
        spec: &NetworkSpec,
        validate: bool,
    ) -> Result<Self, LearnerError> {
        let n = batch.len();
        if n == 0 {
            return Err(LearnerError::Batch("the batch is empty".to_owned()));
        }
        if weights.len() != n || keys.len() != n {
            return Err(LearnerError::Batch(format!(
                "{} weights and {} keys for {n} transitions",
                weights.len(),
                keys.len()
            )));
        }
        // A table restored from a file of an earlier build holds a legacy
        // layout (kind and length only) until its next insert.
        if !batch.layout.reads_as(&spec.observation) {
            let values = |l: &ObservationLayout| {
                l.check()
                    .map_or_else(|_| "invalid".to_owned(), |v| v.to_string())
            };
            return Err(LearnerError::Batch(format!(
                "observations are {} ({} values), the network reads {} ({} values); \
                 sim.observation must match what the actors send",
                batch.layout,
                values(&batch.layout),
                spec.observation,
                values(&spec.observation),
            )));
        }
        if i64::from(batch.num_actions) != spec.num_actions {
            return Err(LearnerError::Batch(format!(
                "the batch has {} actions, the network scores {} ({})",
                batch.num_actions, spec.num_actions, spec.action_set
            )));
        }
        if validate {
            batch
                .validate()
                .map_err(|e| LearnerError::Batch(e.to_string()))?;
        }
        let pool = &batch.observations;
        let entries = |column: &[u32]| {
            let rows = column
                .iter()
                .enumerate()
                .map(|(i, &s)| {
                    pool.get(s as usize).ok_or_else(|| {
                        LearnerError::Batch(format!(
                            "observation of transition {i}: no entry {s} among {}",
                            pool.len()
                        ))
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            Observations::from_encoded(spec, pool.encoding(), rows.into_iter()).map_err(|(i, e)| {
                LearnerError::Batch(format!("observation of transition {i}: {e}"))
            })
        };
        let obs = entries(&batch.columns.observation_index)?;
        let next_obs = entries(&batch.columns.next_observation_index)?;
        let actions: Vec<i64> = batch
            .columns
            .actions
            .iter()
            .map(|&a| i64::from(a))
            .collect();
        Ok(Self {
            obs,
            actions: Tensor::from_slice(&actions),
            rewards: Tensor::from_slice(&batch.columns.rewards),
            discounts: Tensor::from_slice(&batch.columns.discounts),
            next_obs,
            weights: Tensor::from_slice(weights),
            keys,
        })
    }
}
