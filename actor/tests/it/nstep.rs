//! n-step assembly against sums computed by hand, with k-step actions and
//! episode ends inside the window.

use std::sync::Arc;

use crossroads_actor::{BatchBuilder, EncodedObs, NStepAssembler, NStepTransition, ObsRef};
use crossroads_types::codec::ObservationEncoding;
use crossroads_types::{ObservationLayout, codec};

fn obs(id: u64) -> ObsRef {
    let mut bytes = Vec::new();
    let mut values = [0.0f32; 4];
    values[(id % 4) as usize] = id as f32 + 1.0;
    codec::encode(ObservationEncoding::SparseF32, &values, &mut bytes);
    Arc::new(EncodedObs { id, bytes })
}

fn close(a: f32, b: f64) -> bool {
    (f64::from(a) - b).abs() < 1e-5
}

#[test]
fn sums_discounts_and_priorities_over_k_step_actions() {
    let g = 0.9f64;
    let mut nstep = NStepAssembler::new(3, g);
    let mut out: Vec<NStepTransition> = Vec::new();
    // Q rows: the taken action's value and the row maximum matter.
    // d0: action 1 (Q 0.5), reward 1, 1 step.
    nstep.begin(obs(0), &[0.2, 0.5, 0.1], &mut out);
    nstep.record(1, 0.5, 1.0, 1, None, &mut out);
    // d1: action 0 (Q 0.3), reward 2, 2 steps.
    nstep.begin(obs(1), &[0.3, -1.0, 0.0], &mut out);
    nstep.record(0, 0.3, 2.0, 2, None, &mut out);
    // d2: action 2 (Q 0.7), reward 3, 4 steps.
    nstep.begin(obs(2), &[0.0, 0.0, 0.7], &mut out);
    nstep.record(2, 0.7, 3.0, 4, None, &mut out);
    assert!(out.is_empty(), "nothing before the window is full");
    assert_eq!(nstep.pending(), 3);

    // o3 has max Q 10: the window emits d0, bootstrapped over 1+2+4 steps.
    nstep.begin(obs(3), &[10.0, 2.0, f32::NAN], &mut out);
    assert_eq!(out.len(), 1);
    let t = &out[0];
    let r0 = 1.0 + g * 2.0 + g.powi(3) * 3.0; // 4.987
    let d0 = g.powi(7);
    assert!(close(t.reward, r0), "{}", t.reward);
    assert!(close(t.discount, d0), "{}", t.discount);
    assert!(
        close(t.priority, (r0 + d0 * 10.0 - 0.5).abs()),
        "{}",
        t.priority
    );
    assert_eq!(
        (t.observation.id, t.action, t.next_observation.id),
        (0, 1, 3)
    );

    // d3: action 0 (Q 6), reward 4, 8 steps, and the episode ends: d1, d2
    // and d3 are emitted without bootstrap, to the terminal observation.
    out.clear();
    nstep.record(0, 6.0, 4.0, 8, Some(obs(99)), &mut out);
    assert_eq!(out.len(), 3);
    let expected = [
        // (state, action, return, q_taken)
        (1, 0, 2.0 + g.powi(2) * 3.0 + g.powi(6) * 4.0, 0.3),
        (2, 2, 3.0 + g.powi(4) * 4.0, 0.7),
        (3, 0, 4.0, 6.0),
    ];
    for (t, (state, action, ret, q)) in out.iter().zip(expected) {
        assert_eq!((t.observation.id, t.action), (state, action));
        assert!(close(t.reward, ret), "{} vs {ret}", t.reward);
        assert_eq!(t.discount, 0.0);
        assert!(close(t.priority, (ret - q).abs()), "{}", t.priority);
        assert_eq!(t.next_observation.id, 99);
    }
    assert_eq!(nstep.pending(), 0);

    // The next episode starts with an empty window.
    out.clear();
    nstep.begin(obs(100), &[0.0, 0.0, 0.0], &mut out);
    assert!(out.is_empty());
}

#[test]
fn an_episode_shorter_than_the_window_is_flushed() {
    let g = 0.99;
    let mut nstep = NStepAssembler::new(5, g);
    let mut out = Vec::new();
    nstep.begin(obs(0), &[1.0, 2.0], &mut out);
    nstep.record(1, 2.0, -1.0, 4, None, &mut out);
    nstep.begin(obs(1), &[0.0, 0.0], &mut out);
    nstep.record(0, 0.0, 5.0, 3, Some(obs(2)), &mut out);
    assert_eq!(out.len(), 2);
    assert!(close(out[0].reward, -1.0 + g.powi(4) * 5.0));
    assert!(close(
        out[0].priority,
        (-1.0 + g.powi(4) * 5.0 - 2.0f64).abs()
    ));
    assert!(close(out[1].reward, 5.0));
    assert!(
        out.iter()
            .all(|t| t.discount == 0.0 && t.next_observation.id == 2)
    );
}

#[test]
fn a_window_is_cut_before_an_exploratory_action() {
    let g = 0.5f64;
    let mut nstep = NStepAssembler::new(3, g);
    let mut out = Vec::new();
    // d0, d1 greedy (1 and 2 steps); d2 exploratory from o2 (max Q 6).
    nstep.begin(obs(0), &[0.0, 1.0], &mut out);
    nstep.record(1, 1.0, 1.0, 1, None, &mut out);
    nstep.begin(obs(1), &[3.0, 0.0], &mut out);
    nstep.record(0, 3.0, 2.0, 2, None, &mut out);
    nstep.begin(obs(2), &[6.0, -1.0], &mut out);
    assert!(out.is_empty());
    nstep.cut(&mut out);
    // d0: 1 + 0.5 * 2 over 3 steps, then 0.5^3 * 6 from o2;
    // d1: 2 over 2 steps, then 0.5^2 * 6 from o2.
    assert_eq!(out.len(), 2);
    let want = [(0, 2.0, g.powi(3), 1.0), (1, 2.0, g.powi(2), 3.0)];
    for (t, (state, ret, discount, q)) in out.iter().zip(want) {
        assert_eq!((t.observation.id, t.next_observation.id), (state, 2));
        assert!(close(t.reward, ret), "{} vs {ret}", t.reward);
        assert!(close(t.discount, discount), "{} vs {discount}", t.discount);
        assert!(close(t.priority, (ret + discount * 6.0 - q).abs()));
    }
    assert_eq!(nstep.pending(), 0);
    // The exploratory action (reward -4, 1 step) starts the next window:
    // its own return runs on over the greedy decision after it.
    out.clear();
    nstep.record(1, -1.0, -4.0, 1, None, &mut out);
    nstep.begin(obs(3), &[0.0, 0.0], &mut out);
    nstep.record(0, 0.0, 8.0, 1, Some(obs(9)), &mut out);
    assert_eq!(out.len(), 2);
    assert_eq!((out[0].observation.id, out[0].action), (2, 1));
    assert!(close(out[0].reward, -4.0 + g * 8.0));
    assert_eq!(out[0].discount, 0.0);
    assert!(close(out[1].reward, 8.0));
    // A cut with an empty window emits nothing.
    out.clear();
    nstep.begin(obs(10), &[0.0, 0.0], &mut out);
    nstep.cut(&mut out);
    assert!(out.is_empty());
}

#[test]
fn one_step_windows_bootstrap_with_gamma_to_the_k() {
    let g = 0.5;
    let mut nstep = NStepAssembler::new(1, g);
    let mut out = Vec::new();
    nstep.begin(obs(0), &[0.0, 1.0], &mut out);
    nstep.record(1, 1.0, 0.25, 2, None, &mut out);
    nstep.begin(obs(1), &[4.0, 3.0], &mut out);
    assert_eq!(out.len(), 1);
    assert!(close(out[0].reward, 0.25));
    assert!(close(out[0].discount, 0.25));
    assert!(close(out[0].priority, (0.25 + 0.25 * 4.0 - 1.0f64).abs()));
}

#[test]
fn a_batch_stores_each_observation_once() {
    let mut nstep = NStepAssembler::new(2, 0.9);
    let mut out = Vec::new();
    for i in 0..6 {
        nstep.begin(obs(i), &[0.0, 1.0, 0.5, 0.0], &mut out);
        let terminal = (i == 5).then(|| obs(1000));
        nstep.record((i % 4) as u32, 0.0, 1.0, 1, terminal, &mut out);
    }
    assert_eq!(out.len(), 6);
    let mut builder = BatchBuilder::new(
        ObservationLayout::new("toy", 1, 2, 2, 0),
        4,
        ObservationEncoding::SparseF32,
    );
    for t in &out {
        builder.push(t);
    }
    let batch = builder.take();
    assert!(builder.is_empty());
    batch.validate().expect("valid");
    assert_eq!(batch.len(), 6);
    // States 0..=5, bootstrap states 2..=5 and the terminal: 7 distinct.
    assert_eq!(batch.observations.len(), 7);
    let mut values = [0.0f32; 4];
    let t = batch.transition(0).expect("first");
    batch
        .observations
        .decode_into(t.next_observation as usize, &mut values)
        .expect("decodes");
    assert_eq!(values, [0.0, 0.0, 3.0, 0.0], "next state of t0 is o2");
}
