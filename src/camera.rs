//! The pinhole camera: primary rays, and the adjoint side (importance We, its
//! densities, the raster position of a world point) that light tracing and
//! BDPT need.
//!
//! The image rectangle lies on the plane at distance 1 in front of the
//! pinhole; A is its area. Following pbrt-v3 §16.1.1 ("Sampling
//! Cameras", `PerspectiveCamera::We`), the importance of a direction at angle theta to the
//! optical axis is We = 1 / (A cos^4 theta) inside the frame, normalised so
//! that the integral of We cos theta over the image's solid angle is 1. A
//! pixel's measurement (its box-filtered radiance) is We scaled by the
//! number of pixels, which is why the film divides splats by spp and not by
//! the total number of light paths.

use crate::geometry::Ray;
use glam::{DVec2, DVec3, Vec2, Vec3A};

/// The largest image prism renders, in pixels (`Camera::check_resolution`).
pub const MAX_PIXELS: u64 = 1 << 27;

/// Most pixels on a side: every pixel edge is an f32 integer up to 2^24,
/// so each pixel holds raster positions of its own (`f32_at_or_below`).
pub const MAX_SIDE: u32 = 1 << 24;

#[derive(Clone, Debug)]
pub struct Camera {
    pub position: Vec3A,
    /// Unit vectors: optical axis, screen right, screen up.
    forward: Vec3A,
    right: Vec3A,
    up: Vec3A,
    pub width: u32,
    pub height: u32,
    /// Half extents of the image rectangle on the plane z = 1.
    half_w: f32,
    half_h: f32,
    /// Raster pixels per unit of that plane along right and up (the second
    /// negative: rows go down), so that a projection divides once, by z.
    raster_scale: Vec2,
}

/// A direction from a scene point to the camera, with its importance.
#[derive(Clone, Copy, Debug)]
pub struct CameraWiSample {
    /// Unit direction from the reference point towards the pinhole.
    pub wi: Vec3A,
    pub dist: f32,
    /// Raster position (pixels) where the point projects.
    pub raster: Vec2,
    /// Importance We of the direction (whole-image normalisation).
    pub we: f32,
    /// Solid-angle density at the reference point of choosing the pinhole:
    /// dist^2 / |cos theta| (the pinhole is a delta in position, area 1).
    pub pdf_w: f32,
}

impl Camera {
    /// `fov_y_deg` is the full vertical field of view. Looking along
    /// `look_at - position`, screen right is forward x up: looking along +z
    /// with +y up (the Cornell box data), +x appears on the left, as in
    /// right-handed coordinates.
    /// `look_at` and `up` must give a `frame` (loaders check first); the
    /// camera of one that does not has a NaN basis.
    pub fn new(position: Vec3A, look_at: Vec3A, up: Vec3A, fov_y_deg: f32, width: u32, height: u32) -> Self {
        let forward = look_at.as_dvec3() - position.as_dvec3();
        Self::looking(position, forward, up.as_dvec3(), fov_y_deg, width, height)
    }

    /// `new` with a view direction instead of a point to look at (a glTF
    /// camera's -z: far from the origin, position + direction in f32 would
    /// lose the direction).
    pub fn looking(position: Vec3A, forward: DVec3, up: DVec3, fov_y_deg: f32, width: u32, height: u32) -> Self {
        let [forward, right, up] = Self::frame(forward, up).unwrap_or([Vec3A::NAN; 3]);
        let half_h = (fov_y_deg.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height as f32;
        let raster_scale = Self::raster_scale(width, height, half_w, half_h);
        Self { position, forward, right, up, width, height, half_w, half_h, raster_scale }
    }

    fn raster_scale(width: u32, height: u32, half_w: f32, half_h: f32) -> Vec2 {
        Vec2::new(0.5 * width as f32 / half_w, -0.5 * height as f32 / half_h)
    }

    /// The orthonormal (forward, right, up) of a view direction and an up
    /// vector, or None if either is zero or they are parallel. In f64, so a
    /// camera ~1e19 or more from what it looks at (whose squared distance
    /// overflows f32) still has a direction.
    pub fn frame(forward: DVec3, up: DVec3) -> Option<[Vec3A; 3]> {
        let forward = forward.normalize_or_zero();
        let right = forward.cross(up.normalize_or_zero()).normalize_or_zero();
        (forward != DVec3::ZERO && right != DVec3::ZERO)
            .then(|| [forward, right, right.cross(forward)].map(|v| v.as_vec3a()))
    }

    /// Whether a film of `width` x `height` fits: at least one pixel, and at
    /// most `MAX_PIXELS` (each holds three i128 sums, 48 bytes), so absurd
    /// sizes get an error instead of an allocation failure, and at most
    /// `MAX_SIDE` on a side.
    pub fn check_resolution(width: u32, height: u32) -> Result<(), String> {
        let pixels = width as u64 * height as u64;
        if pixels == 0 {
            return Err("width and height must be at least 1".to_string());
        }
        if pixels > MAX_PIXELS {
            return Err(format!(
                "{width} x {height} = {pixels} pixels is more than the {MAX_PIXELS} (2^27, e.g. 16384 x 8192) a film holds"
            ));
        }
        if width.max(height) > MAX_SIDE {
            return Err(format!(
                "{width} x {height}: a side of more than {MAX_SIDE} (2^24) pixels has pixels f32 raster positions cannot reach"
            ));
        }
        Ok(())
    }

    /// The same camera with another resolution (the vertical field of view
    /// is kept).
    pub fn with_resolution(&self, width: u32, height: u32) -> Self {
        let mut c = self.clone();
        c.width = width;
        c.height = height;
        c.half_w = self.half_h * width as f32 / height as f32;
        c.raster_scale = Self::raster_scale(width, height, c.half_w, c.half_h);
        c
    }

    /// Optical axis, screen up (both unit) and the full vertical field of
    /// view in degrees (scene exporters).
    pub fn orientation(&self) -> (Vec3A, Vec3A, f32) {
        (self.forward, self.up, 2.0 * self.half_h.atan().to_degrees())
    }

    /// Area of the image rectangle on the plane at distance 1.
    #[inline]
    pub fn image_area(&self) -> f32 {
        4.0 * self.half_w * self.half_h
    }

    /// Whether the image has an area light tracing can divide by (a normal
    /// f32: a tiny field of view underflows it; loaders refuse such a camera).
    pub fn has_image_area(&self) -> bool {
        self.image_area().is_normal()
    }

    /// The ray through raster position `raster` (pixels, origin top-left).
    #[inline]
    pub fn generate_ray(&self, raster: Vec2) -> Ray {
        let sx = (2.0 * raster.x / self.width as f32 - 1.0) * self.half_w;
        let sy = (1.0 - 2.0 * raster.y / self.height as f32) * self.half_h;
        let d = (self.forward + self.right * sx + self.up * sy).normalize();
        Ray::new(self.position, d)
    }

    /// Raster position of a vector leaving the pinhole (any length), inside
    /// the image or not; None for one not in front of it.
    #[inline]
    pub fn project(&self, v: Vec3A) -> Option<Vec2> {
        self.project_f64(v.as_dvec3()).map(|r| r.as_vec2())
    }

    /// `project` in f64. A narrow view sees directions within a few 1e-6
    /// rad of its axis, where f32 dot products with the screen axes cancel
    /// to a lattice of ~3e-8: at 1.45e-6 rad per pixel (fov 0.001 degrees
    /// over 12 rows) light tracing's splats piled onto it, and rows and
    /// columns of a uniformly lit view read 1.7 % low (an audit, session
    /// 42). The point on the plane z = 1, in pixels from the image centre,
    /// is (x, y) / z times the raster scale.
    #[inline]
    fn project_f64(&self, v: DVec3) -> Option<DVec2> {
        let z = v.dot(self.forward.as_dvec3());
        if z <= 0.0 {
            return None;
        }
        let xy = DVec2::new(v.dot(self.right.as_dvec3()), v.dot(self.up.as_dvec3()));
        let centre = DVec2::new(0.5 * self.width as f64, 0.5 * self.height as f64);
        Some(xy * self.raster_scale.as_dvec2() / z + centre)
    }

    /// Raster position of a vector leaving the pinhole (any length), if
    /// inside the image, decided in f64 (`project_f64`). Rounded down to
    /// f32 (`f32_at_or_below`), so that the pixel that holds it
    /// (`render::splat_pixel`, a floor) is the f64 position's: rounded to
    /// nearest, x within half an f32 ulp below p + 1 became p + 1, and
    /// column 8192 of a 16384-wide image covered [8192 - 2.4e-4, 8193 -
    /// 4.9e-4) (an audit, session 60).
    #[inline]
    pub fn raster_of_direction(&self, v: DVec3) -> Option<Vec2> {
        let r = self.project_f64(v)?;
        let inside = (0.0..self.width as f64).contains(&r.x) && (0.0..self.height as f64).contains(&r.y);
        inside.then(|| Vec2::new(f32_at_or_below(r.x), f32_at_or_below(r.y)))
    }

    /// The directional density (solid angle) of the pinhole choosing `d`:
    /// 1 / (A cos^3 theta); the positional density is a delta. With no test
    /// of the raster position: the camera's own rays and its connections
    /// (`sample_wi`, which decides once whether a point is in the image)
    /// are in it by construction, and a second test of a rounded direction
    /// would disagree at the edges. (A raster on the image's edge, in f32,
    /// the last column's x = w - 1 + u, rounds to w for u within 2^-17 of 1
    /// at w = 256 and projects back a rounding outside the image about half
    /// the time; a 0 there read as a delta to MIS.)
    #[inline]
    pub fn pdf_dir(&self, d: Vec3A) -> f32 {
        let c = d.dot(self.forward);
        1.0 / (self.image_area() * c * c * c)
    }

    /// Cosine between a unit direction leaving the pinhole and the optical axis.
    #[inline]
    pub fn cos_theta(&self, d: Vec3A) -> f32 {
        d.dot(self.forward)
    }

    /// Connect a scene point to the pinhole (pbrt's Camera::SampleWi), in
    /// f64 from the two positions (`project_f64`): inside the image, the
    /// importance We = 1 / (A cos^4 theta).
    #[inline]
    pub fn sample_wi(&self, p_ref: Vec3A) -> Option<CameraWiSample> {
        let v = p_ref.as_dvec3() - self.position.as_dvec3();
        let dist2 = v.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let raster = self.raster_of_direction(v)?;
        let dist = dist2.sqrt();
        let cos = v.dot(self.forward.as_dvec3()) / dist;
        let we = 1.0 / (self.image_area() as f64 * cos.powi(4));
        let wi = (-v / dist).as_vec3a();
        Some(CameraWiSample { wi, dist: dist as f32, raster, we: we as f32, pdf_w: (dist2 / cos) as f32 })
    }
}

/// The largest f32 at or below `x`, for 0 <= x < 2^24 (a raster
/// position): where `x as f32` rounded up it is positive and finite, and
/// one ulp below it is its bits minus one (a compare and a subtraction;
/// `f32::next_down` cost `light` 1.1 % more instructions, this 0.17 %).
#[inline]
fn f32_at_or_below(x: f64) -> f32 {
    let f = x as f32;
    f32::from_bits(f.to_bits() - (f as f64 > x) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Y, 60.0, 64, 48)
    }

    /// A direction whose f64 raster position is just below a pixel's far
    /// edge lands in that pixel: (8193 - d, 8193 - d) in a 16384 x 16384
    /// image (where an f32 ulp is 2^-10), for d from 1e-6 to 0.1 pixel.
    /// Rounded to nearest, every d below 4.9e-4 (half an ulp) landed in
    /// column and row 8193.
    #[test]
    fn a_raster_position_keeps_its_pixel() {
        let c = Camera::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Y, 60.0, 16384, 16384);
        let (scale, centre) = (c.raster_scale.as_dvec2(), DVec2::splat(8192.0));
        let direction = |xy: DVec2| c.forward.as_dvec3() + c.right.as_dvec3() * xy.x + c.up.as_dvec3() * xy.y;
        for d in [1e-6, 1e-5, 1e-4, 4e-4, 4.8e-4, 1e-3, 0.1] {
            let want = DVec2::splat(8193.0 - d);
            // The f32 frame is orthonormal only to ~1e-8, 1e-4 pixel here:
            // Newton steps put the f64 projection on `want`.
            let mut xy = (want - centre) / scale;
            for _ in 0..4 {
                xy += (want - c.project_f64(direction(xy)).unwrap()) / scale;
            }
            let r64 = c.project_f64(direction(xy)).unwrap();
            assert!((r64 - want).abs().max_element() < 1e-9, "{r64} for {want}");
            let r = c.raster_of_direction(direction(xy)).unwrap();
            let pixel = crate::render::splat_pixel(r, glam::UVec2::splat(16384));
            assert_eq!(pixel, 8192 * 16384 + 8192, "d {d}: raster {r} for {want}");
        }
    }

    /// A side of 2^24 pixels is accepted, one more refused.
    #[test]
    fn a_side_is_at_most_2_to_the_24() {
        assert!(Camera::check_resolution(MAX_SIDE, 8).is_ok());
        let e = Camera::check_resolution(MAX_SIDE + 1, 1).unwrap_err();
        assert!(e.contains("a side of more than 16777216 (2^24) pixels"), "{e}");
    }

    /// `f32_at_or_below` at the values a raster position takes: 0, an
    /// integer, just below an integer at every magnitude up to 2^24, and
    /// just below the largest side; each result is at or below x and the
    /// next f32 up is above it.
    #[test]
    fn rounding_down_is_the_largest_f32_at_or_below() {
        let mut xs = vec![0.0, 1.0, 8192.0, (MAX_SIDE - 1) as f64, MAX_SIDE as f64 - 1e-9];
        for k in 0..24 {
            let p = (1u64 << k) as f64;
            xs.extend([p - 1e-12, p - p * 1e-9, p + 0.3, p * 1.7]);
        }
        for x in xs.into_iter().filter(|&x| (0.0..MAX_SIDE as f64).contains(&x)) {
            let f = f32_at_or_below(x);
            assert!(f as f64 <= x && (f.next_up() as f64) > x, "{x}: {f}");
        }
    }

    /// A camera 2e19 from what it looks at (the squared distance passes
    /// f32: the f32 frame was zero, and the loader called it degenerate)
    /// sees along +z all the same; a zero or parallel up has no frame.
    #[test]
    fn far_cameras_have_a_frame() {
        let far = Camera::new(Vec3A::new(0.0, 0.0, -2e19), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
        assert_eq!((far.forward, far.right, far.up), (Vec3A::Z, -Vec3A::X, Vec3A::Y));
        assert!(Camera::frame(DVec3::Z, DVec3::ZERO).is_none());
        assert!(Camera::frame(DVec3::ZERO, DVec3::Y).is_none());
        assert!(Camera::frame(DVec3::Y * 3.0, DVec3::Y).is_none());
    }

    #[test]
    fn raster_round_trip() {
        let c = cam();
        for (x, y) in [(0.5, 0.5), (31.2, 20.7), (63.9, 47.9)] {
            let r = c.generate_ray(Vec2::new(x, y));
            let back = c.raster_of_direction(r.d.as_dvec3()).unwrap();
            assert!((back - Vec2::new(x, y)).length() < 1e-3, "{back}");
        }
    }

    #[test]
    fn importance_integrates_to_one_over_the_image() {
        // Integral over the image's solid angle of We cos = 1, computed on the
        // z = 1 plane where d omega = cos^3 dA. Its area element uses the
        // camera's own A (We = 1 / (A cos^4) makes the sum 1 for any A), so
        // A is checked first against the field of view: 60 degrees
        // vertical, 64 x 48 pixels.
        let c = cam();
        let half_h = (30f64).to_radians().tan();
        let area = (2.0 * half_h) * (2.0 * half_h * 64.0 / 48.0);
        assert!((c.image_area() as f64 / area - 1.0).abs() < 1e-6, "A = {}, expected {area}", c.image_area());
        let n = 400;
        let mut sum = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let r = Vec2::new((i as f32 + 0.5) / n as f32 * 64.0, (j as f32 + 0.5) / n as f32 * 48.0);
                let d = c.generate_ray(r).d;
                let cos = c.cos_theta(d);
                let da = c.image_area() / (n * n) as f32;
                let we = c.sample_wi(c.position + d * 3.0).map_or(0.0, |s| s.we);
                sum += (we * cos * cos * cos * cos * da) as f64;
            }
        }
        assert!((sum - 1.0).abs() < 1e-3, "{sum}");
    }

    #[test]
    fn plus_x_is_on_the_left_for_the_cornell_convention() {
        let c = Camera::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Y, 40.0, 10, 10);
        let r = c.raster_of_direction(DVec3::new(0.1, 0.0, 1.0)).unwrap();
        assert!(r.x < 5.0);
    }
}
