//! The BVH (obvhs) over all scene triangles: closest hit and occlusion.
//! (Helper B replaces the brute-force placeholder with obvhs + a watertight test.)

use crate::geometry::Ray;
use glam::Vec3A;

/// A ray-triangle hit: distance, the triangle's index in the input order, and
/// the barycentrics of its second and third vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    pub t: f32,
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
}

pub struct Accel {
    tris: Vec<[Vec3A; 3]>,
}

impl Accel {
    pub fn build(tris: &[[Vec3A; 3]]) -> Self {
        Self { tris: tris.to_vec() }
    }

    /// Closest hit with t in (0, t_max).
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<TriangleHit> {
        let mut best: Option<TriangleHit> = None;
        let mut t_max = t_max;
        for (i, tri) in self.tris.iter().enumerate() {
            if let Some((t, b1, b2)) = intersect_triangle(ray, tri, t_max) {
                t_max = t;
                best = Some(TriangleHit { t, prim: i as u32, b1, b2 });
            }
        }
        best
    }

    /// Whether anything blocks the ray in (0, t_max).
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        self.tris.iter().any(|tri| intersect_triangle(ray, tri, t_max).is_some())
    }
}

fn intersect_triangle(ray: &Ray, tri: &[Vec3A; 3], t_max: f32) -> Option<(f32, f32, f32)> {
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let p = ray.d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.o - tri[0];
    let b1 = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&b1) {
        return None;
    }
    let q = s.cross(e1);
    let b2 = ray.d.dot(q) * inv;
    if b2 < 0.0 || b1 + b2 > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > 0.0 && t < t_max).then_some((t, b1, b2))
}
