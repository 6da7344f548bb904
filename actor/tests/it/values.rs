//! The Q-values' trait ([`ActionValues`]) on the observations of a
//! [`VecEnv`].

use std::sync::Arc;

use crossroads_actor::ActionValues;
use crossroads_sim::{ActionSet, EnvConfig, Scenario, VecEnv};

/// The trait's default sparse call (for values that read dense rows) gives
/// what the dense call gives on the same observations, and names the
/// observation holding a pair past its end.
#[test]
fn the_default_sparse_call_is_the_dense_call() {
    let scenario = Arc::new(Scenario::builtin("left").expect("scenario"));
    let mut envs =
        VecEnv::new(scenario, EnvConfig::for_actions(ActionSet::Ttg), 5, 3, None).expect("envs");
    let mut values = crate::util::LinearValues::new(envs.obs_len(), envs.num_actions());
    let (m, a) = (envs.len(), envs.num_actions());
    for s in 0..20usize {
        let actions: Vec<usize> = (0..m).map(|i| (s + i) % a).collect();
        envs.step(&actions).expect("step");
        let (mut dense_q, mut sparse_q) = (vec![0.0; m * a], vec![1.0; m * a]);
        let rows = envs.sparse_observations().to_vec();
        values
            .q_values(envs.observations(), m, &mut dense_q)
            .expect("dense");
        values
            .q_values_sparse(&rows, &mut sparse_q)
            .expect("sparse");
        assert_eq!(sparse_q, dense_q, "step {s}");
    }
    let mut rows = envs.sparse_observations().to_vec();
    let len = envs.obs_len() as u32;
    rows[2].push((len, 1.0));
    let err = values
        .q_values_sparse(&rows, &mut vec![0.0; m * a])
        .expect_err("an index past the end");
    assert!(
        err.to_string().contains("observation 2") && err.to_string().contains(&len.to_string()),
        "{err}"
    );
}
