//! The intersection simulator that replaces SUMO: pure Rust, no learning,
//! no networking, no allocation per step.
//!
//! A [`Scenario`] (serde data: the built-in TOML files in
//! `configs/scenarios/`, embedded here, or a user's file) describes lanes as
//! [`Path`]s of straight pieces and arcs, the ego's route with its stop line,
//! creep limit and goal, traffic and ego parameters, rewards and occluders.
//! Compiling it finds the [`ConflictZone`] of every lane the ego's route
//! meets. An [`Env`] runs episodes of a scenario: [`Traffic`] (improved-IDM
//! car following with Krauss's free road, safety and dawdling, emission per lane,
//! drivers that brake for an ego in their way), the ego driven by an [`ActionSet`]
//! (TTG, Sequential, Creep-and-Go; a k-step action is one transition,
//! [`StepResult`]), oriented-rectangle collisions ([`OrientedRect`]), and
//! grid observations written into caller buffers ([`ObsSpec`]). A [`Policy`]
//! chooses actions for a batch of environments; the baselines are
//! [`TtcPolicy`] (with or without creeping) and [`RandomPolicy`].
//! [`evaluate`] runs seeded trials in parallel (same result on any number of
//! threads) into an [`EvalReport`]; [`tune_ttc`] sweeps TTC thresholds;
//! [`bench_scenario`] measures throughput; a [`Scene`] describes a picture
//! of a state (for `crossroads render`); [`Scenario::export`] gives a
//! compiled scenario as plain data ([`ScenarioExport`]) from which
//! `crossroads sumo-check` builds SUMO's network. The baselines also
//! include [`NeverPolicy`] (the ego never goes: traffic alone). A
//! [`DriverPopulation`] (a scenario's `[drivers]`, or a preset: `sumo`,
//! `human`) draws each car's [`Driver`] as it enters: reaction time,
//! braking, headway, attention.
//!
//! # Frame and units
//!
//! Metres, seconds, radians counter-clockwise from east. In every built-in
//! scenario the intersection's centre is the origin, the major road runs
//! along x (eastbound lanes at y < 0, westbound at y > 0, 3.5 m lanes), and
//! the ego comes from the south on the minor road at x = 1.75.
//!
//! # Observations
//!
//! A flat `f32` vector of [`ObsSpec::len`] values: a channel-major grid
//! `[channels][rows][cols]` ([`ObsSpec::index`]) followed by
//! [`EGO_FEATURES`] dense ego features. Cells without a car are 0 in every
//! car channel, so grids are sparse. A car is written into the one cell that
//! holds its centre; if two cars share a cell, the one written last (lanes in
//! scenario order, downstream cars first) wins. Cars outside the grid, and
//! cars in cells the sensor cannot see, are absent.
//!
//! The sizes are written only here: batches and networks carry them as the
//! data [`ObsSpec::layout`] gives (a `crossroads_types::ObservationLayout`),
//! and [`observation_layout`] gives a view's layout by name
//! ([`OBSERVATION_KINDS`]) without building an environment.
//!
//! **TTG grid** ([`ObsKind::Ttg`], 18 x 26): fixed in the world, x from
//! -104 to 104 m in 26 columns of 8 m (column 0 west), y from 18 to -18 m in
//! 18 rows of 2 m (row 0 north). Channels:
//!
//! | channel | value |
//! | --- | --- |
//! | 0 occupied | 1 |
//! | 1 heading | heading / pi, in (-1, 1] (east 0, north 0.5, west 1) |
//! | 2 speed | speed / scenario speed limit (20 m/s), about 0 to 1.3 |
//! | 3 x offset | of the car's centre from its cell's centre, in cells, in [-0.5, 0.5) (east) |
//! | 4 y offset | the same along y (north) |
//!
//! **Sequential grid** ([`ObsKind::Sequential`], 5 x 11): in the ego's
//! frame from its sensor point (the middle of its front bumper): 5 rows of
//! 4 m from 0 to 20 m ahead (row 0 nearest), 11 columns of 180/11 m from
//! 90 m left to 90 m right (column 0 leftmost). Channels: 0 occupied, 1
//! heading relative to the ego's / pi, 2 speed / speed limit, 3 time to
//! collision ([`Env::car_ttc`]) / 10 s, capped at 1 (1 also for cars that
//! will not meet the ego's path), 4 and 5 the car's x offset (ahead) and y
//! offset (left) from its cell's centre in cells, in [-0.5, 0.5).
//!
//! The occupancy channel and the offsets are our additions to the paper's
//! channels. Occupancy, so that a stopped car is never all zeros. The
//! offsets (the paper gives them to its occlusion networks only) because a
//! TTG cell is 8 m long, 0.4 s at the speed limit: without them gaps within
//! that much of each other look the same (what they changed in training:
//! reports/paper/NOTES.md).
//!
//! **Occluded channel**, when the scenario has occluders
//! ([`ObsSpec::occlusion`]): 1 when the straight line from the sensor to
//! the cell's centre crosses an occluder. It comes right after the car
//! channels, before the offsets, as the paper lists the occlusion channels
//! (occluded, x offset, y offset).
//!
//! **Ego features**: speed / speed limit; progress from the stop line to
//! the goal in [0, 1]; 1 once *go* was chosen; steps taken / step limit.
//!
//! # Metrics
//!
//! Outcome (success, collision, timeout), time (steps x 0.2 s), the wait
//! before *go*, and two braking times of traffic, each summed over cars
//! within 100 m of the intersection: the seconds during which a car's
//! intended deceleration (car following and reaction to the ego, before
//! random dawdling) exceeds 1 m/s² ([`TrafficParams::brake_threshold`]),
//! and the seconds its brake light is on by SUMO's rule
//! ([`Traffic::brake_light_time_s`]), the measure both simulators share.
//!
//! # Calibration
//!
//! The reference is SUMO itself, not the paper's numbers: `crossroads
//! sumo-check` runs SUMO (1.28, its defaults: Krauss, sigma 0.5,
//! speedFactor N(1, 0.1)) on networks generated from these very scenarios
//! ([`ScenarioExport`]), drives its ego by the same policies and compares
//! every metric with intervals (`reports/sumo/`). Choices the paper leaves
//! open (see the scenario files and [`TrafficParams`], [`EgoParams`] for
//! every value):
//!
//! - Priority drivers never give way in advance. The drivers of a lane
//!   notice the ego once it has chosen *go*, cannot stop short of their
//!   lane any more, or drives at it faster than a creep, and react from the
//!   step in which they notice it ([`TrafficParams::reaction_delay_s`],
//!   0.2 s: SUMO's drivers act on what they see every step and carry their
//!   reaction time in the Krauss safe speed). Then only a car in the way of
//!   the ego's passage reacts: one that would neither be clear of the
//!   ego's path before the ego enters nor arrive after it is out (0.5 s
//!   margin either side), and that could still stop short of it (one that
//!   cannot passes first where the ego crosses its lane; behind an ego
//!   merging ahead of it, it brakes all the same). It slows just enough to
//!   pass behind the ego, stopping short of the lane if it must ([`give_way_decel`]): with at
//!   most 4.5 m/s² (SUMO's decel) while the ego is behind its stop line,
//!   and as hard as it must, up to 9 m/s², once the ego is on the junction
//!   (past the stop line or gone), as SUMO's drivers brake for a junction
//!   leader. An ego merging ahead of a car is followed like a leader at its
//!   entry speed, bounded the same way. Occlusion runs switch all of this
//!   off, as the paper does (`traffic_reacts = false`), except that an ego
//!   that has merged a car length into a lane is followed there like any
//!   leader rather than driven through.
//! - Car following is the improved IDM ([`iidm_accel`]) with a 0.8 s
//!   headway: plain IDM let a follower faster than its leader hang back
//!   well beyond its desired gap, which spread platoons into a stream more
//!   regular than the random one emitted, with fewer long gaps for TTC. On
//!   a free road cars accelerate as Krauss's do, at the full 2.6 m/s² up to
//!   their desired speed ([`krauss_free_accel`]): IDM's free-road term
//!   fades near the desired speed, and against Krauss dawdling it leaves
//!   cars cruising at `(1 - sigma/2)^(1/4) = 0.93` of it, in streams slower
//!   than SUMO's with fewer openings for TTC (reports/sumo/NOTES.md).
//! - The ego accelerates at 2.6 m/s² (SUMO's default car) and takes each
//!   turn at the speed netconvert gives a junction lane of that shape
//!   ([`EgoParams::lateral_accel`]: `sqrt(5.5 (L / (angle - 15 deg) +
//!   w / 4))`, 4.8, 6.8 and 8.3 m/s on Right, Left and Left2), limited
//!   while its front is on the arc, as SUMO limits a vehicle by its
//!   front's lane. It waits 1 m before the road edge (2 m in the occlusion
//!   family, so that the walls hide the near lane). Empty-road drives from
//!   the stop line are checked against SUMO's (`crossroads sumo-check
//!   --strict` fails beyond 0.3 s).
//! - The goal lies as far past the intersection as the paper's times
//!   allow (its fastest mean times, 4.63, 5.24, 5.40, 4.40 and 7.94 s,
//!   include some waiting).
//! - Cars enter their lane at their desired speed, or at the last car's
//!   speed if that is slower, once the desired gap at that speed is free
//!   (emissions wait in a backlog meanwhile), as SUMO's `departSpeed="max"`
//!   does. The emission probability is per second and lane, drawn each
//!   step (SUMO's flow `probability`).
//! - Left2 and Challenge read the paper's emission figure per direction
//!   (one SUMO flow per route) and split it over the direction's lanes:
//!   0.1 and 0.233 per lane. SUMO reproduces the paper's regime only with
//!   this reading (read per lane, TTC on Challenge never finds a gap).
//! - The occluders' offsets count from 100 m out (the edge of the road the
//!   TTG grid observes), not from the start of the lanes at 150 m, from
//!   where a 30 m wall hid nothing within 99 m of the stopped ego and TTC
//!   without creeping never collided (see `configs/scenarios/occluded.toml`).
//!
//! Result figures (tuned TTC thresholds against SUMO's, empty-road
//! drives, every cell of both simulators) are in `reports/sumo/README.md`,
//! the paper's TTC columns beside ours in `reports/paper/README.md`;
//! `reports/sumo/NOTES.md` has the readings of what the paper leaves open
//! and the mechanism behind each remaining difference.
//!
//! # Determinism
//!
//! [`Env::reset`] seeds xoshiro256++ (rand_xoshiro, seeded by splitmix64)
//! from the seed; every random draw of an episode comes from it, in a fixed
//! order. Trial `i` of an evaluation uses [`episode_seed`]`(seed, i)` and
//! [`policy_seed`]`(seed, i)`, so results do not depend on threads.

mod action;
mod bench;
mod car_following;
mod drivers;
mod env;
mod error;
mod eval;
mod export;
mod geometry;
mod observation;
mod occlusion;
mod params;
mod path;
mod policy;
mod render;
mod risk;
mod scenario;
mod seed;
mod shield;
mod traffic;
mod tune;

pub use action::{ActionSet, Control, DURATIONS, Intent};
pub use bench::{BenchFigures, bench_builtin, bench_scenario};
pub use car_following::{
    dawdle, idm_accel, iidm_accel, iidm_accel_with, iidm_free_accel, krauss_free_accel,
    krauss_safe_speed,
};
pub use drivers::{Bounds, Driver, DriverPopulation, PRESETS as DRIVER_PRESETS};
pub use env::{Ego, Env, EnvConfig, EpisodeMetrics, Outcome, StepResult, TTC_CAP_S};
pub use error::SimError;
pub use eval::{
    EvalConfig, EvalReport, Interval, TrialResult, evaluate, run_trials, summarize, wilson,
};
pub use export::{
    EgoExport, ExportError, LaneExport, LayoutExport, PATH_STEP, RectExport, ScenarioExport,
    ZoneExport,
};
pub use geometry::{OrientedRect, Pose, Vec2, wrap_angle};
pub use observation::*;
pub use occlusion::{ObstacleSpec, OcclusionLayout, OcclusionSpec, Side, line_of_sight};
pub use params::{EgoParams, Rewards, TrafficParams};
pub use path::{Path, PathSpec, PieceSpec};
pub use policy::{
    NeverPolicy, OraclePolicy, Policy, PolicyRng, PolicySpec, RandomPolicy, ShieldCounters,
    ShieldStats, ShieldedPolicy, TtcPolicy, parse_policy, shield_fallback,
};
pub use render::{Color, Layer, RenderView, Scene, SceneOptions, Shape, palette};
pub use risk::{
    GoDecision, IN_VIEW_S, MissedReport, PROBE_EVERY_STEPS, RISKIEST_SHOWN, RiskBin, RiskOptions,
    RiskReport, SafeChance, ValueMargins, ValueStats, go_risk,
};
pub use scenario::{ConflictZone, EgoSpec, Lane, LaneSpec, Scenario, ScenarioSpec};
pub use seed::{episode_seed, policy_seed, splitmix64};
pub use shield::{SensedCar, ShieldParams, Threat, ThreatKind, check_go, sense};
pub use traffic::{Car, EgoConflict, EgoFoe, Traffic, give_way_decel};
pub use tune::{SweepPoint, TuneReport, default_thresholds, tune_ttc};
