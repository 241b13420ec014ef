//! Warps from the unit square, a discrete (alias) distribution, the MIS
//! heuristics, and the per-sample random stream.

use crate::select::select_f32;
use glam::{Vec2, Vec3A, Vec4};
use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// The random stream of one sample. Every (seed, stream, index) triple gets an
/// independent generator, so a pixel's samples (or a light path) draw the same
/// numbers whatever thread runs them and in whatever order. (Independent up
/// to its 64-bit key: among 2^40 samples, a 1024^2 image at 2^20 spp, about
/// 2^15 pairs share one by the birthday bound, and each pair's share of a
/// pixel, 2^-20 of its samples, is far below the pixel's noise.)
///
/// The generator is xoshiro256++ (Blackman & Vigna 2021), whose every output
/// bit is of full quality: one 64-bit step gives a 2D point's two 24-bit
/// coordinates, or the 64 bits of `get_bits`.
pub struct Sampler {
    rng: Xoshiro256PlusPlus,
}

/// 2^-24: a 24-bit integer times it is a float in [0, 1), exactly.
const UNIT_24: f32 = 1.0 / (1u32 << 24) as f32;

/// A probability on the grid of `Sampler::get1d`'s numbers (multiples of
/// 2^-24), so that a choice `u < on_u_grid(p)` is made with exactly that
/// chance, which the chooser reports; kept in [2^-24, 1 - 2^-24] where p is
/// in (0, 1), so that neither outcome that has weight is never chosen.
/// With p off the grid, `u < p` has the chance ceil(p 2^24) / 2^24: for a
/// dielectric's reflectance of 2.5e-7 (index 1.001, head on), 19 % more
/// than p, so its reflections weighed 19 % too much (an audit, session 59).
/// (Russian roulette's 1 - m is on the grid already: `roulette`.)
#[inline]
pub fn on_u_grid(p: f32) -> f32 {
    if p <= 0.0 || p >= 1.0 {
        return p.clamp(0.0, 1.0);
    }
    ((p / UNIT_24).round() * UNIT_24).clamp(UNIT_24, 1.0 - UNIT_24)
}

/// SplitMix64's increment (Steele et al. 2014), 2^64 / phi.
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

impl Sampler {
    /// The state is what `Xoshiro256PlusPlus::seed_from_u64(key)` makes,
    /// SplitMix64's next four outputs from `key`, written here so that it
    /// inlines: that call, out of line, filled a byte buffer through a
    /// generic `fill_bytes` (1.4 % of `path`'s time by `perf`; inlined, 0.15 %
    /// fewer instructions, docs/performance-log.md, "Session 53").
    /// The crate's fallback for an all-zero state never applies: `mix64` is
    /// a bijection, so of four distinct inputs at most one maps to 0.
    #[inline]
    pub fn new(seed: u64, stream: u64, index: u64) -> Self {
        let key = Self::key(seed, stream, index);
        let mut state = [0u8; 32];
        for (i, word) in state.chunks_exact_mut(8).enumerate() {
            let x = key.wrapping_add(GOLDEN_GAMMA.wrapping_mul(i as u64 + 1));
            word.copy_from_slice(&mix64(x).to_le_bytes());
        }
        Self { rng: Xoshiro256PlusPlus::from_seed(state) }
    }

    /// The 64-bit key of the stream (seed, stream, index).
    #[inline]
    fn key(seed: u64, stream: u64, index: u64) -> u64 {
        mix64(seed ^ mix64(stream.wrapping_add(mix64(index ^ GOLDEN_GAMMA))))
    }

    /// A uniform number in [0, 1).
    #[inline]
    pub fn get1d(&mut self) -> f32 {
        // 24 high bits: exactly representable, never rounds up to 1.
        (self.rng.next_u64() >> 40) as f32 * UNIT_24
    }

    /// A uniform point in [0, 1)^2: bits 63-40 and 31-8 of one step.
    #[inline]
    pub fn get2d(&mut self) -> Vec2 {
        let bits = self.rng.next_u64();
        Vec2::new((bits >> 40) as f32, ((bits as u32) >> 8) as f32) * UNIT_24
    }

    /// 64 uniform bits (`AliasTable::sample`, which needs more than the 24
    /// of `get1d`).
    #[inline]
    pub fn get_bits(&mut self) -> u64 {
        self.rng.next_u64()
    }
}

/// SplitMix64 finaliser (Steele et al. 2014): a bijective 64-bit mix.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Cosine-weighted hemisphere around +z (Malley's method on the polar map
/// of the square to the disk, r = sqrt(u.x), phi = 2 pi u.y); pdf =
/// cos(theta) / pi. Shirley & Chiu's concentric map distorts strata less,
/// which matters for stratified or low-discrepancy points, not for the
/// independent numbers prism draws. The polar map leaves fewer operations
/// in a chain: no division, and cos(theta) = sqrt(1 - u.x) does not wait
/// for the disk point (docs/performance-log.md, "Session 18").
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3A {
    let r = u.x.sqrt();
    let (sin, cos) = sin_cos_turn(u.y);
    Vec3A::new(r * cos, r * sin, (1.0 - u.x).max(0.0).sqrt())
}

#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Shirley & Chiu 1997 concentric map of the square to the unit disk.
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o == Vec2::ZERO {
        return Vec2::ZERO;
    }
    // theta = a in the first case, pi/2 - a in the second, with |a| <= pi/4.
    // The case is a coin flip: selects, not branches.
    let first = o.x.abs() > o.y.abs();
    let pick = |a: f32, b: f32| select_f32(first, a, b);
    let (r, q) = (pick(o.x, o.y), pick(o.y, o.x));
    let (sin, cos) = sin_cos_quarter(PI / 4.0 * (q / r));
    r * Vec2::new(pick(cos, sin), pick(sin, cos))
}

/// sin and cos of 2 pi t for t in [0, 1]: the nearest quarter turn k
/// (exact, as 4 t is) and sin_cos_quarter of the rest, |a| <= pi/4, turned
/// by k quarter turns (swaps and sign flips, selected).
#[inline]
fn sin_cos_turn(t: f32) -> (f32, f32) {
    let q = 4.0 * t;
    let k = q.round_ties_even();
    let (s, c) = sin_cos_quarter((q - k) * FRAC_PI_2);
    let k = k as u32 & 3;
    // Turned by k pi/2: (s, c), (c, -s), (-s, -c), (-c, s).
    let odd = k & 1 != 0;
    let (s, c) = (select_f32(odd, c, s), select_f32(odd, s, c));
    (select_f32(k >= 2, -s, s), select_f32(k == 1 || k == 2, -c, c))
}

/// sin and cos of |a| <= pi/4 from their Taylor series to degree 9 and 10
/// (truncation error below 2e-9, under f32 rounding); no libm call.
#[inline]
fn sin_cos_quarter(a: f32) -> (f32, f32) {
    let a2 = a * a;
    let sin = a + a * a2 * (-1.0 / 6.0 + a2 * (1.0 / 120.0 + a2 * (-1.0 / 5040.0 + a2 * (1.0 / 362_880.0))));
    let cos =
        1.0 + a2 * (-0.5 + a2 * (1.0 / 24.0 + a2 * (-1.0 / 720.0 + a2 * (1.0 / 40_320.0 + a2 * (-1.0 / 3_628_800.0)))));
    (sin, cos)
}

/// Uniform direction on the unit sphere; pdf = 1 / (4 pi).
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3A {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3A::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform barycentrics (b0, b1) on a triangle; Heitz 2019, "A Low-Distortion
/// Map Between Triangle and Square".
#[inline]
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    // Of the two, the smaller is halved and the larger reduced by that half;
    // which is which is a coin flip, so selects, not a branch.
    let x_smaller = u.x < u.y;
    let pick = |a: f32, b: f32| select_f32(x_smaller, a, b);
    let (lo, hi) = (pick(u.x, u.y), pick(u.y, u.x));
    let (small, large) = (lo / 2.0, hi - lo / 2.0);
    (pick(small, large), pick(large, small))
}

/// Veach's power heuristic with beta = 2 for two strategies with one sample
/// each. The squares are in f64: in f32 they overflow from pdfs of ~1.8e19
/// on (two such pdfs weighed 0 and 0, or 1 and 1).
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let (a, b) = ((pdf_a as f64).powi(2), (pdf_b as f64).powi(2));
    if a.is_infinite() {
        return 1.0;
    }
    if a + b == 0.0 {
        0.0
    } else {
        (a / (a + b)) as f32
    }
}

/// Multiple-importance-sampling heuristic for combining the strategies of a
/// bidirectional estimator (Veach 1997 §9.2). All three give weights that sum
/// to one over the strategies able to make a path, so all are unbiased.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MisHeuristic {
    /// w_i = p_i^2 / sum_k p_k^2 (Veach's power heuristic, beta = 2).
    #[default]
    Power,
    /// w_i = p_i / sum_k p_k (pbrt's choice).
    Balance,
    /// w_i = 1 / (number of strategies that can make the path): no
    /// importance at all, the baseline that shows what MIS buys.
    Uniform,
}

impl MisHeuristic {
    /// The command-line names, in declaration order.
    pub const NAMES: &'static [&'static str] = &["power", "balance", "uniform"];

    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// What a strategy of relative density r = p_k / p_s adds to the
    /// denominator of strategy s's weight.
    #[inline]
    pub fn term(self, r: f32) -> f32 {
        self.terms(Vec4::splat(r)).x
    }

    /// `term` of each lane.
    #[inline]
    pub fn terms(self, r: Vec4) -> Vec4 {
        match self {
            MisHeuristic::Power => r * r,
            MisHeuristic::Balance => r,
            MisHeuristic::Uniform => Vec4::select(r.cmpgt(Vec4::ZERO), Vec4::ONE, Vec4::ZERO),
        }
    }
}

impl std::str::FromStr for MisHeuristic {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "power" => Ok(MisHeuristic::Power),
            "balance" => Ok(MisHeuristic::Balance),
            "uniform" => Ok(MisHeuristic::Uniform),
            _ => Err(format!("unknown MIS heuristic \"{s}\" (valid: {})", Self::NAMES.join(", "))),
        }
    }
}

/// Walker's alias method (Vose 1991): O(1) sampling of a discrete
/// distribution given by non-negative weights.
#[derive(Clone, Debug, Default)]
pub struct AliasTable {
    bins: Vec<AliasBin>,
}

#[derive(Clone, Copy, Debug, Default)]
struct AliasBin {
    q: f32,
    pmf: f32,
    alias: u32,
}

impl AliasTable {
    /// Returns None when there are no weights or they sum to zero.
    pub fn new(weights: &[f64]) -> Option<Self> {
        let sum: f64 = weights.iter().map(|&w| w.max(0.0)).sum();
        if weights.is_empty() || sum <= 0.0 || !sum.is_finite() {
            return None;
        }
        let n = weights.len();
        let mut bins = vec![AliasBin::default(); n];
        let mut p: Vec<f64> = weights.iter().map(|&w| w.max(0.0) / sum * n as f64).collect();
        let (mut under, mut over): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| p[i] < 1.0);
        while let (Some(&u), Some(&o)) = (under.last(), over.last()) {
            under.pop();
            bins[u].q = p[u] as f32;
            bins[u].alias = o as u32;
            p[o] -= 1.0 - p[u];
            if p[o] < 1.0 {
                over.pop();
                under.push(o);
            }
        }
        for i in under.into_iter().chain(over) {
            bins[i].q = 1.0;
            bins[i].alias = i as u32;
        }
        // The pmf is the probability with which `sample` draws each index:
        // its own bin's threshold plus the rest of every bin that names it
        // as alias, both as stored. The thresholds are rounded to f32 one by
        // one, and many equal weights just under the mean round alike, so
        // the weights' pmf could be off by percents for the one light all
        // their aliases name (10^6 equal emitters beside one lamp of twice
        // their power: +0.66 %).
        let mut drawn = vec![0f64; n];
        for (i, bin) in bins.iter().enumerate() {
            drawn[i] += bin.q as f64;
            drawn[bin.alias as usize] += 1.0 - bin.q as f64;
        }
        for (bin, p) in bins.iter_mut().zip(drawn) {
            bin.pmf = (p / n as f64) as f32;
        }
        Some(Self { bins })
    }

    /// Draw an index from 64 uniform bits (`Sampler::get_bits`); returns
    /// (index, pmf). The bin is the integer part of bits x n / 2^64 and the
    /// coin the fraction, both from one exact 128-bit product: every bin is
    /// equally likely to n / 2^64 and the coin has 64 - log2(n) bits (44
    /// for 10^6 lights), finer than the f32 threshold q. A 24-bit float
    /// split the same way in f32 left the coin about 24 - 2 log2(n) bits:
    /// with 10^4 lights some were drawn at 0.5x to 2.4x their pmf, with
    /// 10^5 some never; 32 bits (session 33) left 12 bits for 10^6.
    #[inline]
    pub fn sample(&self, bits: u64) -> (usize, f32) {
        let product = bits as u128 * self.bins.len() as u128;
        let i = (product >> 64) as usize;
        let coin = (product as u64) as f64 * (1.0 / 18_446_744_073_709_551_616.0);
        let j = if coin < self.bins[i].q as f64 { i } else { self.bins[i].alias as usize };
        (j, self.bins[j].pmf)
    }

    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.bins[i].pmf
    }

    pub fn len(&self) -> usize {
        self.bins.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bins.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `on_u_grid` gives a multiple of 2^-24 whose chance under `u < p` is
    /// itself, over every u `get1d` gives: the nearest to p, kept off 0 and 1
    /// for a p strictly between them; without the grid, `u < 2.5e-7` comes
    /// true for 5 of the 2^24 numbers, 1.19 times p.
    #[test]
    fn a_choice_on_the_grid_has_the_chance_it_reports() {
        let n = (1u32 << 24) as f64;
        for p in [0.0, 1e-12, 2.5e-7, 3e-8, 0.112_066_72, 0.5, 1.0 - 1e-9, 1.0] {
            let q = on_u_grid(p);
            // The numbers k 2^-24 below q: the least k not below it.
            let chance = (q as f64 * n).ceil() / n;
            assert_eq!(q as f64, chance, "p {p}: q {q}");
            assert!((q - p).abs() <= UNIT_24 / 2.0 || (p > 0.0 && q == UNIT_24) || (p < 1.0 && q == 1.0 - UNIT_24));
            assert_eq!(q > 0.0, p > 0.0, "p {p}");
            assert_eq!(q < 1.0, p < 1.0, "p {p}");
        }
        assert_eq!((2.5e-7f32 as f64 * n).ceil(), 5.0);
    }

    /// The two weights of a pair of strategies sum to 1 for any pdfs a
    /// renderer may see, huge ones included (from an audit: 0 + 0 for
    /// (1.3e19, 1.4e19), 1 + 1 for (2e19, 1e25) when squared in f32).
    #[test]
    fn power_heuristic_weights_sum_to_one() {
        for (a, b) in [(1.0, 3.0), (1.3e19, 1.4e19), (2e19, 1e25), (3e38, 1e-30), (f32::MAX, f32::MAX)] {
            let (wa, wb) = (power_heuristic(a, b), power_heuristic(b, a));
            assert!((wa + wb - 1.0).abs() < 1e-6, "({a}, {b}): {wa} + {wb}");
        }
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
        assert_eq!(power_heuristic(f32::INFINITY, 1.0), 1.0);
        // The values themselves (Veach 1997, eq. 9.13: a^2 / (a^2 + b^2)),
        // which the balance heuristic's weights would not give while still
        // summing to 1 (a review, session 55).
        assert_eq!((power_heuristic(1.0, 3.0), power_heuristic(3.0, 1.0)), (0.1, 0.9));
        assert_eq!(power_heuristic(2.0, 2.0), 0.5);
    }

    /// Pearson's chi-square p-value of `points` binned on a 32 x 32 grid
    /// against the uniform distribution.
    fn uniform_grid_p(points: impl Iterator<Item = Vec2>) -> f64 {
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        const G: usize = 32;
        let mut bins = vec![0u32; G * G];
        let mut n = 0;
        for p in points {
            assert!((0.0..1.0).contains(&p.x) && (0.0..1.0).contains(&p.y), "{p}");
            bins[(p.y * G as f32) as usize * G + (p.x * G as f32) as usize] += 1;
            n += 1;
        }
        let expected = n as f64 / (G * G) as f64;
        let chi2: f64 = bins.iter().map(|&b| (b as f64 - expected).powi(2) / expected).sum();
        ChiSquared::new((G * G - 1) as f64).unwrap().sf(chi2)
    }

    /// `Sampler::new` seeds the generator exactly as the crate's
    /// `seed_from_u64` of the same key does (same draws), for keys from
    /// many (seed, stream, index) triples, the zero triple among them.
    /// Fails if a word of the state is mixed, ordered or offset otherwise.
    #[test]
    fn sampler_state_is_seed_from_u64_of_its_key() {
        for (seed, stream, index) in (0..64u64).map(|i| (i / 16, i % 16 * 7919, i * 0x9E37)).chain([(u64::MAX, 3, 5)]) {
            let key = Sampler::key(seed, stream, index);
            let (mut ours, mut crates) = (Sampler::new(seed, stream, index), Xoshiro256PlusPlus::seed_from_u64(key));
            for _ in 0..8 {
                assert_eq!(ours.get_bits(), crates.next_u64(), "({seed}, {stream}, {index})");
            }
        }
    }

    /// A 2D point takes its coordinates from disjoint bits of one 64-bit
    /// step (63-40 and 31-8, checked exactly against the generator), and
    /// the draws are uniform on the square, at the 32 x 32 grid of their
    /// top five bits and of their bottom five: 2D points, successive 1D
    /// draws, and the first draws of neighbouring samples' streams (pairs
    /// 2i, 2i + 1, so that no draw is in two points). Chi-square on 2^18
    /// points per check, each at alpha 1e-4. Negative control: coordinates
    /// from overlapping bits of one step (63-40 and 61-38) are rejected.
    #[test]
    fn sampler_points_are_uniform_and_independent() {
        const N: u64 = 1 << 18;
        let mut s = Sampler::new(7, 11, 13);
        for _ in 0..1000 {
            let bits = s.rng.clone().next_u64();
            let expected = Vec2::new((bits >> 40) as f32, ((bits as u32) >> 8) as f32) * UNIT_24;
            assert_eq!(s.get2d(), expected, "a 2D point from other bits than 63-40 and 31-8 of one step");
        }
        // The bottom five of a draw's 24 bits, as a number in [0, 1).
        let low = |p: Vec2| (p * (1u32 << 19) as f32).fract();
        let mut draws: Vec<(&str, Vec<Vec2>)> = vec![
            ("get2d", (0..N).map(|_| s.get2d()).collect()),
            ("get1d pairs", (0..N).map(|_| Vec2::new(s.get1d(), s.get1d())).collect()),
            (
                "neighbouring streams",
                (0..N)
                    .map(|i| Vec2::new(Sampler::new(7, 0, 2 * i).get1d(), Sampler::new(7, 0, 2 * i + 1).get1d()))
                    .collect(),
            ),
        ];
        draws.extend(draws.clone().into_iter().map(|(what, points)| (what, points.into_iter().map(low).collect())));
        for (k, (what, points)) in draws.into_iter().enumerate() {
            let p = uniform_grid_p(points.into_iter());
            let bits = if k < 3 { "top" } else { "bottom" };
            assert!(p > 1e-4, "{what}, {bits} bits: chi-square p = {p:e}");
        }
        let overlapping =
            |bits: u64| Vec2::new((bits >> 40) as f32, ((bits >> 38) as u32 & 0xff_ffff) as f32) * UNIT_24;
        let p = uniform_grid_p((0..N).map(|_| overlapping(s.get_bits())));
        assert!(p < 1e-4, "the overlapping coordinates passed: p = {p:e}");
    }

    #[test]
    fn sin_cos_quarter_matches_libm() {
        for k in -1000..=1000 {
            let a = k as f32 / 1000.0 * PI / 4.0;
            let (s, c) = sin_cos_quarter(a);
            assert!((s - a.sin()).abs() < 2e-7 && (c - a.cos()).abs() < 2e-7, "{a}: {s} {c}");
        }
    }

    #[test]
    fn sin_cos_turn_matches_libm() {
        for k in 0..=4096 {
            let t = k as f32 / 4096.0;
            let (s, c) = sin_cos_turn(t);
            let a = 2.0 * std::f64::consts::PI * t as f64;
            assert!((s as f64 - a.sin()).abs() < 3e-7 && (c as f64 - a.cos()).abs() < 3e-7, "{t}: {s} {c}");
        }
    }

    #[test]
    fn alias_table_reproduces_weights() {
        let w = [1.0, 0.0, 3.0, 6.0];
        let t = AliasTable::new(&w).unwrap();
        let n = 200_000;
        let mut counts = [0usize; 4];
        let mut s = Sampler::new(1, 2, 3);
        for _ in 0..n {
            let (i, pmf) = t.sample(s.get_bits());
            assert_eq!(pmf, t.pmf(i));
            counts[i] += 1;
        }
        for i in 0..4 {
            let p = (w[i] / 10.0) as f32;
            let sigma = (n as f32 * p * (1.0 - p)).sqrt().max(1.0);
            assert!(((counts[i] as f32) - n as f32 * p).abs() < 5.0 * sigma, "{counts:?}");
        }
        assert!(AliasTable::new(&[0.0, 0.0]).is_none());
    }

    /// Many lights (one per emissive triangle): 10^6 weights over four
    /// decades. Every bin's coin must resolve its threshold q to 1e-7 (a
    /// draw just below q keeps the bin, one just above takes its alias), or
    /// lights of small q are drawn off their pmf. Controls: 32 bits (the
    /// draw of session 33) and the former split of one 24-bit float into
    /// bin and coin (which drew some of 10^4 lights at 0.5x to 2.4x their
    /// pmf) each miss most of them.
    #[test]
    fn alias_table_coins_resolve_small_thresholds() {
        let n = 1_000_000;
        let w: Vec<f64> = (0..n).map(|i| 10f64.powf(4.0 * i as f64 / n as f64)).collect();
        let t = AliasTable::new(&w).unwrap();
        let former = |u: f32| {
            let x = u * n as f32;
            let i = (x as usize).min(n - 1);
            if (x - i as f32).min(1.0) < t.bins[i].q {
                i
            } else {
                t.bins[i].alias as usize
            }
        };
        let (mut checked, mut bits32_wrong, mut former_wrong) = (0, 0, 0);
        for (i, bin) in t.bins.iter().enumerate().filter(|(_, b)| b.q > 1e-4 && b.q < 1.0 - 1e-4) {
            for (coin, want) in [(bin.q as f64 - 1e-7, i), (bin.q as f64 + 1e-7, bin.alias as usize)] {
                let x = (i as f64 + coin) / n as f64;
                let bits = (x * 18_446_744_073_709_551_616.0) as u64;
                assert_eq!(t.sample(bits).0, want, "bin {i}, q {}", bin.q);
                bits32_wrong += (t.sample(bits & !0xFFFF_FFFF).0 != want) as usize;
                former_wrong += (former(x as f32) != want) as usize;
                checked += 1;
            }
        }
        assert!(checked > n, "{checked} thresholds checked");
        assert!(bits32_wrong > checked / 4, "control: 32 bits missed only {bits32_wrong} of {checked}");
        assert!(former_wrong > checked / 4, "control: the 24-bit split missed only {former_wrong} of {checked}");
        // The sampler's draws carry the low half too.
        let mut s = Sampler::new(1, 2, 3);
        assert!((0..8).any(|_| s.get_bits() & 0xFFFF_FFFF != 0), "get_bits gives 32 bits, not 64");
    }

    /// The probability with which `sample` returns each index, from every
    /// bin's range of 64-bit draws, split by bisection where its coin
    /// passes the threshold (the coin grows with the draw within a bin).
    fn drawn_probabilities(t: &AliasTable) -> Vec<f64> {
        let n = t.len() as u128;
        let start = |i: u128| (i << 64).div_ceil(n);
        let mut p = vec![0f64; t.len()];
        for i in 0..n {
            let (lo, hi) = (start(i), start(i + 1));
            let (mut a, mut b) = (lo, hi);
            while a < b {
                let m = (a + b) / 2;
                if t.sample(m as u64).0 == i as usize {
                    a = m + 1;
                } else {
                    b = m;
                }
            }
            p[i as usize] += (a - lo) as f64 / 2f64.powi(64);
            if a < hi {
                p[t.sample((hi - 1) as u64).0] += (hi - a) as f64 / 2f64.powi(64);
            }
        }
        p
    }

    /// The pmf the estimators divide by is the probability `sample` draws
    /// with, to f32's rounding, for 10^6 equal weights beside one of 1.5 or
    /// 2 (an audit's case: every equal bin's threshold just under 1 rounds
    /// alike, and their leftovers all go to the one larger light) and for
    /// weights over four decades. Control: the weights' own pmf (w / sum),
    /// which the table gave before, is off by 0.1 % or more for the larger
    /// light in both cases.
    #[test]
    fn alias_pmf_is_the_drawn_probability() {
        let n = 1_000_000;
        for other in [1.5, 2.0, -1.0] {
            let w: Vec<f64> = match other {
                x if x > 0.0 => (0..=n).map(|i| if i == n { x } else { 1.0 }).collect(),
                _ => (0..n).map(|i| 10f64.powf(4.0 * i as f64 / n as f64)).collect(),
            };
            let t = AliasTable::new(&w).unwrap();
            let drawn = drawn_probabilities(&t);
            let worst = (0..w.len()).map(|i| (drawn[i] / t.pmf(i) as f64 - 1.0).abs()).fold(0.0, f64::max);
            assert!(worst < 2e-7, "weights with {other}: pmf off the drawn probability by {worst:e}");
            if other > 0.0 {
                let sum: f64 = w.iter().sum();
                let by_weight = (drawn[n] / (w[n] / sum) - 1.0).abs();
                assert!(by_weight > 1e-3, "control: w / sum is off by only {by_weight:e} for {other}");
            }
        }
    }

    #[test]
    fn warps_stay_in_their_domains() {
        let mut s = Sampler::new(7, 0, 0);
        for _ in 0..10_000 {
            let u = s.get2d();
            let c = cosine_hemisphere(u);
            assert!(c.z >= 0.0 && (c.length() - 1.0).abs() < 1e-4);
            assert!((uniform_sphere(u).length() - 1.0).abs() < 1e-4);
            let (b0, b1) = uniform_triangle(u);
            assert!(b0 >= 0.0 && b1 >= 0.0 && b0 + b1 <= 1.0 + 1e-6);
        }
    }
}
