//! The update: targets, loss, optimizers, and learning a small known MDP.

use crossroads_config::TargetUpdate;
use crossroads_learner::optimizer::{Optimizer, OptimizerConfig};
use crossroads_learner::targets::{double_dqn_targets, taken, weighted_huber};
use crossroads_learner::{Trainer, TrainerConfig, TrainingBatch};
use crossroads_model::NetworkSpec;
use crossroads_types::Transition;
use tch::{Kind, Tensor};

use crate::{toy_batch, toy_spec};

fn values(t: &Tensor) -> Vec<f32> {
    Vec::try_from(t.flatten(0, -1).to_kind(Kind::Float)).expect("test setup")
}

fn close(got: &[f32], want: &[f32], tol: f32) {
    assert_eq!(got.len(), want.len(), "got {got:?}, want {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() <= tol, "got {got:?}, want {want:?}");
    }
}

#[test]
fn double_dqn_n_step_targets_on_a_hand_made_batch() {
    // Online picks the action, target values it: row 0 online argmax is 1
    // (target 20, not the target's own max 30); row 1 argmax 0 (target 7).
    let q_online_next =
        Tensor::from_slice(&[1.0f32, 3.0, 2.0, 5.0, 0.0, 1.0, 0.0, 0.0, 9.0]).reshape([3, 3]);
    let q_target_next =
        Tensor::from_slice(&[10.0f32, 20.0, 30.0, 7.0, 8.0, 9.0, 1.0, 2.0, 4.0]).reshape([3, 3]);
    let gamma = 0.99f32;
    // A one-step transition, a terminal one, and a 4-step action whose
    // reward is already the discounted sum over its steps.
    let rewards = Tensor::from_slice(&[
        1.0f32,
        -1.0,
        -0.01 * (1.0 + gamma + gamma.powi(2) + gamma.powi(3)),
    ]);
    let discounts = Tensor::from_slice(&[gamma, 0.0, gamma.powi(4)]);
    let y =
        tch::no_grad(|| double_dqn_targets(&q_online_next, &q_target_next, &rewards, &discounts));
    let r2 = -0.01 * (1.0 + gamma + gamma.powi(2) + gamma.powi(3));
    close(
        &values(&y),
        &[1.0 + gamma * 20.0, -1.0, r2 + gamma.powi(4) * 4.0],
        1e-5,
    );
}

#[test]
fn loss_is_huber_weighted_by_importance() {
    let q = Tensor::from_slice(&[0.0f32, 1.0, 5.0, 2.0]).reshape([2, 2]);
    let actions = Tensor::from_slice(&[1i64, 0]);
    let q_sa = taken(&q, &actions);
    close(&values(&q_sa), &[1.0, 5.0], 0.0);
    // TD errors 0.5 (quadratic: 0.125) and 3 (linear: 3 - 0.5 = 2.5).
    let targets = Tensor::from_slice(&[1.5f32, 2.0]);
    let weights = Tensor::from_slice(&[1.0f32, 0.5]);
    let loss = weighted_huber(&q_sa, &targets, &weights, 1.0);
    close(&values(&loss), &[(0.125 + 0.5 * 2.5) / 2.0], 1e-6);
}

#[test]
fn rmsprop_and_adam_follow_their_update_rules() {
    // loss = 2 p, so the gradient is 2.
    let run = |config: OptimizerConfig| {
        let p = Tensor::from_slice(&[1.0f32]).set_requires_grad(true);
        let mut opt = Optimizer::new(config, vec![("p".to_owned(), p.shallow_clone())]);
        let grads = opt.gradients(&(&p * 2.0).sum(Kind::Float)).unwrap();
        let norm = opt.step(&grads, 0.0).unwrap();
        (values(&p.detach())[0], norm)
    };
    let (p, norm) = run(OptimizerConfig::Rmsprop {
        lr: 0.1,
        decay: 0.95,
        eps: 0.01,
    });
    assert!((norm - 2.0).abs() < 1e-9);
    let v = 0.05f32 * 4.0;
    close(&[p], &[1.0 - 0.1 * 2.0 / (v.sqrt() + 0.01)], 1e-6);
    let (p, _) = run(OptimizerConfig::Adam {
        lr: 0.1,
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-8,
    });
    // First Adam step moves by lr * m_hat / (sqrt(v_hat) + eps) = lr.
    close(&[p], &[0.9], 1e-6);
}

#[test]
fn clipping_scales_the_gradient_to_the_limit() {
    let p = Tensor::from_slice(&[1.0f32, 1.0]).set_requires_grad(true);
    let (lr, decay, eps) = (0.1f32, 0.9f32, 0.01f32);
    let mut opt = Optimizer::new(
        OptimizerConfig::Rmsprop {
            lr: lr.into(),
            decay: decay.into(),
            eps: eps.into(),
        },
        vec![("p".to_owned(), p.shallow_clone())],
    );
    let loss = (&p * Tensor::from_slice(&[3.0f32, 4.0])).sum(Kind::Float);
    let grads = opt.gradients(&loss).unwrap();
    close(&values(&grads[0]), &[3.0, 4.0], 0.0);
    let norm = opt.step(&grads, 1.0).unwrap();
    assert!((norm - 5.0).abs() < 1e-6);
    // The step used the gradient scaled to norm 1: (0.6, 0.8).
    let moved: Vec<f32> = [0.6f32, 0.8]
        .iter()
        .map(|g| 1.0 - lr * g / (((1.0 - decay) * g * g).sqrt() + eps))
        .collect();
    close(&values(&p.detach()), &moved, 1e-5);
}

#[test]
fn the_fused_step_matches_the_rule_as_tensor_operations() {
    // Three steps of each optimizer on a parameter of mixed signs and
    // magnitudes, against the same rule written with tch operations.
    let g_of =
        |t: usize| Tensor::from_slice(&[0.5f32, -2.0, 1e-3, 3.0, -0.25, 0.0]) * (1.0 + t as f64);
    for config in [
        OptimizerConfig::Rmsprop {
            lr: 0.01,
            decay: 0.95,
            eps: 0.01,
        },
        OptimizerConfig::Adam {
            lr: 0.001,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        },
    ] {
        let p = Tensor::from_slice(&[1.0f32, -1.0, 0.5, 2.0, 0.0, 3.0]).set_requires_grad(true);
        let mut opt = Optimizer::new(config, vec![("p".to_owned(), p.shallow_clone())]);
        let mut want = Tensor::from_slice(&[1.0f32, -1.0, 0.5, 2.0, 0.0, 3.0]);
        let (mut s1, mut s2) = (want.zeros_like(), want.zeros_like());
        for t in 1..=3 {
            let g = g_of(t);
            let grads = opt.gradients(&(&p * &g).sum(Kind::Float)).unwrap();
            opt.step(&grads, 0.0).unwrap();
            want = match config {
                OptimizerConfig::Rmsprop { lr, decay, eps } => {
                    s1 = &s1 * decay + g.square() * (1.0 - decay);
                    &want - &g * lr / (s1.sqrt() + eps)
                }
                OptimizerConfig::Adam {
                    lr,
                    beta1,
                    beta2,
                    eps,
                } => {
                    s1 = &s1 * beta1 + &g * (1.0 - beta1);
                    s2 = &s2 * beta2 + g.square() * (1.0 - beta2);
                    let v_hat = &s2 / (1.0 - beta2.powi(t as i32));
                    &want - &s1 * (lr / (1.0 - beta1.powi(t as i32))) / (v_hat.sqrt() + eps)
                }
            };
        }
        close(&values(&p.detach()), &values(&want), 1e-5);
        let (state, steps) = opt.state();
        assert_eq!(steps, 3);
        assert_eq!(state.len(), if config.name() == "adam" { 2 } else { 1 });
        close(&values(&state[0].1), &values(&s1), 1e-5);
    }
}

/// A deterministic semi-MDP over three states, with multi-step actions
/// (bootstrap discount gamma^k), and its exact Q* by value iteration.
struct Chain {
    gamma: f64,
    /// (state, action) -> (reward, k, next state or None for terminal).
    moves: Vec<(usize, usize, f64, i32, Option<usize>)>,
}

impl Chain {
    fn new() -> Self {
        Self {
            gamma: 0.9,
            moves: vec![
                (0, 0, 0.5, 1, None),
                (0, 1, -0.1, 2, Some(1)),
                (1, 0, 1.0, 1, None),
                (1, 1, 0.0, 1, Some(2)),
                (2, 0, 2.0, 1, None),
                (2, 1, 0.0, 4, Some(0)),
            ],
        }
    }

    fn q_star(&self) -> [[f64; 2]; 3] {
        let mut q = [[0.0f64; 2]; 3];
        for _ in 0..1000 {
            let v: Vec<f64> = q.iter().map(|r| r[0].max(r[1])).collect();
            for &(s, a, r, k, next) in &self.moves {
                q[s][a] = r + next.map_or(0.0, |n| self.gamma.powi(k) * v[n]);
            }
        }
        q
    }

    fn batch(&self, spec: &NetworkSpec) -> TrainingBatch {
        let mut b = toy_batch(spec);
        let one_hot = |s: usize| {
            let mut v = vec![0.0f32; 3];
            v[s] = 1.0;
            v
        };
        let states: Vec<u32> = (0..3).map(|s| b.push_observation(&one_hot(s))).collect();
        for &(s, a, r, k, next) in &self.moves {
            b.push(Transition {
                observation: states[s],
                action: a as u32,
                reward: r as f32,
                discount: next.map_or(0.0, |_| self.gamma.powi(k) as f32),
                priority: 1.0,
                next_observation: states[next.unwrap_or(0)],
            });
        }
        let n = b.len();
        TrainingBatch::from_batch(&b, &vec![1.0; n], (0..n as u64).collect(), spec)
            .expect("test setup")
    }
}

fn trainer(spec: NetworkSpec, optimizer: OptimizerConfig, target: TargetUpdate) -> Trainer {
    trainer_with_delta(spec, optimizer, target, 1.0)
}

/// `learner.go_label_weight`: an exact *go* label (the absorbing go, its
/// discount 0) weighs in the loss as if its importance weight were W
/// times larger, and its priority is what it would be without the rule.
#[test]
fn exact_go_labels_weigh_more_in_the_loss_and_keep_their_priorities() {
    let chain = Chain::new();
    let spec = toy_spec(3, 2, vec![16]);
    let plain = chain.batch(&spec);
    let optimizer = OptimizerConfig::Rmsprop {
        lr: 0.003,
        decay: 0.95,
        eps: 0.01,
    };
    // In the chain, action 0 ends the episode: the exact labels.
    let go = crossroads_learner::GoLabels {
        action: 0,
        weight: 5.0,
    };
    let exact: Vec<bool> = chain.moves.iter().map(|m| m.1 == 0).collect();
    assert!(exact.iter().any(|&e| e) && exact.iter().any(|&e| !e));
    let mut scaled = chain.batch(&spec);
    let w: Vec<f32> = exact.iter().map(|&e| if e { 5.0 } else { 1.0 }).collect();
    scaled.weights = Tensor::from_slice(&w);

    let mut by_hand = trainer(spec.clone(), optimizer, TargetUpdate::Period);
    let mut unweighed = trainer(spec, optimizer, TargetUpdate::Period);
    let mut weighed = Trainer::new(TrainerConfig {
        go_labels: Some(go),
        ..unweighed.config().clone()
    })
    .unwrap();
    let first = weighed.update(&plain).unwrap();
    let first_plain = unweighed.update(&plain).unwrap();
    assert!(
        first.loss > first_plain.loss * 1.5,
        "{first:?} {first_plain:?}"
    );
    assert_eq!(first.priorities, first_plain.priorities);
    let first_by_hand = by_hand.update(&scaled).unwrap();
    assert_eq!(first.loss.to_bits(), first_by_hand.loss.to_bits());
    for _ in 0..20 {
        let a = weighed.update(&plain).unwrap();
        let b = by_hand.update(&scaled).unwrap();
        assert_eq!(a.loss.to_bits(), b.loss.to_bits());
        assert_eq!(a.priorities, b.priorities);
    }
}

fn trainer_with_delta(
    spec: NetworkSpec,
    optimizer: OptimizerConfig,
    target: TargetUpdate,
    huber_delta: f64,
) -> Trainer {
    Trainer::new(TrainerConfig {
        spec,
        seed: 3,
        optimizer,
        max_grad_norm: 10.0,
        huber_delta,
        target_update: target,
        target_period: 25,
        target_tau: 0.05,
        priority_eps: 1e-6,
        go_labels: None,
    })
    .expect("test setup")
}

#[test]
fn learns_the_q_values_of_a_small_known_mdp() {
    let chain = Chain::new();
    let q_star = chain.q_star();
    // Sanity of the hand-made MDP: the best first move is the long way.
    assert!((q_star[0][1] - (-0.1 + 0.81 * 1.8)).abs() < 1e-9);
    let spec = toy_spec(3, 2, vec![32]);
    let batch = chain.batch(&spec);
    for (optimizer, target) in [
        (
            OptimizerConfig::Adam {
                lr: 0.01,
                beta1: 0.9,
                beta2: 0.999,
                eps: 1e-8,
            },
            TargetUpdate::Period,
        ),
        (
            OptimizerConfig::Rmsprop {
                lr: 0.003,
                decay: 0.95,
                eps: 0.01,
            },
            TargetUpdate::Soft,
        ),
    ] {
        let mut t = trainer(spec.clone(), optimizer, target);
        let mut last = None;
        for _ in 0..3000 {
            last = Some(t.update(&batch).unwrap());
        }
        let q = t
            .online()
            .q_values(&Tensor::eye(3, (Kind::Float, tch::Device::Cpu)))
            .unwrap();
        let got = values(&q);
        let want: Vec<f32> = q_star.iter().flatten().map(|&v| v as f32).collect();
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g - w).abs() < 0.03,
                "{optimizer:?}: learned {got:?}, Q* is {want:?}"
            );
        }
        let stats = last.unwrap();
        assert_eq!(stats.step, 3000);
        assert!(stats.td_abs_mean < 0.03, "{stats:?}");
        assert_eq!(stats.priorities.len(), 6);
    }
}

#[test]
fn a_batch_of_another_network_is_refused_naming_the_mismatch() {
    let spec = toy_spec(3, 2, vec![8]);
    let other = toy_spec(4, 2, vec![8]);
    let mut b = toy_batch(&other);
    let s = b.push_observation(&[1.0, 0.0, 0.0, 0.0]);
    b.push(Transition {
        observation: s,
        action: 0,
        reward: 0.0,
        discount: 0.9,
        priority: 1.0,
        next_observation: s,
    });
    let err = TrainingBatch::from_batch(&b, &[1.0], vec![0], &spec).unwrap_err();
    assert!(err.to_string().contains("(4 values)"), "{err}");
    assert!(err.to_string().contains("(3 values)"), "{err}");

    let mut b = toy_batch(&spec);
    let s = b.push_observation(&[1.0, 0.0, 0.0]);
    b.push(Transition {
        observation: s,
        action: 0,
        reward: 0.0,
        discount: 0.9,
        priority: 1.0,
        next_observation: s,
    });
    b.num_actions = 5;
    let err = TrainingBatch::from_batch(&b, &[1.0], vec![0], &spec).unwrap_err();
    assert!(err.to_string().contains("5 actions"), "{err}");
    b.num_actions = 2;
    b.columns.rewards[0] = f32::NAN;
    let err = TrainingBatch::from_batch(&b, &[1.0], vec![0], &spec).unwrap_err();
    assert!(err.to_string().contains("rewards[0]"), "{err}");
}

#[test]
fn divergence_is_an_error_and_the_update_is_not_applied() {
    let spec = toy_spec(3, 2, vec![8]);
    let chain = Chain::new();
    let mut batch = chain.batch(&spec);
    batch.rewards = Tensor::from_slice(&[f32::INFINITY; 6]);
    let mut t = trainer(
        spec,
        OptimizerConfig::Adam {
            lr: 0.01,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        },
        TargetUpdate::Period,
    );
    let err = t.update(&batch).unwrap_err();
    assert!(err.to_string().contains("diverged"), "{err}");
    assert_eq!(t.step(), 0);
}

/// The return of waiting out the episode: -0.01 a step over the 300 steps
/// of an occlusion episode, discounted by 0.99 a step.
const TIMEOUT_RETURN: f32 = -0.951;

/// Q(go) and Q(wait) learned on a one-state bandit of the simulator's kind:
/// *go* collides (-10) with probability `p` and succeeds (+1) otherwise,
/// *wait* times out; both end the episode. The batch holds the outcomes in
/// their exact proportions (100 gos), so what the loss converges to is the
/// estimator's fixed point, not sampling noise.
fn bandit_q(p: f64, huber_delta: f64) -> (f32, f32) {
    let spec = toy_spec(1, 2, vec![16]);
    let mut b = toy_batch(&spec);
    let s = b.push_observation(&[1.0]);
    let collisions = (100.0 * p).round() as usize;
    for i in 0..100 {
        for (action, reward) in [
            (0, if i < collisions { -10.0 } else { 1.0 }),
            (1, TIMEOUT_RETURN),
        ] {
            b.push(Transition {
                observation: s,
                action,
                reward,
                discount: 0.0,
                priority: 1.0,
                next_observation: s,
            });
        }
    }
    let n = b.len();
    let batch = TrainingBatch::from_batch(&b, &vec![1.0; n], (0..n as u64).collect(), &spec)
        .expect("test setup");
    let mut t = trainer_with_delta(
        spec,
        OptimizerConfig::Adam {
            lr: 0.01,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        },
        TargetUpdate::Period,
        huber_delta,
    );
    for _ in 0..2000 {
        t.update(&batch).expect("update");
    }
    let state = Tensor::ones([1, 1], (Kind::Float, tch::Device::Cpu));
    let q = values(&t.online().q_values(&state).expect("forward"));
    (q[0], q[1])
}

/// Learns the bandit at collision probability `p` with `delta` and checks
/// that Q(go) and Q(wait) are the mean returns and the greedy choice the
/// right one; returns them.
fn assert_mean_returns_learned(p: f64, delta: f64) -> (f32, f32) {
    let (go, wait) = bandit_q(p, delta);
    let want = 1.0 - 11.0 * p as f32;
    assert!(
        (go - want).abs() < 0.05 && (wait - TIMEOUT_RETURN).abs() < 0.05,
        "p = {p}: Q(go) {go}, Q(wait) {wait}; the mean returns are {want} and {TIMEOUT_RETURN}"
    );
    assert_eq!(
        go > wait,
        p < 0.177,
        "p = {p}: Q(go) {go}, Q(wait) {wait}: the greedy choice must flip at p = 0.177"
    );
    (go, wait)
}

/// The mechanism the default loss avoids: with delta 1 a collision's error
/// (~11) is in Huber's linear part and Q(go) settles near 1 - p / (1 - p),
/// the loss's median-like fixed point, so going at 30 % risk (mean return
/// -2.3) looks better than waiting.
fn assert_delta_1_prefers_a_risky_go() {
    let (go, wait) = bandit_q(0.3, 1.0);
    assert!(
        (go - (1.0 - 0.3 / 0.7)).abs() < 0.05 && go > wait,
        "delta 1 at p = 0.3: Q(go) {go}, Q(wait) {wait}"
    );
}

/// The slow test's claims on two risks, one either side of break-even.
#[test]
fn the_default_loss_learns_the_mean_return_either_side_of_break_even() {
    let delta = crossroads_config::LearnerConfig::default().huber_delta;
    for p in [0.1, 0.25] {
        assert_mean_returns_learned(p, delta);
    }
    assert_delta_1_prefers_a_risky_go();
}

#[test]
#[ignore = "slow: CROSSROADS_SLOW_TESTS=1 cargo test -- --include-ignored (make test runs it)"]
fn the_default_loss_learns_the_mean_return_of_a_risky_go() {
    if !crossroads_test_support::gates::slow_tests_enabled(
        "training::the_default_loss_learns_the_mean_return_of_a_risky_go",
    ) {
        return;
    }
    let delta = crossroads_config::LearnerConfig::default().huber_delta;
    // Break-even: 1 - 11 p = TIMEOUT_RETURN at p = 0.177.
    for p in [0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.5] {
        let (go, wait) = assert_mean_returns_learned(p, delta);
        let want = 1.0 - 11.0 * p as f32;
        let (go_1, _) = bandit_q(p, 1.0);
        eprintln!(
            "p {p:.2}: mean return of go {want:+.3}, learned Q(go) {go:+.3} (delta {delta}), {go_1:+.3} (delta 1); Q(wait) {wait:+.3}"
        );
    }
    assert_delta_1_prefers_a_risky_go();
}

/// The early phase (`learner.early_*`): its learning rate and target
/// period for the first updates, the configured ones after, chosen by the
/// trainer's step.
#[test]
fn an_early_phase_takes_its_own_learning_rate_and_target_period() {
    let spec = toy_spec(3, 2, vec![8]);
    let chain = Chain::new();
    let batch = chain.batch(&spec);
    let adam = OptimizerConfig::Adam {
        lr: 1e-4,
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-8,
    };
    let mut t = trainer(spec.clone(), adam, TargetUpdate::Period);
    t.set_early_phase(Some(crossroads_learner::EarlyPhase {
        updates: 10,
        learning_rate: 1e-2,
        target_period: 3,
    }));
    let state = Tensor::eye(3, (Kind::Float, tch::Device::Cpu));
    let target_q = |t: &Trainer| values(&t.target().q_values(&state).expect("forward"));
    let online_q = |t: &Trainer| values(&t.online().q_values(&state).expect("forward"));
    let mut copies = Vec::new();
    let mut learning_rates = Vec::new();
    for _ in 0..30 {
        let before = target_q(&t);
        t.update(&batch).expect("update");
        learning_rates.push(t.optimizer().config().learning_rate());
        if target_q(&t) != before {
            assert_eq!(target_q(&t), online_q(&t), "a target update is a copy");
            copies.push(t.step());
        }
    }
    // Every 3 updates in the first 10, then every 25 (the trainer's own).
    assert_eq!(
        copies,
        vec![3, 6, 9, 25],
        "target copies after these updates"
    );
    assert!(
        learning_rates[..10].iter().all(|&lr| lr == 1e-2),
        "{learning_rates:?}"
    );
    assert!(
        learning_rates[10..].iter().all(|&lr| lr == 1e-4),
        "{learning_rates:?}"
    );

    // Without the phase: the configured settings throughout.
    let mut plain = trainer(spec, adam, TargetUpdate::Period);
    plain.set_early_phase(None);
    plain.update(&batch).expect("update");
    assert_eq!(plain.optimizer().config().learning_rate(), 1e-4);
}
