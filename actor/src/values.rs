//! The one thing the actor needs from a Q-network: batched action values.
//!
//! [`ActionValues`] is called once per vectorized step, with dense rows or,
//! where [`ActionValues::reads_sparse`] says so, each observation's
//! non-zero pairs. `&mut self`, so an implementation can swap weights
//! between calls: the model's `QNetwork` and the actor's `LiveNetwork`
//! implement it, and tests use a linear function.

use crossroads_model::QNetwork;
use crossroads_types::codec;

/// Error of an [`ActionValues`] implementation (a forward pass that failed,
/// weights that do not fit).
pub type ValuesError = Box<dyn std::error::Error + Send + Sync>;

/// Batched Q-values: for `n` observations of [`obs_len`](Self::obs_len)
/// values each, back to back in one flat slice (row-major `n x obs_len`),
/// writes `n x num_actions` values, row-major, into `out`.
///
/// Cost: one forward pass per call, whatever `n`; the actor calls it once
/// per vectorized step with every environment's observation. Thread safety:
/// called from one thread; `&mut self` lets an implementation reuse its
/// buffers and swap in newer weights between calls.
pub trait ActionValues {
    /// Values in one observation.
    fn obs_len(&self) -> usize;

    /// Actions scored per observation.
    fn num_actions(&self) -> usize;

    /// Writes the Q-values of the observations `obs` (`n x obs_len`) into
    /// `out` (`n x num_actions`).
    fn q_values(&mut self, obs: &[f32], n: usize, out: &mut [f32]) -> Result<(), ValuesError>;

    /// Whether [`ActionValues::q_values_sparse`] is the cheaper call (the
    /// network reads only the non-zero values). The caller asks before
    /// each call.
    fn reads_sparse(&self) -> bool {
        false
    }

    /// [`ActionValues::q_values`] of observations given as their non-zero
    /// values, `(index, value)` per observation
    /// ([`crossroads_sim::VecEnv::sparse_observations`]). By default spread into
    /// dense rows for `q_values`.
    fn q_values_sparse(
        &mut self,
        rows: &[Vec<(u32, f32)>],
        out: &mut [f32],
    ) -> Result<(), ValuesError> {
        let len = self.obs_len();
        let mut dense = vec![0.0; rows.len() * len];
        for (r, (row, pairs)) in dense.chunks_exact_mut(len.max(1)).zip(rows).enumerate() {
            codec::spread_pairs(pairs.iter().copied(), row)
                .map_err(|e| format!("observation {r}: {e}"))?;
        }
        self.q_values(&dense, rows.len(), out)
    }
}

/// Copies a network's Q-values into the caller's buffer.
fn write_q(q: &[f32], out: &mut [f32]) -> Result<(), ValuesError> {
    let room = out.len();
    let out = out
        .get_mut(..q.len())
        .ok_or_else(|| format!("output holds {room} values, the network wrote {}", q.len()))?;
    out.copy_from_slice(q);
    Ok(())
}

/// The Q-network drives the actor: one batched forward pass per call, no
/// graph recorded. Its spec must fit the environments (observation length
/// and action count); [`crate::Actor`] checks that before the first step.
impl ActionValues for QNetwork {
    fn obs_len(&self) -> usize {
        self.spec().input_len() as usize
    }

    fn num_actions(&self) -> usize {
        self.spec().num_actions as usize
    }

    fn q_values(&mut self, obs: &[f32], n: usize, out: &mut [f32]) -> Result<(), ValuesError> {
        let len = n * self.obs_len();
        let rows = obs
            .get(..len)
            .ok_or_else(|| format!("{n} observations need {len} values, got {}", obs.len()))?;
        write_q(&self.infer(rows, n)?.q, out)
    }

    fn reads_sparse(&self) -> bool {
        QNetwork::reads_sparse(self)
    }

    fn q_values_sparse(
        &mut self,
        rows: &[Vec<(u32, f32)>],
        out: &mut [f32],
    ) -> Result<(), ValuesError> {
        write_q(&self.infer_sparse(rows)?.q, out)
    }
}

/// Index of the largest value; the first on ties, and NaN never wins
/// (a row of NaN gives 0).
pub fn argmax(row: &[f32]) -> usize {
    let mut best = 0;
    let mut best_value = f32::NEG_INFINITY;
    for (i, &v) in row.iter().enumerate() {
        if v > best_value {
            best = i;
            best_value = v;
        }
    }
    best
}

/// The largest value of a row (the greedy bootstrap), ignoring NaN; 0 for
/// an empty or all-NaN row.
pub fn max_value(row: &[f32]) -> f32 {
    let m = row
        .iter()
        .copied()
        .filter(|v| !v.is_nan())
        .fold(f32::NEG_INFINITY, f32::max);
    if m.is_finite() || m == f32::INFINITY {
        m
    } else {
        0.0
    }
}
