//! [`NativeMlp`]: an MLP network's forward pass in plain Rust, for the
//! actor's batches of a few dozen observations.
//!
//! At those sizes libtorch's dispatch costs more than the arithmetic: an
//! actor's forward pass of the default network (2344-256-256 -> 5, 16 to
//! 32 observations) is some twenty operator calls, each checking,
//! allocating and dispatching, around one 256 x 256 product that takes a
//! fraction of the time (profiles: reports/performance/README.md, "Speed
//! work, before and after"). Here the first layer is the sum of the weight
//! rows of each observation's non-zero values (what the network's embedding
//! bag computes), the other layers and the heads one `sgemm` each
//! (`matrixmultiply` through `ndarray`, which picks AVX2/FMA at run time),
//! in buffers reused from call to call.
//!
//! A copy: [`NativeMlp::of`] reads the network's variables once, and the
//! owner makes a new copy when the weights change (the actor's
//! `LiveNetwork` does on each version it applies). f32 throughout; the
//! values equal libtorch's up to the order of float additions.

use crossroads_types::codec;
use ndarray::linalg::general_mat_mul;
use ndarray::{ArrayView2, ArrayViewMut2};
use tch::Tensor;

use crate::network::{FIRST_WEIGHT, QNetwork};
use crate::precision::Precision;
use crate::{ModelError, observations};

/// A dense layer: `weight` in PyTorch's `[outputs, inputs]` layout.
#[derive(Debug, Clone)]
struct Dense {
    weight: Vec<f32>,
    bias: Vec<f32>,
    inputs: usize,
    outputs: usize,
}

impl Dense {
    /// `out` (`n x outputs`) = `x` (`n x inputs`) times the weight's
    /// transpose, plus the bias.
    fn apply(&self, x: &[f32], n: usize, out: &mut Vec<f32>) -> Result<(), ModelError> {
        out.clear();
        for _ in 0..n {
            out.extend_from_slice(&self.bias);
        }
        let shape = |what: &[f32], cols: usize| ModelError::Shape {
            expected: cols as i64,
            got: vec![n as i64, (what.len() / n.max(1)) as i64],
        };
        let xs = ArrayView2::from_shape((n, self.inputs), x).map_err(|_| shape(x, self.inputs))?;
        let w = ArrayView2::from_shape((self.outputs, self.inputs), &self.weight)
            .map_err(|_| shape(&self.weight, self.inputs))?;
        let mut c =
            ArrayViewMut2::from_shape((n, self.outputs), out.as_mut_slice()).map_err(|_| {
                ModelError::Shape {
                    expected: self.outputs as i64,
                    got: vec![n as i64],
                }
            })?;
        general_mat_mul(1.0, &xs, &w.t(), 1.0, &mut c);
        Ok(())
    }
}

/// The forward pass of an MLP [`QNetwork`] (with at least one hidden
/// layer, computed in f32) over copies of its weights; see the module.
#[derive(Debug, Clone)]
pub struct NativeMlp {
    inputs: usize,
    /// The first layer's weight as the network stores it, `[inputs,
    /// width]`: one row per input value.
    first: Vec<f32>,
    first_bias: Vec<f32>,
    rest: Vec<Dense>,
    /// The value head's row, then the advantage head's.
    heads: Dense,
    actions: usize,
    /// Activations, reused between calls.
    a: Vec<f32>,
    b: Vec<f32>,
}

/// A variable's values, in the layout the network stores them.
fn values_of(net: &QNetwork, name: &str) -> Result<Vec<f32>, ModelError> {
    let t: Tensor = net
        .var_store()
        .variables()
        .remove(name)
        .ok_or_else(|| ModelError::Spec(format!("the network has no variable {name}")))?;
    Ok(Vec::<f32>::try_from(
        t.detach().contiguous().flatten(0, -1),
    )?)
}

/// A `[outputs, inputs]` layer from its variables `<prefix>.weight` and
/// `<prefix>.bias`.
fn dense_of(net: &QNetwork, prefix: &str, inputs: usize) -> Result<Dense, ModelError> {
    let weight = values_of(net, &format!("{prefix}.weight"))?;
    let bias = values_of(net, &format!("{prefix}.bias"))?;
    let outputs = bias.len();
    if weight.len() != outputs * inputs {
        return Err(ModelError::Spec(format!(
            "{prefix}.weight holds {} values, expected {outputs} x {inputs}",
            weight.len()
        )));
    }
    Ok(Dense {
        weight,
        bias,
        inputs,
        outputs,
    })
}

impl NativeMlp {
    /// A copy of `net`'s weights when it is what this pass computes: an MLP
    /// trunk with a hidden layer (the first layer reads sparse rows), in
    /// f32; `None` for any other network (a conv trunk, bf16), which keeps
    /// its libtorch forward pass.
    pub fn of(net: &QNetwork) -> Result<Option<Self>, ModelError> {
        let spec = net.spec();
        if !observations::reads_sparse(spec) || net.precision() != Precision::F32 {
            return Ok(None);
        }
        let inputs = spec.input_len() as usize;
        let first = values_of(net, FIRST_WEIGHT)?;
        let first_bias = values_of(net, "trunk.0.bias")?;
        let mut width = first_bias.len();
        if first.len() != inputs * width {
            return Err(ModelError::Spec(format!(
                "{FIRST_WEIGHT} holds {} values, expected {inputs} x {width}",
                first.len()
            )));
        }
        let mut rest = Vec::with_capacity(spec.hidden.len().saturating_sub(1));
        for i in 1..spec.hidden.len() {
            let layer = dense_of(net, &format!("trunk.{i}"), width)?;
            width = layer.outputs;
            rest.push(layer);
        }
        let value = dense_of(net, "value", width)?;
        let advantage = dense_of(net, "advantage", width)?;
        let actions = advantage.outputs;
        let heads = Dense {
            weight: [value.weight, advantage.weight].concat(),
            bias: [value.bias, advantage.bias].concat(),
            inputs: width,
            outputs: 1 + actions,
        };
        Ok(Some(Self {
            inputs,
            first,
            first_bias,
            rest,
            heads,
            actions,
            a: Vec::new(),
            b: Vec::new(),
        }))
    }

    /// Values in one observation.
    pub fn obs_len(&self) -> usize {
        self.inputs
    }

    /// Actions scored per observation.
    pub fn num_actions(&self) -> usize {
        self.actions
    }

    /// Q-values of observations given as their non-zero values (`(index,
    /// value)` per observation, each index once), written row-major into
    /// `out` (`rows.len() x actions`). Fails on an index beyond the
    /// observation and on NaN or infinite values, naming the row.
    pub fn q_values_sparse<R: AsRef<[(u32, f32)]>>(
        &mut self,
        rows: &[R],
        out: &mut [f32],
    ) -> Result<(), ModelError> {
        self.first_layer(rows)?;
        self.rest_and_heads(rows.len(), out)
    }

    /// Q-values of `n` dense observations back to back in `obs`; the first
    /// layer reads their non-zero values only.
    pub fn q_values(&mut self, obs: &[f32], n: usize, out: &mut [f32]) -> Result<(), ModelError> {
        let len = self.inputs;
        if n == 0 || obs.len() != n * len {
            return Err(ModelError::Shape {
                expected: len as i64,
                got: vec![n as i64, (obs.len() / n.max(1)) as i64],
            });
        }
        let rows: Vec<Vec<(u32, f32)>> = obs.chunks_exact(len).map(codec::nonzero_pairs).collect();
        self.q_values_sparse(&rows, out)
    }

    /// `a` = relu(first layer) of `rows`, each row's non-zero values.
    fn first_layer<R: AsRef<[(u32, f32)]>>(&mut self, rows: &[R]) -> Result<(), ModelError> {
        let width = self.first_bias.len();
        self.a.clear();
        self.a.reserve(rows.len() * width);
        for (row, pairs) in rows.iter().enumerate() {
            let start = self.a.len();
            self.a.extend_from_slice(&self.first_bias);
            let h = &mut self.a[start..];
            for &(index, value) in pairs.as_ref() {
                let i = index as usize;
                if i >= self.inputs {
                    return Err(ModelError::Index {
                        row,
                        index: i,
                        width: self.inputs,
                    });
                }
                if !value.is_finite() {
                    return Err(ModelError::NonFinite(format!(
                        "observation {row} value {index}"
                    )));
                }
                let w = &self.first[i * width..(i + 1) * width];
                for (h, w) in h.iter_mut().zip(w) {
                    *h += value * w;
                }
            }
            h.iter_mut().for_each(|v| *v = v.max(0.0));
        }
        Ok(())
    }

    /// From the first layer's activations in `a`: the other layers, the
    /// heads, and Q = V + A - mean A into `out`.
    fn rest_and_heads(&mut self, n: usize, out: &mut [f32]) -> Result<(), ModelError> {
        for layer in &self.rest {
            layer.apply(&self.a, n, &mut self.b)?;
            self.b.iter_mut().for_each(|v| *v = v.max(0.0));
            std::mem::swap(&mut self.a, &mut self.b);
        }
        self.heads.apply(&self.a, n, &mut self.b)?;
        let a = self.actions;
        let room = out.len();
        let out = out.get_mut(..n * a).ok_or_else(|| ModelError::Shape {
            expected: (n * a) as i64,
            got: vec![room as i64],
        })?;
        for (q, heads) in out.chunks_exact_mut(a).zip(self.b.chunks_exact(1 + a)) {
            let (value, advantage) = (heads[0], &heads[1..]);
            let mean = advantage.iter().sum::<f32>() / a as f32;
            for (q, adv) in q.iter_mut().zip(advantage) {
                *q = value + adv - mean;
            }
        }
        Ok(())
    }
}
