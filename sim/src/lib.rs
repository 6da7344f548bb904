//! The intersection simulator: pure Rust, no learning and no networking.
//! (Placeholder docs; completed below.)

mod action;
mod car_following;
mod env;
mod error;
mod geometry;
mod observation;
mod occlusion;
mod params;
mod path;
mod scenario;
mod traffic;

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
