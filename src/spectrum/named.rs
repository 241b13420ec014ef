//! Named measured spectra (metals, glasses, CIE illuminants), blackbody
//! emission and dispersion formulas.
//!
//! Data (see each JSON file's `_source`): metal (eta, k) and Schott glass IOR
//! tables and the CIE illuminants, all as carried in pbrt-v4
//! (src/pbrt/util/spectrum.cpp). Tables are linear between their samples,
//! like pbrt-v4's `PiecewiseLinearSpectrum`: the metals' and glasses' 1 nm
//! grids hold their means over each nanometre (`Spectrum::piecewise_linear`),
//! the illuminants CIE's values at each whole nanometre.

use super::{cie, piecewise_linear_at, Spectrum};
use serde::Deserialize;
use std::collections::HashMap;
use std::sync::LazyLock;

pub const METAL_NAMES: &[&str] = &["Ag", "Al", "Au", "Cu", "CuZn"];
pub const GLASS_NAMES: &[&str] = &["BK7", "BAF10", "FK51A", "LASF9", "SF5", "SF10", "SF11"];
pub const ILLUMINANT_NAMES: &[&str] = &["D65", "A", "D50", "F2", "F11"];

#[derive(Deserialize)]
struct Table {
    wavelengths_nm: Vec<f32>,
    values: Vec<f32>,
}

#[derive(Deserialize)]
struct MetalTable {
    eta: Table,
    k: Table,
}

impl Table {
    fn points(&self, what: &str) -> Vec<(f32, f32)> {
        assert_eq!(self.wavelengths_nm.len(), self.values.len(), "{what}: ragged table");
        assert!(self.wavelengths_nm.windows(2).all(|w| w[0] < w[1]), "{what}: wavelengths must increase");
        self.wavelengths_nm.iter().copied().zip(self.values.iter().copied()).collect()
    }

    /// Refractive indices: the end values are held outside the table (an IOR
    /// of 0 would be unphysical; the tables reach 370-380 nm at worst).
    fn held(&self, what: &str) -> Spectrum {
        Spectrum::piecewise_linear(&self.points(what))
    }

    /// Emission: zero outside the measured range, as pbrt-v4's
    /// `PiecewiseLinearSpectrum` (F2 and F11 are given on 380-780 nm only).
    fn zero_outside(&self, what: &str) -> Spectrum {
        let p = self.points(what);
        let (lo, hi) = (p[0].0, p[p.len() - 1].0);
        Spectrum::from_fn(|l| if (lo..=hi).contains(&l) { piecewise_linear_at(&p, l as f64) as f32 } else { 0.0 })
    }
}

/// Parses one of the data files: every key not starting with `_` is a table.
fn parse<T: for<'de> Deserialize<'de>>(text: &str, file: &str) -> HashMap<String, T> {
    let all: HashMap<String, serde_json::Value> = serde_json::from_str(text).unwrap_or_else(|e| panic!("{file}: {e}"));
    all.into_iter()
        .filter(|(k, _)| !k.starts_with('_'))
        .map(|(k, v)| {
            let t = serde_json::from_value(v).unwrap_or_else(|e| panic!("{file}/{k}: {e}"));
            (k, t)
        })
        .collect()
}

static METALS: LazyLock<HashMap<String, (Spectrum, Spectrum)>> = LazyLock::new(|| {
    parse::<MetalTable>(include_str!("data/metals.json"), "metals.json")
        .into_iter()
        .map(|(name, t)| {
            let eta = t.eta.held(&name);
            let k = t.k.held(&name);
            (name, (eta, k))
        })
        .collect()
});

static GLASSES: LazyLock<HashMap<String, Spectrum>> = LazyLock::new(|| {
    parse::<Table>(include_str!("data/glasses.json"), "glasses.json")
        .into_iter()
        .map(|(name, t)| {
            let s = t.held(&name);
            (name, s)
        })
        .collect()
});

static ILLUMINANTS: LazyLock<HashMap<String, Spectrum>> = LazyLock::new(|| {
    parse::<Table>(include_str!("data/illuminants.json"), "illuminants.json")
        .into_iter()
        .map(|(name, t)| {
            let s = t.zero_outside(&name);
            let y = s.luminance();
            (name, s.scale((1.0 / y) as f32))
        })
        .collect()
});

/// The canonical spelling in `names` of `name`, ignoring ASCII case.
fn canonical(names: &'static [&'static str], name: &str) -> Option<&'static str> {
    names.iter().copied().find(|n| n.eq_ignore_ascii_case(name))
}

/// Complex index of refraction (eta, k) of a named metal (one of
/// [`METAL_NAMES`], ASCII case ignored); end values held outside the table.
pub fn metal_eta_k(name: &str) -> Option<(Spectrum, Spectrum)> {
    METALS.get(canonical(METAL_NAMES, name)?).cloned()
}

/// Index of refraction of a named glass (one of [`GLASS_NAMES`], ASCII case
/// ignored); end values held outside the table.
pub fn glass_ior(name: &str) -> Option<Spectrum> {
    GLASSES.get(canonical(GLASS_NAMES, name)?).cloned()
}

/// A CIE illuminant (one of [`ILLUMINANT_NAMES`], ASCII case ignored)
/// normalised to luminance Y = 1 (as pbrt-v4 does), zero outside its table.
pub fn illuminant(name: &str) -> Option<Spectrum> {
    ILLUMINANTS.get(canonical(ILLUMINANT_NAMES, name)?).cloned()
}

/// Planck's law: spectral radiance of a blackbody at `kelvin`, in
/// W / (m^2 sr nm), at `lambda_nm`. Non-positive temperatures give 0.
pub fn planck(kelvin: f32, lambda_nm: f32) -> f32 {
    planck64(kelvin, lambda_nm) as f32
}

/// `planck` in f64: above ~1e37 K the radiance passes the f32 range.
fn planck64(kelvin: f32, lambda_nm: f32) -> f64 {
    // CODATA 2018 exact SI constants.
    const H: f64 = 6.626_070_15e-34;
    const C: f64 = 299_792_458.0;
    const KB: f64 = 1.380_649e-23;
    if kelvin.is_nan() || lambda_nm.is_nan() || kelvin <= 0.0 || lambda_nm <= 0.0 {
        return 0.0;
    }
    let l = lambda_nm as f64 * 1e-9;
    let x = H * C / (l * KB * kelvin as f64);
    // exp_m1 keeps the Rayleigh-Jeans limit (small x) accurate.
    let b = 2.0 * H * C * C / (l.powi(5) * x.exp_m1());
    b * 1e-9
}

/// Planck's law at `kelvin`, normalised to luminance Y = 1. A non-positive
/// or non-finite temperature gives `Constant(0)`.
pub fn blackbody(kelvin: f32) -> Spectrum {
    if !kelvin.is_finite() || kelvin <= 0.0 {
        return Spectrum::Constant(0.0);
    }
    // Normalised in f64, before the values are rounded to f32: any finite
    // temperature has a finite luminance there.
    let y = cie::luminance_of(|l| planck64(kelvin, l));
    if y > 0.0 && y.is_finite() {
        Spectrum::from_fn(|l| (planck64(kelvin, l) / y) as f32)
    } else {
        // So cold that the visible emission underflows.
        Spectrum::Constant(0.0)
    }
}

/// The Sellmeier equation n^2 = 1 + sum_i B_i l^2 / (l^2 - C_i) at one
/// wavelength (l in micrometres, C_i in um^2), as in Schott's data sheets.
/// Near a resonance (l^2 ~ C_i) n^2 may go negative; it is clamped to 0, so the
/// coefficients must put the resonances outside 360-830 nm.
pub fn sellmeier_ior(b: [f32; 3], c: [f32; 3], lambda_nm: f32) -> f32 {
    let l2 = (lambda_nm as f64 * 1e-3).powi(2);
    let n2 = 1.0 + b.iter().zip(c.iter()).map(|(&bi, &ci)| bi as f64 * l2 / (l2 - ci as f64)).sum::<f64>();
    n2.max(0.0).sqrt() as f32
}

/// Sellmeier: n^2 = 1 + sum B_i l^2 / (l^2 - C_i), l in micrometres, C in um^2.
pub fn sellmeier(b: [f32; 3], c: [f32; 3]) -> Spectrum {
    Spectrum::from_fn(|l| sellmeier_ior(b, c, l))
}

/// Cauchy's equation n = A + B / l^2 at one wavelength (l in micrometres,
/// B in um^2).
pub fn cauchy_ior(a: f32, b: f32, lambda_nm: f32) -> f32 {
    let l = lambda_nm as f64 * 1e-3;
    (a as f64 + b as f64 / (l * l)) as f32
}

/// Cauchy: n = A + B / l^2, l in micrometres.
pub fn cauchy(a: f32, b: f32) -> Spectrum {
    Spectrum::from_fn(|l| cauchy_ior(a, b, l))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_named_spectrum_loads() {
        for n in METAL_NAMES {
            let (eta, k) = metal_eta_k(n).unwrap();
            assert!(eta.min_value() > 0.0 && k.min_value() > 0.0, "{n}");
        }
        for n in GLASS_NAMES {
            let s = glass_ior(n).unwrap();
            assert!(s.min_value() > 1.3 && s.max_value() < 2.1, "{n}");
        }
        for n in ILLUMINANT_NAMES {
            let s = illuminant(n).unwrap();
            assert!((s.luminance() - 1.0).abs() < 1e-5, "{n}");
            assert!(s.min_value() >= 0.0, "{n}");
        }
        assert!(metal_eta_k("au").is_some());
        assert!(glass_ior("unobtainium").is_none());
        assert!(illuminant("D75").is_none());
    }

    #[test]
    fn fluorescent_tables_are_zero_outside_their_range() {
        let f2 = illuminant("F2").unwrap();
        assert_eq!(f2.eval(370.0), 0.0);
        assert_eq!(f2.eval(800.0), 0.0);
        assert!(f2.eval(380.0) > 0.0);
    }

    #[test]
    fn cauchy_matches_its_formula() {
        // n = 1.5 + 0.00420 / 0.5^2 at 500 nm.
        assert!((cauchy_ior(1.5, 0.0042, 500.0) - 1.5168).abs() < 1e-6);
        assert!((cauchy(1.5, 0.0042).eval(500.0) - 1.5168).abs() < 1e-6);
        assert!(cauchy(1.5, 0.0).is_constant());
    }

    #[test]
    fn sellmeier_without_resonances_is_vacuum() {
        assert_eq!(sellmeier_ior([0.0; 3], [0.01, 0.02, 100.0], 500.0), 1.0);
    }

    #[test]
    fn planck_matches_a_hand_value() {
        // B(500 nm, 5000 K) = 1.2107e13 W/(m^2 sr m) (2hc^2/l^5 / (e^{hc/lkT} - 1)).
        let b = planck(5000.0, 500.0) as f64 * 1e9;
        assert!((b / 1.2107e13 - 1.0).abs() < 1e-3, "{b}");
        assert_eq!(planck(0.0, 500.0), 0.0);
        assert_eq!(blackbody(-1.0), Spectrum::Constant(0.0));
    }
}
