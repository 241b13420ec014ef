//! The 8-wide BVH builder: binned SAH, straight into compressed wide nodes.
//!
//! Above `OPTIMAL_PRIMS` primitives the build is top-down, as Embree's BVH8
//! builder (Wald et al. 2014, "Embree: A Kernel Framework for Efficient CPU
//! Ray Tracing", sec. 4): a wide node starts as one child holding all its
//! primitives and repeatedly splits its child with the largest surface area
//! in two until it has 8 children. Each split is the binned SAH split of Wald
//! 2007 ("On fast Construction of SAH-based Bounding Volume Hierarchies",
//! sec. 3, 32 bins), on the three centroid axes and on a fourth axis of size
//! classes (`sah.rs`); ranges of at most 16 primitives are swept exactly.
//! Smaller subtrees get a local binary SAH tree and the SAH-optimal collapse
//! into wide nodes of Ylitie, Karras & Laine 2017 ("Efficient Incoherent Ray
//! Traversal on GPUs Through Compressed Wide BVHs"), as Bonsai (Ganestam et
//! al. 2015, JCGT 4(3)) builds mini trees under a coarse top split.
//!
//! The node format is Ylitie et al.'s compressed one (sec. 3.1) as obvhs
//! stores it (`CwBvhNode`), so `Accel`'s traversal reads it unchanged.
//!
//! Memory: one 32-byte `PrimRef` per primitive, partitioned in place and
//! left in leaf order (so the primitive array is read off it at the end),
//! and 80 bytes per wide node. No binary BVH over the whole scene is ever
//! held (obvhs's PLOC BVH2 and its optimal-collapse table took 176 bytes per
//! triangle).
//!
//! Determinism: the tree depends only on the input. Large subtrees are built
//! as rayon tasks into their own node arrays and merged in a fixed order into
//! exactly the bytes a serial build writes, whatever the thread count.

mod collapse;
mod node;
mod sah;

use collapse::{Collapse, OPTIMAL_PRIMS};
use glam::{BVec4A, Vec3A, Vec4};
use node::emit;
use obvhs::{
    aabb::Aabb,
    cwbvh::{node::CwBvhNode, CwBvh},
};
use rayon::prelude::*;
use sah::{sah_split, split_in_two};

/// Children per wide node.
const BRANCHING: usize = 8;

/// Primitives per leaf child: the child meta byte holds the count in unary in
/// its top 3 bits (Ylitie et al. 2017, sec. 3.1).
pub const MAX_LEAF_PRIMS: usize = 3;

/// Nodes over at least this many primitives build their inner children as
/// rayon tasks.
const PARALLEL_SUBTREES: usize = 4096;

/// Below this many levels (wide ones above `OPTIMAL_PRIMS`, binary ones
/// below) the builder splits by SAH; deeper, by object median, which halves
/// every range, so a pathological input (centroids spaced exponentially,
/// where each SAH split peels off a few primitives) still gives a tree of
/// logarithmic depth and a bounded recursion.
const SAH_DEPTH: u32 = 32;

/// `x` as an integer that orders as `f32::total_cmp` orders the floats
/// (total_cmp's own transform): the sweeps' sort and the octant slots'
/// greedy assignment compare these, without a branch.
fn total_order_key(x: f32) -> i32 {
    let bits = x.to_bits() as i32;
    bits ^ (((bits >> 31) as u32) >> 1) as i32
}

/// A primitive's box and its index (in the w lane of `min`, as bits), as
/// Embree's `PrimRef`: 32 bytes, moved as one by the partition.
#[derive(Clone, Copy, Debug)]
pub struct PrimRef {
    min: Vec4,
    max: Vec3A,
}

impl PrimRef {
    pub fn new(bounds: Aabb, index: u32) -> Self {
        Self { min: bounds.min.extend(f32::from_bits(index)), max: bounds.max }
    }

    /// False for an empty box (`Aabb::empty()`), which marks a primitive
    /// to leave out.
    pub fn is_valid(&self) -> bool {
        self.bounds().min.cmple(self.max).all()
    }

    pub fn index(&self) -> u32 {
        self.min.w.to_bits()
    }

    #[inline(always)]
    fn bounds(&self) -> Aabb {
        // The index lane is masked out, so no arithmetic sees its bits.
        let min = Vec4::select(BVec4A::new(true, true, true, false), self.min, Vec4::ZERO);
        Aabb::new(Vec3A::from_vec4(min), self.max)
    }
}

/// Builds the CWBVH over `refs`. Its `primitive_indices` lists each
/// `PrimRef::index` once, a node's leaf primitives contiguous: the
/// partition leaves `refs` in that order, so no second array is needed.
pub fn build(mut refs: Vec<PrimRef>) -> CwBvh {
    if refs.is_empty() {
        return CwBvh::default();
    }
    let root = Range::of(&refs, 0, refs.len());
    let mut nodes = vec![CwBvhNode::default()];
    build_node(&mut refs, 0, root, 0, 0, &mut nodes);
    nodes.shrink_to_fit();
    // The build leaves the primitives in leaf order.
    let primitive_indices = refs.par_iter().map(PrimRef::index).collect();
    CwBvh { nodes, primitive_indices, total_aabb: root.bounds, exact_node_aabbs: None, uses_spatial_splits: false }
}

/// `refs[start..end]` with the union of their boxes and of their centroids.
#[derive(Clone, Copy, Debug)]
struct Range {
    start: usize,
    end: usize,
    bounds: Aabb,
    centroids: Aabb,
}

impl Range {
    fn of(refs: &[PrimRef], start: usize, end: usize) -> Self {
        let mut r = Self { start, end, bounds: Aabb::empty(), centroids: Aabb::empty() };
        for p in &refs[start..end] {
            r.grow(p);
        }
        r
    }

    fn len(&self) -> usize {
        self.end - self.start
    }

    #[inline(always)]
    fn grow(&mut self, p: &PrimRef) {
        let b = p.bounds();
        self.bounds = self.bounds.union(&b);
        self.centroids.extend(b.min + b.max);
    }
}

/// Appends the nodes of a subtree built on its own (root at `sub[0]`, child
/// indices local) with its root in `nodes[slot]`, as if built here: its
/// child indices move by where its nodes land. (Primitive indices are
/// global already.)
fn merge(nodes: &mut Vec<CwBvhNode>, sub: Vec<CwBvhNode>, slot: usize) {
    let offset = (nodes.len() - 1) as u32;
    let mut sub = sub.into_iter().map(|mut n| {
        n.child_base_idx += offset;
        n
    });
    nodes[slot] = sub.next().expect("a subtree has a root");
    nodes.extend(sub);
}

/// Builds the wide node over `refs` (all of `node`; `refs[0]` is primitive
/// `base` of the whole build) into `nodes[slot]`, then its inner children's
/// subtrees: top-down while the node is large, by the optimal collapse
/// below `OPTIMAL_PRIMS`.
fn build_node(refs: &mut [PrimRef], base: usize, node: Range, slot: usize, depth: u32, nodes: &mut Vec<CwBvhNode>) {
    if node.len() <= OPTIMAL_PRIMS {
        return Collapse::new(refs, node).emit_subtree(refs, base, 0, 0, slot, nodes);
    }
    let children = open_children(refs, node, depth);
    let inner = emit(refs, base, node.bounds, &children, slot, nodes);
    // Disjoint slices for the inner children, in memory order.
    let mut rest = &mut *refs;
    let mut taken = 0;
    let mut jobs = Vec::with_capacity(BRANCHING);
    for (_, child, child_slot) in inner.into_iter().flatten() {
        let (_, tail) = std::mem::take(&mut rest).split_at_mut(child.start - taken);
        let (mine, tail) = tail.split_at_mut(child.len());
        rest = tail;
        taken = child.end;
        jobs.push((mine, base + child.start, Range { start: 0, end: child.len(), ..child }, child_slot));
    }
    if node.len() >= PARALLEL_SUBTREES {
        let subs: Vec<(Vec<CwBvhNode>, usize)> = jobs
            .into_par_iter()
            .map(|(refs, base, child, child_slot)| {
                let mut sub = vec![CwBvhNode::default()];
                build_node(refs, base, child, 0, depth + 1, &mut sub);
                sub.shrink_to_fit();
                (sub, child_slot)
            })
            .collect();
        // Grown once to the exact size: doubling a large node array would
        // reserve up to twice what the tree needs at the build's peak.
        nodes.reserve_exact(subs.iter().map(|(sub, _)| sub.len() - 1).sum());
        for (sub, child_slot) in subs {
            merge(nodes, sub, child_slot);
        }
    } else {
        for (refs, base, child, child_slot) in jobs {
            build_node(refs, base, child, child_slot, depth + 1, nodes);
        }
    }
}

/// The children of a large wide node over `refs` (all of `node`), in memory
/// order: the child with the largest surface area is split until there are
/// 8 (Wald et al. 2014). Every child of a range this large has more than
/// `MAX_LEAF_PRIMS` primitives but for rare lopsided splits, and those stay
/// leaves.
fn open_children(refs: &mut [PrimRef], node: Range, depth: u32) -> Vec<Range> {
    let mut children = vec![node];
    while children.len() < BRANCHING {
        let Some(i) = largest(&children, |c| c.len() > MAX_LEAF_PRIMS) else {
            break;
        };
        let split = if depth >= SAH_DEPTH { None } else { sah_split(refs, &children[i]) };
        let (left, right) = split_in_two(refs, &children[i], split);
        children[i] = left;
        children.insert(i + 1, right);
    }
    children
}

/// The index of the child with the largest surface area among those
/// `eligible`; the first on ties.
fn largest(children: &[Range], eligible: impl Fn(&Range) -> bool) -> Option<usize> {
    let mut best: Option<(usize, f32)> = None;
    for (i, c) in children.iter().enumerate() {
        let area = c.bounds.half_area();
        if eligible(c) && best.is_none_or(|(_, a)| area > a) {
            best = Some((i, area));
        }
    }
    best.map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in [0, 1) from a 64-bit LCG (Knuth's MMIX
    /// constants): reproducible inputs for the builder's tests.
    pub(super) fn uniform(seed: u64) -> impl FnMut() -> f32 {
        let mut state = seed;
        move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// Boxes of a random soup of `n` small triangles in the unit cube, plus
    /// a few flat, long and coincident ones.
    fn soup(n: usize, seed: u64) -> Vec<Aabb> {
        let mut next = uniform(seed);
        let mut boxes: Vec<Aabb> = (0..n)
            .map(|_| {
                let c = Vec3A::new(next(), next(), next());
                let size = Vec3A::new(next(), next(), next()) * 0.05;
                Aabb::new(c, c + size)
            })
            .collect();
        boxes.push(Aabb::new(Vec3A::ZERO, Vec3A::new(1.0, 1.0, 0.0)));
        boxes.push(Aabb::new(Vec3A::splat(0.5), Vec3A::splat(0.5)));
        boxes.push(Aabb::new(Vec3A::splat(0.5), Vec3A::splat(0.5)));
        boxes.push(Aabb::new(Vec3A::new(-100.0, 0.2, 0.2), Vec3A::new(100.0, 0.2, 0.3)));
        boxes
    }

    fn build_boxes(boxes: &[Aabb]) -> CwBvh {
        build(boxes.iter().enumerate().map(|(i, b)| PrimRef::new(*b, i as u32)).collect())
    }

    /// Walks the CWBVH from the root; checks every child's dequantized box
    /// holds the boxes of all primitives under it, leaves hold 1-3, and
    /// returns the primitives in visiting order and the depth.
    fn check(bvh: &CwBvh, boxes: &[Aabb]) -> (Vec<u32>, usize) {
        fn walk(bvh: &CwBvh, boxes: &[Aabb], node: usize, out: &mut Vec<u32>, depth: usize) -> (Vec<u32>, usize) {
            assert!(depth < 64, "too deep");
            let n = &bvh.nodes[node];
            let e = n.compute_extent();
            let p = Vec3A::from(n.p);
            let mut all = Vec::new();
            let mut deepest = depth;
            for slot in 0..BRANCHING {
                let meta = n.child_meta[slot];
                if meta == 0 {
                    continue;
                }
                let prims = if n.imask & (1 << slot) != 0 {
                    assert_eq!(meta, (24 + slot as u8) | 0b0010_0000);
                    let child = n.child_base_idx + (n.imask & ((1u8 << slot) - 1)).count_ones();
                    let (prims, d) = walk(bvh, boxes, child as usize, out, depth + 1);
                    deepest = deepest.max(d);
                    prims
                } else {
                    let count = (meta >> 5).count_ones();
                    assert!(matches!(meta >> 5, 0b001 | 0b011 | 0b111), "meta {meta:#010b}");
                    let first = (n.primitive_base_idx + (meta & 0x1f) as u32) as usize;
                    let prims = bvh.primitive_indices[first..first + count as usize].to_vec();
                    out.extend_from_slice(&prims);
                    prims
                };
                let q = |v: [[u8; 8]; 3]| Vec3A::new(v[0][slot] as f32, v[1][slot] as f32, v[2][slot] as f32);
                let lo = q([n.child_min_x, n.child_min_y, n.child_min_z]);
                let hi = q([n.child_max_x, n.child_max_y, n.child_max_z]);
                assert!(lo.cmple(hi).all());
                // The rounding of (box - p) before quantizing, which the
                // traversal's slack covers: half an ulp of 255 e.
                let tol = e * 255.0 * f32::EPSILON;
                for &i in &prims {
                    let b = boxes[i as usize];
                    assert!((p + lo * e - tol).cmple(b.min).all(), "slot {slot} min {lo} vs {b:?}");
                    assert!((p + hi * e + tol).cmpge(b.max).all(), "slot {slot} max {hi} vs {b:?}");
                }
                all.extend(prims);
            }
            assert!(!all.is_empty(), "empty node");
            (all, deepest)
        }
        let mut out = Vec::new();
        let (_, depth) = walk(bvh, boxes, 0, &mut out, 0);
        (out, depth)
    }

    #[test]
    fn every_primitive_once_in_conservative_boxes() {
        assert!(build_boxes(&[]).nodes.is_empty());
        for n in [1, 2, 3, 4, 10, 1000, 5000, 100_000] {
            let boxes = soup(n, n as u64);
            let bvh = build_boxes(&boxes);
            let (mut seen, _) = check(&bvh, &boxes);
            let mut listed = bvh.primitive_indices.clone();
            seen.sort_unstable();
            listed.sort_unstable();
            let all: Vec<u32> = (0..boxes.len() as u32).collect();
            assert_eq!((seen, listed), (all.clone(), all));
            let total = boxes.iter().fold(Aabb::empty(), |a, b| a.union(b));
            assert_eq!((bvh.total_aabb.min, bvh.total_aabb.max), (total.min, total.max));
        }
    }

    #[test]
    fn nodes_are_wide_and_leaves_small() {
        let boxes = soup(20_000, 7);
        let bvh = build_boxes(&boxes);
        // 20k primitives in 8-wide nodes with leaves of up to 3: a few
        // thousand nodes, not one per primitive.
        assert!(bvh.nodes.len() < boxes.len() / 4, "{} nodes", bvh.nodes.len());
        // An inner node is only made for more than 3 primitives, so every
        // node has at least 2 children.
        for n in &bvh.nodes {
            assert!(n.child_meta.iter().filter(|&&m| m != 0).count() >= 2);
        }
    }

    #[test]
    fn same_bytes_at_any_thread_count() {
        let boxes = soup(60_000, 3);
        let on = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let bvh = pool.install(|| build_boxes(&boxes));
            (bvh.nodes, bvh.primitive_indices)
        };
        assert!(on(1) == on(3));
    }

    #[test]
    fn beyond_sah_depth_splits_are_medians() {
        // 1024 unit boxes on a line at x = i^2: object medians halve the
        // counts (every child a power of two), SAH planes do not.
        let boxes: Vec<Aabb> = (0..1024)
            .map(|i| {
                let x = (i * i) as f32;
                Aabb::new(Vec3A::new(x, 0.0, 0.0), Vec3A::new(x + 1.0, 1.0, 1.0))
            })
            .collect();
        let sizes = |depth| {
            let mut refs: Vec<PrimRef> = boxes.iter().enumerate().map(|(i, b)| PrimRef::new(*b, i as u32)).collect();
            let root = Range::of(&refs, 0, refs.len());
            open_children(&mut refs, root, depth).iter().map(Range::len).collect::<Vec<_>>()
        };
        let median = sizes(SAH_DEPTH);
        assert_eq!(median.len(), BRANCHING);
        assert!(median.iter().all(|s| s.is_power_of_two()), "{median:?}");
        let sah = sizes(SAH_DEPTH - 1);
        assert!(!sah.iter().all(|s| s.is_power_of_two()), "{sah:?}");
    }

    #[test]
    fn slots_follow_octants() {
        // Two children side by side along +x: the one at larger x belongs
        // in the slots of rays going -x (bit 2 set) and vice versa.
        let boxes =
            [Aabb::new(Vec3A::ZERO, Vec3A::ONE), Aabb::new(Vec3A::new(2.0, 0.0, 0.0), Vec3A::new(3.0, 1.0, 1.0))];
        let bvh = build_boxes(&boxes);
        let n = &bvh.nodes[0];
        let mut found = 0;
        for slot in 0..BRANCHING {
            let meta = n.child_meta[slot];
            if meta != 0 {
                let prim = bvh.primitive_indices[(n.primitive_base_idx + (meta & 0x1f) as u32) as usize];
                assert_eq!(prim == 1, slot & 0b100 != 0, "prim {prim} in slot {slot}");
                found += 1;
            }
        }
        assert_eq!(found, 2);
    }
}
