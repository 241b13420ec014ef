//! Rays, shading frames and robust ray-origin offsetting.

use glam::{DVec3, Vec3A};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub o: Vec3A,
    pub d: Vec3A,
    /// BVH slots of triangles whose planes the ray cannot meet, so the
    /// traversal need not test them nor their exactly coplanar neighbours in
    /// slot order (`Accel::coplanar_run`; `NO_TRIANGLE` for none): the one it
    /// leaves and the one it is aimed at. A ray leaving a planar triangle,
    /// from an origin offset to the side it travels to, moves away from the
    /// triangle's plane and can never meet the plane again; a shadow ray
    /// stops short of its target's plane, which a line crosses only once.
    pub skip: [u32; 2],
}

/// No triangle (a `SurfacePoint` off any surface, or a `Ray::skip` entry).
pub const NO_TRIANGLE: u32 = u32::MAX;

impl Ray {
    #[inline]
    pub fn new(o: Vec3A, d: Vec3A) -> Self {
        Self { o, d, skip: [NO_TRIANGLE; 2] }
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

/// gamma(n) = n eps / (1 - n eps) with eps = 2^-24 (half an ulp of 1): the
/// relative error bound of n successive f32 roundings (Higham 2002, pbrt-v4
/// section 6.8.1).
#[inline]
pub const fn gamma(n: u32) -> f32 {
    let ne = n as f32 * (f32::EPSILON * 0.5);
    ne / (1.0 - ne)
}

/// A conservative bound, per axis, on the rounding error of the point
/// b0 v0 + b1 v1 + b2 v2 interpolated from a triangle's vertices (pbrt-v4
/// section 6.8.5): gamma(7) (|b0 v0| + |b1 v1| + |b2 v2|). It follows the
/// magnitude of the vertices, not of the point, so it stays right for points
/// near the origin on large triangles and is tiny for tiny scenes.
#[inline]
pub fn barycentric_error(v: &[Vec3A; 3], b0: f32, b1: f32, b2: f32) -> Vec3A {
    ((v[0] * b0).abs() + (v[1] * b1).abs() + (v[2] * b2).abs()) * gamma(7)
}

/// The least barycentric of a point `triangle_point` leaves untouched:
/// `EDGE_MARGIN` (16) bounds E of the rounding error of a point on the
/// triangle `v` over its least altitude h_min = 2 area / longest edge, so
/// that such a point lies at least 16 E from every edge's line. The bound
/// is E = gamma(7) |(max_j |v_j.x|, max_j |v_j.y|, max_j |v_j.z|)|
/// (`rounding_extent`), which `barycentric_error` stays within for any
/// barycentrics >= 0 summing to 1. At most `MAX_EDGE_MARGIN`, 1/64: a
/// triangle whose least altitude is below 1,024 E (4.3 mm 10 from the
/// origin; a sliver, or a small triangle far out) keeps its points h_min /
/// 64 from its edges, less than 16 E, rather than pushing them towards its
/// middle. In f64, from the vertices as stored.
///
/// Why 16 E: where a neighbour's plane passes through an edge at an angle
/// phi to this triangle's plane (a cube's face beside another: 90
/// degrees), a point 16 E from the edge is at least 16 E sin(phi) from
/// that plane, and once rounded (a little under E, with the barycentrics'
/// own rounding) at least 15 E sin(phi) - E, on its own triangle's side.
/// A spawned ray moves it further by at most 1.5 E: the offset along the
/// own normal, at most |n| |p_error| <= E, and one ulp a coordinate with
/// the rounding of the sum, under 0.5 E. So for phi above 10 degrees its
/// origin stays on the own side of the neighbour's plane
/// (docs/performance-log.md, "Session 47").
pub fn edge_margin(v: &[Vec3A; 3]) -> f32 {
    let [a, b, c] = v.map(|x| x.as_dvec3());
    let twice_area = (b - a).cross(c - a).length();
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    // A degenerate triangle (never hit nor sampled) gives NaN or infinity,
    // which `min` turns into the cap.
    (EDGE_MARGIN * rounding_extent(v) * longest / twice_area).min(MAX_EDGE_MARGIN) as f32
}

/// E of `edge_margin`, in f64.
fn rounding_extent(v: &[Vec3A; 3]) -> f64 {
    gamma(7) as f64 * v[0].abs().max(v[1].abs()).max(v[2].abs()).as_dvec3().length()
}

const EDGE_MARGIN: f64 = 16.0;
const MAX_EDGE_MARGIN: f64 = 1.0 / 64.0;

/// The point with barycentrics `b` (summing to 1) on the triangle `v`, with
/// its rounding error bound (`barycentric_error`), made from `b` itself
/// unless one is below `margin` (`edge_margin(v)`), when it is moved to
/// the nearest point at least `EDGE_MARGIN` E from every edge's line
/// (margin h_min where the margin is capped; `kept_off_edges`). Within
/// rounding of an edge, a point could land exactly in a neighbour's plane,
/// or beyond it: a ray spawned there, offset along its own normal only,
/// left through the neighbour at t = 0, and light inside a closed cube got
/// out (a seed sweep, session 47; `a_closed_shell_keeps_its_light_in`). The move is 16 E or less
/// across an edge, more only within 16 E / sin(theta / 2) of a vertex of
/// angle theta, and the light points and hits it moves are a fraction of
/// about 16 E times the perimeter over the area.
#[inline(always)]
pub fn triangle_point(v: &[Vec3A; 3], b: [f32; 3], margin: f32) -> (Vec3A, Vec3A) {
    let b = kept_off_edges(v, b, margin);
    (v[0] * b[0] + v[1] * b[1] + v[2] * b[2], barycentric_error(v, b[0], b[1], b[2]))
}

/// `b`, or if one is below `margin` (`near_edges`), the barycentrics of
/// the nearest point at least `EDGE_MARGIN` E (or margin h_min) from
/// every edge's line (`inset`).
#[inline(always)]
pub fn kept_off_edges(v: &[Vec3A; 3], b: [f32; 3], margin: f32) -> [f32; 3] {
    if near_edges(b, margin) {
        inset(v, b, margin)
    } else {
        b
    }
}

/// Whether a barycentric of `b` is below `margin` (a NaN is not). One
/// vector compare: `f32::min` orders NaNs, which costs more.
#[inline(always)]
pub fn near_edges(b: [f32; 3], margin: f32) -> bool {
    Vec3A::from(b).cmplt(Vec3A::splat(margin)).any()
}

/// The barycentrics of the point nearest to `b`'s in the triangle `v`
/// inset by d = `EDGE_MARGIN` E: every edge moved inwards by d, which is
/// `v` scaled about its incentre I by 1 - k, k = d / r (r the inradius),
/// and holds exactly the points with b_i >= k beta_i, beta_i = the side
/// opposite vertex i over the perimeter (I's barycentrics). k is taken as
/// `margin` / beta_max, which is d / r where the margin is not capped (it
/// is d over the least altitude, 2 area / longest side, and r = 2 area /
/// perimeter), and where it is capped gives the points margin h_min from
/// the edges; either way k beta_i <= `margin`, so `near_edges` at the
/// margin misses no point outside the inset triangle. The nearest
/// point is found in f64 (Ericson 2005, "Real-Time Collision Detection",
/// 5.1.5, `ClosestPtPointTriangle`). So a point is moved across the edges
/// it is too near, by at most d each, not along them: until session 49 the
/// three barycentrics were raised to the margin and renormalised, which on
/// a sliver (margin 7.3e-3 on a right triangle 1 cm by 1 m, 10 from the
/// origin) slid points millimetres along it, and a light's points were no
/// longer uniform: 5 mm below such a strip light next-event estimation and
/// light tracing read 2.4 % low (an audit;
/// `light_points_keep_their_density_on_slivers`). A point already in the
/// inset triangle is left as it is (on a sliver of aspect 1e-6, the
/// nearest-point arithmetic itself would move it along by ~13 E; a
/// review). Inlined though rarely run and large: out of line (`#[cold]`,
/// `#[inline(never)]`), the call inside the walks' inlined loops made the
/// README's `path` render 1.08x as long (ABBA, 3 pairs: 1.220 against
/// 1.135 s) for +0.33 % instructions, as session 47 found of the rule
/// before it (docs/performance-log.md, "Session 47" and "Session 49").
#[inline(always)]
pub fn inset(v: &[Vec3A; 3], b: [f32; 3], margin: f32) -> [f32; 3] {
    let t = v.map(|x| x.as_dvec3());
    let sides = [(t[2] - t[1]).length(), (t[0] - t[2]).length(), (t[1] - t[0]).length()];
    let perimeter = sides[0] + sides[1] + sides[2];
    let beta = sides.map(|s| s / perimeter);
    let k = margin as f64 / beta[0].max(beta[1]).max(beta[2]);
    if !(k.is_finite() && perimeter > 0.0) || (0..3).all(|i| b[i] as f64 >= k * beta[i]) {
        // Inside already, or a degenerate triangle (never hit nor sampled).
        return b;
    }
    let centre = t[0] * beta[0] + t[1] * beta[1] + t[2] * beta[2];
    let inner = t.map(|x| centre + (x - centre) * (1.0 - k));
    let p = t[0] * b[0] as f64 + t[1] * b[1] as f64 + t[2] * b[2] as f64;
    let q = nearest_in_triangle(p, &inner);
    [0, 1, 2].map(|i| (k * beta[i] + (1.0 - k) * q[i]) as f32)
}

/// The barycentrics of the point of the triangle `t` nearest to `p`, a
/// point in its plane (Ericson 2005, 5.1.5: by the Voronoi regions of its
/// vertices and edges).
fn nearest_in_triangle(p: DVec3, [a, b, c]: &[DVec3; 3]) -> [f64; 3] {
    let (ab, ac, ap) = (*b - *a, *c - *a, p - *a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - *b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - *c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    [1.0 - v - w, v, w]
}

/// A point that rays leave from or arrive at: position, a bound on its
/// rounding error per axis, and the geometric normal (zero off surfaces: the
/// pinhole, a point light, the environment's far point).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub p: Vec3A,
    pub p_error: Vec3A,
    pub n: Vec3A,
    /// The BVH slot of the triangle the point is on, or `NO_TRIANGLE`.
    pub slot: u32,
}

impl SurfacePoint {
    /// An exactly known point off any surface.
    #[inline]
    pub fn at(p: Vec3A) -> Self {
        Self { p, p_error: Vec3A::ZERO, n: Vec3A::ZERO, slot: NO_TRIANGLE }
    }

    /// A ray leaving the point towards `w`, from `offset_ray_origin`, that
    /// need not test the point's own triangle. Off surfaces (n = 0) the
    /// offset is 0 and the ray starts at the point itself (a -0 coordinate
    /// becoming +0), with no test of n.
    #[inline]
    pub fn spawn_ray(&self, w: Vec3A) -> Ray {
        Ray { o: offset_ray_origin(self.p, self.p_error, self.n, w), d: w, skip: [self.slot, NO_TRIANGLE] }
    }

    /// Where a segment along `d` (any length) leaves this point, and
    /// whether it leaves by a side rounding cannot flip. The origin is
    /// `spawn_ray`'s (the point itself off surfaces). The side is
    /// resolved when the far end, `far`, lies off this point's plane
    /// (through `p`, normal `n`) by at least what the two points' rounding
    /// (`p_error`) could move it: |n . d| >= |n| . (p_error + far.p_error).
    /// If not, the geometric cosine here is within rounding of 0, so the
    /// connection carries (almost) nothing, while in f32 it could join the
    /// two faces of one wall, which the segment test, skipping both end
    /// triangles and their coplanar neighbours, cannot see it cross: light
    /// inside a closed shell lit the room outside through such segments (an
    /// audit and a review, session 43; `a_closed_shell_keeps_its_light_in`).
    /// (The normal's own rounding, which grows on sliver triangles and with
    /// the distance to `far`, is not counted.)
    ///
    /// Written without a test of n = 0, which an end off any surface (the
    /// pinhole, a point light) has: the bound carries |n| . MIN_POSITIVE
    /// more, which is 0 there, where the cosine is 0 too, so `>=` passes:
    /// such an end has no plane. On a surface the extra term is above 0
    /// (|n|_1 is about 1 or more, and Rust never flushes subnormals to
    /// zero), so a far end exactly in the plane fails even where both
    /// points are exact; next to any error bound above ~1e-30 it rounds
    /// away. Until session 45 the test was `n == 0 || |n . d| > bound`: the
    /// two differ only where |n . d| equals the bound exactly, which the
    /// old form blocked. The cosine also chooses the offset's side. Against
    /// testing n = 0 at each use and taking the dot product twice, this
    /// saves ~18 instructions a segment (docs/performance-log.md,
    /// "Session 45").
    #[inline(always)]
    fn depart(&self, d: Vec3A, far: &SurfacePoint) -> (Vec3A, bool) {
        let cos = self.n.dot(d);
        let bound = self.n.abs().dot(self.p_error + far.p_error + Vec3A::splat(f32::MIN_POSITIVE));
        (offset_to_side(self.p, self.p_error, self.n, cos), cos.abs() >= bound)
    }
}

/// A shading normal as prism shades with it: `n` normalised and turned to
/// the winding side `ng`, or `ng` itself where `n` is zero or not finite.
#[inline]
pub fn shading_normal(n: Vec3A, ng: Vec3A) -> Vec3A {
    let n = n.normalize_or_zero();
    if n == Vec3A::ZERO || !n.is_finite() {
        ng
    } else if n.dot(ng) < 0.0 {
        -n
    } else {
        n
    }
}

/// A shadow ray, the test of whether light passes between two points or
/// from a point to infinity: nothing may block `ray` in (0, t_max), and a
/// segment's ends must leave their surfaces by sides rounding cannot flip
/// (`ends_resolved`).
#[derive(Clone, Copy, Debug)]
pub struct Shadow {
    pub ray: Ray,
    pub t_max: f32,
    /// `SurfacePoint::depart`'s test of a segment's ends (true for a ray
    /// to infinity): if not, the segment counts as blocked, since it may
    /// cross the very surfaces it skips.
    pub ends_resolved: bool,
}

impl Shadow {
    /// The segment between two points, each end offset off its own surface
    /// (pbrt-v4 `SpawnRayTo` from both ends), up to the far end's offset
    /// point. Both ends' triangles and their coplanar runs are skipped and
    /// each end is moved off its surface by its error bound, so the segment
    /// needs no further margin: pbrt-v4 stops it at 1 - 1e-4 of its length
    /// (`ShadowEpsilon`; Mitsuba 3 at 1 - ~9e-4), which hides every occluder
    /// that near the light from next-event estimation while rays leaving the
    /// light meet it (a black cover 1e-4 below a lamp 2.5 away passed 88 %
    /// of the lamp's light to `path`'s NEE and none to light tracing).
    ///
    /// An end off any surface (a point light, the pinhole) is not offset:
    /// the segment starts there, as the rays that light or camera sends do.
    /// A surface through that point (a lamp on the floor) is then met at
    /// t ~ 0, where the intersection test takes only a hit certainly ahead
    /// (t > delta_t, or the sign of the plane distance in f64): a point
    /// exactly in the plane is not blocked by it, one rounded below a tilted
    /// floor is, the same for the segment and for the lamp's own rays. Met
    /// at the far end, t ~ 1, the floor blocked the segment or not by
    /// rounding (a lamp on the floor lit 12 % less by NEE than by light
    /// tracing).
    ///
    /// Skipping the end triangles assumes each end leaves its surface by
    /// the side the segment points to; where rounding decides that side
    /// (`SurfacePoint::depart`), the segment is blocked.
    #[inline(always)]
    pub fn segment(a: SurfacePoint, b: SurfacePoint) -> Self {
        let (a, b) = if b.n == Vec3A::ZERO && a.n != Vec3A::ZERO { (b, a) } else { (a, b) };
        let d = b.p - a.p;
        let (o, a_resolved) = a.depart(d, &b);
        let (target, b_resolved) = b.depart(-d, &a);
        let ray = Ray { o, d: target - o, skip: [a.slot, b.slot] };
        Self { ray, t_max: 1.0, ends_resolved: a_resolved && b_resolved }
    }

    /// From a point towards infinity in direction `w` (an infinite light).
    #[inline]
    pub fn escape(a: SurfacePoint, w: Vec3A) -> Self {
        Self { ray: a.spawn_ray(w), t_max: f32::INFINITY, ends_resolved: true }
    }
}

/// Offset a spawned ray's origin off the surface so it cannot re-hit it
/// (pbrt-v4 section 6.8.6, `OffsetRayOrigin`): move `p` along the unit
/// geometric normal `n`, to the side of the direction `w`, by
/// d = |n| . p_error, the extent of the error box of `p` along n; then round
/// each moved coordinate once more away from `p`, so the rounding of the
/// addition cannot bring it back inside the box. The true surface point lies
/// in the box, so the origin is on `w`'s side of the surface; the remaining
/// risk, a re-hit at t ~ 0 from the rounding of the intersection test
/// itself, is removed by that test's taking only hits certainly ahead
/// (t > delta_t, or within it the sign of the plane distance in f64;
/// src/accel/lanes.rs).
#[inline]
pub fn offset_ray_origin(p: Vec3A, p_error: Vec3A, n: Vec3A, w: Vec3A) -> Vec3A {
    offset_to_side(p, p_error, n, n.dot(w))
}

/// `offset_ray_origin` with the cosine n . w given.
#[inline(always)]
fn offset_to_side(p: Vec3A, p_error: Vec3A, n: Vec3A, cos: f32) -> Vec3A {
    let d = n.abs().dot(p_error);
    let offset = if cos < 0.0 { -d * n } else { d * n };
    step_away(p + offset, offset)
}

/// `po` moved one ulp further on each axis where `o` is non-zero, in o's
/// direction: IEEE 754 nextUp where o > 0, nextDown where o < 0, as integer
/// steps on the bits (the magnitude grows by one ulp when po and o have the
/// same sign and shrinks when they differ; from +-0 the step lands on the
/// smallest subnormal of o's sign). Selects rather than branches: the signs
/// of a surface normal's components are as good as random. The three axes
/// in one SSE2 register: the scalar steps, three lanes' integer work and
/// their moves between registers, cost `bdpt` 0.5 % more instructions
/// (docs/performance-log.md, "Session 45").
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn step_away(po: Vec3A, o: Vec3A) -> Vec3A {
    use std::arch::x86_64::*;
    // SAFETY: these intrinsics only need SSE2, which every x86-64 CPU has
    // (it is part of the x86-64 baseline target); none touches memory.
    unsafe {
        let (x, o) = (_mm_castps_si128(po.into()), _mm_castps_si128(o.into()));
        let (sign, one, zero) = (_mm_set1_epi32(i32::MIN), _mm_set1_epi32(1), _mm_setzero_si128());
        let select = |m: __m128i, a: __m128i, b: __m128i| _mm_or_si128(_mm_and_si128(m, a), _mm_andnot_si128(m, b));
        let toward = _mm_or_si128(_mm_srai_epi32::<31>(_mm_xor_si128(x, o)), one);
        let x_is_zero = _mm_cmpeq_epi32(_mm_andnot_si128(sign, x), zero);
        let moved = select(x_is_zero, _mm_or_si128(_mm_and_si128(o, sign), one), _mm_add_epi32(x, toward));
        let o_is_zero = _mm_cmpeq_epi32(_mm_andnot_si128(sign, o), zero);
        Vec3A::from(_mm_castsi128_ps(select(o_is_zero, x, moved)))
    }
}

/// `step_away` one axis at a time: off x86-64, and the reference its SSE2
/// form is tested against.
#[cfg(any(test, not(target_arch = "x86_64")))]
#[inline]
fn step_away_scalar(po: Vec3A, o: Vec3A) -> Vec3A {
    use crate::select::select_u32;
    const SIGN: u32 = 0x8000_0000;
    let step = |x: f32, o: f32| {
        let (x, o) = (x.to_bits(), o.to_bits());
        let toward = (((x ^ o) as i32) >> 31) as u32 | 1;
        let moved = select_u32(x & !SIGN == 0, (o & SIGN) | 1, x.wrapping_add(toward));
        f32::from_bits(select_u32(o & !SIGN == 0, x, moved))
    };
    Vec3A::new(step(po.x, o.x), step(po.y, o.y), step(po.z, o.z))
}

#[cfg(not(target_arch = "x86_64"))]
use step_away_scalar as step_away;

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

    /// The steps on the bits, in both forms, against the standard library's
    /// next_up and next_down, on the special values and on random bit
    /// patterns, on each axis (-x moves the other way on the second, and
    /// o = 0 leaves the third as it is).
    #[test]
    fn step_away_is_next_up_or_next_down() {
        let mut specials = vec![0.0f32, -0.0, f32::MIN_POSITIVE, -f32::MIN_POSITIVE, 1e-45, -1e-45, 1.0, -1.0];
        specials.extend([f32::MAX, -f32::MAX, 3.5e7, -2.0e-38, 0.1, -123.456]);
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let random = std::iter::repeat_with(move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            f32::from_bits(state as u32)
        });
        let xs: Vec<f32> = specials.iter().copied().chain(random.filter(|x| x.is_finite()).take(100_000)).collect();
        for (i, &x) in xs.iter().enumerate() {
            for o in [1e-3f32, -1e-3, 0.0, -0.0, xs[(i * 7919) % xs.len()]] {
                let want = if o > 0.0 {
                    x.next_up()
                } else if o < 0.0 {
                    x.next_down()
                } else {
                    x
                };
                for step in [step_away, step_away_scalar] {
                    let got = step(Vec3A::new(x, -x, want), Vec3A::new(o, -o, 0.0));
                    let want = [want, -want, want].map(f32::to_bits);
                    assert_eq!(got.to_array().map(f32::to_bits), want, "x = {x:e}, o = {o:e}");
                }
            }
        }
    }

    /// Points at least the margin from every edge are made exactly as
    /// before (b unchanged); the others are moved to at least 15 E from
    /// every edge's line (16 E less the rounding; margin h_min less the
    /// rounding where the margin is capped), across the edges they
    /// are too near: by at most 16 E where they are near one edge, by at
    /// most 16 E / sin(theta / 2) near a vertex of angle theta. On a unit
    /// right triangle at the origin, whose margin is 16 E / h_min with
    /// E = gamma(7) sqrt(2), h_min = 1 / sqrt(2), and on a sliver, the
    /// strip light of `light_points_keep_their_density_on_slivers`, where
    /// raising the barycentrics to the margin and renormalising them, the
    /// rule before session 49, moves a point near the middle of a long edge
    /// by 3.6 mm along it, 50 times 16 E (the control).
    #[test]
    fn triangle_points_keep_the_margin_from_every_edge() {
        let unit = [Vec3A::ZERO, Vec3A::X, Vec3A::Y];
        let margin = edge_margin(&unit);
        let want = 16.0 * gamma(7) as f64 * 2f64.sqrt() * 2f64.sqrt();
        assert!((margin as f64 / want - 1.0).abs() < 1e-6, "{margin} vs {want}");
        let strip = [Vec3A::new(10.0, 0.0, 0.0), Vec3A::new(10.0, 0.01, 0.0), Vec3A::new(11.0, 0.0, 0.0)];
        let at = |v: &[Vec3A; 3], b: [f32; 3]| (0..3).map(|i| v[i].as_dvec3() * b[i] as f64).sum::<DVec3>();
        let line_distance = |p: DVec3, a: Vec3A, b: Vec3A| {
            let (a, b) = (a.as_dvec3(), b.as_dvec3());
            (p - a).cross(b - a).length() / (b - a).length()
        };
        // Equilateral triangles at x = 10 of side 5 mm (its margin just
        // below the cap: a first form of `inset` left its moved points
        // 10.8 E from an edge; a review) and 1 mm (capped: h_min / 64).
        let equilateral = |side: f32| {
            [
                Vec3A::new(10.0, 0.0, 0.0),
                Vec3A::new(10.0 + side, 0.0, 0.0),
                Vec3A::new(10.0 + side / 2.0, side * 0.866, 0.0),
            ]
        };
        for v in [unit, strip, equilateral(0.005), equilateral(0.001)] {
            let (margin, e) = (edge_margin(&v), rounding_extent(&v));
            let t = v.map(|x| x.as_dvec3());
            let longest = (0..3).map(|i| (t[(i + 1) % 3] - t[i]).length()).fold(0.0, f64::max);
            let h_min = (t[1] - t[0]).cross(t[2] - t[0]).length() / longest;
            let clearance = (16.0 * e).min(margin as f64 * h_min);
            let angle = |i: usize| (t[(i + 1) % 3] - t[i]).angle_between(t[(i + 2) % 3] - t[i]);
            let sharpest = angle(0).min(angle(1)).min(angle(2));
            for b in [
                [0.2, 0.3, 0.5],
                [margin, margin, 1.0 - 2.0 * margin],
                [0.0, 0.5, 0.5],
                [0.5, 1e-9, 0.5],
                [0.5, 0.5, 0.0],
                [-1e-9, 1e-9, 1.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1e-4, 1e-4, 1.0 - 2e-4],
            ] {
                let (p, err) = triangle_point(&v, b, margin);
                let got = kept_off_edges(&v, b, margin);
                assert_eq!(
                    (p, err),
                    (v[0] * got[0] + v[1] * got[1] + v[2] * got[2], barycentric_error(&v, got[0], got[1], got[2]))
                );
                if !near_edges(b, margin) {
                    assert_eq!(got, b);
                    continue;
                }
                let (q, moved) = (p.as_dvec3(), (p.as_dvec3() - at(&v, b)).length());
                let nearest = (0..3).map(|i| line_distance(q, v[(i + 1) % 3], v[(i + 2) % 3])).fold(f64::MAX, f64::min);
                assert!(nearest >= clearance - e, "{b:?}: {:.2} E from an edge", nearest / e);
                assert!(moved <= 16.0 * e / (sharpest / 2.0).sin() + e, "{b:?}: moved {:.1} E", moved / e);
                // Near one edge, away from the vertices: across it only.
                if b == [0.0, 0.5, 0.5] || b == [0.5, 1e-9, 0.5] || b == [0.5, 0.5, 0.0] {
                    assert!(moved <= 16.0 * e + e, "{b:?}: moved {:.1} E", moved / e);
                }
            }
        }
        // The control: the old rule's move near the middle of the strip's
        // long edge.
        let (b, m) = ([0.5f32, 1e-9, 0.5], edge_margin(&strip));
        let c = b.map(|x| x.max(m));
        let old = c.map(|x| x / (c[0] + c[1] + c[2]));
        let slid = (at(&strip, old) - at(&strip, b)).length();
        assert!(slid > 40.0 * 16.0 * rounding_extent(&strip), "the control: the old rule moved {slid:e}");
    }

    /// The margin is capped at `MAX_EDGE_MARGIN` where f32 cannot resolve
    /// the triangle: a sliver (least altitude 1e-7 of a unit edge), a
    /// degenerate one (collinear or repeated vertices: NaN or infinity
    /// before the cap) and a triangle of legs 0.1 at (1e5, 1e5, 1e5), where
    /// f32's spacing is 0.0078 (margin ~16 before the cap). The same
    /// sliver 1e-2 tall keeps its own margin, 16 E / h_min with E =
    /// gamma(7) |(1, 1e-2, 0)| and h_min = 1e-2 (the area's twice over the
    /// longest edge, 1), and the margin grows with the distance from the
    /// origin.
    #[test]
    fn edge_margin_is_capped_where_f32_cannot_resolve_the_triangle() {
        let cap = MAX_EDGE_MARGIN as f32;
        let sliver = |h: f32| [Vec3A::ZERO, Vec3A::X, Vec3A::new(0.5, h, 0.0)];
        let far = Vec3A::splat(1e5);
        let tiny_and_far = [far, far + Vec3A::X * 0.1, far + Vec3A::Y * 0.1];
        assert!((tiny_and_far[1] - far).cross(tiny_and_far[2] - far).length() > 0.0);
        for (name, v) in [
            ("sliver", sliver(1e-7)),
            ("collinear", sliver(0.0)),
            ("repeated vertex", [Vec3A::ZERO, Vec3A::X, Vec3A::X]),
            ("point", [Vec3A::ONE; 3]),
            ("tiny and far", tiny_and_far),
        ] {
            assert_eq!(edge_margin(&v), cap, "{name}");
        }
        let tall = edge_margin(&sliver(1e-2)) as f64;
        let want = 16.0 * gamma(7) as f64 * (1.0f64 + 1e-4).sqrt() / 1e-2;
        assert!(want < MAX_EDGE_MARGIN && (tall / want - 1.0).abs() < 1e-5, "{tall} vs {want}");
        let near = edge_margin(&[Vec3A::ZERO, Vec3A::X, Vec3A::Y]);
        let moved = edge_margin(&[Vec3A::ONE, Vec3A::ONE + Vec3A::X, Vec3A::ONE + Vec3A::Y]);
        assert!(moved > near, "{moved} vs {near}");
    }

    #[test]
    fn offset_goes_to_w_side_by_the_error_bound() {
        let n = Vec3A::new(0.36, 0.48, 0.8);
        let v = [Vec3A::new(1.0, -2.0, 0.5), Vec3A::new(-3.0, 0.25, 1.0), Vec3A::new(0.5, 2.0, -4.0)];
        for scale in [0.0f32, 1e-3, 0.5, 1.0, 1e3, 1e5, -1e5] {
            let v = v.map(|x| x * scale);
            let (b0, b1, b2) = (0.2, 0.3, 0.5);
            let p = v[0] * b0 + v[1] * b1 + v[2] * b2;
            let e = barycentric_error(&v, b0, b1, b2);
            for w in [n, -n, Vec3A::new(0.0, 0.0, 1.0), Vec3A::new(0.0, 0.0, -1.0)] {
                let q = offset_ray_origin(p, e, n, w);
                let side = (q - p).dot(n) * n.dot(w).signum();
                assert!(side > 0.0 || (scale == 0.0 && q == p), "p = {p}, w = {w}, q = {q}");
                // At least the error box's extent along n, and not much more.
                let d = n.abs().dot(e);
                assert!(side >= d * 0.999 && side <= 2.0 * d + 1e-30, "{p} -> {q}: {side} vs {d}");
            }
        }
    }
}
