//! Tunable physical parameters of traffic, ego and rewards, with the paper's
//! and SUMO's defaults. Every field can be overridden in a scenario file.

use serde::{Deserialize, Serialize};

/// Traffic vehicles: size, IDM car following, Krauss dawdling, desired
/// speeds and how they react to the ego. Defaults are SUMO's passenger car.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrafficParams {
    /// Car length, m.
    pub length: f64,
    /// Car width, m.
    pub width: f64,
    /// IDM maximum acceleration `a`, m/s².
    pub accel: f64,
    /// IDM comfortable deceleration `b`, m/s².
    pub decel: f64,
    /// Hardest physically possible braking, m/s².
    pub emergency_decel: f64,
    /// Krauss driver imperfection: each step speed drops by
    /// `sigma * accel * dt * U[0,1)`.
    pub sigma: f64,
    /// Reaction time of the Krauss safe speed, s (SUMO's tau).
    pub tau: f64,
    /// IDM desired time headway `T`, s. Traffic follows the improved IDM
    /// ([`crate::iidm_accel`]), which keeps this headway in platoons; 0.8 s
    /// (a little under SUMO's tau of 1 s) gives a lane a capacity of about
    /// 0.8 cars/s at the platoon speeds seen, 17 to 18 m/s.
    pub headway: f64,
    /// IDM standstill gap `s0`, m (SUMO's minGap).
    pub min_gap: f64,
    /// IDM acceleration exponent `delta`.
    pub idm_delta: f64,
    /// Free-road acceleration by Krauss's rule ([`crate::krauss_free_accel`]:
    /// the full `accel` up to the desired speed, as SUMO's cars) rather than
    /// IDM's (`accel (1 - (v/v0)^delta)`), which under dawdling leaves cars
    /// cruising below their desired speed, in streams slower than SUMO's
    /// (reports/sumo/NOTES.md).
    pub krauss_free_road: bool,
    /// Mean of the speed factor (desired speed = lane limit x factor).
    pub speed_factor_mean: f64,
    /// Standard deviation of the speed factor.
    pub speed_factor_dev: f64,
    /// Lower clip of the speed factor.
    pub speed_factor_min: f64,
    /// Upper clip of the speed factor.
    pub speed_factor_max: f64,
    /// Drivers of a lane take an ego that is moving towards it as coming
    /// when it would reach the lane within this many seconds.
    pub yield_horizon_s: f64,
    /// Hardest braking a driver accepts to give way to an ego that is
    /// pulling out in front of him (SUMO's comfortable `decel`); a driver
    /// who would need more drives on, keeping his right of way. Only an ego
    /// already in his lane, or about to merge into it ahead of him (he
    /// cannot drive on past it), is braked for harder, up to
    /// `emergency_decel`. m/s².
    pub yield_decel: f64,
    /// Margin, s, either side of the ego's passage through a lane: a car
    /// clear of the ego's path this long before the ego enters, or arriving
    /// this long after it is out, is not in its way.
    pub yield_margin_s: f64,
    /// Seconds the drivers of a lane need to notice an ego that comes at
    /// (or into) their lane before they react to it at all. One 0.2 s step,
    /// as in SUMO, whose drivers act on what they see every action step
    /// (by default the simulation step) and carry their reaction time in
    /// the Krauss safe speed (`tau`) instead. With 0.5 s, a car 35 to 40 m
    /// up the far lane could not avoid an ego merging at turn speed, and
    /// TTC on Left stayed under 99 % at every threshold.
    pub reaction_delay_s: f64,
    /// A car counts as braking while its intended deceleration (car
    /// following and reaction to the ego, before random dawdling) exceeds
    /// this, m/s². Dawdling alone (at most `sigma * accel`) never counts.
    pub brake_threshold: f64,
    /// Braking counts only for cars whose centre is within this distance of
    /// the origin (the intersection's centre in every built-in scenario), m.
    /// Cars settling into the flow right after entering their lane, far
    /// upstream, are not disturbed by the ego.
    pub brake_zone: f64,
    /// At most this many emissions wait for a blocked lane entrance (SUMO's
    /// insertion backlog); more are dropped.
    pub max_pending: u32,
}

impl Default for TrafficParams {
    fn default() -> Self {
        Self {
            length: 5.0,
            width: 1.8,
            accel: 2.6,
            decel: 4.5,
            emergency_decel: 9.0,
            sigma: 0.5,
            tau: 1.0,
            headway: 0.8,
            min_gap: 2.5,
            idm_delta: 4.0,
            krauss_free_road: true,
            speed_factor_mean: 1.0,
            speed_factor_dev: 0.1,
            speed_factor_min: 0.2,
            speed_factor_max: 2.0,
            yield_horizon_s: 6.0,
            yield_decel: 4.5,
            yield_margin_s: 0.5,
            reaction_delay_s: 0.2,
            brake_threshold: 1.0,
            brake_zone: 100.0,
            max_pending: 64,
        }
    }
}

/// The ego vehicle: size and the dynamics behind each action.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EgoParams {
    /// Length, m.
    pub length: f64,
    /// Width, m.
    pub width: f64,
    /// Acceleration of *go* and *accelerate*, m/s². SUMO's default, as the
    /// ego is a car of the same type as traffic.
    pub accel: f64,
    /// Deceleration of *decelerate* and of stopping to wait, m/s².
    pub decel: f64,
    /// Top speed on the ego's path, m/s.
    pub max_speed: f64,
    /// Sets the speed limit of each turn as SUMO's netconvert sets that of
    /// a junction's internal lane (`junctions.limit-turn-speed`, 5.5 m/s²
    /// by default; `NBEdge::buildInnerEdges`): `sqrt(lateral_accel x r)`
    /// with the arc's effective radius
    /// `r = length / (angle - turn_angle_allowance) + lane_width / 4`, m/s².
    /// The limit holds while the front
    /// bumper is on the arc (SUMO limits a vehicle by the lane its front is
    /// on), and the ego brakes for it in advance.
    pub lateral_accel: f64,
    /// Angle of a turn that costs no speed, degrees (netconvert's
    /// `junctions.limit-turn-speed.min-angle`, 15).
    pub turn_angle_allowance_deg: f64,
    /// Width of the ego's lane in the turn, m (a quarter of it is added to
    /// the radius: "permit higher turning speed on wide lanes").
    pub lane_width: f64,
    /// Target speed of *creep*, m/s.
    pub creep_speed: f64,
}

impl Default for EgoParams {
    fn default() -> Self {
        Self {
            length: 5.0,
            width: 1.8,
            accel: 2.6,
            decel: 4.5,
            max_speed: 15.0,
            lateral_accel: 5.5,
            turn_angle_allowance_deg: 15.0,
            lane_width: 3.5,
            creep_speed: 1.0,
        }
    }
}

/// Rewards of the paper.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Rewards {
    /// On reaching the goal.
    pub success: f64,
    /// On a collision.
    pub collision: f64,
    /// Every step, the terminal one included.
    pub step: f64,
}

impl Rewards {
    /// The undiscounted return of an episode that ended `outcome` after
    /// `steps` steps: the step reward on every step, plus the success or
    /// collision reward (a timeout earns the step rewards alone).
    pub fn episode_return(&self, outcome: crate::Outcome, steps: u32) -> f64 {
        let end = match outcome {
            crate::Outcome::Success => self.success,
            crate::Outcome::Collision => self.collision,
            crate::Outcome::Timeout => 0.0,
        };
        self.step * f64::from(steps) + end
    }
}

impl Default for Rewards {
    fn default() -> Self {
        Self {
            success: 1.0,
            collision: -10.0,
            step: -0.01,
        }
    }
}
