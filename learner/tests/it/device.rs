//! `runtime.device`: where the learner's networks go, the clear stop when
//! `cuda` cannot be met, the optimizer's step off the CPU (its rule as
//! tensor operations) against the fused one, and a CUDA trainer against
//! the CPU's. The CUDA test is ignored unless asked for (`cargo test --
//! --include-ignored`, as `make test` runs it); asked for without a CUDA
//! device it says why and returns, unless CROSSROADS_REQUIRE_CUDA=1, where
//! it fails naming what is missing.

use crossroads_common::Shutdown;
use crossroads_config::{Config, DeviceSetting, TargetUpdate};
use crossroads_learner::bench::{SplitMix, synthetic_batch, synthetic_observation};
use crossroads_learner::optimizer::{Optimizer, OptimizerConfig};
use crossroads_learner::{Trainer, TrainerConfig, TrainingBatch, UpdateStats};
use crossroads_model::{CudaSupport, NetworkSpec, QNetwork, TrunkKind, resolve_device};
use tch::{Device, Kind, Tensor};

const ADAM: OptimizerConfig = OptimizerConfig::Adam {
    lr: 1e-3,
    beta1: 0.9,
    beta2: 0.999,
    eps: 1e-8,
};

const RMSPROP: OptimizerConfig = OptimizerConfig::Rmsprop {
    lr: 1e-3,
    decay: 0.95,
    eps: 0.01,
};

fn mlp() -> NetworkSpec {
    crate::small_mlp()
}

fn conv() -> NetworkSpec {
    NetworkSpec::new(crate::layout("ttg"), "ttg", TrunkKind::Conv, vec![4, 8, 32])
        .expect("test setup")
}

fn config(spec: NetworkSpec, optimizer: OptimizerConfig) -> TrainerConfig {
    TrainerConfig {
        spec,
        seed: 5,
        optimizer,
        max_grad_norm: 1.0,
        huber_delta: 1.0,
        target_update: TargetUpdate::Period,
        target_period: 2,
        target_tau: 0.01,
        priority_eps: 1e-6,
        go_labels: None,
    }
}

fn batches(spec: &NetworkSpec, n: usize) -> Vec<TrainingBatch> {
    let mut rng = SplitMix::new(3);
    (0..n)
        .map(|i| {
            let b = synthetic_batch(spec, 32, &mut rng);
            let w: Vec<f32> = (0..b.len()).map(|j| 0.5 + (j % 3) as f32 * 0.25).collect();
            TrainingBatch::from_batch(
                &b,
                &w,
                (0..b.len() as u64).map(|k| k + 100 * i as u64).collect(),
                spec,
            )
            .expect("test setup")
        })
        .collect()
}

/// Every variable of `n` by name, with its values: what two networks are
/// compared by (the safetensors header follows a hash map's order).
fn variables(n: &QNetwork) -> Vec<(String, Vec<f32>)> {
    n.parameters()
        .into_iter()
        .map(|(name, t)| (name, values(&t.detach())))
        .collect()
}

fn values(t: &Tensor) -> Vec<f32> {
    Vec::try_from(t.to_device(Device::Cpu).flatten(0, -1).to_kind(Kind::Float)).expect("values")
}

/// `got` within `tol` of `want`, relative where the values exceed 1.
fn close(got: &[f32], want: &[f32], tol: f32, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (g, w) in got.iter().zip(want) {
        assert!(
            (g - w).abs() <= tol * w.abs().max(1.0),
            "{what}: got {got:?}, want {want:?}"
        );
    }
}

#[test]
fn cpu_and_auto_resolve_to_the_cpu_where_there_is_no_cuda() {
    assert_eq!(resolve_device(DeviceSetting::Cpu).unwrap(), Device::Cpu);
    let auto = resolve_device(DeviceSetting::Auto).unwrap();
    if tch::Cuda::is_available() {
        assert_eq!(auto, Device::Cuda(0));
    } else {
        assert_eq!(auto, Device::Cpu);
    }
}

/// `runtime.device = "cuda"` without CUDA stops the learner at start, with
/// an error that names what is missing and what to do.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cuda_without_cuda_stops_the_learner_at_start_naming_what_is_missing() {
    if tch::Cuda::is_available() {
        eprintln!("skipped: CUDA is available here, so runtime.device = \"cuda\" can be met");
        return;
    }
    let mut c = Config::default();
    c.learner.listen = ([127, 0, 0, 1], 0).into();
    crate::set_observation(&mut c.sim, "sequential");
    c.sim.action_set = "ttg".to_owned();
    c.learner.hidden = vec![32];
    c.learner.shm_publish = false;
    c.learner.checkpoint_dir = None;
    c.runtime.device = DeviceSetting::Cuda;
    let err = crossroads_learner::start(&c, None, Shutdown::new())
        .await
        .expect_err("no CUDA here");
    let message = err.to_string();
    let missing = if CudaSupport::probe().built_with_cuda {
        "no CUDA device"
    } else {
        "built without CUDA"
    };
    assert!(
        message.contains("runtime.device = \"cuda\"")
            && message.contains(missing)
            && message.contains("runtime.device = \"cpu\""),
        "{message}"
    );
}

/// The step a learner off the CPU takes (the rule as tensor operations on
/// the parameters' device) is the fused CPU pass's, clipped or not, and
/// leaves the same state.
#[test]
fn the_tensor_operation_step_matches_the_fused_one() {
    let g_of =
        |t: usize| Tensor::from_slice(&[0.5f32, -2.0, 1e-3, 3.0, -0.25, 0.0]) * (1.0 + t as f64);
    for config in [RMSPROP, ADAM] {
        for max_norm in [0.0, 1.0] {
            let start = [1.0f32, -1.0, 0.5, 2.0, 0.0, 3.0];
            let p = Tensor::from_slice(&start).set_requires_grad(true);
            let q = Tensor::from_slice(&start).set_requires_grad(true);
            let mut fused = Optimizer::new(config, vec![("p".to_owned(), p.shallow_clone())]);
            let mut ops =
                Optimizer::new(config, vec![("p".to_owned(), q.shallow_clone())]).unfused();
            assert!(fused.is_fused() && !ops.is_fused());
            for t in 1..=3 {
                let g = g_of(t);
                let grads = fused.gradients(&(&p * &g).sum(Kind::Float)).unwrap();
                let norm_fused = fused.step(&grads, max_norm).unwrap();
                let grads = ops.gradients(&(&q * &g).sum(Kind::Float)).unwrap();
                let norm_ops = ops.step(&grads, max_norm).unwrap();
                assert!(
                    (norm_fused - norm_ops).abs() < 1e-6 * norm_fused.max(1.0),
                    "{config:?}: norm {norm_fused} fused, {norm_ops} as tensor operations"
                );
            }
            let what = format!("{config:?}, max_norm {max_norm}");
            close(&values(&q.detach()), &values(&p.detach()), 1e-6, &what);
            let (a, steps_a) = fused.state();
            let (b, steps_b) = ops.state();
            assert_eq!(steps_a, steps_b);
            for ((name_a, a), (name_b, b)) in a.iter().zip(&b) {
                assert_eq!(name_a, name_b);
                assert_eq!(b.device(), Device::Cpu);
                close(&values(b), &values(a), 1e-6, &format!("{what}: {name_a}"));
            }
        }
    }
}

/// A trainer made for the CPU device is the plain one, update for update,
/// and a batch moved to the CPU is the batch.
#[test]
fn a_trainer_on_the_cpu_device_is_the_plain_one() {
    let spec = mlp();
    let mut plain = Trainer::new(config(spec.clone(), ADAM)).unwrap();
    let mut on_cpu = Trainer::new_on(config(spec.clone(), ADAM), Device::Cpu).unwrap();
    assert_eq!(on_cpu.device(), Device::Cpu);
    assert!(on_cpu.optimizer().is_fused());
    let bits = |s: &UpdateStats| {
        let mut v = vec![s.loss.to_bits(), s.grad_norm.to_bits()];
        v.extend(s.priorities.iter().map(|p| u64::from(p.to_bits())));
        v
    };
    for b in batches(&spec, 3) {
        let a = plain.update(&b).unwrap();
        let c = on_cpu.update(&b.to_device(Device::Cpu)).unwrap();
        assert_eq!(bits(&a), bits(&c));
    }
    // Variable by variable: the bytes' header follows a hash map's order.
    assert_eq!(variables(plain.online()), variables(on_cpu.online()));
}

/// Whether a CUDA device is here to test on. Without one the test says why
/// on standard error and is skipped, unless CROSSROADS_REQUIRE_CUDA=1,
/// where it fails naming what is missing.
fn cuda_or_skip(test: &str) -> bool {
    if tch::Cuda::is_available() {
        return true;
    }
    let why = resolve_device(DeviceSetting::Cuda)
        .err()
        .map_or_else(|| "no CUDA device".to_owned(), |e| e.to_string());
    crossroads_test_support::gates::skip_unless_required(
        crossroads_test_support::Need::Cuda,
        &format!("{test} needs a CUDA device and a CUDA libtorch ({why})"),
    );
    false
}

/// A trainer on CUDA device 0 starts from the CPU's weights of its seed,
/// follows the CPU trainer update for update (to the float noise of
/// another device's kernels), and what it saves (weights, checkpoint
/// state) is on the CPU and loads there.
#[test]
#[ignore = "needs a CUDA device and a CUDA libtorch: \
            CROSSROADS_REQUIRE_CUDA=1 cargo test -- --include-ignored"]
fn a_cuda_trainer_follows_the_cpu_one_and_its_weights_load_on_the_cpu() {
    if !cuda_or_skip("a_cuda_trainer_follows_the_cpu_one_and_its_weights_load_on_the_cpu") {
        return;
    }
    let cuda = Device::Cuda(0);
    for spec in [mlp(), conv()] {
        for optimizer in [ADAM, RMSPROP] {
            let what = format!("{:?} {}", spec.trunk, optimizer.name());
            let mut cpu = Trainer::new(config(spec.clone(), optimizer)).unwrap();
            let mut gpu = Trainer::new_on(config(spec.clone(), optimizer), cuda).unwrap();
            assert_eq!(gpu.device(), cuda);
            assert_eq!(gpu.online().device(), cuda);
            assert_eq!(gpu.target().device(), cuda);
            assert!(!gpu.optimizer().is_fused(), "{what}");
            assert_eq!(
                gpu.online().to_safetensors(0).unwrap(),
                cpu.online().to_safetensors(0).unwrap(),
                "{what}: the same seed gives the same weights on either device"
            );
            for (i, b) in batches(&spec, 4).iter().enumerate() {
                let a = cpu.update(b).unwrap();
                let g = gpu.update(b).unwrap();
                assert_eq!(a.step, g.step);
                // The first update starts from equal weights; later ones
                // carry the noise of earlier steps (cuDNN may compute
                // convolutions in TF32).
                let tol = if i == 0 { 5e-3 } else { 2e-2 };
                let what = format!("{what}, update {}", a.step);
                close(
                    &[g.loss as f32],
                    &[a.loss as f32],
                    tol,
                    &format!("{what}: loss"),
                );
                close(
                    &[g.grad_norm as f32],
                    &[a.grad_norm as f32],
                    tol,
                    &format!("{what}: gradient norm"),
                );
                close(
                    &g.priorities,
                    &a.priorities,
                    tol,
                    &format!("{what}: priorities"),
                );
            }

            let mut rng = SplitMix::new(17);
            let rows = 8;
            let obs: Vec<f32> = (0..rows)
                .flat_map(|_| synthetic_observation(&spec, &mut rng))
                .collect();
            let x = Tensor::from_slice(&obs).reshape([rows as i64, spec.input_len()]);
            let q_gpu = values(&gpu.online().q_values(&x).unwrap());
            let q_cpu = values(&cpu.online().q_values(&x).unwrap());
            close(
                &q_gpu,
                &q_cpu,
                2e-2,
                &format!("{what}: Q-values after training"),
            );

            // The weights a CUDA learner publishes load on the CPU, as an
            // actor loads them.
            let bytes = gpu.online().to_safetensors(7).unwrap();
            let (net, version) = QNetwork::from_safetensors(&bytes).unwrap();
            assert_eq!(version, 7);
            assert_eq!(net.device(), Device::Cpu);
            let q_loaded = values(&net.q_values(&x).unwrap());
            close(
                &q_loaded,
                &q_gpu,
                5e-3,
                &format!("{what}: loaded on the CPU"),
            );

            // Its checkpoint state is on the CPU and resumes a CPU trainer.
            let state = gpu.state(7).unwrap();
            assert!(
                state
                    .optimizer
                    .iter()
                    .all(|(_, t)| t.device() == Device::Cpu),
                "{what}: optimizer state on the CPU"
            );
            let mut resumed = Trainer::new(config(spec.clone(), optimizer)).unwrap();
            resumed.restore(state).unwrap();
            assert_eq!(resumed.step(), gpu.step());
            // Variable by variable: the bytes' header follows a hash map's order.
            let (saved, _) = QNetwork::from_safetensors(&bytes).unwrap();
            assert_eq!(variables(resumed.online()), variables(&saved));
            let more = batches(&spec, 5);
            let a = resumed.update(&more[4]).unwrap();
            let g = gpu.update(&more[4]).unwrap();
            close(
                &g.priorities,
                &a.priorities,
                5e-3,
                &format!("{what}: after resuming"),
            );
        }
    }
}
