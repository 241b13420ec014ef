//! Render space: the scene moved near the origin, exactly, before anything
//! is computed from its positions.
//!
//! f32 positions carry an absolute rounding error that grows with their
//! magnitude: the spawn offsets (pbrt-v4 §6.8.6), the hit points and the
//! densities BDPT recomputes between stored vertices all err by units in
//! the last place of the coordinates, not of the scene's size. A 1-unit
//! room at x = 1e4 read 0.7 % dark under `bdpt` (MIS weights of one path
//! summing below 1) and leaked light through its corners under `path`
//! from x = 10 on, while the same room at the origin did neither (an
//! audit, session 42). pbrt-v4 renders in "camera-world" space for the
//! same reason (§5.1.1). Here the shift is chosen so that the move is
//! exact: each axis on which the geometry lies wholly on one side of 0, at
//! least its extent rounded up to a power of two away, is moved by a multiple of a power of two no
//! finer than any position's last place, so every vertex keeps its exact
//! value relative to every other. The image is the same in exact arithmetic
//! and, for a scene whose positions were exact, bit for bit the image of
//! the scene built at the origin. Scenes that contain the origin are not
//! moved.

use glam::Vec3A;

/// The translation that takes positions within [lo, hi] to render space
/// (subtract it); 0 on every axis that it would not help.
pub fn origin_shift(lo: Vec3A, hi: Vec3A) -> Vec3A {
    let axis = |lo: f32, hi: f32| {
        if !(lo.is_finite() && hi.is_finite()) || (lo <= 0.0 && hi >= 0.0) {
            return 0.0;
        }
        // The side's nearer and farther distances from 0.
        let (near, far) = if lo > 0.0 { (lo, hi) } else { (-hi, -lo) };
        // A power of two at least the extent and the farthest position's
        // last place: positions and the shift are then all multiples of
        // each position's last place, and so is every difference.
        let grid = (far - near).max(ulp(far)).max(f32::MIN_POSITIVE);
        let grid = 2f32.powi(grid.log2().ceil() as i32);
        if !grid.is_finite() {
            // Extents near f32::MAX: no power of two bounds them.
            return 0.0;
        }
        let shift = (near / grid).floor() * grid;
        if lo > 0.0 {
            shift
        } else {
            -shift
        }
    };
    Vec3A::new(axis(lo.x, hi.x), axis(lo.y, hi.y), axis(lo.z, hi.z))
}

/// A point moved by `-shift`, correctly rounded (exact for the geometry the
/// shift was chosen for; a camera or light far outside it may round).
pub fn shifted(p: Vec3A, shift: Vec3A) -> Vec3A {
    (p.as_dvec3() - shift.as_dvec3()).as_vec3a()
}

/// The distance from |x| to the next larger f32.
fn ulp(x: f32) -> f32 {
    let x = x.abs();
    f32::from_bits(x.to_bits() + 1) - x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Geometry that contains the origin, or lies nearer to it than its
    /// extent rounded up to a power of two, is not moved; far geometry is
    /// moved to within twice that power of two of the origin, exactly.
    #[test]
    fn the_shift_is_exact_and_only_where_it_helps() {
        let v = |x, y, z| Vec3A::new(x, y, z);
        assert_eq!(origin_shift(v(0.0, -1.0, -550.0), v(556.0, 548.8, 0.0)), Vec3A::ZERO);
        assert_eq!(origin_shift(v(1.0, 1.0, 1.0), v(551.0, 2.0, 1.5)), v(0.0, 1.0, 1.0));
        assert_eq!(origin_shift(v(1e4, -1e4 - 1.0, 5.0), v(1e4 + 1.0, -1e4, 5.0)), v(1e4, -1e4, 5.0));
        let (lo, hi) = (v(1e6 + 0.1, 3e5 + 0.37, -7e4 - 1.2), v(1e6 + 1.37, 3e5 + 0.9, -7e4 - 0.3));
        let shift = origin_shift(lo, hi);
        for p in [lo, hi, (lo + hi) * 0.5, v(1e6 + 0.7, 3e5 + 0.4, -7e4 - 1.0)] {
            let q = p - shift;
            assert_eq!(q + shift, p, "{p} is not moved exactly");
            assert_eq!(shifted(p, shift), q);
            assert!(q.abs().max_element() <= 2.5, "{p} -> {q}");
        }
        // A flat scene far out, and one thinner than its last place.
        assert_eq!(origin_shift(v(3.0, 0.0, 0.0), v(3.0, 1.0, 1.0)), v(3.0, 0.0, 0.0));
        let p = 1e7f32;
        let s = origin_shift(v(p, 0.0, 0.0), v(p, 0.0, 0.0)).x;
        assert_eq!(p - s + s, p);
        assert!((p - s).abs() <= 1.0);
        // Non-finite bounds (an empty scene) and extents no f32 power of
        // two bounds move nothing.
        assert_eq!(origin_shift(Vec3A::INFINITY, Vec3A::NEG_INFINITY), Vec3A::ZERO);
        assert_eq!(origin_shift(v(1.0, 1e38, -3e38), v(f32::MAX, 3e38, -1e38)), Vec3A::ZERO);
    }
}
