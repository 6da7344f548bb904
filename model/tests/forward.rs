//! A forward pass through libtorch on CPU with known weights.

use crossroads_model::{
    NativeMlp, NetworkSpec, ObservationLayout, Observations, Precision, QNetwork, TrunkKind,
    weights,
};
use tch::{Device, Kind, Tensor};

/// Sets variable `name` to `values` in the weights file's layout (PyTorch's:
/// a linear weight is `[out, in]`), through the network's views.
fn set(net: &QNetwork, name: &str, values: &[f32], shape: &[i64]) {
    let vars: std::collections::HashMap<_, _> = net.named_variables().into_iter().collect();
    let var = vars
        .get(name)
        .unwrap_or_else(|| panic!("no variable {name}; have {:?}", vars.keys()));
    tch::no_grad(|| {
        let mut var = var.shallow_clone();
        var.copy_(&Tensor::from_slice(values).reshape(shape));
    });
}

/// A grid of 5 x 18 x 26 and 4 dense values: a large, mostly empty input
/// like the simulator's TTG view. The sizes are this test's own (the
/// simulator's are in `crossroads_sim`): the model reads whatever layout
/// it is given.
fn large() -> ObservationLayout {
    ObservationLayout::new("large", 5, 18, 26, 4)
}

/// A small grid of 6 x 5 x 11 and 4 dense values.
fn small() -> ObservationLayout {
    ObservationLayout::new("small", 6, 5, 11, 4)
}

/// An MLP over `inputs` plain values (no grid, no ego features).
fn plain_mlp(inputs: i64, hidden: Vec<i64>, num_actions: i64) -> NetworkSpec {
    NetworkSpec {
        observation: ObservationLayout {
            kind: "plain".to_owned(),
            channels: 1,
            rows: 1,
            cols: inputs,
            extra: 0,
        },
        action_set: "plain".to_owned(),
        num_actions,
        trunk: TrunkKind::Mlp,
        hidden,
    }
}

#[test]
fn dueling_forward_matches_hand_computation() {
    let net = QNetwork::new(plain_mlp(2, vec![2], 3), 0).expect("valid spec");

    // trunk: h = relu(W x + b) with W = [[1, 2], [-1, 1]], b = [0, 0.5]
    set(&net, "trunk.0.weight", &[1.0, 2.0, -1.0, 1.0], &[2, 2]);
    set(&net, "trunk.0.bias", &[0.0, 0.5], &[2]);
    // value: V = [0.5, -1] . h + 1
    set(&net, "value.weight", &[0.5, -1.0], &[1, 2]);
    set(&net, "value.bias", &[1.0], &[1]);
    // advantage: A = [[1, 0], [0, 1], [1, 1]] h + [0, 0, -3]
    set(
        &net,
        "advantage.weight",
        &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        &[3, 2],
    );
    set(&net, "advantage.bias", &[0.0, 0.0, -3.0], &[3]);

    // x = [1, 1]:  h = relu([3, 0.5]) = [3, 0.5]; V = 1.5 - 0.5 + 1 = 2
    //   A = [3, 0.5, 0.5], mean 4/3; Q = 2 + A - 4/3 = [11/3, 7/6, 7/6]
    // x = [2, -1]: h = relu([0, -2.5]) = [0, 0]; V = 1
    //   A = [0, 0, -3], mean -1; Q = 1 + A + 1 = [2, 2, -1]
    let x = Tensor::from_slice(&[1.0f32, 1.0, 2.0, -1.0]).reshape([2, 2]);
    let q = net.q_values(&x).expect("forward");
    assert_eq!(q.size(), vec![2, 3]);
    assert_eq!(q.kind(), Kind::Float);
    let got: Vec<f32> = Vec::try_from(q.flatten(0, -1)).expect("to vec");
    let want = [11.0 / 3.0, 7.0 / 6.0, 7.0 / 6.0, 2.0, 2.0, -1.0];
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-5, "got {got:?}, want {want:?}");
    }
    // Inference (the actors' call) gives the same values.
    let batch = net.infer(&[1.0, 1.0, 2.0, -1.0], 2).expect("infer");
    for (g, w) in batch.row(0).iter().chain(batch.row(1)).zip(want) {
        assert!((g - w).abs() < 1e-5, "infer: got {g}, want {w}");
    }
}

#[test]
fn wrong_input_shape_is_an_error_naming_the_shape() {
    let net = QNetwork::new(plain_mlp(4, vec![8], 5), 0).expect("valid spec");
    let err = net
        .q_values(&Tensor::zeros([3, 7], (Kind::Float, Device::Cpu)))
        .expect_err("7 features instead of 4");
    assert!(err.to_string().contains("[batch, 4]"), "{err}");
    assert!(err.to_string().contains("[3, 7]"), "{err}");
}

#[test]
fn zero_width_spec_is_rejected() {
    let err = QNetwork::new(plain_mlp(4, vec![0], 5), 0).expect_err("a layer of width 0");
    assert!(err.to_string().contains("hidden sizes"), "{err}");
}

mod qnetwork {
    use crossroads_model::{
        ModelError, NetworkSpec, ObservationLayout, QNetwork, TrunkKind, weights,
    };

    use super::{large, small};
    use tch::{Kind, Tensor};

    /// Observations in [0, 1) from `seed`, without libtorch's global
    /// generator (other tests seed it concurrently).
    fn obs(spec: &NetworkSpec, batch: i64, seed: i64) -> Tensor {
        let n = (batch * spec.input_len()) as usize;
        let mut state = (seed as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let values: Vec<f32> = (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect();
        Tensor::from_slice(&values).reshape([batch, spec.input_len()])
    }

    /// Grids of several shapes (one odd, one without dense values) and
    /// every action set, each with both trunks.
    fn specs() -> Vec<NetworkSpec> {
        let layouts = [
            large(),
            ObservationLayout::new("large-occluded", 6, 18, 26, 4),
            small(),
            ObservationLayout::new("odd", 2, 3, 7, 0),
        ];
        let mut out = Vec::new();
        for layout in layouts {
            for actions in ["ttg", "sequential", "creep"] {
                out.push(
                    NetworkSpec::new(layout.clone(), actions, TrunkKind::Mlp, vec![32, 16])
                        .expect("test setup"),
                );
                out.push(
                    NetworkSpec::new(layout.clone(), actions, TrunkKind::Conv, vec![4, 8, 16])
                        .expect("test setup"),
                );
            }
        }
        out
    }

    #[test]
    fn every_layout_and_action_set_has_a_network_of_each_trunk() {
        for spec in specs() {
            let net = QNetwork::new(spec.clone(), 3).unwrap();
            let q = net.q_values(&obs(&spec, 5, 1)).unwrap();
            assert_eq!(q.size(), vec![5, spec.num_actions], "{spec:?}");
            let flat: Vec<f32> = Vec::try_from(obs(&spec, 2, 2).flatten(0, -1)).unwrap();
            let batch = net.infer(&flat, 2).unwrap();
            assert_eq!(batch.len(), 2);
            assert_eq!(batch.row(1).len(), spec.num_actions as usize);
            assert!(
                batch
                    .greedy()
                    .iter()
                    .all(|&a| (a as i64) < spec.num_actions)
            );
        }
    }

    #[test]
    fn dueling_identity_holds_for_both_trunks() {
        // Q = V + A - mean_a A, so mean_a Q = V and Q - mean_a Q = A - mean_a A.
        for trunk in [TrunkKind::Mlp, TrunkKind::Conv] {
            let hidden = if trunk == TrunkKind::Mlp {
                vec![64]
            } else {
                vec![8, 8, 32]
            };
            let spec = NetworkSpec::new(small(), "sequential", trunk, hidden).unwrap();
            let net = QNetwork::new(spec.clone(), 9).unwrap();
            let x = obs(&spec, 7, 4);
            let q = net.q_values(&x).unwrap();
            let (v, a) = net.streams(&x).unwrap();
            assert_eq!(v.size(), vec![7, 1]);
            let q_mean = q.mean_dim(1, true, Kind::Float);
            let a_centered = &a - a.mean_dim(1, true, Kind::Float);
            let err_v = (&q_mean - &v).abs().max().double_value(&[]);
            let err_a = (&q - &q_mean - a_centered).abs().max().double_value(&[]);
            assert!(err_v < 1e-5, "{trunk:?}: mean Q differs from V by {err_v}");
            assert!(
                err_a < 1e-5,
                "{trunk:?}: centred Q differs from centred A by {err_a}"
            );
            // A constant added to every advantage leaves Q unchanged.
            let (_, a2) = net.streams(&x).unwrap();
            let q_shifted = &v + (&a2 + 3.5) - (&a2 + 3.5).mean_dim(1, true, Kind::Float);
            assert!((q_shifted - &q).abs().max().double_value(&[]) < 1e-5);
        }
    }

    #[test]
    fn safetensors_round_trip_gives_bit_identical_q_values() {
        for spec in [
            NetworkSpec::new(large(), "ttg", TrunkKind::Mlp, vec![64, 32]).unwrap(),
            NetworkSpec::new(
                ObservationLayout::new("large-occluded", 6, 18, 26, 4),
                "creep",
                TrunkKind::Conv,
                vec![8, 16, 32],
            )
            .unwrap(),
        ] {
            let net = QNetwork::new(spec.clone(), 5).unwrap();
            let bytes = net.to_safetensors(42).unwrap();
            let (back, version) = QNetwork::from_safetensors(&bytes).unwrap();
            assert_eq!(version, 42);
            assert_eq!(back.spec(), &spec);
            let x = obs(&spec, 16, 8);
            let a: Vec<f32> = Vec::try_from(net.q_values(&x).unwrap().flatten(0, -1)).unwrap();
            let b: Vec<f32> = Vec::try_from(back.q_values(&x).unwrap().flatten(0, -1)).unwrap();
            let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a), bits(&b));
        }
    }

    #[test]
    fn weights_carry_names_shapes_spec_and_version() {
        let spec = NetworkSpec::new(large(), "ttg", TrunkKind::Mlp, vec![256, 256]).unwrap();
        let net = QNetwork::new(spec.clone(), 1).unwrap();
        let (meta, tensors) = weights::decode(&net.to_safetensors(7).unwrap()).unwrap();
        assert_eq!(meta["format"], weights::FORMAT);
        assert_eq!(meta["weights_version"], "7");
        let mut names: Vec<(String, Vec<i64>)> =
            tensors.iter().map(|(n, t)| (n.clone(), t.size())).collect();
        names.sort();
        assert_eq!(
            names,
            vec![
                ("advantage.bias".to_owned(), vec![5]),
                ("advantage.weight".to_owned(), vec![5, 256]),
                ("trunk.0.bias".to_owned(), vec![256]),
                ("trunk.0.weight".to_owned(), vec![256, 5 * 18 * 26 + 4]),
                ("trunk.1.bias".to_owned(), vec![256]),
                ("trunk.1.weight".to_owned(), vec![256, 256]),
                ("value.bias".to_owned(), vec![1]),
                ("value.weight".to_owned(), vec![1, 256]),
            ]
        );
    }

    #[test]
    fn bad_weights_are_refused_and_leave_the_network_unchanged() {
        let spec = NetworkSpec::new(small(), "sequential", TrunkKind::Mlp, vec![16]).unwrap();
        let mut net = QNetwork::new(spec.clone(), 1).unwrap();
        let x = obs(&spec, 3, 3);
        let before: Vec<f32> = Vec::try_from(net.q_values(&x).unwrap().flatten(0, -1)).unwrap();

        let other = NetworkSpec::new(small(), "creep", TrunkKind::Mlp, vec![16]).unwrap();
        let bytes = QNetwork::new(other, 1).unwrap().to_safetensors(1).unwrap();
        let err = net.load_safetensors(&bytes).unwrap_err();
        assert!(matches!(err, ModelError::SpecMismatch { .. }), "{err}");

        let err = net.load_safetensors(b"not a safetensors file").unwrap_err();
        assert!(err.to_string().contains("invalid weights file"), "{err}");

        // NaN in one tensor.
        let mut tensors = net.named_variables();
        let (meta, _) = weights::decode(&net.to_safetensors(2).unwrap()).unwrap();
        tensors[0].1 = tensors[0].1.full_like(f64::NAN);
        let nan = weights::encode(&tensors, &meta).unwrap();
        let err = net.load_safetensors(&nan).unwrap_err();
        assert!(err.to_string().contains("NaN"), "{err}");

        // A missing tensor.
        let short = weights::encode(&net.named_variables()[1..], &meta).unwrap();
        let err = net.load_safetensors(&short).unwrap_err();
        assert!(err.to_string().contains("missing"), "{err}");

        let after: Vec<f32> = Vec::try_from(net.q_values(&x).unwrap().flatten(0, -1)).unwrap();
        assert_eq!(before, after);
    }

    #[test]
    fn inference_rejects_wrong_lengths_and_non_finite_input() {
        let spec = NetworkSpec::new(small(), "ttg", TrunkKind::Mlp, vec![8]).unwrap();
        let net = QNetwork::new(spec.clone(), 1).unwrap();
        let n = spec.input_len() as usize;
        let err = net.infer(&vec![0.0; n * 2 - 1], 2).unwrap_err();
        assert!(matches!(err, ModelError::Shape { .. }), "{err}");
        let mut x = vec![0.0; n * 2];
        x[n + 3] = f32::NAN;
        let err = net.infer(&x, 2).unwrap_err();
        assert_eq!(
            err.to_string(),
            "observation 1 value 3 holds NaN or infinite values"
        );
        let err = net
            .q_values(&Tensor::zeros(
                [2, spec.input_len()],
                (Kind::Double, tch::Device::Cpu),
            ))
            .unwrap_err();
        assert!(matches!(err, ModelError::Kind(Kind::Double)), "{err}");
    }

    #[test]
    fn invalid_specs_name_the_problem() {
        let err = NetworkSpec::new(large(), "ttg", TrunkKind::Conv, vec![16]).unwrap_err();
        assert!(err.to_string().contains("conv trunk"), "{err}");
        let no_rows = ObservationLayout::new("large", 5, 0, 26, 4);
        let err = NetworkSpec::new(no_rows, "ttg", TrunkKind::Mlp, vec![16]).unwrap_err();
        assert!(
            err.to_string()
                .contains("observation dimensions must be positive: large [5x0x26 + 4]"),
            "{err}"
        );
        let err = NetworkSpec::new(large(), "left", TrunkKind::Mlp, vec![16]).unwrap_err();
        assert!(
            err.to_string().contains("unknown action set \"left\""),
            "{err}"
        );
    }

    #[test]
    fn soft_and_hard_updates_move_towards_the_source() {
        let spec = NetworkSpec::new(small(), "creep", TrunkKind::Mlp, vec![8]).unwrap();
        let online = QNetwork::new(spec.clone(), 1).unwrap();
        let mut target = QNetwork::new(spec.clone(), 2).unwrap();
        let x = obs(&spec, 4, 1);
        let dist = |a: &QNetwork, b: &QNetwork| {
            (a.q_values(&x).unwrap() - b.q_values(&x).unwrap())
                .abs()
                .sum(Kind::Float)
                .double_value(&[])
        };
        let d0 = dist(&online, &target);
        target.soft_update_from(&online, 0.5).unwrap();
        assert!(dist(&online, &target) < d0);
        target.copy_from(&online).unwrap();
        assert_eq!(dist(&online, &target), 0.0);
    }
}

/// Observations mostly zero (a row entirely), some negative values.
fn sparse_rows(inputs: usize, rows: usize) -> Vec<f32> {
    (0..rows * inputs)
        .map(|i| {
            let (r, c) = (i / inputs, i % inputs);
            if r == 1 || (c * 7 + r) % 5 != 0 {
                0.0
            } else {
                (c as f32 - 3.0) * 0.25
            }
        })
        .collect()
}

#[test]
fn sparse_and_dense_observations_give_the_same_q_values_and_gradients() {
    let net = QNetwork::new(plain_mlp(23, vec![8, 4], 3), 5).expect("valid spec");
    let rows = 4;
    let values = sparse_rows(23, rows);
    let sparse = Observations::new(net.spec(), &values, rows);
    assert!(matches!(sparse, Observations::Sparse(_)));
    let dense = Tensor::from_slice(&values).reshape([rows as i64, 23]);
    assert_eq!(
        Vec::<f32>::try_from(sparse.to_dense().flatten(0, -1)).unwrap(),
        values
    );

    let grads = |q: Tensor| {
        let params: Vec<Tensor> = net.parameters().into_iter().map(|(_, t)| t).collect();
        let loss = (&q * &q).sum(Kind::Float);
        Tensor::run_backward(&[loss], &params, false, false)
            .into_iter()
            .map(|g| Vec::<f32>::try_from(g.flatten(0, -1)).unwrap())
            .collect::<Vec<_>>()
    };
    let q_dense = net.q_values(&dense).unwrap();
    let q_sparse = net.q_values_of(&sparse).unwrap();
    let a: Vec<f32> = Vec::try_from(q_dense.flatten(0, -1)).unwrap();
    let b: Vec<f32> = Vec::try_from(q_sparse.flatten(0, -1)).unwrap();
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-5, "dense {a:?}, sparse {b:?}");
    }
    for (gd, gs) in grads(q_dense).iter().zip(grads(q_sparse)) {
        for (x, y) in gd.iter().zip(&gs) {
            assert!((x - y).abs() < 1e-4, "dense {gd:?}, sparse {gs:?}");
        }
    }
    // The actors' call reads the same observations sparse.
    let inferred = net.infer(&values, rows).unwrap();
    for (x, y) in inferred.q.iter().zip(&a) {
        assert!((x - y).abs() < 1e-5);
    }
}

#[test]
fn the_first_mlp_weight_keeps_pytorchs_layout_outside_the_network() {
    let net = QNetwork::new(plain_mlp(23, vec![8], 3), 9).expect("valid spec");
    // Stored transposed for the sparse pass ...
    let stored: std::collections::HashMap<_, _> = net.parameters().into_iter().collect();
    assert_eq!(stored["trunk.0.weight"].size(), vec![23, 8]);
    // ... [out, in] in the file, and the file's values are the layer's.
    let bytes = net.to_safetensors(1).unwrap();
    let (_, tensors) = weights::decode(&bytes).unwrap();
    let file: std::collections::HashMap<_, _> = tensors.into_iter().collect();
    let w = &file["trunk.0.weight"];
    assert_eq!(w.size(), vec![8, 23]);
    let x = Tensor::from_slice(&sparse_rows(23, 3)).reshape([3, 23]);
    let h = x.linear(w, Some(&file["trunk.0.bias"])).relu();
    let v = h.linear(&file["value.weight"], Some(&file["value.bias"]));
    let a = h.linear(&file["advantage.weight"], Some(&file["advantage.bias"]));
    let q = &v + &a - a.mean_dim(1, true, Kind::Float);
    let diff = (q - net.q_values(&x).unwrap())
        .abs()
        .max()
        .double_value(&[]);
    assert!(
        diff < 1e-5,
        "the file's weights give other Q-values: {diff}"
    );
    // The layout turn is its own inverse and leaves other variables alone.
    let t = Tensor::zeros([8, 23], (Kind::Float, Device::Cpu));
    assert_eq!(net.file_layout("trunk.0.weight", t).size(), vec![23, 8]);
    let t = Tensor::zeros([1, 8], (Kind::Float, Device::Cpu));
    assert_eq!(net.file_layout("value.weight", t).size(), vec![1, 8]);
}

/// A bf16 trunk computes what the fp32 one does to bf16's precision,
/// trains the fp32 variables (its gradients point the same way), and the
/// format survives loading weights.
#[test]
fn a_bf16_trunk_follows_the_fp32_one_over_fp32_variables() {
    for trunk in [TrunkKind::Conv, TrunkKind::Mlp] {
        let hidden = match trunk {
            TrunkKind::Conv => vec![4, 8, 32],
            TrunkKind::Mlp => vec![32, 16],
        };
        let spec = NetworkSpec::new(large(), "ttg", trunk, hidden).expect("valid spec");
        let f32_net = QNetwork::new(spec.clone(), 7).expect("network");
        let mut bf16_net = QNetwork::new(spec.clone(), 7).expect("network");
        bf16_net.set_precision(Precision::Bf16);
        assert_eq!(bf16_net.precision(), Precision::Bf16);
        let rows = 6;
        let values: Vec<f32> = sparse_rows(spec.input_len() as usize, rows)
            .into_iter()
            .map(|v| v.clamp(-1.0, 1.0))
            .collect();
        let x = Tensor::from_slice(&values).reshape([rows as i64, spec.input_len()]);

        let q32 = f32_net.q_values(&x).unwrap();
        let q16 = bf16_net.q_values(&x).unwrap();
        assert_eq!(q16.kind(), Kind::Float, "{trunk:?}: Q-values stay f32");
        let scale = q32.abs().max().double_value(&[]).max(1e-3);
        let diff = (&q32 - &q16).abs().max().double_value(&[]);
        assert!(diff > 0.0, "{trunk:?}: bf16 computed exactly fp32");
        assert!(diff < 0.03 * scale, "{trunk:?}: |dQ| {diff} of |Q| {scale}");

        let grads = |net: &QNetwork, q: Tensor| {
            let params: Vec<Tensor> = net.parameters().into_iter().map(|(_, t)| t).collect();
            Tensor::run_backward(&[(&q * &q).sum(Kind::Float)], &params, false, false)
        };
        for ((name, _), (g32, g16)) in f32_net
            .parameters()
            .iter()
            .zip(grads(&f32_net, q32).iter().zip(grads(&bf16_net, q16)))
        {
            assert_eq!(g16.kind(), Kind::Float, "{trunk:?} {name}");
            let (a, b) = (g32.flatten(0, -1), g16.flatten(0, -1));
            let norm = a.norm().double_value(&[]);
            if norm < 1e-6 {
                continue;
            }
            let cos = a.dot(&b).double_value(&[]) / (norm * b.norm().double_value(&[]));
            assert!(cos > 0.99, "{trunk:?} {name}: cosine {cos}");
        }

        let bytes = f32_net.to_safetensors(3).unwrap();
        bf16_net.load_safetensors(&bytes).unwrap();
        assert_eq!(bf16_net.precision(), Precision::Bf16);
        let flat: Vec<f32> = values.clone();
        let inferred = bf16_net.infer(&flat, rows).unwrap();
        let q16: Vec<f32> = Vec::try_from(bf16_net.q_values(&x).unwrap().flatten(0, -1)).unwrap();
        assert_eq!(inferred.q, q16, "{trunk:?}: infer runs the bf16 trunk");
    }
}

#[test]
fn auto_precision_is_bf16_only_for_training_a_conv_trunk_on_amx() {
    use crossroads_config::PrecisionSetting;
    use crossroads_model::Work;
    let conv = NetworkSpec::new(large(), "ttg", TrunkKind::Conv, vec![4, 8, 32]).unwrap();
    let mlp = NetworkSpec::new(large(), "ttg", TrunkKind::Mlp, vec![32]).unwrap();
    let amx = crossroads_model::cpu_has_amx_bf16();
    let expected = if amx { Precision::Bf16 } else { Precision::F32 };
    let auto = PrecisionSetting::Auto;
    assert_eq!(Precision::choose(auto, &conv, Work::Training), expected);
    assert_eq!(Precision::choose(auto, &conv, Work::Acting), Precision::F32);
    assert_eq!(
        Precision::choose(auto, &mlp, Work::Training),
        Precision::F32
    );
    for spec in [&conv, &mlp] {
        for work in [Work::Training, Work::Acting] {
            assert_eq!(
                Precision::choose(PrecisionSetting::F32, spec, work),
                Precision::F32
            );
            assert_eq!(
                Precision::choose(PrecisionSetting::Bf16, spec, work),
                Precision::Bf16
            );
        }
    }
}

/// The plain-Rust forward pass gives libtorch's Q-values (up to the order
/// of float additions) for one to three hidden layers, from pairs and from
/// dense rows, on the network's own weights and after they change; it
/// declines networks it does not compute and names bad input.
#[test]
fn the_native_mlp_gives_the_networks_q_values() {
    let close = |a: &[f32], b: &[f32], what: &str| {
        assert_eq!(a.len(), b.len(), "{what}");
        for (x, y) in a.iter().zip(b) {
            assert!(
                (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
                "{what}: {a:?} vs {b:?}"
            );
        }
    };
    for hidden in [vec![16], vec![32, 16], vec![24, 12, 8]] {
        let mut net = QNetwork::new(plain_mlp(41, hidden.clone(), 4), 9).expect("valid spec");
        let rows = 6;
        let values = sparse_rows(41, rows);
        let pairs: Vec<Vec<(u32, f32)>> = values
            .chunks_exact(41)
            .map(crossroads_types::codec::nonzero_pairs)
            .collect();
        for round in 0..2 {
            let expected = net.infer(&values, rows).expect("libtorch").q;
            let mut native = NativeMlp::of(&net).expect("copy").expect("an f32 MLP");
            assert_eq!((native.obs_len(), native.num_actions()), (41, 4));
            let mut q = vec![f32::NAN; rows * 4];
            native.q_values_sparse(&pairs, &mut q).expect("pairs");
            close(&q, &expected, &format!("{hidden:?} round {round}, pairs"));
            let mut q = vec![f32::NAN; rows * 4];
            native.q_values(&values, rows, &mut q).expect("dense");
            close(&q, &expected, &format!("{hidden:?} round {round}, dense"));
            // New weights (another seed's): a new copy follows them.
            let other = QNetwork::new(plain_mlp(41, hidden.clone(), 4), 10 + round).expect("spec");
            net.copy_from(&other).expect("same spec");
        }
        let mut native = NativeMlp::of(&net).expect("copy").expect("an f32 MLP");
        let mut q = vec![0.0; 2 * 4];
        let err = native
            .q_values_sparse(&[vec![(3, 1.0)], vec![(41, 1.0)]], &mut q)
            .expect_err("an index past the end");
        assert!(err.to_string().contains("observation 1"), "{err}");
        let err = native
            .q_values_sparse(&[vec![(3, f32::NAN)]], &mut q)
            .expect_err("NaN");
        assert!(err.to_string().contains("NaN"), "{err}");
        assert!(
            native.q_values(&values[..40], 1, &mut q).is_err(),
            "a short row"
        );
    }
    let conv = NetworkSpec::new(large(), "ttg", TrunkKind::Conv, vec![4, 8, 16]).expect("spec");
    let conv = QNetwork::new(conv, 1).expect("conv network");
    assert!(NativeMlp::of(&conv).expect("no copy").is_none(), "conv");
    let mut bf16 = QNetwork::new(plain_mlp(41, vec![16], 4), 1).expect("spec");
    bf16.set_precision(Precision::Bf16);
    assert!(NativeMlp::of(&bf16).expect("no copy").is_none(), "bf16");
    let linear = QNetwork::new(plain_mlp(41, vec![], 4), 1).expect("no hidden layer");
    assert!(
        NativeMlp::of(&linear).expect("no copy").is_none(),
        "no hidden layer"
    );
}

/// `runtime.device`: `cpu` is the CPU; `auto` is CUDA device 0 only where
/// libtorch has CUDA and sees a GPU; `cuda` without either is an error
/// naming which is missing. The first half reasons over stated support,
/// so it holds on any machine; the second asks this one.
#[test]
fn the_device_setting_resolves_to_the_cpu_or_names_what_is_missing() {
    use crossroads_config::DeviceSetting;
    use crossroads_model::{CudaSupport, device_name, resolve_device};
    let cpu_build = CudaSupport {
        built_with_cuda: false,
        devices: 0,
        cudnn: false,
    };
    let no_gpu = CudaSupport {
        built_with_cuda: true,
        devices: 0,
        cudnn: false,
    };
    let gpu = CudaSupport {
        built_with_cuda: true,
        devices: 2,
        cudnn: true,
    };
    for support in [cpu_build, no_gpu, gpu] {
        assert_eq!(support.resolve(DeviceSetting::Cpu).unwrap(), Device::Cpu);
    }
    assert_eq!(cpu_build.resolve(DeviceSetting::Auto).unwrap(), Device::Cpu);
    assert_eq!(no_gpu.resolve(DeviceSetting::Auto).unwrap(), Device::Cpu);
    assert_eq!(gpu.resolve(DeviceSetting::Auto).unwrap(), Device::Cuda(0));
    assert_eq!(gpu.resolve(DeviceSetting::Cuda).unwrap(), Device::Cuda(0));
    let err = cpu_build
        .resolve(DeviceSetting::Cuda)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("runtime.device = \"cuda\"") && err.contains("built without CUDA"),
        "{err}"
    );
    let err = no_gpu.resolve(DeviceSetting::Cuda).unwrap_err().to_string();
    assert!(
        err.contains("runtime.device = \"cuda\"") && err.contains("no CUDA device"),
        "{err}"
    );
    assert_eq!(device_name(Device::Cpu), "cpu");
    assert_eq!(device_name(Device::Cuda(0)), "cuda:0");

    // This machine.
    assert_eq!(resolve_device(DeviceSetting::Cpu).unwrap(), Device::Cpu);
    let here = CudaSupport::probe();
    assert_eq!(here.available(), tch::Cuda::is_available());
    if tch::Cuda::is_available() {
        assert_eq!(
            resolve_device(DeviceSetting::Auto).unwrap(),
            Device::Cuda(0)
        );
        assert_eq!(
            resolve_device(DeviceSetting::Cuda).unwrap(),
            Device::Cuda(0)
        );
    } else {
        assert_eq!(resolve_device(DeviceSetting::Auto).unwrap(), Device::Cpu);
        let err = resolve_device(DeviceSetting::Cuda).unwrap_err().to_string();
        let missing = if here.built_with_cuda {
            "no CUDA device"
        } else {
            "built without CUDA"
        };
        assert!(err.contains(missing), "{err}");
    }
}

/// On a CUDA learner `runtime.precision = "auto"` is fp32; an explicit
/// `bf16` stays; on the CPU the choice is [`Precision::choose`]'s.
#[test]
fn auto_precision_is_fp32_on_a_cuda_device() {
    use crossroads_config::PrecisionSetting;
    use crossroads_model::Work;
    let conv = NetworkSpec::new(large(), "ttg", TrunkKind::Conv, vec![4, 8, 32]).unwrap();
    for work in [Work::Training, Work::Acting] {
        for setting in [
            PrecisionSetting::Auto,
            PrecisionSetting::F32,
            PrecisionSetting::Bf16,
        ] {
            assert_eq!(
                Precision::choose_on(setting, &conv, work, Device::Cpu),
                Precision::choose(setting, &conv, work)
            );
        }
        let on_cuda = |setting| Precision::choose_on(setting, &conv, work, Device::Cuda(0));
        assert_eq!(on_cuda(PrecisionSetting::Auto), Precision::F32);
        assert_eq!(on_cuda(PrecisionSetting::F32), Precision::F32);
        assert_eq!(on_cuda(PrecisionSetting::Bf16), Precision::Bf16);
    }
}

/// A network built for the CPU device is the plain one: same weights from
/// the same seed, and observations "moved" to the CPU give the same
/// Q-values in either form.
#[test]
fn a_network_on_the_cpu_device_is_the_plain_one() {
    let spec = plain_mlp(23, vec![8, 4], 3);
    let plain = QNetwork::new(spec.clone(), 5).expect("valid spec");
    let on_cpu = QNetwork::new_on(spec, 5, Device::Cpu).expect("valid spec");
    assert_eq!(on_cpu.device(), Device::Cpu);
    assert_eq!(plain.device(), Device::Cpu);
    // Variable by variable: the bytes' header follows a hash map's order.
    assert_eq!(variables(&on_cpu), variables(&plain));
    let rows = 4;
    let values = sparse_rows(23, rows);
    let sparse = Observations::new(on_cpu.spec(), &values, rows);
    let dense = Observations::Dense(Tensor::from_slice(&values).reshape([rows as i64, 23]));
    let q = |obs: &Observations| -> Vec<f32> {
        Vec::try_from(on_cpu.q_values_of(obs).unwrap().flatten(0, -1)).unwrap()
    };
    let want = q(&sparse);
    for obs in [sparse.to_device(Device::Cpu), dense.to_device(Device::Cpu)] {
        for (x, y) in q(&obs).iter().zip(&want) {
            assert!((x - y).abs() < 1e-5, "{want:?}");
        }
    }
}

/// Whether a CUDA device is here to test on. Without one the test says why
/// on standard error and is skipped, unless CROSSROADS_REQUIRE_CUDA=1,
/// where it fails naming what is missing.
fn cuda_or_skip(test: &str) -> bool {
    if tch::Cuda::is_available() {
        return true;
    }
    let why = crossroads_model::resolve_device(crossroads_config::DeviceSetting::Cuda)
        .err()
        .map_or_else(|| "no CUDA device".to_owned(), |e| e.to_string());
    crossroads_test_support::gates::skip_unless_required(
        crossroads_test_support::Need::Cuda,
        &format!("{test} needs a CUDA device and a CUDA libtorch ({why})"),
    );
    false
}

/// On CUDA a network has the CPU's weights of the same seed (the same
/// weights file, byte for byte), computes the CPU's Q-values from
/// observations given on the CPU, and loads weights files.
#[test]
#[ignore = "needs a CUDA device and a CUDA libtorch: \
            CROSSROADS_REQUIRE_CUDA=1 cargo test -- --include-ignored"]
fn a_network_on_cuda_computes_what_the_cpu_one_does() {
    if !cuda_or_skip("a_network_on_cuda_computes_what_the_cpu_one_does") {
        return;
    }
    let cuda = Device::Cuda(0);
    for trunk in [TrunkKind::Mlp, TrunkKind::Conv] {
        let hidden = match trunk {
            TrunkKind::Conv => vec![4, 8, 32],
            TrunkKind::Mlp => vec![32, 16],
        };
        let spec = NetworkSpec::new(large(), "ttg", trunk, hidden).expect("valid spec");
        let cpu_net = QNetwork::new(spec.clone(), 7).expect("network");
        let mut gpu_net = QNetwork::new_on(spec.clone(), 7, cuda).expect("network");
        assert_eq!(gpu_net.device(), cuda);
        assert!(
            gpu_net.parameters().iter().all(|(_, t)| t.device() == cuda),
            "{trunk:?}: every variable on the GPU"
        );
        assert_eq!(
            gpu_net.to_safetensors(2).unwrap(),
            cpu_net.to_safetensors(2).unwrap(),
            "{trunk:?}: same seed, same weights file"
        );
        let rows = 6;
        let values: Vec<f32> = sparse_rows(spec.input_len() as usize, rows)
            .into_iter()
            .map(|v| v.clamp(-1.0, 1.0))
            .collect();
        let obs = Observations::new(&spec, &values, rows);
        let want: Vec<f32> =
            Vec::try_from(cpu_net.q_values_of(&obs).unwrap().flatten(0, -1)).unwrap();
        let q = gpu_net.q_values_of(&obs).unwrap();
        assert_eq!(q.device(), cuda);
        let got: Vec<f32> = Vec::try_from(q.to_device(Device::Cpu).flatten(0, -1)).unwrap();
        let inferred = gpu_net.infer(&values, rows).unwrap();
        // cuDNN may compute convolutions in TF32.
        for (what, got) in [("q_values_of", &got), ("infer", &inferred.q)] {
            for (x, y) in got.iter().zip(&want) {
                assert!(
                    (x - y).abs() < 1e-3 * y.abs().max(1.0),
                    "{trunk:?} {what}: {got:?}, CPU {want:?}"
                );
            }
        }
        // A file written on the CPU loads on the GPU and back.
        let other = QNetwork::new(spec.clone(), 8).expect("network");
        let bytes = other.to_safetensors(3).unwrap();
        assert_eq!(gpu_net.load_safetensors(&bytes).unwrap(), 3);
        assert_eq!(gpu_net.device(), cuda);
        // Variable by variable: the bytes' header follows a hash map's order.
        let (back, _) = QNetwork::from_safetensors(&gpu_net.to_safetensors(3).unwrap()).unwrap();
        assert_eq!(variables(&back), variables(&other));
    }
}

/// Every variable of `n` by name, its values on the CPU: what two networks
/// are compared by (the safetensors header follows a hash map's order, so
/// equal weights need not give equal bytes).
fn variables(n: &QNetwork) -> Vec<(String, Vec<f32>)> {
    n.parameters()
        .into_iter()
        .map(|(name, t)| {
            let v = Vec::<f32>::try_from(t.detach().to_device(Device::Cpu).flatten(0, -1))
                .expect("values");
            (name, v)
        })
        .collect()
}
