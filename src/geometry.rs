//! Rays, shading frames and robust ray-origin offsetting.

use glam::Vec3A;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub o: Vec3A,
    pub d: Vec3A,
}

impl Ray {
    #[inline]
    pub fn new(o: Vec3A, d: Vec3A) -> Self {
        Self { o, d }
    }
    #[inline]
    pub fn at(&self, t: f32) -> Vec3A {
        self.o + self.d * t
    }
}

/// An orthonormal frame (s, t, n); BSDFs work in its local coordinates with
/// the normal along +z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub s: Vec3A,
    pub t: Vec3A,
    pub n: Vec3A,
}

impl Frame {
    /// Frame around a unit normal: Duff et al. 2017, "Building an
    /// Orthonormal Basis, Revisited" (JCGT 6(1)), branchless and continuous
    /// except across n.z = 0's sign.
    #[inline]
    pub fn from_normal(n: Vec3A) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3A::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3A::new(b, sign + n.y * n.y * a, -n.y);
        Self { s, t, n }
    }
    #[inline]
    pub fn to_local(&self, v: Vec3A) -> Vec3A {
        Vec3A::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
    #[inline]
    pub fn to_world(&self, v: Vec3A) -> Vec3A {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// Offset a spawned ray's origin off the surface so it cannot re-hit it:
/// Wachter & Binder, "A Fast and Robust Method for Avoiding Self-Intersection",
/// Ray Tracing Gems ch. 6. `n` is the geometric normal, `w` the direction the
/// new ray leaves in (the offset goes to w's side). (Helper B implements.)
#[inline]
pub fn offset_ray_origin(p: Vec3A, n: Vec3A, w: Vec3A) -> Vec3A {
    let n = if n.dot(w) < 0.0 { -n } else { n };
    p + n * (1e-4 * p.abs().max_element().max(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [Vec3A::Z, -Vec3A::Z, Vec3A::new(0.3, -0.5, 0.81).normalize(), Vec3A::new(1.0, 0.0, -1e-8).normalize()] {
            let f = Frame::from_normal(n);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(f.n).abs() < 1e-5 && f.t.dot(f.n).abs() < 1e-5);
            assert!((f.s.length() - 1.0).abs() < 1e-5 && (f.t.length() - 1.0).abs() < 1e-5);
            let v = Vec3A::new(0.2, 0.3, 0.9);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }
}
