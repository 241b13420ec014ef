//! The watertight ray/triangle test (Woop, Benthin & Wald 2013) once, on
//! SIMD lanes of either kind the traversals use: four triangles of one ray
//! (`Vec4`, `PreparedRay::intersect_block`) or one triangle of eight rays
//! (`f32x8`, the packets of `packet.rs`). Both get each lane's result from
//! the same operations in the same order, so a ray finds the same hits
//! either way.

use super::exact::triple_product;
use crate::geometry::gamma;
use glam::{DVec3, Vec3A, Vec4};
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Sub};
use wide::f32x8;

/// A vector of f32 lanes with the operations of the watertight test.
pub(super) trait Lanes:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    /// A comparison's result, lane by lane.
    type Mask: Copy + BitOr<Output = Self::Mask> + BitAnd<Output = Self::Mask>;
    const ZERO: Self;
    const LANES: usize;
    fn splat(v: f32) -> Self;
    fn abs(self) -> Self;
    /// The hardware max (the second operand where either is NaN).
    fn max(self, other: Self) -> Self;
    fn eq(self, other: Self) -> Self::Mask;
    fn lt(self, other: Self) -> Self::Mask;
    fn gt(self, other: Self) -> Self::Mask;
    fn ge(self, other: Self) -> Self::Mask;
    fn select(mask: Self::Mask, if_true: Self, if_false: Self) -> Self;
    fn bitmask(mask: Self::Mask) -> u32;
    fn lane(self, l: usize) -> f32;
    fn set_lane(&mut self, l: usize, v: f32);
}

impl Lanes for Vec4 {
    type Mask = glam::BVec4A;
    const ZERO: Self = Vec4::ZERO;
    const LANES: usize = 4;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        Vec4::splat(v)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Vec4::abs(self)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        Vec4::max(self, other)
    }
    #[inline(always)]
    fn eq(self, other: Self) -> Self::Mask {
        self.cmpeq(other)
    }
    #[inline(always)]
    fn lt(self, other: Self) -> Self::Mask {
        self.cmplt(other)
    }
    #[inline(always)]
    fn gt(self, other: Self) -> Self::Mask {
        self.cmpgt(other)
    }
    #[inline(always)]
    fn ge(self, other: Self) -> Self::Mask {
        self.cmpge(other)
    }
    #[inline(always)]
    fn select(mask: Self::Mask, if_true: Self, if_false: Self) -> Self {
        Vec4::select(mask, if_true, if_false)
    }
    #[inline(always)]
    fn bitmask(mask: Self::Mask) -> u32 {
        mask.bitmask()
    }
    #[inline(always)]
    fn lane(self, l: usize) -> f32 {
        self[l]
    }
    #[inline(always)]
    fn set_lane(&mut self, l: usize, v: f32) {
        self[l] = v;
    }
}

impl Lanes for f32x8 {
    type Mask = f32x8;
    const ZERO: Self = f32x8::ZERO;
    const LANES: usize = 8;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        f32x8::splat(v)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f32x8::abs(self)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        self.fast_max(other)
    }
    #[inline(always)]
    fn eq(self, other: Self) -> Self::Mask {
        self.simd_eq(other)
    }
    #[inline(always)]
    fn lt(self, other: Self) -> Self::Mask {
        self.simd_lt(other)
    }
    #[inline(always)]
    fn gt(self, other: Self) -> Self::Mask {
        self.simd_gt(other)
    }
    #[inline(always)]
    fn ge(self, other: Self) -> Self::Mask {
        self.simd_ge(other)
    }
    #[inline(always)]
    fn select(mask: Self::Mask, if_true: Self, if_false: Self) -> Self {
        mask.select(if_true, if_false)
    }
    #[inline(always)]
    fn bitmask(mask: Self::Mask) -> u32 {
        mask.to_bitmask()
    }
    #[inline(always)]
    fn lane(self, l: usize) -> f32 {
        self.to_array()[l]
    }
    #[inline(always)]
    fn set_lane(&mut self, l: usize, v: f32) {
        let mut a = self.to_array();
        a[l] = v;
        *self = f32x8::new(a);
    }
}

/// The lanes that pass the watertight test, and those (`near`) that do but
/// for the sign of t, with their distances and the barycentrics of the
/// second and third vertices. `ts` and `ds` are t
/// before the division, signed by det, and |det|: a caller whose t_max
/// shrank since the test can check a lane again (`ts < t_max ds`).
pub(super) struct Candidates<L> {
    pub mask: u32,
    /// Lanes inside the triangle whose t is within its rounding error of 0:
    /// a hit or not as `near_t_in_f64` finds.
    pub near: u32,
    /// A bound on the barycentrics' error from the edge functions' rounding
    /// (pbrt-v4's delta_e over |det|): where a barycentric is within it of
    /// 0 the ray passes that close to an edge, and the test may be wrong
    /// about it (`Accel::intersect_exact` settles it).
    pub edge_error: L,
    pub t: L,
    pub b1: L,
    pub b2: L,
    pub ts: L,
    pub ds: L,
}

/// Woop, Benthin & Wald 2013, fig. 2/3 (no backface culling), lane by
/// lane, from the vertices' coordinates relative to the ray origin, permuted
/// and sheared (`x`, `y`; `z` unscaled, with its scale `sz`), for the lanes
/// set in `lanes` and distances in (0, `t_max`). Every triangle sharing a
/// vertex computes the same sheared coordinates for it, and the edge
/// function of a shared edge in the neighbour is the exact negation of ours
/// (x1 y2 - y1 x2 vs y1 x2 - x1 y2, products commute exactly), so a ray on
/// the edge cannot miss both.
#[inline(always)]
pub(super) fn watertight<L: Lanes>(
    x: [L; 3],
    y: [L; 3],
    z: [L; 3],
    sz: L,
    t_max: L,
    lanes: u32,
) -> Option<Candidates<L>> {
    // The edge functions (U, V, W) = (cx by - cy bx, ax cy - ay cx,
    // bx ay - by ax) of vertices (a, b, c).
    let mut e = [x[2] * y[1] - y[2] * x[1], x[0] * y[2] - y[0] * x[2], x[1] * y[0] - y[1] * x[0]];
    // Exactly zero means the ray is (in f32) on an edge; the f32 products
    // are exact in f64, so recomputing there gets the true sign (sec. 3.3).
    let zero = L::bitmask(e[0].eq(L::ZERO) | e[1].eq(L::ZERO) | e[2].eq(L::ZERO)) & lanes;
    if zero != 0 {
        e = edges_in_f64(&x, &y, e, zero);
    }
    // Outside unless the signs agree (zeros aside). A triangle no lane is
    // inside, what most tests meet, stops here.
    let neg = e[0].lt(L::ZERO) | e[1].lt(L::ZERO) | e[2].lt(L::ZERO);
    let pos = e[0].gt(L::ZERO) | e[1].gt(L::ZERO) | e[2].gt(L::ZERO);
    let inside = !L::bitmask(neg & pos) & lanes;
    if inside == 0 {
        return None;
    }
    let det = (e[0] + e[1]) + e[2];
    let t_scaled = (e[0] * (z[0] * sz) + e[1] * (z[1] * sz)) + e[2] * (z[2] * sz);
    // Range test on t = t_scaled / det before dividing (sec. 3.4), with
    // the sign of det folded in (the paper's xorf; for det = -0 or a
    // negative NaN the two differ, and the lane fails either way): lanes
    // at or beyond t_max are done. Those behind the origin (ts <= 0) stay,
    // as rounding may hide a hit just ahead (below).
    let (ts, ds) = (L::select(det.lt(L::ZERO), -t_scaled, t_scaled), det.abs());
    let live = inside & !L::bitmask(ts.ge(t_max * ds));
    if live == 0 {
        return None;
    }
    let rcp = L::splat(1.0) / det;
    let t = t_scaled * rcp;
    // The division can round up to t_max. And t itself carries rounding
    // error: accept it only when conservatively positive, t > delta_t
    // (pbrt-v4 section 6.8.7, the bounds of its `IntersectTriangle`), so a
    // ray leaving a surface never re-hits it at t ~ 0 whatever the scene's
    // scale (see `offset_ray_origin`); written so that NaN fails, which
    // rejects det = 0 too. Where t is within its error of 0 (|t| <=
    // delta_t, which grows with the vertices' distance: a few 1e-6 of a
    // floor's size) the caller settles its sign in f64 (`near_t_in_f64`),
    // so a ray leaving an object just above a large floor still meets it.
    let (delta, delta_e) = delta_t(&x, &y, &z, sz, &e, rcp);
    let mask = L::bitmask(t.gt(delta)) & live;
    let near = L::bitmask(t.gt(-delta)) & live & !mask;
    let edge_error = delta_e * rcp.abs();
    Some(Candidates { mask, near, edge_error, t, b1: e[1] * rcp, b2: e[2] * rcp, ts, ds })
}

/// The distance along the ray (o, d) to the plane of `tri` when it is
/// certainly positive, else None: t = N.(p0 - o) / N.d with
/// N = (p1 - p0) x (p2 - p0), in f64 from the f32 inputs.
///
/// Error bound (Higham's gamma_n = n u / (1 - n u), u = 2^-53): with A, B, V
/// the exact differences p1 - p0, p2 - p0, p0 - o and each computed one off
/// by a factor (1 + delta), |delta| <= u, every component of the computed N
/// is within gamma_4 M of the exact one, M = |A| x |B| taken term by term
/// (|A_y B_z| + |A_z B_y|, ...), so |N| <= (1 + gamma_4) M; the dot
/// products add gamma_4 (V rounded, a product, two sums) and gamma_3 (d is
/// exact) of sum |N_i||V_i| and sum |N_i||d_i|. Together both computed
/// values lie within gamma_9 sum M_i |V_i| and gamma_9 sum M_i |d_i| of
/// N.V and N.d; the bounds, themselves evaluated with a few roundings, are
/// doubled. Beyond them both signs are certain, and t > 0 exactly.
pub(super) fn near_t_in_f64(o: Vec3A, d: Vec3A, tri: &[Vec3A; 3]) -> Option<f32> {
    ahead_t_in_f64(o, d, tri).map(|(t, _)| t as f32)
}

/// `near_t_in_f64`'s distance, in f64 (its f32 rounding is above 0), with
/// a bound on its error: the computed N.V and N.d lie within their bounds
/// bv, bd of the exact ones (above), so t errs by at most
/// |t| (bv / (|N.V| - bv) + bd / (|N.d| - bd)), and the division by one
/// rounding more (counted twice).
fn ahead_t_in_f64(o: Vec3A, d: Vec3A, tri: &[Vec3A; 3]) -> Option<(f64, f64)> {
    let [p0, p1, p2] = tri.map(|v| v.as_dvec3());
    let (a, b, v, d) = (p1 - p0, p2 - p0, p0 - o.as_dvec3(), d.as_dvec3());
    let (n, m) = (a.cross(b), abs_cross(a, b));
    let (num, den) = (n.dot(v), n.dot(d));
    let (sign, bv, bd) = (den.signum(), rounding_bound(m, v), rounding_bound(m, d));
    let t = num / den;
    let err = t.abs() * (bv / (num.abs() - bv) + bd / (den.abs() - bd) + 2.0 * f64::EPSILON);
    (den.abs() > bd && num * sign > bv && t as f32 > 0.0).then_some((t, err))
}

/// A hit found in f64 (`hit_in_f64`).
pub(super) struct HitF64 {
    pub t: f64,
    /// A bound on the error of `t` (`ahead_t_in_f64`).
    pub err: f64,
    pub b1: f32,
    pub b2: f32,
}

/// The ray (o, d) against `tri` in f64, for `Accel::intersect_exact`:
/// inside by the signs of the scalar triple products
/// ((v_i - o) x (v_j - o)) . d of its edges (the side of the ray each edge
/// passes; zero counts for both sides), which two triangles sharing an
/// edge compute exactly negated (each product in a cross component
/// commutes), so a ray cannot pass between them; at the distance of
/// `ahead_t_in_f64`, if that is certainly ahead. (The three products sum
/// to N . d, N = (v1 - v0) x (v2 - v0).)
pub(super) fn hit_in_f64(o: Vec3A, d: Vec3A, tri: &[Vec3A; 3]) -> Option<HitF64> {
    let dd = d.as_dvec3();
    let rel = tri.map(|v| v.as_dvec3() - o.as_dvec3());
    // Edge (i, j)'s product, the weight of the vertex opposite. Within its
    // rounding error (the bound of `ahead_t_in_f64`, on the terms'
    // magnitudes) it is found again with its exact sign: a sign from
    // rounding could leave every triangle around a vertex outside a ray
    // through it (44f9860), and a 0 for every product that small took a
    // ray passing 1.6e-8 outside a cube's edge, from 1,000 away, as
    // through it: both faces met, the far one first (a review, session
    // 48). The bound is symmetric in the two vertices, so neighbours take
    // the same branch for the edge they share.
    let side = |i: usize, j: usize| {
        let (p, q) = (rel[i], rel[j]);
        let s = p.cross(q).dot(dd);
        if s.abs() > rounding_bound(abs_cross(p, q), dd) {
            s
        } else {
            triple_product(o, d, tri[i], tri[j])
        }
    };
    // The weights of vertices 0, 1 and 2; all 0 for a ray in the plane.
    let (u, v, w) = (side(1, 2), side(2, 0), side(0, 1));
    let inside = (u >= 0.0 && v >= 0.0 && w >= 0.0) || (u <= 0.0 && v <= 0.0 && w <= 0.0);
    let sum = u + v + w;
    if !inside || sum == 0.0 {
        return None;
    }
    let (t, err) = ahead_t_in_f64(o, d, tri)?;
    let (b1, b2) = ((v / sum) as f32, (w / sum) as f32);
    Some(HitF64 { t, err, b1, b2 })
}

/// Of two faces a ray meets at one distance (within the f64 distances'
/// error: a ray through the edge they share), whether it enters the solid
/// by `a`: crossing a's plane, it moves to the side where `b` lies (the
/// side of b's vertex farthest from that plane), which at a convex edge is
/// the solid's; at a concave one neither face passes this test. Free of
/// the winding (a shell wound inward has its fronts inside). A vertex
/// within the rounding of a's plane (`rounding_bound`) counts as in it, so
/// neither of two coplanar faces passes either, tilted or not.
pub(super) fn enters_by(a: &[Vec3A; 3], b: &[Vec3A; 3], d: Vec3A) -> bool {
    let [p0, p1, p2] = a.map(|v| v.as_dvec3());
    let (e1, e2) = (p1 - p0, p2 - p0);
    let (n, m) = (e1.cross(e2), abs_cross(e1, e2));
    let height = |w: Vec3A| {
        let v = w.as_dvec3() - p0;
        let s = n.dot(v);
        if s.abs() > rounding_bound(m, v) {
            s
        } else {
            0.0
        }
    };
    let far = b.map(height).into_iter().fold(0.0f64, |f, s| if s.abs() > f.abs() { s } else { f });
    far != 0.0 && (n.dot(d.as_dvec3()) > 0.0) == (far > 0.0)
}

/// M = |p| x |q| taken term by term (|p_y q_z| + |p_z q_y|, ...): the
/// magnitude of the terms of p x q (`near_t_in_f64`'s error bound).
fn abs_cross(p: DVec3, q: DVec3) -> DVec3 {
    let (pa, qa) = (p.abs(), q.abs());
    DVec3::new(pa.y * qa.z + pa.z * qa.y, pa.z * qa.x + pa.x * qa.z, pa.x * qa.y + pa.y * qa.x)
}

/// The bound of `near_t_in_f64` on the rounding error of (p x q) . w
/// computed in f64 from f32 inputs, M = `abs_cross(p, q)`: twice
/// gamma_9 M . |w|.
fn rounding_bound(m: DVec3, w: DVec3) -> f64 {
    2.0 * gamma64(9) * m.dot(w.abs())
}

/// Higham's gamma_n in f64.
const fn gamma64(n: u32) -> f64 {
    let nu = n as f64 * f64::EPSILON * 0.5;
    nu / (1.0 - nu)
}

/// Bound on the rounding error of t, per lane, from the sheared vertex
/// coordinates `x`, `y`, the unscaled `z` with its scale `sz`, the edge
/// functions `e` and 1 / det. As pbrt-v4's, except that the shear's error
/// follows the unscaled z the shear multiplies (pbrt uses the scaled z
/// there, which is loose for short directions and not conservative for
/// long ones).
#[inline(always)]
fn delta_t<L: Lanes>(x: &[L; 3], y: &[L; 3], z: &[L; 3], sz: L, e: &[L; 3], rcp: L) -> (L, L) {
    // (The one-triangle form took the max over (a, c), then b: the same but
    // for a NaN, and a NaN in x or y makes det NaN, failing the lane.)
    let max_abs = |v: &[L; 3]| v[0].abs().max(v[1].abs()).max(v[2].abs());
    let (max_x, max_y, max_z, max_e) = (max_abs(x), max_abs(y), max_abs(z), max_abs(e));
    let g = |n: u32| L::splat(gamma(n));
    let max_zs = max_z * sz.abs();
    let delta_zs = g(3) * max_zs;
    let delta_x = g(5) * (max_x + max_z);
    let delta_y = g(5) * (max_y + max_z);
    let delta_e = L::splat(2.0) * (g(2) * max_x * max_y + delta_y * max_x + delta_x * max_y);
    (L::splat(3.0) * (g(3) * max_e * max_zs + delta_e * max_zs + delta_zs * max_e) * rcp.abs(), delta_e)
}

/// The edge functions `e` with those of the lanes in `redo` recomputed in
/// f64 from the sheared coordinates (all three of a lane, as one f32
/// product pair each, exact in f64, then rounded once).
#[cold]
#[inline(never)]
fn edges_in_f64<L: Lanes>(x: &[L; 3], y: &[L; 3], mut e: [L; 3], redo: u32) -> [L; 3] {
    for l in (0..L::LANES).filter(|l| redo >> l & 1 != 0) {
        let f = |v: L| v.lane(l) as f64;
        let edge = |a: usize, b: usize| (f(x[a]) * f(y[b]) - f(y[a]) * f(x[b])) as f32;
        let (u, v, w) = (edge(2, 1), edge(0, 2), edge(1, 0));
        e[0].set_lane(l, u);
        e[1].set_lane(l, v);
        e[2].set_lane(l, w);
    }
    e
}
