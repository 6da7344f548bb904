//! A forward pass through libtorch on CPU with known weights.

use crossroads_model::{DuelingMlp, MlpSpec};
use tch::{Device, Kind, Tensor, nn};

fn set(vs: &nn::VarStore, name: &str, values: &[f32], shape: &[i64]) {
    let vars = vs.variables();
    let var = vars
        .get(name)
        .unwrap_or_else(|| panic!("no variable {name}; have {:?}", vars.keys()));
    tch::no_grad(|| {
        let mut var = var.shallow_clone();
        var.copy_(&Tensor::from_slice(values).reshape(shape));
    });
}

#[test]
fn dueling_forward_matches_hand_computation() {
    let vs = nn::VarStore::new(Device::Cpu);
    let spec = MlpSpec {
        input: 2,
        hidden: vec![2],
        num_actions: 3,
    };
    let net = DuelingMlp::new(&vs.root(), spec).expect("valid spec");

    // trunk: h = relu(W x + b) with W = [[1, 2], [-1, 1]], b = [0, 0.5]
    set(&vs, "trunk.0.weight", &[1.0, 2.0, -1.0, 1.0], &[2, 2]);
    set(&vs, "trunk.0.bias", &[0.0, 0.5], &[2]);
    // value: V = [0.5, -1] . h + 1
    set(&vs, "value.weight", &[0.5, -1.0], &[1, 2]);
    set(&vs, "value.bias", &[1.0], &[1]);
    // advantage: A = [[1, 0], [0, 1], [1, 1]] h + [0, 0, -3]
    set(
        &vs,
        "advantage.weight",
        &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        &[3, 2],
    );
    set(&vs, "advantage.bias", &[0.0, 0.0, -3.0], &[3]);

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
}

#[test]
fn wrong_input_shape_is_an_error_naming_the_shape() {
    let vs = nn::VarStore::new(Device::Cpu);
    let spec = MlpSpec {
        input: 4,
        hidden: vec![8],
        num_actions: 5,
    };
    let net = DuelingMlp::new(&vs.root(), spec).expect("valid spec");
    let err = net
        .q_values(&Tensor::zeros([3, 7], (Kind::Float, Device::Cpu)))
        .expect_err("7 features instead of 4");
    assert!(err.to_string().contains("[batch, 4]"), "{err}");
    assert!(err.to_string().contains("[3, 7]"), "{err}");
}

#[test]
fn zero_width_spec_is_rejected() {
    let vs = nn::VarStore::new(Device::Cpu);
    let spec = MlpSpec {
        input: 4,
        hidden: vec![0],
        num_actions: 5,
    };
    assert!(DuelingMlp::new(&vs.root(), spec).is_err());
}
