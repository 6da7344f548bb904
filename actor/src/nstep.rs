//! n-step transitions over k-step actions, with initial priorities from the
//! actor's own Q estimates, and the batches they travel in.
//!
//! Per environment an [`NStepAssembler`] keeps a window of the last n
//! decisions. Decision j took `k_j` simulation steps and earned `r_j` (its
//! steps' rewards already discounted within it, as the simulator returns
//! them). The transition from decision t carries
//!
//! - return `R = sum_j gamma^(K_j) r_j`, where `K_j` is the number of
//!   simulation steps before decision j in the window,
//! - bootstrap discount `gamma^(K)` with K the window's total steps, or 0
//!   when the episode ended inside the window (by the step limit too: it is
//!   part of the task, and the observation carries the steps taken),
//! - the observation n decisions later (or the episode's last one),
//! - priority `|R + discount * max_a Q(s', a) - Q(s_t, a_t)|`,
//!
//! the replay's [`TransitionBatch`] columns (`rewards`, `discounts`,
//! `priorities`) and what the learner's target `R + discount *
//! Q_target(s', argmax Q(s'))` expects. [`BatchBuilder`] packs them.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use crossroads_types::codec::ObservationEncoding;
use crossroads_types::{ObservationLayout, Transition, TransitionBatch};

use crate::values::max_value;

/// Priority given when the TD error is not finite (a network that returned
/// NaN), so the batch still validates.
pub const FALLBACK_PRIORITY: f32 = 1.0;

/// An encoded observation shared by the transitions that refer to it (as
/// state of one and next state of another); `id` is unique per actor, so a
/// batch stores it once.
#[derive(Debug, PartialEq, Eq)]
pub struct EncodedObs {
    /// Unique within the actor.
    pub id: u64,
    /// Encoded with the batch's observation encoding.
    pub bytes: Vec<u8>,
}

/// A shared encoded observation.
pub type ObsRef = Arc<EncodedObs>;

/// One assembled n-step transition.
#[derive(Debug, Clone, PartialEq)]
pub struct NStepTransition {
    /// State s_t.
    pub observation: ObsRef,
    /// Action a_t.
    pub action: u32,
    /// `sum_j gamma^(K_j) r_j` over the window.
    pub reward: f32,
    /// `gamma^K` over the window's K simulation steps; 0 at episode end.
    pub discount: f32,
    /// Initial priority, |TD error|.
    pub priority: f32,
    /// State after the window (the episode's last at its end).
    pub next_observation: ObsRef,
}

#[derive(Debug, Clone)]
struct Decision {
    observation: ObsRef,
    action: u32,
    q_taken: f32,
    reward: f64,
    steps: u32,
}

/// The n-step window of one environment. Call [`begin`](Self::begin) with
/// each new observation and its Q-values (before acting), then
/// [`record`](Self::record) with what the action did. An episode end
/// flushes the whole window; the actor calls [`cut`](Self::cut) before an
/// exploratory action. Cost: O(n) per emitted transition, no allocation
/// beyond the window.
#[derive(Debug, Clone)]
pub struct NStepAssembler {
    n: usize,
    gamma: f64,
    window: VecDeque<Decision>,
    current: Option<(ObsRef, f32)>,
}

impl NStepAssembler {
    /// Windows of `n` (at least 1) decisions, discount `gamma` per
    /// simulation step.
    pub fn new(n: usize, gamma: f64) -> Self {
        Self {
            n: n.max(1),
            gamma,
            window: VecDeque::with_capacity(n + 1),
            current: None,
        }
    }

    /// The observation the next action is decided on (after
    /// [`begin`](Self::begin), before [`record`](Self::record)).
    pub fn current_observation(&self) -> Option<&ObsRef> {
        self.current.as_ref().map(|(obs, _)| obs)
    }

    /// Decisions waiting in the window.
    pub fn pending(&self) -> usize {
        self.window.len()
    }

    /// The environment now shows `observation`, whose Q-values are `q`.
    /// A full window emits its oldest transition, bootstrapped from here.
    pub fn begin(&mut self, observation: ObsRef, q: &[f32], out: &mut Vec<NStepTransition>) {
        let max_q = max_value(q);
        if self.window.len() >= self.n {
            out.push(self.emit_front(Arc::clone(&observation), Some(max_q)));
        }
        self.current = Some((observation, max_q));
    }

    /// The action `action`, whose Q-value was `q_taken`, took `steps`
    /// simulation steps and earned `reward`. When the episode ended
    /// (`terminal` holds its last observation) every decision in the window
    /// is emitted, without bootstrap.
    pub fn record(
        &mut self,
        action: u32,
        q_taken: f32,
        reward: f64,
        steps: u32,
        terminal: Option<ObsRef>,
        out: &mut Vec<NStepTransition>,
    ) {
        let Some((observation, _)) = self.current.take() else {
            return;
        };
        self.window.push_back(Decision {
            observation,
            action,
            q_taken,
            reward,
            steps,
        });
        if let Some(last) = terminal {
            while !self.window.is_empty() {
                out.push(self.emit_front(Arc::clone(&last), None));
            }
        }
    }

    /// The action about to be recorded is not the greedy one: every
    /// decision in the window is emitted now, bootstrapped from the current
    /// observation, so no n-step return sums over an exploratory action
    /// (which would pull Q of the greedy actions before it towards the
    /// random action's outcome, a random *go* most of all). The
    /// exploratory decision itself starts the next window.
    pub fn cut(&mut self, out: &mut Vec<NStepTransition>) {
        let Some((observation, max_q)) = self.current.clone() else {
            return;
        };
        while !self.window.is_empty() {
            out.push(self.emit_front(Arc::clone(&observation), Some(max_q)));
        }
    }

    /// Forgets the window (an episode abandoned without an end).
    pub fn clear(&mut self) {
        self.window.clear();
        self.current = None;
    }

    fn emit_front(&mut self, next: ObsRef, bootstrap: Option<f32>) -> NStepTransition {
        let mut ret = 0.0f64;
        let mut k = 0i32;
        for d in &self.window {
            ret += self.gamma.powi(k) * d.reward;
            k = k.saturating_add(d.steps as i32);
        }
        let (discount, target) = match bootstrap {
            Some(max_q) => {
                let discount = self.gamma.powi(k);
                (discount, ret + discount * f64::from(max_q))
            }
            None => (0.0, ret),
        };
        let front = self.window.pop_front();
        let (observation, action, q_taken) = match front {
            Some(d) => (d.observation, d.action, d.q_taken),
            None => (Arc::clone(&next), 0, 0.0),
        };
        let td = (target - f64::from(q_taken)).abs() as f32;
        NStepTransition {
            observation,
            action,
            reward: ret as f32,
            discount: discount as f32,
            priority: if td.is_finite() {
                td
            } else {
                FALLBACK_PRIORITY
            },
            next_observation: next,
        }
    }
}

/// Collects transitions into a [`TransitionBatch`], each observation once
/// in its pool however many transitions refer to it.
#[derive(Debug, Clone)]
pub struct BatchBuilder {
    layout: ObservationLayout,
    num_actions: u32,
    encoding: ObservationEncoding,
    batch: TransitionBatch,
    pool: HashMap<u64, u32>,
}

impl BatchBuilder {
    /// An empty builder of batches of observations of `layout` (encoded
    /// with `encoding`) and `num_actions` actions.
    pub fn new(layout: ObservationLayout, num_actions: u32, encoding: ObservationEncoding) -> Self {
        Self {
            batch: TransitionBatch::new(layout.clone(), num_actions, encoding),
            layout,
            num_actions,
            encoding,
            pool: HashMap::new(),
        }
    }

    /// Transitions collected.
    pub fn len(&self) -> usize {
        self.batch.len()
    }

    /// Whether none are.
    pub fn is_empty(&self) -> bool {
        self.batch.is_empty()
    }

    /// Adds one transition.
    pub fn push(&mut self, t: &NStepTransition) {
        let observation = self.intern(&t.observation);
        let next_observation = self.intern(&t.next_observation);
        self.batch.push(Transition {
            observation,
            action: t.action,
            reward: t.reward,
            discount: t.discount,
            priority: t.priority,
            next_observation,
        });
    }

    /// The batch so far; the builder starts empty again.
    pub fn take(&mut self) -> TransitionBatch {
        self.pool.clear();
        std::mem::replace(
            &mut self.batch,
            TransitionBatch::new(self.layout.clone(), self.num_actions, self.encoding),
        )
    }

    fn intern(&mut self, obs: &ObsRef) -> u32 {
        let batch = &mut self.batch;
        *self
            .pool
            .entry(obs.id)
            .or_insert_with(|| batch.observations.push_encoded(&obs.bytes))
    }
}
