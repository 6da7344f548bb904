//! Traffic on the priority road: emission, improved-IDM car following with
//! Krauss's free-road acceleration, safety and dawdling, and the drivers'
//! reaction to the ego, whose rule is stated here and nowhere else.
//!
//! Priority drivers never give way in advance. A lane's drivers take the
//! ego as coming once it has chosen *go*, cannot stop short of their lane,
//! or drives at it faster than a creep and is about to enter (the
//! environment fills each lane's [`EgoFoe`]); each reacts once his reaction
//! time has passed (`reaction_delay_s`, 0.2 s: one step, as in SUMO), an
//! inattentive one only to an ego merged into his lane ahead of him. Only a
//! car in the ego's way reacts: one that would neither clear its path before
//! it enters nor arrive after it is out (`yield_margin_s`, 0.5 s, either
//! side) and could still stop short of it (one that cannot passes first,
//! except behind an ego merging ahead). It slows just enough to pass behind
//! it ([`give_way_decel`]), by at most `yield_decel` (4.5 m/s²; needing
//! more, it drives on) while the ego is behind its stop line, by up to
//! `emergency_decel` (9 m/s²) once the ego is on the junction, as SUMO's
//! drivers brake for a junction leader. An ego merging ahead is followed as
//! a leader; without `traffic_reacts` (occlusion) only once a car length in.

use std::collections::VecDeque;

use rand::RngExt;
use rand_distr::StandardNormal;

use crate::car_following::{
    dawdle, iidm_accel_with, iidm_free_accel, krauss_free_accel, krauss_safe_speed,
};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::drivers::Driver;
use crate::error::SimError;
use crate::geometry::{OrientedRect, Vec2};
use crate::params::TrafficParams;
use crate::scenario::Scenario;

/// Bumper-to-bumper distance the Krauss bound keeps to a leader even in an
/// emergency, m.
const HARD_GAP: f64 = 0.5;
/// Capacity reserved per lane, so stepping never allocates.
const LANE_CAPACITY: usize = 64;

/// One traffic car.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Car {
    /// Unique within an episode.
    pub id: u32,
    /// Index of its lane in [`Scenario::lanes`].
    pub lane: usize,
    /// Lane coordinate of its front bumper, m.
    pub s: f64,
    /// Speed, m/s.
    pub v: f64,
    /// Desired speed: lane limit x speed factor, m/s.
    pub v_desired: f64,
    /// Whether it braked harder than the braking threshold this step.
    pub braking: bool,
    /// Whether it gives way to (or brakes for) the ego; kept while its lane
    /// knows about the ego, so drivers do not dither.
    pub yielding: bool,
    /// Centre of the car in the world.
    pub pos: Vec2,
    /// Unit vector of its heading.
    pub axis: Vec2,
    /// Heading, radians counter-clockwise from east.
    pub heading: f64,
    /// Its driver, drawn from the scenario's population as it entered;
    /// `None`: the scenario's `[traffic]` driver.
    pub driver: Option<Driver>,
}

impl Car {
    /// Its footprint.
    pub fn rect(&self, length: f64, width: f64) -> OrientedRect {
        OrientedRect::with_axis(self.pos, self.axis, length, width)
    }
}

/// What the drivers of one lane know about the ego during a step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum EgoFoe {
    /// Nothing to react to: the ego is not on its way into the lane, or
    /// the drivers have not had their reaction time yet.
    #[default]
    None,
    /// The ego is about to enter the lane, or is in it.
    Conflict(EgoConflict),
}

/// The ego as the drivers of one lane see it once they have noticed it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgoConflict {
    /// Smallest lane coordinate the ego's footprint covers on its way
    /// through the lane; drivers who give way stop short of it.
    pub lane_in: f64,
    /// What a car's rear must pass to be clear of the ego's path.
    pub lane_clear: f64,
    /// Seconds until the ego's footprint enters the lane; 0 once it has.
    pub t_enter: f64,
    /// Seconds until the ego is out of the lane (a crossing) or one car
    /// length into it (a merge, after which cars simply follow it);
    /// infinite when the ego is not expected to get there (stopped).
    pub t_exit: f64,
    /// The ego's footprint overlaps the lane now.
    pub occupying: bool,
    /// Smallest lane coordinate of the ego's footprint now (when
    /// occupying).
    pub rear: f64,
    /// Ego speed projected on the lane, never negative, when occupying;
    /// before a merge, the speed it will enter the lane with.
    pub v: f64,
    /// The ego ends its route in this lane: once in, it is a leader.
    pub merge: bool,
    /// The ego is on the junction: past its stop line, or on its way
    /// after *go*. Drivers in its way then brake as hard as they must, up
    /// to `emergency_decel`, as SUMO's do for a vehicle on the junction
    /// (its junction leader); before, they give way with at most
    /// `yield_decel` or drive on.
    pub on_junction: bool,
    /// Seconds since the lane's drivers could first see the ego coming;
    /// each reacts once his own reaction time has passed (infinite where
    /// the ego is simply a leader to follow).
    pub noticed_s: f64,
}

/// Constant deceleration, m/s², that makes a car at speed `v` reach a point
/// `room` metres ahead no earlier than `t` seconds from now, stopping short
/// of it if it must. Negative when it may even speed up; infinite when it
/// is already there.
pub fn give_way_decel(v: f64, room: f64, t: f64) -> f64 {
    if room <= 0.0 {
        return if v > 0.0 { f64::INFINITY } else { 0.0 };
    }
    if t.is_finite() && v * t <= 2.0 * room {
        // Slows to arrive exactly at t without stopping: room = v t - d t^2 / 2.
        2.0 * (v * t - room) / (t * t)
    } else {
        // Stops exactly at the point.
        v * v / (2.0 * room)
    }
}

/// All traffic cars, lane by lane, downstream first.
#[derive(Debug, Clone)]
pub struct Traffic {
    lanes: Vec<VecDeque<Car>>,
    pending: Vec<u32>,
    /// Speed factor of the car waiting to enter each lane, drawn once.
    next_factor: Vec<Option<f64>>,
    next_id: u32,
    emissions: u64,
    insertions: u64,
    brake_time_s: f64,
    brake_light_s: f64,
    guard_hits: u64,
    /// Draws each entering car's driver: a stream of its own, so a
    /// population that draws nothing leaves every other draw as it was.
    drivers_rng: Xoshiro256PlusPlus,
}

impl Traffic {
    /// Empty traffic for a scenario.
    pub fn new(scenario: &Scenario) -> Self {
        let n = scenario.lanes().len();
        Self {
            lanes: (0..n)
                .map(|_| VecDeque::with_capacity(LANE_CAPACITY))
                .collect(),
            pending: vec![0; n],
            next_factor: vec![None; n],
            next_id: 0,
            emissions: 0,
            insertions: 0,
            brake_time_s: 0.0,
            brake_light_s: 0.0,
            guard_hits: 0,
            drivers_rng: Xoshiro256PlusPlus::seed_from_u64(0),
        }
    }

    /// Seeds the stream that draws each entering car's driver.
    pub fn seed_drivers(&mut self, seed: u64) {
        self.drivers_rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    }

    /// Removes every car and clears the counters; keeps the memory.
    pub fn clear(&mut self) {
        self.lanes.iter_mut().for_each(VecDeque::clear);
        self.pending.iter_mut().for_each(|p| *p = 0);
        self.next_factor.iter_mut().for_each(|f| *f = None);
        self.next_id = 0;
        self.emissions = 0;
        self.insertions = 0;
        self.brake_time_s = 0.0;
        self.brake_light_s = 0.0;
        self.guard_hits = 0;
    }

    /// Cars of lane `lane`, downstream first.
    pub fn lane(&self, lane: usize) -> &VecDeque<Car> {
        &self.lanes[lane]
    }

    /// Every car.
    pub fn cars(&self) -> impl Iterator<Item = &Car> {
        self.lanes.iter().flatten()
    }

    /// Number of cars.
    pub fn len(&self) -> usize {
        self.lanes.iter().map(VecDeque::len).sum()
    }

    /// Whether there are no cars.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Seconds of braking summed over cars since the last
    /// [`Traffic::reset_counters`].
    pub fn brake_time_s(&self) -> f64 {
        self.brake_time_s
    }

    /// Seconds of brake lights summed over cars since the last
    /// [`Traffic::reset_counters`], by SUMO's rule
    /// (`MSVehicle::setBrakingSignals`): a car's light is on in a step
    /// whose speed change, dawdling included, is a deceleration above
    /// `(0.05 + 0.005 v) v` m/s² (a speed-dependent "pseudo friction":
    /// 1 m/s² at 10 m/s, 3 m/s² at 20 m/s), and whenever it ends the step
    /// at 0.1 m/s or less (a car halted in a queue shows its brake light).
    /// Counted within the brake zone, as [`Traffic::brake_time_s`].
    pub fn brake_light_time_s(&self) -> f64 {
        self.brake_light_s
    }

    /// How often the last-resort spacing guard had to move a car back
    /// because car following alone would have let it touch its leader.
    /// Stays 0 unless the model is broken; tests check it.
    pub fn guard_hits(&self) -> u64 {
        self.guard_hits
    }

    /// Emission events (Bernoulli successes of the emission probability)
    /// since [`Traffic::clear`].
    pub fn emissions(&self) -> u64 {
        self.emissions
    }

    /// Cars that entered their lane since [`Traffic::clear`]; lags
    /// [`Traffic::emissions`] by the backlog of a blocked entrance.
    pub fn insertions(&self) -> u64 {
        self.insertions
    }

    /// Emissions waiting for their lane's entrance to clear.
    pub fn backlog(&self) -> u64 {
        self.pending.iter().map(|&p| u64::from(p)).sum()
    }

    /// Zeroes the braking times.
    pub fn reset_counters(&mut self) {
        self.brake_time_s = 0.0;
        self.brake_light_s = 0.0;
    }

    /// Advances every car by one step, then emits. `foes[i]` is what lane
    /// `i` knows about the ego (missing entries mean nothing).
    pub fn step(&mut self, scenario: &Scenario, foes: &[EgoFoe], rng: &mut impl rand::Rng) {
        let p = &scenario.spec().traffic;
        let dt = scenario.dt();
        let len = p.length;
        let brake_zone2 = p.brake_zone * p.brake_zone;
        for (li, lane) in scenario.lanes().iter().enumerate() {
            let foe = foes.get(li).copied().unwrap_or_default();
            let cars = &mut self.lanes[li];
            // Leader's state before this step, and its front after it.
            let mut leader: Option<(f64, f64)> = None;
            let mut leader_new_s = f64::INFINITY;
            for car in cars.iter_mut() {
                let (gap, v_lead) = match leader {
                    Some((ls, lv)) => (ls - len - car.s, lv),
                    None => (f64::INFINITY, 0.0),
                };
                // The parameters as this car's driver applies them.
                let own;
                let p = match car.driver {
                    Some(d) => {
                        own = d.params(p);
                        &own
                    }
                    None => p,
                };
                let a_free = if p.krauss_free_road {
                    krauss_free_accel(car.v, car.v_desired, dt, p)
                } else {
                    iidm_free_accel(car.v, car.v_desired, p)
                };
                let mut a = iidm_accel_with(a_free, car.v, car.v_desired, gap, v_lead, p);
                match foe {
                    EgoFoe::Conflict(c) if notices(car, &c, p) => {
                        a = a.min(react(car, a_free, &c, p));
                    }
                    _ => car.yielding = false,
                }
                let floor = (car.v - p.emergency_decel * dt).max(0.0);
                let mut v_new = (car.v + a.max(-p.emergency_decel) * dt).max(0.0);
                if leader.is_some() {
                    // Krauss: never faster than what lets it stop behind a
                    // leader braking as hard as possible; physics still caps
                    // the braking.
                    let safe = krauss_safe_speed(gap - HARD_GAP, v_lead, p.tau, p.emergency_decel);
                    v_new = v_new.min(safe.max(floor));
                }
                car.braking = v_new - car.v < -p.brake_threshold * dt;
                let near = car.pos.dot(car.pos) <= brake_zone2;
                if car.braking && near {
                    self.brake_time_s += dt;
                }
                let v_new = dawdle(v_new, rng.random::<f64>(), dt, p);
                if near && brake_light(car.v, v_new, dt) {
                    self.brake_light_s += dt;
                }
                leader = Some((car.s, car.v));
                car.v = v_new;
                car.s += v_new * dt;
                // Last resort: never let a car into its leader.
                let max_s = leader_new_s - len - 0.1 * HARD_GAP;
                if car.s > max_s {
                    car.s = max_s;
                    self.guard_hits += 1;
                }
                leader_new_s = car.s;
                place(car, lane, len);
            }
            while cars.front().is_some_and(|c| c.s - len > lane.path.length()) {
                cars.pop_front();
            }
            self.emit(scenario, li, rng);
        }
    }

    /// Adds a car with its front at lane coordinate `s`, upstream of every
    /// car already in the lane.
    pub fn place(
        &mut self,
        scenario: &Scenario,
        lane: usize,
        s: f64,
        v: f64,
    ) -> Result<(), SimError> {
        let Some(l) = scenario.lanes().get(lane) else {
            return Err(SimError::invalid(
                scenario.name(),
                format!("no lane {lane}"),
            ));
        };
        let length = scenario.spec().traffic.length;
        if self.lanes[lane].back().is_some_and(|c| c.s - length <= s) {
            return Err(SimError::invalid(
                scenario.name(),
                "cars must be placed downstream first, without overlap",
            ));
        }
        let car = new_car(&mut self.next_id, l, lane, s, v, v.max(0.1), length);
        self.lanes[lane].push_back(car);
        Ok(())
    }

    /// [`Traffic::place`] with a desired speed of its own and a driver
    /// (`None`: the scenario's `[traffic]` driver).
    pub fn place_driven(
        &mut self,
        scenario: &Scenario,
        lane: usize,
        (s, v, v_desired): (f64, f64, f64),
        driver: Option<Driver>,
    ) -> Result<(), SimError> {
        self.place(scenario, lane, s, v)?;
        let car = self.lanes[lane].back_mut().expect("just placed");
        car.v_desired = v_desired.max(0.1);
        car.driver = driver;
        Ok(())
    }

    fn emit(&mut self, scenario: &Scenario, li: usize, rng: &mut impl rand::Rng) {
        let p = &scenario.spec().traffic;
        let lane = &scenario.lanes()[li];
        if rng.random::<f64>() < lane.emission_per_s * scenario.dt() {
            self.emissions += 1;
            self.pending[li] = (self.pending[li] + 1).min(p.max_pending);
        }
        if self.pending[li] == 0 {
            return;
        }
        let cars = &mut self.lanes[li];
        let (gap, v_lead) = match cars.back() {
            Some(last) => (last.s - p.length, last.v),
            None => (f64::INFINITY, f64::INFINITY),
        };
        let factor = *self.next_factor[li].get_or_insert_with(|| {
            // The population's speed factor bounds, read once per car.
            let q = scenario.spec().drivers.traffic(p);
            let z: f64 = rng.sample(StandardNormal);
            (q.speed_factor_mean + q.speed_factor_dev * z)
                .clamp(q.speed_factor_min, q.speed_factor_max)
        });
        let v_desired = lane.speed_limit * factor;
        // Enter at the desired speed, or at the last car's speed if that is
        // slower (SUMO's departSpeed="max"), no closer than the desired gap
        // at that speed (and than the Krauss bound needs); until then the
        // emission waits, as SUMO's insertion backlog does. A faster car
        // does not wait for the gap it would want at its own speed, so
        // platoons form at the entrance as they do on the road.
        let v = v_desired.min(v_lead);
        let s_star = (p.min_gap + v * p.headway).max(v * p.tau + HARD_GAP);
        if gap < s_star {
            return;
        }
        self.pending[li] -= 1;
        self.next_factor[li] = None;
        self.insertions += 1;
        let mut car = new_car(&mut self.next_id, lane, li, 0.0, v, v_desired, p.length);
        car.driver = scenario.spec().drivers.draw(p, &mut self.drivers_rng);
        cars.push_back(car);
    }
}

/// Whether the car's driver reacts to the ego this step: once his reaction
/// time has passed since his lane's drivers could first see it coming, and,
/// if he is inattentive, only to an ego that has merged into his lane ahead
/// of him (he follows it as any leader).
fn notices(car: &Car, c: &EgoConflict, p: &TrafficParams) -> bool {
    c.noticed_s >= p.reaction_delay_s - 1e-9
        && (car.driver.is_none_or(|d| d.attentive) || (c.merge && c.occupying && car.s < c.rear))
}

/// SUMO's brake light for a step from speed `v` to `v_new`
/// (`MSVehicle::setBrakingSignals`): on when the car slows by more than
/// its pseudo friction `(0.05 + 0.005 v) v` m/s² over the step, or ends it
/// at 0.1 m/s or less.
fn brake_light(v: f64, v_new: f64, dt: f64) -> bool {
    v_new < v - (0.05 + 0.005 * v) * v * dt || v_new <= 0.1
}

/// Acceleration bound of a car that has noticed the ego (`INFINITY` for
/// none), by the rule of the module doc; `a_free` is the car's free-road
/// acceleration. Whether it could stop short is judged with
/// `emergency_decel`; braking for an ego on the junction is planned with
/// `decel` and finalized down to the emergency deceleration, as SUMO's is.
/// A car giving way to an ego about to merge ahead of it follows it as a
/// leader at its entry, bounded the same way; once the ego is in the merge
/// lane it is followed like any leader.
fn react(car: &mut Car, a_free: f64, c: &EgoConflict, p: &TrafficParams) -> f64 {
    let (v, v0) = (car.v, car.v_desired);
    let follow = |gap: f64| iidm_accel_with(a_free, v, v0, gap, c.v, p);
    if c.merge && c.occupying {
        return if car.s < c.rear {
            follow(c.rear - car.s)
        } else {
            f64::INFINITY
        };
    }
    // Where the car must stop if it gives way: short of the ego's path, or
    // behind the ego's footprint for a car already past the path's start.
    let target = if car.s < c.lane_in {
        c.lane_in
    } else if c.occupying && car.s < c.rear {
        c.rear
    } else {
        return f64::INFINITY;
    };
    let room = target - car.s - HARD_GAP;
    let after = c.t_exit + p.yield_margin_s;
    if !car.yielding {
        let (t_arrive, t_clear) = if car.v > 0.1 {
            (
                (target - car.s) / car.v,
                (c.lane_clear + p.length - car.s) / car.v,
            )
        } else {
            (f64::INFINITY, f64::INFINITY)
        };
        // A driver who could not stop short of the ego's path even with
        // emergency braking passes first, unless the ego is already in his
        // lane: starting to brake then only leaves him in the ego's path
        // later. Not at a merge: an ego merging ahead drives away along
        // his lane, and braking lets him fall in behind it (without this,
        // TTC on Right at 1 s collided 3.5 % of the time, drivers at full
        // speed into the side of the merging ego; SUMO 0.8 %).
        let can_stop =
            c.merge || c.occupying || car.v * car.v <= 2.0 * p.emergency_decel * room.max(0.0);
        car.yielding = t_clear + p.yield_margin_s > c.t_enter && t_arrive < after && can_stop;
    }
    if !car.yielding {
        return f64::INFINITY;
    }
    let hard = c.occupying || c.on_junction;
    if c.merge {
        // The ego is about to be its leader, entering at `c.v`. Driving on
        // past it is no option, so a driver who cannot slow to its speed
        // before its entry with comfortable braking brakes as hard as he
        // must.
        let follow = follow(target - car.s);
        let need = if car.v > c.v {
            (car.v * car.v - c.v * c.v) / (2.0 * room.max(0.1))
        } else {
            0.0
        };
        return if hard {
            follow.max(-p.emergency_decel)
        } else if need > p.yield_decel {
            follow.max(-need.min(p.emergency_decel))
        } else {
            follow.max(-p.yield_decel)
        };
    }
    let cap = if hard {
        p.emergency_decel
    } else {
        p.yield_decel
    };
    -give_way_decel(car.v, room, after).min(cap)
}

/// A car taking the next id at `s` on lane `li`, posed on the lane.
fn new_car(
    next_id: &mut u32,
    lane: &crate::scenario::Lane,
    li: usize,
    s: f64,
    v: f64,
    v_desired: f64,
    length: f64,
) -> Car {
    let mut car = Car {
        id: *next_id,
        lane: li,
        s,
        v,
        v_desired,
        braking: false,
        yielding: false,
        pos: Vec2::default(),
        axis: Vec2::default(),
        heading: 0.0,
        driver: None,
    };
    *next_id = next_id.wrapping_add(1);
    place(&mut car, lane, length);
    car
}

fn place(car: &mut Car, lane: &crate::scenario::Lane, length: f64) {
    let centre = car.s - 0.5 * length;
    if let Some((start, dir, heading)) = lane.straight {
        car.pos = start + dir * centre;
        car.axis = dir;
        car.heading = heading;
    } else {
        let pose = lane.path.pose_at(centre);
        car.pos = pose.pos;
        car.heading = pose.heading;
        car.axis = Vec2::from_angle(pose.heading);
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    use super::*;

    #[test]
    fn free_flow_speeds_follow_the_speed_factor() {
        let s = Scenario::builtin("challenge").unwrap();
        // Every car seen on the road at 10 s intervals over two minutes.
        let mut t = Traffic::new(&s);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        let mut seen = std::collections::HashMap::new();
        for i in 1..=(120.0 / s.dt()) as usize {
            t.step(&s, &[], &mut rng);
            if i % 50 == 0 {
                for c in t.cars() {
                    assert!((10.0..=30.0).contains(&c.v_desired), "{c:?}");
                    assert!(c.v <= c.v_desired + 1e-9);
                    seen.insert(c.id, c.v_desired);
                }
            }
        }
        let n = seen.len();
        assert!(n > 60, "{n}");
        let mean_factor = seen.values().map(|v| v / 20.0).sum::<f64>() / n as f64;
        assert!((mean_factor - 1.0).abs() < 0.05, "{mean_factor}");
    }

    fn lone_car(s: &Scenario, at: f64, v: f64) -> Traffic {
        let mut t = Traffic::new(s);
        let mut car = Car {
            id: 0,
            lane: 0,
            s: at,
            v,
            v_desired: v,
            braking: false,
            yielding: false,
            pos: Vec2::default(),
            axis: Vec2::default(),
            heading: 0.0,
            driver: None,
        };
        place(&mut car, &s.lanes()[0], 5.0);
        t.lanes[0].push_back(car);
        t
    }

    /// Mean speed of a lone car with a desired speed of 20 m/s from 60 to
    /// 250 m down a free road (settled after starting at 20 m/s).
    fn cruising_speed(s: &Scenario) -> f64 {
        let mut t = lone_car(s, 0.0, 20.0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        let (mut sum, mut n) = (0.0, 0);
        while t.lanes[0].front().is_some_and(|c| c.id == 0 && c.s < 250.0) {
            t.step(s, &[], &mut rng);
            if t.lanes[0][0].s > 60.0 {
                sum += t.lanes[0][0].v;
                n += 1;
            }
        }
        sum / f64::from(n)
    }

    #[test]
    fn free_cars_cruise_at_their_desired_speed_despite_dawdling() {
        // Krauss's free road: full acceleration back to the desired speed
        // after each dawdle, so a car loses on average sigma a dt / 2 =
        // 0.13 m/s (SUMO's cruising speed).
        let s = Scenario::builtin("forward").unwrap();
        let krauss = cruising_speed(&s);
        assert!((krauss - (20.0 - 0.13)).abs() < 0.05, "{krauss}");
        // IDM's free-road term, a (1 - (v/v0)^4), balances the mean dawdle
        // sigma a / 2 only at (1 - sigma / 2)^(1/4) = 0.93 of v0.
        let mut spec = s.spec().clone();
        spec.traffic.krauss_free_road = false;
        let idm = cruising_speed(&Scenario::compile(spec).unwrap());
        assert!((idm - 20.0 * 0.75_f64.powf(0.25)).abs() < 0.3, "{idm}");
    }

    /// The ego crossing lane 0 of `forward` between lane coordinates 150
    /// and 155, entering in `t_enter` and out in `t_exit` seconds.
    fn crossing(t_enter: f64, t_exit: f64, occupying: bool) -> [EgoFoe; 1] {
        [EgoFoe::Conflict(EgoConflict {
            lane_in: 150.0,
            lane_clear: 155.0,
            t_enter,
            t_exit,
            occupying,
            rear: 150.0,
            v: 0.0,
            merge: false,
            on_junction: occupying,
            noticed_s: f64::INFINITY,
        })]
    }

    /// One step of a lone car at 20 m/s at lane coordinate `at`, short of
    /// an ego on the junction from 150 m, whose lane saw the ego coming
    /// `noticed_s` ago; the car's speed after the step.
    fn speed_after_one_step(at: f64, driver: Option<Driver>, noticed_s: f64) -> f64 {
        let s = Scenario::builtin("forward").unwrap();
        let mut t = lone_car(&s, at, 20.0);
        t.lanes[0][0].driver = driver;
        let mut foes = crossing(0.0, 10.0, true);
        if let EgoFoe::Conflict(c) = &mut foes[0] {
            c.noticed_s = noticed_s;
        }
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        t.step(&s, &foes, &mut rng);
        t.lanes[0][0].v
    }

    fn human(reaction_s: f64, emergency_decel: f64, attentive: bool) -> Driver {
        Driver {
            reaction_s,
            yield_decel: 3.0,
            emergency_decel,
            headway: 1.5,
            attentive,
        }
    }

    #[test]
    fn each_driver_reacts_after_his_own_reaction_time() {
        // A stop short of the lane needs 3.3 m/s²; dawdling alone takes at
        // most sigma a dt = 0.26 m/s off in a step.
        let braked = |v: f64| v < 20.0 - 0.5;
        // The scenario's driver (0.2 s) reacts as soon as his lane has seen
        // the ego for one step; a slow driver not before his 1.5 s.
        assert!(braked(speed_after_one_step(90.0, None, 0.2)));
        assert!(!braked(speed_after_one_step(
            90.0,
            Some(human(1.5, 9.0, true)),
            1.4
        )));
        assert!(braked(speed_after_one_step(
            90.0,
            Some(human(1.5, 9.0, true)),
            1.5
        )));
        // An inattentive driver never brakes for an ego crossing his lane.
        assert!(!braked(speed_after_one_step(
            90.0,
            Some(human(0.7, 9.0, false)),
            10.0
        )));
    }

    #[test]
    fn a_driver_brakes_no_harder_than_he_can() {
        // 30 m short of an ego on the junction at 20 m/s a stop needs
        // 6.7 m/s²: a driver who can brake 9 m/s² does, one who can brake
        // 5.5 brakes that hard and no harder (dawdling may take 0.26 m/s
        // more off).
        let dt = 0.2;
        let weak = 20.0 - speed_after_one_step(120.0, Some(human(0.7, 5.5, true)), 10.0);
        let strong = 20.0 - speed_after_one_step(120.0, Some(human(0.7, 9.0, true)), 10.0);
        assert!(weak <= 5.5 * dt + 0.27 && weak >= 5.5 * dt - 1e-9, "{weak}");
        assert!(strong > 6.0 * dt, "{strong}");
    }

    #[test]
    fn cars_follow_an_ego_that_merged_into_their_lane() {
        let s = Scenario::builtin("forward").unwrap();
        let mut t = lone_car(&s, 50.0, 20.0);
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        // A stopped ego in the lane 100 m ahead of the car.
        let foes = [EgoFoe::Conflict(EgoConflict {
            lane_in: 140.0,
            lane_clear: 160.0,
            t_enter: 0.0,
            t_exit: 0.0,
            occupying: true,
            rear: 150.0,
            v: 0.0,
            merge: true,
            on_junction: true,
            noticed_s: f64::INFINITY,
        })];
        let mut braked = false;
        for _ in 0..200 {
            t.step(&s, &foes, &mut rng);
            let c = t.lanes[0][0];
            braked |= c.braking;
            assert!(c.s < 150.0, "{c:?}");
        }
        let c = t.lanes[0][0];
        assert!(c.v < 0.05 && c.s > 140.0, "{c:?}");
        assert!(braked && t.brake_time_s() > 0.0);
        assert_eq!(t.guard_hits(), 0);
    }

    #[test]
    fn only_cars_in_the_way_of_the_ego_react() {
        let s = Scenario::builtin("forward").unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let decel = |t: &mut Traffic, foes: &[EgoFoe], rng: &mut Xoshiro256PlusPlus| {
            let v = t.lanes[0][0].v;
            let mut calm = s.spec().clone();
            calm.traffic.sigma = 0.0;
            let calm = Scenario::compile(calm).unwrap();
            t.step(&calm, foes, rng);
            (v - t.lanes[0][0].v) / 0.2
        };
        // Clear of the crossing ((155 + 5 - 140) / 20 = 1 s) well before the
        // ego enters in 3 s: drives on.
        let mut t = lone_car(&s, 140.0, 20.0);
        assert!(decel(&mut t, &crossing(3.0, 4.0, false), &mut rng) < 1e-9);
        assert!(!t.lanes[0][0].yielding);
        // 100 m away, arriving in 5 s, after the ego is out (4 s) with
        // 0.5 s to spare: drives on.
        let mut t = lone_car(&s, 50.0, 20.0);
        assert!(decel(&mut t, &crossing(1.0, 4.0, false), &mut rng) < 1e-9);
        // 60 m away, arriving in 3 s, while the ego is in the lane: slows
        // just enough to arrive 0.5 s after the ego is out, at 4.5 s:
        // 2 (20 x 4.5 - 59.5) / 4.5^2 = 3.0 m/s².
        let mut t = lone_car(&s, 90.0, 20.0);
        let d = decel(&mut t, &crossing(1.0, 4.0, false), &mut rng);
        assert!((d - 3.012).abs() < 0.01 && t.lanes[0][0].braking, "{d}");
        // 30 m away: it would need 400 / 59 = 6.8 m/s² to stop short of the
        // crossing, but brakes only as hard as is comfortable (4.5) while the
        // ego is still outside its lane...
        let mut t = lone_car(&s, 120.0, 20.0);
        let d = decel(&mut t, &crossing(1.0, 4.0, false), &mut rng);
        assert!((d - 4.5).abs() < 1e-9, "{d}");
        // ...and as hard as it must once the ego is in it: 19.1 m/s with
        // 25.68 m to go, 7.1 m/s².
        let d = decel(&mut t, &crossing(0.0, 3.0, true), &mut rng);
        assert!((d - 19.1 * 19.1 / (2.0 * 25.68)).abs() < 1e-6, "{d}");
        assert!(t.lanes[0][0].yielding);
        // Up to 9 m/s² at most: 15 m away it would need 13.8.
        let mut t = lone_car(&s, 135.0, 20.0);
        let d = decel(&mut t, &crossing(0.0, 3.0, true), &mut rng);
        assert!((d - 9.0).abs() < 1e-9, "{d}");
        // Gone: it forgets the ego.
        decel(&mut t, &[EgoFoe::None], &mut rng);
        assert!(!t.lanes[0][0].yielding);
        // 15 m short of an ego that is about to enter, it cannot stop even
        // with 9 m/s² (13.8 needed): it passes first, without braking.
        let mut t = lone_car(&s, 135.0, 20.0);
        let d = decel(&mut t, &crossing(0.5, 3.0, false), &mut rng);
        assert!(d.abs() < 1e-9 && !t.lanes[0][0].yielding, "{d}");
    }

    #[test]
    fn cars_brake_as_hard_as_they_must_for_an_ego_on_the_junction() {
        let s = Scenario::builtin("forward").unwrap();
        let mut calm = s.spec().clone();
        calm.traffic.sigma = 0.0;
        let calm = Scenario::compile(calm).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        // 30 m short of the crossing at 20 m/s, the ego entering in 1 s:
        // stopping short takes 400 / (2 x 29.5) = 6.78 m/s².
        let decel = |on_junction: bool, rng: &mut Xoshiro256PlusPlus| {
            let mut t = lone_car(&s, 120.0, 20.0);
            let mut foes = crossing(1.0, 4.0, false);
            if let EgoFoe::Conflict(c) = &mut foes[0] {
                c.on_junction = on_junction;
            }
            t.step(&calm, &foes, rng);
            (20.0 - t.lanes[0][0].v) / 0.2
        };
        // An ego still behind its stop line that pulls out: comfortable
        // braking at most (SUMO's drivers do not yield to a foe that has
        // not entered the junction)...
        assert!((decel(false, &mut rng) - 4.5).abs() < 1e-9);
        // ...one on the junction is a junction leader: as hard as it takes.
        let d = decel(true, &mut rng);
        assert!((d - 400.0 / 59.0).abs() < 0.05, "{d}");
    }

    #[test]
    fn cars_brake_harder_than_comfortable_only_for_a_merge_they_cannot_follow() {
        let s = Scenario::builtin("forward").unwrap();
        let mut calm = s.spec().clone();
        calm.traffic.sigma = 0.0;
        let calm = Scenario::compile(calm).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        // The ego is about to enter lane 0 at coordinate 150, at 5 m/s.
        let merging = [EgoFoe::Conflict(EgoConflict {
            lane_in: 150.0,
            lane_clear: 155.0,
            t_enter: 0.5,
            t_exit: 5.0,
            occupying: false,
            rear: 150.0,
            v: 5.0,
            merge: true,
            on_junction: false,
            noticed_s: f64::INFINITY,
        })];
        let decel = |at: f64, rng: &mut Xoshiro256PlusPlus| {
            let mut t = lone_car(&s, at, 20.0);
            t.step(&calm, &merging, rng);
            (20.0 - t.lanes[0][0].v) / 0.2
        };
        // 30 m short of the entry: slowing to 5 m/s takes
        // (400 - 25) / (2 x 29.5) = 6.4 m/s², more than the comfortable
        // 4.5, and it brakes at least that hard.
        let d = decel(120.0, &mut rng);
        assert!((375.0 / 59.0 - 1e-9..=9.0).contains(&d), "{d}");
        // 55 m short: 3.4 m/s² would do; it brakes, no harder than 4.5.
        let d = decel(95.0, &mut rng);
        assert!(d > 0.0 && d <= 4.5 + 1e-9, "{d}");
        // 15 m short it could not stop short of the entry even with 9 m/s²
        // (13.8 needed), as the crossing car that passes first; behind a
        // merging ego it brakes as hard as it can instead.
        let d = decel(135.0, &mut rng);
        assert!((d - 9.0).abs() < 1e-9, "{d}");
    }

    #[test]
    fn give_way_decel_values() {
        // Enough time to stop: the stopping deceleration, 400 / 80.
        assert!((give_way_decel(20.0, 40.0, f64::INFINITY) - 5.0).abs() < 1e-12);
        assert!((give_way_decel(20.0, 40.0, 10.0) - 5.0).abs() < 1e-12);
        // 100 m to cover in at least 6 s: 2 (120 - 100) / 36.
        assert!((give_way_decel(20.0, 100.0, 6.0) - 40.0 / 36.0).abs() < 1e-12);
        // Already late enough: it may even speed up.
        assert!(give_way_decel(10.0, 100.0, 5.0) < 0.0);
        assert_eq!(give_way_decel(5.0, 0.0, 1.0), f64::INFINITY);
        assert_eq!(give_way_decel(0.0, 0.0, 1.0), 0.0);
    }
}
