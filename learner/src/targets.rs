//! The arithmetic of one DQN update, as plain functions over tensors so that
//! tests can check them on hand-made numbers.

use tch::{Kind, Reduction, Tensor};

/// Double-DQN n-step targets (van Hasselt et al. 2016):
/// `y = r + d * Q_target(s', argmax_a Q_online(s', a))`.
///
/// `rewards` is each transition's discounted reward over its k steps and
/// `discounts` its bootstrap discount gamma^k (0 when the episode ended), as
/// actors send them, so multi-step actions and n-step returns need nothing
/// more here. The online network picks the action, the target network
/// values it. Shapes: `q_*_next` `[batch, actions]`, the others `[batch]`.
/// Call under `tch::no_grad`.
pub fn double_dqn_targets(
    q_online_next: &Tensor,
    q_target_next: &Tensor,
    rewards: &Tensor,
    discounts: &Tensor,
) -> Tensor {
    let best = q_online_next.argmax(1, true);
    let next_value = q_target_next.gather(1, &best, false).squeeze_dim(1);
    rewards + discounts * next_value
}

/// Q(s, a) of the taken actions: `q` `[batch, actions]`, `actions` `[batch]`
/// (i64).
pub fn taken(q: &Tensor, actions: &Tensor) -> Tensor {
    q.gather(1, &actions.unsqueeze(1), false).squeeze_dim(1)
}

/// Huber loss of `q_sa` against `targets`, each term weighted by its
/// importance weight, averaged over the batch (Schaul et al. 2016).
pub fn weighted_huber(q_sa: &Tensor, targets: &Tensor, weights: &Tensor, delta: f64) -> Tensor {
    let per_item = q_sa.huber_loss(targets, Reduction::None, delta);
    (per_item * weights).mean(Kind::Float)
}
