//! The intersection simulator that replaces SUMO: pure Rust, no learning,
//! no networking, no allocation per step.
//!
//! A [`Scenario`] (the built-in TOML files of `configs/scenarios/`, embedded
//! here, or a user's) describes lanes as [`Path`]s, the ego's route, traffic
//! and ego parameters, rewards and occluders; compiling it finds the
//! [`ConflictZone`] of every lane the route meets. An [`Env`] runs episodes:
//! [`Traffic`] (improved IDM with Krauss's free road, safety and dawdling;
//! each car's [`Driver`] drawn from a [`DriverPopulation`], braking for an
//! ego in its way by the rule of `sim/src/traffic.rs`), the ego driven by an
//! [`ActionSet`] (TTG, Sequential, Creep-and-Go; a k-step action is one
//! [`StepResult`]), [`OrientedRect`] collisions, and grid observations
//! written into caller buffers ([`ObsSpec`]; [`ObsKind`] gives the layout).
//! A [`Policy`] acts for a batch of environments ([`TtcPolicy`], with or
//! without creeping, [`RandomPolicy`], [`NeverPolicy`]; [`ShieldedPolicy`]
//! puts one behind the safety shield); a [`VecEnv`] steps many at once.
//! [`evaluate`] runs seeded trials in parallel, the same on any number of
//! threads, into an [`EvalReport`]; [`tune_ttc`], [`bench_scenario`],
//! [`Scene`], [`Scenario::export`] serve the CLI. More: docs/simulator.md.

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
mod vec_env;

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
    GoPolicy, NeverPolicy, OraclePolicy, Policy, PolicyRng, PolicySpec, RandomPolicy,
    ShieldCounters, ShieldStats, ShieldedPolicy, TtcPolicy, parse_policy, shield_fallback,
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
pub use vec_env::{EnvStep, EpisodeEnd, VecEnv};
