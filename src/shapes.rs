//! Triangle meshes and the analytic shapes scenes and tests are built from.
//!
//! Convention: the geometric normal of triangle (a, b, c) is
//! normalize((b - a) x (c - a)); closed shapes are wound so that it points
//! out (counter-clockwise seen from outside).

use glam::{Affine3A, Vec3A};
use std::collections::HashMap;

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3A>,
    /// Per-vertex shading normals; empty means flat (use the geometric normal).
    pub normals: Vec<Vec3A>,
    pub indices: Vec<[u32; 3]>,
}

impl Mesh {
    /// Two triangles (0,1,2), (0,2,3); flat.
    pub fn quad(corners: [Vec3A; 4]) -> Mesh {
        Mesh { positions: corners.to_vec(), normals: Vec::new(), indices: vec![[0, 1, 2], [0, 2, 3]] }
    }

    /// Axis-aligned box, 12 triangles wound outward; flat.
    pub fn cuboid(min: Vec3A, max: Vec3A) -> Mesh {
        // Corner i has x from bit 0, y from bit 1, z from bit 2.
        let positions = (0..8)
            .map(|i| {
                Vec3A::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                )
            })
            .collect();
        // Each face as a counter-clockwise loop seen from outside.
        let faces: [[u32; 4]; 6] = [
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
        ];
        let indices = faces.iter().flat_map(|f| [[f[0], f[1], f[2]], [f[0], f[2], f[3]]]).collect();
        Mesh { positions, normals: Vec::new(), indices }
    }

    /// Triangles of `sphere` with `subdivisions` (at most 30): 20 * 4^s.
    pub fn sphere_triangles(subdivisions: u32) -> usize {
        20 << (2 * subdivisions)
    }

    /// Icosphere: an icosahedron whose faces are split in four `subdivisions`
    /// times (20 * 4^s triangles), vertices projected onto the sphere. Wound
    /// outward; `smooth` adds the exact sphere normals per vertex.
    pub fn sphere(center: Vec3A, radius: f32, subdivisions: u32, smooth: bool) -> Mesh {
        let phi = (1.0 + 5f32.sqrt()) * 0.5;
        let mut unit: Vec<Vec3A> = [
            [-1.0, phi, 0.0],
            [1.0, phi, 0.0],
            [-1.0, -phi, 0.0],
            [1.0, -phi, 0.0],
            [0.0, -1.0, phi],
            [0.0, 1.0, phi],
            [0.0, -1.0, -phi],
            [0.0, 1.0, -phi],
            [phi, 0.0, -1.0],
            [phi, 0.0, 1.0],
            [-phi, 0.0, -1.0],
            [-phi, 0.0, 1.0],
        ]
        .iter()
        .map(|&p| Vec3A::from(p).normalize())
        .collect();
        let mut indices: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            // Shared midpoints keep the mesh closed (each edge split once).
            let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(indices.len() * 3 / 2);
            let mut next = Vec::with_capacity(indices.len() * 4);
            for &[a, b, c] in &indices {
                let mut m = |i: u32, j: u32| {
                    *mid.entry((i.min(j), i.max(j))).or_insert_with(|| {
                        unit.push((unit[i as usize] + unit[j as usize]).normalize());
                        unit.len() as u32 - 1
                    })
                };
                let (ab, bc, ca) = (m(a, b), m(b, c), m(c, a));
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            indices = next;
        }
        Mesh {
            positions: unit.iter().map(|&u| center + u * radius).collect(),
            normals: if smooth { unit } else { Vec::new() },
            indices,
        }
    }

    /// Applies `m` to positions, and its inverse transpose to normals
    /// (renormalised; a zero normal stays zero, as does every normal under
    /// a singular `m`: NaN took the whole triangle's shading normal, where
    /// untransformed the zero one drops out of the interpolation; from an
    /// audit, session 50). A mirroring transform (det < 0) also reverses the
    /// winding, so the geometric normal keeps pointing the way the
    /// transformed shading normals do. The determinant and the inverse in
    /// f64: in f32 a scale of 1e-16 on every axis has a determinant of
    /// -0 when mirrored, which kept the winding (an audit, session 49),
    /// and no inverse.
    pub fn transform(&mut self, m: Affine3A) {
        for p in &mut self.positions {
            *p = m.transform_point3a(*p);
        }
        let m3 = m.matrix3.as_dmat3();
        let normal_matrix = m3.inverse().transpose();
        for n in &mut self.normals {
            *n = (normal_matrix * n.as_dvec3()).normalize_or_zero().as_vec3a();
        }
        if m3.determinant() < 0.0 {
            self.reverse_winding();
        }
    }

    /// Reverses the winding and negates the shading normals (e.g. a sphere
    /// seen from inside).
    pub fn flip(&mut self) {
        self.reverse_winding();
        for n in &mut self.normals {
            *n = -*n;
        }
    }

    fn reverse_winding(&mut self) {
        for t in &mut self.indices {
            t.swap(1, 2);
        }
    }

    /// Fails, naming the first, if a triangle's normal cannot be computed
    /// in f32: the squared length of the cross product of its edges (what
    /// its normal and area, and `accel::is_degenerate`, take) overflows,
    /// for edges beyond ~4e9. Such a triangle would drop out of the BVH
    /// unseen. (The loaders' check, with their own error positions.)
    pub fn check_f32_extent(&self) -> Result<(), String> {
        match self.triangles().position(|v| !(v[1] - v[0]).cross(v[2] - v[0]).length_squared().is_finite()) {
            None => Ok(()),
            Some(t) => Err(format!(
                "triangle {t} is too large for f32 arithmetic (edges beyond ~4e9 units: the cross product of two \
                 edges, its normal and area, overflow); scale the scene down"
            )),
        }
    }

    pub fn triangles(&self) -> impl Iterator<Item = [Vec3A; 3]> + '_ {
        self.indices.iter().map(|t| t.map(|i| self.positions[i as usize]))
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.indices.len()
    }

    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Quat, Vec3};

    /// A zero shading normal stays zero under a transform, as untransformed
    /// (it then drops out of the interpolation); it was renormalised to NaN,
    /// which took the whole triangle's (from an audit, session 50).
    #[test]
    fn zero_normals_stay_zero_when_transformed() {
        let mut m = Mesh::cuboid(Vec3A::ZERO, Vec3A::ONE);
        m.normals = vec![Vec3A::Z; m.positions.len()];
        m.normals[0] = Vec3A::ZERO;
        m.transform(Affine3A::from_translation(Vec3::X));
        assert_eq!(m.normals[0], Vec3A::ZERO);
        assert!(m.normals[1..].iter().all(|&n| n == Vec3A::Z), "{:?}", m.normals);
    }

    fn normal(t: &[Vec3A; 3]) -> Vec3A {
        (t[1] - t[0]).cross(t[2] - t[0]).normalize()
    }

    fn area(m: &Mesh) -> f64 {
        m.triangles().map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length() as f64).sum()
    }

    fn assert_outward(m: &Mesh, center: Vec3A) {
        for t in m.triangles() {
            let c = (t[0] + t[1] + t[2]) / 3.0;
            assert!(normal(&t).dot(c - center) > 0.0, "inward triangle {t:?}");
        }
    }

    #[test]
    fn quad_is_two_triangles_with_one_normal() {
        let q = Mesh::quad([Vec3A::ZERO, Vec3A::X, Vec3A::X + Vec3A::Y, Vec3A::Y]);
        assert_eq!(q.len(), 2);
        for t in q.triangles() {
            assert!((normal(&t) - Vec3A::Z).length() < 1e-6);
        }
    }

    #[test]
    fn cuboid_normals_point_outward() {
        let (lo, hi) = (Vec3A::new(-1.0, 0.0, 2.0), Vec3A::new(3.0, 0.5, 4.0));
        let m = Mesh::cuboid(lo, hi);
        assert_eq!(m.len(), 12);
        assert_outward(&m, (lo + hi) * 0.5);
        let s = hi - lo;
        let expected = 2.0 * (s.x * s.y + s.y * s.z + s.z * s.x) as f64;
        assert!((area(&m) - expected).abs() < 1e-5);
        // Each axis direction is covered by exactly two triangles.
        for axis in [Vec3A::X, Vec3A::Y, Vec3A::Z, -Vec3A::X, -Vec3A::Y, -Vec3A::Z] {
            let k = m.triangles().filter(|t| normal(t).dot(axis) > 0.999).count();
            assert_eq!(k, 2, "{axis}");
        }
    }

    #[test]
    fn sphere_is_outward_closed_and_converges_in_area() {
        let c = Vec3A::new(0.5, -2.0, 1.0);
        let r = 1.5f32;
        let exact = 4.0 * std::f64::consts::PI * (r as f64).powi(2);
        let mut last_err = f64::INFINITY;
        for s in 0..6 {
            let m = Mesh::sphere(c, r, s, true);
            assert_eq!(m.len(), 20 * 4usize.pow(s));
            assert_eq!(Mesh::sphere_triangles(s), m.len());
            // Closed: V - E + F = 2 with E = 3F/2.
            assert_eq!(m.positions.len() + m.len() - 3 * m.len() / 2, 2);
            assert_outward(&m, c);
            for (p, n) in m.positions.iter().zip(&m.normals) {
                assert!(((*p - c).length() - r).abs() < 1e-5);
                assert!((*n - (*p - c) / r).length() < 1e-5);
            }
            let err = (exact - area(&m)) / exact;
            assert!(err > 0.0 && err < last_err * 0.35, "s = {s}: {err}");
            last_err = err;
        }
        assert!(last_err < 1e-3);
        assert!(Mesh::sphere(c, r, 2, false).normals.is_empty());
    }

    #[test]
    fn transform_moves_points_and_keeps_normals_outward() {
        let base = Mesh::sphere(Vec3A::ZERO, 1.0, 2, true);
        let scale = Vec3A::new(2.0, 0.5, 1.0);
        let t = Vec3A::new(3.0, -1.0, 2.0);
        for mirror in [false, true] {
            let s = if mirror { scale * Vec3A::new(-1.0, 1.0, 1.0) } else { scale };
            let m3 = Mat3::from_quat(Quat::from_rotation_y(0.7)) * Mat3::from_diagonal(s.into());
            let a = Affine3A::from_mat3_translation(m3, t.into());
            let mut m = base.clone();
            m.transform(a);
            assert_outward(&m, t);
            for (i, (p, n)) in m.positions.iter().zip(&m.normals).enumerate() {
                assert!((*p - a.transform_point3a(base.positions[i])).length() < 1e-5);
                assert!((n.length() - 1.0).abs() < 1e-5);
                // A point on an ellipsoid: the normal is the gradient of
                // |M^-1 (p - t)|^2, i.e. along M^-T M^-1 (p - t).
                let q = a.matrix3.inverse();
                let g = (q.transpose() * (q * (*p - t))).normalize();
                assert!((*n - g).length() < 1e-4, "{n} vs {g}");
            }
            assert_eq!(m.indices[0] != base.indices[0], mirror);
        }
    }

    /// A mirroring scale too small for an f32 determinant (1e-48 is below
    /// f32's least subnormal) still reverses the winding and keeps the
    /// normals: a sphere of radius 1e12 scaled by (-1e-16, 1e-16, 1e-16)
    /// is a sphere of radius 1e-4, wound outward.
    #[test]
    fn tiny_mirroring_scales_reverse_the_winding() {
        let base = Mesh::sphere(Vec3A::ZERO, 1e12, 1, true);
        let scale = Vec3A::new(-1e-16, 1e-16, 1e-16);
        assert_eq!(Mat3::from_diagonal(scale.into()).determinant(), 0.0, "the premise: f32 cannot hold it");
        let mut m = base.clone();
        m.transform(Affine3A::from_mat3(Mat3::from_diagonal(scale.into())));
        assert_outward(&m, Vec3A::ZERO);
        for (p, n) in m.positions.iter().zip(&m.normals) {
            assert!((p.length() / 1e-4 - 1.0).abs() < 1e-5, "{p}");
            assert!((n.dot(p.normalize()) - 1.0).abs() < 1e-5, "{n} at {p}");
        }
    }

    #[test]
    fn flip_reverses_winding_and_normals() {
        let base = Mesh::sphere(Vec3A::ZERO, 1.0, 1, true);
        let mut m = base.clone();
        m.flip();
        for (t, b) in m.triangles().zip(base.triangles()) {
            assert!((normal(&t) + normal(&b)).length() < 1e-6);
        }
        for (n, b) in m.normals.iter().zip(&base.normals) {
            assert_eq!(*n, -*b);
        }
        m.flip();
        assert_eq!(m, base);
    }
}
