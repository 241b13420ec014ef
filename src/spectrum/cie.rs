//! CIE 1931 2-degree colour matching functions (1 nm, 360-830 nm; data file
//! `data/cie1931_2deg_cmf_1nm.csv`, CIE tables as carried in pbrt-v4) and the
//! conversion of a hero-wavelength estimate to XYZ and linear sRGB (D65).

use super::{padded, slot, SampledSpectrum, SampledWavelengths, Spectrum, DENSE_SLOTS, N_DENSE};
use glam::{Mat3, Vec3, Vec4};
use std::sync::LazyLock;

pub(super) const LAMBDA_MIN_I: i32 = 360;
pub(super) const LAMBDA_MAX_I: i32 = 830;
pub const LAMBDA_MIN: f32 = LAMBDA_MIN_I as f32;
pub const LAMBDA_MAX: f32 = LAMBDA_MAX_I as f32;

/// Integral of ybar over 360-830 nm (1 nm sums), the normaliser that maps a
/// constant spectrum of value v to luminance Y = v.
pub const CIE_Y_INTEGRAL: f32 = 106.856_895;

/// xbar, ybar, zbar at each integer wavelength, interleaved, then zeros up
/// to `DENSE_SLOTS`: looked up by a masked index, as `DenseTable` is.
static CMF: LazyLock<[[f32; 3]; DENSE_SLOTS]> = LazyLock::new(|| {
    let text = include_str!("data/cie1931_2deg_cmf_1nm.csv");
    let rows: Vec<[f32; 3]> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("lambda"))
        .map(|l| {
            let v: Vec<f32> = l.split(',').map(|x| x.trim().parse().expect("CIE table")).collect();
            [v[1], v[2], v[3]]
        })
        .collect();
    assert_eq!(rows.len(), N_DENSE, "CIE table must cover 360..=830 nm at 1 nm");
    padded(&rows)
});

/// The colour matching functions over the visible range.
fn cmf_rows() -> &'static [[f32; 3]] {
    &CMF[..N_DENSE]
}

/// The colour matching functions at one path's sampled wavelengths, as the
/// linear map from its spectral estimate to a colour: row j holds, per lane
/// i, cmf_j(l_i) / (4 p(l_i) integral of ybar), the Monte Carlo weights of
/// XYZ_j = sum_i cmf_j(l_i) L_i / (4 p(l_i)) (zero for a lane with pdf 0: a
/// terminated secondary contributes nothing). Built once per sample, it
/// converts the sample's camera estimate and all its splats (light tracing
/// makes ~3 per sample) with three dot products each.
#[derive(Clone, Copy, Debug)]
pub struct SampledCmf {
    rows: [Vec4; 3],
}

impl SampledCmf {
    /// The map to CIE XYZ.
    #[inline]
    pub fn xyz(lambda: &SampledWavelengths) -> Self {
        let w = SampledSpectrum::ONE.safe_div(SampledSpectrum(lambda.pdf)).0 / (4.0 * CIE_Y_INTEGRAL);
        let slots = &*CMF;
        let cmf = |i: u32| Vec3::from_array(slots[slot(i)]);
        let [a, b, c, d] = lambda.dense.map(cmf);
        let row = |k: usize| Vec4::new(a[k], b[k], c[k], d[k]) * w;
        Self { rows: [row(0), row(1), row(2)] }
    }

    /// The map to linear sRGB: the XYZ rows through `xyz_to_linear_srgb`.
    #[inline]
    pub fn linear_srgb(lambda: &SampledWavelengths) -> Self {
        let [x, y, z] = Self::xyz(lambda).rows;
        let m = XYZ_TO_LINEAR_SRGB.transpose();
        let row = |j: usize| x * m.col(j).x + y * m.col(j).y + z * m.col(j).z;
        Self { rows: [row(0), row(1), row(2)] }
    }

    /// The colour of estimate `l`.
    #[inline]
    pub fn apply(&self, l: SampledSpectrum) -> Vec3 {
        Vec3::new(self.rows[0].dot(l.0), self.rows[1].dot(l.0), self.rows[2].dot(l.0))
    }
}

/// Monte Carlo estimate of XYZ from radiance at the sampled wavelengths
/// (`SampledCmf`).
pub fn to_xyz(l: SampledSpectrum, lambda: &SampledWavelengths) -> Vec3 {
    SampledCmf::xyz(lambda).apply(l)
}

/// XYZ to linear sRGB (D65 white), the standard matrix (IEC 61966-2-1).
const XYZ_TO_LINEAR_SRGB: Mat3 = Mat3::from_cols_array(&[
    3.240_454_2,
    -0.969_266,
    0.055_643_4, //
    -1.537_138_5,
    1.876_010_8,
    -0.204_025_9, //
    -0.498_531_4,
    0.041_556,
    1.057_225_2,
]);

/// `XYZ_TO_LINEAR_SRGB` applied to a colour.
pub fn xyz_to_linear_srgb(xyz: Vec3) -> Vec3 {
    XYZ_TO_LINEAR_SRGB * xyz
}

/// Exact XYZ of a spectrum (1 nm sums), normalised so a constant v has Y = v.
pub fn spectrum_to_xyz(s: &Spectrum) -> Vec3 {
    let mut acc = Vec3::ZERO;
    for (i, c) in cmf_rows().iter().enumerate() {
        acc += Vec3::from_array(*c) * s.eval(LAMBDA_MIN + i as f32);
    }
    acc / CIE_Y_INTEGRAL
}

/// Luminance Y of `s` (see `luminance_of`).
pub(super) fn luminance(s: &Spectrum) -> f64 {
    luminance_of(|l| s.eval(l) as f64)
}

/// Luminance Y of the spectrum `f` (nm -> value): the sum of f ybar over the
/// 1 nm table divided by that of ybar. In f64: the sum of a spectrum near
/// the top of the f32 range (an emission of 4e36) would overflow f32, and
/// an infinite light power leaves a scene with no light sampling at all.
pub(super) fn luminance_of(f: impl Fn(f32) -> f64) -> f64 {
    let sum: f64 = cmf_rows().iter().enumerate().map(|(i, c)| c[1] as f64 * f(LAMBDA_MIN + i as f32)).sum();
    sum / CIE_Y_INTEGRAL as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ybar_integral_matches_the_table() {
        let s: f32 = cmf_rows().iter().map(|c| c[1]).sum();
        assert!((s - CIE_Y_INTEGRAL).abs() < 1e-3, "{s}");
        assert!((Spectrum::Constant(2.5).luminance() - 2.5).abs() < 1e-4);
    }

    /// The film's one map equals the two steps it folds together, the XYZ
    /// estimate and then the sRGB matrix, at wavelengths across the range
    /// and with the secondaries ended (lanes of pdf 0 add nothing).
    #[test]
    fn srgb_map_is_the_matrix_after_the_xyz_estimate() {
        let l = SampledSpectrum::new(0.7, 2.5, 0.01, 1.3);
        for k in 0..64 {
            let mut lambda = SampledWavelengths::sample_visible((k as f32 + 0.5) / 64.0);
            if k % 2 == 1 {
                lambda.terminate_secondary();
            }
            let two_steps = xyz_to_linear_srgb(to_xyz(l, &lambda));
            let one_map = SampledCmf::linear_srgb(&lambda).apply(l);
            let scale = two_steps.abs().max_element().max(1e-3);
            assert!((one_map - two_steps).abs().max_element() < 1e-5 * scale, "{one_map} vs {two_steps}, lambda {k}");
        }
    }

    #[test]
    fn equal_energy_is_white_point_e() {
        let xyz = spectrum_to_xyz(&Spectrum::Constant(1.0));
        let sum = xyz.x + xyz.y + xyz.z;
        // Illuminant E has chromaticity (1/3, 1/3).
        assert!((xyz.x / sum - 1.0 / 3.0).abs() < 1e-3);
        assert!((xyz.y / sum - 1.0 / 3.0).abs() < 1e-3);
    }
}
