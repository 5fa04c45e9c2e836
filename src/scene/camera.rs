//! Pinhole camera: rays through an image plane.

use bevy_ecs::component::Component;
use glam::{DMat3, DVec3, DVec4, Mat3A, Vec2, Vec3, Vec3A};

use crate::core::math::Ray;

/// A pinhole camera looking from `look_from` towards `look_at`.
///
/// Positions are world coordinates in double precision, like
/// [`Transform`](crate::geometry::transform::Transform): a camera 1e9 units
/// from the world origin keeps its sub-millimetre placement.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct Camera {
    /// Eye position (world coordinates).
    pub look_from: DVec3,
    /// A point the camera looks at (world coordinates).
    pub look_at: DVec3,
    /// Approximate up direction (need not be orthogonal to the view).
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov_degrees: f32,
    /// Optional name (from glTF).
    pub name: Option<String>,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            look_from: DVec3::new(0.0, 0.0, 5.0),
            look_at: DVec3::ZERO,
            up: Vec3::Y,
            vfov_degrees: 40.0,
            name: None,
        }
    }
}

impl Camera {
    /// Checks that the camera defines a usable view; the error says why not.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.look_from.is_finite() && self.look_at.is_finite() && self.up.is_finite()) {
            return Err("camera position, target and up must be finite".into());
        }
        let forward = self.look_at - self.look_from;
        if forward.length_squared() <= 0.0 {
            return Err("camera look_from and look_at are the same point".into());
        }
        if forward
            .normalize()
            .as_vec3()
            .cross(self.up)
            .length_squared()
            < 1e-12
        {
            return Err("camera up is parallel to the viewing direction".into());
        }
        if !(self.vfov_degrees > 0.0 && self.vfov_degrees < 180.0) {
            return Err(format!(
                "camera vertical field of view must be in (0, 180) degrees, got {}",
                self.vfov_degrees
            ));
        }
        Ok(())
    }
}

/// A camera prepared for one image size: maps film positions to rays.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    origin: Vec3A,
    /// World-space offset of the image plane's top-left corner (at distance 1).
    top_left: Vec3A,
    /// Step per pixel to the right.
    dx: Vec3A,
    /// Step per pixel downwards.
    dy: Vec3A,
}

impl CameraRays {
    /// Prepares `camera` for a `width` x `height` image in world
    /// coordinates (render origin at the world origin); the aspect ratio
    /// is the image's. The camera must pass [`Camera::validate`].
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        Self::relative_to(camera, DVec3::ZERO, width, height)
    }

    /// Prepares `camera` for a `width` x `height` image in the frame
    /// centred on `origin` (a scene's
    /// [`origin`](crate::scene::RenderScene::origin)): the eye is
    /// `look_from - origin`, subtracted in f64, and the viewing direction
    /// is computed in f64 before rounding.
    pub fn relative_to(camera: &Camera, origin: DVec3, width: u32, height: u32) -> Self {
        let forward = (camera.look_at - camera.look_from).normalize().as_vec3();
        let right = forward.cross(camera.up).normalize();
        let up = right.cross(forward);
        let half_h = (camera.vfov_degrees.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height as f32;
        let top_left = forward - right * half_w + up * half_h;
        Self {
            origin: (camera.look_from - origin).as_vec3a(),
            top_left: top_left.into(),
            dx: (right * (2.0 * half_w / width as f32)).into(),
            dy: (-up * (2.0 * half_h / height as f32)).into(),
        }
    }

    /// The ray through film position `p` in pixels (`(0,0)` is the top-left
    /// corner of the image, `(0.5, 0.5)` the centre of the first pixel).
    /// The direction is unit length.
    #[inline]
    pub fn ray(&self, p: Vec2) -> Ray {
        let d = self.top_left + self.dx * p.x + self.dy * p.y;
        Ray::new(self.origin, d.normalize())
    }

    /// The eye: where every camera ray starts.
    pub fn origin(&self) -> Vec3A {
        self.origin
    }

    /// The inverse of [`CameraRays::ray`]: prepares the projection of
    /// world points onto the film.
    pub fn projection(&self) -> CameraProjection {
        CameraProjection {
            origin: self.origin,
            to_film: Mat3A::from_cols(self.top_left, self.dx, self.dy).inverse(),
        }
    }
}

/// World points to film positions: the inverse of [`CameraRays::ray`].
#[derive(Clone, Copy, Debug)]
pub struct CameraProjection {
    origin: Vec3A,
    /// Inverse of the matrix whose columns are the image plane's top-left
    /// corner and its steps per pixel.
    to_film: Mat3A,
}

impl CameraProjection {
    /// Film position (pixels, as [`CameraRays::ray`] takes them) and depth
    /// of world point `p`. The depth is the distance along the viewing
    /// direction; points at or behind the eye have depth `<= 0` and no
    /// meaningful film position.
    #[inline]
    pub fn project(&self, p: Vec3A) -> (Vec2, f32) {
        let v = self.to_film * (p - self.origin);
        (Vec2::new(v.y / v.x, v.z / v.x), v.x)
    }

    /// The eye.
    pub fn origin(&self) -> Vec3A {
        self.origin
    }

    /// Homogeneous clip coordinates of world point `p` for a film of
    /// `size` pixels, in double precision: `w` is the depth of
    /// [`Self::project`], and `x / w`, `y / w` run from -1 to 1 across the
    /// image (left to right, top to bottom), so the image is the view
    /// volume `|x|, |y| <= w` of [`crate::core::clip`]. `z` is 0 (depth is
    /// not clipped). Clip coordinates are linear in `p`: a parameter
    /// along a clipped segment is the same parameter along the world
    /// segment.
    pub fn to_clip(&self, p: Vec3A, size: Vec2) -> DVec4 {
        let v = DMat3::from_cols(
            self.to_film.x_axis.as_dvec3(),
            self.to_film.y_axis.as_dvec3(),
            self.to_film.z_axis.as_dvec3(),
        ) * (p.as_dvec3() - self.origin.as_dvec3());
        DVec4::new(
            2.0 * v.y / size.x as f64 - v.x,
            2.0 * v.z / size.y as f64 - v.x,
            0.0,
            v.x,
        )
    }

    /// Film position in pixels of a point in the view volume of
    /// [`Self::to_clip`] (`w > 0`, `|x|, |y| <= w`): inside
    /// `[0, size.x] x [0, size.y]`, boundary included.
    pub fn clip_to_film(c: DVec4, size: Vec2) -> Vec2 {
        let f = |v: f64, s: f32| ((v / c.w + 1.0) * 0.5 * s as f64).clamp(0.0, s as f64) as f32;
        Vec2::new(f(c.x, size.x), f(c.y, size.y))
    }
}
