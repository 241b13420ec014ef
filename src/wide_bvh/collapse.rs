//! The SAH-optimal collapse of a small binary SAH tree into 8-wide nodes.

use super::node::emit;
use super::sah::{sah_split, split_in_two};
use super::{PrimRef, Range, BRANCHING, MAX_LEAF_PRIMS, SAH_DEPTH};
use obvhs::cwbvh::node::CwBvhNode;

/// Ylitie et al. 2017's SAH-optimal collapse of a binary BVH into 8-wide
/// nodes by dynamic programming over the SAH cost, here over a local binary SAH tree of at most
/// `OPTIMAL_PRIMS` primitives, so the table stays small. `cost[n][i - 1]` is
/// the least cost of binary node n's subtree spread over at most i child
/// slots of a wide node:
///
/// - C(n, 1) = min(C_leaf(n), C_inner(n)), C_leaf(n) = A(n) N(n) c_prim for
///   N(n) <= 3 (else infinite), C_inner(n) = A(n) c_node + D(n, 8);
/// - C(n, i) = min(C(n, i - 1), D(n, i)) for i > 1;
/// - D(n, j) = min over 0 < k < j of C(left, k) + C(right, j - k).
pub(super) struct Collapse {
    nodes: Vec<BinaryNode>,
    cost: Vec<[f32; BRANCHING]>,
    /// How C(n, i) was reached (index i - 1).
    choice: Vec<[Choice; BRANCHING]>,
    /// The best k of D(n, j) (index j - 1; j = 8 for C_inner).
    split: Vec<[u8; BRANCHING]>,
}

#[derive(Clone, Copy, Debug)]
struct BinaryNode {
    range: Range,
    /// Indices of the two children; None for a single primitive.
    children: Option<[usize; 2]>,
    depth: u32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Choice {
    Leaf,
    Inner,
    FewerSlots,
    Distribute,
}

/// SAH cost of a wide node test relative to a triangle test (as obvhs; the
/// instruction counts here are ~150 per node and ~50 per triangle).
const NODE_COST: f32 = 1.0;
const PRIM_COST: f32 = 0.3;

/// Subtrees of at most this many primitives are collapsed optimally.
pub(super) const OPTIMAL_PRIMS: usize = 256;

impl Collapse {
    /// The binary SAH tree over `refs` (all of `root`), partitioned in place,
    /// and its table; node 0 is the root, children follow their parents.
    pub(super) fn new(refs: &mut [PrimRef], root: Range) -> Self {
        // (A binary tree over n primitives has 2 n - 1 nodes.)
        let mut nodes = Vec::with_capacity(2 * root.len() - 1);
        nodes.push(BinaryNode { range: root, children: None, depth: 0 });
        let mut i = 0;
        while i < nodes.len() {
            let BinaryNode { range, depth, .. } = nodes[i];
            if range.len() > 1 {
                let split = if depth < SAH_DEPTH { sah_split(refs, &range) } else { None };
                let (left, right) = split_in_two(refs, &range, split);
                nodes[i].children = Some([nodes.len(), nodes.len() + 1]);
                nodes.push(BinaryNode { range: left, children: None, depth: depth + 1 });
                nodes.push(BinaryNode { range: right, children: None, depth: depth + 1 });
            }
            i += 1;
        }
        let n = nodes.len();
        let mut table = Self {
            nodes,
            cost: vec![[0.0; BRANCHING]; n],
            choice: vec![[Choice::Leaf; BRANCHING]; n],
            // k = 1 is a split of every j >= 2; it stays where no cost is
            // finite (boxes whose area passes f32's range), which would
            // otherwise leave k = 0 and a slot -1 to `distribute`.
            split: vec![[1; BRANCHING]; n],
        };
        for i in (0..n).rev() {
            table.fill(i);
        }
        table
    }

    /// Row `n` of the table, from its children's rows.
    fn fill(&mut self, n: usize) {
        let range = self.nodes[n].range;
        let area = range.bounds.half_area();
        let leaf = if range.len() <= MAX_LEAF_PRIMS { area * range.len() as f32 * PRIM_COST } else { f32::INFINITY };
        let Some([l, r]) = self.nodes[n].children else {
            self.cost[n] = [leaf; BRANCHING];
            self.choice[n] = [Choice::Leaf; BRANCHING];
            return;
        };
        // D(n, j) for j = 2..=8 at index j - 1, the least k on ties. A
        // cost (not negative; infinite or NaN past f32's range) and k as
        // one integer key, the cost's bits above k's, so the least key is
        // the least cost (under `<`: a NaN never wins) then k, found with
        // integer minima, not branches on data.
        let (left, right) = (self.cost[l], self.cost[r]);
        let mut distribute = [f32::INFINITY; BRANCHING];
        for j in 2..=BRANCHING {
            let key = |c: f32, k: usize| u64::from(c.to_bits()) << 8 | k as u64;
            let best = (1..j).map(|k| key(left[k - 1] + right[j - k - 1], k)).fold(key(f32::INFINITY, 1), u64::min);
            distribute[j - 1] = f32::from_bits((best >> 8) as u32);
            self.split[n][j - 1] = best as u8;
        }
        let inner = area * NODE_COST + distribute[BRANCHING - 1];
        // (A leaf of too many primitives costs infinity, as may an inner
        // node whose area overflows: the tie goes to the inner node.)
        let fits = range.len() <= MAX_LEAF_PRIMS;
        let (mut cost, mut choice) = if fits && leaf <= inner { (leaf, Choice::Leaf) } else { (inner, Choice::Inner) };
        self.cost[n][0] = cost;
        self.choice[n][0] = choice;
        for i in 2..BRANCHING {
            if distribute[i - 1] < cost {
                (cost, choice) = (distribute[i - 1], Choice::Distribute);
            } else {
                choice = Choice::FewerSlots;
            }
            self.cost[n][i - 1] = cost;
            self.choice[n][i - 1] = choice;
        }
    }

    /// The binary nodes that fill the slots of D(n, j).
    fn distribute(&self, n: usize, j: usize, out: &mut Vec<usize>) {
        let [l, r] = self.nodes[n].children.expect("only inner nodes distribute");
        let k = self.split[n][j - 1] as usize;
        self.slots(l, k, out);
        self.slots(r, j - k, out);
    }

    /// The binary nodes that fill the slots of C(n, i).
    fn slots(&self, n: usize, i: usize, out: &mut Vec<usize>) {
        match self.choice[n][i - 1] {
            Choice::Leaf | Choice::Inner => out.push(n),
            Choice::FewerSlots => self.slots(n, i - 1, out),
            Choice::Distribute => self.distribute(n, i, out),
        }
    }

    /// Emits binary node `n` as the wide node in `nodes[slot]` (C_inner,
    /// or a leaf child of its own for a root of at most 3 primitives), then
    /// its inner children. `shift`: how far `emit` has moved `n`'s
    /// primitives since the table was made.
    pub(super) fn emit_subtree(
        &self,
        refs: &mut [PrimRef],
        base: usize,
        n: usize,
        shift: usize,
        slot: usize,
        nodes: &mut Vec<CwBvhNode>,
    ) {
        // An inner child has more than 3 primitives, so C_inner; the root
        // of a subtree of 2 or 3 also spreads them over slots: D(n, 8) is
        // at most C_leaf(n), as the children's boxes are no larger.
        let mut members = Vec::with_capacity(BRANCHING);
        if self.nodes[n].children.is_some() {
            self.distribute(n, BRANCHING, &mut members);
        } else {
            members.push(n);
        }
        let moved = |r: Range| Range { start: r.start + shift, end: r.end + shift, ..r };
        let children: [Range; BRANCHING] =
            std::array::from_fn(|c| moved(self.nodes[members[c.min(members.len() - 1)]].range));
        let bounds = self.nodes[n].range.bounds;
        for (c, child, child_slot) in
            emit(refs, base, bounds, &children[..members.len()], slot, nodes).into_iter().flatten()
        {
            let m = members[c];
            self.emit_subtree(refs, base, m, child.start - self.nodes[m].range.start, child_slot, nodes);
        }
    }
}
