//! The 8-wide BVH builder: binned SAH, straight into compressed wide nodes.
//!
//! Above `OPTIMAL_PRIMS` primitives the build is top-down, as Embree's BVH8
//! builder (Wald et al. 2014, "Embree: A Kernel Framework for Efficient CPU
//! Ray Tracing", sec. 4): a wide node starts as one child holding all its
//! primitives and repeatedly splits its child with the largest surface area
//! in two until it has 8 children. Each split is the binned SAH split of Wald
//! 2007 ("On fast Construction of SAH-based Bounding Volume Hierarchies",
//! sec. 3, 32 bins), on the three centroid axes and on a fourth axis of size
//! classes (see `Grid`); ranges of at most 16 primitives are swept exactly.
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

use glam::{BVec4A, Vec3A, Vec4};
use obvhs::{
    aabb::Aabb,
    cwbvh::{node::CwBvhNode, CwBvh},
};
use rayon::prelude::*;

/// Children per wide node.
const BRANCHING: usize = 8;

/// Primitives per leaf child: the child meta byte holds the count in unary in
/// its top 3 bits (Ylitie et al. 2017, sec. 3.1).
pub const MAX_LEAF_PRIMS: usize = 3;

/// Bins per axis for the binned SAH.
const BINS: usize = 32;

/// Nodes over at least this many primitives build their inner children as
/// rayon tasks.
const PARALLEL_SUBTREES: usize = 4096;

/// Ranges of at least twice this many primitives are binned in parallel
/// chunks of this size.
const PARALLEL_CHUNK: usize = 32 * 1024;

/// Below this many levels (wide ones above `OPTIMAL_PRIMS`, binary ones
/// below) the builder splits by SAH; deeper, by object median, which halves
/// every range, so a pathological input (centroids spaced exponentially,
/// where each SAH split peels off a few primitives) still gives a tree of
/// logarithmic depth and a bounded recursion.
const SAH_DEPTH: u32 = 32;

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
    let mut jobs = Vec::with_capacity(inner.len());
    for (_, child, child_slot) in inner {
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

/// `range` split by `split`, or at its middle (object median) if None.
fn split_in_two(refs: &mut [PrimRef], range: &Range, split: Option<Split>) -> (Range, Range) {
    match split {
        Some(s) => partition(refs, range, &s),
        None => {
            let mid = range.start + range.len() / 2;
            (Range::of(refs, range.start, mid), Range::of(refs, mid, range.end))
        }
    }
}

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
struct Collapse {
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
const OPTIMAL_PRIMS: usize = 256;

impl Collapse {
    /// The binary SAH tree over `refs` (all of `root`), partitioned in place,
    /// and its table; node 0 is the root, children follow their parents.
    fn new(refs: &mut [PrimRef], root: Range) -> Self {
        let mut nodes = vec![BinaryNode { range: root, children: None, depth: 0 }];
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
            split: vec![[0; BRANCHING]; n],
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
        // D(n, j) for j = 2..=8 at index j - 1.
        let mut distribute = [f32::INFINITY; BRANCHING];
        for j in 2..=BRANCHING {
            for k in 1..j {
                let c = self.cost[l][k - 1] + self.cost[r][j - k - 1];
                if c < distribute[j - 1] {
                    distribute[j - 1] = c;
                    self.split[n][j - 1] = k as u8;
                }
            }
        }
        let inner = area * NODE_COST + distribute[BRANCHING - 1];
        let (mut cost, mut choice) = if leaf <= inner { (leaf, Choice::Leaf) } else { (inner, Choice::Inner) };
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
    fn emit_subtree(
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
        let children: Vec<Range> = members.iter().map(|&m| moved(self.nodes[m].range)).collect();
        let bounds = self.nodes[n].range.bounds;
        for (c, child, child_slot) in emit(refs, base, bounds, &children, slot, nodes) {
            let m = members[c];
            self.emit_subtree(refs, base, m, child.start - self.nodes[m].range.start, child_slot, nodes);
        }
    }
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

/// A SAH split: the primitives below the plane on `axis` go left.
#[derive(Clone, Copy, Debug)]
struct Split {
    axis: usize,
    plane: Plane,
    cost: f32,
}

#[derive(Clone, Copy, Debug)]
enum Plane {
    /// Binned: a bin below `bin` of `grid`.
    Bin { grid: Grid, bin: usize },
    /// Swept: a key (`sweep_key`) below this one.
    Key(f32),
}

impl Split {
    #[inline(always)]
    fn goes_left(&self, p: &PrimRef) -> bool {
        match self.plane {
            Plane::Bin { grid, bin } => grid.bin(p, self.axis) < bin,
            Plane::Key(key) => sweep_key(p, self.axis) < key,
        }
    }
}

/// Bins on 3 spatial axes and one of size. The spatial bins are Wald's
/// (2007): the (doubled) centroid's cell on a grid of `BINS` over the
/// centroids' bounds. The size axis classes primitives by octave of their
/// box's surface area relative to the range's (bin k: 2^-k-1 < ratio <=
/// 2^-k): a plane through the centroids cannot cut large primitives that
/// enclose small ones from them (the walls of a room around its furniture,
/// whose centroids lie on all sides of it), while a size split can, and the
/// SAH takes it only where it is cheaper.
#[derive(Clone, Copy, Debug)]
struct Grid {
    origin: Vec3A,
    scale: Vec3A,
    /// 1 / the range's half area; 0 for a flat range (size bin 0).
    rcp_area: f32,
}

/// Bin axes: x, y, z and size.
const AXES: usize = 4;

impl Grid {
    fn new(range: &Range) -> Self {
        let extent = range.centroids.max - range.centroids.min;
        // Just under BINS / extent, so the largest centroid lands in the last
        // bin; zero on a flat axis (every centroid in bin 0).
        let scale = Vec3A::select(extent.cmpgt(Vec3A::ZERO), (BINS as f32 * 0.9999) / extent, Vec3A::ZERO);
        let area = range.bounds.half_area();
        Self { origin: range.centroids.min, scale, rcp_area: if area > 0.0 { 1.0 / area } else { 0.0 } }
    }

    #[inline(always)]
    fn bins(&self, p: &PrimRef) -> [usize; AXES] {
        let b = p.bounds();
        let c = ((b.min + b.max - self.origin) * self.scale).min(Vec3A::splat((BINS - 1) as f32));
        // The octave from the float's exponent: 127 - exponent of a ratio
        // in (0, 1]; a zero ratio (or a flat range) in the last bin / bin 0.
        let ratio = b.half_area() * self.rcp_area;
        let octave = 127i32.saturating_sub((ratio.to_bits() >> 23) as i32).clamp(0, BINS as i32 - 1);
        [c.x as usize, c.y as usize, c.z as usize, octave as usize]
    }

    /// The bin of `p` on one axis, as `bins` computes it.
    #[inline(always)]
    fn bin(&self, p: &PrimRef, axis: usize) -> usize {
        self.bins(p)[axis]
    }

    /// Whether the size axis can separate anything (else only 3 are binned).
    fn sized(&self) -> bool {
        self.rcp_area > 0.0
    }
}

#[derive(Clone, Copy)]
struct Bins {
    bounds: [[Aabb; BINS]; AXES],
    counts: [[u32; BINS]; AXES],
}

impl Bins {
    fn empty() -> Self {
        Self { bounds: [[Aabb::empty(); BINS]; AXES], counts: [[0; BINS]; AXES] }
    }

    fn fill(refs: &[PrimRef], grid: &Grid) -> Self {
        let mut bins = Self::empty();
        for p in refs {
            let b = p.bounds();
            for (axis, bin) in grid.bins(p).into_iter().enumerate() {
                bins.bounds[axis][bin] = bins.bounds[axis][bin].union(&b);
                bins.counts[axis][bin] += 1;
            }
        }
        bins
    }

    /// Exact in any order (min, max and integer sums), so parallel binning
    /// gives the serial result.
    fn merge(mut self, other: Self) -> Self {
        for axis in 0..AXES {
            for bin in 0..BINS {
                self.bounds[axis][bin] = self.bounds[axis][bin].union(&other.bounds[axis][bin]);
                self.counts[axis][bin] += other.counts[axis][bin];
            }
        }
        self
    }
}

/// Ranges of at most this many primitives are split by a full SAH sweep
/// over the sorted keys (exact), larger ones by binning.
const SWEEP_PRIMS: usize = 16;

/// The cheapest SAH split of `range`, or None if neither a plane nor a size
/// class separates its primitives (all centroids coincide and all sizes are
/// alike).
fn sah_split(refs: &[PrimRef], range: &Range) -> Option<Split> {
    let refs = &refs[range.start..range.end];
    if refs.len() <= SWEEP_PRIMS {
        swept_split(refs)
    } else {
        binned_split(refs, range)
    }
}

fn binned_split(refs: &[PrimRef], range: &Range) -> Option<Split> {
    let grid = Grid::new(range);
    let bins = if refs.len() >= 2 * PARALLEL_CHUNK {
        refs.par_chunks(PARALLEL_CHUNK).map(|c| Bins::fill(c, &grid)).reduce(Bins::empty, Bins::merge)
    } else {
        Bins::fill(refs, &grid)
    };
    let mut best: Option<Split> = None;
    for axis in 0..AXES {
        if if axis < 3 { grid.scale[axis] == 0.0 } else { !grid.sized() } {
            continue;
        }
        // right_cost[b]: area x count of bins b.. (the right side of a plane
        // before bin b).
        let mut right_cost = [0.0f32; BINS];
        let (mut bounds, mut count) = (Aabb::empty(), 0u32);
        for b in (1..BINS).rev() {
            bounds = bounds.union(&bins.bounds[axis][b]);
            count += bins.counts[axis][b];
            right_cost[b] = if count == 0 { f32::INFINITY } else { bounds.half_area() * count as f32 };
        }
        let (mut bounds, mut count) = (Aabb::empty(), 0u32);
        for (b, right) in right_cost.iter().enumerate().skip(1) {
            bounds = bounds.union(&bins.bounds[axis][b - 1]);
            count += bins.counts[axis][b - 1];
            if count == 0 {
                continue;
            }
            let cost = bounds.half_area() * count as f32 + right;
            if best.is_none_or(|s| cost < s.cost) {
                best = Some(Split { axis, plane: Plane::Bin { grid, bin: b }, cost });
            }
        }
    }
    best.filter(|s| s.cost.is_finite())
}

/// What a sweep sorts by: the (doubled) centroid on axes 0-2, the box's
/// half area on axis 3 (the size axis).
#[inline(always)]
fn sweep_key(p: &PrimRef, axis: usize) -> f32 {
    let b = p.bounds();
    if axis < 3 {
        (b.min + b.max)[axis]
    } else {
        b.half_area()
    }
}

/// The full SAH sweep of a small range: on each axis the primitives sorted
/// by key, every plane between two distinct keys.
fn swept_split(refs: &[PrimRef]) -> Option<Split> {
    let n = refs.len();
    let mut best: Option<Split> = None;
    let mut order = [(0.0f32, 0usize); SWEEP_PRIMS];
    let mut right_cost = [0.0f32; SWEEP_PRIMS];
    for axis in 0..AXES {
        for (i, p) in refs.iter().enumerate() {
            order[i] = (sweep_key(p, axis), i);
        }
        order[..n].sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut bounds = Aabb::empty();
        for i in (1..n).rev() {
            bounds = bounds.union(&refs[order[i].1].bounds());
            right_cost[i] = bounds.half_area() * (n - i) as f32;
        }
        let mut bounds = Aabb::empty();
        for i in 1..n {
            bounds = bounds.union(&refs[order[i - 1].1].bounds());
            if order[i - 1].0 == order[i].0 {
                continue;
            }
            let cost = bounds.half_area() * i as f32 + right_cost[i];
            if best.is_none_or(|s| cost < s.cost) {
                best = Some(Split { axis, plane: Plane::Key(order[i].0), cost });
            }
        }
    }
    best
}

/// Partitions `range` in place by `split` (Hoare's scheme: deterministic,
/// each primitive classified once) and returns both sides with their bounds.
fn partition(refs: &mut [PrimRef], range: &Range, split: &Split) -> (Range, Range) {
    let empty = |start, end| Range { start, end, bounds: Aabb::empty(), centroids: Aabb::empty() };
    let (mut left, mut right) = (empty(range.start, range.start), empty(range.end, range.end));
    let (mut i, mut j) = (range.start, range.end);
    while i < j {
        if split.goes_left(&refs[i]) {
            left.grow(&refs[i]);
            i += 1;
        } else {
            j -= 1;
            refs.swap(i, j);
            right.grow(&refs[j]);
        }
    }
    left.end = i;
    right.start = i;
    (left, right)
}

/// Writes the wide node with box `aabb` and `children` (ranges of `refs`
/// in memory order, covering the node's) into `nodes[slot]`: slots by ray
/// octant, quantized boxes, metadata; reserves nodes for its inner
/// children. CWBVH addresses a node's leaf primitives by offsets 0..24
/// from primitive_base_idx, so the leaf children's primitives are moved to
/// the front of the node's range and the inner children's ranges up behind them, each as a
/// block. Returns the inner children (index, moved range, reserved slot) in
/// memory order.
fn emit(
    refs: &mut [PrimRef],
    base: usize,
    aabb: Aabb,
    children: &[Range],
    slot: usize,
    nodes: &mut Vec<CwBvhNode>,
) -> Vec<(usize, Range, usize)> {
    let is_leaf = |c: &Range| c.len() <= MAX_LEAF_PRIMS;
    let first = children[0].start;
    let leaf_prims: Vec<PrimRef> =
        children.iter().filter(|c| is_leaf(c)).flat_map(|c| refs[c.start..c.end].iter().copied()).collect();
    let mut moved = children.to_vec();
    let mut next = first + leaf_prims.len();
    let mut offsets = [0u8; BRANCHING];
    let mut leaf_offset = 0;
    for (c, child) in moved.iter_mut().enumerate() {
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
    refs[first..first + leaf_prims.len()].copy_from_slice(&leaf_prims);

    let slot_of = octant_slots(&aabb, children);
    let e = quantization_step(aabb.max - aabb.min);
    let rcp_e = 1.0 / e;
    let mut wide = CwBvhNode {
        p: aabb.min.into(),
        e: e.to_array().map(|c| (c.to_bits() >> 23) as u8),
        child_base_idx: nodes.len() as u32,
        primitive_base_idx: (base + first) as u32,
        ..CwBvhNode::default()
    };
    let mut by_slot: [Option<usize>; BRANCHING] = [None; BRANCHING];
    for (c, &s) in slot_of.iter().enumerate() {
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
        // Rounded outward on a grid of power-of-two step, so the dequantized
        // box p + q e holds the child's box (up to the rounding of b - p
        // that `intersect_node`'s slack covers).
        let b = child.bounds;
        let lo = ((b.min - aabb.min) * rcp_e).floor().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
        let hi = ((b.max - aabb.min) * rcp_e).ceil().clamp(Vec3A::ZERO, Vec3A::splat(255.0));
        wide.child_min_x[s] = lo.x as u8;
        wide.child_min_y[s] = lo.y as u8;
        wide.child_min_z[s] = lo.z as u8;
        wide.child_max_x[s] = hi.x as u8;
        wide.child_max_y[s] = hi.y as u8;
        wide.child_max_z[s] = hi.z as u8;
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
    (0..children.len()).filter(|&c| !is_leaf(&children[c])).map(|c| (c, moved[c], inner_slots[c])).collect()
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
/// sec. 3.2, "ordering the children"), as obvhs's `order_children`: the cost
/// of child c in slot s is the dot product of octant s's diagonal direction
/// with the vector from the node's centre to c's centre, and the cheapest
/// (child, free slot) pair is taken until all are placed (greedy; the paper
/// suggests an auction, obvhs found greedy almost as good). A ray of octant
/// s then visits the children in slot order xor s roughly front to back.
/// Returns each child's slot.
fn octant_slots(node: &Aabb, children: &[Range]) -> Vec<usize> {
    let centre = node.center();
    // cost[c][s]; slot s's direction: bit 2 of s negates x, bit 1 y, bit 0
    // z, matching the traversal's oct_inv4.
    let sign = |s: usize, bit: usize| if s & bit != 0 { -1.0 } else { 1.0 };
    let mut cost = [[0.0f32; BRANCHING]; BRANCHING];
    for (row, child) in cost.iter_mut().zip(children) {
        let v = child.bounds.center() - centre;
        for (s, c) in row.iter_mut().enumerate() {
            *c = Vec3A::new(sign(s, 0b100), sign(s, 0b010), sign(s, 0b001)).dot(v);
        }
    }
    let mut slot_of = vec![usize::MAX; children.len()];
    let mut filled = [false; BRANCHING];
    for _ in 0..children.len() {
        let mut best: Option<(usize, usize, f32)> = None;
        for c in (0..children.len()).filter(|&c| slot_of[c] == usize::MAX) {
            for s in (0..BRANCHING).filter(|&s| !filled[s]) {
                if best.is_none_or(|(_, _, b)| cost[c][s] < b) {
                    best = Some((c, s, cost[c][s]));
                }
            }
        }
        let (c, s, _) = best.expect("a free slot for every child");
        filled[s] = true;
        slot_of[c] = s;
    }
    slot_of
}

#[cfg(test)]
mod tests {
    use super::*;

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
            assert_eq!(bvh.total_aabb.min, boxes.iter().fold(Aabb::empty(), |a, b| a.union(b)).min);
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
