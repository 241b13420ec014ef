//! Eight rays through the BVH at once, one per SIMD lane (a ray packet,
//! Wald, Slusallek, Benthin & Wagner 2001, "Interactive Rendering with
//! Coherent Ray Tracing", with the active-lane masks of their sec. 4).
//!
//! The packet visits the union of the nodes its rays enter: a child is
//! visited with the lanes whose rays enter its box, and each of its
//! triangles is tested against those lanes together. Every lane computes
//! exactly what the single-ray traversal computes for its ray (the same
//! slab products and sums, the same watertight test with the same axis
//! permutation, chosen per lane by selects), so a lane accepts exactly the
//! hits the single ray accepts. Only the order in which a packet meets
//! them differs, and ties do not hang on it: the least (t, slot) wins
//! either way (`Closest`), but for two rare cases `Closest` names (hits
//! within rounding of the origin, and ties in another leaf for grazing
//! rays).
//!
//! Packets pay for coherent rays only (docs/performance-log.md, "Session 20"):
//! a pixel's camera rays trace 2.9x faster than one at a time, incoherent
//! rays 0.87x as fast (the union of their nodes and triangles grows nearly
//! as fast as the lanes), so `path` traces its camera rays this way and
//! nothing else does.

use super::lanes::{near_t_in_f64, watertight, Candidates, Lanes};
use super::{Accel, GroupStack, SLACK, TIE_REACH};
use crate::geometry::Ray;
use glam::Vec3A;
use obvhs::cwbvh::node::CwBvhNode;
use wide::{f32x8, i32x8};

/// Lanes per packet.
pub const LANES: usize = 8;

/// A packet's per-lane ray constants (`PreparedRay`'s, lane by lane).
struct PreparedPacket<'a> {
    o: [f32x8; 3],
    /// Each lane's ray as given, for the hits that need f64.
    rays: &'a [Ray; LANES],
    inv: [f32x8; 3],
    abs_inv: [f32x8; 3],
    o_k: [f32x8; 3],
    s: [f32x8; 3],
    /// `is_k[a][c]`: the lanes whose permutation puts axis c at place a
    /// (c = 0, 1; the rest have axis 2 there).
    is_k: [[f32x8; 2]; 3],
    /// The two skipped slot runs, (first, last) biased by 2^31 so a signed
    /// compare orders them as unsigned.
    skip: [[i32x8; 2]; 2],
    /// Lanes with a ray that can hit anything.
    active: u32,
    /// Per lane, the octant whose slot order is near to far for its ray
    /// (`PreparedRay::oct_inv4`'s byte).
    octant: [usize; LANES],
}

/// Slot s biased for the signed compares of `PreparedPacket::skip`.
#[inline(always)]
fn bias(s: u32) -> i32 {
    (s ^ 0x8000_0000) as i32
}

impl<'a> PreparedPacket<'a> {
    /// `PreparedRay::new` in every lane at once, with the same operations
    /// in the same order (so the same constants, bit for bit).
    fn new(accel: &Accel, rays: &'a [Ray; LANES], active: u32) -> Self {
        // Axis k of every lane's origin and direction.
        let o = [0, 1, 2].map(|k| f32x8::new(std::array::from_fn(|l| rays[l].o[k])));
        let d = [0, 1, 2].map(|k| f32x8::new(std::array::from_fn(|l| rays[l].d[k])));
        // Finite (x - x is 0 exactly when x is finite, the point of the
        // lint's "equal operands") and not zero.
        let zero = |v: f32x8| v.simd_eq(f32x8::ZERO);
        #[allow(clippy::eq_op)]
        let finite =
            (0..3).fold(f32x8::splat(f32::from_bits(u32::MAX)), |m, k| m & zero((o[k] - o[k]) + (d[k] - d[k])));
        let length2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let on = (finite & length2.simd_gt(f32x8::ZERO)).to_bitmask() & active;
        // kz: the first axis of largest |d|; (kx, ky) the next two
        // cyclically, swapped when d[kz] < 0 (`AXIS_ORDERS`).
        let ad = d.map(f32x8::abs);
        let kz0 = ad[0].simd_ge(ad[1]) & ad[0].simd_ge(ad[2]);
        let kz1 = !kz0 & ad[1].simd_ge(ad[2]);
        let kz2 = !(kz0 | kz1);
        let d_kz = kz0.select(d[0], kz1.select(d[1], d[2]));
        let neg = d_kz.simd_lt(f32x8::ZERO);
        let is_k = [
            [(kz1 & neg) | (kz2 & !neg), (kz0 & !neg) | (kz2 & neg)],
            [(kz1 & !neg) | (kz2 & neg), (kz0 & neg) | (kz2 & !neg)],
            [kz0, kz1],
        ];
        let pick = |v: &[f32x8; 3], a: usize| is_k[a][0].select(v[0], is_k[a][1].select(v[1], v[2]));
        let o_k = [0, 1, 2].map(|a| pick(&o, a));
        let d_k = [0, 1, 2].map(|a| pick(&d, a));
        let sz = f32x8::ONE / d_k[2];
        let inv = d.map(|c| f32x8::ONE / c.abs().fast_max(f32x8::splat(1e-20)).copysign(c));
        let negative = inv.map(|c| c.is_sign_negative().to_bitmask());
        let octant = std::array::from_fn(|l| {
            let bit = |k: usize| (!negative[k] >> l & 1) as usize;
            bit(0) << 2 | bit(1) << 1 | bit(2)
        });
        let skip = [0, 1].map(|i| {
            let runs: [(u32, u32); LANES] = std::array::from_fn(|l| accel.skip_run(rays[l].skip[i]));
            [runs.map(|r| bias(r.0)), runs.map(|r| bias(r.1))].map(i32x8::new)
        });
        Self {
            o,
            rays,
            inv,
            abs_inv: inv.map(f32x8::abs),
            o_k,
            s: [d_k[0] * sz, d_k[1] * sz, sz],
            is_k,
            skip,
            active: on,
            octant,
        }
    }

    /// The lanes that do not skip `slot`.
    #[inline(always)]
    fn not_skipping(&self, slot: u32) -> u32 {
        let s = i32x8::splat(bias(slot));
        let inside = |[first, last]: [i32x8; 2]| !first.simd_gt(s) & !s.simd_gt(last);
        !(inside(self.skip[0]) | inside(self.skip[1])).to_bitmask()
    }

    /// The lanes (of `lanes`) whose rays enter child `c` of the node before
    /// their `t_max`, and the smallest entry distance among them. As
    /// `NodeSlabs`, lane by lane.
    #[inline(always)]
    fn node_children(&self, node: &CwBvhNode, t_max: f32x8, lanes: u32) -> [u32; 8] {
        let e = node.compute_extent();
        let p = glam::Vec3A::from(node.p);
        let mut scale = [f32x8::ZERO; 3];
        let mut near_off = [f32x8::ZERO; 3];
        let mut far_off = [f32x8::ZERO; 3];
        for k in 0..3 {
            let diff = f32x8::splat(p[k]) - self.o[k];
            let base = diff * self.inv[k];
            let slack = (diff.abs() + f32x8::splat(e[k] * 256.0)) * self.abs_inv[k] * f32x8::splat(SLACK);
            scale[k] = f32x8::splat(e[k]) * self.inv[k];
            near_off[k] = base - slack;
            far_off[k] = base + slack;
        }
        // The quantized planes as floats, all children at once.
        let q = |v: &[u8; 8]| v.map(f32::from);
        let lo = [q(&node.child_min_x), q(&node.child_min_y), q(&node.child_min_z)];
        let hi = [q(&node.child_max_x), q(&node.child_max_y), q(&node.child_max_z)];
        let mut hits = [0u32; 8];
        for (c, hit) in hits.iter_mut().enumerate() {
            if node.child_meta[c] == 0 {
                continue;
            }
            let slab = |k: usize| {
                let (a, b) = (f32x8::splat(lo[k][c]) * scale[k], f32x8::splat(hi[k][c]) * scale[k]);
                (a.fast_min(b) + near_off[k], a.fast_max(b) + far_off[k])
            };
            let ((nx, fx), (ny, fy), (nz, fz)) = (slab(0), slab(1), slab(2));
            let t_near = nx.fast_max(ny).fast_max(nz).fast_max(f32x8::ZERO);
            let t_far = fx.fast_min(fy).fast_min(fz).fast_min(t_max);
            *hit = t_near.simd_le(t_far).to_bitmask() & lanes;
        }
        hits
    }
}

/// Each lane's `Closest`, with its hit's barycentrics and edge error.
struct Hits {
    t: f32x8,
    slot: i32x8,
    reach: f32x8,
    b1: f32x8,
    b2: f32x8,
    edge_error: f32x8,
}

impl Accel {
    /// `intersect` for up to eight rays (lanes of `active`).
    pub fn intersect8(
        &self,
        rays: &[Ray; LANES],
        t_max: [f32; LANES],
        active: u32,
    ) -> [Option<super::TriangleHit>; LANES] {
        let pre = PreparedPacket::new(self, rays, active);
        let mut hits = Hits::new(t_max);
        let found = self.traverse8(&pre, &mut hits);
        let (t, slot, b1, b2) = (hits.t.to_array(), hits.slot.to_array(), hits.b1.to_array(), hits.b2.to_array());
        let edge_error = hits.edge_error.to_array();
        std::array::from_fn(|l| {
            (found >> l & 1 != 0).then(|| self.hit(t[l], slot[l] as u32, b1[l], b2[l], edge_error[l]))
        })
    }

    /// The packet traversal: the closest hit of each lane's ray, into
    /// `hits`; returns the lanes that found one.
    #[inline(always)]
    fn traverse8(&self, pre: &PreparedPacket, hits: &mut Hits) -> u32 {
        let mut found = 0u32;
        if self.bvh.nodes.is_empty() || pre.active == 0 {
            return found;
        }
        let mut stack = GroupStack::new();
        stack.push((0, pre.active));
        while let Some((index, lanes)) = stack.pop() {
            let node = &self.bvh.nodes[index as usize];
            let children = pre.node_children(node, hits.reach, lanes);
            // Children in the order of the first lane's octant, near to far
            // for its ray (Ylitie et al. 2017, sec. 3.1); the inner ones go
            // onto the stack far to near.
            let octant = pre.octant[lanes.trailing_zeros() as usize];
            let mut inner = [(0u32, 0u32); 8];
            let mut n_inner = 0;
            for c in (0..8).rev().map(|i| i ^ octant) {
                let child_lanes = children[c];
                if child_lanes == 0 {
                    continue;
                }
                if node.is_leaf(c) {
                    let (first, count) = node.child_primitives(c);
                    for slot in first..first + count {
                        let lanes = child_lanes & pre.not_skipping(slot);
                        if lanes != 0 {
                            found |= pre.intersect_triangle(self, slot, lanes, hits);
                        }
                    }
                } else {
                    inner[n_inner] = (node.child_node_index(c), child_lanes);
                    n_inner += 1;
                }
            }
            for &group in inner[..n_inner].iter().rev() {
                stack.push(group);
            }
        }
        found
    }
}

impl Hits {
    fn new(t_max: [f32; LANES]) -> Self {
        // (Slots compare as i32: the 2^31 triangles past which they would
        // not take 80 GB, more than any scene prism renders.)
        let (t, zero) = (f32x8::new(t_max), f32x8::ZERO);
        Self { t, slot: i32x8::ZERO, reach: t * f32x8::splat(TIE_REACH), b1: zero, b2: zero, edge_error: zero }
    }
}

impl PreparedPacket<'_> {
    /// The watertight test (`lanes::watertight`) of the triangle in `slot`
    /// against the rays of `lanes`, each lane with its own axis
    /// permutation; returns the lanes whose best hit it became.
    #[inline(always)]
    fn intersect_triangle(&self, accel: &Accel, slot: u32, lanes: u32, hits: &mut Hits) -> u32 {
        let v = accel.vertices(slot);
        // Coordinate of place a (kx, ky, kz) of vertex j, per lane.
        let pick = |a: usize, j: usize| {
            let [is0, is1] = self.is_k[a];
            is0.select(f32x8::splat(v[j].x), is1.select(f32x8::splat(v[j].y), f32x8::splat(v[j].z)))
        };
        let (sx, sy, sz) = (self.s[0], self.s[1], self.s[2]);
        let z = [0, 1, 2].map(|j| pick(2, j) - self.o_k[2]);
        let x = [0, 1, 2].map(|j| (pick(0, j) - self.o_k[0]) - sx * z[j]);
        let y = [0, 1, 2].map(|j| (pick(1, j) - self.o_k[1]) - sy * z[j]);
        let Some(mut c) = watertight(x, y, z, sz, hits.reach, lanes) else {
            return 0;
        };
        if c.near != 0 {
            c = self.settle_near(c, &v);
        }
        let tie = c.t.simd_eq(hits.t).to_bitmask() & i32x8::splat(slot as i32).simd_lt(hits.slot).to_bitmask();
        let won = (c.t.simd_lt(hits.t).to_bitmask() | tie) & c.mask;
        if won == 0 {
            return 0;
        }
        // All ones in the lanes it won, as floats and as integers.
        let ones: [u32; LANES] = std::array::from_fn(|l| 0u32.wrapping_sub(won >> l & 1));
        let m = f32x8::new(ones.map(f32::from_bits));
        hits.t = m.select(c.t, hits.t);
        hits.reach = m.select(c.t * f32x8::splat(TIE_REACH), hits.reach);
        hits.b1 = m.select(c.b1, hits.b1);
        hits.b2 = m.select(c.b2, hits.b2);
        hits.slot = i32x8::new(ones.map(|b| b as i32)).select(i32x8::splat(slot as i32), hits.slot);
        hits.edge_error = m.select(c.edge_error, hits.edge_error);
        won
    }

    /// `c` with the lanes whose rays meet the triangle `v` within the
    /// rounding error of their t from the origin and certainly ahead of it
    /// (`near_t_in_f64`) added, at that distance.
    #[inline(always)]
    fn settle_near(&self, mut c: Candidates<f32x8>, v: &[Vec3A; 3]) -> Candidates<f32x8> {
        for l in (0..LANES).filter(|l| c.near >> l & 1 != 0) {
            if let Some(t) = near_t_in_f64(self.rays[l].o, self.rays[l].d, v) {
                c.t.set_lane(l, t);
                c.mask |= 1 << l;
            }
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::uniform;
    use super::*;
    use crate::shapes::Mesh;
    use glam::{Affine3A, Vec3, Vec3A};

    /// A closed room with two rotated boxes and a 642-vertex sphere.
    fn scene() -> Vec<[Vec3A; 3]> {
        let mut room = Mesh::cuboid(Vec3A::ZERO, Vec3A::ONE);
        room.transform(Affine3A::IDENTITY);
        let mut tall = Mesh::cuboid(Vec3A::new(-0.15, 0.0, -0.15), Vec3A::new(0.15, 0.6, 0.15));
        tall.transform(Affine3A::from_translation(Vec3::new(0.33, 0.0, 0.65)) * Affine3A::from_rotation_y(0.3));
        let ball = Mesh::sphere(Vec3A::new(0.7, 0.2, 0.3), 0.15, 3, false);
        [room, tall, ball].iter().flat_map(|m| m.triangles().collect::<Vec<_>>()).collect()
    }

    /// Rays from points in the room, some leaving a triangle (skipping
    /// its slot), some aimed along axes and through vertices.
    fn rays(accel: &Accel, tris: &[[Vec3A; 3]], n: usize) -> Vec<(Ray, f32)> {
        let mut u = uniform(7);
        let slots = accel.slot_map();
        (0..n)
            .map(|i| {
                let mut d = Vec3A::new(u() - 0.5, u() - 0.5, u() - 0.5);
                if i % 7 == 0 {
                    d = Vec3A::X * d.x.signum();
                }
                let (mut ray, t_max) = if i % 3 == 0 {
                    let k = (u() * tris.len() as f32) as usize;
                    let [a, b, c] = tris[k];
                    let p = if i % 6 == 0 { a } else { a + (b - a) * 0.25 + (c - a) * 0.25 };
                    let n = (b - a).cross(c - a);
                    let d = if d.dot(n) < 0.0 { -d } else { d };
                    let mut r = Ray::new(p, d);
                    r.skip[0] = slots[k];
                    (r, f32::INFINITY)
                } else {
                    (Ray::new(Vec3A::new(u(), u(), u()), d), if i % 2 == 0 { u() } else { f32::INFINITY })
                };
                if i % 11 == 0 {
                    ray.d = tris[(u() * tris.len() as f32) as usize][1] - ray.o;
                }
                (ray, t_max)
            })
            .collect()
    }

    /// Every lane of a packet finds what its ray finds alone: the same
    /// triangle at the same distance, bit for bit, ties included (the least
    /// (t, slot) wins, `Closest`; none of these rays meets its cases
    /// apart); inactive lanes find nothing. The sphere
    /// is there twice, each triangle coincident with its copy, so every ray
    /// that meets it meets an exact tie. (Until session 50 a tie went to the
    /// first triangle the traversal met, in an order that differs between
    /// a packet and a ray, and this test allowed another triangle within 2
    /// ulps.)
    #[test]
    fn packets_agree_with_single_rays() {
        let mut tris = scene();
        let boxes = 24;
        tris.extend_from_within(boxes..);
        let accel = Accel::build(&tris);
        let all = rays(&accel, &tris, 40_000);
        let (mut hits, mut ties) = (0, 0);
        for (i, chunk) in all.chunks_exact(LANES).enumerate() {
            let ray: [Ray; LANES] = std::array::from_fn(|l| chunk[l].0);
            let t_max: [f32; LANES] = std::array::from_fn(|l| chunk[l].1);
            let active = if i % 5 == 0 { 0b1011_0110 } else { 0xff };
            let closest = accel.intersect8(&ray, t_max, active);
            for l in 0..LANES {
                let on = active >> l & 1 != 0;
                let want = accel.intersect(&ray[l], t_max[l]).filter(|_| on);
                assert_eq!(closest[l], want, "{:?}", ray[l]);
                hits += want.is_some() as u32;
                ties += want.is_some_and(|h| h.prim as usize >= boxes) as u32;
            }
        }
        assert!(hits > 20_000, "{hits} hits: too few to test");
        assert!(ties > 2_000, "{ties} of {hits} hits met the sphere and its copy: too few to test");
    }
}
