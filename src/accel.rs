//! The BVH over all scene triangles: closest hit and occlusion.
//!
//! Structure: a compressed 8-wide BVH (Ylitie, Karras & Laine 2017, "Efficient
//! Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs") in obvhs's
//! node format, built top-down by binned SAH (`wide_bvh`). Traversal is
//! our own loop after the paper's algorithm 1 (`Accel::traverse`), with our
//! own node and primitive tests:
//!
//! - Primitive: the watertight ray/triangle test of Woop, Benthin & Wald 2013,
//!   "Watertight Ray/Triangle Intersection" (JCGT 2(1)), with its
//!   double-precision fallback (`lanes::watertight`), on four triangles at
//!   once (one per SIMD lane, `TriangleBlock`). A ray through a shared edge
//!   or vertex hits at least one of the triangles that share it, whatever
//!   the rounding. A hit is taken when its t is certainly positive: beyond
//!   t's error bound (pbrt-v4's), or, within it, by the sign of the plane
//!   distance in f64 with a bound of its own (`lanes::near_t_in_f64`), so
//!   a ray leaving an object just above a large floor still meets it.
//! - Near an edge: a hit within rounding of its triangle's edge
//!   (`Scene::interaction` finds it) is traced again in f64
//!   (`Accel::intersect_exact`), where the f32 test can meet a ray that
//!   passes a convex edge on the face it would leave by.
//! - Packets: eight coherent rays at once (`packet.rs`, `intersect8`), each
//!   lane finding what its ray finds alone.
//! - Node: obvhs's own child-box test clamps t_near to an absolute 1e-4 (culling
//!   every hit closer than that: a real loss in a millimetre-scale scene) and
//!   has no allowance for rounding, so a ray grazing a box face or edge (an
//!   axis-aligned wall, a cube edge) can drop the box that holds the triangle
//!   the primitive test would have hit. Ours widens every slab interval by a
//!   bound on its rounding error, in the spirit of Ize 2013, "Robust BVH Ray
//!   Traversal" (JCGT 2(2)); see `intersect_node`.
//!
//! Triangles are stored in BVH leaf order (obvhs's `primitive_indices`), four
//! to a block, so a leaf's triangles are contiguous in memory;
//! `primitive_indices` maps a slot back to the input index that
//! `TriangleHit::prim` reports. Degenerate
//! triangles (zero area, non-finite vertices) are left out of the BVH: they can
//! never be hit, and a renderer could not compute their normal anyway.

mod exact;
mod lanes;
mod packet;

pub use packet::LANES;

use crate::geometry::{edge_margin, Ray, NO_TRIANGLE};
use crate::wide_bvh::{self, PrimRef};
use glam::{DVec3, Vec3A, Vec4};
use obvhs::{
    aabb::Aabb,
    cwbvh::{node::CwBvhNode, CwBvh},
};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::ControlFlow;

/// A ray-triangle hit: distance, the triangle's index in the input order, the
/// barycentrics of its second and third vertices, and its vertices (as given
/// to `build`, bit for bit: read from the slot the traversal found, so a hit
/// needs no lookup by input index).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    pub t: f32,
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
    pub v: [Vec3A; 3],
    /// The triangle's BVH slot (for `Ray::skip` of rays leaving it).
    pub slot: u32,
    /// The triangle's `geometry::edge_margin`, computed when it was built.
    pub margin: f32,
    /// A bound on the error of the barycentrics from the f32 test's edge
    /// functions (`lanes::Candidates::edge_error`; 0 from
    /// `intersect_exact`): where one is within it of 0 the test may be
    /// wrong about the ray (`Scene::interaction` then asks
    /// `intersect_exact`).
    pub edge_error: f32,
}

pub struct Accel {
    bvh: CwBvh,
    /// Triangles in BVH slot order, four to a block: slot s is lane s % 4
    /// of block s / 4, input triangle `bvh.primitive_indices[s]`.
    blocks: Vec<TriangleBlock>,
    /// Per slot, how many slots just before and just after it hold
    /// triangles in exactly its plane (at most `MAX_RUN` each way).
    coplanar: Vec<[u8; 2]>,
    /// Input indices of the degenerate triangles, left out (ascending).
    degenerate: Vec<u32>,
    /// Number of input triangles, degenerate ones included.
    input_len: usize,
}

impl Accel {
    pub fn build(tris: &[[Vec3A; 3]]) -> Self {
        Self::build_with(tris.len(), |i| tris[i])
    }

    /// Builds over `len` triangles given by `tri(i)` (called twice per
    /// triangle, from several threads), so a caller with indexed meshes needs
    /// no `[[Vec3A; 3]]` copy of its vertices.
    ///
    /// Memory: the builder's 32-byte boxes are freed before the triangles
    /// are copied in slot order, so the two are never held together.
    pub fn build_with<F>(len: usize, tri: F) -> Self
    where
        F: Fn(usize) -> [Vec3A; 3] + Sync,
    {
        assert!(len <= (u32::MAX - 32) as usize, "{len} triangles: at most 2^32 - 33");
        // Degenerate triangles get an empty box and are dropped in place.
        let mut refs: Vec<PrimRef> = (0..len)
            .into_par_iter()
            .map(|i| {
                let t = tri(i);
                let b = if is_degenerate(&t) {
                    Aabb::empty()
                } else {
                    Aabb::new(t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))
                };
                PrimRef::new(b, i as u32)
            })
            .collect();
        let degenerate = refs.iter().filter(|r| !r.is_valid()).map(PrimRef::index).collect();
        refs.retain(|r| r.is_valid());
        let bvh = wide_bvh::build(refs);
        let blocks: Vec<TriangleBlock> = bvh
            .primitive_indices
            .par_chunks(4)
            .map(|slots| TriangleBlock::new(slots.iter().map(|&i| tri(i as usize))))
            .collect();
        let coplanar = coplanar_runs(&blocks, bvh.primitive_indices.len());
        Self { bvh, blocks, coplanar, degenerate, input_len: len }
    }

    /// The slots a ray leaving (or aimed at) the triangle in `slot` skips:
    /// `slot` and the run of slots around it whose triangles lie exactly in
    /// its plane. `NO_TRIANGLE` gives an empty range.
    pub fn coplanar_run(&self, slot: u32) -> std::ops::Range<u32> {
        match self.skip_run(slot) {
            (u32::MAX, _) => 0..0,
            (first, last) => first..last + 1,
        }
    }

    /// `coplanar_run` as the traversal's (first, last) pair; (MAX, MAX), a
    /// run no group reaches, for `NO_TRIANGLE`.
    #[inline(always)]
    fn skip_run(&self, slot: u32) -> (u32, u32) {
        match self.coplanar.get(slot as usize) {
            Some(&[back, fwd]) => (slot - back as u32, slot + fwd as u32),
            None => (u32::MAX, u32::MAX),
        }
    }

    /// The input index of the triangle in each slot.
    pub fn slot_prims(&self) -> &[u32] {
        &self.bvh.primitive_indices
    }

    /// The input indices of the degenerate triangles, which the BVH leaves
    /// out (ascending).
    pub fn degenerate(&self) -> &[u32] {
        &self.degenerate
    }

    /// The vertices of the triangle in BVH slot `slot` as given to `build`
    /// (bit for bit).
    #[inline]
    pub fn vertices(&self, slot: u32) -> [Vec3A; 3] {
        debug_assert!((slot as usize) < self.bvh.primitive_indices.len(), "slot {slot} is a padding lane");
        self.blocks[slot as usize / 4].vertices(slot as usize % 4)
    }

    /// The `geometry::edge_margin` of the triangle in BVH slot `slot`.
    #[inline]
    pub fn edge_margin(&self, slot: u32) -> f32 {
        self.blocks[slot as usize / 4].margin[slot as usize % 4]
    }

    /// Input index -> BVH slot (what `Ray::skip` and `TriangleHit::slot`
    /// hold), `NO_TRIANGLE` for a degenerate triangle. Made on demand, 4
    /// bytes per triangle, for exporters and tests: rendering needs no
    /// such map (a hit reports both), and keeping one would add to the
    /// memory peak.
    pub fn slot_map(&self) -> Vec<u32> {
        let mut slots = vec![NO_TRIANGLE; self.input_len];
        for (s, &i) in self.bvh.primitive_indices.iter().enumerate() {
            slots[i as usize] = s as u32;
        }
        slots
    }

    /// The slots of a few input triangles (`slot_map` for just these: one
    /// pass over the slots, memory in proportion to `prims`).
    pub fn slots_of(&self, prims: &[u32]) -> Vec<u32> {
        let mut order: Vec<(u32, usize)> = prims.iter().copied().zip(0..).collect();
        order.sort_unstable();
        let mut slots = vec![NO_TRIANGLE; prims.len()];
        if !order.is_empty() {
            for (s, &i) in self.bvh.primitive_indices.iter().enumerate() {
                let first = order.partition_point(|&(p, _)| p < i);
                for &(_, k) in order[first..].iter().take_while(|&&(p, _)| p == i) {
                    slots[k] = s as u32;
                }
            }
        }
        slots
    }

    /// Heap bytes held (nodes, triangles, index maps), for memory reports.
    pub fn heap_bytes(&self) -> usize {
        use std::mem::size_of;
        self.bvh.nodes.capacity() * size_of::<CwBvhNode>()
            + self.bvh.primitive_indices.capacity() * 4
            + self.blocks.capacity() * size_of::<TriangleBlock>()
            + self.coplanar.capacity() * 2
            + self.degenerate.capacity() * 4
    }

    /// Number of input triangles (degenerate ones included, though they are
    /// never hit).
    pub fn len(&self) -> usize {
        self.input_len
    }

    pub fn is_empty(&self) -> bool {
        self.input_len == 0
    }

    /// Scene bounds (min, max) over the non-degenerate triangles; a zero box
    /// at the origin for an empty scene, so derived radii stay finite.
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        if self.blocks.is_empty() {
            (Vec3A::ZERO, Vec3A::ZERO)
        } else {
            (self.bvh.total_aabb.min, self.bvh.total_aabb.max)
        }
    }

    /// Closest hit with t in (0, t_max), not testing the triangles of
    /// `ray.skip` and their coplanar runs.
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<TriangleHit> {
        self.closest::<false>(ray, t_max)
    }

    /// `intersect` with every triangle of the visited leaves tested in f64
    /// (`lanes::hit_in_f64`), and the closest hit by its distance in f64:
    /// for a ray whose f32 hit lies within rounding of an edge
    /// (`Scene::interaction`). Near a convex edge of a closed surface, the
    /// f32 test can find both faces for a ray that passes just outside the
    /// edge (in the shear's rounding; they share the edge's sign, so both
    /// or neither), and order the two faces of one that clips the corner
    /// either way (their distances a few 1e-9 apart): either way a path
    /// went on from the inside face of the shell, and light inside a
    /// closed cube reached camera paths (2 of 150 renders of
    /// `a_closed_shell_keeps_its_light_in`'s cube under `path`, session
    /// 47). In f64 the side of each edge is exact (where rounding could
    /// decide it, by `exact::triple_product`); the order errs by ~1e-16 of
    /// the distances' terms. Slow (per triangle, not per block), and rare.
    #[cold]
    #[inline(never)]
    pub fn intersect_exact(&self, ray: &Ray, t_max: f32) -> Option<TriangleHit> {
        self.closest::<true>(ray, t_max)
    }

    /// The closest hit, by the f32 test or with `EXACT` in f64 (whose hits
    /// carry `edge_error` 0).
    #[inline(always)]
    fn closest<const EXACT: bool>(&self, ray: &Ray, t_max: f32) -> Option<TriangleHit> {
        let pre = PreparedRay::new(ray)?;
        let mut t = t_max;
        let skip = ray.skip.map(|slot| self.skip_run(slot));
        let (slot, b1, b2, edge_error) = self.traverse::<false, EXACT>(&pre, skip, &mut t)?;
        Some(self.hit(t, slot, b1, b2, edge_error))
    }

    #[inline(always)]
    fn hit(&self, t: f32, slot: u32, b1: f32, b2: f32, edge_error: f32) -> TriangleHit {
        TriangleHit {
            t,
            prim: self.bvh.primitive_indices[slot as usize],
            b1,
            b2,
            v: self.vertices(slot),
            slot,
            margin: self.edge_margin(slot),
            edge_error,
        }
    }

    /// Whether anything but the triangles of `ray.skip` and their coplanar
    /// runs blocks the ray in (0, t_max); stops at the first hit. Out of
    /// line: inlined with `Scene::unoccluded` into `Bdpt::sample`'s
    /// connections, it cost `bdpt` 11 % more instructions
    /// (docs/performance-log.md, "Session 16").
    #[inline(never)]
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        let Some(pre) = PreparedRay::new(ray) else {
            return false;
        };
        let (skip, mut t_max) = (ray.skip.map(|slot| self.skip_run(slot)), t_max);
        self.traverse::<true, false>(&pre, skip, &mut t_max).is_some()
    }

    /// Calls `visit` with the slot of every triangle whose bounds overlap
    /// `query` (touching counts), and of some near it. None is missed,
    /// though a quantized child box may fall half a unit in the last place
    /// short of its triangles (wide_bvh/node.rs): obvhs's `intersect_aabb`
    /// maps the query to the node's grid with the very operations the
    /// builder used, fl(x - p) times a power of two, and rounding keeps
    /// order, so a triangle bound below the query's max maps below it too
    /// (and likewise for the min). A builder that quantized otherwise (in
    /// f64, say) would have to pad this query. The walk stops when `visit`
    /// breaks. For scene checks that compare neighbouring triangles
    /// (`Scene::emitters_on_surfaces`), not for rendering.
    pub fn overlapping(&self, query: (Vec3A, Vec3A), mut visit: impl FnMut(u32) -> ControlFlow<()>) {
        let query = Aabb::new(query.0, query.1);
        let mut stack = if self.bvh.nodes.is_empty() { Vec::new() } else { vec![0u32] };
        while let Some(i) = stack.pop() {
            let node = &self.bvh.nodes[i as usize];
            // Octant 0: inner children's bits are 24 + their slot, and
            // their nodes follow `child_base_idx` in slot order.
            let hits = node.intersect_aabb(&query, 0);
            for slot in (0..8).filter(|s| hits & 1 << (24 + s) != 0) {
                stack.push(node.child_base_idx + (node.imask as u32 & ((1 << slot) - 1)).count_ones());
            }
            let mut tris = hits & 0x00ff_ffff;
            while tris != 0 {
                if visit(node.primitive_base_idx + tris.trailing_zeros()).is_break() {
                    return;
                }
                tris &= tris - 1;
            }
        }
    }

    /// Ylitie, Karras & Laine 2017, algorithm 1, on the CPU: visits the
    /// nodes whose boxes the ray enters before `t_max`, inner children in
    /// the order of the ray's octant, and tests the triangle slots of a
    /// visited node's hit leaves as a group (base slot, mask), each hit
    /// shortening `t_max`. Returns the closest hit (slot, b1, b2), or with
    /// `ANY_HIT` the first one found. A group is a base index and a hit
    /// mask: for nodes, inner children's bits (top byte, by traversal
    /// priority) over the node's `imask`; for triangles, one bit per slot.
    /// The slot runs in `skip` are cleared from the triangle masks (no
    /// branch per triangle, whose outcome the CPU could not predict).
    ///
    /// No closure: the whole loop, the triangle test included, is inlined
    /// into each caller (a closure for the leaves was compiled out of line
    /// once `Scene::intersect` was inlined into several integrators, a call
    /// per visited group).
    #[inline(always)]
    fn traverse<const ANY_HIT: bool, const EXACT: bool>(
        &self,
        r: &PreparedRay,
        skip: [(u32, u32); 2],
        t_max: &mut f32,
    ) -> Option<(u32, f32, f32, f32)> {
        let mut best = None;
        if self.bvh.nodes.is_empty() {
            return best;
        }
        // Any hit will do for occlusion, whatever the order in which the
        // children are visited: storage order (octant 0) spares the
        // per-node reordering and the ray's octant.
        let oct_inv4 = if ANY_HIT { 0 } else { r.oct_inv4 };
        let mut stack = GroupStack::new();
        // With `EXACT`, the best hit's distance in f64, its error bound and
        // its triangle (`intersect_exact`).
        let (mut best_t64, mut best_err, mut best_tri) = (*t_max as f64, 0.0, [Vec3A::ZERO; 3]);
        // Without `EXACT`, the best hit's distance and slot. (Any hit will
        // do for occlusion: no tie to settle, so no reach past t_max.)
        let mut closest = if ANY_HIT { Closest::before(*t_max) } else { Closest::new(*t_max) };
        // The root as the only inner child of a virtual parent.
        let mut nodes = (0u32, 0x8000_0000u32);
        loop {
            let mut tris = (0u32, 0u32);
            if nodes.1 & 0xff00_0000 != 0 {
                let hits = nodes.1;
                let bit = 31 - hits.leading_zeros();
                nodes.1 &= !(1 << bit);
                if nodes.1 & 0xff00_0000 != 0 {
                    stack.push(nodes);
                }
                let slot = (bit - 24) ^ (oct_inv4 & 0xff);
                let child = nodes.0 + (hits & !(u32::MAX << slot)).count_ones();
                let node = &self.bvh.nodes[child as usize];
                // (f32 rounding of an f64 distance, and a box test with a
                // slack, admit the hits at t_max; `EXACT_REACH` more is to spare.)
                let reach = if EXACT { *t_max * (1.0 + EXACT_REACH) } else { closest.reach };
                let hit_mask = intersect_node(node, r, reach, oct_inv4);
                nodes = (node.child_base_idx, (hit_mask & 0xff00_0000) | node.imask as u32);
                let base = node.primitive_base_idx;
                tris = (base, hit_mask & 0x00ff_ffff & !(group_bits(skip[0], base) | group_bits(skip[1], base)));
            }
            if tris.1 != 0 {
                for (block, lanes) in blocks(tris.0, tris.1) {
                    if EXACT {
                        for lane in (0..4).filter(|l| lanes >> l & 1 != 0) {
                            let tri = self.blocks[block as usize].vertices(lane as usize);
                            let Some(h) = lanes::hit_in_f64(r.o, r.d, &tri) else { continue };
                            // At one distance within the error (a ray
                            // through an edge), the face it enters by wins,
                            // and where neither does (coincident copies, a
                            // concave edge) the least slot, as in
                            // `Closest::takes` (a review, session 55: the
                            // face met first won, so along every edge of a
                            // duplicated surface a hairline took the other
                            // copy); a first hit only has to lie before t_max.
                            let slot = 4 * block + lane;
                            let takes = match best {
                                Some((best_slot, ..)) if (h.t - best_t64).abs() <= h.err + best_err => {
                                    lanes::enters_by(&tri, &best_tri, r.d)
                                        || (slot < best_slot && !lanes::enters_by(&best_tri, &tri, r.d))
                                }
                                _ => h.t < best_t64,
                            };
                            if takes {
                                (best_t64, best_err, best_tri, *t_max) = (h.t, h.err, tri, h.t as f32);
                                best = Some((slot, h.b1, h.b2, 0.0));
                            }
                        }
                        continue;
                    }
                    if let Some(hit) = r.intersect_block(&self.blocks[block as usize], 4 * block, lanes, &mut closest) {
                        best = Some(hit);
                        if ANY_HIT {
                            return best;
                        }
                    }
                }
            }
            if nodes.1 & 0xff00_0000 == 0 {
                match stack.pop() {
                    Some(g) => nodes = g,
                    None => {
                        if !EXACT {
                            *t_max = closest.t;
                        }
                        return best;
                    }
                }
            }
        }
    }
}

/// The triangle-mask bits of the slots first..=last in a group based at
/// `base` (none for (MAX, MAX): slots stay below 2^32 - 32).
#[inline(always)]
fn group_bits((first, last): (u32, u32), base: u32) -> u32 {
    let lo = first.saturating_sub(base).min(32);
    let hi = last.saturating_add(1).saturating_sub(base).min(32);
    (((1u64 << hi) - 1) & !((1u64 << lo) - 1)) as u32
}

/// Longest coplanar run kept each way from a slot: a node's triangles are
/// at most 24 consecutive slots, so a longer run skips nothing more.
const MAX_RUN: u8 = 23;

/// Per slot, (back, fwd): how many of the slots just before and just after
/// it hold triangles exactly in its plane, up to `MAX_RUN`. Neighbours are
/// compared with exact orientation predicates (Shewchuk 1997, "Adaptive
/// Precision Floating-Point Arithmetic and Fast Robust Geometric
/// Predicates", `robust::orient3d`, exact for f32 inputs): all three
/// vertices of one on the other's plane. Non-degenerate triangles have one
/// plane each, so coplanarity of neighbours carries along a run.
fn coplanar_runs(blocks: &[TriangleBlock], len: usize) -> Vec<[u8; 2]> {
    let tri = |s: usize| blocks[s / 4].vertices(s % 4);
    let joined: Vec<bool> = (1..len).into_par_iter().map(|s| coplanar(&tri(s - 1), &tri(s))).collect();
    let mut runs = vec![[0u8; 2]; len];
    for (s, &j) in joined.iter().enumerate() {
        if j {
            runs[s + 1][0] = (runs[s][0] + 1).min(MAX_RUN);
        }
    }
    for (s, &j) in joined.iter().enumerate().rev() {
        if j {
            runs[s][1] = (runs[s + 1][1] + 1).min(MAX_RUN);
        }
    }
    runs
}

/// Whether all of `other`'s vertices lie exactly in the plane of `own`. A
/// shared vertex does trivially; it is not handed to `orient3d`, whose exact
/// (slow) stage every zero determinant reaches.
fn coplanar(own: &[Vec3A; 3], other: &[Vec3A; 3]) -> bool {
    let c = |v: Vec3A| robust::Coord3D { x: v.x, y: v.y, z: v.z };
    let [a, b, p] = own.map(c);
    other.iter().all(|v| own.contains(v) || robust::orient3d(a, b, p, c(*v)) == 0.0)
}

/// The blocks of four slots that hold the slots of a traversal group (bit
/// i of `mask`: slot `base + i`), as (block, lanes), from the highest slot
/// down (the order in which a loop over the slots would meet them); `lanes`
/// has bit l for slot `4 * block + l`.
#[inline(always)]
fn blocks(base: u32, mask: u32) -> impl Iterator<Item = (u32, u32)> {
    // A group spans at most 24 slots, so the shifted mask fits 27 bits.
    let mut m = (mask as u64) << (base % 4);
    std::iter::from_fn(move || {
        if m == 0 {
            return None;
        }
        let nibble = (63 - m.leading_zeros()) / 4;
        let lanes = (m >> (4 * nibble)) as u32 & 0xf;
        m &= (1u64 << (4 * nibble)) - 1;
        Some((base / 4 + nibble, lanes))
    })
}

/// The traversal stack: node groups still to visit. It holds at most one
/// group per tree level, and wide BVHs are shallow, so 32 entries in place
/// suffice for all but pathological trees, which spill to the heap instead
/// of losing nodes. (Not a `SmallVec`: its checks of where the entries
/// live cost ~40 instructions per ray, 2-3 % of a Cornell box render.)
/// The entries in place start uninitialised: zeroing their 256 bytes took
/// 11 instructions a ray, 0.7 % of `path`'s and 0.85 % of `bdpt`'s
/// (docs/performance-log.md, "Session 46").
///
/// Invariant: `inline[i]` is initialised for every i < min(len, INLINE).
/// `new` starts at len 0; `push` writes `inline[len]` before len grows past
/// it (or spills, at len >= INLINE); `pop` shrinks len, and so the set;
/// nothing else changes `len` or `inline`.
struct GroupStack {
    inline: [MaybeUninit<(u32, u32)>; GroupStack::INLINE],
    len: usize,
    spill: Vec<(u32, u32)>,
}

impl GroupStack {
    const INLINE: usize = 32;

    #[inline(always)]
    fn new() -> Self {
        Self { inline: [const { MaybeUninit::uninit() }; Self::INLINE], len: 0, spill: Vec::new() }
    }

    #[inline(always)]
    fn push(&mut self, group: (u32, u32)) {
        match self.inline.get_mut(self.len) {
            Some(slot) => _ = slot.write(group),
            None => self.spill.push(group),
        }
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<(u32, u32)> {
        self.len = self.len.checked_sub(1)?;
        match self.inline.get(self.len) {
            // SAFETY: `len` has just dropped below its value before this
            // call, so `inline[len]` (< INLINE here) is below the old
            // min(len, INLINE) and initialised by the struct's invariant.
            Some(group) => Some(unsafe { group.assume_init() }),
            None => self.spill.pop(),
        }
    }
}

/// Whether a triangle can never be hit: a non-finite vertex, or zero area
/// (its cross product is zero in double precision or underflows in single
/// precision, where a renderer's normalize() would produce NaN).
pub fn is_degenerate(tri: &[Vec3A; 3]) -> bool {
    if !(tri[0].is_finite() && tri[1].is_finite() && tri[2].is_finite()) {
        return true;
    }
    let n32 = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
    let l2 = n32.length_squared();
    if !(l2.is_finite() && l2 > 0.0) {
        return true;
    }
    let [a, b, c] = tri.map(|v| v.as_dvec3());
    (b - a).cross(c - a) == DVec3::ZERO
}

/// One watertight ray/triangle test (Woop et al. 2013) without a BVH: the
/// reference the BVH is tested against. Returns (t, b1, b2) for t in
/// (0, t_max); never hits a degenerate triangle.
pub fn intersect_triangle(ray: &Ray, tri: &[Vec3A; 3], t_max: f32) -> Option<(f32, f32, f32)> {
    if is_degenerate(tri) {
        return None;
    }
    let mut closest = Closest::new(t_max);
    let (_, b1, b2, _) =
        PreparedRay::new(ray)?.intersect_block(&TriangleBlock::new([*tri].into_iter()), 0, 1, &mut closest)?;
    Some((closest.t, b1, b2))
}

/// The closest hit so far of a traversal in f32: its distance `t` and
/// `slot` (at first t_max and none), and the `reach` of the range tests of
/// triangles and nodes, t (1 + 2^-21).
///
/// A hit is taken if it is closer, or as close and in a lower slot: the
/// least (t, slot) wins, whatever the order in which the traversal meets
/// the hits, so a ray finds the same triangle alone and in a packet, whose
/// order follows another lane's octant (`packet.rs`). At an exact tie (two
/// coincident triangles: a duplicated face, a decal) the lone ray took the
/// last of a block's tied triangles and the packet the first, so a pixel's
/// colour hung on whether its samples went in packets, which hangs on where
/// a render's sample range starts (a part, a resume; from an audit,
/// session 50).
///
/// The reach lets every hit as close as the best pass the range test
/// `ts < reach |det|` (`lanes::watertight`): t is fl(ts fl(1 / |det|)),
/// two roundings of ts / |det|, so ts / |det| <= t (1 + u)^2 (u = 2^-24),
/// and fl(reach |det|) >= t (1 + 8u)(1 - u)^2 |det|, which is above
/// t (1 + u)^2 |det| and so above ts, for every hit whose t is at most the
/// best's (normal floats; a reach of infinity passes all). Tested against
/// the best t itself, a tie passed or not by the luck of rounding, and so
/// by the order.
///
/// Two cases are left to the order, both rare. Nodes are entered within
/// the same reach, so a tie in another leaf is met unless the f32
/// distances err by more than 2^-21 of themselves (a ray grazing the
/// triangles). And a hit within rounding of the ray's origin
/// (`Candidates::near`) passes the range test on its f32 distance but
/// ranks by its f64 one, so of two such hits (a ray leaving a corner
/// within rounding of both faces) the order can decide.
#[derive(Clone, Copy)]
pub(crate) struct Closest {
    pub t: f32,
    slot: u32,
    pub reach: f32,
}

/// 1 + 2^-21: `Closest::reach` over t.
const TIE_REACH: f32 = 1.0 + 1.0 / (1u32 << 21) as f32;

impl Closest {
    #[inline(always)]
    pub fn new(t_max: f32) -> Self {
        // (Slot 0 takes no tie with t_max: no slot is below it.)
        Self { t: t_max, slot: 0, reach: t_max * TIE_REACH }
    }

    /// `new`'s, for a search that stops at the first hit: no reach past
    /// t_max, as no tie is settled.
    #[inline(always)]
    pub fn before(t_max: f32) -> Self {
        Self { t: t_max, slot: 0, reach: t_max }
    }

    /// Whether the hit (t, slot) is the closest so far; if so it becomes it.
    #[inline(always)]
    pub fn takes(&mut self, t: f32, slot: u32) -> bool {
        let closer = t < self.t || (t == self.t && slot < self.slot);
        if closer {
            *self = Self { t, slot, reach: t * TIE_REACH };
        }
        closer
    }
}

/// The margin, as a fraction of t_max, by which an exact traversal
/// (`Accel::intersect_exact`) enters boxes beyond its best hit.
const EXACT_REACH: f32 = 1.0 / 65536.0;

/// Four triangles of consecutive BVH slots, stored by coordinate, one per
/// SIMD lane: `c[3 k + j]` holds coordinate k (x, y, z) of vertex j of each.
/// The watertight test permutes the axes per ray (kx, ky, kz); in this
/// layout that is a choice of rows, and it runs on four triangles at once
/// (`PreparedRay::intersect_block`): whether a block holds a candidate is
/// one branch, where one per triangle would follow the geometry, which the
/// CPU cannot predict (the few candidates are then taken lane by lane).
/// With each triangle's `edge_margin`, which a hit hands on
/// (`Scene::interaction`), 160 bytes, 40 per triangle; the lanes past the
/// last triangle are zero, computed on but masked out by every traversal
/// group.
#[derive(Clone, Copy, Debug)]
#[repr(align(16))]
struct TriangleBlock {
    c: [[f32; 4]; 9],
    margin: [f32; 4],
}

impl TriangleBlock {
    /// Up to four triangles, in lane order.
    fn new(tris: impl Iterator<Item = [Vec3A; 3]>) -> Self {
        let (mut c, mut margin) = ([[0.0f32; 4]; 9], [0.0f32; 4]);
        for (lane, t) in tris.enumerate() {
            for (i, row) in c.iter_mut().enumerate() {
                row[lane] = t[i % 3][i / 3];
            }
            margin[lane] = edge_margin(&t);
        }
        Self { c, margin }
    }

    /// Coordinate k of vertex j of the four triangles.
    #[inline(always)]
    fn row(&self, k: usize, j: usize) -> Vec4 {
        Vec4::from_array(self.c[3 * k + j])
    }

    /// The vertices of the triangle in `lane`, bit for bit as given.
    #[inline(always)]
    fn vertices(&self, lane: usize) -> [Vec3A; 3] {
        // (Written out: in session 22's replay of a render's rays, a program
        // calling prism as a library, `[0, 1, 2].map` here was compiled out
        // of line, a call per fetch that made its packets 1.8x and its
        // closest hits 1.25x slower than the render's own code; see
        // docs/performance-log.md, "Session 23".)
        let vertex = |j: usize| Vec3A::new(self.c[j][lane], self.c[3 + j][lane], self.c[6 + j][lane]);
        [vertex(0), vertex(1), vertex(2)]
    }
}

/// The watertight test's axis orders (kx, ky, kz, 3) by 2 kz + [d[kz] < 0]:
/// kz the dominant axis, (kx, ky) the next two cyclically, swapped for a
/// negative d[kz] so the projected winding is kept (Woop et al. 2013, fig. 2).
/// The fourth entry keeps the padding lane in place.
const AXIS_ORDERS: [[u32; 4]; 6] = [[1, 2, 0, 3], [2, 1, 0, 3], [2, 0, 1, 3], [0, 2, 1, 3], [0, 1, 2, 3], [1, 0, 2, 3]];

/// (v[k[0]], v[k[1]], v[k[2]]): one variable shuffle with AVX.
#[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
#[inline(always)]
fn permute(v: Vec3A, k: &[u32; 4]) -> Vec3A {
    use std::arch::x86_64::*;
    // SAFETY: compiled only when the build enables AVX (x86-64-v3, see
    // .cargo/config.toml), so every CPU that runs it has AVX; the load reads
    // the 16 bytes of `k`, a valid, initialised [u32; 4] (unaligned load).
    unsafe { Vec3A::from(_mm_permutevar_ps(v.into(), _mm_loadu_si128(k.as_ptr().cast()))) }
}

#[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
#[inline(always)]
fn permute(v: Vec3A, k: &[u32; 4]) -> Vec3A {
    Vec3A::new(v[k[0] as usize], v[k[1] as usize], v[k[2] as usize])
}

/// Per-ray constants of the watertight test (Woop et al. 2013, sec. 3) and of
/// the node test.
struct PreparedRay {
    o: Vec3A,
    d: Vec3A,
    /// The axis permutation: kz the dominant axis of d, (kx, ky) the others,
    /// swapped if d[kz] < 0 so the projected winding (sign of det) is kept.
    k: [usize; 3],
    /// o permuted: (o[kx], o[ky], o[kz]).
    o_k: Vec3A,
    /// Shear constants Sx = d[kx] / d[kz], Sy = d[ky] / d[kz], Sz = 1 / d[kz]:
    /// in the sheared space the ray is +z through the origin.
    s: Vec3A,
    /// 1/d, with zero components replaced by +-1e-20 so no 0 * inf = NaN can
    /// silently drop a box (a NaN compare is false).
    inv: Vec3A,
    abs_inv: Vec3A,
    /// obvhs's `oct_inv4`: the ray's octant as a byte, bit 2 for d.x >= 0,
    /// bit 1 for d.y, bit 0 for d.z (after the zero replacement above), in
    /// each of the four bytes. Inner children's traversal order follows it.
    oct_inv4: u32,
}

impl PreparedRay {
    #[inline(always)]
    fn new(ray: &Ray) -> Option<Self> {
        let d = ray.d;
        // Both finite in one test: x - x is 0 exactly when x is finite
        // (inf - inf and NaN give NaN), which is the point of the lint's
        // "equal operands".
        #[allow(clippy::eq_op)]
        let finite = ((ray.o - ray.o) + (d - d)).cmpeq(Vec3A::ZERO).all();
        if !(finite && d.length_squared() > 0.0) {
            return None;
        }
        // kz: the first axis of largest |d|; (kx, ky) the next two
        // cyclically, swapped when d[kz] < 0. Which of the six it is
        // depends on a random direction, so it is looked up, not branched on.
        let ad = d.abs();
        let kz = ad.cmpeq(Vec3A::splat(ad.max_element())).bitmask().trailing_zeros();
        let k = AXIS_ORDERS[(2 * kz + ((d.is_negative_bitmask() >> kz) & 1)) as usize];
        let (d_k, o_k) = (permute(d, &k), permute(ray.o, &k));
        let k = [k[0], k[1], k[2]].map(|i| i as usize);
        let sz = 1.0 / d_k.z;
        let dc = d.abs().max(Vec3A::splat(1e-20)).copysign(d);
        let inv = Vec3A::ONE / dc;
        // The non-negative axes as bits (x, y, z), reversed to (z, y, x).
        const REVERSED: [u32; 8] = [0, 4, 2, 6, 1, 5, 3, 7];
        let octant = REVERSED[(!inv.is_negative_bitmask() & 7) as usize];
        Some(Self {
            o: ray.o,
            d,
            k,
            o_k,
            s: Vec3A::new(d_k.x * sz, d_k.y * sz, sz),
            inv,
            abs_inv: inv.abs(),
            oct_inv4: octant * 0x0101_0101,
        })
    }

    /// The watertight test (`lanes::watertight`) on the four triangles of a
    /// block at once, one per lane, for the lanes set in `lanes`; the
    /// block's first slot is `first`.
    ///
    /// Each hit that `closest` takes (`Closest::takes`) becomes it; the
    /// last so taken is returned as (slot, b1, b2, edge_error). The lanes
    /// are tested against the reach of the call and the few that pass are
    /// checked again against the reach of the best hit so far, which
    /// accepts the same hits as testing each against it (the reach only
    /// shrinks, and a rounded product reach |det| is monotonic in it). A
    /// lane whose t is within its rounding error of 0 (`Candidates::near`)
    /// passes the same range test and then takes its t from the f64 test,
    /// if that finds it ahead (so a segment shorter than that error, whose
    /// f32 t reaches t_max, still misses what lies within it).
    #[inline(always)]
    fn intersect_block(
        &self,
        block: &TriangleBlock,
        first: u32,
        lanes: u32,
        closest: &mut Closest,
    ) -> Option<(u32, f32, f32, f32)> {
        // (`min` tells the compiler the rows are in bounds.)
        let [kx, ky, kz] = self.k.map(|k| k.min(2));
        let splat = Vec4::splat;
        let (sx, sy, sz) = (splat(self.s.x), splat(self.s.y), self.s.z);
        // Vertex j's coordinates relative to o, then sheared, in every lane.
        // (Written out: `[0, 1, 2].map` left an out-of-line call here.)
        let zj = |j| block.row(kz, j) - splat(self.o_k.z);
        let z = [zj(0), zj(1), zj(2)];
        let sheared = |k, o: f32, s: Vec4, j: usize| (block.row(k, j) - splat(o)) - s * z[j];
        let x = [sheared(kx, self.o_k.x, sx, 0), sheared(kx, self.o_k.x, sx, 1), sheared(kx, self.o_k.x, sx, 2)];
        let y = [sheared(ky, self.o_k.y, sy, 0), sheared(ky, self.o_k.y, sy, 1), sheared(ky, self.o_k.y, sy, 2)];
        let c = lanes::watertight(x, y, z, splat(sz), splat(closest.reach), lanes)?;
        let mut candidates = c.mask | c.near;
        let (mut t, ts, ds) = (c.t.to_array(), c.ts.to_array(), c.ds.to_array());
        let (b1, b2, edge_error) = (c.b1.to_array(), c.b2.to_array(), c.edge_error.to_array());
        let mut hit = None;
        while candidates != 0 {
            let lane = 31 - candidates.leading_zeros();
            candidates &= !(1 << lane);
            let l = lane as usize;
            let sure = c.mask >> lane & 1 != 0;
            let taken = ts[l] < closest.reach * ds[l] && (sure || self.near_hit(block, l, &mut t[l]));
            if taken && closest.takes(t[l], first + lane) {
                hit = Some((first + lane, b1[l], b2[l], edge_error[l]));
            }
        }
        hit
    }

    /// Whether the triangle in `lane` of `block`, which the ray meets
    /// within the rounding error of its t from the origin, is certainly
    /// ahead of it (`lanes::near_t_in_f64`), with `t` set to its distance.
    ///
    /// Rare (a ray meets few triangles that near its origin), so the ray is
    /// read through `black_box`: otherwise LLVM hoists its conversion to
    /// f64 out of the traversal loop to every ray's start, ~12 instructions
    /// a ray (`bdpt` 0.4 %, `path` 0.5 %; docs/performance-log.md, "Session
    /// 46"). An out-of-line call instead cost more, spilling the loop's
    /// vector registers. The hint changes no value.
    #[inline(always)]
    fn near_hit(&self, block: &TriangleBlock, lane: usize, t: &mut f32) -> bool {
        let (o, d) = std::hint::black_box((self.o, self.d));
        lanes::near_t_in_f64(o, d, &block.vertices(lane)).map(|near| *t = near).is_some()
    }
}

/// 2^-20: slab t values below carry at most ~4 roundings of 2^-24 relative to
/// (|p - o| + 256 e) / |d|; the slack is 16x that.
const SLACK: f32 = 1.0 / (1u32 << 20) as f32;

/// Ray vs the (up to) 8 quantized child boxes of a CWBVH node; returns the
/// obvhs hit mask (inner children in the top byte, leaf triangles below).
///
/// The child plane at grid coordinate q is p + q e (p = node origin, e = a
/// power of two per axis), so t = q (e / d) + (p - o) / d, as obvhs computes
/// it. Each term is rounded; their absolute error is below
/// 4 * 2^-24 (|p - o| + 255 e) |1/d|, and the quantization's own rounding of
/// (child_min - p) below 2^-24 * 255 e. Subtracting `slack` from every near
/// plane and adding it to every far plane makes the interval contain the
/// exact one, so the test is conservative: a triangle whose exact box the ray
/// touches is always tested (Ize 2013 argues the same for plain boxes).
/// t_near is clamped at 0 (not obvhs's 1e-4), t_far at the current t_max.
///
/// With AVX2 (the x86-64-v3 build) all 8 children are one register and the
/// hit mask is assembled without a loop (`NodeSlabs::hit_mask8`); otherwise
/// in two halves of 4 (`NodeSlabs::hit_mask4`). Both compute the same
/// products and sums in the same order, so they give the same mask.
#[inline(always)]
fn intersect_node(node: &CwBvhNode, r: &PreparedRay, t_max: f32, oct_inv4: u32) -> u32 {
    let slabs = NodeSlabs::new(node, r);
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    let mask = slabs.hit_mask8(t_max, child_bits8, bit_index8);
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    let mask = slabs.hit_mask4(t_max, child_bits8, bit_index8);
    mask
}

/// One node's child slabs as the ray sees them: per axis, the min and max
/// planes' grid coordinates and the affine map q -> t = q scale + offset,
/// the offsets widened by the slack. Which plane is near follows the sign
/// of d, i.e. of `scale`: the near plane's q scale is the smaller product
/// of the two and the far plane's the larger, so the tests take the min
/// and max of the products (bit for bit the product of the plane a choice
/// by sign would take, without the choice).
struct NodeSlabs<'a> {
    lo: [&'a [u8; 8]; 3],
    hi: [&'a [u8; 8]; 3],
    scale: Vec3A,
    near_off: Vec3A,
    far_off: Vec3A,
}

impl<'a> NodeSlabs<'a> {
    #[inline(always)]
    fn new(node: &'a CwBvhNode, r: &PreparedRay) -> Self {
        let e = node.compute_extent();
        let diff = Vec3A::from(node.p) - r.o;
        let base = diff * r.inv;
        let slack = (diff.abs() + e * 256.0) * r.abs_inv * SLACK;
        Self {
            lo: [&node.child_min_x, &node.child_min_y, &node.child_min_z],
            hi: [&node.child_max_x, &node.child_max_y, &node.child_max_z],
            scale: e * r.inv,
            near_off: base - slack,
            far_off: base + slack,
        }
    }

    /// All 8 children in one AVX2 register. The hit children's mask bits
    /// (`child_bits << bit_index`, per child) are shifted in their lanes,
    /// kept where the slabs overlap and OR-ed together.
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    #[inline(always)]
    fn hit_mask8(&self, t_max: f32, child_bits8: u64, bit_index8: u64) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: this function is compiled only when the build enables AVX2
        // (`cfg(target_feature = "avx2")`, as .cargo/config.toml's
        // x86-64-v3 does), so every CPU that runs the binary has AVX2, AVX and
        // SSE2; none of these intrinsics reads or writes memory.
        unsafe {
            let widen = |b: u64| _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(b as i64));
            let q = |v: &[u8; 8]| _mm256_cvtepi32_ps(widen(u64::from_le_bytes(*v)));
            let (s, n, f) = (self.scale.to_array(), self.near_off.to_array(), self.far_off.to_array());
            // Axis k's near and far t of every child.
            let slab = |k: usize| {
                let scale = _mm256_set1_ps(s[k]);
                let (a, b) = (_mm256_mul_ps(q(self.lo[k]), scale), _mm256_mul_ps(q(self.hi[k]), scale));
                let near = _mm256_add_ps(_mm256_min_ps(a, b), _mm256_set1_ps(n[k]));
                (near, _mm256_add_ps(_mm256_max_ps(a, b), _mm256_set1_ps(f[k])))
            };
            let ((nx, fx), (ny, fy), (nz, fz)) = (slab(0), slab(1), slab(2));
            let t_near = _mm256_max_ps(_mm256_max_ps(_mm256_max_ps(nx, ny), nz), _mm256_setzero_ps());
            let t_far = _mm256_min_ps(_mm256_min_ps(_mm256_min_ps(fx, fy), fz), _mm256_set1_ps(t_max));
            // All ones in the lanes of hit children (false for NaN, as cmple).
            let hit = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far));
            let bits = _mm256_and_si256(_mm256_sllv_epi32(widen(child_bits8), widen(bit_index8)), hit);
            let v = _mm_or_si128(_mm256_castsi256_si128(bits), _mm256_extracti128_si256::<1>(bits));
            let v = _mm_or_si128(v, _mm_shuffle_epi32::<0b01_00_11_10>(v));
            let v = _mm_or_si128(v, _mm_shuffle_epi32::<0b10_11_00_01>(v));
            _mm_cvtsi128_si32(v) as u32
        }
    }

    /// Children 0-3 and 4-7 in two 4-lane halves, one loop step per hit
    /// child.
    #[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "avx2"))))]
    #[inline(always)]
    fn hit_mask4(&self, t_max: f32, child_bits8: u64, bit_index8: u64) -> u32 {
        let (lo, hi) = (self.lo.map(decode8), self.hi.map(decode8));
        let (s, n, f) = (self.scale.to_array(), self.near_off.to_array(), self.far_off.to_array());
        let mut hit_mask = 0u32;
        for i in 0..2 {
            // Axis k's near and far t of children 4 i .. 4 i + 3.
            let slab = |k: usize| {
                let (a, b) = (lo[k][i] * s[k], hi[k][i] * s[k]);
                (a.min(b) + Vec4::splat(n[k]), a.max(b) + Vec4::splat(f[k]))
            };
            let ((nx, fx), (ny, fy), (nz, fz)) = (slab(0), slab(1), slab(2));
            let t_near = nx.max(ny).max(nz).max(Vec4::ZERO);
            let t_far = fx.min(fy).min(fz).min(Vec4::splat(t_max));
            let mut mask = t_near.cmple(t_far).bitmask();
            while mask != 0 {
                let child = i * 4 + mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let child_bits = ((child_bits8 >> (child * 8)) as u32) & 0xff;
                let bit_index = ((bit_index8 >> (child * 8)) as u32) & 0xff;
                hit_mask |= child_bits << bit_index;
            }
        }
        hit_mask
    }
}

/// The 8 quantized child coordinates of one node axis as floats, children
/// 0-3 and 4-7. On x86-64 two SSE2 unpacks widen the bytes to 32-bit
/// integers for one conversion per 4 lanes (48 scalar conversions per node
/// otherwise, the traversal's hottest line).
#[cfg(all(target_arch = "x86_64", any(test, not(target_feature = "avx2"))))]
#[inline(always)]
fn decode8(v: &[u8; 8]) -> [Vec4; 2] {
    use std::arch::x86_64::*;
    // SAFETY: these intrinsics only need SSE2, which every x86-64 CPU has
    // (it is part of the x86-64 baseline target); none touches memory.
    unsafe {
        let zero = _mm_setzero_si128();
        let bytes = _mm_cvtsi64_si128(i64::from_le_bytes(*v));
        let words = _mm_unpacklo_epi8(bytes, zero);
        let lo = _mm_cvtepi32_ps(_mm_unpacklo_epi16(words, zero));
        let hi = _mm_cvtepi32_ps(_mm_unpackhi_epi16(words, zero));
        [Vec4::from(lo), Vec4::from(hi)]
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn decode8(v: &[u8; 8]) -> [Vec4; 2] {
    let f = v.map(f32::from);
    [Vec4::from_slice(&f[..4]), Vec4::from_slice(&f[4..])]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `group_bits` against its definition, bit by bit: slot base + i of a
    /// group's 24 triangle bits is set iff first <= base + i <= last; runs
    /// before, across, inside and after the group, and the empty run.
    #[test]
    fn group_bits_marks_exactly_the_runs_slots() {
        let runs = (0..80u32).flat_map(|first| (first..first + 47).map(move |last| (first, last)));
        for (first, last) in runs.chain([(u32::MAX, u32::MAX)]) {
            for base in (0..80).step_by(4) {
                let want = (0..24).filter(|i| (first..=last).contains(&(base + i))).fold(0, |m, i| m | 1 << i);
                assert_eq!(group_bits((first, last), base) & 0x00ff_ffff, want, "run {first}..={last}, base {base}");
            }
        }
    }

    fn quad() -> Vec<[Vec3A; 3]> {
        let c = [
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.0, 0.0),
            Vec3A::new(1.0, 1.0, 0.0),
            Vec3A::new(0.0, 1.0, 0.0),
        ];
        vec![[c[0], c[1], c[2]], [c[0], c[2], c[3]]]
    }

    /// A ray with a non-finite origin or direction, or a zero direction,
    /// hits nothing (`PreparedRay::new` refuses it). Without that check a
    /// NaN direction would index past the axis-order table and panic.
    #[test]
    fn rays_that_are_not_finite_hit_nothing() {
        let accel = Accel::build(&quad());
        let (o, d) = (Vec3A::new(0.5, 0.5, 1.0), -Vec3A::Z);
        assert!(accel.intersect(&Ray::new(o, d), f32::INFINITY).is_some(), "the control ray must hit");
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for lane in 0..3 {
                let mut v = Vec3A::ZERO;
                v[lane] = bad;
                for ray in [Ray::new(o + v, d), Ray::new(o, d + v)] {
                    assert!(accel.intersect(&ray, f32::INFINITY).is_none(), "{ray:?}");
                    assert!(!accel.occluded(&ray, f32::INFINITY), "{ray:?}");
                }
            }
        }
        let zero = Ray::new(o, Vec3A::ZERO);
        assert!(accel.intersect(&zero, f32::INFINITY).is_none() && !accel.occluded(&zero, f32::INFINITY));
    }

    #[test]
    fn decode8_converts_every_byte_exactly() {
        for base in (0..=255u8).step_by(8) {
            let v: [u8; 8] = std::array::from_fn(|i| base + i as u8);
            let [lo, hi] = decode8(&v);
            let want = v.map(f32::from);
            assert_eq!((lo.to_array(), hi.to_array()), (want[..4].try_into().unwrap(), want[4..].try_into().unwrap()));
        }
        let v = [255, 0, 128, 1, 7, 200, 0, 255];
        let [lo, hi] = decode8(&v);
        assert_eq!([lo.to_array(), hi.to_array()].concat(), v.map(f32::from));
    }

    /// Uniform numbers in [0, 1) from a xorshift generator.
    pub(super) fn uniform(mut seed: u64) -> impl FnMut() -> f32 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// 3000 small random triangles in a 10-unit cube.
    fn random_triangles(f: &mut impl FnMut() -> f32) -> Vec<[Vec3A; 3]> {
        (0..3000)
            .map(|_| {
                let c = Vec3A::new(f(), f(), f()) * 10.0;
                [c, c + Vec3A::new(f(), f(), f()), c + Vec3A::new(f(), f(), f())]
            })
            .collect()
    }

    /// The 8-lane node test computes the same mask as the 4-lane one, for
    /// every node of a random scene's tree and rays of all octants, with
    /// t_max cutting some children off.
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    #[test]
    fn node_test_8_lanes_matches_4_lanes() {
        let mut f = uniform(0x2545_f491_4f6c_dd1d);
        let a = Accel::build(&random_triangles(&mut f));
        assert!(a.bvh.nodes.len() > 100);
        let (mut hits, mut misses) = (0, 0);
        for i in 0..20_000 {
            // Aimed at a point of the node's box, so most rays meet children.
            let node = &a.bvh.nodes[i % a.bvh.nodes.len()];
            let b = node.aabb();
            let o = Vec3A::new(f(), f(), f()) * 14.0 - 2.0;
            let d = b.min + (b.max - b.min) * Vec3A::new(f(), f(), f()) - o;
            let r = PreparedRay::new(&Ray::new(o, d)).unwrap();
            let oct_inv4 = r.oct_inv4;
            let t_max = if i % 3 == 0 { f32::INFINITY } else { f() * 1.5 };
            let slabs = NodeSlabs::new(node, &r);
            let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
            let m8 = slabs.hit_mask8(t_max, child_bits8, bit_index8);
            assert_eq!(m8, slabs.hit_mask4(t_max, child_bits8, bit_index8), "ray {i}");
            if m8 == 0 {
                misses += 1;
            } else {
                hits += 1;
            }
        }
        assert!(hits > 1000 && misses > 1000, "{hits} hits, {misses} misses");
    }

    /// `overlapping` visits each slot at most once and every slot whose
    /// triangle's bounds meet the query box, including boxes that only
    /// touch one (a corner of a triangle's bounds as the query), and far
    /// fewer than all for small boxes (it is a query, not a scan). Two
    /// scenes: random triangles, and flat ones in the axis-aligned planes
    /// y = 2.5 and (one unit in the last place above) y = 2.5+, whose nodes
    /// have zero extent in y and the finest grid step: the coplanar check's
    /// case. (Taking the inner children in the wrong order, octant 3, fails
    /// it.)
    #[test]
    fn overlapping_finds_every_triangle_whose_box_meets_the_query() {
        let mut f = uniform(0x6a09_e667_f3bc_c908);
        let plane = |i: usize| if i % 5 == 0 { 2.5f32.next_up() } else { 2.5 };
        let flat: Vec<[Vec3A; 3]> = (0..3000)
            .map(|i| {
                let c = Vec3A::new(f() * 10.0, plane(i), f() * 10.0);
                [c, c + Vec3A::new(f(), 0.0, f()), c + Vec3A::new(f(), 0.0, f())]
            })
            .collect();
        for (scene, tris) in [("random", random_triangles(&mut f)), ("flat", flat)] {
            let a = Accel::build(&tris);
            let n = a.slot_prims().len();
            let bounds = |s: u32| {
                let v = a.vertices(s);
                (v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]))
            };
            let mut visited_total = 0;
            for i in 0..600 {
                let query = if i % 3 == 0 {
                    let corner = bounds((i * 7 % n) as u32).1;
                    (corner, corner)
                } else {
                    let lo = Vec3A::new(f(), f(), f()) * 11.0 - 0.5;
                    let mut q = (lo, lo + Vec3A::new(f(), f(), f()) * if i % 3 == 1 { 0.3 } else { 4.0 });
                    if scene == "flat" {
                        (q.0.y, q.1.y) = (plane(i), plane(i));
                    }
                    q
                };
                let mut seen = vec![0u32; n];
                a.overlapping(query, |s| {
                    seen[s as usize] += 1;
                    ControlFlow::Continue(())
                });
                assert!(seen.iter().all(|&c| c <= 1), "{scene}, query {i}: a slot visited twice");
                for s in 0..n as u32 {
                    let (lo, hi) = bounds(s);
                    let meets = lo.cmple(query.1).all() && hi.cmpge(query.0).all();
                    assert!(!meets || seen[s as usize] == 1, "{scene}, query {i} {query:?}: slot {s} missed");
                }
                visited_total += seen.iter().sum::<u32>() as usize;
            }
            assert!(visited_total < 600 * n / 10, "{scene}: {visited_total} visits: the query scans");
        }
    }

    /// For each of the 8 octants, also with +0 components (which the zero
    /// replacement makes +1e-20, so they count as positive): obvhs's
    /// `oct_inv4` byte has bit 2 for
    /// d.x >= 0, bit 1 for d.y and bit 0 for d.z, in all four bytes (its
    /// `CwBvhNode::intersect_ray` convention).
    #[test]
    fn octant_byte_follows_the_signs() {
        for octant in 0..8u32 {
            for zero in [false, true] {
                let neg = [0, 1, 2].map(|a| octant >> a & 1 == 1);
                let mut d = Vec3A::new(0.5, 0.25, 0.125);
                for a in 0..3 {
                    d[a] = if neg[a] {
                        -d[a]
                    } else if zero {
                        0.0
                    } else {
                        d[a]
                    };
                }
                let Some(r) = PreparedRay::new(&Ray::new(Vec3A::ONE, d)) else {
                    assert_eq!(d, Vec3A::ZERO, "only the zero direction has no prepared ray");
                    continue;
                };
                let byte = (!neg[0] as u32) << 2 | (!neg[1] as u32) << 1 | !neg[2] as u32;
                assert_eq!(r.oct_inv4, byte * 0x0101_0101, "d {d}");
            }
        }
    }

    /// Four triangles in one block give the hits each gives alone, met
    /// one at a time with a running `Closest`: lanes do not leak into each
    /// other, and the closest hit wins. The triangles are stacked across the ray so most
    /// rays pass several, and some share vertices on a grid, so that rays
    /// through those vertices reach the double-precision step.
    #[test]
    fn block_test_matches_its_lanes_one_at_a_time() {
        let mut f = uniform(0x9e37_79b9_7f4a_7c15);
        let mut several = 0;
        for i in 0..20_000 {
            let tris: [[Vec3A; 3]; 4] = std::array::from_fn(|_| {
                let z = f() * 4.0 + 1.0;
                let tilt = (f() - 0.5) * (i % 2) as f32;
                let a = f() * 6.0;
                std::array::from_fn(|v| {
                    let (x, y) = if i % 4 < 2 {
                        // Large, around the axis: most rays pass all four.
                        let a = a + 2.1 * v as f32;
                        (3.0 * a.cos(), 3.0 * a.sin())
                    } else {
                        // On a 3 x 3 grid: shared vertices and edges.
                        ((f() * 3.0).floor() - 1.0, (f() * 3.0).floor() - 1.0)
                    };
                    Vec3A::new(x, y, z + tilt * x)
                })
            });
            let block = TriangleBlock::new(tris.into_iter());
            // Down the axis or through a grid vertex in a third of the cases.
            let (o, d) = if i % 3 == 0 {
                (Vec3A::new((f() * 3.0).floor() - 1.0, (f() * 3.0).floor() - 1.0, -1.0), Vec3A::Z)
            } else {
                (Vec3A::new(f() - 0.5, f() - 0.5, -1.0), Vec3A::new(f() - 0.5, f() - 0.5, 1.0) * (0.5 + f()))
            };
            let ray = Ray::new(o, d);
            let Some(pre) = PreparedRay::new(&ray) else { continue };
            let lanes = 1 + (f() * 15.0) as u32;
            let t0 = if i % 5 == 0 { 3.0 } else { f32::INFINITY };
            let mut in_block = Closest::new(t0);
            let got = pre.intersect_block(&block, 0, lanes, &mut in_block);
            let (mut one_by_one, mut want, mut hits) = (Closest::new(t0), None, 0);
            for lane in (0..4).rev().filter(|l| lanes >> l & 1 != 0) {
                let alone = TriangleBlock::new([tris[lane as usize]].into_iter());
                if let Some((_, b1, b2, edge_error)) = pre.intersect_block(&alone, lane, 1, &mut one_by_one) {
                    want = Some((lane, b1, b2, edge_error));
                }
                hits += intersect_triangle(&ray, &tris[lane as usize], t0).is_some() as u32;
            }
            let t = |c: Closest| c.t.to_bits();
            assert_eq!((got, t(in_block)), (want, t(one_by_one)), "case {i}: {ray:?} lanes {lanes:b} {tris:?}");
            several += (hits > 1) as u32;
        }
        assert!(several > 2000, "only {several} rays hit more than one triangle: test too weak");
        // The f64 step in every lane: two triangles whose shared edge has
        // f32 edge function exactly 0 but not in exact arithmetic (the
        // construction of tests/accel.rs `edge_function_zero_in_f32_...`),
        // so only the f64 products decide which one the ray hits.
        let e = f32::EPSILON;
        let (b, c) = (Vec3A::new(-(1.0 + e), -(1.0 + 2.0 * e), 0.0), Vec3A::new(1.0, 1.0 + e, 0.0));
        let (left, right) = ([Vec3A::new(1.0, -1.0, 0.0), b, c], [Vec3A::new(-1.0, 1.0, 0.0), c, b]);
        let pre = PreparedRay::new(&Ray::new(Vec3A::new(0.0, 0.0, 1.0), -Vec3A::Z)).unwrap();
        let alone = |tri: [Vec3A; 3]| {
            let mut closest = Closest::new(f32::INFINITY);
            pre.intersect_block(&TriangleBlock::new([tri].into_iter()), 0, 1, &mut closest).map(|h| (h.1, h.2, h.3))
        };
        let (hit_left, hit_right) = (alone(left), alone(right));
        assert!(hit_left.is_some() != hit_right.is_some(), "exactly one of the two is hit");
        for (l, r) in (0..4).flat_map(|l| (0..4).filter(move |&r| r != l).map(move |r| (l, r))) {
            let mut tris = [[Vec3A::splat(9.0), Vec3A::new(9.0, 10.0, 9.0), Vec3A::new(10.0, 9.0, 9.0)]; 4];
            (tris[l], tris[r]) = (left, right);
            let mut closest = Closest::new(f32::INFINITY);
            let got = pre.intersect_block(&TriangleBlock::new(tris.into_iter()), 0, 0xf, &mut closest);
            let want = hit_left.map(|h| (l as u32, h.0, h.1, h.2)).or(hit_right.map(|h| (r as u32, h.0, h.1, h.2)));
            assert_eq!(got, want, "left in lane {l}, right in lane {r}");
        }
    }

    /// Last in, first out, past the 32 entries in place and back.
    #[test]
    fn group_stack_spills_and_keeps_order() {
        let mut stack = GroupStack::new();
        for round in 0..2u32 {
            for i in 0..100 {
                stack.push((i, round));
            }
            assert_eq!(stack.spill.len(), 100 - GroupStack::INLINE, "entries past the inline ones spill");
            for i in (0..100).rev() {
                assert_eq!(stack.pop(), Some((i, round)));
            }
            assert_eq!(stack.pop(), None);
        }
    }

    #[test]
    fn empty_scene_misses() {
        let a = Accel::build(&[]);
        let r = Ray::new(Vec3A::ZERO, Vec3A::X);
        assert!(a.is_empty());
        assert_eq!(a.len(), 0);
        assert!(a.intersect(&r, f32::INFINITY).is_none());
        assert!(!a.occluded(&r, f32::INFINITY));
        assert_eq!(a.bounds(), (Vec3A::ZERO, Vec3A::ZERO));
    }

    /// The table against Woop et al.'s rule, for a direction of each
    /// dominant axis and sign: kz that axis, (kx, ky) the next two
    /// cyclically, swapped when d[kz] < 0; `permute` puts them in lanes.
    #[test]
    fn axis_orders_follow_the_dominant_axis() {
        for kz in 0..3 {
            for sign in [1.0f32, -1.0] {
                let mut d = Vec3A::new(0.3, -0.2, 0.25);
                d[kz] = 2.0 * sign;
                let r = PreparedRay::new(&Ray::new(Vec3A::new(1.0, 2.0, 3.0), d)).unwrap();
                let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
                let want = if sign < 0.0 { [ky, kx, kz] } else { [kx, ky, kz] };
                assert_eq!(r.k, want, "d = {d}");
                assert_eq!(r.o_k, Vec3A::from(want.map(|k| k as f32 + 1.0)), "d = {d}");
                let s = Vec3A::new(d[want[0]] / d[kz], d[want[1]] / d[kz], 1.0 / d[kz]);
                assert!((r.s - s).abs().max_element() < 1e-6, "d = {d}: {} vs {s}", r.s);
            }
        }
    }

    #[test]
    fn tiny_scenes_hit_with_input_index_and_barycentrics() {
        for n in 1..=2 {
            let tris = &quad()[..n];
            let a = Accel::build(tris);
            assert_eq!(a.len(), n);
            let r = Ray::new(Vec3A::new(0.7, 0.2, 1.0), -Vec3A::Z);
            let h = a.intersect(&r, f32::INFINITY).expect("hit");
            assert_eq!(h.prim, 0);
            assert!((h.t - 1.0).abs() < 1e-6);
            let p = tris[0][0] * (1.0 - h.b1 - h.b2) + tris[0][1] * h.b1 + tris[0][2] * h.b2;
            assert!((p - Vec3A::new(0.7, 0.2, 0.0)).length() < 1e-6, "{p}");
            assert!(a.occluded(&r, 1.5) && !a.occluded(&r, 1.0));
            assert!(a.intersect(&r, 1.0).is_none());
        }
    }

    #[test]
    fn diagonal_of_quad_is_hit() {
        let a = Accel::build(&quad());
        for k in 0..=64 {
            let s = k as f32 / 64.0;
            let r = Ray::new(Vec3A::new(s, s, 1.0), -Vec3A::Z);
            assert!(a.intersect(&r, f32::INFINITY).is_some(), "s = {s}");
            assert!(a.occluded(&r, f32::INFINITY), "s = {s}");
        }
    }

    #[test]
    fn degenerate_triangles_are_dropped() {
        let p = Vec3A::new(1.0, 2.0, 3.0);
        let tris = [
            [p, p, p],
            [Vec3A::ZERO, Vec3A::X, Vec3A::X * 2.0],
            [Vec3A::ZERO, Vec3A::X, Vec3A::new(f32::NAN, 0.0, 0.0)],
        ];
        assert!(tris.iter().all(is_degenerate));
        let a = Accel::build(&tris);
        assert_eq!(a.len(), 3);
        assert_eq!(a.degenerate(), [0, 1, 2]);
        assert_eq!(a.slot_map(), [NO_TRIANGLE; 3]);
        let r = Ray::new(Vec3A::new(0.5, 0.0, 1.0), -Vec3A::Z);
        assert!(a.intersect(&r, f32::INFINITY).is_none());
    }

    /// `slots_of` (area lights) and `slot_map` (exporters) agree, for
    /// unsorted and repeated indices and a degenerate triangle; every slot
    /// holds its input triangle.
    #[test]
    fn slot_lookups_agree() {
        let mut tris: Vec<[Vec3A; 3]> = (0..40)
            .map(|i| {
                let o = Vec3A::new((i % 7) as f32, (i / 7) as f32, (i % 3) as f32);
                [o, o + Vec3A::X, o + Vec3A::Y]
            })
            .collect();
        tris[17] = [Vec3A::ZERO; 3];
        let a = Accel::build(&tris);
        let map = a.slot_map();
        assert_eq!(a.degenerate(), [17]);
        assert_eq!(map[17], NO_TRIANGLE);
        for (i, &s) in map.iter().enumerate().filter(|&(i, _)| i != 17) {
            assert_eq!(a.vertices(s), tris[i], "triangle {i}");
        }
        let prims = [39, 3, 17, 3, 0, 22];
        assert_eq!(a.slots_of(&prims), prims.map(|p| map[p as usize]));
        assert!(a.slots_of(&[]).is_empty());
    }
}
