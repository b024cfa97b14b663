//! Mitsuba's `perspective` sensor: a pinhole camera looking down +z in camera space, with
//! camera +x on the image's left (Mitsuba's film mapping scales x and y by -0.5,
//! `include/mitsuba/render/sensor.h`), plus the importance function and its pdfs that light
//! tracing needs.

use crate::geometry::{Ray, Transform};
use glam::{Vec2, Vec3};

/// A pinhole camera.
#[derive(Clone, Debug)]
pub struct PerspectiveCamera {
    /// Camera to world (rigid).
    pub to_world: Transform,
    /// Eye position.
    pub origin: Vec3,
    /// View direction (camera +z in world space).
    pub forward: Vec3,
    /// Width in pixels of the rendered image (the film's crop window).
    pub width: u32,
    /// Height in pixels of the rendered image.
    pub height: u32,
    /// The crop window's offset within the full film, and the full film's size.
    window: (f32, f32, f32, f32),
    /// tan(fov_x / 2).
    pub tan_half_x: f32,
    /// Width / height of the full film.
    pub aspect: f32,
    /// Near clip distance along camera z.
    pub near_clip: f32,
    /// Far clip distance along camera z.
    pub far_clip: f32,
    /// Area of the rendered image's rectangle on the plane z = 1.
    image_plane_area: f32,
    /// Camera to world, rounded to f32 for ray generation.
    to_world_f32: glam::Mat4,
    /// World to camera, rounded to f32.
    to_camera_f32: glam::Mat4,
}

/// A connection from a scene point to the camera (for light tracing).
#[derive(Clone, Copy, Debug)]
pub struct CameraSample {
    /// Unit direction from the scene point to the eye.
    pub wi: Vec3,
    /// Distance to the eye.
    pub dist: f32,
    /// `We · cos θ_cam / dist²`: multiplied by a light subpath's throughput, its BSDF value and
    /// `|cos θ|` at the scene point, it gives the contribution to the pixel at `raster`.
    pub weight: f32,
    /// Continuous raster position (pixels).
    pub raster: Vec2,
    /// Solid-angle pdf at the scene point of this connection: `dist² / cos θ_cam`.
    pub pdf: f32,
}

impl PerspectiveCamera {
    /// A camera from its horizontal field of view in degrees.
    pub fn new(to_world: Transform, fov_x_deg: f32, width: u32, height: u32, near_clip: f32, far_clip: f32) -> Self {
        let tan_half_x = (0.5 * fov_x_deg.to_radians()).tan();
        let aspect = width as f32 / height as f32;
        let origin = to_world.point(Vec3::ZERO);
        let forward = to_world.vector(Vec3::Z).normalize();
        let image_plane_area = (2.0 * tan_half_x) * (2.0 * tan_half_x / aspect);
        PerspectiveCamera {
            to_world,
            origin,
            forward,
            width,
            height,
            window: (0.0, 0.0, width as f32, height as f32),
            tan_half_x,
            aspect,
            near_clip,
            far_clip,
            image_plane_area,
            to_world_f32: to_world.m.as_mat4(),
            to_camera_f32: to_world.inv_f32(),
        }
    }

    /// The camera rendering only the `width × height` window at `(x, y)` of its film (Mitsuba's
    /// `crop_*`): raster positions and the image's importance refer to the window, the
    /// projection to the full film.
    pub fn with_crop(mut self, x: u32, y: u32, width: u32, height: u32) -> Self {
        let (full_w, full_h) = (self.width as f32, self.height as f32);
        self.image_plane_area *= (width as f32 * height as f32) / (full_w * full_h);
        (self.width, self.height) = (width, height);
        self.window = (x as f32, y as f32, full_w, full_h);
        self
    }

    /// The same view at `width × height` pixels, crop window included, or `None` if that
    /// changes the image's proportions (the view would change with them). For tests and
    /// benchmarks that render a scene smaller than its file says.
    pub fn with_resolution(mut self, width: u32, height: u32) -> Option<Self> {
        // same proportions: width · self.height == height · self.width, in integers
        if width == 0 || (width as u64) * (self.height as u64) != (height as u64) * (self.width as u64) {
            return None;
        }
        let s = width as f32 / self.width as f32;
        let (x0, y0, full_w, full_h) = self.window;
        self.window = (x0 * s, y0 * s, full_w * s, full_h * s);
        (self.width, self.height) = (width, height);
        // the aspect and the window's share of the image plane are unchanged
        Some(self)
    }

    /// The primary ray through continuous raster position `raster` (pixels, (0,0) = top-left).
    #[inline]
    pub fn generate_ray(&self, raster: Vec2) -> Ray {
        let (x0, y0, full_w, full_h) = self.window;
        let u = (raster.x + x0) / full_w;
        let v = (raster.y + y0) / full_h;
        let d_cam = Vec3::new((1.0 - 2.0 * u) * self.tan_half_x, (1.0 - 2.0 * v) * self.tan_half_x / self.aspect, 1.0);
        let inv_len = 1.0 / d_cam.length();
        let d = self.to_world_f32.transform_vector3(d_cam * inv_len).normalize();
        // rays start on the near plane and end on the far plane, as Mitsuba's do
        let near_t = self.near_clip / inv_len;
        Ray { o: self.origin + d * near_t, d, tmax: (self.far_clip - self.near_clip) / inv_len }
    }

    /// Raster position hit by a world direction leaving the eye, if it is inside the image.
    pub fn raster_of(&self, d: Vec3) -> Option<Vec2> {
        let dc = self.to_camera_f32.transform_vector3(d);
        if dc.z <= 0.0 {
            return None;
        }
        let u = 0.5 * (1.0 - dc.x / (dc.z * self.tan_half_x));
        let v = 0.5 * (1.0 - self.aspect * dc.y / (dc.z * self.tan_half_x));
        let (x0, y0, full_w, full_h) = self.window;
        let r = Vec2::new(u * full_w - x0, v * full_h - y0);
        (r.x >= 0.0 && r.y >= 0.0 && r.x < self.width as f32 && r.y < self.height as f32).then_some(r)
    }

    /// Cosine between a world direction and the view axis.
    #[inline]
    fn cos_theta(&self, d: Vec3) -> f32 {
        d.dot(self.forward)
    }

    /// Importance `We` emitted along world direction `d` (normalised so that a pixel's
    /// importance integrates to 1 over its solid angle times the pixel count).
    pub fn importance(&self, d: Vec3) -> f32 {
        let c = self.cos_theta(d);
        if c <= 0.0 || self.raster_of(d).is_none() {
            return 0.0;
        }
        1.0 / (self.image_plane_area * c * c * c * c)
    }

    /// Position pdf (a pinhole: delta, reported as 1) and direction pdf (solid angle) of
    /// sampling `d` with [`Self::generate_ray`] at a uniform raster position.
    pub fn pdf_ray(&self, d: Vec3) -> (f32, f32) {
        let c = self.cos_theta(d);
        if c <= 0.0 || self.raster_of(d).is_none() {
            return (1.0, 0.0);
        }
        (1.0, 1.0 / (self.image_plane_area * c * c * c))
    }

    /// Connects scene point `p` to the eye.
    pub fn sample_direct(&self, p: Vec3) -> Option<CameraSample> {
        let to_eye = self.origin - p;
        let dist2 = to_eye.length_squared();
        let dist = dist2.sqrt();
        let wi = to_eye / dist;
        let raster = self.raster_of(-wi)?;
        let c = self.cos_theta(-wi);
        let z = c * dist;
        if z < self.near_clip || z > self.far_clip {
            return None;
        }
        let we = 1.0 / (self.image_plane_area * c * c * c * c);
        Some(CameraSample { wi, dist, weight: we * c / dist2, raster, pdf: dist2 / c })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> PerspectiveCamera {
        PerspectiveCamera::new(
            Transform::look_at(glam::DVec3::ZERO, glam::DVec3::Z, glam::DVec3::Y).unwrap(),
            60.0,
            200,
            100,
            0.01,
            1000.0,
        )
    }

    #[test]
    fn camera_x_is_the_image_left() {
        let c = cam();
        // an object at world +x (camera left) appears left of centre; +y appears above
        let left = c.raster_of(Vec3::new(0.3, 0.0, 1.0).normalize()).unwrap();
        let up = c.raster_of(Vec3::new(0.0, 0.2, 1.0).normalize()).unwrap();
        assert!(left.x < 100.0 && (left.y - 50.0).abs() < 1e-3);
        assert!(up.y < 50.0);
        // the half-fov direction on -x touches the right border
        let t = (30f32).to_radians().tan();
        let edge = c.raster_of(Vec3::new(-t * 0.999, 0.0, 1.0).normalize()).unwrap();
        assert!(edge.x > 199.0);
    }

    #[test]
    fn a_cropped_camera_sees_its_window_of_the_full_view() {
        let full = cam();
        let crop = cam().with_crop(50, 20, 100, 40);
        for (x, y) in [(0.5f32, 0.5f32), (99.5, 39.5), (37.25, 12.75)] {
            let a = crop.generate_ray(Vec2::new(x, y)).d;
            let b = full.generate_ray(Vec2::new(x + 50.0, y + 20.0)).d;
            assert!((a - b).length() < 1e-6);
            assert!((crop.raster_of(a).unwrap() - Vec2::new(x, y)).length() < 1e-3);
        }
        assert!(crop.raster_of(full.generate_ray(Vec2::new(10.0, 10.0)).d).is_none());
        // the window's importance integrates to 1 over the window
        let d = crop.generate_ray(Vec2::new(50.0, 20.0)).d;
        let ratio = crop.importance(d) / full.importance(d);
        assert!((ratio - 200.0 * 100.0 / (100.0 * 40.0)).abs() < 1e-3);
    }

    #[test]
    fn a_resized_camera_sees_the_same_view_at_another_resolution() {
        let full = cam();
        let half = cam().with_resolution(100, 50).expect("same proportions");
        for (x, y) in [(0.5f32, 0.5f32), (99.5, 49.5), (37.25, 12.75)] {
            let a = half.generate_ray(Vec2::new(x, y)).d;
            assert!((a - full.generate_ray(Vec2::new(2.0 * x, 2.0 * y)).d).length() < 1e-6);
            assert!((half.raster_of(a).unwrap() - Vec2::new(x, y)).length() < 1e-3);
        }
        let d = full.generate_ray(Vec2::new(70.0, 30.0)).d;
        assert_eq!(half.importance(d), full.importance(d), "the image's importance is the same");
        let crop = cam().with_crop(50, 20, 100, 40).with_resolution(50, 20).expect("same proportions");
        let a = crop.generate_ray(Vec2::new(5.0, 5.0)).d;
        assert!((a - full.generate_ray(Vec2::new(60.0, 30.0)).d).length() < 1e-6);
        assert!(cam().with_resolution(100, 40).is_none(), "other proportions are refused");
    }

    #[test]
    fn raster_round_trips_through_rays() {
        let c = cam();
        for (x, y) in [(0.5, 0.5), (10.25, 80.75), (199.5, 99.5), (100.0, 50.0)] {
            let r = c.generate_ray(Vec2::new(x, y));
            let back = c.raster_of(r.d).unwrap();
            assert!((back - Vec2::new(x, y)).length() < 1e-3, "{back}");
        }
    }

    #[test]
    fn importance_integrates_to_one_over_the_image() {
        // ∫ We cos dω over the image = 1 for a pinhole normalised per image
        let c = cam();
        let (nx, ny) = (400, 200);
        let mut sum = 0.0f64;
        for i in 0..nx {
            for j in 0..ny {
                let raster = Vec2::new((i as f32 + 0.5) / nx as f32 * 200.0, (j as f32 + 0.5) / ny as f32 * 100.0);
                let d = c.generate_ray(raster).d;
                // dω of a raster cell = dA_plane cos³ with dA_plane = area / cells
                let cos = d.dot(c.forward);
                let d_omega = c.image_plane_area / (nx * ny) as f32 * cos * cos * cos;
                sum += (c.importance(d) * cos * d_omega) as f64;
                let (_, pdf_dir) = c.pdf_ray(d);
                assert!((pdf_dir * d_omega * (nx * ny) as f32 - 1.0).abs() < 1e-3);
            }
        }
        assert!((sum - 1.0).abs() < 1e-3, "{sum}");
    }
}
