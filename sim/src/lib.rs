//! The intersection simulator: pure Rust, no learning and no networking.
//! (Placeholder docs; completed below.)

mod action;
mod bench;
mod car_following;
mod env;
mod error;
mod eval;
mod geometry;
mod observation;
mod occlusion;
mod params;
mod path;
mod policy;
mod scenario;
mod seed;
mod traffic;
mod tune;

pub use action::{ActionSet, Control, DURATIONS, Intent};
pub use car_following::{dawdle, idm_accel, krauss_safe_speed};
pub use env::{Ego, Env, EnvConfig, EpisodeMetrics, Outcome, StepResult, TTC_CAP_S};
pub use error::SimError;
pub use geometry::{OrientedRect, Pose, Vec2, wrap_angle};
pub use observation::*;
pub use occlusion::{ObstacleSpec, OcclusionLayout, OcclusionSpec, Side, line_of_sight};
pub use params::{EgoParams, Rewards, TrafficParams};
pub use path::{Path, PathSpec, PieceSpec};
pub use scenario::{ConflictZone, EgoSpec, Lane, LaneSpec, Scenario, ScenarioSpec};
pub use traffic::{Car, EgoFoe, Traffic};
pub use bench::{BenchFigures, bench_builtin, bench_scenario};
pub use eval::{EvalConfig, EvalReport, Interval, TrialResult, evaluate, run_trials, summarize, wilson};
pub use policy::{Policy, PolicyRng, PolicySpec, RandomPolicy, TtcPolicy, parse_policy};
pub use seed::{episode_seed, policy_seed, splitmix64};
pub use tune::{SweepPoint, TuneReport, default_thresholds, tune_ttc};
