//! The update rules as one pass over each parameter's memory: the values
//! of the gradient, the parameter and its state slots are read once and
//! written once, where the same rule as tensor operations makes about a
//! dozen passes and as many temporaries.
//!
//! `with_slices` holds the workspace's one `#[allow(unsafe_code)]`
//! outside build scripts: it makes slices only of dense, contiguous f32 CPU
//! tensors of one size whose memory does not overlap, and refuses anything
//! else (parameters off the CPU take the optimizer's tensor-operation step
//! instead, `Optimizer::step`).

use tch::{Device, Kind, Tensor};

use super::OptimizerConfig;

/// Runs `f` on the values of `read` and of each of `write`, which must all
/// be dense f32 CPU tensors of one size, with no two sharing memory; `None`
/// (and `f` not run) when one is not. The one place of the learner that
/// reads tensor memory directly (the workspace denies `unsafe` elsewhere).
#[allow(unsafe_code)]
pub(super) fn with_slices<R>(
    read: &Tensor,
    write: &mut [&mut Tensor],
    f: impl FnOnce(&[f32], &mut [&mut [f32]]) -> R,
) -> Option<R> {
    let n = read.numel();
    let dense = |t: &Tensor| t.defined() && t.kind() == Kind::Float && t.device() == Device::Cpu;
    let all = std::iter::once(read).chain(write.iter().map(|t| &**t));
    let mut ranges = Vec::with_capacity(write.len() + 1);
    for t in all {
        if !dense(t) || !t.is_contiguous() || t.numel() != n {
            return None;
        }
        let start = t.data_ptr() as usize;
        ranges.push((start, start + n * size_of::<f32>()));
    }
    if n == 0 {
        let mut empty: Vec<&mut [f32]> = write.iter().map(|_| Default::default()).collect();
        return Some(f(&[], &mut empty));
    }
    ranges.sort_unstable();
    if ranges.windows(2).any(|w| w[1].0 < w[0].1) {
        return None;
    }
    // SAFETY: each tensor is a defined, contiguous f32 CPU tensor of `n`
    // values (checked above), so its data pointer addresses `n` aligned,
    // initialized f32s that stay alive while the tensors are borrowed,
    // which they are for this whole call. The ranges do not overlap
    // (checked above), so the one shared slice and the mutable ones never
    // alias. Tensors here belong to the optimizer's owner, the training
    // thread; no other thread reads or writes them meanwhile.
    let read = unsafe { std::slice::from_raw_parts(read.data_ptr() as *const f32, n) };
    let mut write: Vec<&mut [f32]> = write
        .iter()
        .map(|t| unsafe { std::slice::from_raw_parts_mut(t.data_ptr() as *mut f32, n) })
        .collect();
    Some(f(read, &mut write))
}

/// The sum of the squares of `g`, accumulated in f64.
pub(super) fn sum_of_squares(g: &[f32]) -> f64 {
    // f32 partial sums over short runs (vectorized), added up in f64.
    g.chunks(256)
        .map(|c| f64::from(c.iter().map(|v| v * v).sum::<f32>()))
        .sum()
}

/// One step of an optimizer with its constants worked out.
#[derive(Debug, Clone, Copy)]
pub(super) enum Rule {
    /// `v += (1 - decay)(g^2 - v); p -= lr g / (sqrt(v) + eps)`.
    Rmsprop { lr: f32, decay: f32, eps: f32 },
    /// `m += (1 - b1)(g - m); v += (1 - b2)(g^2 - v);
    /// p -= lr / (1 - b1^t) m / (sqrt(v) / sqrt(1 - b2^t) + eps)`.
    Adam {
        step_size: f32,
        beta1: f32,
        beta2: f32,
        root_correction: f32,
        eps: f32,
    },
}

impl Rule {
    /// The rule of `config` for step `t` (1 for the first).
    pub(super) fn new(config: OptimizerConfig, t: u64) -> Self {
        match config {
            OptimizerConfig::Rmsprop { lr, decay, eps } => Rule::Rmsprop {
                lr: lr as f32,
                decay: decay as f32,
                eps: eps as f32,
            },
            OptimizerConfig::Adam {
                lr,
                beta1,
                beta2,
                eps,
            } => {
                let t = i32::try_from(t).unwrap_or(i32::MAX);
                Rule::Adam {
                    step_size: (lr / (1.0 - beta1.powi(t))) as f32,
                    beta1: beta1 as f32,
                    beta2: beta2 as f32,
                    root_correction: (1.0 / (1.0 - beta2.powi(t)).sqrt()) as f32,
                    eps: eps as f32,
                }
            }
        }
    }

    /// Applies the rule to one parameter: `state` is the parameter's
    /// values then its slots (RMSProp: the square average; Adam: the two
    /// moments), `g` its gradient, multiplied by `scale` first.
    pub(super) fn apply(&self, g: &[f32], scale: f32, state: &mut [&mut [f32]]) {
        match (*self, state) {
            (Rule::Rmsprop { lr, decay, eps }, [p, sq]) => {
                for ((p, sq), g) in p.iter_mut().zip(sq.iter_mut()).zip(g) {
                    let g = g * scale;
                    *sq += (1.0 - decay) * (g * g - *sq);
                    *p -= lr * g / (sq.sqrt() + eps);
                }
            }
            (
                Rule::Adam {
                    step_size,
                    beta1,
                    beta2,
                    root_correction,
                    eps,
                },
                [p, m, v],
            ) => {
                for (((p, m), v), g) in p.iter_mut().zip(m.iter_mut()).zip(v.iter_mut()).zip(g) {
                    let g = g * scale;
                    *m += (1.0 - beta1) * (g - *m);
                    *v += (1.0 - beta2) * (g * g - *v);
                    *p -= step_size * *m / (v.sqrt() * root_correction + eps);
                }
            }
            (rule, state) => {
                debug_assert!(false, "{rule:?} with {} state slices", state.len());
            }
        }
    }
}
