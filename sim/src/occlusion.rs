//! Occluding obstacles: fixed ones and the paper's random family, and
//! visibility by ray casting from the ego's sensor point.

use rand::RngExt;
use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::geometry::{OrientedRect, Vec2};

/// A fixed obstacle, as written in a scenario file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    /// Centre `[x, y]`, m.
    pub center: [f64; 2],
    /// Extent along `heading_deg`, m.
    pub length: f64,
    /// Extent across, m.
    pub width: f64,
    /// Degrees counter-clockwise from east.
    #[serde(default)]
    pub heading_deg: f64,
}

impl ObstacleSpec {
    pub(crate) fn rect(&self) -> OrientedRect {
        OrientedRect::new(
            Vec2::new(self.center[0], self.center[1]),
            self.heading_deg.to_radians(),
            self.length,
            self.width,
        )
    }
}

/// Which side of the ego's road an occluder stands on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// West of the minor road (the near lane's traffic comes from there).
    Left,
    /// East of the minor road.
    Right,
    /// One occluder on each side.
    Both,
}

impl Side {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Left => "left",
            Self::Right => "right",
            Self::Both => "both",
        }
    }
}

/// The paper's random occluder family, drawn anew each episode.
///
/// Frame: the major road runs along x with its near edge (the ego's side)
/// at `near_edge_y`; the ego approaches from negative y. Each occluder is a
/// wall along the near lane, `gap` off the road edge, `width` thick and
/// `length` long. Its far end lies `offset` metres from the outer boundary
/// of its side (`side_extent` from the centre, the paper's "left-most
/// boundary of that side"), and it never reaches closer than `corner_x` to
/// the centre line of the minor road, so it stays off the ego's road.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcclusionSpec {
    /// Sides to draw from, uniformly.
    pub sides: Vec<Side>,
    /// Lengths to draw from, m.
    pub lengths: Vec<f64>,
    /// Widths to draw from, m.
    pub widths: Vec<f64>,
    /// Offsets from the side's outer boundary to draw from, m.
    pub offsets: Vec<f64>,
    /// Distance of each side's outer boundary from the centre, m.
    pub side_extent: f64,
    /// y of the road edge on the ego's side, m.
    pub near_edge_y: f64,
    /// Clearance between the road edge and the occluder, m.
    pub gap: f64,
    /// Occluders end at least this far (in |x|) from the minor road's centre.
    pub corner_x: f64,
}

/// One draw of the occluder family.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OcclusionLayout {
    /// Side.
    pub side: Side,
    /// Length, m.
    pub length: f64,
    /// Width, m.
    pub width: f64,
    /// Offset, m.
    pub offset: f64,
}

impl OcclusionSpec {
    pub(crate) fn validate(&self, what: &str) -> Result<(), SimError> {
        if self.sides.is_empty()
            || self.lengths.is_empty()
            || self.widths.is_empty()
            || self.offsets.is_empty()
        {
            return Err(SimError::invalid(what, "occlusion lists must not be empty"));
        }
        let all = self.lengths.iter().chain(&self.widths).chain(&self.offsets);
        if all.clone().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(SimError::invalid(
                what,
                "occluder sizes and offsets must be positive",
            ));
        }
        Ok(())
    }

    /// Draws a layout.
    pub(crate) fn sample(&self, rng: &mut impl rand::Rng) -> OcclusionLayout {
        OcclusionLayout {
            side: self.sides[rng.random_range(0..self.sides.len())],
            length: self.lengths[rng.random_range(0..self.lengths.len())],
            width: self.widths[rng.random_range(0..self.widths.len())],
            offset: self.offsets[rng.random_range(0..self.offsets.len())],
        }
    }

    /// The occluders of a layout, appended to `out`.
    pub(crate) fn place(&self, layout: &OcclusionLayout, out: &mut Vec<OrientedRect>) {
        let y_inner = self.near_edge_y - self.gap;
        let cy = y_inner - 0.5 * layout.width;
        // Distance from the centre of the far and near ends of the wall.
        let far = self.side_extent - layout.offset;
        let near = (far - layout.length).max(self.corner_x);
        if far <= near {
            return;
        }
        let len = far - near;
        let mid = 0.5 * (far + near);
        let sides: &[f64] = match layout.side {
            Side::Left => &[-1.0],
            Side::Right => &[1.0],
            Side::Both => &[-1.0, 1.0],
        };
        for &sx in sides {
            out.push(OrientedRect::new(
                Vec2::new(sx * mid, cy),
                0.0,
                len,
                layout.width,
            ));
        }
    }
}

/// Whether the straight line from `eye` to `target` is free of occluders.
pub fn line_of_sight(eye: Vec2, target: Vec2, occluders: &[OrientedRect]) -> bool {
    occluders.iter().all(|o| !o.intersects_segment(eye, target))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> OcclusionSpec {
        OcclusionSpec {
            sides: vec![Side::Left],
            lengths: vec![30.0],
            widths: vec![1.0],
            offsets: vec![51.0],
            side_extent: 100.0,
            near_edge_y: -7.0,
            gap: 0.5,
            corner_x: 4.5,
        }
    }

    #[test]
    fn places_walls_from_the_outer_boundary() {
        let mut out = Vec::new();
        let layout = OcclusionLayout {
            side: Side::Both,
            length: 30.0,
            width: 1.0,
            offset: 51.0,
        };
        spec().place(&layout, &mut out);
        assert_eq!(out.len(), 2);
        // Far end 49 m from the centre, near end 19 m.
        let c = out[0].corners();
        let xs: Vec<f64> = c.iter().map(|p| p.x).collect();
        let ys: Vec<f64> = c.iter().map(|p| p.y).collect();
        assert!((xs.iter().cloned().fold(f64::INFINITY, f64::min) - -49.0).abs() < 1e-9);
        assert!((xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - -19.0).abs() < 1e-9);
        assert!((ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - -7.5).abs() < 1e-9);
        assert!((ys.iter().cloned().fold(f64::INFINITY, f64::min) - -8.5).abs() < 1e-9);
        assert!((out[1].center.x - 34.0).abs() < 1e-9);
        // A long wall is clipped at the corner.
        let mut out = Vec::new();
        let long = OcclusionLayout {
            side: Side::Right,
            length: 90.0,
            width: 2.0,
            offset: 51.0,
        };
        spec().place(&long, &mut out);
        assert!((out[0].center.x - 0.5 * (49.0 + 4.5)).abs() < 1e-9);
    }

    /// Hand-computed scene: a 1 m thick wall along y in [-8.5, -7.5] for x
    /// in [-49, -19]; the eye at (1.75, -9).
    #[test]
    fn ray_cast_on_hand_computed_scene() {
        let mut walls = Vec::new();
        spec().place(
            &OcclusionLayout {
                side: Side::Left,
                length: 30.0,
                width: 1.0,
                offset: 51.0,
            },
            &mut walls,
        );
        let eye = Vec2::new(1.75, -9.0);
        // Towards (-30, -5.25): crosses y = -7.5 at x = 1.75 - 0.4 * 31.75 = -10.95,
        // y = -8.5 at x = 1.75 - (0.5/3.75) * 31.75 = -2.48: misses the wall
        // (x range [-49, -19]) entirely.
        assert!(line_of_sight(eye, Vec2::new(-30.0, -5.25), &walls));
        // Towards (-80, -5.25): crosses y = -8.5 at x = -9.1 and y = -7.5 at
        // x = -30.95, inside [-49, -19]: blocked.
        assert!(!line_of_sight(eye, Vec2::new(-80.0, -5.25), &walls));
        // From a point past the wall's inner face nothing on the road is hidden.
        let eye2 = Vec2::new(1.75, -7.0);
        assert!(line_of_sight(eye2, Vec2::new(-80.0, -5.25), &walls));
        // The right side is free.
        assert!(line_of_sight(eye, Vec2::new(80.0, -5.25), &walls));
        // A target behind the wall, seen straight on, is hidden.
        assert!(!line_of_sight(
            Vec2::new(-30.0, -5.0),
            Vec2::new(-30.0, -20.0),
            &walls
        ));
    }
}
