//! Scenario descriptions (serde data: built-in TOML files or a user's file)
//! and their compiled form: lanes, the ego's path, conflict zones and the
//! ego's speed profile.

use serde::{Deserialize, Serialize};

use crate::drivers::DriverPopulation;
use crate::error::SimError;
use crate::geometry::{OrientedRect, Vec2};
use crate::occlusion::{ObstacleSpec, OcclusionSpec, Side};
use crate::params::{EgoParams, Rewards, TrafficParams};
use crate::path::{Path, PathSpec};

/// Built-in scenario files, embedded so the library works without the
/// `configs/` folder.
const BUILTIN: &[(&str, &str)] = &[
    ("right", include_str!("../../configs/scenarios/right.toml")),
    ("left", include_str!("../../configs/scenarios/left.toml")),
    ("left2", include_str!("../../configs/scenarios/left2.toml")),
    (
        "forward",
        include_str!("../../configs/scenarios/forward.toml"),
    ),
    (
        "challenge",
        include_str!("../../configs/scenarios/challenge.toml"),
    ),
    (
        "occluded",
        include_str!("../../configs/scenarios/occluded.toml"),
    ),
];

/// A scenario as written in a TOML file. See `configs/scenarios/` for
/// examples; [`Scenario::load`] reads one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioSpec {
    /// Name shown in reports.
    pub name: String,
    /// One line for people.
    #[serde(default)]
    pub description: String,
    /// Simulation step, s.
    #[serde(default = "default_step")]
    pub step_s: f64,
    /// Steps before an episode times out.
    pub step_limit: u32,
    /// Default speed limit of the lanes, m/s.
    pub speed_limit: f64,
    /// Default probability per second that a lane emits a car.
    pub emission_per_s: f64,
    /// Whether traffic brakes for an ego that occupies or is about to enter
    /// its lane. Without, nobody brakes for the ego on its way; an ego that
    /// has merged a car length into a lane is still followed there like any
    /// leader.
    #[serde(default = "default_true")]
    pub traffic_reacts: bool,
    /// Seconds of traffic simulated before the episode starts, so the road
    /// is in its steady state.
    #[serde(default = "default_warmup")]
    pub warmup_s: f64,
    /// Whether observations carry the occlusion channels. Defaults to
    /// whether the scenario has occluders.
    #[serde(default)]
    pub occlusion_channels: Option<bool>,
    /// Traffic lanes.
    pub lanes: Vec<LaneSpec>,
    /// The ego's route and limits.
    pub ego: EgoSpec,
    /// Traffic vehicle parameters.
    #[serde(default)]
    pub traffic: TrafficParams,
    /// Who drives the traffic, drawn per car as it enters its lane. Unset
    /// (the `sumo` preset): every car has the `[traffic]` driver. Its
    /// speed factor bounds replace `[traffic]`'s where a car's desired
    /// speed is drawn (and in the export for SUMO); `[traffic]` itself
    /// stays as written, so another population can replace this one.
    #[serde(default)]
    pub drivers: DriverPopulation,
    /// Rewards.
    #[serde(default)]
    pub rewards: Rewards,
    /// Fixed occluders.
    #[serde(default)]
    pub obstacles: Vec<ObstacleSpec>,
    /// Random occluders drawn each episode.
    #[serde(default)]
    pub occlusion: Option<OcclusionSpec>,
}

fn default_step() -> f64 {
    0.2
}
fn default_true() -> bool {
    true
}
fn default_warmup() -> f64 {
    16.0
}

/// A traffic lane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaneSpec {
    /// Name, for people.
    pub name: String,
    /// Centre line in driving direction; cars enter at its start.
    pub path: PathSpec,
    /// Overrides the scenario's speed limit.
    #[serde(default)]
    pub speed_limit: Option<f64>,
    /// Overrides the scenario's emission probability.
    #[serde(default)]
    pub emission_per_s: Option<f64>,
}

/// The ego's route. Arc lengths are of the ego's front bumper along `path`
/// (the centre of the car follows the path).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgoSpec {
    /// Route of the ego's centre.
    pub path: PathSpec,
    /// Arc length of the stop line; the ego starts stopped with its front
    /// bumper on it.
    pub stop_line_s: f64,
    /// The episode succeeds when the front bumper passes this arc length.
    pub goal_s: f64,
    /// *Creep* never moves the front bumper past this arc length.
    pub creep_limit_s: f64,
    /// Dynamics.
    #[serde(default)]
    pub params: EgoParams,
}

/// Where the ego's path meets a lane: the ego's front-bumper arc lengths
/// during which its footprint overlaps the lane's band (the swept width of
/// traffic), and the lane coordinates of that overlap.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ConflictZone {
    /// First ego arc length with overlap.
    pub ego_in: f64,
    /// Last ego arc length with overlap (the goal for a merge).
    pub ego_out: f64,
    /// Smallest lane coordinate the ego covers.
    pub lane_in: f64,
    /// Largest lane coordinate the ego covers.
    pub lane_out: f64,
    /// The ego ends its route in this lane (it merges rather than crosses).
    pub merge: bool,
    /// For a merge, the largest lane coordinate the ego covers during its
    /// first car length in the lane: a car whose rear is past it is ahead
    /// of the merging ego.
    pub lane_merge_clear: f64,
}

impl ConflictZone {
    /// Lane coordinate a car's rear must pass before the car is no longer a
    /// threat: the far edge of a crossing, the entry point of a merge (once
    /// past it, the car drives away ahead of the ego).
    pub fn lane_clear(&self) -> f64 {
        if self.merge {
            self.lane_merge_clear
        } else {
            self.lane_out
        }
    }
}

/// A compiled lane.
#[derive(Debug, Clone)]
pub struct Lane {
    /// Name.
    pub name: String,
    /// Centre line.
    pub path: Path,
    /// Speed limit, m/s.
    pub speed_limit: f64,
    /// Probability per second of emitting a car.
    pub emission_per_s: f64,
    /// Where the ego's path meets this lane, if it does.
    pub zone: Option<ConflictZone>,
    /// Start, unit direction and heading when the lane is one straight
    /// piece (all built-in lanes), for fast placement of cars.
    pub straight: Option<(Vec2, Vec2, f64)>,
}

impl Lane {
    /// Lane coordinate of the point of the centre line nearest to `p`.
    pub fn coordinate(&self, p: Vec2) -> f64 {
        match self.straight {
            Some((start, dir, _)) => (p - start).dot(dir),
            None => self.path.project(p).0,
        }
    }
}

/// A compiled scenario, ready to simulate. Cheap to share behind an `Arc`.
#[derive(Debug, Clone)]
pub struct Scenario {
    spec: ScenarioSpec,
    lanes: Vec<Lane>,
    ego_path: Path,
    fixed_obstacles: Vec<OrientedRect>,
    /// Largest ego speed at each `PROFILE_STEP` of front-bumper arc length.
    speed_profile: Vec<f64>,
    occlusion_channels: bool,
}

/// Resolution of the ego speed profile, m.
const PROFILE_STEP: f64 = 0.25;
/// Resolution of the conflict-zone search along the ego path, m.
const ZONE_STEP: f64 = 0.05;
/// Braking the ego plans with before a curve, m/s².
const CURVE_BRAKE: f64 = 3.0;

impl Scenario {
    /// Names of the built-in scenarios. The occlusion family also accepts
    /// `occluded-<length>[-<side>]`, e.g. `occluded-60` or `occluded-90-left`,
    /// which fix the drawn length (and side).
    pub fn builtin_names() -> Vec<&'static str> {
        BUILTIN.iter().map(|(n, _)| *n).collect()
    }

    /// A built-in scenario by name.
    pub fn builtin(name: &str) -> Result<Self, SimError> {
        let unknown = || SimError::UnknownScenario {
            name: name.to_owned(),
            known: format!(
                "{}, occluded-<30|60|90>[-<left|right|both>]",
                Self::builtin_names().join(", ")
            ),
        };
        if let Some((_, text)) = BUILTIN.iter().find(|(n, _)| *n == name) {
            return Self::from_toml_str(text, name);
        }
        let Some(rest) = name.strip_prefix("occluded-") else {
            return Err(unknown());
        };
        let (_, text) = BUILTIN
            .iter()
            .find(|(n, _)| *n == "occluded")
            .ok_or_else(unknown)?;
        let mut spec = parse_spec(text, "occluded")?;
        let occ = spec.occlusion.as_mut().ok_or_else(unknown)?;
        let mut parts = rest.split('-');
        let length: f64 = parts
            .next()
            .and_then(|l| l.parse().ok())
            .ok_or_else(unknown)?;
        occ.lengths = vec![length];
        if let Some(side) = parts.next() {
            occ.sides = vec![match side {
                "left" => Side::Left,
                "right" => Side::Right,
                "both" => Side::Both,
                _ => return Err(unknown()),
            }];
        }
        if parts.next().is_some() {
            return Err(unknown());
        }
        spec.name = name.to_owned();
        Self::compile(spec)
    }

    /// A built-in scenario by name, or a scenario file if `name_or_path`
    /// ends in `.toml` or contains a path separator.
    pub fn load(name_or_path: &str) -> Result<Self, SimError> {
        if name_or_path.ends_with(".toml")
            || name_or_path.contains(std::path::MAIN_SEPARATOR)
            || name_or_path.contains('/')
        {
            Self::from_file(std::path::Path::new(name_or_path))
        } else {
            Self::builtin(name_or_path)
        }
    }

    /// [`Scenario::load`], then, when `drivers` names a preset (`sumo`,
    /// `human`) or a drivers TOML file, with that population in place of
    /// the scenario's own.
    pub fn load_with_drivers(name_or_path: &str, drivers: Option<&str>) -> Result<Self, SimError> {
        let scenario = Self::load(name_or_path)?;
        match drivers {
            Some(d) => scenario.with_drivers(DriverPopulation::load(d)?),
            None => Ok(scenario),
        }
    }

    /// Reads a scenario file.
    pub fn from_file(path: &std::path::Path) -> Result<Self, SimError> {
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses a scenario from TOML text; `what` names it in errors.
    pub fn from_toml_str(text: &str, what: &str) -> Result<Self, SimError> {
        Self::compile(parse_spec(text, what)?)
    }

    /// This scenario with another driver population (a preset or a user's
    /// table), replacing its `[drivers]`.
    pub fn with_drivers(&self, drivers: DriverPopulation) -> Result<Self, SimError> {
        let mut spec = self.spec.clone();
        spec.drivers = drivers;
        Self::compile(spec)
    }

    /// Validates and compiles a description.
    pub fn compile(spec: ScenarioSpec) -> Result<Self, SimError> {
        let what = spec.name.clone();
        let what = what.as_str();
        spec.drivers.check(&format!("{what} drivers"))?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(spec.step_s) || spec.step_limit == 0 || !positive(spec.speed_limit) {
            return Err(SimError::invalid(
                what,
                "step_s, step_limit and speed_limit must be positive",
            ));
        }
        if !(spec.warmup_s.is_finite() && spec.warmup_s >= 0.0) {
            return Err(SimError::invalid(what, "warmup_s must be zero or more"));
        }
        if spec.lanes.is_empty() {
            return Err(SimError::invalid(
                what,
                "a scenario needs at least one lane",
            ));
        }
        let ego_path = Path::from_spec(&spec.ego.path, &format!("{what} ego path"))?;
        let e = &spec.ego;
        if !(e.stop_line_s < e.creep_limit_s
            && e.creep_limit_s < e.goal_s
            && e.goal_s <= ego_path.length())
        {
            return Err(SimError::invalid(
                what,
                "the ego needs stop_line_s < creep_limit_s < goal_s <= path length",
            ));
        }
        if e.stop_line_s < e.params.length {
            return Err(SimError::invalid(
                what,
                "the ego's path must start a car length before the stop line",
            ));
        }
        let p = &e.params;
        let allowance_ok =
            p.turn_angle_allowance_deg.is_finite() && p.turn_angle_allowance_deg >= 0.0;
        if !allowance_ok
            || ![
                p.length,
                p.width,
                p.accel,
                p.decel,
                p.max_speed,
                p.lateral_accel,
                p.lane_width,
                p.creep_speed,
            ]
            .into_iter()
            .all(positive)
        {
            return Err(SimError::invalid(
                what,
                "ego parameters must be positive (turn_angle_allowance_deg zero or more)",
            ));
        }
        let t = &spec.traffic;
        if ![
            t.length,
            t.width,
            t.accel,
            t.decel,
            t.emergency_decel,
            t.tau,
            t.headway,
            t.min_gap,
            t.idm_delta,
        ]
        .into_iter()
        .all(positive)
            || t.emergency_decel < t.decel
            || !(0.0..=1.0).contains(&t.sigma)
        {
            return Err(SimError::invalid(what, "traffic parameters out of range"));
        }
        let mut lanes = Vec::with_capacity(spec.lanes.len());
        for (i, l) in spec.lanes.iter().enumerate() {
            let path = Path::from_spec(&l.path, &format!("{what} lane {i}"))?;
            let speed_limit = l.speed_limit.unwrap_or(spec.speed_limit);
            let emission_per_s = l.emission_per_s.unwrap_or(spec.emission_per_s);
            if !(positive(speed_limit)
                && emission_per_s >= 0.0
                && emission_per_s * spec.step_s <= 1.0)
            {
                return Err(SimError::invalid(
                    what,
                    format!("lane {}: bad speed limit or emission", l.name),
                ));
            }
            let zone = conflict_zone(&ego_path, &spec.ego, &path, t.width);
            let straight = path.as_straight().map(|(p0, d)| (p0, d, d.y.atan2(d.x)));
            lanes.push(Lane {
                name: l.name.clone(),
                path,
                speed_limit,
                emission_per_s,
                zone,
                straight,
            });
        }
        if let Some(occ) = &spec.occlusion {
            occ.validate(what)?;
        }
        let fixed_obstacles = spec.obstacles.iter().map(ObstacleSpec::rect).collect();
        let occlusion_channels = spec
            .occlusion_channels
            .unwrap_or(spec.occlusion.is_some() || !spec.obstacles.is_empty());
        let speed_profile = speed_profile(&ego_path, &spec.ego);
        Ok(Self {
            spec,
            lanes,
            ego_path,
            fixed_obstacles,
            speed_profile,
            occlusion_channels,
        })
    }

    /// Name.
    pub fn name(&self) -> &str {
        &self.spec.name
    }

    /// The description it was compiled from.
    pub fn spec(&self) -> &ScenarioSpec {
        &self.spec
    }

    /// Lanes.
    pub fn lanes(&self) -> &[Lane] {
        &self.lanes
    }

    /// The ego's path (of its centre).
    pub fn ego_path(&self) -> &Path {
        &self.ego_path
    }

    /// Step, s.
    pub fn dt(&self) -> f64 {
        self.spec.step_s
    }

    /// Whether observations carry the occlusion channels.
    pub fn occlusion_channels(&self) -> bool {
        self.occlusion_channels
    }

    /// Occluders present in every episode.
    pub fn fixed_obstacles(&self) -> &[OrientedRect] {
        &self.fixed_obstacles
    }

    /// Largest speed of the ego with its front bumper at arc length `s`, so
    /// that it can take every curve ahead within its lateral acceleration.
    pub fn ego_speed_cap(&self, s: f64) -> f64 {
        let i = (s.max(0.0) / PROFILE_STEP) as usize;
        self.speed_profile[i.min(self.speed_profile.len() - 1)]
    }
}

fn parse_spec(text: &str, what: &str) -> Result<ScenarioSpec, SimError> {
    toml::from_str(text).map_err(|e| SimError::Parse {
        what: what.to_owned(),
        source: Box::new(e),
    })
}

/// The ego's footprint with its front bumper at arc length `s`.
pub(crate) fn ego_rect(path: &Path, params: &EgoParams, s: f64) -> OrientedRect {
    let pose = path.pose_at(s - 0.5 * params.length);
    OrientedRect::new(pose.pos, pose.heading, params.length, params.width)
}

fn conflict_zone(
    ego_path: &Path,
    ego: &EgoSpec,
    lane: &Path,
    traffic_width: f64,
) -> Option<ConflictZone> {
    let entry_len = ego.params.length;
    // A small margin so grazing contacts also count as conflicts.
    let half_band = 0.5 * traffic_width + 0.1;
    let mut zone: Option<ConflictZone> = None;
    let mut s = ego.stop_line_s;
    while s <= ego.goal_s + 1e-9 {
        let corners = ego_rect(ego_path, &ego.params, s).corners();
        let mut lo_lat = f64::INFINITY;
        let mut hi_lat = f64::NEG_INFINITY;
        let mut lo_l = f64::INFINITY;
        let mut hi_l = f64::NEG_INFINITY;
        for c in corners {
            let (l, lat) = lane.project(c);
            lo_lat = lo_lat.min(lat);
            hi_lat = hi_lat.max(lat);
            lo_l = lo_l.min(l);
            hi_l = hi_l.max(l);
        }
        if hi_lat >= -half_band && lo_lat <= half_band {
            let z = zone.get_or_insert(ConflictZone {
                ego_in: s,
                ego_out: s,
                lane_in: lo_l,
                lane_out: hi_l,
                merge: false,
                lane_merge_clear: hi_l,
            });
            z.ego_out = s;
            if s <= z.ego_in + entry_len {
                z.lane_merge_clear = z.lane_merge_clear.max(hi_l);
            }
            z.lane_in = z.lane_in.min(lo_l);
            z.lane_out = z.lane_out.max(hi_l);
        }
        s += ZONE_STEP;
    }
    if let Some(z) = zone.as_mut() {
        z.merge = z.ego_out + ZONE_STEP > ego.goal_s;
    }
    zone
}

/// The speed limit of a turn by SUMO's netconvert rule
/// ([`EgoParams::lateral_accel`]).
pub(crate) fn turn_speed(length: f64, radius: f64, p: &EgoParams) -> f64 {
    let angle = length / radius - p.turn_angle_allowance_deg.to_radians();
    if angle <= 0.0 || length <= 1.0 {
        return f64::INFINITY;
    }
    (p.lateral_accel * (length / angle + 0.25 * p.lane_width)).sqrt()
}

fn speed_profile(path: &Path, ego: &EgoSpec) -> Vec<f64> {
    let p = &ego.params;
    let n = (path.length() / PROFILE_STEP) as usize + 2;
    let mut v = vec![p.max_speed; n];
    // A turn limits the ego while its front's arc length is on the arc, as
    // SUMO limits a vehicle by the lane its front is on (its lane position
    // is the front's, and its internal lane is our arc).
    for (start, length, radius) in path.arcs() {
        let cap = turn_speed(length, radius, p);
        let (lo, hi) = (start, start + length);
        for (i, vi) in v.iter_mut().enumerate() {
            let s = i as f64 * PROFILE_STEP;
            if s >= lo - PROFILE_STEP && s <= hi {
                *vi = vi.min(cap);
            }
        }
    }
    for i in (0..n - 1).rev() {
        let reachable = (v[i + 1] * v[i + 1] + 2.0 * CURVE_BRAKE * PROFILE_STEP).sqrt();
        v[i] = v[i].min(reachable);
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtins_compile_with_expected_zones() {
        for name in Scenario::builtin_names() {
            let s = Scenario::builtin(name).unwrap();
            assert!(s.lanes().iter().any(|l| l.zone.is_some()), "{name}");
        }
        let left = Scenario::builtin("left").unwrap();
        let zones: Vec<_> = left.lanes().iter().map(|l| l.zone.unwrap()).collect();
        // Crosses the near (eastbound) lane, merges into the far one.
        assert!(!zones[0].merge && zones[1].merge, "{zones:?}");
        let right = Scenario::builtin("right").unwrap();
        assert!(right.lanes()[0].zone.unwrap().merge);
        assert!(right.lanes()[1].zone.is_none());
        let fwd = Scenario::builtin("forward").unwrap();
        assert!(fwd.lanes().iter().all(|l| !l.zone.unwrap().merge));
        let ch = Scenario::builtin("challenge").unwrap();
        assert_eq!(ch.lanes().len(), 6);
    }

    #[test]
    fn occluded_names_fix_the_family() {
        let s = Scenario::builtin("occluded-60-left").unwrap();
        let occ = s.spec().occlusion.as_ref().unwrap();
        assert_eq!(occ.lengths, vec![60.0]);
        assert_eq!(occ.sides, vec![Side::Left]);
        assert!(s.occlusion_channels());
        assert!(Scenario::builtin("occluded-x").is_err());
        assert!(Scenario::builtin("occluded-60-up").is_err());
        assert!(matches!(
            Scenario::builtin("nope"),
            Err(SimError::UnknownScenario { .. })
        ));
    }

    #[test]
    fn speed_profile_slows_for_turns_as_sumo_does() {
        let left = Scenario::builtin("left").unwrap();
        let stop = left.spec().ego.stop_line_s;
        // The 6.25 m quarter circle, 9.817 m long: netconvert's effective
        // radius 9.817 / (90 - 15 degrees) + 3.5 / 4 = 8.375 m, and
        // sqrt(5.5 x 8.375) = 6.787 m/s.
        let want =
            (5.5_f64 * (6.25 * std::f64::consts::FRAC_PI_2 / 75f64.to_radians() + 0.875)).sqrt();
        assert!((want - 6.787).abs() < 1e-3, "{want}");
        // The arc runs from the stop line to 9.8 m past it.
        for s in [stop + 0.5, stop + 5.0, stop + 9.5] {
            let on_arc = left.ego_speed_cap(s);
            assert!((on_arc - want).abs() < 1e-9, "{s}: {on_arc}");
        }
        // Once the front has left the arc the ego may speed up, body still
        // in the turn or not.
        assert!(left.ego_speed_cap(stop + 10.5) > want + 0.5);
        // Before the arc the ego may be faster, but not so fast that it
        // could not brake down at 3 m/s² in time.
        let before = left.ego_speed_cap(stop - 10.0);
        assert!(
            before > want && before * before <= want * want + 2.0 * 3.0 * 10.0,
            "{before}"
        );
        assert!(left.ego_speed_cap(left.spec().ego.goal_s + 40.0) > 10.0);
        // A turn of less than the allowance costs no speed.
        let p = EgoParams::default();
        assert_eq!(turn_speed(2.0, 10.0, &p), f64::INFINITY);
    }

    #[test]
    fn bad_files_are_errors() {
        assert!(matches!(
            Scenario::from_toml_str("name = 1", "x"),
            Err(SimError::Parse { .. })
        ));
        let mut spec = Scenario::builtin("left").unwrap().spec().clone();
        spec.ego.goal_s = 1.0;
        assert!(matches!(
            Scenario::compile(spec),
            Err(SimError::Invalid { .. })
        ));
    }
}
