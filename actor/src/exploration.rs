//! Exploration: the Ape-X epsilon ladder over every environment of every
//! actor, and epsilon-greedy choices with a seeded random stream per
//! environment that keep an absorbing *go* from ending exploration early,
//! or that hold an intent for several decisions.

use crossroads_sim::{ActionSet, Intent};
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

/// An actor's rungs of the Ape-X ladder. Ape-X's N is the number of acting
/// copies, so the ladder runs over every environment of every actor:
/// environment `e` of actor `index` (of `count`, `envs` each) is rung
/// `index * envs + e` of `count * envs`. With 2 actors of 16 environments
/// the 32 epsilons run from 0.4 to 0.4^8; a ladder over the 2 processes
/// alone gave 0.4 and 0.00066 and nothing between.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ladder {
    /// Epsilon of rung 0.
    pub base: f64,
    /// Ape-X's exponent (7).
    pub alpha: f64,
    /// This actor's first rung.
    pub first: u32,
    /// Its environments (rungs).
    pub envs: u32,
    /// Rungs over the whole run.
    pub rungs: u32,
    /// Whether each environment has its own rung (Ape-X); otherwise every
    /// environment of the actor stands on rung `first` of `rungs`.
    pub per_env: bool,
}

impl Ladder {
    /// The rungs of actor `index` of `count`, with `envs` environments each.
    pub fn new(base: f64, alpha: f64, index: u32, count: u32, envs: u32) -> Self {
        let envs = envs.max(1);
        Self {
            base,
            alpha,
            first: index.saturating_mul(envs),
            envs,
            rungs: count.max(1).saturating_mul(envs),
            per_env: true,
        }
    }

    /// The earlier ladder over actor processes: every environment of actor
    /// `index` explores with rung `index` of `count` (kept to compare).
    pub fn per_actor(base: f64, alpha: f64, index: u32, count: u32, envs: u32) -> Self {
        Self {
            base,
            alpha,
            first: index,
            envs: envs.max(1),
            rungs: count.max(1),
            per_env: false,
        }
    }

    /// The same `epsilon` in every environment.
    pub fn constant(epsilon: f64, envs: u32) -> Self {
        Self::new(epsilon, 0.0, 0, 1, envs)
    }

    /// Epsilon of this actor's environment `env`.
    pub fn epsilon(&self, env: usize) -> f64 {
        let rung = if self.per_env {
            self.first.saturating_add(env as u32)
        } else {
            self.first
        };
        epsilon_ladder(rung, self.rungs, self.base, self.alpha)
    }

    /// Mean epsilon over this actor's environments.
    pub fn mean(&self) -> f64 {
        (0..self.envs as usize)
            .map(|e| self.epsilon(e))
            .sum::<f64>()
            / f64::from(self.envs)
    }
}

/// How actions are chosen from Q-values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// Training: each environment explores with its rung's epsilon;
    /// transitions are assembled and pushed.
    Explore {
        /// The environments' epsilons.
        ladder: Ladder,
    },
    /// Evaluation: always greedy; no transitions.
    Greedy,
}

impl Mode {
    /// Mean epsilon over the environments (0 when greedy).
    pub fn epsilon(self) -> f64 {
        match self {
            Mode::Explore { ladder } => ladder.mean(),
            Mode::Greedy => 0.0,
        }
    }

    /// Epsilon of environment `env` (0 when greedy).
    pub fn epsilon_of(self, env: usize) -> f64 {
        match self {
            Mode::Explore { ladder } => ladder.epsilon(env),
            Mode::Greedy => 0.0,
        }
    }

    /// Whether transitions are assembled and pushed.
    pub fn is_training(self) -> bool {
        matches!(self, Mode::Explore { .. })
    }
}

/// An action set whose *go* ends the episode (TTG, Creep): the index of
/// *go* and the episode's step limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AbsorbingGo {
    /// The index of *go*.
    pub action: usize,
    /// Simulation steps of an episode at most.
    pub step_limit: u32,
}

/// Exploration by intents (`actor.explore_intents`): an exploring
/// environment holds wait, creep or go for a geometric number of
/// decisions, each decision the action of `set` that carries the intent
/// out at the ego's present speed ([`ActionSet::encode`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intents {
    /// The action set the intents are encoded in (Creep or Sequential).
    pub set: ActionSet,
    /// The scenario's creep speed, m/s.
    pub creep_speed: f64,
    /// Mean hold, decisions (at least 1).
    pub mean_hold: f64,
}

impl Intents {
    /// The intents an exploring environment draws from, uniformly.
    const ALL: [Intent; 3] = [Intent::Wait, Intent::Creep, Intent::Go];

    /// A hold drawn from the geometric distribution on 1, 2, ... with
    /// mean `mean_hold`.
    fn draw_hold(&self, rng: &mut Xoshiro256PlusPlus) -> u32 {
        if self.mean_hold <= 1.0 {
            return 1;
        }
        let stop = 1.0 / self.mean_hold;
        let u: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
        let extra = (u.ln() / (1.0 - stop).ln()).floor();
        1 + extra.min(f64::from(u32::MAX - 1)) as u32
    }
}

/// Epsilon-greedy choices for M environments, each with its own random
/// stream, so choices depend on the seed and the environment's index only.
///
/// Where *go* is absorbing, a uniformly random action ends most exploring
/// episodes within a few decisions (Creep at epsilon 0.4: *go* on 13 % of
/// decisions, so few episodes creep to the limit or live to see a gap open
/// late). There, a random action is drawn among the others, and *go* is
/// explored once per episode at most: with the environment's epsilon an
/// episode gets a *go* due at a step drawn uniformly over the step limit,
/// so exploring gos fall evenly over every phase of an episode (before the
/// stop line, at the creep limit, late).
///
/// With [`Intents`], where the epsilon fires and no intent is held, the
/// environment draws an intent and its hold instead of one action, and
/// follows it to the hold's end or the episode's (the absorbing *go*'s
/// schedule is then off: a held *go* is the one exploring *go*).
#[derive(Debug, Clone)]
pub struct EpsilonGreedy {
    mode: Mode,
    /// The actor's index of this one's environment 0.
    first: usize,
    rngs: Vec<Xoshiro256PlusPlus>,
    go: Option<AbsorbingGo>,
    go_at: Vec<Option<u32>>,
    intents: Option<Intents>,
    /// Per environment, the intent held and the decisions it has left.
    held: Vec<Option<(Intent, u32)>>,
    greedy: Vec<bool>,
}

impl EpsilonGreedy {
    /// Streams for `envs` environments; stream `i` is seeded from
    /// `seed` and `i`. Random actions are uniform over all actions.
    pub fn new(mode: Mode, envs: usize, seed: u64) -> Self {
        Self::for_range(mode, 0..envs, seed)
    }

    /// The streams and epsilons of environments `range` of a
    /// [`EpsilonGreedy::new`] of `range.end`: environment `k` here is
    /// environment `range.start + k` there.
    pub fn for_range(mode: Mode, range: std::ops::Range<usize>, seed: u64) -> Self {
        let first = range.start;
        let envs = range.len();
        let rngs = range
            .map(|i| Xoshiro256PlusPlus::seed_from_u64(crossroads_sim::policy_seed(seed, i as u64)))
            .collect();
        Self {
            mode,
            first,
            rngs,
            go: None,
            go_at: vec![None; envs],
            intents: None,
            held: vec![None; envs],
            greedy: vec![true; envs],
        }
    }

    /// Explores by intents (see the type and [`Intents`]).
    pub fn with_intents(mut self, intents: Intents) -> Self {
        self.intents = Some(intents);
        self
    }

    /// Explores an absorbing *go* once per episode at most (see the type).
    pub fn with_absorbing_go(mut self, go: AbsorbingGo) -> Self {
        self.go = Some(go);
        self
    }

    /// The mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Whether environment `env`'s last action was the greedy one.
    pub fn was_greedy(&self, env: usize) -> bool {
        self.greedy.get(env).copied().unwrap_or(true)
    }

    /// Writes one action per environment from its row of `q` (`envs x
    /// num_actions`); `steps` holds the simulation steps each environment's
    /// episode has taken (0 at its first decision), `speeds` each ego's
    /// speed, m/s (read by [`Intents`] only; 0 where missing).
    pub fn choose(
        &mut self,
        q: &[f32],
        num_actions: usize,
        steps: &[u32],
        speeds: &[f64],
        actions: &mut [usize],
    ) {
        for (i, row) in q.chunks_exact(num_actions).enumerate().take(actions.len()) {
            let epsilon = self.mode.epsilon_of(self.first + i).clamp(0.0, 1.0);
            let best = argmax(row);
            let rng = &mut self.rngs[i];
            let step = steps.get(i).copied().unwrap_or(0);
            if step == 0 {
                self.held[i] = None;
            }
            let action = match (self.go, self.intents) {
                _ if epsilon <= 0.0 => best,
                (_, Some(intents)) => {
                    if self.held[i].is_none() && rng.random_bool(epsilon) {
                        let intent = Intents::ALL[rng.random_range(0..Intents::ALL.len())];
                        // A go is held to the episode's end, as an
                        // absorbing go is: crossing is not undone.
                        let hold = match intent {
                            Intent::Go => u32::MAX,
                            _ => intents.draw_hold(rng),
                        };
                        self.held[i] = Some((intent, hold));
                    }
                    match self.held[i] {
                        Some((intent, left)) => {
                            self.held[i] = (left > 1).then_some((intent, left - 1));
                            let v = speeds.get(i).copied().unwrap_or(0.0);
                            intents
                                .set
                                .encode(intent, v, intents.creep_speed)
                                .unwrap_or(best)
                        }
                        None => best,
                    }
                }
                (None, None) => {
                    if rng.random_bool(epsilon) {
                        rng.random_range(0..num_actions)
                    } else {
                        best
                    }
                }
                (Some(go), None) => {
                    if step == 0 {
                        self.go_at[i] = rng
                            .random_bool(epsilon)
                            .then(|| rng.random_range(0..go.step_limit.max(1)));
                    }
                    if self.go_at[i].is_some_and(|at| step >= at) {
                        self.go_at[i] = None;
                        go.action
                    } else if num_actions > 1 && rng.random_bool(epsilon) {
                        let other = rng.random_range(0..num_actions - 1);
                        if other >= go.action { other + 1 } else { other }
                    } else {
                        best
                    }
                }
            };
            self.greedy[i] = action == best;
            actions[i] = action;
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
    fn the_ladder_runs_over_every_environment_of_every_actor() {
        // 2 actors x 16 environments: 32 rungs from 0.4 to 0.4^8, actor 1
        // continuing where actor 0 stops.
        let a = Ladder::new(0.4, 7.0, 0, 2, 16);
        let b = Ladder::new(0.4, 7.0, 1, 2, 16);
        let all: Vec<f64> = (0..16)
            .map(|e| a.epsilon(e))
            .chain((0..16).map(|e| b.epsilon(e)))
            .collect();
        for (g, eps) in all.iter().enumerate() {
            let want = 0.4f64.powf(1.0 + 7.0 * g as f64 / 31.0);
            assert!((eps - want).abs() < 1e-12, "rung {g}: {eps} vs {want}");
        }
        assert!((all[0] - 0.4).abs() < 1e-12);
        assert!((all[31] - 0.4f64.powi(8)).abs() < 1e-15);
        // Between the two processes' extremes lie 30 others; the old
        // per-process ladder had none.
        assert_eq!(all.iter().filter(|&&e| e < 0.39 && e > 0.0007).count(), 30);
        assert!(a.mean() > b.mean());
        assert!((Ladder::constant(0.3, 4).mean() - 0.3).abs() < 1e-12);
    }

    #[test]
    fn an_absorbing_go_is_explored_once_per_episode_at_a_uniform_step() {
        // Greedy is action 1 (wait); go is action 0. At epsilon 1 every
        // episode gets one exploring go, due at a step uniform over 0..100,
        // and other random actions never go.
        let q = [0.0f32, 1.0, 0.0];
        let go = AbsorbingGo {
            action: 0,
            step_limit: 100,
        };
        let mode = Mode::Explore {
            ladder: Ladder::constant(1.0, 1),
        };
        let mut e = EpsilonGreedy::new(mode, 1, 3).with_absorbing_go(go);
        let mut go_steps = Vec::new();
        for _ in 0..2000 {
            for step in 0..100 {
                let mut a = [9];
                e.choose(&q, 3, &[step], &[], &mut a);
                if a[0] == 0 {
                    assert!(!e.was_greedy(0));
                    go_steps.push(step);
                    break;
                }
            }
        }
        assert_eq!(go_steps.len(), 2000, "one go per episode");
        let early = go_steps.iter().filter(|&&s| s < 50).count();
        assert!(
            (900..1100).contains(&early),
            "{early} of 2000 before step 50"
        );
    }

    #[test]
    fn intents_are_held_for_geometric_spells_of_their_encoded_actions() {
        // Sequential at creep speed: wait is 1 (decelerate), creep 2
        // (keep), go 0 (accelerate), each for one step. Greedy is 7. At
        // epsilon 1 every decision follows a held intent: spells of wait or
        // creep, 10 decisions on average (two of the same in a row merge:
        // 15), until a go, which holds to the episode's end.
        let creep_speed = 2.0;
        let intents = Intents {
            set: ActionSet::Sequential,
            creep_speed,
            mean_hold: 10.0,
        };
        let mut q = [0.0f32; 12];
        q[7] = 1.0;
        let mode = Mode::Explore {
            ladder: Ladder::constant(1.0, 1),
        };
        let mut e = EpsilonGreedy::new(mode, 1, 5).with_intents(intents);
        let (mut before_go, mut runs, mut went) = (0usize, 0usize, 0usize);
        for _episode in 0..2000 {
            let mut seen = Vec::new();
            for step in 0..300 {
                let mut a = [9];
                e.choose(&q, 12, &[step], &[creep_speed], &mut a);
                assert!(!e.was_greedy(0));
                seen.push(a[0]);
            }
            assert!(seen.iter().all(|&a| a <= 2), "only one-step intents");
            let Some(go) = seen.iter().position(|&a| a == 0) else {
                continue;
            };
            went += 1;
            assert!(seen[go..].iter().all(|&a| a == 0), "a go holds to the end");
            if go > 0 {
                before_go += go;
                runs += 1 + seen[..go].windows(2).filter(|w| w[0] != w[1]).count();
            }
        }
        assert!(went > 1950, "{went} of 2000 episodes went");
        let mean_run = before_go as f64 / runs as f64;
        assert!((12.0..18.0).contains(&mean_run), "mean run {mean_run}");
        // A new episode (step 0) drops the held intent; greedy never holds.
        let mut g = EpsilonGreedy::new(Mode::Greedy, 1, 5).with_intents(intents);
        let mut a = [9];
        g.choose(&q, 12, &[3], &[creep_speed], &mut a);
        assert_eq!(a, [7]);
        let low = Mode::Explore {
            ladder: Ladder::constant(1e-9, 1),
        };
        let mut e = EpsilonGreedy::new(low, 1, 5).with_intents(intents);
        e.held[0] = Some((Intent::Wait, 50));
        e.choose(&q, 12, &[4], &[creep_speed], &mut a);
        assert_eq!(a, [1], "the held wait");
        e.choose(&q, 12, &[0], &[creep_speed], &mut a);
        assert_eq!(a, [7], "dropped at the episode's start");
    }

    #[test]
    fn greedy_picks_the_argmax_and_epsilon_one_is_uniform() {
        let q = [0.0, 2.0, 1.0, 5.0, -1.0, 0.0];
        let mut actions = [9; 2];
        EpsilonGreedy::new(Mode::Greedy, 2, 1).choose(&q, 3, &[0, 0], &[], &mut actions);
        assert_eq!(actions, [1, 0]);

        let explore = |eps| Mode::Explore {
            ladder: Ladder::constant(eps, 1),
        };
        let mut e = EpsilonGreedy::new(explore(1.0), 1, 7);
        let mut counts = [0; 3];
        for _ in 0..3000 {
            let mut a = [0];
            e.choose(&q[..3], 3, &[5], &[], &mut a);
            counts[a[0]] += 1;
            assert_eq!(e.was_greedy(0), a[0] == 1);
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
            let mode = Mode::Explore {
                ladder: Ladder::constant(0.5, 4),
            };
            let mut e = EpsilonGreedy::new(mode, 4, seed);
            let mut out = Vec::new();
            for _ in 0..20 {
                let mut a = [0; 4];
                e.choose(&q, 5, &[1; 4], &[], &mut a);
                out.extend(a);
            }
            out
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }
}
