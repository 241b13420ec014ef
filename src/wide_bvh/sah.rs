//! SAH splits of a range of primitives in two: binned (Wald 2007) on the
//! three centroid axes and on size classes, or swept exactly for small
//! ranges; and the in-place partition that applies one.

use super::{total_order_key, PrimRef, Range};
use glam::{BVec4A, Vec3A, Vec4};
use obvhs::aabb::Aabb;
use rayon::prelude::*;

/// Bins per axis for the binned SAH.
const BINS: usize = 32;

/// Ranges of at least twice this many primitives are binned in parallel
/// chunks of this size.
const PARALLEL_CHUNK: usize = 32 * 1024;

/// A SAH split: the primitives below the plane on `axis` go left.
#[derive(Clone, Copy, Debug)]
pub(super) struct Split {
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
            Plane::Bin { grid, bin } => grid.below(p, self.axis, bin),
            Plane::Key(key) => sweep_key(&p.bounds(), self.axis) < key,
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
        // (`& (BINS - 1)`, a no-op on [0, 31], spares the bounds checks.)
        let [x, y, z] = truncate(self.cells(&b)).map(|c| c as usize & (BINS - 1));
        [x, y, z, self.octave(&b)]
    }

    /// Whether the bin of `p` on one axis, as `bins` computes it, is below
    /// `bin`, without the other three axes: a partition asks this. A cell
    /// in [0, 31] is below a whole number exactly when its floor is.
    #[inline(always)]
    fn below(&self, p: &PrimRef, axis: usize, bin: usize) -> bool {
        let b = p.bounds();
        if axis < 3 {
            self.cells(&b)[axis] < bin as f32
        } else {
            self.octave(&b) < bin
        }
    }

    /// The (doubled) centroid's cell on each spatial axis, as floats in
    /// [0, 31] (a NaN, from centroids past f32's range, in 31).
    #[inline(always)]
    fn cells(&self, b: &Aabb) -> Vec3A {
        ((b.min + b.max - self.origin) * self.scale).min(Vec3A::splat((BINS - 1) as f32)).max(Vec3A::ZERO)
    }

    /// The size bin: the octave from the float's exponent, 127 - exponent
    /// of a ratio in (0, 1]; a zero ratio (or a flat range) in the last
    /// bin / bin 0.
    #[inline(always)]
    fn octave(&self, b: &Aabb) -> usize {
        let ratio = b.half_area() * self.rcp_area;
        127i32.saturating_sub((ratio.to_bits() >> 23) as i32).clamp(0, BINS as i32 - 1) as usize
    }

    /// Whether the size axis can separate anything (else only 3 are binned).
    fn sized(&self) -> bool {
        self.rcp_area > 0.0
    }
}

/// The lanes of `v`, each in [0, 31], truncated to integers, all three by
/// one instruction: Rust's `as` saturates lane by lane with branches for
/// NaN and overflow, which no cell needs, and floor is emulated in SSE2.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn truncate(v: Vec3A) -> [i32; 3] {
    use std::arch::x86_64::{_mm_cvtsi128_si32, _mm_cvttps_epi32, _mm_shuffle_epi32};
    // SAFETY: these intrinsics only need SSE2, which every x86-64 CPU has
    // (it is part of the x86-64 baseline target); none touches memory.
    unsafe {
        let i = _mm_cvttps_epi32(v.into());
        [
            _mm_cvtsi128_si32(i),
            _mm_cvtsi128_si32(_mm_shuffle_epi32::<1>(i)),
            _mm_cvtsi128_si32(_mm_shuffle_epi32::<2>(i)),
        ]
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn truncate(v: Vec3A) -> [i32; 3] {
    v.to_array().map(|c| c as i32)
}

/// Per bin, the four axes' boxes and counts side by side, as the
/// evaluation reads them.
#[derive(Clone, Copy)]
struct Bins {
    bounds: [[Aabb; AXES]; BINS],
    counts: [[u32; AXES]; BINS],
}

impl Bins {
    fn empty() -> Self {
        Self { bounds: [[Aabb::empty(); AXES]; BINS], counts: [[0; AXES]; BINS] }
    }

    fn fill(refs: &[PrimRef], grid: &Grid) -> Self {
        let mut bins = Self::empty();
        for p in refs {
            let b = p.bounds();
            for (axis, bin) in grid.bins(p).into_iter().enumerate() {
                bins.bounds[bin][axis] = bins.bounds[bin][axis].union(&b);
                bins.counts[bin][axis] += 1;
            }
        }
        bins
    }

    /// Exact in any order (min, max and integer sums), so parallel binning
    /// gives the serial result.
    fn merge(mut self, other: Self) -> Self {
        for bin in 0..BINS {
            for axis in 0..AXES {
                self.bounds[bin][axis] = self.bounds[bin][axis].union(&other.bounds[bin][axis]);
                self.counts[bin][axis] += other.counts[bin][axis];
            }
        }
        self
    }
}

/// One side of a plane on each of the four axes: the union of its bins and
/// their count.
#[derive(Clone, Copy)]
struct Side {
    bounds: [Aabb; AXES],
    count: [u32; AXES],
}

impl Side {
    fn empty() -> Self {
        Self { bounds: [Aabb::empty(); AXES], count: [0; AXES] }
    }

    fn add(&mut self, bins: &Bins, bin: usize) {
        for axis in 0..AXES {
            self.bounds[axis] = self.bounds[axis].union(&bins.bounds[bin][axis]);
            self.count[axis] += bins.counts[bin][axis];
        }
    }

    /// Half area x count on each axis, the four side by side in one vector;
    /// the area as `Aabb::half_area` computes it, (d.x + d.y) d.z + d.x d.y,
    /// so the costs are those of a side at a time, to the bit.
    fn cost(&self) -> Vec4 {
        let d = self.bounds.map(|b| b.diagonal());
        let lane = |c: usize| Vec4::from_array(d.map(|d| d[c]));
        let (x, y, z) = (lane(0), lane(1), lane(2));
        ((x + y) * z + x * y) * Vec4::from_array(self.count.map(|c| c as f32))
    }

    fn nonempty(&self) -> BVec4A {
        BVec4A::from(self.count.map(|c| c != 0))
    }
}

/// Ranges of at most this many primitives are split by a full SAH sweep
/// over the sorted keys (exact), larger ones by binning.
const SWEEP_PRIMS: usize = 16;

/// The cheapest SAH split of `range`, or None if neither a plane nor a size
/// class separates its primitives (all centroids coincide and all sizes are
/// alike).
pub(super) fn sah_split(refs: &[PrimRef], range: &Range) -> Option<Split> {
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
    // The four axes side by side; an axis that separates nothing (flat, or
    // all of a size) takes no part. right_cost[b]: area x count of bins b..
    // (the right side of a plane before bin b), infinite if empty.
    let scale = grid.scale;
    let usable = BVec4A::new(scale.x > 0.0, scale.y > 0.0, scale.z > 0.0, grid.sized());
    let mut right_cost = [Vec4::ZERO; BINS];
    let mut right = Side::empty();
    for b in (1..BINS).rev() {
        right.add(&bins, b);
        right_cost[b] = Vec4::select(right.nonempty(), right.cost(), Vec4::INFINITY);
    }
    // Each axis's cheapest plane, the first on ties. (Not a cost past f32's
    // range: a NaN, once kept, would stay.)
    let (mut best_cost, mut best_bin) = (Vec4::INFINITY, Vec4::ZERO);
    let mut left = Side::empty();
    for (b, right) in right_cost.iter().enumerate().skip(1) {
        left.add(&bins, b - 1);
        let cost = left.cost() + *right;
        let better = usable & left.nonempty() & cost.is_finite_mask() & cost.cmplt(best_cost);
        best_cost = Vec4::select(better, cost, best_cost);
        best_bin = Vec4::select(better, Vec4::splat(b as f32), best_bin);
    }
    // The cheapest of the axes', the first on ties (bin 0: no plane).
    let mut best: Option<Split> = None;
    for axis in 0..AXES {
        let (cost, bin) = (best_cost[axis], best_bin[axis] as usize);
        if bin > 0 && best.is_none_or(|s| cost < s.cost) {
            best = Some(Split { axis, plane: Plane::Bin { grid, bin }, cost });
        }
    }
    best
}

/// What a sweep sorts by: the (doubled) centroid on axes 0-2, the box's
/// half area on axis 3 (the size axis).
#[inline(always)]
fn sweep_key(b: &Aabb, axis: usize) -> f32 {
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
    let mut boxes = [Aabb::empty(); SWEEP_PRIMS];
    let mut keys = [[0.0f32; AXES]; SWEEP_PRIMS];
    for ((b, k), p) in boxes.iter_mut().zip(&mut keys).zip(refs) {
        *b = p.bounds();
        *k = std::array::from_fn(|axis| sweep_key(b, axis));
    }
    let orders = sorted_orders(&keys, n);
    let mut best: Option<Split> = None;
    let mut right_cost = [0.0f32; SWEEP_PRIMS];
    for (axis, order) in orders.iter().enumerate() {
        let sorted = |i: usize| order[i] as usize;
        let mut bounds = Aabb::empty();
        for i in (1..n).rev() {
            bounds = bounds.union(&boxes[sorted(i)]);
            right_cost[i] = bounds.half_area() * (n - i) as f32;
        }
        let mut bounds = Aabb::empty();
        for i in 1..n {
            bounds = bounds.union(&boxes[sorted(i - 1)]);
            let key = keys[sorted(i)][axis];
            if keys[sorted(i - 1)][axis] == key {
                continue;
            }
            let cost = bounds.half_area() * i as f32 + right_cost[i];
            // (Not a cost past f32's range: a NaN, once kept, would stay.)
            if cost.is_finite() && best.is_none_or(|s| cost < s.cost) {
                best = Some(Split { axis, plane: Plane::Key(key), cost });
            }
        }
    }
    best
}

/// On each axis, the indices of `keys[..n]` sorted by key in
/// `f32::total_cmp`'s order, ties by index, found by counting each one's
/// rank: n^2 comparisons without a branch, the four axes side by side in
/// one vector, where a sort of 16 mispredicts.
fn sorted_orders(keys: &[[f32; AXES]; SWEEP_PRIMS], n: usize) -> [[u8; SWEEP_PRIMS]; AXES] {
    let mut ord = [[0i32; AXES]; SWEEP_PRIMS];
    for (o, k) in ord[..n].iter_mut().zip(keys) {
        *o = k.map(total_order_key);
    }
    let mut orders = [[0; SWEEP_PRIMS]; AXES];
    for i in 0..n {
        // A tie counts for j before i.
        let mut rank = [0u32; AXES];
        for (j, o) in ord[..n].iter().enumerate() {
            for a in 0..AXES {
                rank[a] += ((o[a] < ord[i][a]) | ((o[a] == ord[i][a]) & (j < i))) as u32;
            }
        }
        for (order, r) in orders.iter_mut().zip(rank) {
            order[r as usize] = i as u8;
        }
    }
    orders
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

/// `range` split by `split`, or at its middle (object median) if None.
pub(super) fn split_in_two(refs: &mut [PrimRef], range: &Range, split: Option<Split>) -> (Range, Range) {
    match split {
        Some(s) => partition(refs, range, &s),
        None => {
            let mid = range.start + range.len() / 2;
            (Range::of(refs, range.start, mid), Range::of(refs, mid, range.end))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sweep's best split has a finite cost: three slivers at x =
    /// -2e38, -1.5e38 and 2e38 make the first candidate's right box
    /// infinitely wide and flat, its area NaN, and a NaN once kept was
    /// never replaced (no cost is below it), so the two far ends shared a
    /// child (from an audit, session 50). The finite split keeps the
    /// two near ones together.
    #[test]
    fn a_sweep_passes_over_costs_past_f32s_range() {
        let sliver = |x: f32, i: u32| {
            let lo = Vec3A::new(x, 0.0, 0.0);
            PrimRef::new(Aabb::new(lo, lo + Vec3A::new(x.abs() * f32::EPSILON, 1e-13, 0.0)), i)
        };
        let refs = [sliver(-2e38, 0), sliver(-1.5e38, 1), sliver(2e38, 2)];
        let split = swept_split(&refs).expect("a finite split");
        assert!(split.cost.is_finite(), "{split:?}");
        assert!(matches!(split.plane, Plane::Key(k) if split.axis == 0 && k > 0.0), "{split:?}");
    }

    /// A partition classifies by `Grid::below`, the binning by `Grid::bins`:
    /// they must agree, or a split's two sides would not be the bins its
    /// cost was computed from. Boxes of every size class, flat and
    /// degenerate ones included, over a range's grid and over a sub-range's
    /// (where most boxes fall outside and clamp).
    #[test]
    fn one_axis_bin_matches_all_axes_bins() {
        let mut next = crate::wide_bvh::tests::uniform(7);
        let mut refs: Vec<PrimRef> = (0..4000)
            .map(|i| {
                let c = Vec3A::new(next(), next(), next()) * 10.0 - 5.0;
                let size = Vec3A::new(next(), next(), next()) * 2f32.powi(-(i % 24));
                PrimRef::new(Aabb::new(c, c + size), i as u32)
            })
            .collect();
        refs.push(PrimRef::new(Aabb::new(Vec3A::ZERO, Vec3A::new(1.0, 1.0, 0.0)), 4000));
        refs.push(PrimRef::new(Aabb::new(Vec3A::splat(0.5), Vec3A::splat(0.5)), 4001));
        for range in [Range::of(&refs, 0, refs.len()), Range::of(&refs, 100, 200)] {
            let grid = Grid::new(&range);
            let mut seen = [[false; BINS]; AXES];
            for p in &refs {
                let all = grid.bins(p);
                for (axis, &bin) in all.iter().enumerate() {
                    assert!(bin < BINS);
                    for plane in 0..=BINS {
                        assert_eq!(grid.below(p, axis, plane), bin < plane, "axis {axis}, {:?}", p.bounds());
                    }
                    // The cells' floors, as a saturating conversion gives them.
                    if axis < 3 {
                        assert_eq!(bin, grid.cells(&p.bounds())[axis] as usize);
                    }
                    seen[axis][bin] = true;
                }
            }
            // The boxes reach many bins on every axis, so the agreement is
            // not that of a constant.
            for (axis, bins) in seen.iter().enumerate() {
                assert!(bins.iter().filter(|&&b| b).count() >= 16, "axis {axis} reached {bins:?}");
            }
        }
    }

    /// The ranks give the order of a sort by `total_cmp`, ties by index, on
    /// every axis: keys with many ties, both zeros, infinities and NaNs,
    /// 1 to 16 of them.
    #[test]
    fn sorted_orders_sort_by_total_order_then_index() {
        let specials = [0.0, -0.0, 1.0, -1.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN, 1e-40];
        let mut next = crate::wide_bvh::tests::uniform(9);
        for trial in 0..3000 {
            let n = 1 + trial % SWEEP_PRIMS;
            let mut keys = [[0.0f32; AXES]; SWEEP_PRIMS];
            for k in keys[..n].iter_mut().flatten() {
                let u = next();
                *k = if trial % 3 == 0 { (u * 4.0).floor() } else { specials[(u * specials.len() as f32) as usize] };
            }
            let orders = sorted_orders(&keys, n);
            for (axis, order) in orders.iter().enumerate() {
                let mut by_sort: Vec<usize> = (0..n).collect();
                by_sort.sort_by(|&a, &b| keys[a][axis].total_cmp(&keys[b][axis]).then(a.cmp(&b)));
                let ranked: Vec<usize> = order[..n].iter().map(|&i| i as usize).collect();
                assert_eq!(ranked, by_sort, "axis {axis}: {:?}", &keys[..n]);
            }
        }
    }
}
