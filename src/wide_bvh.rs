//! BVH2 -> compressed 8-wide BVH (CWBVH) conversion.
//!
//! The node format is Ylitie, Karras & Laine 2017, "Efficient Incoherent Ray
//! Traversal on GPUs Through Compressed Wide BVHs", sec. 3.1, as obvhs 0.4
//! stores it (`CwBvhNode`), so `Accel`'s traversal reads it unchanged. The
//! collapse is not the paper's optimal SAH one (sec. 3.2, obvhs's
//! `bvh2_to_cwbvh`), whose dynamic-programming table of 7 decisions per BVH2
//! node costs 112 bytes per triangle alongside the BVH2. It is the greedy
//! top-down collapse the paper names as the simple alternative and Embree's
//! BVH8 builder uses (Wald et al. 2014, "Embree: A Kernel Framework for
//! Efficient CPU Ray Tracing"): a wide node starts from its BVH2 node's two
//! children and repeatedly replaces the child with the largest surface area by
//! that child's two children. It needs the BVH2 and O(8) scratch per wide node.

use glam::Vec3A;
use obvhs::{
    bvh2::Bvh2,
    cwbvh::{node::CwBvhNode, CwBvh},
};

/// Children per wide node.
const BRANCHING: usize = 8;

/// Primitives per leaf child: the child meta byte holds the count in unary in
/// its top 3 bits (Ylitie et al. 2017, sec. 3.1).
pub const MAX_LEAF_PRIMS: u32 = 3;

/// Converts `bvh2` (leaves of at most `MAX_LEAF_PRIMS` primitives; PLOC's have
/// one) into a CWBVH whose `primitive_indices` holds each of `bvh2`'s
/// primitive indices exactly once, a node's leaf primitives contiguous.
///
/// A BVH2 subtree with at most `MAX_LEAF_PRIMS` primitives becomes a leaf
/// child: it is not opened, so a leaf never splits its primitives over
/// several slots. Every larger subtree can be opened, so the greedy
/// expansion ends with 8 children or with only leaf children left.
pub fn collapse(bvh2: &Bvh2) -> CwBvh {
    let Some(root) = bvh2.nodes.first() else {
        return CwBvh::default();
    };
    let mut out = Collapse {
        bvh2,
        nodes: vec![CwBvhNode::default()],
        primitive_indices: Vec::with_capacity(bvh2.primitive_indices.len()),
    };
    // Depth first, children in slot order, as obvhs lays the nodes out: a
    // node's inner children are contiguous and follow their parent's block.
    let mut stack = vec![(0u32, 0u32)];
    while let Some((wide, node)) = stack.pop() {
        out.emit(wide as usize, node as usize, &mut stack);
    }
    out.nodes.shrink_to_fit();
    CwBvh {
        nodes: out.nodes,
        primitive_indices: out.primitive_indices,
        total_aabb: *root.aabb(),
        exact_node_aabbs: None,
        uses_spatial_splits: bvh2.uses_spatial_splits,
    }
}

struct Collapse<'a> {
    bvh2: &'a Bvh2,
    nodes: Vec<CwBvhNode>,
    primitive_indices: Vec<u32>,
}

/// A child of the wide node being built: a BVH2 node, whether it becomes a
/// leaf child (at most `MAX_LEAF_PRIMS` primitives under it) and its area.
#[derive(Clone, Copy)]
struct Child {
    node: u32,
    leaf: bool,
    half_area: f32,
}

impl Child {
    fn new(bvh2: &Bvh2, node: u32) -> Self {
        let n = &bvh2.nodes[node as usize];
        Self { node, leaf: leaf_prims(bvh2, node as usize).is_some(), half_area: n.aabb().half_area() }
    }
}

impl Collapse<'_> {
    /// Fills wide node `wide` from BVH2 node `node`: its children, their
    /// quantized boxes and metadata, its leaf primitives (appended to
    /// `primitive_indices`) and empty nodes for its inner children (appended
    /// to `nodes`), which it pushes as (wide node, BVH2 node) onto `stack`,
    /// the first slot on top.
    fn emit(&mut self, wide: usize, node: usize, stack: &mut Vec<(u32, u32)>) {
        let bvh2 = self.bvh2;
        let mut children = self.greedy_children(node);
        order_children(bvh2, node, &mut children);

        let aabb = bvh2.nodes[node].aabb();
        let e = quantization_step(aabb.max - aabb.min);
        let rcp_e = 1.0 / e;
        let mut out = CwBvhNode {
            p: aabb.min.into(),
            e: e.to_array().map(|c| (c.to_bits() >> 23) as u8),
            child_base_idx: self.nodes.len() as u32,
            primitive_base_idx: self.primitive_indices.len() as u32,
            ..CwBvhNode::default()
        };
        let stack_base = stack.len();
        let mut inner = 0;
        let mut prims = 0u32;
        for (slot, child) in children.iter().enumerate() {
            let Some(child) = *child else { continue };
            let b = bvh2.nodes[child.node as usize].aabb();
            // Rounded outward, as obvhs quantizes: floor / ceil on a grid
            // of power-of-two step, so the dequantized box p + q e holds the
            // child's box (up to the rounding of b - p that `intersect_node`'s
            // slack covers).
            let lo = ((b.min - aabb.min) * rcp_e).floor().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
            let hi = ((b.max - aabb.min) * rcp_e).ceil().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
            out.child_min_x[slot] = lo.x as u8;
            out.child_min_y[slot] = lo.y as u8;
            out.child_min_z[slot] = lo.z as u8;
            out.child_max_x[slot] = hi.x as u8;
            out.child_max_y[slot] = hi.y as u8;
            out.child_max_z[slot] = hi.z as u8;
            if child.leaf {
                let before = self.primitive_indices.len();
                self.push_primitives(child.node as usize);
                let count = (self.primitive_indices.len() - before) as u32;
                // Meta: the count in unary in the top 3 bits, the offset of
                // the first primitive from primitive_base_idx below.
                out.child_meta[slot] = prims as u8 | ((1u8 << count) - 1) << 5;
                prims += count;
            } else {
                // Meta of an inner child: 001 then 24 + slot.
                out.imask |= 1 << slot;
                out.child_meta[slot] = (24 + slot as u8) | 0b0010_0000;
                stack.push(((self.nodes.len() + inner) as u32, child.node));
                inner += 1;
            }
        }
        debug_assert!(prims as usize <= BRANCHING * MAX_LEAF_PRIMS as usize);
        stack[stack_base..].reverse();
        self.nodes.resize(self.nodes.len() + inner, CwBvhNode::default());
        self.nodes[wide] = out;
    }

    /// The greedy top-down collapse: from `node`'s two children (`node`
    /// itself if it is a leaf, which only the root can be), open the child
    /// with the largest surface area that is not a leaf child until there are
    /// 8 children. Children stay in BVH2 order (an opened child's two take
    /// its place), which `order_children` uses to break ties.
    fn greedy_children(&self, node: usize) -> [Option<Child>; BRANCHING] {
        let bvh2 = self.bvh2;
        let n = &bvh2.nodes[node];
        let mut children = [None; BRANCHING];
        let mut count = if n.is_leaf() {
            children[0] = Some(Child::new(bvh2, node as u32));
            1
        } else {
            children[0] = Some(Child::new(bvh2, n.first_index));
            children[1] = Some(Child::new(bvh2, n.first_index + 1));
            2
        };
        while count < BRANCHING {
            let mut best: Option<(usize, f32)> = None;
            for (i, child) in children[..count].iter().enumerate() {
                let child = child.expect("children are packed");
                if !child.leaf && best.is_none_or(|(_, a)| child.half_area > a) {
                    best = Some((i, child.half_area));
                }
            }
            let Some((i, _)) = best else { break };
            let first = bvh2.nodes[children[i].expect("children are packed").node as usize].first_index;
            children.copy_within(i + 1..count, i + 2);
            children[i] = Some(Child::new(bvh2, first));
            children[i + 1] = Some(Child::new(bvh2, first + 1));
            count += 1;
        }
        children
    }

    /// Appends the primitives under BVH2 `node`, left to right.
    fn push_primitives(&mut self, node: usize) {
        let n = &self.bvh2.nodes[node];
        if n.is_leaf() {
            let first = n.first_index as usize;
            self.primitive_indices
                .extend_from_slice(&self.bvh2.primitive_indices[first..first + n.prim_count as usize]);
        } else {
            self.push_primitives(n.first_index as usize);
            self.push_primitives(n.first_index as usize + 1);
        }
    }
}

/// The number of primitives under BVH2 `node` if at most `MAX_LEAF_PRIMS`
/// (the subtree becomes one leaf child), else None. Such a subtree has at
/// most 3 leaves, so at most 2 levels: the count looks no deeper and visits
/// at most 7 nodes.
fn leaf_prims(bvh2: &Bvh2, node: usize) -> Option<u32> {
    fn count(bvh2: &Bvh2, node: usize, levels: u32) -> Option<u32> {
        let n = &bvh2.nodes[node];
        if n.is_leaf() {
            assert!(
                n.prim_count <= MAX_LEAF_PRIMS,
                "BVH2 leaf with {} primitives: a CWBVH leaf holds at most {MAX_LEAF_PRIMS}",
                n.prim_count
            );
            return Some(n.prim_count);
        }
        let levels = levels.checked_sub(1)?;
        Some(count(bvh2, n.first_index as usize, levels)? + count(bvh2, n.first_index as usize + 1, levels)?)
    }
    count(bvh2, node, 2).filter(|&c| c <= MAX_LEAF_PRIMS)
}

/// The grid step per axis for a node of extent `extent`: the smallest power
/// of two e with 255 e >= extent, computed as obvhs does
/// (2^ceil(log2(extent / 255))), then doubled where its rounding fell short
/// (extent just above 255 times a power of two), so no child coordinate is
/// clamped at 255.
fn quantization_step(extent: Vec3A) -> Vec3A {
    let extent = extent.max(Vec3A::splat(1e-20));
    let e = (extent * (1.0 / 255.0)).log2().ceil().exp2();
    Vec3A::select((e * 255.0).cmplt(extent), e * 2.0, e)
}

/// Assigns the children to the 8 slots by ray octant (Ylitie et al. 2017,
/// sec. 3.2, "ordering the children"), exactly as obvhs's `order_children`:
/// the cost of child c in slot s is the dot product of octant s's diagonal
/// direction with the vector from the node's centre to c's centre, and the
/// cheapest (child, free slot) pair is taken until all are placed (greedy;
/// the paper suggests an auction, obvhs found greedy almost as good). A ray
/// of octant s then visits the children in slot order xor s roughly front to
/// back.
fn order_children(bvh2: &Bvh2, node: usize, children: &mut [Option<Child>; BRANCHING]) {
    let count = children.iter().take_while(|c| c.is_some()).count();
    let centre = bvh2.nodes[node].aabb().center();
    // cost[c][s]; slot s's direction: bit 2 of s negates x, bit 1 y, bit 0
    // z, matching the traversal's oct_inv4.
    let mut cost = [[0.0f32; BRANCHING]; BRANCHING];
    for (row, child) in cost.iter_mut().zip(&children[..count]) {
        let v = bvh2.nodes[child.expect("children are packed").node as usize].aabb().center() - centre;
        for (s, c) in row.iter_mut().enumerate() {
            let d = Vec3A::new(
                if s & 0b100 != 0 { -1.0 } else { 1.0 },
                if s & 0b010 != 0 { -1.0 } else { 1.0 },
                if s & 0b001 != 0 { -1.0 } else { 1.0 },
            );
            *c = d.dot(v);
        }
    }
    let mut assignment = [usize::MAX; BRANCHING];
    let mut filled = [false; BRANCHING];
    loop {
        let mut best: Option<(usize, usize, f32)> = None;
        for (c, row) in cost[..count].iter().enumerate() {
            if assignment[c] != usize::MAX {
                continue;
            }
            for (s, &cost) in row.iter().enumerate() {
                if !filled[s] && best.is_none_or(|(_, _, b)| cost < b) {
                    best = Some((c, s, cost));
                }
            }
        }
        let Some((c, s, _)) = best else { break };
        filled[s] = true;
        assignment[c] = s;
    }
    let original = std::mem::replace(children, [None; BRANCHING]);
    for c in 0..count {
        children[assignment[c]] = original[c];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::{aabb::Aabb, bvh2::builder::build_bvh2, BvhBuildParams};
    use std::time::Duration;

    /// Boxes of a random soup of `n` small triangles in the unit cube, plus
    /// a few flat, long and coincident ones.
    fn soup(n: usize, seed: u64) -> Vec<Aabb> {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
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

    fn bvh2(boxes: &[Aabb], max_prims_per_leaf: u32) -> Bvh2 {
        let params = BvhBuildParams { max_prims_per_leaf, ..BvhBuildParams::fast_build() };
        build_bvh2(boxes, params, &mut Duration::default())
    }

    /// Walks the CWBVH from the root; checks every child's dequantized box
    /// holds the boxes of all primitives under it, leaves hold 1-3, and
    /// returns the primitives in visiting order.
    fn check(bvh: &CwBvh, boxes: &[Aabb]) -> Vec<u32> {
        fn walk(bvh: &CwBvh, boxes: &[Aabb], node: usize, out: &mut Vec<u32>, depth: usize) -> Vec<u32> {
            assert!(depth < 64, "too deep");
            let n = &bvh.nodes[node];
            let e = n.compute_extent();
            let p = Vec3A::from(n.p);
            let mut all = Vec::new();
            for slot in 0..BRANCHING {
                let meta = n.child_meta[slot];
                if meta == 0 {
                    continue;
                }
                let prims = if n.imask & (1 << slot) != 0 {
                    assert_eq!(meta, (24 + slot as u8) | 0b0010_0000);
                    let child = n.child_base_idx + (n.imask & ((1u8 << slot) - 1)).count_ones();
                    walk(bvh, boxes, child as usize, out, depth + 1)
                } else {
                    let count = (meta >> 5).count_ones();
                    assert!(matches!(meta >> 5, 0b001 | 0b011 | 0b111), "meta {meta:#010b}");
                    assert!((1..=MAX_LEAF_PRIMS).contains(&count));
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
            all
        }
        let mut out = Vec::new();
        walk(bvh, boxes, 0, &mut out, 0);
        out
    }

    #[test]
    fn every_primitive_once_in_conservative_boxes() {
        for (n, leaf) in [(1, 1), (2, 1), (3, 1), (10, 1), (1000, 1), (5000, 3), (20000, 1)] {
            let boxes = soup(n, n as u64);
            let bvh = collapse(&bvh2(&boxes, leaf));
            let mut seen = check(&bvh, &boxes);
            assert_eq!(seen.len(), boxes.len());
            // Visiting order is leaf order: each node's leaves contiguous.
            let mut sorted = bvh.primitive_indices.clone();
            sorted.sort_unstable();
            seen.sort_unstable();
            assert_eq!(seen, sorted);
            assert_eq!(sorted, (0..boxes.len() as u32).collect::<Vec<_>>());
        }
    }

    #[test]
    fn leaf_children_are_full_and_nodes_wide() {
        // Every subtree with at most 3 primitives is one leaf child and
        // every node but those whose children are all leaves has 8 children.
        let boxes = soup(20000, 7);
        let bvh = collapse(&bvh2(&boxes, 1));
        for n in &bvh.nodes {
            let children = n.child_meta.iter().filter(|&&m| m != 0).count();
            assert!(children == BRANCHING || n.imask == 0, "{children} children, imask {:#b}", n.imask);
        }
        // 20k primitives in 8-wide nodes with leaves of up to 3: a few
        // thousand nodes, not one per primitive.
        assert!(bvh.nodes.len() < boxes.len() / 4, "{} nodes", bvh.nodes.len());
    }

    #[test]
    fn quantization_step_covers_the_extent() {
        for x in [0.0f32, 1e-30, 1.0, 255.0, 255.0 * 4.0, 255.0f32.next_up() * 4.0, 3.7e5, 1e30] {
            let e = quantization_step(Vec3A::splat(x));
            assert!(e.x * 255.0 >= x && e.x.to_bits() & 0x807f_ffff == 0, "{x}: {e}");
            assert!(x == 0.0 || e.x * 127.5 < x.max(1e-20), "{x}: {e} not the smallest");
        }
    }

    #[test]
    fn slots_follow_octants() {
        // Two children side by side along +x: the one at larger x belongs
        // in the slots of rays going -x (bit 2 set) and vice versa.
        let boxes =
            [Aabb::new(Vec3A::ZERO, Vec3A::ONE), Aabb::new(Vec3A::new(2.0, 0.0, 0.0), Vec3A::new(3.0, 1.0, 1.0))];
        let bvh = collapse(&bvh2(&boxes, 1));
        let n = &bvh.nodes[0];
        for slot in 0..BRANCHING {
            let meta = n.child_meta[slot];
            if meta != 0 {
                let prim = bvh.primitive_indices[(n.primitive_base_idx + (meta & 0x1f) as u32) as usize];
                assert_eq!(prim == 1, slot & 0b100 != 0, "prim {prim} in slot {slot}");
            }
        }
    }
}
