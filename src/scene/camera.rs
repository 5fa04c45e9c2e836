//! Pinhole camera: rays through an image plane (or, for panoramas, in
//! every direction: [`crate::scene::panorama`]).

use bevy_ecs::component::Component;
use glam::{DVec3, Mat3A, Vec2, Vec3, Vec3A};

use crate::core::math::Ray;
use crate::core::settings::Panorama;
use crate::scene::panorama::PanoramaRays;

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
    /// Lens shift: the image window slides in its own plane, right by
    /// `shift.x` and up by `shift.y` image heights, while the eye and the
    /// viewing direction stay put (an off-axis view, as a shift lens or
    /// Blender's camera shift, relative to the height here). Zero is the
    /// usual centred view; light-field cameras use it so that every view
    /// frames the same window of the focal plane.
    pub shift: Vec2,
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
            shift: Vec2::ZERO,
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
        if !self.shift.is_finite() {
            return Err(format!("camera shift must be finite, got {}", self.shift));
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
    /// A panorama instead of the image plane (`None`: perspective).
    panorama: Option<PanoramaRays>,
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
        // The window's centre, moved by the shift (in image heights).
        let centre = forward
            + right * (2.0 * half_h * camera.shift.x)
            + up * (2.0 * half_h * camera.shift.y);
        let top_left = centre - right * half_w + up * half_h;
        Self {
            origin: (camera.look_from - origin).as_vec3a(),
            top_left: top_left.into(),
            dx: (right * (2.0 * half_w / width as f32)).into(),
            dy: (-up * (2.0 * half_h / height as f32)).into(),
            panorama: None,
        }
    }

    /// Prepares `camera` for a `width` x `height` panorama of kind
    /// `panorama` in the frame centred on `origin`, or for its perspective
    /// view when `panorama` is `None` (exactly
    /// [`CameraRays::relative_to`]). The panorama's map frame is the
    /// camera's: `+X` its viewing direction, `+Y` its up, `+Z` its right
    /// (see [`crate::scene::panorama`]); the field of view is not used.
    pub fn panoramic(
        camera: &Camera,
        origin: DVec3,
        width: u32,
        height: u32,
        panorama: Option<Panorama>,
    ) -> Self {
        let mut rays = Self::relative_to(camera, origin, width, height);
        if let Some(kind) = panorama {
            let forward = (camera.look_at - camera.look_from).normalize().as_vec3();
            let right = forward.cross(camera.up).normalize();
            let up = right.cross(forward);
            rays.panorama = Some(PanoramaRays::new(
                kind,
                [forward.into(), up.into(), right.into()],
                width,
                height,
            ));
        }
        rays
    }

    /// The panorama these rays cover, if they are panoramic.
    pub fn panorama(&self) -> Option<&PanoramaRays> {
        self.panorama.as_ref()
    }

    /// The ray through film position `p` in pixels (`(0,0)` is the top-left
    /// corner of the image, `(0.5, 0.5)` the centre of the first pixel).
    /// The direction is unit length.
    #[inline]
    pub fn ray(&self, p: Vec2) -> Ray {
        if let Some(pano) = &self.panorama {
            return Ray::new(self.origin, pano.direction(p));
        }
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
}
