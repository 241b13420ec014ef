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
/// Ray Tracing Gems ch. 6 (listing 6-1). `p` is the hit point, best computed
/// from barycentrics (b0 v0 + b1 v1 + b2 v2: a few ulps of error, which the
/// chapter's constants cover) rather than o + t d (error grows with t and |o|).
/// `n` is the unit geometric normal, `w` the direction the new ray leaves in;
/// the offset goes to w's side.
///
/// Each coordinate moves by int_scale * n_i ulps, which scales with the
/// coordinate's magnitude as the intersection error does; near the origin,
/// where ulps become tiny (and denormal), by float_scale * n_i instead.
#[inline]
pub fn offset_ray_origin(p: Vec3A, n: Vec3A, w: Vec3A) -> Vec3A {
    // The chapter's constants: below |x| = 1/32 use a fixed offset of 2^-16;
    // above, 256 ulps along a unit normal.
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    debug_assert!((n.length_squared() - 1.0).abs() < 1e-3, "offset_ray_origin wants a unit normal, got {n}");
    let n = if n.dot(w) < 0.0 { -n } else { n };
    let offset = |p: f32, n: f32| -> f32 {
        if p.abs() < ORIGIN {
            p + FLOAT_SCALE * n
        } else {
            // Float bits are sign-magnitude and monotonic in magnitude, so
            // adding k to the bits of |p| moves p by k ulps away from 0; for
            // negative p, subtracting moves it toward +. `as` truncates, as
            // the chapter's int conversion does.
            let of_i = (INT_SCALE * n) as i32;
            let bits = p.to_bits() as i32;
            f32::from_bits(bits.wrapping_add(if p < 0.0 { -of_i } else { of_i }) as u32)
        }
    };
    Vec3A::new(offset(p.x, n.x), offset(p.y, n.y), offset(p.z, n.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [Vec3A::Z, -Vec3A::Z, Vec3A::new(0.3, -0.5, 0.81).normalize(), Vec3A::new(1.0, 0.0, -1e-8).normalize()]
        {
            let f = Frame::from_normal(n);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(f.n).abs() < 1e-5 && f.t.dot(f.n).abs() < 1e-5);
            assert!((f.s.length() - 1.0).abs() < 1e-5 && (f.t.length() - 1.0).abs() < 1e-5);
            let v = Vec3A::new(0.2, 0.3, 0.9);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn offset_goes_to_w_side_and_scales_with_magnitude() {
        let n = Vec3A::new(0.36, 0.48, 0.8);
        for scale in [0.0f32, 1e-3, 0.5, 1.0, 1e3, 1e5, -1e5] {
            let p = Vec3A::new(1.0, -2.0, 0.5) * scale;
            for w in [n, -n, Vec3A::new(0.0, 0.0, 1.0), Vec3A::new(0.0, 0.0, -1.0)] {
                let q = offset_ray_origin(p, n, w);
                let side = (q - p).dot(n) * n.dot(w).signum();
                assert!(side > 0.0, "p = {p}, w = {w}, q = {q}");
                // Never more than int_scale ulps (or float_scale) per axis.
                let bound = (p.abs() * (256.0 * f32::EPSILON)).max(Vec3A::splat(1.0 / 65536.0));
                assert!(((q - p).abs() - bound).max_element() <= 0.0, "{p} -> {q}");
            }
        }
    }
}
