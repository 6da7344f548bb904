//! [`QNetwork`]: the dueling Q-network over an MLP or conv trunk, owning its
//! variables, with the batched inference actors use and the copies the
//! learner's target network needs.
//!
//! Every network is built on the CPU, from its seed, and the learner's
//! then moves to its device ([`QNetwork::new_on`]: the same seed gives the
//! same weights on any device). The trunk is an MLP, or 3x3
//! convolutions (stride 1, then 2) and one fully connected layer, with the
//! ego features joined after the convolutions. [`QNetwork::infer`] (dense
//! rows) and [`QNetwork::infer_sparse`] (each row's non-zero pairs) are the
//! actors' no-grad calls and refuse malformed or non-finite input;
//! [`QNetwork::copy_from`] and [`QNetwork::soft_update_from`] serve the
//! target network. On a device other than the CPU the forward passes move
//! their input there ([`QNetwork::q_values_of`]); weights files and what
//! [`QNetwork::infer`] returns are read back to the CPU. Outside the network
//! a variable has PyTorch's layout; an MLP's first weight is stored
//! transposed ([`QNetwork::file_layout`] turns a tensor between the two).

use crossroads_types::codec;
use tch::{Device, Kind, Tensor, nn, nn::Module};

use crate::ModelError;
use crate::observations::{self, Observations, SparseRows};
use crate::precision::Precision;
use crate::spec::{NetworkSpec, TrunkKind};
use crate::weights::{self, WeightsMeta};

/// The variable an MLP trunk's first layer stores transposed.
pub(crate) const FIRST_WEIGHT: &str = "trunk.0.weight";

/// The first layer of an MLP trunk. Its weight is stored transposed,
/// `[inputs, hidden]`, so that over sparse observations the layer is the
/// sum of the (contiguous) rows of the non-zero inputs times their values:
/// an embedding bag, which skips the zeros that make up nearly all of a
/// TTG observation (figures: reports/performance/README.md). Outside the
/// network (safetensors, optimizer state) the weight has PyTorch's
/// `[hidden, inputs]` layout; see [`QNetwork::file_layout`].
struct FirstLayer {
    weight_t: Tensor,
    bias: Tensor,
}

impl FirstLayer {
    /// Builds the layer under `path`, drawing the same initial values as
    /// `nn::linear` (bias, then a Kaiming-uniform weight over the inputs).
    fn new(path: nn::Path<'_>, inputs: i64, hidden: i64) -> Self {
        let bound = 1.0 / (inputs as f64).sqrt();
        let bias = path.var(
            "bias",
            &[hidden],
            nn::Init::Uniform {
                lo: -bound,
                up: bound,
            },
        );
        let weight = nn::init(
            nn::init::DEFAULT_KAIMING_UNIFORM,
            &[hidden, inputs],
            Device::Cpu,
        );
        let weight_t = path.var_copy("weight", &weight.tr().contiguous());
        Self { weight_t, bias }
    }

    fn forward(&self, obs: &Observations) -> Tensor {
        match obs {
            Observations::Dense(x) => self.bias.addmm(x, &self.weight_t),
            Observations::Sparse(s) => {
                let (sum, _, _, _) = Tensor::embedding_bag(
                    &self.weight_t,
                    &s.indices,
                    &s.offsets,
                    false,
                    0, // sum
                    false,
                    Some(&s.values),
                    false,
                );
                sum + &self.bias
            }
        }
    }
}

/// The trunk's layers, as built.
enum TrunkLayers {
    /// `first` is `None` when the MLP has no hidden layer.
    Mlp {
        first: Option<FirstLayer>,
        rest: Vec<nn::Linear>,
    },
    /// Each convolution with its stride (3x3 kernels, padding 1).
    Conv {
        convs: Vec<(nn::Conv2D, i64)>,
        fc: nn::Linear,
    },
}

/// A dueling Q-network: trunk, then value V(s) and advantage A(s, a) heads,
/// Q = V + A - mean_a A (Wang et al. 2016).
///
/// Variables are named `trunk.<i>.{weight,bias}` (`trunk.fc.*` after the
/// convolutions of a conv trunk), `value.*` and `advantage.*`; these are the
/// tensor names in the safetensors weights. Not `Sync`: one thread runs it
/// at a time; libtorch parallelizes each call over its intra-op threads.
pub struct QNetwork {
    spec: NetworkSpec,
    vs: nn::VarStore,
    trunk: TrunkLayers,
    value: nn::Linear,
    advantage: nn::Linear,
    precision: Precision,
    /// Where the variables are (the CPU unless [`QNetwork::new_on`] said
    /// otherwise).
    device: Device,
}

impl std::fmt::Debug for QNetwork {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QNetwork")
            .field("spec", &self.spec)
            .field("parameters", &self.num_parameters())
            .field("precision", &self.precision)
            .field("device", &self.device)
            .finish_non_exhaustive()
    }
}

/// Q-values of a batch from [`QNetwork::infer`], row-major
/// `[batch][num_actions]`.
#[derive(Debug, Clone, PartialEq)]
pub struct QBatch {
    /// The values.
    pub q: Vec<f32>,
    /// Actions per row.
    pub num_actions: usize,
}

impl QBatch {
    /// Row `i`'s Q-values.
    pub fn row(&self, i: usize) -> &[f32] {
        &self.q[i * self.num_actions..(i + 1) * self.num_actions]
    }

    /// Rows in the batch.
    pub fn len(&self) -> usize {
        self.q.len() / self.num_actions.max(1)
    }

    /// Whether the batch has no rows.
    pub fn is_empty(&self) -> bool {
        self.q.is_empty()
    }

    /// The greedy action of each row (the first of equal maxima).
    pub fn greedy(&self) -> Vec<u32> {
        (0..self.len())
            .map(|i| {
                let row = self.row(i);
                let mut best = 0;
                for (a, v) in row.iter().enumerate() {
                    if *v > row[best] {
                        best = a;
                    }
                }
                best as u32
            })
            .collect()
    }
}

fn conv_out(n: i64, stride: i64) -> i64 {
    // kernel 3, padding 1
    (n + 2 - 3) / stride + 1
}

impl QNetwork {
    /// A network of `spec` on the CPU, initialized from `seed` (the same
    /// seed gives the same weights).
    pub fn new(spec: NetworkSpec, seed: u64) -> Result<Self, ModelError> {
        Self::new_on(spec, seed, Device::Cpu)
    }

    /// A network of `spec` on `device` (the learner's, `runtime.device`),
    /// initialized from `seed` on the CPU and then moved, so that the same
    /// seed gives the same weights on every device.
    pub fn new_on(spec: NetworkSpec, seed: u64, device: Device) -> Result<Self, ModelError> {
        spec.validate()?;
        // libtorch's generator is global: seeding and drawing the initial
        // weights must not interleave with another thread's, or the same
        // seed would not give the same weights.
        static INIT: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _init = INIT
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        tch::manual_seed(seed as i64);
        let vs = nn::VarStore::new(Device::Cpu);
        let root = vs.root();
        let trunk_path = &root / "trunk";
        let (trunk, width) = match spec.trunk {
            TrunkKind::Mlp => {
                let mut width = spec.input_len();
                let first = spec.hidden.first().map(|&h| {
                    let layer = FirstLayer::new(&trunk_path / 0, width, h);
                    width = h;
                    layer
                });
                let mut rest = Vec::with_capacity(spec.hidden.len());
                for (i, &h) in spec.hidden.iter().enumerate().skip(1) {
                    rest.push(nn::linear(&trunk_path / i, width, h, Default::default()));
                    width = h;
                }
                (TrunkLayers::Mlp { first, rest }, width)
            }
            TrunkKind::Conv => {
                let o = &spec.observation;
                let (channels, fc_width) = spec.hidden.split_at(spec.hidden.len() - 1);
                let mut convs = Vec::with_capacity(channels.len());
                let (mut c, mut h, mut w) = (o.channels, o.rows, o.cols);
                for (i, &out) in channels.iter().enumerate() {
                    let stride = if i == 0 { 1 } else { 2 };
                    let config = nn::ConvConfig {
                        stride,
                        padding: 1,
                        ..Default::default()
                    };
                    convs.push((nn::conv2d(&trunk_path / i, c, out, 3, config), stride));
                    c = out;
                    h = conv_out(h, stride);
                    w = conv_out(w, stride);
                }
                let flat = c * h * w + o.extra;
                let fc = nn::linear(&trunk_path / "fc", flat, fc_width[0], Default::default());
                (TrunkLayers::Conv { convs, fc }, fc_width[0])
            }
        };
        let value = nn::linear(&root / "value", width, 1, Default::default());
        let advantage = nn::linear(
            &root / "advantage",
            width,
            spec.num_actions,
            Default::default(),
        );
        let mut net = Self {
            spec,
            vs,
            trunk,
            value,
            advantage,
            precision: Precision::F32,
            device: Device::Cpu,
        };
        if device != Device::Cpu {
            // Moves each variable's data in place: the layers' handles
            // share the variables, so they follow.
            net.vs.set_device(device);
            net.device = device;
        }
        Ok(net)
    }

    /// Where the variables are, and where the forward passes compute.
    pub fn device(&self) -> Device {
        self.device
    }

    /// The number format of the trunk (fp32 from [`QNetwork::new`]).
    pub fn precision(&self) -> Precision {
        self.precision
    }

    /// Computes the trunk in `precision` from now on; the variables stay
    /// fp32 (see [`Precision`]), so loading weights, copies and files do
    /// not change.
    pub fn set_precision(&mut self, precision: Precision) {
        self.precision = precision;
    }

    /// What this network is.
    pub fn spec(&self) -> &NetworkSpec {
        &self.spec
    }

    /// Its variables.
    pub fn var_store(&self) -> &nn::VarStore {
        &self.vs
    }

    /// Number of scalar parameters.
    pub fn num_parameters(&self) -> i64 {
        self.vs
            .trainable_variables()
            .iter()
            .map(Tensor::numel)
            .sum::<usize>() as i64
    }

    /// Every variable with its name, sorted by name, in the layout of the
    /// weights file (PyTorch's: the first MLP weight `[hidden, inputs]`),
    /// as every variable is seen outside the network (weights files,
    /// optimizer state in checkpoints).
    /// The tensors share memory with the variables.
    pub fn named_variables(&self) -> Vec<(String, Tensor)> {
        self.parameters()
            .into_iter()
            .map(|(name, t)| {
                let t = self.file_layout(&name, t);
                (name, t)
            })
            .collect()
    }

    /// Every variable with its name, sorted by name, as stored (what an
    /// optimizer updates in place; see [`QNetwork::file_layout`]).
    pub fn parameters(&self) -> Vec<(String, Tensor)> {
        let mut v: Vec<_> = self.vs.variables().into_iter().collect();
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    }

    /// Whether the first layer reads [`Observations::Sparse`] without
    /// densifying them (an MLP trunk with a hidden layer).
    pub fn reads_sparse(&self) -> bool {
        observations::reads_sparse(&self.spec)
    }

    /// Turns a tensor shaped like variable `name` between the layout the
    /// network stores it in and the weights file's (the same operation
    /// both ways): the first weight of an MLP trunk is stored transposed,
    /// `[inputs, hidden]`, for its sparse forward pass; every other
    /// variable is the same in both. For tensors that follow a variable's
    /// shape, such as an optimizer's state.
    pub fn file_layout(&self, name: &str, t: Tensor) -> Tensor {
        if self.reads_sparse() && name == FIRST_WEIGHT {
            t.tr()
        } else {
            t
        }
    }

    /// Q-values `[batch, num_actions]` for observations `[batch, input]`
    /// (f32). Records the graph for backpropagation unless called under
    /// `tch::no_grad`.
    pub fn q_values(&self, obs: &Tensor) -> Result<Tensor, ModelError> {
        self.q_values_of(&Observations::Dense(obs.shallow_clone()))
    }

    /// [`QNetwork::q_values`] of observations in either form (see
    /// [`Observations::new`] for the fast one). On a network off the CPU
    /// the observations are moved to its device first (a no-op where they
    /// are there already) and the Q-values are on that device.
    pub fn q_values_of(&self, obs: &Observations) -> Result<Tensor, ModelError> {
        self.check_input(obs)?;
        Ok(self.forward_on_device(obs))
    }

    /// [`QNetwork::forward`] of `obs` moved to the network's device; on
    /// the CPU, `obs` as it is.
    fn forward_on_device(&self, obs: &Observations) -> Tensor {
        if self.device == Device::Cpu {
            self.forward(obs)
        } else {
            self.forward(&obs.to_device(self.device))
        }
    }

    fn check_input(&self, obs: &Observations) -> Result<(), ModelError> {
        let input = self.spec.input_len();
        match obs {
            Observations::Dense(x) => {
                let size = x.size();
                if size.len() != 2 || size[1] != input {
                    return Err(ModelError::Shape {
                        expected: input,
                        got: size,
                    });
                }
                if x.kind() != Kind::Float {
                    return Err(ModelError::Kind(x.kind()));
                }
            }
            Observations::Sparse(s) => {
                if s.width != input {
                    return Err(ModelError::Shape {
                        expected: input,
                        got: vec![s.rows, s.width],
                    });
                }
            }
        }
        Ok(())
    }

    /// The two streams before they are combined: V(s) `[batch, 1]` and
    /// A(s, a) `[batch, num_actions]`; Q = V + A - mean_a A.
    pub fn streams(&self, obs: &Tensor) -> Result<(Tensor, Tensor), ModelError> {
        let obs = Observations::Dense(obs.shallow_clone());
        self.check_input(&obs)?;
        let obs = if self.device == Device::Cpu {
            obs
        } else {
            obs.to_device(self.device)
        };
        let h = self.trunk_features(&obs);
        Ok((self.value.forward(&h), self.advantage.forward(&h)))
    }

    fn forward(&self, obs: &Observations) -> Tensor {
        let h = self.trunk_features(obs);
        let value = self.value.forward(&h);
        let advantage = self.advantage.forward(&h);
        let mean = advantage.mean_dim(1, true, Kind::Float);
        value + advantage - mean
    }

    fn trunk_features(&self, obs: &Observations) -> Tensor {
        let h = match &self.trunk {
            TrunkLayers::Mlp { first, rest } => {
                let h = match first {
                    Some(first) => first.forward(obs).relu(),
                    None => obs.to_dense(),
                };
                rest.iter()
                    .fold(self.cast(h), |h, l| self.linear(l, &h).relu())
            }
            TrunkLayers::Conv { convs, fc } => {
                let obs = self.cast(obs.to_dense());
                let o = &self.spec.observation;
                let batch = obs.size()[0];
                let grid = obs
                    .narrow(1, 0, o.grid_len())
                    .reshape([batch, o.channels, o.rows, o.cols]);
                let maps = convs
                    .iter()
                    .fold(grid, |h, (conv, stride)| {
                        self.conv(conv, *stride, &h).relu()
                    })
                    .flatten(1, -1);
                let joined = if o.extra > 0 {
                    Tensor::cat(&[maps, obs.narrow(1, o.grid_len(), o.extra)], 1)
                } else {
                    maps
                };
                self.linear(fc, &joined).relu()
            }
        };
        h.to_kind(Kind::Float)
    }

    /// `x` in the trunk's number format.
    fn cast(&self, x: Tensor) -> Tensor {
        match self.precision {
            Precision::F32 => x,
            Precision::Bf16 => x.to_kind(Kind::BFloat16),
        }
    }

    /// A dense layer of the trunk, its weights cast to the trunk's format
    /// (`x` is in it already).
    fn linear(&self, layer: &nn::Linear, x: &Tensor) -> Tensor {
        match self.precision {
            Precision::F32 => layer.forward(x),
            Precision::Bf16 => x.linear(
                &layer.ws.to_kind(Kind::BFloat16),
                layer.bs.as_ref().map(|b| b.to_kind(Kind::BFloat16)),
            ),
        }
    }

    /// A 3x3 convolution of the trunk (padding 1), as
    /// [`QNetwork::linear`].
    fn conv(&self, layer: &nn::Conv2D, stride: i64, x: &Tensor) -> Tensor {
        match self.precision {
            Precision::F32 => layer.forward(x),
            Precision::Bf16 => x.conv2d(
                &layer.ws.to_kind(Kind::BFloat16),
                layer.bs.as_ref().map(|b| b.to_kind(Kind::BFloat16)),
                [stride; 2],
                [1, 1],
                [1, 1],
                1,
            ),
        }
    }

    /// Batched inference for actors: `obs` holds `batch` flat observations
    /// back to back; returns their Q-values. Runs without recording a graph,
    /// over the non-zero values only where the trunk allows
    /// ([`Observations::new`]). Fails on a wrong length and on NaN or
    /// infinite input.
    pub fn infer(&self, obs: &[f32], batch: usize) -> Result<QBatch, ModelError> {
        let input = self.spec.input_len() as usize;
        if batch == 0 || obs.len() != batch * input {
            return Err(ModelError::Shape {
                expected: self.spec.input_len(),
                got: vec![batch as i64, obs.len() as i64 / batch.max(1) as i64],
            });
        }
        let non_finite = |i: usize| {
            ModelError::NonFinite(format!("observation {} value {}", i / input, i % input))
        };
        let x = if self.reads_sparse() {
            Observations::Sparse(
                SparseRows::from_finite(obs, batch, input).map_err(|(i, _)| non_finite(i))?,
            )
        } else {
            if let Some(i) = obs.iter().position(|v| !v.is_finite()) {
                return Err(non_finite(i));
            }
            Observations::new(&self.spec, obs, batch)
        };
        self.infer_observations(&x)
    }

    /// [`QNetwork::infer`] of observations given as their non-zero values:
    /// one list of `(index, value)` per observation, each index once (what
    /// the simulators write, `Env::write_observation_sparse`). A network
    /// that reads sparse rows takes them as they are; any other gets them
    /// spread into dense rows. Fails on an index beyond the observation
    /// and on NaN or infinite values.
    pub fn infer_sparse<R: AsRef<[(u32, f32)]>>(&self, rows: &[R]) -> Result<QBatch, ModelError> {
        if rows.is_empty() {
            return Err(ModelError::Shape {
                expected: self.spec.input_len(),
                got: vec![0],
            });
        }
        let width = self.spec.input_len() as usize;
        if !self.reads_sparse() {
            // Dense rows straight from the pairs; `infer` checks the values.
            let mut dense = vec![0.0; rows.len() * width];
            for (r, (row, pairs)) in dense.chunks_exact_mut(width).zip(rows).enumerate() {
                if let Err(codec::CodecError::IndexRange { index, .. }) =
                    codec::spread_pairs(pairs.as_ref().iter().copied(), row)
                {
                    return Err(ModelError::Index {
                        row: r,
                        index: index as usize,
                        width,
                    });
                }
            }
            return self.infer(&dense, rows.len());
        }
        let sparse =
            SparseRows::from_pairs(rows.iter().map(|r| r.as_ref().iter().copied()), width)?;
        self.infer_observations(&Observations::Sparse(sparse))
    }

    fn infer_observations(&self, x: &Observations) -> Result<QBatch, ModelError> {
        // `Vec::try_from` copies from any device.
        let q = tch::no_grad(|| self.forward_on_device(x));
        let q = Vec::<f32>::try_from(q.flatten(0, -1))?;
        Ok(QBatch {
            q,
            num_actions: self.spec.num_actions as usize,
        })
    }

    /// Makes this network's variables equal to `other`'s (the hard target
    /// update). The specs must match.
    pub fn copy_from(&mut self, other: &QNetwork) -> Result<(), ModelError> {
        self.check_same(other)?;
        self.vs.copy(&other.vs)?;
        Ok(())
    }

    /// Moves every variable a fraction `tau` towards `other`'s:
    /// `self = (1 - tau) self + tau other` (the soft target update).
    pub fn soft_update_from(&mut self, other: &QNetwork, tau: f64) -> Result<(), ModelError> {
        self.check_same(other)?;
        let theirs = other.vs.variables();
        tch::no_grad(|| {
            for (name, mut mine) in self.vs.variables() {
                if let Some(t) = theirs.get(&name) {
                    let _ = mine.lerp_(t, tau);
                }
            }
        });
        Ok(())
    }

    fn check_same(&self, other: &QNetwork) -> Result<(), ModelError> {
        if self.spec != other.spec {
            return Err(ModelError::SpecMismatch {
                expected: Box::new(self.spec.clone()),
                got: Box::new(other.spec.clone()),
            });
        }
        Ok(())
    }

    /// The weights as safetensors bytes, with the spec and `version` in the
    /// file's metadata (see [`crate::weights`]); the same bytes whatever
    /// the device (the values are read back to the CPU).
    pub fn to_safetensors(&self, version: u64) -> Result<Vec<u8>, ModelError> {
        let meta = WeightsMeta {
            version,
            spec: self.spec.clone(),
        };
        weights::encode(&self.named_variables(), &meta.to_metadata()?)
    }

    /// A network built from safetensors bytes written by
    /// [`QNetwork::to_safetensors`]; returns it and the weights' version.
    pub fn from_safetensors(bytes: &[u8]) -> Result<(Self, u64), ModelError> {
        let (metadata, _) = weights::decode(bytes)?;
        let meta = WeightsMeta::from_metadata(&metadata)?;
        let mut net = Self::new(meta.spec, 0)?;
        let version = net.load_safetensors(bytes)?;
        Ok((net, version))
    }

    /// Loads weights into this network, on whatever device it is; returns
    /// their version. The file's spec must equal this network's, and its
    /// tensors must be exactly this network's, with the same shapes and
    /// finite values; nothing changes when any check fails.
    pub fn load_safetensors(&mut self, bytes: &[u8]) -> Result<u64, ModelError> {
        let (metadata, tensors) = weights::decode(bytes)?;
        let meta = WeightsMeta::from_metadata(&metadata)?;
        if meta.spec != self.spec {
            return Err(ModelError::SpecMismatch {
                expected: Box::new(self.spec.clone()),
                got: Box::new(meta.spec),
            });
        }
        self.assign(tensors)?;
        Ok(meta.version)
    }

    /// Sets every variable from `tensors` (name, value), which must name
    /// each variable once with its shape and hold finite values. All or
    /// nothing.
    pub fn assign(&mut self, tensors: Vec<(String, Tensor)>) -> Result<(), ModelError> {
        let vars = self
            .named_variables()
            .into_iter()
            .collect::<std::collections::HashMap<_, _>>();
        weights::assign(&vars, tensors)
    }
}
