//! [`Observations`]: a batch of observations in the form a network's first
//! layer reads fastest. A TTG observation is 2344 values of which a few
//! dozen are non-zero; an MLP's first layer over it is then the sum of the
//! weight rows of the non-zero inputs, each times its value (an embedding
//! bag with per-sample weights), which skips the zeros the dense product
//! multiplies.
//!
//! [`Observations::new`] (dense values) and [`Observations::from_encoded`]
//! (the replay's encoded entries, checked) pick the form: sparse rows for
//! an MLP trunk with hidden layers, dense otherwise (a conv trunk's first
//! layer is a convolution). Both build their tensors on the CPU;
//! [`Observations::to_device`] moves them to a network's device.

use crossroads_types::codec::{self, CodecError, ObservationEncoding};
use tch::{Device, Kind, Tensor};

use crate::ModelError;
use crate::spec::{NetworkSpec, TrunkKind};

/// A batch of observations as a [`QNetwork`](crate::QNetwork) reads them.
#[derive(Debug)]
pub enum Observations {
    /// `[rows, width]` f32.
    Dense(Tensor),
    /// The non-zero values of each row.
    Sparse(SparseRows),
}

/// The non-zero values of a batch of rows: row `r`'s are
/// `values[offsets[r]..offsets[r + 1]]` at columns `indices[..]` (the
/// layout of `embedding_bag`).
#[derive(Debug)]
pub struct SparseRows {
    pub(crate) indices: Tensor,
    pub(crate) values: Tensor,
    pub(crate) offsets: Tensor,
    pub(crate) rows: i64,
    pub(crate) width: i64,
}

impl SparseRows {
    /// The non-zero values of `rows` rows of `width` values each, back to
    /// back in `values`. Panics if `values` is not `rows * width` long.
    pub fn from_dense(values: &[f32], rows: usize, width: usize) -> Self {
        match Self::from_finite(values, rows, width) {
            Ok(s) | Err((_, s)) => s,
        }
    }

    /// [`SparseRows::from_dense`], failing with the index of the first
    /// value that is NaN or infinite (and the rows anyway). One pass: the
    /// check costs nothing on the zeros, which are most of a TTG
    /// observation and skipped 16 at a time
    /// ([`codec::for_each_nonzero`]).
    pub fn from_finite(values: &[f32], rows: usize, width: usize) -> Result<Self, (usize, Self)> {
        assert_eq!(values.len(), rows * width, "rows * width values");
        let mut indices = Vec::new();
        let mut nonzero = Vec::new();
        let mut offsets = Vec::with_capacity(rows);
        let mut bad = None;
        for (r, row) in values.chunks_exact(width.max(1)).take(rows).enumerate() {
            offsets.push(indices.len() as i64);
            codec::for_each_nonzero(row, |i, v| {
                if !v.is_finite() && bad.is_none() {
                    bad = Some(r * width + i);
                }
                indices.push(i as i64);
                nonzero.push(v);
            });
        }
        offsets.resize(rows, indices.len() as i64);
        let rows = Self::from_parts(&indices, &nonzero, &offsets, width);
        match bad {
            None => Ok(rows),
            Some(i) => Err((i, rows)),
        }
    }

    /// Rows given by their non-zero values: `rows` yields each row's
    /// `(index, value)` pairs (each index once, below `width`). What the
    /// simulators write and the replay stores, taken without a dense
    /// buffer in between. Fails naming the row of an index out of range
    /// or of a NaN or infinite value.
    pub fn from_pairs<R, P>(rows: R, width: usize) -> Result<Self, ModelError>
    where
        R: IntoIterator<Item = P>,
        P: IntoIterator<Item = (u32, f32)>,
    {
        let mut indices = Vec::new();
        let mut nonzero = Vec::new();
        let mut offsets = Vec::new();
        for (r, row) in rows.into_iter().enumerate() {
            offsets.push(indices.len() as i64);
            for (i, v) in row {
                if i as usize >= width {
                    return Err(ModelError::Index {
                        row: r,
                        index: i as usize,
                        width,
                    });
                }
                if !v.is_finite() {
                    return Err(ModelError::NonFinite(format!("observation {r} value {i}")));
                }
                indices.push(i64::from(i));
                nonzero.push(v);
            }
        }
        Ok(Self::from_parts(&indices, &nonzero, &offsets, width))
    }

    /// The rows whose `r`th holds `values[offsets[r]..offsets[r + 1]]` at
    /// columns `indices[..]` (the last up to the end).
    fn from_parts(indices: &[i64], values: &[f32], offsets: &[i64], width: usize) -> Self {
        Self {
            indices: Tensor::from_slice(indices),
            values: Tensor::from_slice(values),
            offsets: Tensor::from_slice(offsets),
            rows: offsets.len() as i64,
            width: width as i64,
        }
    }

    /// Non-zero values in the batch.
    pub fn nonzero(&self) -> usize {
        self.indices.numel()
    }

    /// The same rows with their tensors on `device` (shallow copies where
    /// they are there already).
    pub fn to_device(&self, device: Device) -> Self {
        Self {
            indices: self.indices.to_device(device),
            values: self.values.to_device(device),
            offsets: self.offsets.to_device(device),
            rows: self.rows,
            width: self.width,
        }
    }

    /// The rows as a dense `[rows, width]` tensor, on the device of the
    /// rows' tensors.
    pub fn to_dense(&self) -> Tensor {
        let device = self.values.device();
        if self.rows == 0 {
            return Tensor::zeros([0, self.width], (Kind::Float, device));
        }
        let counts = Tensor::cat(
            &[
                self.offsets.narrow(0, 1, self.rows - 1),
                Tensor::from_slice(&[self.indices.numel() as i64]).to_device(device),
            ],
            0,
        ) - &self.offsets;
        let row_of = Tensor::arange(self.rows, (Kind::Int64, device))
            .repeat_interleave_self_tensor(&counts, 0, None);
        let flat = row_of * self.width + &self.indices;
        Tensor::zeros([self.rows * self.width], (Kind::Float, device))
            .index_put(&[Some(flat)], &self.values, false)
            .reshape([self.rows, self.width])
    }
}

impl Observations {
    /// `rows` observations of `spec`'s input width, back to back in
    /// `values`, in the form `spec`'s network reads fastest: sparse for an
    /// MLP trunk with hidden layers (its first layer sums the weight rows
    /// of the non-zero inputs), dense otherwise. Panics if `values` is not
    /// `rows` observations long.
    pub fn new(spec: &NetworkSpec, values: &[f32], rows: usize) -> Self {
        let width = spec.input_len() as usize;
        if reads_sparse(spec) {
            Observations::Sparse(SparseRows::from_dense(values, rows, width))
        } else {
            assert_eq!(values.len(), rows * width, "rows * width values");
            Observations::Dense(Tensor::from_slice(values).reshape([rows as i64, width as i64]))
        }
    }

    /// Observations encoded with the observation codec (the replay's
    /// entries), one per item of `rows`, in the form `spec`'s network
    /// reads fastest: sparse entries go straight into
    /// [`SparseRows::from_pairs`] for a network that reads sparse rows,
    /// everything else is decoded into dense rows. Each entry is checked
    /// ([`codec::check`]); an error gives the position of the first bad
    /// one.
    pub fn from_encoded<'a>(
        spec: &NetworkSpec,
        encoding: ObservationEncoding,
        rows: impl ExactSizeIterator<Item = &'a [u8]>,
    ) -> Result<Self, (usize, CodecError)> {
        let width = spec.input_len() as usize;
        let n = rows.len();
        if reads_sparse(spec) && encoding == ObservationEncoding::SparseF32 {
            let (mut indices, mut values, mut offsets) = (Vec::new(), Vec::new(), Vec::new());
            for (r, bytes) in rows.enumerate() {
                codec::check(encoding, bytes, width).map_err(|e| (r, e))?;
                offsets.push(indices.len() as i64);
                for (i, v) in codec::sparse_pairs(bytes) {
                    indices.push(i64::from(i));
                    values.push(v);
                }
            }
            let sparse = SparseRows::from_parts(&indices, &values, &offsets, width);
            return Ok(Observations::Sparse(sparse));
        }
        let mut dense = vec![0f32; n * width];
        for ((r, bytes), out) in rows.enumerate().zip(dense.chunks_exact_mut(width.max(1))) {
            codec::decode_into(encoding, bytes, out).map_err(|e| (r, e))?;
        }
        Ok(Observations::new(spec, &dense, n))
    }

    /// Rows in the batch.
    pub fn rows(&self) -> i64 {
        match self {
            Observations::Dense(t) => t.size().first().copied().unwrap_or(0),
            Observations::Sparse(s) => s.rows,
        }
    }

    /// The same observations with their tensors on `device` (shallow
    /// copies where they are there already): what a network off the CPU
    /// reads.
    pub fn to_device(&self, device: Device) -> Self {
        match self {
            Observations::Dense(t) => Observations::Dense(t.to_device(device)),
            Observations::Sparse(s) => Observations::Sparse(s.to_device(device)),
        }
    }

    /// The batch as a dense `[rows, width]` tensor (a shallow copy of a
    /// dense one).
    pub fn to_dense(&self) -> Tensor {
        match self {
            Observations::Dense(t) => t.shallow_clone(),
            Observations::Sparse(s) => s.to_dense(),
        }
    }
}

/// Whether `spec`'s network reads [`Observations::Sparse`] without
/// densifying them: an MLP trunk with a hidden layer (its first layer is
/// the embedding bag); a conv trunk or bare heads read dense rows.
pub(crate) fn reads_sparse(spec: &NetworkSpec) -> bool {
    spec.trunk == TrunkKind::Mlp && !spec.hidden.is_empty()
}

impl From<Tensor> for Observations {
    fn from(t: Tensor) -> Self {
        Observations::Dense(t)
    }
}
