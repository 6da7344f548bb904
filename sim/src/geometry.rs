//! Plane geometry: points, oriented rectangles and their overlap (separating
//! axis test), and segment-rectangle intersection for ray casting.

/// A point or vector in the plane, metres. `x` east, `y` north.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec2 {
    /// East.
    pub x: f64,
    /// North.
    pub y: f64,
}

impl Vec2 {
    /// The point `(x, y)`.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// Unit vector at `angle` radians counter-clockwise from east.
    pub fn from_angle(angle: f64) -> Self {
        let (s, c) = angle.sin_cos();
        Self::new(c, s)
    }

    /// Dot product.
    pub fn dot(self, o: Self) -> f64 {
        self.x * o.x + self.y * o.y
    }

    /// z component of the cross product.
    pub fn cross(self, o: Self) -> f64 {
        self.x * o.y - self.y * o.x
    }

    /// Euclidean length.
    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }

    /// Rotated a quarter turn counter-clockwise (the left normal).
    pub fn perp(self) -> Self {
        Self::new(-self.y, self.x)
    }
}

impl std::ops::Add for Vec2 {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y)
    }
}

impl std::ops::Sub for Vec2 {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y)
    }
}

impl std::ops::Mul<f64> for Vec2 {
    type Output = Self;
    fn mul(self, k: f64) -> Self {
        Self::new(self.x * k, self.y * k)
    }
}

/// Position and heading of a body.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Reference point.
    pub pos: Vec2,
    /// Radians counter-clockwise from east.
    pub heading: f64,
}

/// A rectangle of `length` x `width` centred on `center`, its length along
/// `heading`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrientedRect {
    /// Centre.
    pub center: Vec2,
    /// Unit vector along the length.
    pub axis: Vec2,
    /// Half the length.
    pub half_length: f64,
    /// Half the width.
    pub half_width: f64,
}

impl OrientedRect {
    /// Rectangle of `length` x `width` centred at `center`, length along
    /// `heading` (radians).
    pub fn new(center: Vec2, heading: f64, length: f64, width: f64) -> Self {
        Self::with_axis(center, Vec2::from_angle(heading), length, width)
    }

    /// As [`OrientedRect::new`] with the unit axis already computed, to spare
    /// a `sin_cos` per car per step.
    pub fn with_axis(center: Vec2, axis: Vec2, length: f64, width: f64) -> Self {
        Self {
            center,
            axis,
            half_length: 0.5 * length,
            half_width: 0.5 * width,
        }
    }

    /// The four corners, counter-clockwise from front left.
    pub fn corners(&self) -> [Vec2; 4] {
        let f = self.axis * self.half_length;
        let l = self.axis.perp() * self.half_width;
        let c = self.center;
        [c + f + l, c - f + l, c - f - l, c + f - l]
    }

    /// Radius of the circumscribed circle.
    pub fn radius(&self) -> f64 {
        self.half_length.hypot(self.half_width)
    }

    /// Half the extent of the rectangle projected on unit vector `dir`.
    fn half_extent_on(&self, dir: Vec2) -> f64 {
        self.half_length * self.axis.dot(dir).abs()
            + self.half_width * self.axis.perp().dot(dir).abs()
    }

    /// Whether the two rectangles overlap (touching counts as overlap).
    /// Separating axis test over the four edge normals.
    pub fn overlaps(&self, other: &Self) -> bool {
        let d = other.center - self.center;
        let r = self.radius() + other.radius();
        if d.dot(d) > r * r {
            return false;
        }
        for axis in [self.axis, self.axis.perp(), other.axis, other.axis.perp()] {
            let dist = d.dot(axis).abs();
            if dist > self.half_extent_on(axis) + other.half_extent_on(axis) {
                return false;
            }
        }
        true
    }

    /// Whether the segment from `a` to `b` crosses the rectangle's interior
    /// or boundary (slab test in the rectangle's frame).
    pub fn intersects_segment(&self, a: Vec2, b: Vec2) -> bool {
        let u = self.axis;
        let v = u.perp();
        let pa = a - self.center;
        let pb = b - self.center;
        let (a1, a2) = (pa.dot(u), pa.dot(v));
        let (b1, b2) = (pb.dot(u), pb.dot(v));
        let mut t0 = 0.0_f64;
        let mut t1 = 1.0_f64;
        for (p, q, h) in [(a1, b1, self.half_length), (a2, b2, self.half_width)] {
            let d = q - p;
            if d.abs() < 1e-12 {
                if p.abs() > h {
                    return false;
                }
            } else {
                let mut ta = (-h - p) / d;
                let mut tb = (h - p) / d;
                if ta > tb {
                    std::mem::swap(&mut ta, &mut tb);
                }
                t0 = t0.max(ta);
                t1 = t1.min(tb);
                if t0 > t1 {
                    return false;
                }
            }
        }
        true
    }
}

/// Angle wrapped into `(-pi, pi]`.
pub fn wrap_angle(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let mut r = a % TAU;
    if r <= -PI {
        r += TAU;
    } else if r > PI {
        r -= TAU;
    }
    r
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_4;

    use super::*;

    fn car(x: f64, y: f64, heading: f64) -> OrientedRect {
        OrientedRect::new(Vec2::new(x, y), heading, 5.0, 1.8)
    }

    #[test]
    fn axis_aligned_overlap() {
        let a = car(0.0, 0.0, 0.0);
        // Bumper to bumper 0.1 m apart: separate; 0.1 m overlap: collide.
        assert!(!a.overlaps(&car(5.1, 0.0, 0.0)));
        assert!(a.overlaps(&car(4.9, 0.0, 0.0)));
        // Side by side in adjacent 3.5 m lanes: separate.
        assert!(!a.overlaps(&car(0.0, 3.5, 0.0)));
        // Side by side 1.7 m apart (widths 1.8): overlap.
        assert!(a.overlaps(&car(1.0, 1.7, 0.0)));
        // Touching counts.
        assert!(a.overlaps(&car(5.0, 0.0, 0.0)));
        // Containment.
        assert!(a.overlaps(&OrientedRect::new(Vec2::new(0.5, 0.1), 0.3, 1.0, 0.5)));
    }

    #[test]
    fn crossing_cars() {
        // A car heading north whose front is 0.5 m short of an eastbound
        // car's side: the north car spans y in [-3.9, 1.1] around x = 0, the
        // east car y in [1.6 - 0.9, 1.6 + 0.9] = [0.7, 2.5]: 0.4 m overlap.
        let north = car(0.0, -1.4, std::f64::consts::FRAC_PI_2);
        assert!(north.overlaps(&car(0.0, 1.6, 0.0)));
        // Moved 0.5 m further: front at 0.6 < 0.7: separate.
        assert!(!car(0.0, -1.9, std::f64::consts::FRAC_PI_2).overlaps(&car(0.0, 1.6, 0.0)));
    }

    #[test]
    fn rotated_near_miss_needs_the_separating_axis() {
        // A unit square next to one rotated 45 degrees (half diagonal
        // 0.7071), centres on the x axis: they overlap iff the distance is
        // below 0.5 + 0.7071 = 1.2071.
        let square = OrientedRect::new(Vec2::new(0.0, 0.0), 0.0, 1.0, 1.0);
        let diamond = |x: f64| OrientedRect::new(Vec2::new(x, 0.0), FRAC_PI_4, 1.0, 1.0);
        assert!(square.overlaps(&diamond(1.20)));
        assert!(!square.overlaps(&diamond(1.22)));
        // Centred at (1.05, 1.05) the diamond's near edge is the line
        // x + y = 2.1 - 0.7071 = 1.393, beyond the square's corner
        // (x + y = 1): separate, although the circumcircles overlap.
        assert!(!square.overlaps(&OrientedRect::new(
            Vec2::new(1.05, 1.05),
            FRAC_PI_4,
            1.0,
            1.0
        )));
        // Two long thin bars crossing like an X overlap.
        let bar = |h: f64| OrientedRect::new(Vec2::new(0.0, 0.0), h, 10.0, 0.1);
        assert!(bar(FRAC_PI_4).overlaps(&bar(-FRAC_PI_4)));
        // Parallel bars 0.2 apart do not, though their circles overlap.
        assert!(!bar(FRAC_PI_4).overlaps(&OrientedRect::new(
            Vec2::new(-0.1414, 0.1414),
            FRAC_PI_4,
            10.0,
            0.1
        )));
    }

    #[test]
    fn segment_rect_intersection() {
        let r = OrientedRect::new(Vec2::new(0.0, 0.0), 0.0, 4.0, 2.0);
        // Through the middle.
        assert!(r.intersects_segment(Vec2::new(-5.0, 0.0), Vec2::new(5.0, 0.0)));
        // Passing above.
        assert!(!r.intersects_segment(Vec2::new(-5.0, 1.1), Vec2::new(5.0, 1.1)));
        // Stopping short.
        assert!(!r.intersects_segment(Vec2::new(-5.0, 0.0), Vec2::new(-2.1, 0.0)));
        // Diagonal clipping a corner: from (1, 3) to (3, 0.5) crosses
        // y = 1 at x = 2.6 (outside, x half 2), and x = 2 at y = 1.75: misses.
        assert!(!r.intersects_segment(Vec2::new(1.0, 3.0), Vec2::new(3.0, 0.5)));
        // From (1, 3) to (2.5, -1): crosses y = 1 at x = 1.75: inside.
        assert!(r.intersects_segment(Vec2::new(1.0, 3.0), Vec2::new(2.5, -1.0)));
        // Rotated rectangle.
        let d = OrientedRect::new(Vec2::new(0.0, 0.0), FRAC_PI_4, 2.0, 2.0);
        assert!(!d.intersects_segment(Vec2::new(1.3, 1.3), Vec2::new(3.0, 0.0)));
        assert!(d.intersects_segment(Vec2::new(1.3, -1.3), Vec2::new(-1.3, 1.3)));
    }

    #[test]
    fn wrapping() {
        assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) - -0.5).abs() < 1e-12);
        assert!((wrap_angle(7.0) - (7.0 - std::f64::consts::TAU)).abs() < 1e-12);
    }
}
