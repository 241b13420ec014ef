//! Writing one compressed wide node: child slots by ray octant, quantized
//! child boxes and metadata (Ylitie et al. 2017, sec. 3.1, in obvhs's
//! `CwBvhNode` layout).

use super::{total_order_key, PrimRef, Range, BRANCHING, MAX_LEAF_PRIMS};
use glam::Vec3A;
use obvhs::{aabb::Aabb, cwbvh::node::CwBvhNode};

/// Writes the wide node with box `aabb` and `children` (ranges of `refs`
/// in memory order, covering the node's) into `nodes[slot]`: slots by ray
/// octant, quantized boxes, metadata; reserves nodes for its inner
/// children. Returns the inner children (index, moved range, reserved slot)
/// in memory order, then None.
pub(super) fn emit(
    refs: &mut [PrimRef],
    base: usize,
    aabb: Aabb,
    children: &[Range],
    slot: usize,
    nodes: &mut Vec<CwBvhNode>,
) -> [Option<(usize, Range, usize)>; BRANCHING] {
    let (moved, offsets) = leaves_first(refs, children);
    let e = quantization_step(aabb.max - aabb.min);
    let mut wide = CwBvhNode {
        p: aabb.min.into(),
        e: e.to_array().map(|c| (c.to_bits() >> 23) as u8),
        child_base_idx: nodes.len() as u32,
        primitive_base_idx: (base + children[0].start) as u32,
        ..CwBvhNode::default()
    };
    let mut by_slot: [Option<usize>; BRANCHING] = [None; BRANCHING];
    for (c, s) in octant_slots(&aabb, children).into_iter().enumerate().take(children.len()) {
        by_slot[s] = Some(c);
    }
    // Leaf children: the count in unary in the top 3 bits, the offset of
    // the first primitive from primitive_base_idx below. Inner children:
    // 001 then 24 + slot; their nodes follow in slot order.
    let mut inner_slots = [0usize; BRANCHING];
    let mut inner = 0;
    for (s, c) in by_slot.iter().enumerate() {
        let Some(c) = *c else { continue };
        let child = &children[c];
        quantize_child(&mut wide, s, &child.bounds, &aabb, e);
        if is_leaf(child) {
            wide.child_meta[s] = offsets[c] | ((1u8 << child.len()) - 1) << 5;
        } else {
            wide.imask |= 1 << s;
            wide.child_meta[s] = (24 + s as u8) | 0b0010_0000;
            inner_slots[c] = nodes.len() + inner;
            inner += 1;
        }
    }
    nodes.resize(nodes.len() + inner, CwBvhNode::default());
    nodes[slot] = wide;
    let mut inner = (0..children.len()).filter(|&c| !is_leaf(&children[c])).map(|c| (c, moved[c], inner_slots[c]));
    std::array::from_fn(|_| inner.next())
}

fn is_leaf(c: &Range) -> bool {
    c.len() <= MAX_LEAF_PRIMS
}

/// CWBVH addresses a node's leaf primitives by offsets 0..24 from
/// primitive_base_idx, so this moves the leaf children's primitives to the
/// front of the node's range and the inner children's ranges up behind
/// them, each as a block. Returns the children's ranges after the move and
/// each leaf child's offset.
fn leaves_first(refs: &mut [PrimRef], children: &[Range]) -> ([Range; BRANCHING], [u8; BRANCHING]) {
    let first = children[0].start;
    let mut leaf_prims = [refs[first]; BRANCHING * MAX_LEAF_PRIMS];
    let mut leaf_count = 0;
    for c in children.iter().filter(|c| is_leaf(c)) {
        leaf_prims[leaf_count..leaf_count + c.len()].copy_from_slice(&refs[c.start..c.end]);
        leaf_count += c.len();
    }
    let leaf_prims = &leaf_prims[..leaf_count];
    let mut moved = [children[0]; BRANCHING];
    moved[..children.len()].copy_from_slice(children);
    let mut next = first + leaf_prims.len();
    let mut offsets = [0u8; BRANCHING];
    let mut leaf_offset = 0;
    for (c, child) in moved[..children.len()].iter_mut().enumerate() {
        if is_leaf(child) {
            offsets[c] = leaf_offset as u8;
            leaf_offset += child.len();
        } else {
            let len = child.len();
            (child.start, child.end) = (next, next + len);
            next += len;
        }
    }
    // Later blocks first: each moves up (or stays), onto space already free.
    for (old, new) in children.iter().zip(&moved).rev().filter(|(c, _)| !is_leaf(c)) {
        refs.copy_within(old.start..old.end, new.start);
    }
    refs[first..first + leaf_prims.len()].copy_from_slice(leaf_prims);
    (moved, offsets)
}

/// Writes box `b` of the child in slot `s` of `wide` (box `node`, grid step
/// `e`), rounded outward on the grid of power-of-two step, so the
/// dequantized box p + q e holds the child's box (up to the rounding of
/// b - p that `intersect_node`'s slack covers).
fn quantize_child(wide: &mut CwBvhNode, s: usize, b: &Aabb, node: &Aabb, e: Vec3A) {
    let rcp_e = 1.0 / e;
    let lo = ((b.min - node.min) * rcp_e).floor().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
    let hi = ((b.max - node.min) * rcp_e).ceil().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
    wide.child_min_x[s] = lo.x as u8;
    wide.child_min_y[s] = lo.y as u8;
    wide.child_min_z[s] = lo.z as u8;
    wide.child_max_x[s] = hi.x as u8;
    wide.child_max_y[s] = hi.y as u8;
    wide.child_max_z[s] = hi.z as u8;
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

/// A pair's cost as `octant_slots` ranks it: -0.0 as +0.0, and a NaN (a
/// centre past f32's range: inf - inf) as +inf, the worst, tied with
/// other infinite costs by (child, slot).
fn octant_cost(dot: f32) -> f32 {
    if dot.is_nan() {
        f32::INFINITY
    } else {
        dot + 0.0
    }
}

/// Assigns the children to the 8 slots by ray octant (Ylitie et al. 2017,
/// sec. 3.2, "ordering the children"), as obvhs's `order_children`: the cost
/// of child c in slot s is the dot product of octant s's diagonal direction
/// with the vector from the node's centre to c's centre, and the cheapest
/// (child, free slot) pair is taken until all are placed (greedy; the paper
/// suggests an auction, obvhs found greedy almost as good), the first
/// (child, slot) in order on ties, a NaN cost as infinite. A ray of
/// octant s then visits the children in slot order xor s roughly front to
/// back. Returns each child's slot (the first `children.len()` entries).
fn octant_slots(node: &Aabb, children: &[Range]) -> [usize; BRANCHING] {
    let centre = node.center();
    // Pair (c, s) as a key that orders by cost, then c, then s: the cost
    // (`octant_cost`) in total_cmp's order as an integer above the pair's
    // index c * 8 + s. Slot
    // s's direction: bit 2 of s negates x, bit 1 y, bit 0 z, matching the
    // traversal's oct_inv4. Taken rows and columns are i64::MAX.
    let sign = |s: usize, bit: usize| if s & bit != 0 { -1.0 } else { 1.0 };
    let mut keys = [i64::MAX; BRANCHING * BRANCHING];
    for (c, child) in children.iter().enumerate() {
        let v = child.bounds.center() - centre;
        for s in 0..BRANCHING {
            let cost = octant_cost(Vec3A::new(sign(s, 0b100), sign(s, 0b010), sign(s, 0b001)).dot(v));
            keys[c * BRANCHING + s] = (total_order_key(cost) as i64) << 32 | (c * BRANCHING + s) as i64;
        }
    }
    let mut slot_of = [0; BRANCHING];
    for _ in 0..children.len() {
        // A branch-free minimum over all 64 keys (vectorised).
        let pair = (keys.iter().fold(i64::MAX, |a, &k| a.min(k)) & 63) as usize;
        let (c, s) = (pair / BRANCHING, pair % BRANCHING);
        slot_of[c] = s;
        for k in 0..BRANCHING {
            keys[c * BRANCHING + k] = i64::MAX;
            keys[k * BRANCHING + s] = i64::MAX;
        }
    }
    slot_of
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantization_step_covers_the_extent() {
        for x in [0.0f32, 1e-30, 1.0, 255.0, 255.0 * 4.0, 255.0f32.next_up() * 4.0, 3.7e5, 1e30] {
            let e = quantization_step(Vec3A::splat(x));
            assert!(e.x * 255.0 >= x && e.x.to_bits() & 0x807f_ffff == 0, "{x}: {e}");
            assert!(x == 0.0 || e.x * 127.5 < x.max(1e-20), "{x}: {e} not the smallest");
        }
    }

    /// The greedy assignment as a plain search, each step the cheapest free
    /// (child, slot) pair under `<`, the first in (child, slot) order on
    /// ties: what `octant_slots` computes with integer keys.
    fn greedy_by_search(node: &Aabb, children: &[Range]) -> Vec<usize> {
        let sign = |s: usize, bit: usize| if s & bit != 0 { -1.0 } else { 1.0 };
        let cost = |c: usize, s: usize| {
            let v = children[c].bounds.center() - node.center();
            let dot = Vec3A::new(sign(s, 0b100), sign(s, 0b010), sign(s, 0b001)).dot(v);
            if dot.is_nan() {
                f32::INFINITY
            } else {
                dot
            }
        };
        let mut slot_of = vec![usize::MAX; children.len()];
        let mut filled = [false; BRANCHING];
        for _ in 0..children.len() {
            let mut best: Option<(usize, usize, f32)> = None;
            for c in (0..children.len()).filter(|&c| slot_of[c] == usize::MAX) {
                for s in (0..BRANCHING).filter(|&s| !filled[s]) {
                    if best.is_none_or(|(_, _, b)| cost(c, s) < b) {
                        best = Some((c, s, cost(c, s)));
                    }
                }
            }
            let (c, s, _) = best.unwrap();
            (filled[s], slot_of[c]) = (true, s);
        }
        slot_of
    }

    /// Random children, children on a lattice of few values, whose costs
    /// tie (zeros of both signs among them), and children out to 2.5e38,
    /// whose centres overflow (infinite and NaN costs), 1 to 8 of them.
    #[test]
    fn octant_slots_is_the_greedy_assignment() {
        let mut next = crate::wide_bvh::tests::uniform(5);
        for trial in 0..3000 {
            let mut point = || {
                let v = Vec3A::new(next(), next(), next());
                match trial % 3 {
                    0 => v * 8.0 - 4.0,
                    1 => (v * 3.0).floor() - 1.0,
                    _ => ((v * 3.0).floor() - 1.0) * 2.5e38,
                }
            };
            let children: Vec<Range> = (0..1 + trial % BRANCHING)
                .map(|i| {
                    let (a, b) = (point(), point());
                    let bounds = Aabb::new(a.min(b), a.max(b));
                    Range { start: i, end: i + 1, bounds, centroids: bounds }
                })
                .collect();
            let node = children.iter().fold(Aabb::empty(), |a, c| a.union(&c.bounds));
            let slots = octant_slots(&node, &children)[..children.len()].to_vec();
            assert_eq!(slots, greedy_by_search(&node, &children), "{children:?}");
            let mut distinct = slots.clone();
            distinct.sort_unstable();
            distinct.dedup();
            assert_eq!(distinct.len(), children.len());
        }
    }
}
