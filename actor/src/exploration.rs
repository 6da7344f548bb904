//! Exploration: the Ape-X epsilon ladder and epsilon-greedy choices with a
//! seeded random stream per environment.

use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::values::argmax;

/// Ape-X's epsilon of actor `index` among `count`:
/// `base^(1 + alpha * index / (count - 1))`; `base` for a single actor.
/// With the paper's `base` 0.4 and `alpha` 7 the ladder runs from 0.4 down
/// to 0.4^8 (about 0.00066).
pub fn epsilon_ladder(index: u32, count: u32, base: f64, alpha: f64) -> f64 {
    if count <= 1 {
        return base;
    }
    let i = f64::from(index.min(count - 1));
    base.powf(1.0 + alpha * i / f64::from(count - 1))
}

/// How actions are chosen from Q-values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// Training: a uniformly random action with probability `epsilon`, the
    /// greedy one otherwise; transitions are assembled and pushed.
    Explore {
        /// Probability of a random action, in [0, 1].
        epsilon: f64,
    },
    /// Evaluation: always greedy; no transitions.
    Greedy,
}

impl Mode {
    /// The epsilon in effect (0 when greedy).
    pub fn epsilon(self) -> f64 {
        match self {
            Mode::Explore { epsilon } => epsilon,
            Mode::Greedy => 0.0,
        }
    }

    /// Whether transitions are assembled and pushed.
    pub fn is_training(self) -> bool {
        matches!(self, Mode::Explore { .. })
    }
}

/// Epsilon-greedy choices for M environments, each with its own random
/// stream, so choices depend on the seed and the environment's index only.
#[derive(Debug, Clone)]
pub struct EpsilonGreedy {
    mode: Mode,
    rngs: Vec<Xoshiro256PlusPlus>,
}

impl EpsilonGreedy {
    /// Streams for `envs` environments; stream `i` is seeded from
    /// `seed` and `i`.
    pub fn new(mode: Mode, envs: usize, seed: u64) -> Self {
        let rngs = (0..envs as u64)
            .map(|i| Xoshiro256PlusPlus::seed_from_u64(crossroads_sim::policy_seed(seed, i)))
            .collect();
        Self { mode, rngs }
    }

    /// The mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Writes one action per environment from its row of `q` (`envs x
    /// num_actions`).
    pub fn choose(&mut self, q: &[f32], num_actions: usize, actions: &mut [usize]) {
        let epsilon = self.mode.epsilon();
        for ((rng, row), action) in self
            .rngs
            .iter_mut()
            .zip(q.chunks_exact(num_actions))
            .zip(actions.iter_mut())
        {
            *action = if epsilon > 0.0 && rng.random_bool(epsilon.clamp(0.0, 1.0)) {
                rng.random_range(0..num_actions)
            } else {
                argmax(row)
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ladder_matches_ape_x() {
        assert_eq!(epsilon_ladder(0, 1, 0.4, 7.0), 0.4);
        assert!((epsilon_ladder(0, 8, 0.4, 7.0) - 0.4).abs() < 1e-12);
        assert!((epsilon_ladder(7, 8, 0.4, 7.0) - 0.4f64.powi(8)).abs() < 1e-15);
        // i = 1 of 8: 0.4^(1 + 7/7) = 0.4^2.
        assert!((epsilon_ladder(1, 8, 0.4, 7.0) - 0.16).abs() < 1e-12);
        // i = 1 of 3: 0.4^(1 + 3.5).
        assert!((epsilon_ladder(1, 3, 0.4, 7.0) - 0.4f64.powf(4.5)).abs() < 1e-15);
        let ladder: Vec<f64> = (0..16).map(|i| epsilon_ladder(i, 16, 0.4, 7.0)).collect();
        assert!(ladder.windows(2).all(|w| w[0] > w[1]), "{ladder:?}");
    }

    #[test]
    fn greedy_picks_the_argmax_and_epsilon_one_is_uniform() {
        let q = [0.0, 2.0, 1.0, 5.0, -1.0, 0.0];
        let mut actions = [9; 2];
        EpsilonGreedy::new(Mode::Greedy, 2, 1).choose(&q, 3, &mut actions);
        assert_eq!(actions, [1, 0]);

        let mut e = EpsilonGreedy::new(Mode::Explore { epsilon: 1.0 }, 1, 7);
        let mut counts = [0; 3];
        for _ in 0..3000 {
            let mut a = [0];
            e.choose(&q[..3], 3, &mut a);
            counts[a[0]] += 1;
        }
        assert!(
            counts.iter().all(|&c| (800..1200).contains(&c)),
            "{counts:?}"
        );
    }

    #[test]
    fn choices_are_reproducible_by_seed() {
        let q = vec![0.5f32; 4 * 5];
        let run = |seed| {
            let mut e = EpsilonGreedy::new(Mode::Explore { epsilon: 0.5 }, 4, seed);
            let mut out = Vec::new();
            for _ in 0..20 {
                let mut a = [0; 4];
                e.choose(&q, 5, &mut a);
                out.extend(a);
            }
            out
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }
}
