//! Chi-square goodness of fit of a direction sampler against its density, and
//! adaptive integration over the sphere (VALIDATION.md §4; the design of
//! Mitsuba 3's `chi2.py` and pbrt-v4's `bsdfs_test.cpp`, TRANSPORT-NOTES §2).
//!
//! - The sphere is cut into `n_t` x `n_phi` cells in coordinates (t, phi)
//!   about an `axis`: (1 - cos theta') / 2 = t^k, phi' the azimuth. k = 1 is
//!   Mitsuba's equal-area (cos theta, phi) grid; k > 1 refines the cells near
//!   the axis (rows of equal t are then finer in theta' near the pole), which
//!   lets a histogram resolve a lobe too narrow for an equal-area grid when the
//!   axis is put on the lobe. Any fixed partition gives a valid test.
//! - Observed counts: `n_samples` draws of the sampler, binned; failed or
//!   specular samples land in no cell of the sphere and are counted as one
//!   cell more, which expects n (1 - integral of the pdf): the cells then
//!   partition all n samples, as Pearson's terms - 1 degrees of freedom
//!   assume, and a sampler that fails more often than its pdf leaves room
//!   for is seen (until session 54 they were left out: the total was free,
//!   one degree of freedom uncounted, and a sampler losing 1 % of its
//!   samples passed). That expectation is a sum over every cell's cubature,
//!   whose errors, each a fraction of its cell's sigma, add up: its term
//!   takes the sum's error, `TOTAL_TOLERANCE` n, as variance beside the
//!   Poisson one, and is also a test of its own, one degree of freedom,
//!   each of the two at half the case's significance (session 59).
//! - Expected counts: n_samples times the integral of the pdf over each cell,
//!   by adaptive 3x3 Gauss-Legendre cubature (each cell split at least once;
//!   a square is refined until four children agree with their parent within
//!   a tenth of the cell's Poisson sigma or 0.02 counts, at most 7 levels
//!   deep; the error of the children is far smaller than that difference). A cell whose count
//!   differs from this by more than 3 sigma is integrated again, cut into
//!   16 x 16 adaptive squares first, so that a lobe thinner than the first
//!   cubature nodes is not missed (the integral does not depend on the
//!   samples, only how finely it is resolved: this cannot hide an error).
//! - Cells are sorted by expected count; consecutive cells are pooled until a
//!   pool expects at least 5, each pool is one term (obs - exp)^2 / exp and one
//!   degree of freedom; dof = terms - 1; p = P(chi2_dof > statistic).
//! - Sanity failures before any statistic (Mitsuba, pbrt): a sample that is
//!   not a unit vector, a negative or non-finite expected count, a pdf
//!   integral above 1.1, or more than 1e-5 n samples in cells the pdf says are
//!   empty (pbrt's floating-point leniency), the absent samples' cell
//!   included.

use glam::{DVec3, Vec2, Vec3A};
use prism::sampling::Sampler;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::PI;

/// Minimum expected count of a pooled term (Mitsuba, pbrt: 5).
pub const MIN_EXPECTED: f64 = 5.0;

/// How far the sum of the cells' cubatures may be from a pdf's integral
/// over the sphere. The rough dielectric of index 1.01, alpha 0.8, seen at
/// wo.z = 0.05 sums to 0.99924, where finer cubatures (grids of 80 x 160 to
/// 320 x 640 cells, each at relative accuracy 1e-7) read 0.99875-0.99889
/// and the sampler fails for 1.04e-3 of 4M samples: its absent cell
/// expected 758 samples and counted ~1,000 at every seed, a term of ~100
/// that the seed sweep's offset 110 pushed over the threshold (p 3e-6).
/// With this error the term is ~0.4. A sampler that fails for 1 % more
/// than its pdf leaves room for still gives a term of ~400, which
/// `Chi2Outcome::p_total` tests alone (p ~1e-88 in
/// `chi2_negative_controls`), as among the thousands of cells it would
/// pass (p 1.3e-2 at offset 110).
pub const TOTAL_TOLERANCE: f64 = 5e-4;

/// The Sidak-corrected per-test significance for `tests` tests at family-wise
/// level `alpha`: 1 - (1 - alpha)^(1/tests).
pub fn sidak(alpha: f64, tests: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / tests as f64)
}

/// How accurately a cell integral is wanted: the adaptive cubature stops
/// when its error estimate is below max(abs, rel |I|, sqrt_scale sqrt(|I|)).
#[derive(Clone, Copy, Debug)]
pub struct Accuracy {
    pub abs: f64,
    pub rel: f64,
    pub sqrt_scale: f64,
}

impl Accuracy {
    /// For expected counts out of `n` samples: 0.02 counts, or a tenth of the
    /// cell's Poisson sigma sqrt(n p), whichever is larger.
    pub fn counts(n: usize) -> Self {
        let n = n as f64;
        Self { abs: 0.02 / n, rel: 0.0, sqrt_scale: 0.1 / n.sqrt() }
    }

    /// For a quadrature: relative `rel` with a tiny absolute floor.
    pub fn relative(rel: f64) -> Self {
        Self { abs: 1e-9, rel, sqrt_scale: 0.0 }
    }

    fn tolerance(&self, estimate: f64) -> f64 {
        let e = estimate.abs();
        self.abs.max(self.rel * e).max(self.sqrt_scale * e.sqrt())
    }
}

/// A partition of the sphere into cells of (t, phi) about `axis`.
#[derive(Clone, Copy, Debug)]
pub struct SphereGrid {
    pub axis: DVec3,
    t1: DVec3,
    t2: DVec3,
    /// Pole refinement exponent: (1 - cos theta') / 2 = t^k.
    pub k: f64,
    pub n_t: usize,
    pub n_phi: usize,
}

impl SphereGrid {
    /// Mitsuba's equal-area grid in (cos theta, phi) about +z. An even `n_t`
    /// puts a row edge on the horizon, where reflection lobes are cut off.
    pub fn equal_area(n_t: usize, n_phi: usize) -> Self {
        Self { axis: DVec3::Z, t1: DVec3::X, t2: DVec3::Y, k: 1.0, n_t, n_phi }
    }

    /// Cells refined towards `axis` with exponent `k` (1 = equal area).
    pub fn around(axis: Vec3A, k: f64, n_t: usize, n_phi: usize) -> Self {
        let axis = DVec3::new(axis.x as f64, axis.y as f64, axis.z as f64).normalize();
        let (t1, t2) = axis.any_orthonormal_pair();
        Self { axis, t1, t2, k, n_t, n_phi }
    }

    /// A grid whose first rows resolve a lobe of angular radius `width`
    /// (radians) centred on `axis`: the first five rows end at theta' = width.
    pub fn for_lobe(axis: Vec3A, width: f64, n_t: usize, n_phi: usize) -> Self {
        // theta' ~ 2 t^(k/2) near the pole.
        let t5 = (5.0 / n_t as f64).min(0.5);
        let k = (2.0 * (width / 2.0).ln() / t5.ln()).clamp(1.0, 10.0);
        Self::around(axis, k, n_t, n_phi)
    }

    pub fn cells(&self) -> usize {
        self.n_t * self.n_phi
    }

    /// The cell of a unit direction.
    pub fn cell_of(&self, w: Vec3A) -> usize {
        let w = DVec3::new(w.x as f64, w.y as f64, w.z as f64).normalize();
        // (1 - cos) / 2 = |w - axis|^2 / 4, accurate near the pole.
        let u = ((w - self.axis).length_squared() / 4.0).clamp(0.0, 1.0);
        let t = u.powf(1.0 / self.k);
        let mut phi = w.dot(self.t2).atan2(w.dot(self.t1));
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let i = ((t * self.n_t as f64) as usize).min(self.n_t - 1);
        let j = ((phi / (2.0 * PI) * self.n_phi as f64) as usize).min(self.n_phi - 1);
        i * self.n_phi + j
    }

    /// The direction at (t, phi).
    pub fn direction(&self, t: f64, phi: f64) -> Vec3A {
        let u = if self.k == 1.0 { t } else { t.powf(self.k) };
        let cos = 1.0 - 2.0 * u;
        let sin = 2.0 * (u * (1.0 - u)).max(0.0).sqrt();
        let w = self.axis * cos + (self.t1 * phi.cos() + self.t2 * phi.sin()) * sin;
        Vec3A::new(w.x as f32, w.y as f32, w.z as f32)
    }

    /// |d cos theta' / dt|: the solid angle is this times dt dphi.
    fn jacobian(&self, t: f64) -> f64 {
        if self.k == 1.0 {
            2.0
        } else {
            2.0 * self.k * t.powf(self.k - 1.0)
        }
    }

    /// The integral of `f` over cell `c` (solid angle measure).
    pub fn integrate_cell(&self, f: &dyn Fn(Vec3A) -> f64, c: usize, acc: Accuracy) -> f64 {
        self.integrate_cell_split(f, c, acc, 1)
    }

    /// The integral over cell `c`, cut first into `split` x `split` squares
    /// that are each integrated adaptively: for cells where a lobe may be
    /// thinner than the spacing of the first cubature nodes.
    pub fn integrate_cell_split(&self, f: &dyn Fn(Vec3A) -> f64, c: usize, acc: Accuracy, split: usize) -> f64 {
        let (i, j) = (c / self.n_phi, c % self.n_phi);
        let (dt, dp) = (1.0 / (self.n_t * split) as f64, 2.0 * PI / (self.n_phi * split) as f64);
        let g = |t: f64, p: f64| f(self.direction(t, p)) * self.jacobian(t);
        let squares: Vec<Square> = (i * split..(i + 1) * split)
            .flat_map(|a| {
                (j * split..(j + 1) * split).map(move |b| Square {
                    x0: a as f64 * dt,
                    x1: (a + 1) as f64 * dt,
                    y0: b as f64 * dp,
                    y1: (b + 1) as f64 * dp,
                })
            })
            .collect();
        let coarse: Vec<f64> = squares.iter().map(|sq| sq.gauss3(&g)).collect();
        let tol = acc.tolerance(coarse.iter().sum()) / squares.len() as f64;
        squares.iter().zip(coarse).map(|(sq, whole)| adaptive(&g, *sq, whole, tol, 0)).sum()
    }

    /// The integral of `f` over every cell.
    pub fn integrate_cells(&self, f: &dyn Fn(Vec3A) -> f64, acc: Accuracy) -> Vec<f64> {
        (0..self.cells()).map(|c| self.integrate_cell(f, c, acc)).collect()
    }

    /// The integral of `f` over the whole sphere.
    pub fn integrate(&self, f: &dyn Fn(Vec3A) -> f64, acc: Accuracy) -> f64 {
        self.integrate_split(f, acc, 1)
    }

    /// The integral over the sphere with every cell cut into `split` x `split`
    /// adaptive squares first (for integrands with features thinner than the
    /// first cubature nodes).
    pub fn integrate_split(&self, f: &dyn Fn(Vec3A) -> f64, acc: Accuracy, split: usize) -> f64 {
        (0..self.cells()).map(|c| self.integrate_cell_split(f, c, acc, split)).sum()
    }
}

#[derive(Clone, Copy)]
struct Square {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

/// 3-point Gauss-Legendre nodes and weights on [-1, 1].
const GL_X: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
const GL_W: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
const MAX_DEPTH: u32 = 7;
/// Squares per axis when a suspicious cell is integrated again.
const FINE_SPLIT: usize = 16;

impl Square {
    fn gauss3(&self, g: &dyn Fn(f64, f64) -> f64) -> f64 {
        let (cx, hx) = (0.5 * (self.x0 + self.x1), 0.5 * (self.x1 - self.x0));
        let (cy, hy) = (0.5 * (self.y0 + self.y1), 0.5 * (self.y1 - self.y0));
        let mut s = 0.0;
        for (xa, wa) in GL_X.iter().zip(GL_W) {
            for (ya, wb) in GL_X.iter().zip(GL_W) {
                s += wa * wb * g(cx + hx * xa, cy + hy * ya);
            }
        }
        s * hx * hy
    }

    fn quarters(&self) -> [Square; 4] {
        let (xm, ym) = (0.5 * (self.x0 + self.x1), 0.5 * (self.y0 + self.y1));
        [
            Square { x0: self.x0, x1: xm, y0: self.y0, y1: ym },
            Square { x0: xm, x1: self.x1, y0: self.y0, y1: ym },
            Square { x0: self.x0, x1: xm, y0: ym, y1: self.y1 },
            Square { x0: xm, x1: self.x1, y0: ym, y1: self.y1 },
        ]
    }
}

fn adaptive(g: &dyn Fn(f64, f64) -> f64, sq: Square, whole: f64, tol: f64, depth: u32) -> f64 {
    let q = sq.quarters();
    let parts = q.map(|s| s.gauss3(g));
    let sum: f64 = parts.iter().sum();
    if depth >= MAX_DEPTH || (sum - whole).abs() <= tol {
        return sum;
    }
    (0..4).map(|k| adaptive(g, q[k], parts[k], tol / 2.0, depth + 1)).sum()
}

/// Outcome of one chi-square test.
#[derive(Clone, Debug)]
pub struct Chi2Outcome {
    pub chi2: f64,
    pub dof: usize,
    pub p_value: f64,
    /// The absent samples' term alone, as a statistic of one degree of
    /// freedom: among thousands of terms a loss of 1 % of the samples is
    /// diluted (`TOTAL_TOLERANCE`).
    pub p_total: f64,
    /// Samples that landed on the sphere (not failed, not specular).
    pub sampled: usize,
    /// Integral of the pdf over the sphere.
    pub pdf_integral: f64,
    /// A sanity failure, which rejects regardless of p.
    pub error: Option<String>,
    /// The largest contributions (obs, exp, direction of the cell) for diagnosis.
    pub worst: Vec<(f64, f64, Vec3A)>,
}

impl Chi2Outcome {
    /// At family-wise level `alpha` for the case: each of its two
    /// statistics at alpha / 2 (Bonferroni).
    pub fn rejected(&self, alpha: f64) -> bool {
        let p = self.p_value.min(self.p_total);
        self.error.is_some() || p.is_nan() || p < alpha / 2.0
    }
}

/// Histogram `n_samples` directions from `sample(uc, u2)` and test them against
/// `pdf` on `grid`.
pub fn chi2_test(
    mut sample: impl FnMut(f32, Vec2) -> Option<Vec3A>,
    pdf: &dyn Fn(Vec3A) -> f64,
    grid: &SphereGrid,
    n_samples: usize,
    seed: u64,
) -> Chi2Outcome {
    let mut obs = vec![0.0f64; grid.cells()];
    let mut rng = Sampler::new(seed, 0xC412, 0);
    let mut sampled = 0;
    let mut error = None;
    for _ in 0..n_samples {
        let (uc, u2) = (rng.get1d(), rng.get2d());
        let Some(w) = sample(uc, u2) else { continue };
        if !w.is_finite() || (w.length() - 1.0).abs() > 1e-3 {
            error.get_or_insert(format!("sample {w:?} is not a unit vector"));
            continue;
        }
        obs[grid.cell_of(w)] += 1.0;
        sampled += 1;
    }
    let n = n_samples as f64;
    let acc = Accuracy::counts(n_samples);
    let mut exp: Vec<f64> = grid.integrate_cells(pdf, acc).iter().map(|p| p * n).collect();
    // Where the counts disagree with the cubature, look harder: the integral
    // does not depend on the samples, only how finely it is resolved, so this
    // cannot hide an error; it keeps a lobe thinner than the first cubature
    // nodes from being missed (then only the samples betray it). A cell the
    // first cubature found empty is looked at again for a single sample: the
    // edge of a lobe's support (the eta 1.01 transmission lobe) can cross it
    // in a sliver between the nodes, and 1 to 3 samples there (expected up
    // to ~5) were counted as strays.
    for c in 0..exp.len() {
        let (o, e) = (obs[c], exp[c]);
        if (o - e) * (o - e) > 9.0 * e.max(1.0) || (e == 0.0 && o > 0.0) {
            exp[c] = n * grid.integrate_cell_split(pdf, c, acc, FINE_SPLIT);
        }
    }
    let pdf_integral = exp.iter().sum::<f64>() / n;
    obs.push(n - sampled as f64);
    exp.push((n * (1.0 - pdf_integral)).max(0.0));
    if let Some(c) = exp.iter().position(|e| !(e.is_finite() && *e >= 0.0)) {
        error.get_or_insert(format!("cell {c}: expected count {}", exp[c]));
    }
    if pdf_integral > 1.1 {
        error.get_or_insert(format!("the pdf integrates to {pdf_integral}"));
    }
    let stray: f64 = obs.iter().zip(&exp).filter(|(_, e)| **e == 0.0).map(|(o, _)| o).sum();
    if stray > 1e-5 * n {
        error.get_or_insert(format!("{stray} samples in cells where the pdf is 0"));
    }
    let (chi2, dof, worst, total_term) = pooled_chi2(&obs, &exp, grid, TOTAL_TOLERANCE * n);
    let sf = |x: f64, dof: usize| ChiSquared::new(dof as f64).map(|d| d.sf(x)).unwrap_or(f64::NAN);
    let p_value = if dof == 0 { 1.0 } else { sf(chi2, dof) };
    Chi2Outcome { chi2, dof, p_value, p_total: sf(total_term, 1), sampled, pdf_integral, error, worst }
}

/// Pearson's statistic with cells pooled (sorted by expected count) until each
/// term expects at least `MIN_EXPECTED`. The last cell is the absent
/// samples', a term of its own whose variance adds `total_error`^2, the
/// error of its expectation, to the Poisson variance (in `worst` its
/// direction is zero); that term is returned too.
fn pooled_chi2(
    obs: &[f64],
    exp: &[f64],
    grid: &SphereGrid,
    total_error: f64,
) -> (f64, usize, Vec<(f64, f64, Vec3A)>, f64) {
    let absent = obs.len() - 1;
    let mut order: Vec<usize> = (0..absent).collect();
    order.sort_by(|&a, &b| exp[a].total_cmp(&exp[b]));
    let (o, e) = (obs[absent], exp[absent]);
    let absent_term = (o - e) * (o - e) / (e + total_error * total_error);
    let (mut chi2, mut terms) = (absent_term, 1usize);
    let (mut pool_obs, mut pool_exp) = (0.0, 0.0);
    let mut contributions = vec![(absent_term, o, e, absent)];
    for &c in &order {
        pool_obs += obs[c];
        pool_exp += exp[c];
        if pool_exp >= MIN_EXPECTED {
            let term = (pool_obs - pool_exp) * (pool_obs - pool_exp) / pool_exp;
            chi2 += term;
            terms += 1;
            contributions.push((term, pool_obs, pool_exp, c));
            pool_obs = 0.0;
            pool_exp = 0.0;
        }
    }
    if pool_exp > 0.0 {
        // The leftover pool (only when the whole sphere expects < 5 more).
        chi2 += (pool_obs - pool_exp) * (pool_obs - pool_exp) / pool_exp;
        terms += 1;
    }
    contributions.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (dt, dp) = (1.0 / grid.n_t as f64, 2.0 * PI / grid.n_phi as f64);
    let worst = contributions
        .iter()
        .take(6)
        .map(|&(_, o, e, c)| {
            let (i, j) = (c / grid.n_phi, c % grid.n_phi);
            let w = if c == grid.cells() {
                Vec3A::ZERO
            } else {
                grid.direction((i as f64 + 0.5) * dt, (j as f64 + 0.5) * dp)
            };
            (o, e, w)
        })
        .collect();
    (chi2, terms.saturating_sub(1), worst, absent_term)
}
