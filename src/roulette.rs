//! Russian roulette (Arvo and Kirk, "Particle Transport and Image
//! Synthesis", SIGGRAPH 1990): ending a path at random without bias. One
//! rule for every estimator, camera and light subpaths alike.

use crate::spectrum::SampledSpectrum;

/// Russian roulette on throughput (pbrt-v4 PathIntegrator): after
/// `MIN_DEPTH` bounces, continue with probability min(1, max beta') where
/// beta' is the throughput with refraction's 1/eta^2 taken out; survivors
/// are reweighted by 1/(continuation probability). Returns false to stop.
/// The stopping probability q is on u's grid of 2^-24 (1 - m rounds to it,
/// and 1 - q is then exact), so a survivor's weight is exactly the inverse
/// of its chance; it is at most 1 - 2^-24, or a throughput at or below
/// 2^-25, for which 1 - m rounds to 1, would never survive (an audit,
/// session 36).
///
/// The uniform number is drawn by `u` only when the coin is tossed: not
/// before `MIN_DEPTH` nor while the throughput is at least 1 (a step of the
/// generator saved per early bounce, docs/performance-log.md, "Session 47").
#[inline]
pub fn russian_roulette(beta: &mut SampledSpectrum, eta_scale: f32, depth: u32, u: impl FnOnce() -> f32) -> bool {
    const MIN_DEPTH: u32 = 3;
    if depth < MIN_DEPTH {
        return true;
    }
    let m = (*beta * eta_scale).max_component();
    if m >= 1.0 {
        return true;
    }
    let q = (1.0 - m).clamp(0.0, 1.0 - f32::EPSILON / 2.0);
    if u() < q {
        return false;
    }
    *beta /= 1.0 - q;
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Roulette keeps the expected throughput: over every u the sampler can
    /// give (k 2^-24, k < 2^24), the mean of what survives is the
    /// throughput, to f32's rounding of one division, from 1e-9 (at or
    /// below 2^-25, 1 - m rounds to 1: without the clamp such a path never
    /// survived and the mean was 0) to just under 1.
    #[test]
    fn roulette_keeps_the_expected_throughput() {
        for m in [1e-9f32, 2f32.powi(-25), 3e-8, 1e-6, 0.3, 0.5, 0.7, 0.999_999] {
            let mut sum = 0f64;
            for k in 0..1u32 << 24 {
                let mut beta = SampledSpectrum::splat(m);
                if russian_roulette(&mut beta, 1.0, 3, || k as f32 / (1u32 << 24) as f32) {
                    sum += beta[0] as f64;
                }
            }
            let mean = sum / (1u32 << 24) as f64;
            assert!((mean / m as f64 - 1.0).abs() < 1e-6, "throughput {m}: mean after roulette {mean}");
        }
    }
}
