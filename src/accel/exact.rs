//! A ray's scalar triple product with an edge, ((p - o) x (q - o)) . d,
//! with its exact sign, for f32 inputs, by expansion arithmetic
//! (Shewchuk 1997, "Adaptive Precision Floating-Point Arithmetic and Fast
//! Robust Geometric Predicates", sections 2.2-2.6). `lanes::hit_in_f64`
//! asks for it where its f64 product lies within that product's rounding
//! bound: there a sign from rounding (or a 0 for it) lets a ray through
//! the edge between two triangles, or has it meet the far one first.

use glam::Vec3A;

/// ((p - o) x (q - o)) . d, with its exact sign (0 only for an exact 0)
/// and nearly its magnitude (`Expansion::estimate`). Expanding
/// the cross product (o x o = 0) gives d . (p x q) + q . (o x d) - p . (o x d):
/// 18 products of three f32s. The product of two f32s is exact in f64
/// (48 bits of 53); times the third it is exactly two f64s (TwoProduct,
/// by a fused multiply-add); the 36 are summed without error into a
/// nonoverlapping expansion, whose largest component has the sum's sign
/// and dominates the rest.
/// No product of three f32s (2^-447 to 2^384 in magnitude, subnormals
/// included) underflows or overflows in f64, so every step is exact.
pub(super) fn triple_product(o: Vec3A, d: Vec3A, p: Vec3A, q: Vec3A) -> f64 {
    let mut sum = Expansion::new();
    for (a, b, w, sign) in [(p, q, d, 1.0), (o, d, q, 1.0), (o, d, p, -1.0)] {
        // (a x b) . w, a cross component at a time.
        let [a, b, w] = [a, b, w].map(|v| v.as_dvec3());
        for (plus, minus, w) in [(a.y * b.z, a.z * b.y, w.x), (a.z * b.x, a.x * b.z, w.y), (a.x * b.y, a.y * b.x, w.z)]
        {
            sum.add_product(plus, sign * w);
            sum.add_product(-minus, sign * w);
        }
    }
    sum.estimate()
}

/// A nonoverlapping expansion (Shewchuk's section 2.2): f64 components by
/// increasing magnitude, zeros left out, whose exact sum is its value;
/// room for the 36 of `triple_product` (each addition adds at most
/// one component).
struct Expansion {
    c: [f64; 36],
    len: usize,
}

impl Expansion {
    fn new() -> Self {
        Self { c: [0.0; 36], len: 0 }
    }

    /// Adds x y exactly: its rounded value and the rounding error, which a
    /// fused multiply-add gives exactly (no underflow: see
    /// `triple_product`).
    fn add_product(&mut self, x: f64, y: f64) {
        let product = x * y;
        self.add(x.mul_add(y, -product));
        self.add(product);
    }

    /// Adds b exactly: Shewchuk's Grow-Expansion with zero elimination
    /// (his Theorem 10 and Figure 7's ZEROELIM), which keeps the
    /// components nonoverlapping and increasing.
    fn add(&mut self, b: f64) {
        let (mut q, mut len) = (b, 0);
        for i in 0..self.len {
            let (sum, error) = two_sum(q, self.c[i]);
            q = sum;
            if error != 0.0 {
                self.c[len] = error;
                len += 1;
            }
        }
        if q != 0.0 {
            self.c[len] = q;
            len += 1;
        }
        self.len = len;
    }

    /// The value: its sign exactly, the largest component's (the others
    /// sum to less than that component's lowest bit), its magnitude that
    /// of the components summed in f64 (Shewchuk's ESTIMATE), or the
    /// largest component's where that sum rounds to 0 (the others just
    /// short of it and opposite, in theory); 0 for an empty expansion, the
    /// one whose value is 0.
    fn estimate(&self) -> f64 {
        let terms = &self.c[..self.len];
        terms.last().map_or(0.0, |&top| match terms.iter().sum::<f64>() {
            0.0 => top,
            sum => sum.abs().copysign(top),
        })
    }
}

/// Knuth's TwoSum: a + b rounded, and its rounding error exactly
/// (Shewchuk's Theorem 7; round to nearest, no overflow).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let sum = a + b;
    let b_virtual = sum - a;
    let a_virtual = sum - b_virtual;
    (sum, (a - a_virtual) + (b - b_virtual))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    /// ((p - o) x (q - o)) . d in integers, for inputs on the grid of
    /// 2^-13 (|x| < 2^11: 24 bits, exact in f32).
    fn exact_on_grid(o: Vec3A, d: Vec3A, p: Vec3A, q: Vec3A) -> i128 {
        let int = |v: Vec3A| v.to_array().map(|x| (x * 8192.0) as i128);
        let ([o, d, p, q], sub) = ([o, d, p, q].map(int), |a: [i128; 3], b: [i128; 3]| [0, 1, 2].map(|i| a[i] - b[i]));
        let (a, b) = (sub(p, o), sub(q, o));
        let c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        c[0] * d[0] + c[1] * d[1] + c[2] * d[2]
    }

    /// Nearly degenerate triples on the grid: d an integer combination of
    /// p - o and q - o (in the plane of o, p and q), moved by -2..2 steps
    /// on each axis, so that about one in 125 products is exactly 0. The
    /// sign matches integer arithmetic's, flips with the edge's direction,
    /// and survives scaling o, p and q by 2^-100 or 2^60 and d by 2^-120
    /// (exponents no integer check spans). The control: the f64 product's
    /// own sign is wrong (or not 0 where the product is) for some of them,
    /// so the triples reach the rounding the expansion is there for.
    #[test]
    fn triple_product_has_the_exact_sign() {
        let mut u = Sampler::new(3, 0, 0);
        let grid = |x: f32| (x * 8192.0).round() / 8192.0;
        let point = |u: &mut Sampler| Vec3A::new(u.get1d(), u.get1d(), u.get1d()).map(|x| grid(500.0 * x - 250.0));
        let (mut zeros, mut f64_wrong) = (0, 0);
        for _ in 0..20_000 {
            let (o, p, q) = (point(&mut u), point(&mut u), point(&mut u));
            let weight = |u: &mut Sampler| [-1.0, 1.0, 2.0][(u.get1d() * 3.0) as usize];
            let (s, t) = (weight(&mut u), weight(&mut u));
            let nudge = Vec3A::new(u.get1d(), u.get1d(), u.get1d()).map(|x| ((x * 5.0).floor() - 2.0) / 8192.0);
            let d = (p - o) * s + (q - o) * t + nudge;
            let want = exact_on_grid(o, d, p, q).signum() as f64;
            let sign = |x: f64| if x == 0.0 { 0.0 } else { x.signum() };
            assert_eq!(sign(triple_product(o, d, p, q)), want, "o {o}, d {d}, p {p}, q {q}");
            assert_eq!(sign(triple_product(o, d, q, p)), -want);
            for (k, j) in [(2f32.powi(-100), 2f32.powi(-120)), (2f32.powi(60), 1.0)] {
                assert_eq!(sign(triple_product(o * k, d * j, p * k, q * k)), want, "scaled by {k}, {j}");
            }
            let [o64, d64, p64, q64] = [o, d, p, q].map(|v| v.as_dvec3());
            let naive = (p64 - o64).cross(q64 - o64).dot(d64);
            zeros += (want == 0.0) as u32;
            f64_wrong += (sign(naive) != want) as u32;
        }
        assert!(zeros > 100, "only {zeros} exact zeros");
        assert!(f64_wrong > 0, "the control: f64 got every sign right");
    }
}
