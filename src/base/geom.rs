//! Axis-aligned boxes and small vector helpers shared by the builder, encoders and tracers.

use glam::Vec3;

/// An axis-aligned box in fp32 world space. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Zeroable)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::INFINITY), max: Vec3::splat(f32::NEG_INFINITY) };

    pub fn from_points(pts: &[Vec3]) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in pts {
            b.grow(*p);
        }
        b
    }

    #[inline]
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    #[inline]
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Surface area (0 for an empty box).
    #[inline]
    pub fn area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let d = self.max - self.min;
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }

    #[inline]
    pub fn center(&self) -> Vec3 {
        // Halves first: min + max may overflow for boxes near fp32's range.
        self.min * 0.5 + self.max * 0.5
    }

    #[inline]
    pub fn diagonal(&self) -> f32 {
        if self.is_empty() {
            0.0
        } else {
            // In f64: the squared extent of a box beyond 1.8e19 overflows fp32.
            let d = (self.max - self.min).as_dvec3();
            d.length() as f32
        }
    }

    /// True when `o` lies inside `self` (closed box).
    pub fn contains(&self, o: &Aabb) -> bool {
        self.min.cmple(o.min).all() && self.max.cmpge(o.max).all()
    }
}

/// Index of the component with the largest absolute value.
#[inline]
pub fn max_abs_axis(v: Vec3) -> usize {
    let a = v.abs();
    if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    }
}
