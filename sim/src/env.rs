//! The environment: one episode of one scenario, stepped by action indices
//! of an action set, with k-step actions as single semi-MDP transitions.

use std::sync::Arc;

use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

use crate::action::{ActionSet, Control};
use crate::error::SimError;
use crate::geometry::{OrientedRect, Vec2};
use crate::observation::{self, ObsKind, ObsSpec};
use crate::occlusion::{OcclusionLayout, line_of_sight};
use crate::scenario::{ConflictZone, Lane, Scenario, ego_rect};
use crate::traffic::{Car, EgoConflict, EgoFoe, Traffic};

/// Cap on normalized and reported time to collision, s.
pub const TTC_CAP_S: f64 = 10.0;

/// How an episode ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Outcome {
    /// The ego reached its goal.
    Success,
    /// The ego touched a traffic car.
    Collision,
    /// The step limit came first.
    Timeout,
}

/// Settings of an environment that stay fixed across episodes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvConfig {
    /// How action indices decode.
    pub action_set: ActionSet,
    /// What [`Env::write_observation`] writes.
    pub observation: ObsKind,
    /// Discount used to sum the rewards of a k-step action.
    pub gamma: f64,
    /// Reward of a collision, replacing the scenario's `rewards.collision`
    /// (reward shaping for training; outcomes are the same).
    pub collision_reward: Option<f64>,
}

impl EnvConfig {
    /// The paper's pairing: the Sequential grid for Sequential actions, the
    /// TTG grid otherwise; gamma 0.99.
    pub fn for_actions(action_set: ActionSet) -> Self {
        let observation = match action_set {
            ActionSet::Sequential => ObsKind::Sequential,
            ActionSet::Ttg | ActionSet::Creep => ObsKind::Ttg,
        };
        Self {
            action_set,
            observation,
            gamma: 0.99,
            collision_reward: None,
        }
    }
}

/// Result of one [`Env::step`]: one transition of the semi-MDP.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepResult {
    /// `sum_{i<k} gamma^i r_i` over the simulation steps taken.
    pub reward: f64,
    /// Simulation steps taken, `k`; bootstrap with `gamma^k`.
    pub steps: u32,
    /// The episode is over.
    pub done: bool,
    /// How it ended, when `done`.
    pub outcome: Option<Outcome>,
}

/// What an episode measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EpisodeMetrics {
    /// How it ended; `None` while it runs.
    pub outcome: Option<Outcome>,
    /// Simulation steps so far.
    pub steps: u32,
    /// Seconds so far (steps x dt); the time to goal on success.
    pub time_s: f64,
    /// Seconds of braking, summed over traffic cars (see
    /// [`crate::TrafficParams::brake_threshold`]).
    pub brake_time_s: f64,
    /// Seconds of brake lights by SUMO's rule, summed over traffic cars
    /// ([`Traffic::brake_light_time_s`]).
    pub brake_light_s: f64,
    /// Seconds before *go* was chosen; `None` while it has not been.
    pub wait_s: Option<f64>,
    /// Where and how fast the ego was when *go* was chosen: its front,
    /// m past the creep limit (negative: short of it), and its speed,
    /// m/s; `None` while it has not gone.
    pub go_state: Option<(f64, f64)>,
}

/// The ego's longitudinal state along its path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ego {
    /// Arc length of the front bumper, m.
    pub s: f64,
    /// Speed, m/s.
    pub v: f64,
    /// A final *go* was chosen.
    pub committed: bool,
}

/// One simulated intersection. Holds no references and allocates nothing
/// per step once built, so an actor can own many and step them in
/// parallel (`Env` is `Send + Sync`).
#[derive(Debug, Clone)]
pub struct Env {
    scenario: Arc<Scenario>,
    config: EnvConfig,
    rng: Xoshiro256PlusPlus,
    traffic: Traffic,
    ego: Ego,
    pub(crate) ego_rect: OrientedRect,
    pub(crate) sensor: Vec2,
    occluders: Vec<OrientedRect>,
    layout: Option<OcclusionLayout>,
    foes: Vec<EgoFoe>,
    foe_time: Vec<f64>,
    steps: u32,
    /// Step at which *go* was chosen, and [`EpisodeMetrics::go_state`].
    gone: Option<(u32, (f64, f64))>,
    outcome: Option<Outcome>,
    /// Visibility of each observation cell from the sensor, when the
    /// observation has occlusion channels.
    pub(crate) cell_visible: Vec<bool>,
    visible_from: Option<(Vec2, f64)>,
}

impl Env {
    /// An environment; call [`Env::reset`] before stepping.
    pub fn new(scenario: Arc<Scenario>, config: EnvConfig) -> Self {
        let traffic = Traffic::new(&scenario);
        let n = scenario.lanes().len();
        let spec = config.observation.spec(scenario.occlusion_channels());
        let mut env = Self {
            config,
            rng: Xoshiro256PlusPlus::seed_from_u64(0),
            traffic,
            ego: Ego {
                s: 0.0,
                v: 0.0,
                committed: false,
            },
            ego_rect: OrientedRect::new(Vec2::default(), 0.0, 1.0, 1.0),
            sensor: Vec2::default(),
            occluders: Vec::with_capacity(4 + scenario.fixed_obstacles().len()),
            layout: None,
            foes: vec![EgoFoe::None; n],
            foe_time: vec![0.0; n],
            steps: 0,
            gone: None,
            outcome: None,
            cell_visible: vec![true; spec.rows * spec.cols],
            visible_from: None,
            scenario,
        };
        env.reset(0);
        env
    }

    /// A copy of this environment, now, whose traffic draws from a new
    /// random stream seeded by `seed`: the same present, another future
    /// (drivers dawdle and emit cars differently from here on). What
    /// [`crate::go_risk`] replays a decision in.
    pub fn fork(&self, seed: u64) -> Self {
        let mut env = self.clone();
        env.rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        env
    }

    /// Starts a new episode. The same seed gives the same episode on every
    /// machine (xoshiro256++ seeded by splitmix64).
    pub fn reset(&mut self, seed: u64) {
        self.rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        self.traffic.clear();
        self.traffic
            .seed_drivers(crate::seed::splitmix64(seed ^ 0xD21F_E25D_0B5E_ED00));
        self.occluders.clear();
        self.occluders
            .extend_from_slice(self.scenario.fixed_obstacles());
        self.layout = self.scenario.spec().occlusion.as_ref().map(|occ| {
            let layout = occ.sample(&mut self.rng);
            occ.place(&layout, &mut self.occluders);
            layout
        });
        let warmup = (self.scenario.spec().warmup_s / self.scenario.dt()).round() as u32;
        for _ in 0..warmup {
            self.traffic.step(&self.scenario, &[], &mut self.rng);
        }
        self.traffic.reset_counters();
        self.foes.iter_mut().for_each(|f| *f = EgoFoe::None);
        self.foe_time.iter_mut().for_each(|t| *t = 0.0);
        self.ego = Ego {
            s: self.scenario.spec().ego.stop_line_s,
            v: 0.0,
            committed: false,
        };
        self.steps = 0;
        self.gone = None;
        self.outcome = None;
        self.visible_from = None;
        self.update_ego_geometry();
        self.refresh_visibility();
    }

    /// Applies one action: one transition, possibly several simulation
    /// steps. Stepping a finished episode is a no-op with `done` set.
    pub fn step(&mut self, action: usize) -> Result<StepResult, SimError> {
        self.step_with(action, |_| {})
    }

    /// [`Env::step`], calling `each` after every simulation step of the
    /// transition (for drawing every 0.2 s of a long *go*). The occlusion
    /// grid is refreshed once per transition, so inside one use
    /// [`Env::is_visible`] rather than the observation.
    pub fn step_with(
        &mut self,
        action: usize,
        mut each: impl FnMut(&Self),
    ) -> Result<StepResult, SimError> {
        let control = self.config.action_set.decode(action)?;
        let gamma = self.config.gamma;
        let mut result = StepResult {
            reward: 0.0,
            steps: 0,
            done: self.outcome.is_some(),
            outcome: self.outcome,
        };
        if result.done {
            return Ok(result);
        }
        let steps = match control {
            Control::Go => u32::MAX,
            Control::Wait(k) | Control::Accel(_, k) => k,
            Control::Creep => 1,
        };
        let mut discount = 1.0;
        while result.steps < steps {
            let r = self.sim_step(control);
            result.reward += discount * r;
            discount *= gamma;
            result.steps += 1;
            each(self);
            if self.outcome.is_some() {
                break;
            }
        }
        result.done = self.outcome.is_some();
        result.outcome = self.outcome;
        self.refresh_visibility();
        Ok(result)
    }

    /// One simulation step under `control`; returns its reward.
    fn sim_step(&mut self, control: Control) -> f64 {
        let sc = Arc::clone(&self.scenario);
        let dt = sc.dt();
        // Drivers see a go at once, not a step later.
        if control == Control::Go {
            self.ego.committed = true;
            if self.gone.is_none() {
                let limit = sc.spec().ego.creep_limit_s;
                self.gone = Some((self.steps, (self.ego.s - limit, self.ego.v)));
            }
        }
        self.update_foes(dt);
        self.move_ego(control, dt);
        self.traffic.step(&sc, &self.foes, &mut self.rng);
        self.update_ego_geometry();
        self.steps += 1;
        let rewards = &sc.spec().rewards;
        let mut r = rewards.step;
        if self.collides() {
            self.outcome = Some(Outcome::Collision);
            r += self.config.collision_reward.unwrap_or(rewards.collision);
        } else if self.ego.s >= sc.spec().ego.goal_s {
            self.outcome = Some(Outcome::Success);
            r += rewards.success;
        } else if self.steps >= sc.spec().step_limit {
            self.outcome = Some(Outcome::Timeout);
        }
        r
    }

    fn move_ego(&mut self, control: Control, dt: f64) {
        let sc = &self.scenario;
        let e = &sc.spec().ego;
        let p = &e.params;
        let ego = &mut self.ego;
        let cap = sc.ego_speed_cap(ego.s);
        let stop = (ego.v - p.decel * dt).max(0.0);
        let v_new = match control {
            Control::Go => {
                ego.committed = true;
                (ego.v + p.accel * dt).min(cap)
            }
            Control::Wait(_) => stop,
            Control::Accel(m, _) => {
                let a = match m {
                    1.. => p.accel,
                    0 => 0.0,
                    _ => -p.decel,
                };
                (ego.v + a * dt).clamp(0.0, cap)
            }
            Control::Creep => {
                let target = p.creep_speed.min(cap);
                let v = if ego.v < target {
                    (ego.v + p.accel * dt).min(target)
                } else {
                    stop.max(target)
                };
                // Never past the creep limit; past it already, creep waits.
                v.min(((e.creep_limit_s - ego.s) / dt).max(0.0))
            }
        };
        ego.v = v_new;
        ego.s += v_new * dt;
    }

    fn update_ego_geometry(&mut self) {
        let p = &self.scenario.spec().ego.params;
        self.ego_rect = ego_rect(self.scenario.ego_path(), p, self.ego.s);
        self.sensor = self.ego_rect.center + self.ego_rect.axis * self.ego_rect.half_length;
    }

    /// Recomputes which observation cells the sensor sees, if the sensor
    /// moved; once per transition, not per simulation step.
    fn refresh_visibility(&mut self) {
        if self.scenario.occlusion_channels() {
            let key = (self.sensor, self.ego_rect.axis.x);
            if self.visible_from != Some(key) {
                observation::compute_visibility(self);
                self.visible_from = Some(key);
            }
        }
    }

    /// What each lane knows about the ego before this step.
    fn update_foes(&mut self, dt: f64) {
        let sc = Arc::clone(&self.scenario);
        let tp = &sc.spec().traffic;
        let ep = &sc.spec().ego.params;
        let ego = self.ego;
        if !sc.spec().traffic_reacts {
            // Nobody brakes for the ego on its way; only an ego that has
            // merged into a lane (a car length in) is followed there, as any
            // leader is.
            for (i, lane) in sc.lanes().iter().enumerate() {
                self.foes[i] = EgoFoe::None;
                let Some(z) = lane.zone else { continue };
                if z.merge && ego.s >= z.ego_in + ep.length && ego.s <= z.ego_out {
                    let (rear, v) = self.footprint_on(lane);
                    self.foes[i] = EgoFoe::Conflict(EgoConflict {
                        lane_in: z.lane_in,
                        lane_clear: z.lane_clear(),
                        t_enter: 0.0,
                        t_exit: 0.0,
                        occupying: true,
                        rear,
                        v,
                        merge: true,
                        on_junction: true,
                        noticed_s: f64::INFINITY,
                    });
                }
            }
            return;
        }
        // Where the ego would stand if it braked now: drivers take it as
        // coming once it can no longer stop short of their lane, has
        // committed, or drives at their lane faster than a creep.
        let stop_s = ego.s + ego.v * ego.v / (2.0 * ep.decel);
        let moving = ego.committed || ego.v > ep.creep_speed + 0.5;
        for (i, lane) in sc.lanes().iter().enumerate() {
            self.foes[i] = EgoFoe::None;
            let Some(z) = lane.zone else { continue };
            let inside = ego.s >= z.ego_in && ego.s <= z.ego_out;
            // A merge is over for the lane's drivers once the ego is a car
            // length in: from then on it is their leader.
            let exit_s = if z.merge {
                z.ego_in + ep.length
            } else {
                z.ego_out
            };
            let (t_enter, t_exit) =
                if inside || (ego.s < z.ego_in && (moving || stop_s >= z.ego_in)) {
                    (
                        self.ego_arrival(z.ego_in, tp.yield_horizon_s),
                        self.ego_arrival(exit_s, 2.0 * tp.yield_horizon_s),
                    )
                } else {
                    (f64::INFINITY, f64::INFINITY)
                };
            // An ego that is neither committed nor unable to stop is taken
            // as coming only when it is close to entering.
            let coming = !inside
                && t_enter <= tp.yield_horizon_s
                && (ego.committed || stop_s >= z.ego_in || t_enter <= 2.0);
            if !(inside || coming) {
                self.foe_time[i] = 0.0;
                continue;
            }
            // Each driver needs his reaction time to notice the ego
            // (traffic checks it per car).
            self.foe_time[i] += dt;
            let (mut rear, mut v) = (z.lane_in, 0.0);
            if z.merge && !inside {
                // Full acceleration up to the curve speed limit.
                let d = z.ego_in - ego.s;
                let reach = if ego.committed {
                    (ego.v * ego.v + 2.0 * ep.accel * d).sqrt()
                } else {
                    ego.v
                };
                v = reach.min(sc.ego_speed_cap(z.ego_in));
            }
            if inside {
                (rear, v) = self.footprint_on(lane);
            }
            self.foes[i] = EgoFoe::Conflict(EgoConflict {
                lane_in: z.lane_in,
                lane_clear: z.lane_clear(),
                t_enter: if inside { 0.0 } else { t_enter },
                t_exit,
                occupying: inside,
                rear,
                v,
                merge: z.merge,
                on_junction: ego.committed || ego.s > sc.spec().ego.stop_line_s + 1e-9,
                noticed_s: self.foe_time[i],
            });
        }
    }

    /// Smallest lane coordinate of the ego's footprint on `lane`, and the
    /// ego's speed along the lane (never negative).
    fn footprint_on(&self, lane: &Lane) -> (f64, f64) {
        let mut rear = f64::INFINITY;
        for c in self.ego_rect.corners() {
            rear = rear.min(lane.coordinate(c));
        }
        let lane_dir = match lane.straight {
            Some((_, dir, _)) => dir,
            None => Vec2::from_angle(lane.path.pose_at(rear).heading),
        };
        (
            rear,
            (self.ego.v * self.ego_rect.axis.dot(lane_dir)).max(0.0),
        )
    }

    /// Seconds until the ego's front reaches arc length `target`, as a
    /// driver would predict it: full acceleration along the curve speed
    /// limits once committed, constant speed otherwise. Infinite beyond
    /// `horizon`.
    fn ego_arrival(&self, target: f64, horizon: f64) -> f64 {
        let ego = self.ego;
        if target <= ego.s {
            return 0.0;
        }
        if !ego.committed {
            let t = if ego.v > 0.05 {
                (target - ego.s) / ego.v
            } else {
                f64::INFINITY
            };
            return if t <= horizon { t } else { f64::INFINITY };
        }
        let sc = &self.scenario;
        let (dt, a) = (sc.dt(), sc.spec().ego.params.accel);
        let (mut s, mut v, mut t) = (ego.s, ego.v, 0.0);
        while t <= horizon {
            v = (v + a * dt).min(sc.ego_speed_cap(s));
            let next = s + v * dt;
            if next >= target {
                return t + (target - s) / v.max(1e-6);
            }
            s = next;
            t += dt;
        }
        f64::INFINITY
    }

    fn collides(&self) -> bool {
        let tp = &self.scenario.spec().traffic;
        self.traffic
            .cars()
            .any(|c| c.rect(tp.length, tp.width).overlaps(&self.ego_rect))
    }

    /// Writes the observation into `out`, which must be
    /// [`Env::obs_spec`]`.len()` long. Allocates nothing.
    pub fn write_observation(&self, out: &mut [f32]) -> Result<(), SimError> {
        observation::write(self, self.config.observation, out)
    }

    /// The observation's non-zero values as `(index, value)` pairs in
    /// increasing index order, into `out` (cleared first): the values
    /// [`Env::write_observation`] leaves non-zero, without writing or
    /// reading the zeros (98 % of a TTG grid). Allocates only to grow
    /// `out`.
    pub fn write_observation_sparse(&self, out: &mut Vec<(u32, f32)>) {
        observation::write_sparse(self, self.config.observation, out);
    }

    /// Shape of the observations this environment writes.
    pub fn obs_spec(&self) -> ObsSpec {
        self.config
            .observation
            .spec(self.scenario.occlusion_channels())
    }

    /// The fixed settings.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// The scenario.
    pub fn scenario(&self) -> &Arc<Scenario> {
        &self.scenario
    }

    /// The ego's state.
    pub fn ego(&self) -> Ego {
        self.ego
    }

    /// The ego's footprint.
    pub fn ego_footprint(&self) -> OrientedRect {
        self.ego_rect
    }

    /// The ego's sensor point (middle of its front bumper), from which
    /// visibility is ray cast.
    pub fn sensor(&self) -> Vec2 {
        self.sensor
    }

    /// Traffic.
    pub fn traffic(&self) -> &Traffic {
        &self.traffic
    }

    /// What each lane's drivers knew about the ego during the last step.
    pub fn foes(&self) -> &[EgoFoe] {
        &self.foes
    }

    /// This episode's occluders.
    pub fn occluders(&self) -> &[OrientedRect] {
        &self.occluders
    }

    /// This episode's draw of the random occluder family, if any.
    pub fn occlusion_layout(&self) -> Option<OcclusionLayout> {
        self.layout
    }

    /// Steps taken in this episode.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Whether the episode is over.
    pub fn is_done(&self) -> bool {
        self.outcome.is_some()
    }

    /// How the episode ended, once it has.
    pub fn outcome(&self) -> Option<Outcome> {
        self.outcome
    }

    /// What this episode measured so far.
    pub fn metrics(&self) -> EpisodeMetrics {
        EpisodeMetrics {
            outcome: self.outcome,
            steps: self.steps,
            time_s: f64::from(self.steps) * self.scenario.dt(),
            brake_time_s: self.traffic.brake_time_s(),
            brake_light_s: self.traffic.brake_light_time_s(),
            wait_s: self.gone.map(|(k, _)| f64::from(k) * self.scenario.dt()),
            go_state: self.gone.map(|(_, state)| state),
        }
    }

    /// Whether the straight line from the sensor to `p` is free of
    /// occluders.
    pub fn is_visible(&self, p: Vec2) -> bool {
        line_of_sight(self.sensor, p, &self.occluders)
    }

    /// Time to collision of a car: constant-speed time until its front
    /// reaches the ego's conflict zone on its lane; 0 inside the zone;
    /// infinite once it has cleared it, when stopped, or when its lane does
    /// not meet the ego's path.
    pub fn car_ttc(&self, car: &Car) -> f64 {
        match self.scenario.lanes()[car.lane].zone {
            Some(z) => ttc(&z, car, self.scenario.spec().traffic.length),
            None => f64::INFINITY,
        }
    }

    /// Smallest [`Env::car_ttc`] over cars the sensor sees (every car if
    /// `visible_only` is false).
    pub fn min_ttc(&self, visible_only: bool) -> f64 {
        let check = visible_only && !self.occluders.is_empty();
        let mut best = f64::INFINITY;
        for car in self.traffic.cars() {
            let t = self.car_ttc(car);
            if t < best && (!check || self.is_visible(car.pos)) {
                best = t;
            }
        }
        best
    }

    /// Whether the sensor sees every conflicting lane from the conflict
    /// zone back to `range` metres upstream (sampled every 5 m).
    pub fn sees_conflicts(&self, range: f64) -> bool {
        if self.occluders.is_empty() {
            return true;
        }
        self.scenario.lanes().iter().all(|lane| {
            let Some(z) = lane.zone else { return true };
            let mut d = 0.0;
            while d <= range {
                let l = z.lane_in - d;
                if l < 0.0 {
                    break;
                }
                if !self.is_visible(lane.path.pose_at(l).pos) {
                    return false;
                }
                d += 5.0;
            }
            true
        })
    }

    /// Scene construction for tests and tools: removes all traffic.
    pub fn clear_traffic(&mut self) {
        self.traffic.clear();
    }

    /// Scene construction: adds a car on `lane` with its front at lane
    /// coordinate `s`, driving at `v` (also its desired speed). Cars must be
    /// added downstream first within a lane.
    pub fn place_car(&mut self, lane: usize, s: f64, v: f64) -> Result<(), SimError> {
        self.traffic.place(&self.scenario, lane, s, v)
    }

    /// Scene construction: [`Env::place_car`] at `(s, v, v_desired)`
    /// with its own desired speed and driver (`None`: the scenario's
    /// `[traffic]` driver).
    pub fn place_driven(
        &mut self,
        lane: usize,
        state: (f64, f64, f64),
        driver: Option<crate::drivers::Driver>,
    ) -> Result<(), SimError> {
        self.traffic
            .place_driven(&self.scenario, lane, state, driver)
    }

    /// Scene construction: puts the ego's front bumper at arc length `s`
    /// with speed `v`.
    pub fn set_ego(&mut self, s: f64, v: f64, committed: bool) {
        self.ego = Ego { s, v, committed };
        self.visible_from = None;
        self.update_ego_geometry();
        self.refresh_visibility();
    }

    /// Scene construction: replaces this episode's occluders.
    pub fn set_occluders(&mut self, occluders: &[OrientedRect]) {
        self.occluders.clear();
        self.occluders.extend_from_slice(occluders);
        self.visible_from = None;
        self.update_ego_geometry();
        self.refresh_visibility();
    }
}

pub(crate) fn ttc(z: &ConflictZone, car: &Car, length: f64) -> f64 {
    if car.s - length >= z.lane_clear() {
        f64::INFINITY
    } else if car.s >= z.lane_in {
        0.0
    } else if car.v > 0.1 {
        (z.lane_in - car.s) / car.v
    } else {
        f64::INFINITY
    }
}
