//! The fit of Jakob & Hanika 2019 ("A Low-Dimensional Function Space for
//! Efficient Spectral Upsampling", EG 2019), Sec. 3-4: a reflectance
//! s(l) = S(c0 t^2 + c1 t + c2), S(x) = 1/2 + x / (2 sqrt(1 + x^2)), whose
//! colour under the sRGB white (D65) matches a target, found by damped
//! Gauss-Newton (Levenberg-Marquardt) on the CIELAB difference.
//!
//! Wavelength is normalised while fitting, t = (l - 360 nm) / 470 nm, so the
//! three coefficients have comparable scales (as in pbrt-v4's rgb2spec_opt).
//! All sums are the renderer's own 1 nm sums over 360..=830 nm, so a fit that
//! converges here round-trips exactly under the definition of `super`.

use crate::spectrum::{illuminant, xyz_to_linear_srgb, Spectrum, LAMBDA_MIN, N_DENSE};
use glam::Vec3;
use std::sync::LazyLock;

/// Width of the fitted range, nm: t = (l - LAMBDA_MIN) / LAMBDA_SPAN.
pub(super) const LAMBDA_SPAN: f64 = (N_DENSE - 1) as f64;

type Mat3 = [[f64; 3]; 3];

/// The observer (CIE 1931 2-degree CMFs) under D65, as weights per 1 nm sample.
struct Observer {
    /// Normalised wavelength of each 1 nm sample.
    t: Vec<f64>,
    /// cmf(l) D65(l) / sum(ybar D65): XYZ of a reflectance is sum(s w).
    w: Vec<[f64; 3]>,
    /// XYZ of the perfect reflector under D65 (Y = 1): CIELAB's white.
    white: [f64; 3],
    /// Linear sRGB from XYZ, the renderer's matrix (`xyz_to_linear_srgb`).
    xyz_to_rgb: Mat3,
    rgb_to_xyz: Mat3,
}

/// The CMF file that `cie.rs` reads, parsed the same way.
fn cmf_table() -> Vec<[f64; 3]> {
    let rows: Vec<[f64; 3]> = include_str!("../data/cie1931_2deg_cmf_1nm.csv")
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("lambda"))
        .map(|l| {
            let v: Vec<f32> = l.split(',').map(|x| x.trim().parse().expect("CIE table")).collect();
            [v[1] as f64, v[2] as f64, v[3] as f64]
        })
        .collect();
    assert_eq!(rows.len(), N_DENSE, "CIE table must cover 360..=830 nm at 1 nm");
    rows
}

static OBSERVER: LazyLock<Observer> = LazyLock::new(|| {
    let d65 = illuminant("D65").expect("D65 is tabulated");
    let cmf = cmf_table();
    let spd: Vec<f64> = (0..N_DENSE).map(|i| d65.eval(LAMBDA_MIN + i as f32) as f64).collect();
    let norm: f64 = cmf.iter().zip(&spd).map(|(c, e)| c[1] * e).sum();
    let w: Vec<[f64; 3]> = cmf.iter().zip(&spd).map(|(c, e)| c.map(|v| v * e / norm)).collect();
    let white = w.iter().fold([0.0; 3], |a, v| [a[0] + v[0], a[1] + v[1], a[2] + v[2]]);
    // Columns of the renderer's matrix, read back exactly (M e_j).
    let mut xyz_to_rgb = [[0.0; 3]; 3];
    for (j, e) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
        let col = xyz_to_linear_srgb(e).to_array();
        for i in 0..3 {
            xyz_to_rgb[i][j] = col[i] as f64;
        }
    }
    let rgb_to_xyz = inverse(&xyz_to_rgb).expect("sRGB matrix is invertible");
    Observer { t: (0..N_DENSE).map(|i| i as f64 / LAMBDA_SPAN).collect(), w, white, xyz_to_rgb, rgb_to_xyz }
});

/// The sigmoid S(x) = 1/2 + x / (2 sqrt(1 + x^2)) of Jakob & Hanika (eq. 3):
/// algebraic, so cheaper than tanh, and in [0, 1] for every x.
#[inline]
pub(crate) fn sigmoid(x: f64) -> f64 {
    if x.abs() > 1e10 {
        // x^2 would overflow; S is 0 or 1 to f64 precision here anyway.
        return if x > 0.0 { 1.0 } else { 0.0 };
    }
    if x.is_nan() {
        return 0.0;
    }
    0.5 + x / (2.0 * (1.0 + x * x).sqrt())
}

/// dS/dx = 1 / (2 (1 + x^2)^(3/2)).
#[inline]
fn sigmoid_derivative(x: f64) -> f64 {
    if x.abs() > 1e10 {
        return 0.0;
    }
    let q = 1.0 + x * x;
    0.5 / (q * q.sqrt())
}

#[inline]
fn polynomial(c: &[f64; 3], t: f64) -> f64 {
    (c[0] * t + c[1]) * t + c[2]
}

/// The reflectance of normalised-wavelength coefficients as a 1 nm spectrum.
pub(super) fn spectrum_of(c: &[f64; 3]) -> Spectrum {
    Spectrum::from_fn(|l| {
        let t = (l as f64 - LAMBDA_MIN as f64) / LAMBDA_SPAN;
        sigmoid(polynomial(c, t)) as f32
    })
}

/// XYZ under D65 of the reflectance with coefficients c and its Jacobian
/// d XYZ / d c (rows X, Y, Z).
fn xyz_and_jacobian(c: &[f64; 3]) -> ([f64; 3], Mat3) {
    let o = &*OBSERVER;
    let mut xyz = [0.0; 3];
    let mut jac = [[0.0; 3]; 3];
    for (&t, w) in o.t.iter().zip(&o.w) {
        let x = polynomial(c, t);
        let s = sigmoid(x);
        let ds = sigmoid_derivative(x);
        let basis = [t * t * ds, t * ds, ds];
        for r in 0..3 {
            xyz[r] += w[r] * s;
            for k in 0..3 {
                jac[r][k] += w[r] * basis[k];
            }
        }
    }
    (xyz, jac)
}

/// Linear sRGB of the reflectance with coefficients c under D65 (f64).
pub(super) fn rgb_of(c: &[f64; 3]) -> [f64; 3] {
    mul(&OBSERVER.xyz_to_rgb, &xyz_and_jacobian(c).0)
}

const LAB_DELTA: f64 = 6.0 / 29.0;

/// CIELAB's f and its derivative (CIE 15:2004, eq. 8.3).
#[inline]
fn lab_f(t: f64) -> (f64, f64) {
    if t > LAB_DELTA * LAB_DELTA * LAB_DELTA {
        let f = t.cbrt();
        (f, 1.0 / (3.0 * f * f))
    } else {
        let k = 1.0 / (3.0 * LAB_DELTA * LAB_DELTA);
        (t * k + 4.0 / 29.0, k)
    }
}

/// CIELAB of XYZ relative to `white`, and d Lab / d XYZ.
fn lab_and_jacobian(xyz: &[f64; 3], white: &[f64; 3]) -> ([f64; 3], Mat3) {
    let (fx, dx) = lab_f(xyz[0] / white[0]);
    let (fy, dy) = lab_f(xyz[1] / white[1]);
    let (fz, dz) = lab_f(xyz[2] / white[2]);
    let (dx, dy, dz) = (dx / white[0], dy / white[1], dz / white[2]);
    let lab = [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)];
    let jac = [[0.0, 116.0 * dy, 0.0], [500.0 * dx, -500.0 * dy, 0.0], [0.0, 200.0 * dy, -200.0 * dz]];
    (lab, jac)
}

/// Stopping rule and safeguards of one fit.
#[derive(Clone, Copy, Debug)]
pub(super) struct FitOptions {
    /// Accepted Levenberg-Marquardt steps at most.
    pub max_steps: usize,
    /// Stop once every linear-sRGB component is this close to the target.
    pub rgb_tolerance: f64,
}

/// Fits `c` (normalised-wavelength coefficients, updated in place, used as
/// the starting point) so that the reflectance's linear sRGB under D65 is
/// `rgb`. Returns the final max-norm error in linear sRGB.
///
/// Residual: CIELAB difference (Jakob & Hanika, Sec. 4: errors are weighed
/// perceptually, so dark colours are fitted as carefully as bright ones).
/// Steps: Gauss-Newton on the 3x3 system, with Marquardt's damping
/// (J^T J + mu diag(J^T J)) when a full step does not lower the residual.
pub(super) fn fit(rgb: [f64; 3], c: &mut [f64; 3], opt: FitOptions) -> f64 {
    let o = &*OBSERVER;
    let target_xyz = mul(&o.rgb_to_xyz, &rgb);
    let target_lab = lab_and_jacobian(&target_xyz, &o.white).0;
    let evaluate = |c: &[f64; 3]| {
        let (xyz, jx) = xyz_and_jacobian(c);
        let (lab, jl) = lab_and_jacobian(&xyz, &o.white);
        let r = [lab[0] - target_lab[0], lab[1] - target_lab[1], lab[2] - target_lab[2]];
        let fit_rgb = mul(&o.xyz_to_rgb, &xyz);
        let err = (0..3).map(|i| (fit_rgb[i] - rgb[i]).abs()).fold(0.0, f64::max);
        (r, matmul(&jl, &jx), err)
    };
    let cost = |r: &[f64; 3]| r.iter().map(|v| v * v).sum::<f64>();

    let (mut r, mut jac, mut err) = evaluate(c);
    let mut mu = 0.0;
    for _ in 0..opt.max_steps {
        if err <= opt.rgb_tolerance {
            break;
        }
        let jt = transpose(&jac);
        let a = matmul(&jt, &jac);
        let g = mul(&jt, &r);
        // Marquardt's scaling, floored so a saturated (flat) direction is
        // still damped.
        let floor = 1e-12 * (a[0][0] + a[1][1] + a[2][2]);
        let mut accepted = false;
        for _ in 0..16 {
            let mut ad = a;
            for k in 0..3 {
                ad[k][k] += mu * a[k][k].max(floor);
            }
            let Some(ai) = inverse(&ad) else {
                mu = (mu * 10.0).max(1e-6);
                continue;
            };
            let step = mul(&ai, &g);
            let trial = [c[0] - step[0], c[1] - step[1], c[2] - step[2]];
            let (r2, jac2, err2) = evaluate(&trial);
            if cost(&r2) < cost(&r) {
                (*c, r, jac, err) = (trial, r2, jac2, err2);
                mu *= 0.1;
                if mu < 1e-9 {
                    mu = 0.0;
                }
                accepted = true;
                break;
            }
            mu = (mu * 10.0).max(1e-6);
        }
        if !accepted {
            // No damping lowers the residual: a (local) optimum at f64 precision.
            break;
        }
    }
    err
}

fn mul(m: &Mat3, v: &[f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn matmul(a: &Mat3, b: &Mat3) -> Mat3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn transpose(a: &Mat3) -> Mat3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[j][i]))
}

/// Inverse by the adjugate; None when singular to working precision.
fn inverse(m: &Mat3) -> Option<Mat3> {
    let cof = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    let det = m[0][0] * cof(0, 0) + m[0][1] * cof(0, 1) + m[0][2] * cof(0, 2);
    let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    if !det.is_finite() || det.abs() <= 1e-14 * scale * scale * scale {
        return None;
    }
    Some([0, 1, 2].map(|i| [0, 1, 2].map(|j| cof(j, i) / det)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sigmoid_limits_and_derivative() {
        assert_eq!(sigmoid(0.0), 0.5);
        assert_eq!(sigmoid(1e300), 1.0);
        assert_eq!(sigmoid(f64::NEG_INFINITY), 0.0);
        for x in [-30.0, -1.0, -0.1, 0.3, 2.0, 50.0] {
            let h = 1e-6 * (1.0 + f64::abs(x));
            let fd = (sigmoid(x + h) - sigmoid(x - h)) / (2.0 * h);
            assert!((fd - sigmoid_derivative(x)).abs() < 1e-7 * (1.0 + fd.abs()), "{x}");
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let o = &*OBSERVER;
        for c in [[0.0, 0.0, 0.0], [-3.0, 2.5, -0.4], [40.0, -35.0, 6.0]] {
            let (xyz, jx) = xyz_and_jacobian(&c);
            let (_, jl) = lab_and_jacobian(&xyz, &o.white);
            let j = matmul(&jl, &jx);
            for k in 0..3 {
                let h = 1e-6;
                let (mut cp, mut cm) = (c, c);
                cp[k] += h;
                cm[k] -= h;
                let lp = lab_and_jacobian(&xyz_and_jacobian(&cp).0, &o.white).0;
                let lm = lab_and_jacobian(&xyz_and_jacobian(&cm).0, &o.white).0;
                for r in 0..3 {
                    let fd = (lp[r] - lm[r]) / (2.0 * h);
                    assert!((fd - j[r][k]).abs() < 1e-5 * (1.0 + fd.abs()), "{c:?} {r} {k}");
                }
            }
        }
    }

    #[test]
    fn white_is_lab_100_0_0_and_rgb_1() {
        let o = &*OBSERVER;
        let lab = lab_and_jacobian(&o.white, &o.white).0;
        assert!((lab[0] - 100.0).abs() < 1e-12 && lab[1].abs() < 1e-12 && lab[2].abs() < 1e-12);
        // The tabulated D65 lands on the sRGB white to ~3e-6.
        for v in mul(&o.xyz_to_rgb, &o.white) {
            assert!((v - 1.0).abs() < 1e-5, "{v}");
        }
        let i = matmul(&o.xyz_to_rgb, &o.rgb_to_xyz);
        for (r, row) in i.iter().enumerate() {
            for (k, v) in row.iter().enumerate() {
                assert!((v - if r == k { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn fits_a_saturated_colour_from_flat_grey() {
        let opt = FitOptions { max_steps: 100, rgb_tolerance: 1e-9 };
        for rgb in [[0.8, 0.1, 0.05], [0.05, 0.3, 0.6], [0.2, 0.7, 0.1], [0.02, 0.01, 0.015]] {
            let mut c = [0.0; 3];
            let err = fit(rgb, &mut c, opt);
            assert!(err < 1e-9, "{rgb:?}: {err}");
            let back = rgb_of(&c);
            assert!((0..3).all(|i| (back[i] - rgb[i]).abs() < 1e-9));
        }
    }
}
