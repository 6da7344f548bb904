//! A compiled scenario as plain data for another simulator: the lanes, the
//! ego's route sampled as a polyline, the conflict zones the TTC rule uses
//! and every occluder layout of the random family. `crossroads sumo-check`
//! writes it as JSON, and `scripts/sumo_check/` builds SUMO's network and
//! drives SUMO's ego from it, so the two simulators share one description.

use serde::Serialize;

use crate::drivers::DriverPopulation;
use crate::geometry::{OrientedRect, Pose};
use crate::occlusion::OcclusionLayout;
use crate::params::{EgoParams, Rewards, TrafficParams};
use crate::scenario::{ConflictZone, Scenario};

/// Spacing of the exported ego path, m.
pub const PATH_STEP: f64 = 0.25;

/// Everything another simulator needs to run a scenario as ours does.
#[derive(Debug, Clone, Serialize)]
pub struct ScenarioExport {
    /// Scenario name.
    pub name: String,
    /// Simulation step, s.
    pub step_s: f64,
    /// Steps before a timeout.
    pub step_limit: u32,
    /// Speed limit of every lane without its own, m/s.
    pub speed_limit: f64,
    /// Whether traffic reacts to the ego.
    pub traffic_reacts: bool,
    /// Traffic parameters (the population's speed factor bounds applied).
    pub traffic: TrafficParams,
    /// Who drives: the bounds each car's driver is drawn from (all unset
    /// for the `sumo` preset, every car the `traffic` driver).
    pub drivers: DriverPopulation,
    /// Rewards (for completeness; outcomes do not depend on them).
    pub rewards: Rewards,
    /// The ego.
    pub ego: EgoExport,
    /// Traffic lanes, in scenario order.
    pub lanes: Vec<LaneExport>,
    /// The random occluder family: every layout with its rectangles (fixed
    /// obstacles included), each equally likely, as
    /// [`crate::OcclusionSpec`] draws side, length, width and offset
    /// uniformly and independently. One empty layout for a scenario
    /// without the family (its fixed obstacles only, if any).
    pub occluder_layouts: Vec<LayoutExport>,
}

/// The ego's route and parameters.
#[derive(Debug, Clone, Serialize)]
pub struct EgoExport {
    /// Dynamics.
    pub params: EgoParams,
    /// Arc length of the front bumper at the stop line, m.
    pub stop_line_s: f64,
    /// Arc length of the front bumper at the goal, m.
    pub goal_s: f64,
    /// Farthest the front bumper creeps, m.
    pub creep_limit_s: f64,
    /// Spacing of `path`, m.
    pub path_step: f64,
    /// The path of the ego's centre every `path_step` metres from its
    /// start: `[x, y, heading]` (heading in radians counter-clockwise from
    /// east). The front bumper at arc length `s` sits half a car length
    /// ahead of the centre point at `s - length / 2`.
    pub path: Vec<[f64; 3]>,
    /// Radius of curvature at each point of `path` (infinite on straights
    /// is written as 0).
    pub radius: Vec<f64>,
}

/// One traffic lane: straight, with its conflict zone.
#[derive(Debug, Clone, Serialize)]
pub struct LaneExport {
    /// Lane name.
    pub name: String,
    /// Where lane coordinate 0 is, `[x, y]`.
    pub start: [f64; 2],
    /// Unit direction of travel, `[x, y]`.
    pub dir: [f64; 2],
    /// Length, m.
    pub length: f64,
    /// Speed limit, m/s.
    pub speed_limit: f64,
    /// Emission probability per second.
    pub emission_per_s: f64,
    /// Where the ego's path meets it, if it does.
    pub zone: Option<ZoneExport>,
}

/// [`ConflictZone`] with its derived clear point.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ZoneExport {
    /// The zone as the TTC rule and traffic use it.
    #[serde(flatten)]
    pub zone: ConflictZone,
    /// [`ConflictZone::lane_clear`].
    pub lane_clear: f64,
}

/// One occluder layout.
#[derive(Debug, Clone, Serialize)]
pub struct LayoutExport {
    /// The draw, if from the random family.
    pub layout: Option<OcclusionLayout>,
    /// Its rectangles.
    pub rects: Vec<RectExport>,
}

/// An oriented rectangle.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct RectExport {
    /// Centre `[x, y]`.
    pub center: [f64; 2],
    /// Unit vector along the length.
    pub axis: [f64; 2],
    /// Half the length.
    pub half_length: f64,
    /// Half the width.
    pub half_width: f64,
}

impl From<&OrientedRect> for RectExport {
    fn from(r: &OrientedRect) -> Self {
        Self {
            center: [r.center.x, r.center.y],
            axis: [r.axis.x, r.axis.y],
            half_length: r.half_length,
            half_width: r.half_width,
        }
    }
}

/// Why a scenario cannot be exported.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("scenario {scenario}: {reason}")]
pub struct ExportError {
    /// Scenario name.
    pub scenario: String,
    /// What is not supported.
    pub reason: String,
}

impl Scenario {
    /// This scenario as data for another simulator. Lanes must be straight
    /// (the only kind another simulator is generated for).
    pub fn export(&self) -> Result<ScenarioExport, ExportError> {
        let spec = self.spec();
        let fail = |reason: String| ExportError {
            scenario: spec.name.clone(),
            reason,
        };
        let mut lanes = Vec::with_capacity(self.lanes().len());
        for lane in self.lanes() {
            let (start, dir, _) = lane
                .straight
                .ok_or_else(|| fail(format!("lane {} is not one straight piece", lane.name)))?;
            lanes.push(LaneExport {
                name: lane.name.clone(),
                start: [start.x, start.y],
                dir: [dir.x, dir.y],
                length: lane.path.length(),
                speed_limit: lane.speed_limit,
                emission_per_s: lane.emission_per_s,
                zone: lane.zone.map(|zone| ZoneExport {
                    zone,
                    lane_clear: zone.lane_clear(),
                }),
            });
        }
        let path = self.ego_path();
        let n = (path.length() / PATH_STEP).floor() as usize + 1;
        let at = |i: usize| path.pose_at(i as f64 * PATH_STEP);
        let points = (0..n)
            .map(|i| {
                let Pose { pos, heading } = at(i);
                [pos.x, pos.y, heading]
            })
            .collect();
        let radius = (0..n)
            .map(|i| {
                let r = path.radius_at(i as f64 * PATH_STEP);
                if r.is_finite() { r } else { 0.0 }
            })
            .collect();
        let mut occluder_layouts = Vec::new();
        let fixed = self.fixed_obstacles();
        match &spec.occlusion {
            Some(occ) => {
                for &side in &occ.sides {
                    for &length in &occ.lengths {
                        for &width in &occ.widths {
                            for &offset in &occ.offsets {
                                let layout = OcclusionLayout {
                                    side,
                                    length,
                                    width,
                                    offset,
                                };
                                let mut rects = fixed.to_vec();
                                occ.place(&layout, &mut rects);
                                occluder_layouts.push(LayoutExport {
                                    layout: Some(layout),
                                    rects: rects.iter().map(RectExport::from).collect(),
                                });
                            }
                        }
                    }
                }
            }
            None => occluder_layouts.push(LayoutExport {
                layout: None,
                rects: fixed.iter().map(RectExport::from).collect(),
            }),
        }
        Ok(ScenarioExport {
            name: spec.name.clone(),
            step_s: spec.step_s,
            step_limit: spec.step_limit,
            speed_limit: spec.speed_limit,
            traffic_reacts: spec.traffic_reacts,
            traffic: spec.drivers.traffic(&spec.traffic),
            drivers: spec.drivers.clone(),
            rewards: spec.rewards.clone(),
            ego: EgoExport {
                params: spec.ego.params.clone(),
                stop_line_s: spec.ego.stop_line_s,
                goal_s: spec.ego.goal_s,
                creep_limit_s: spec.ego.creep_limit_s,
                path_step: PATH_STEP,
                path: points,
                radius,
            },
            lanes,
            occluder_layouts,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_exports_with_its_zones_and_layouts() {
        for name in ["right", "left", "left2", "forward", "challenge", "occluded"] {
            let s = Scenario::builtin(name).unwrap();
            let e = s.export().unwrap();
            assert_eq!(e.lanes.len(), s.lanes().len(), "{name}");
            assert!(e.lanes.iter().any(|l| l.zone.is_some()), "{name}");
            // The path ends where the compiled path does, to within a step.
            let last = e.ego.path.last().unwrap();
            let end = s.ego_path().pose_at(s.ego_path().length()).pos;
            assert!((last[0] - end.x).hypot(last[1] - end.y) <= PATH_STEP + 1e-9);
        }
        let occ = Scenario::builtin("occluded").unwrap().export().unwrap();
        // 3 sides x 3 lengths x 3 widths x 3 offsets, the two-sided ones
        // with two walls.
        assert_eq!(occ.occluder_layouts.len(), 81);
        assert!(occ.occluder_layouts.iter().any(|l| l.rects.len() == 2));
        let left = Scenario::builtin("left").unwrap().export().unwrap();
        assert_eq!(left.occluder_layouts.len(), 1);
        assert!(left.occluder_layouts[0].rects.is_empty());
        // Left's arc: radius 6.25 m somewhere on the path.
        assert!(left.ego.radius.iter().any(|r| (r - 6.25).abs() < 1e-9));
    }
}
