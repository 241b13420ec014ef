//! Emitters lying in another surface's plane, overlapping it: which of the
//! two a ray meets there is decided by rounding, not by the geometry, and
//! each estimator traces different rays, so they disagree. The Cornell
//! box's measured data put its light in the ceiling's plane; so placed,
//! `path` read 6.5 % below `light` and `bdpt` inside the room
//! (docs/scene-format.md). Estimators cannot fix this; the scene can.

use super::{mesh_index, Scene};
use crate::geometry::NO_TRIANGLE;
use crate::light::{AreaLight, Light};
use glam::{DVec2, DVec3, Vec2, Vec3A};
use rayon::prelude::*;
use std::ops::ControlFlow;

impl Scene {
    /// A warning naming the emitting triangles that lie within a few units
    /// in the last place of another triangle's plane and overlap it with
    /// positive area (a shared edge is no overlap), if any do. The other
    /// may emit too: of two emitters laid on each other (two one-sided
    /// quads facing apart, a cuboid flat on one axis) a ray meets one, by
    /// rounding, so `path` lost one side of such a lamp (an audit: 0.24
    /// against 0.31 for `light` and `bdpt`; a `two_sided` quad is the lamp
    /// it meant). Each emitter is tested against the triangles the BVH
    /// finds near its bounds only (`MAX_CANDIDATES` of them at most), of
    /// its own mesh against `MAX_OWN_MESH_TESTS` at most, so the check
    /// costs about a ray query per emitter.
    pub fn emitters_on_surfaces(&self) -> Option<String> {
        // An emitter left out of the BVH (collinear vertices) is never hit,
        // so no rounding decides anything there.
        let emitters: Vec<(&AreaLight, &str)> = (self.lights.iter().zip(&self.light_names))
            .filter_map(|(l, name)| match l {
                Light::Area(a) if a.slot != NO_TRIANGLE => Some((a, name.as_str())),
                _ => None,
            })
            .collect();
        let mut emitter_slots: Vec<(u32, &str)> = emitters.iter().map(|&(a, name)| (a.slot, name)).collect();
        emitter_slots.sort_unstable();
        // Half the pad is already no less than any triangle's tolerance in
        // `in_plane`: it covers the largest coordinate of the scene. The
        // other half covers the rounding of the padded bounds.
        let (lo, hi) = self.accel.bounds();
        let mesh_of_slot = |slot: u32| self.mesh_of(slot, self.accel.slot_prims()[slot as usize]);
        let surface_of = |e: &AreaLight| {
            let pad = 2.0 * (near(e.v.iter().copied().chain([lo, hi])) + off_plane(Vec3A::ONE, self.render_shift));
            let (e_lo, e_hi) = bounds(e.v);
            let own_mesh = self.mesh_of(e.slot, e.prim);
            let (mut surface, mut visits, mut own_tests) = (None, 0, 0);
            self.accel.overlapping((e_lo - pad, e_hi + pad), |slot| {
                visits += 1;
                if visits > MAX_CANDIDATES {
                    return ControlFlow::Break(());
                }
                let own = mesh_of_slot(slot) == own_mesh;
                if slot == e.slot || (own && own_tests == MAX_OWN_MESH_TESTS) {
                    return ControlFlow::Continue(());
                }
                let t = self.accel.vertices(slot);
                let tolerance = near(e.v.iter().chain(&t).copied()) + off_plane(e.n, self.render_shift);
                if !in_plane(&e.v, e.n, &t, tolerance) {
                    return ControlFlow::Continue(());
                }
                if overlap_in_plane(&e.v, e.n, &t, tolerance) {
                    surface = Some(match emitter_slots.binary_search_by_key(&slot, |&(s, _)| s) {
                        Ok(i) => format!("the emitter \"{}\"", emitter_slots[i].1),
                        Err(_) => self.surface_name(slot),
                    });
                    return ControlFlow::Break(());
                }
                own_tests += own as u32;
                ControlFlow::Continue(())
            });
            surface
        };
        let found: Vec<(&str, String)> =
            emitters.par_iter().filter_map(|&(e, name)| Some((name, surface_of(e)?))).collect();
        let (name, surface, more) = first_and_more(&found, "emitting triangles")?;
        Some(format!(
            "the emitter \"{name}\" lies in the plane of {surface} and overlaps it{more}: which of the two a ray meets there is decided by rounding, so the estimators disagree (move the emitter off the surface, or cut the surface away under it; for a lamp that emits both ways, one emitter with \"two_sided\")"
        ))
    }

    /// A warning naming the point lights that lie on a triangle: within a
    /// few units in the last place of the light's coordinates of its
    /// plane, inside it or on its edge. Whether such a light's rays meet
    /// the surface where it stands is decided by rounding: a tilted floor
    /// through the light met half of them at t ~ 1e-8, and light tracing
    /// and `bdpt` rendered that half of its flux scattered from a point,
    /// which no camera path can reach (an audit: `light` 0.33 against
    /// `path` 0.21). A level floor exactly through it meets none of them
    /// (t = 0 is no hit), so half its light passes through the floor and
    /// the estimators agree on that; it is named all the same, as what it
    /// renders rests on the same rounding. The check costs a box query per
    /// point light.
    pub fn point_lights_on_surfaces(&self) -> Option<String> {
        let (lo, hi) = self.accel.bounds();
        let surface_at = |p: Vec3A| {
            let pad = Vec3A::splat(2.0 * (near([p, lo, hi]) + off_plane(Vec3A::ONE, self.render_shift)));
            let mut surface = None;
            self.accel.overlapping((p - pad, p + pad), |slot| {
                if !holds(&self.accel.vertices(slot), p, self.render_shift) {
                    return ControlFlow::Continue(());
                }
                surface = Some(self.surface_name(slot));
                ControlFlow::Break(())
            });
            surface
        };
        let found: Vec<(&str, String)> = (self.lights.iter().zip(&self.light_names))
            .filter_map(|(l, name)| match l {
                Light::Point(pl) => Some((name.as_str(), surface_at(pl.p)?)),
                _ => None,
            })
            .collect();
        let (name, surface, more) = first_and_more(&found, "point lights")?;
        Some(format!(
            "the point light \"{name}\" lies on {surface}{more}: whether its light meets that surface where the light stands is decided by rounding, and the estimators can disagree (move the light off the surface)"
        ))
    }

    /// "a \"material\" surface", of the triangle in BVH slot `slot`.
    fn surface_name(&self, slot: u32) -> String {
        let prim = self.accel.slot_prims()[slot as usize];
        let mesh = &self.meshes[mesh_index(&self.meshes, prim)];
        format!("a \"{}\" surface", self.materials[mesh.material as usize].name)
    }
}

/// The first of `found` (a name and the surface it lies on), and
/// " (and n more `what`)" for the rest, if any.
fn first_and_more<'a>(found: &'a [(&'a str, String)], what: &str) -> Option<(&'a str, &'a str, String)> {
    let (name, surface) = found.first()?;
    let more = match found.len() {
        1 => String::new(),
        n => format!(" (and {} more {what})", n - 1),
    };
    Some((name, surface, more))
}

/// Whether point `p` lies in the plane of triangle `t` within a few units
/// in the last place of its own coordinates (how far rounding moves a
/// light meant to stand on the surface), and inside `t` or on its edge.
/// In f64, so that the triangle's size adds nothing: a light 0.05 above a
/// level ground of 1e5, whose rays meet the ground where they should, was
/// taken for one on it with the tolerance of the ground's coordinates.
fn holds(t: &[Vec3A; 3], p: Vec3A, shift: Vec3A) -> bool {
    let [a, b, c] = t.map(|v| v.as_dvec3());
    let q = p.as_dvec3();
    let n = (b - a).cross(c - a).normalize_or_zero();
    let extent = [a, b, c, q].iter().map(|v| v.abs().max_element()).fold(0.0, f64::max);
    let tolerance = (near([p]) + off_plane(n.as_vec3a(), shift)) as f64 + 64.0 * f64::EPSILON * extent;
    if (q - a).dot(n).abs() > tolerance {
        return false;
    }
    let [i, j] = kept_axes(n.abs().max_position());
    let drop = |v: DVec3| DVec2::new(v[i], v[j]);
    let (t, p) = ([a, b, c].map(drop), drop(q));
    // The edge functions, each measured from its edge's first vertex.
    let side = |i: usize| (t[(i + 1) % 3] - t[i]).perp_dot(p - t[i]);
    let s = [side(0), side(1), side(2)];
    s.iter().all(|&x| x >= 0.0) || s.iter().all(|&x| x <= 0.0)
}

/// The two axes kept when a plane is projected along its normal's largest
/// axis `dropped`, which keeps the plane from collapsing (in cyclic order,
/// so the projection keeps its orientation).
fn kept_axes(dropped: usize) -> [usize; 2] {
    [(dropped + 1) % 3, (dropped + 2) % 3]
}

/// An emitter's overlap tests (`overlap_in_plane`) with triangles of its
/// own mesh in its plane, at most. An emitting disk cut as a fan of n
/// triangles has every other triangle in its plane and its bounds, none
/// overlapping it, and with no bound the check made n^2 tests (an audit,
/// session 44). Its own mesh overlaps an emitter where the mesh folds onto
/// itself (a cuboid flat on one axis), among its few nearest triangles.
/// Other meshes' triangles in the plane are all tested: charged to one
/// bound, the fan's triangles used it up before a ceiling's under them,
/// and a fan of 128 on a ceiling of 200 triangles went unnamed (a review).
const MAX_OWN_MESH_TESTS: u32 = 64;

/// The triangles the box query visits for one emitter, at most: what
/// bounds the check on the fan, whose every triangle the query finds for
/// every other (16,000 triangles: 5.4 s; 64,000: 98 s).
const MAX_CANDIDATES: u32 = 4096;

/// Whether triangle `t` lies in the plane of emitter `e` (unit normal `n`)
/// within `tolerance` (a few units in the last place of their
/// coordinates), within that of `e`'s bounds.
fn in_plane(e: &[Vec3A; 3], n: Vec3A, t: &[Vec3A; 3], tolerance: f32) -> bool {
    !apart(bounds(*e), bounds(*t), tolerance) && t.iter().all(|&v| (v - e[0]).dot(n).abs() <= tolerance)
}

/// Whether triangle `t`, in the plane of emitter `e` (`in_plane`), overlaps
/// it in that plane with positive area.
fn overlap_in_plane(e: &[Vec3A; 3], n: Vec3A, t: &[Vec3A; 3], tolerance: f32) -> bool {
    // Projected along the normal's largest axis, which keeps the plane's
    // area (up to a factor), the triangles overlap unless an edge of one
    // separates them (the separating axis theorem); touching is separated.
    let [i, j] = kept_axes(n.abs().max_position());
    let drop = |v: Vec3A| Vec2::new(v[i], v[j]);
    let (a, b) = (e.map(drop), t.map(drop));
    // Measured from the edge's first vertex, the edge's own vertices are
    // at exactly 0 on its normal (-e_y e_x + e_x e_y), wherever they are
    // (measured from the origin, the two ends of a shared edge rounded
    // apart, and the two triangles of an emitting quad overlapped); and
    // spans that meet within the tolerance touch: a T-junction's vertex,
    // rounded off its neighbour's edge, overlapped it by a hair.
    let separates = |tri: &[Vec2; 3], i: usize| {
        let normal = (tri[(i + 1) % 3] - tri[i]).perp();
        let slack = tolerance * normal.length();
        let span = |p: &[Vec2; 3]| {
            let d = p.map(|v| normal.dot(v - tri[i]));
            (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]))
        };
        let ((a_lo, a_hi), (b_lo, b_hi)) = (span(&a), span(&b));
        a_hi <= b_lo + slack || b_hi <= a_lo + slack
    };
    !(0..3).any(|i| separates(&a, i) || separates(&b, i))
}

/// The axis-aligned bounds of `points`.
fn bounds(points: impl IntoIterator<Item = Vec3A>) -> (Vec3A, Vec3A) {
    points.into_iter().fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)))
}

/// Whether bounds `a` and `b` are more than `gap` apart along some axis.
fn apart(a: (Vec3A, Vec3A), b: (Vec3A, Vec3A), gap: f32) -> bool {
    (b.0 - a.1).max_element() > gap || (a.0 - b.1).max_element() > gap
}

/// A few units in the last place of the largest coordinate of `points`:
/// how close two surfaces must be for rounding to decide which one a ray
/// meets.
fn near(points: impl IntoIterator<Item = Vec3A>) -> f32 {
    8.0 * f32::EPSILON * points.into_iter().map(|p| p.abs().max_element()).fold(0.0, f32::max)
}

/// What render space's `shift` (`Scene::render_shift`) adds to `near` off
/// a plane of unit normal `n`: the positions were rounded at the file's
/// magnitude on each shifted axis, which moves a point off the plane only
/// along its normal's components. A light in a ceiling's plane, turned and
/// moved to x = 2e4, lay 2e-3 off it and was not named; taken on every
/// axis, the shift named a lamp 0.01 below a level ceiling moved along x
/// (an audit and a review, session 42).
fn off_plane(n: Vec3A, shift: Vec3A) -> f32 {
    8.0 * f32::EPSILON * n.abs().dot(shift.abs())
}
