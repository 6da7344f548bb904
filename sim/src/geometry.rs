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
        self.half_length * self.axis.dot(dir).abs() + self.half_width * self.axis.perp().dot(dir).abs()
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
