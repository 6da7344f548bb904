//! Paths: chains of straight pieces and circular arcs, parameterized by arc
//! length. Traffic lanes and the ego's route are paths.

use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::geometry::{Pose, Vec2};

/// One piece of a path, as written in a scenario file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum PieceSpec {
    /// Straight ahead for this many metres.
    Straight(f64),
    /// A circular arc; positive `angle_deg` turns left (counter-clockwise).
    Turn {
        /// Radius, metres.
        radius: f64,
        /// Signed angle turned, degrees; positive is a left turn.
        angle_deg: f64,
    },
}

/// A path as written in a scenario file: a start pose and pieces driven in
/// order, so consecutive pieces always join without kinks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PathSpec {
    /// Start point `[x, y]`, metres.
    pub start: [f64; 2],
    /// Start heading, degrees counter-clockwise from east.
    pub heading_deg: f64,
    /// Pieces in driving order.
    pub pieces: Vec<PieceSpec>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Segment {
    Line {
        start: Vec2,
        dir: Vec2,
    },
    Arc {
        center: Vec2,
        radius: f64,
        start_angle: f64,
        sign: f64,
    },
}

/// A compiled path: pose and curvature at any arc length.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    segments: Vec<Segment>,
    /// Arc length at the start of each segment, plus the total at the end.
    starts: Vec<f64>,
}

impl Path {
    /// Compiles a path description; `what` names it in errors.
    pub fn from_spec(spec: &PathSpec, what: &str) -> Result<Self, SimError> {
        if spec.pieces.is_empty() {
            return Err(SimError::invalid(what, "a path needs at least one piece"));
        }
        let mut pos = Vec2::new(spec.start[0], spec.start[1]);
        let mut heading = spec.heading_deg.to_radians();
        let mut segments = Vec::with_capacity(spec.pieces.len());
        let mut starts = vec![0.0];
        let mut s = 0.0;
        for piece in &spec.pieces {
            match *piece {
                PieceSpec::Straight(len) => {
                    if !(len.is_finite() && len > 0.0) {
                        return Err(SimError::invalid(
                            what,
                            "straight pieces need a positive length",
                        ));
                    }
                    let dir = Vec2::from_angle(heading);
                    segments.push(Segment::Line { start: pos, dir });
                    pos = pos + dir * len;
                    s += len;
                }
                PieceSpec::Turn { radius, angle_deg } => {
                    if !(radius.is_finite()
                        && radius > 0.0
                        && angle_deg.is_finite()
                        && angle_deg != 0.0)
                    {
                        return Err(SimError::invalid(
                            what,
                            "turns need a positive radius and a non-zero angle",
                        ));
                    }
                    let sign = angle_deg.signum();
                    // The centre lies on the side the path turns to.
                    let center = pos + Vec2::from_angle(heading).perp() * (sign * radius);
                    let start_angle = heading - sign * std::f64::consts::FRAC_PI_2;
                    segments.push(Segment::Arc {
                        center,
                        radius,
                        start_angle,
                        sign,
                    });
                    let sweep = angle_deg.to_radians();
                    heading += sweep;
                    let end_angle = start_angle + sweep;
                    pos = center + Vec2::from_angle(end_angle) * radius;
                    s += radius * sweep.abs();
                }
            }
            starts.push(s);
        }
        Ok(Self { segments, starts })
    }

    /// Start point and unit direction, if the path is one straight piece;
    /// lets hot loops skip the general pose computation.
    pub fn as_straight(&self) -> Option<(Vec2, Vec2)> {
        match self.segments.as_slice() {
            [Segment::Line { start, dir }] => Some((*start, *dir)),
            _ => None,
        }
    }

    /// The arcs of the path: `(start, length, radius)` of each, in
    /// metres of arc length, in order; the angle turned is
    /// `length / radius`.
    pub fn arcs(&self) -> impl Iterator<Item = (f64, f64, f64)> + '_ {
        self.segments
            .iter()
            .enumerate()
            .filter_map(|(i, seg)| match seg {
                Segment::Arc { radius, .. } => {
                    Some((self.starts[i], self.starts[i + 1] - self.starts[i], *radius))
                }
                Segment::Line { .. } => None,
            })
    }

    /// Total arc length, metres.
    pub fn length(&self) -> f64 {
        self.starts[self.segments.len()]
    }

    fn segment_index(&self, s: f64) -> usize {
        let n = self.segments.len();
        let mut i = 0;
        while i + 1 < n && s >= self.starts[i + 1] {
            i += 1;
        }
        i
    }

    /// Pose at arc length `s`; before the start and past the end the path
    /// extends straight along its end tangents.
    pub fn pose_at(&self, s: f64) -> Pose {
        let i = if s <= 0.0 { 0 } else { self.segment_index(s) };
        let mut local = s - self.starts[i];
        let seg_len = self.starts[i + 1] - self.starts[i];
        let beyond = if i + 1 == self.segments.len() && local > seg_len {
            let b = local - seg_len;
            local = seg_len;
            b
        } else {
            0.0
        };
        let before = if s < 0.0 {
            local = 0.0;
            s
        } else {
            0.0
        };
        let pose = match self.segments[i] {
            Segment::Line { start, dir } => Pose {
                pos: start + dir * local,
                heading: dir.y.atan2(dir.x),
            },
            Segment::Arc {
                center,
                radius,
                start_angle,
                sign,
            } => {
                let a = start_angle + sign * local / radius;
                Pose {
                    pos: center + Vec2::from_angle(a) * radius,
                    heading: a + sign * std::f64::consts::FRAC_PI_2,
                }
            }
        };
        let extra = beyond + before;
        if extra == 0.0 {
            pose
        } else {
            Pose {
                pos: pose.pos + Vec2::from_angle(pose.heading) * extra,
                heading: pose.heading,
            }
        }
    }

    /// Radius of curvature at `s`; infinite on straight pieces.
    pub fn radius_at(&self, s: f64) -> f64 {
        if s < 0.0 || s > self.length() {
            return f64::INFINITY;
        }
        match self.segments[self.segment_index(s)] {
            Segment::Line { .. } => f64::INFINITY,
            Segment::Arc { radius, .. } => radius,
        }
    }

    /// Arc length of the point of the path nearest to `p` and the signed
    /// lateral offset of `p` (positive to the left of the direction of
    /// travel). Points beyond the ends project on the extended end tangents.
    pub fn project(&self, p: Vec2) -> (f64, f64) {
        let n = self.segments.len();
        let mut best = (0.0, 0.0, f64::INFINITY);
        for (i, seg) in self.segments.iter().enumerate() {
            let s0 = self.starts[i];
            let len = self.starts[i + 1] - s0;
            let lo = if i == 0 { f64::NEG_INFINITY } else { 0.0 };
            let hi = if i + 1 == n { f64::INFINITY } else { len };
            let (local, lat) = match *seg {
                Segment::Line { start, dir } => {
                    let d = p - start;
                    (d.dot(dir).clamp(lo, hi), dir.cross(d))
                }
                Segment::Arc {
                    center,
                    radius,
                    start_angle,
                    sign,
                } => {
                    let d = p - center;
                    let ang = d.y.atan2(d.x);
                    let delta = crate::geometry::wrap_angle(sign * (ang - start_angle));
                    let local = (delta * radius).clamp(0.0, len);
                    // Left of travel is towards the centre on a left turn.
                    (local, sign * (radius - d.norm()))
                }
            };
            let q = self.pose_at(s0 + local).pos;
            let dist = (p - q).norm();
            if dist < best.2 - 1e-9 {
                best = (s0 + local, lat, dist);
            }
        }
        (best.0, best.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(pieces: Vec<PieceSpec>) -> PathSpec {
        PathSpec {
            start: [0.0, 0.0],
            heading_deg: 90.0,
            pieces,
        }
    }

    #[test]
    fn left_turn_ends_where_expected() {
        let p = Path::from_spec(
            &spec(vec![
                PieceSpec::Straight(10.0),
                PieceSpec::Turn {
                    radius: 5.0,
                    angle_deg: 90.0,
                },
                PieceSpec::Straight(3.0),
            ]),
            "t",
        )
        .unwrap();
        let len = 10.0 + 5.0 * std::f64::consts::FRAC_PI_2 + 3.0;
        assert!((p.length() - len).abs() < 1e-9);
        let end = p.pose_at(len);
        assert!((end.pos.x - -8.0).abs() < 1e-9, "{end:?}");
        assert!((end.pos.y - 15.0).abs() < 1e-9, "{end:?}");
        assert!((end.heading - std::f64::consts::PI).abs() < 1e-9);
        let (s, lat) = p.project(Vec2::new(-6.0, 16.0));
        assert!((s - (len - 2.0)).abs() < 1e-9);
        // Heading west, north is to the right.
        assert!((lat - -1.0).abs() < 1e-9);
    }

    #[test]
    fn right_turn_and_projection_on_arc() {
        let p = Path::from_spec(
            &spec(vec![
                PieceSpec::Straight(2.0),
                PieceSpec::Turn {
                    radius: 4.0,
                    angle_deg: -90.0,
                },
            ]),
            "t",
        )
        .unwrap();
        let end = p.pose_at(p.length());
        assert!((end.pos.x - 4.0).abs() < 1e-9 && (end.pos.y - 6.0).abs() < 1e-9);
        assert!(end.heading.abs() < 1e-9);
        assert_eq!(p.radius_at(3.0), 4.0);
        assert!(p.radius_at(1.0).is_infinite());
        // A point just inside the arc (towards the centre, on the right).
        let mid = p.pose_at(2.0 + 4.0 * std::f64::consts::FRAC_PI_4);
        let inside = mid.pos + Vec2::from_angle(mid.heading).perp() * -0.5;
        let (s, lat) = p.project(inside);
        assert!((s - (2.0 + 4.0 * std::f64::consts::FRAC_PI_4)).abs() < 1e-9);
        assert!((lat - -0.5).abs() < 1e-9);
        // Extension past the end.
        let beyond = p.pose_at(p.length() + 2.0);
        assert!((beyond.pos.x - 6.0).abs() < 1e-9);
    }

    #[test]
    fn rejects_bad_pieces() {
        assert!(Path::from_spec(&spec(vec![]), "t").is_err());
        assert!(Path::from_spec(&spec(vec![PieceSpec::Straight(-1.0)]), "t").is_err());
        assert!(
            Path::from_spec(
                &spec(vec![PieceSpec::Turn {
                    radius: 0.0,
                    angle_deg: 9.0
                }]),
                "t"
            )
            .is_err()
        );
    }
}
