//! Cameras: pinhole, thin lens (depth of field) and orthographic rays
//! through an image plane, panoramas in every direction
//! ([`crate::scene::panorama`]), and the automatic framing of a scene's
//! bounds.

use bevy_ecs::component::Component;
use glam::{DMat3, DVec3, DVec4, Mat3A, Vec2, Vec3, Vec3A};

use crate::core::math::Ray;
use crate::core::settings::Panorama;
use crate::scene::panorama::PanoramaRays;

/// How a camera projects the world onto its image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Rays from one eye (or from a lens around it) through the image plane,
    /// with [`Camera::vfov_degrees`] as the vertical field of view.
    Perspective,
    /// Parallel rays along the viewing direction from a rectangle around
    /// the eye, `2 * half_height` world units tall (glTF's `ymag` is the
    /// half height); the width follows the image's aspect ratio.
    Orthographic {
        /// Half the height of the viewed rectangle, in world units.
        half_height: f32,
    },
}

/// A camera looking from `look_from` towards `look_at`: a pinhole by
/// default, a thin lens when [`Camera::lens_radius`] is positive, or an
/// orthographic projection.
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
    /// Vertical field of view in degrees (perspective projection).
    pub vfov_degrees: f32,
    /// Lens shift: the image window slides in its own plane, right by
    /// `shift.x` and up by `shift.y` image heights, while the eye and the
    /// viewing direction stay put (an off-axis view, as a shift lens or
    /// Blender's camera shift, relative to the height here). Zero is the
    /// usual centred view; light-field cameras use it so that every view
    /// frames the same window of the focal plane.
    pub shift: Vec2,
    /// Radius of the thin lens's aperture in world units; 0 (the default)
    /// is a pinhole, whose image is sharp at every depth.
    pub lens_radius: f32,
    /// Distance from the eye, along the viewing direction, of the plane
    /// in focus; 0 (the default) focuses on `look_at`. Only used when
    /// `lens_radius` is positive.
    pub focus_distance: f32,
    /// Perspective (default) or orthographic.
    pub projection: Projection,
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
            lens_radius: 0.0,
            focus_distance: 0.0,
            projection: Projection::Perspective,
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
        if !(self.lens_radius.is_finite() && self.lens_radius >= 0.0) {
            return Err(format!(
                "camera lens radius must be finite and >= 0, got {}",
                self.lens_radius
            ));
        }
        if !(self.focus_distance.is_finite() && self.focus_distance >= 0.0) {
            return Err(format!(
                "camera focus distance must be finite and >= 0 (0: the look_at point), got {}",
                self.focus_distance
            ));
        }
        if let Projection::Orthographic { half_height } = self.projection
            && !(half_height.is_finite() && half_height > 0.0)
        {
            return Err(format!(
                "orthographic camera half height must be finite and positive, got {half_height}"
            ));
        }
        Ok(())
    }

    /// The distance of the plane in focus: [`Camera::focus_distance`], or
    /// the distance to `look_at` when that is 0.
    pub fn focal_distance(&self) -> f32 {
        if self.focus_distance > 0.0 {
            self.focus_distance
        } else {
            (self.look_at - self.look_from).length() as f32
        }
    }

    /// Sets the aperture from an f-number: the lens radius is
    /// `focal_length / (2 N)`, with the focal length of a lens that images
    /// the plane in focus (at [`Camera::focal_distance`]) onto a 36 x 24 mm
    /// frame (full-frame film) with this camera's vertical field of view,
    /// and scene units taken as metres. The focal length is
    /// `0.012 / tan(vfov / 2)` m (an approximation valid when the focus
    /// is far compared with the focal length).
    pub fn set_f_number(&mut self, f_number: f32) {
        let focal_length = 0.012 / (self.vfov_degrees.to_radians() * 0.5).tan();
        self.lens_radius = focal_length / (2.0 * f_number);
    }
}

/// Vertical field of view of the cameras made by [`frame_bounds`], in
/// degrees.
pub const AUTO_VFOV_DEGREES: f32 = 40.0;

/// A camera that frames the box `lo..hi` (world coordinates) for an image
/// of aspect ratio `aspect` (width / height): it looks at the box's centre
/// along `-Z` (from the `+Z` side, glTF's "front"), with `+Y` up and a
/// vertical field of view of [`AUTO_VFOV_DEGREES`], from the distance at
/// which the box's front face fills 90% of the narrower image side (the
/// box's depth is added so that nothing is behind the eye). A box of zero
/// size gets the distance of a unit box.
pub fn frame_bounds(lo: DVec3, hi: DVec3, aspect: f64) -> Camera {
    let centre = 0.5 * (lo + hi);
    let half = (0.5 * (hi - lo)).max(DVec3::ZERO);
    let half = if half.max_element() > 0.0 {
        half
    } else {
        DVec3::splat(0.5)
    };
    let tan_v = (AUTO_VFOV_DEGREES as f64 * 0.5).to_radians().tan();
    let tan_h = tan_v * aspect;
    let fill = 0.9;
    let distance = (half.y / (fill * tan_v)).max(half.x / (fill * tan_h)) + half.z;
    Camera {
        look_from: centre + DVec3::Z * distance,
        look_at: centre,
        up: Vec3::Y,
        vfov_degrees: AUTO_VFOV_DEGREES,
        name: Some("automatic framing".into()),
        ..Camera::default()
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
    /// Unit right and up vectors of the lens plane, scaled by the lens
    /// radius (zero for a pinhole).
    lens_u: Vec3A,
    lens_v: Vec3A,
    /// Unit viewing direction.
    forward: Vec3A,
    /// Distance to the plane in focus along the viewing direction.
    focus: f32,
    /// Orthographic: the unit viewing direction (rays are parallel and the
    /// image plane offsets are added to the origin instead).
    ortho_forward: Option<Vec3A>,
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
        let (half_h, ortho_forward, plane_centre) = match camera.projection {
            Projection::Perspective => (
                (camera.vfov_degrees.to_radians() * 0.5).tan(),
                None,
                forward,
            ),
            Projection::Orthographic { half_height } => {
                (half_height, Some(Vec3A::from(forward)), Vec3::ZERO)
            }
        };
        let half_w = half_h * width as f32 / height as f32;
        // The window's centre, moved by the shift (in image heights).
        let centre = plane_centre
            + right * (2.0 * half_h * camera.shift.x)
            + up * (2.0 * half_h * camera.shift.y);
        let top_left = centre - right * half_w + up * half_h;
        let lens = camera.lens_radius;
        Self {
            origin: (camera.look_from - origin).as_vec3a(),
            top_left: top_left.into(),
            dx: (right * (2.0 * half_w / width as f32)).into(),
            dy: (-up * (2.0 * half_h / height as f32)).into(),
            lens_u: (right * lens).into(),
            lens_v: (up * lens).into(),
            forward: forward.into(),
            focus: camera.focal_distance(),
            ortho_forward,
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
    /// corner of the image, `(0.5, 0.5)` the centre of the first pixel)
    /// from the centre of the lens (the pinhole ray). The direction is unit
    /// length.
    #[inline]
    pub fn ray(&self, p: Vec2) -> Ray {
        if let Some(pano) = &self.panorama {
            return self.panorama_ray(pano, p);
        }
        let d = self.top_left + self.dx * p.x + self.dy * p.y;
        match self.ortho_forward {
            // (`unit_rounded`: `pixel_centre_row` repeats this across
            // lanes, and glam's `normalize` rounds differently on aarch64.)
            None => Ray::new(self.origin, crate::core::math::unit_rounded(d)),
            Some(forward) => Ray::new(self.origin + d, forward),
        }
    }

    /// [`CameraRays::ray`] through the centres of `N` neighbouring pixels
    /// of row `y`, from column `x` on (the lanes from `n` on repeat the
    /// last pixel), computed across the lanes: each coordinate of each ray with
    /// the same IEEE operations on the same values as [`CameraRays::ray`]
    /// (the image-plane point, then its length as `sqrt((x*x + y*y) +
    /// z*z)` and the division by it), so the same bits. `None` for a
    /// panorama or an orthographic camera (traced with
    /// [`CameraRays::ray`]).
    ///
    /// One ray at a time, generating the frame-loop benchmark's camera
    /// rays took 3.5-4.9% of its frame (`perf`): a square root and a
    /// division per ray, and the shuffles of a horizontal dot product.
    #[inline]
    pub fn pixel_centre_row<const N: usize>(&self, x: u32, y: u32, n: usize) -> Option<[Ray; N]> {
        if self.panorama.is_some() || self.ortho_forward.is_some() || n == 0 {
            return None;
        }
        let py = y as f32 + 0.5;
        let tl = self.top_left.to_array();
        let (dx, dy) = (self.dx.to_array(), self.dy.to_array());
        let px: [f32; N] = std::array::from_fn(|l| (x + l.min(n - 1) as u32) as f32 + 0.5);
        let mut d = [[0.0f32; N]; 3];
        for (a, d) in d.iter_mut().enumerate() {
            for (d, &px) in d.iter_mut().zip(&px) {
                *d = (tl[a] + dx[a] * px) + dy[a] * py;
            }
        }
        let mut len = [0.0f32; N];
        for (l, len) in len.iter_mut().enumerate() {
            *len = ((d[0][l] * d[0][l] + d[1][l] * d[1][l]) + d[2][l] * d[2][l]).sqrt();
        }
        for d in &mut d {
            for (d, &len) in d.iter_mut().zip(&len) {
                *d /= len;
            }
        }
        Some(std::array::from_fn(|l| {
            Ray::new(self.origin, Vec3A::new(d[0][l], d[1][l], d[2][l]))
        }))
    }

    /// [`CameraRays::ray`] for a panorama, out of line so that the
    /// perspective path stays as small as it was (the panorama branch inline
    /// cost the wavefront's camera-ray stage about 2% more instructions).
    #[cold]
    #[inline(never)]
    fn panorama_ray(&self, pano: &PanoramaRays, p: Vec2) -> Ray {
        Ray::new(self.origin, pano.direction(p))
    }

    /// True when the camera has a lens of positive radius (depth of
    /// field): [`CameraRays::lens_ray`] then depends on its lens sample.
    #[inline]
    pub fn has_lens(&self) -> bool {
        self.lens_u != Vec3A::ZERO
    }

    /// The ray cone of a camera ray (texture level of detail): one pixel's
    /// footprint. A perspective camera's cone starts at the eye with a
    /// spread of one pixel's angle at the image centre; an orthographic
    /// camera's rays are parallel, so its cone is one pixel wide and does
    /// not spread. A lens is ignored (the pinhole's footprint is used).
    #[inline]
    pub fn cone(&self) -> crate::core::math::RayCone {
        let pixel = self.dy.length();
        match self.ortho_forward {
            None => crate::core::math::RayCone {
                width: 0.0,
                spread: pixel,
            },
            Some(_) => crate::core::math::RayCone {
                width: pixel,
                spread: 0.0,
            },
        }
    }

    /// The ray through film position `p` from lens point `lens` (a uniform
    /// sample of the unit square, mapped concentrically onto the unit disk
    /// and scaled by the lens radius): it starts on the lens and passes
    /// through the point that the pinhole ray [`CameraRays::ray`] meets on
    /// the plane in focus, so that plane stays sharp. Without a lens this
    /// is exactly [`CameraRays::ray`].
    #[inline]
    pub fn lens_ray(&self, p: Vec2, lens: Vec2) -> Ray {
        let pinhole = self.ray(p);
        // Panoramas are pinholes: every direction from one eye.
        if !self.has_lens() || self.panorama.is_some() {
            return pinhole;
        }
        let disk = crate::core::sampling::concentric_disk(lens);
        let offset = self.lens_u * disk.x + self.lens_v * disk.y;
        // Distance along the pinhole ray to the plane in focus, which is
        // perpendicular to the viewing direction.
        let cos = pinhole.direction.dot(self.forward);
        let t = self.focus / cos;
        let focus_point = pinhole.origin + pinhole.direction * t;
        let origin = pinhole.origin + offset;
        Ray::new(origin, (focus_point - origin).normalize())
    }

    /// The eye: where every camera ray starts.
    pub fn origin(&self) -> Vec3A {
        self.origin
    }

    /// True for a pinhole perspective camera (no lens, no panorama, not
    /// orthographic): every ray starts at one eye.
    pub fn pinhole_perspective(&self) -> bool {
        !self.has_lens() && self.panorama.is_none() && self.ortho_forward.is_none()
    }

    /// The unit viewing direction, normal to the image plane.
    pub fn forward(&self) -> Vec3A {
        self.forward
    }

    /// Area of one pixel on the image plane at distance 1 from the eye.
    pub fn pixel_area(&self) -> f32 {
        self.dx.length() * self.dy.length()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The automatic camera sees every corner of the box inside the image,
    /// and the box fills 90% of the image's narrower side (up to the
    /// perspective of its depth: its front face exactly, the projected box
    /// a little more).
    #[test]
    fn framing_puts_the_box_in_view() {
        for (lo, hi, aspect) in [
            (
                DVec3::new(-1.0, -1.0, -1.0),
                DVec3::new(1.0, 1.0, 1.0),
                4.0 / 3.0,
            ),
            (
                DVec3::new(10.0, 0.0, -3.0),
                DVec3::new(30.0, 2.0, 3.0),
                4.0 / 3.0,
            ),
            (DVec3::new(0.0, -5.0, 0.0), DVec3::new(0.1, 5.0, 0.1), 1.0),
            (DVec3::new(0.0, 0.0, -50.0), DVec3::new(1.0, 1.0, 50.0), 2.0),
        ] {
            let (w, h) = ((240.0 * aspect) as u32, 240);
            let cam = frame_bounds(lo, hi, w as f64 / h as f64);
            cam.validate().unwrap();
            let proj = CameraRays::new(&cam, w, h).projection();
            let (mut min, mut max) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
            for i in 0..8 {
                let c = DVec3::select(glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0), hi, lo);
                let (p, depth) = proj.project(c.as_vec3a());
                assert!(depth > 0.0, "corner {c} behind the eye");
                assert!(
                    p.x >= 0.0 && p.y >= 0.0 && p.x <= w as f32 && p.y <= h as f32,
                    "corner {c} at {p} outside the {w}x{h} image"
                );
                min = min.min(p);
                max = max.max(p);
            }
            let fill = ((max.x - min.x) / w as f32).max((max.y - min.y) / h as f32);
            assert!(fill >= 0.89, "box {lo}..{hi} fills only {fill}");
        }
    }

    /// A row of pixel-centre rays computed across lanes is the rays of
    /// [`CameraRays::ray`] bit for bit, partial rows included; panoramas
    /// and orthographic cameras are left to it.
    #[test]
    fn pixel_centre_rows_are_the_single_rays() {
        let mut checked = 0;
        for (from, at, fov, (w, h)) in [
            (
                DVec3::new(1.0, 2.0, 3.0),
                DVec3::new(0.0, 0.0, -4.0),
                40.0,
                (640, 360),
            ),
            (
                DVec3::new(-3.7e4, 0.1, 2.9e4),
                DVec3::new(-3.7e4, 5.0, 0.0),
                90.0,
                (97, 31),
            ),
            (
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(0.0, -1.0, 1e-3),
                1.5,
                (33, 17),
            ),
        ] {
            let cam = Camera {
                look_from: from,
                look_at: at,
                vfov_degrees: fov,
                ..Camera::default()
            };
            cam.validate().unwrap();
            let rays = CameraRays::new(&cam, w, h);
            for y in (0..h).step_by(3) {
                for x in (0..w).step_by(5) {
                    let n = ((w - x) as usize).min(16).min(1 + (x as usize % 16));
                    let row = rays.pixel_centre_row::<16>(x, y, n).unwrap();
                    for (l, r) in row.iter().enumerate() {
                        let px = x + l.min(n - 1) as u32;
                        let one = rays.ray(Vec2::new(px as f32 + 0.5, y as f32 + 0.5));
                        let bits = |v: Vec3A| v.to_array().map(f32::to_bits);
                        assert_eq!(bits(r.origin), bits(one.origin));
                        assert_eq!(bits(r.direction), bits(one.direction), "pixel {px},{y}");
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 10_000);
        let ortho = Camera {
            projection: Projection::Orthographic { half_height: 1.0 },
            ..Camera::default()
        };
        assert!(
            CameraRays::new(&ortho, 8, 8)
                .pixel_centre_row::<16>(0, 0, 8)
                .is_none()
        );
    }

    /// Every lens ray of a film position meets the plane in focus where
    /// the pinhole ray does; lens samples spread the ray origins over a
    /// disk of the lens radius; without a lens the ray is the pinhole's.
    #[test]
    fn lens_rays_meet_on_the_plane_in_focus() {
        let cam = Camera {
            look_from: DVec3::new(1.0, 2.0, 3.0),
            look_at: DVec3::new(0.0, 0.0, -4.0),
            lens_radius: 0.25,
            focus_distance: 6.0,
            ..Camera::default()
        };
        let rays = CameraRays::new(&cam, 32, 24);
        let forward = (cam.look_at - cam.look_from).normalize().as_vec3a();
        for p in [
            Vec2::new(0.5, 0.5),
            Vec2::new(16.0, 12.0),
            Vec2::new(31.5, 3.25),
        ] {
            let pin = rays.ray(p);
            let on_plane = |r: &Ray| {
                r.at((6.0 - (r.origin - pin.origin).dot(forward)) / r.direction.dot(forward))
            };
            let target = on_plane(&pin);
            for u in [
                Vec2::new(0.1, 0.9),
                Vec2::new(0.5, 0.5),
                Vec2::new(0.99, 0.01),
            ] {
                let r = rays.lens_ray(p, u);
                assert!((r.direction.length() - 1.0).abs() < 1e-5);
                assert!((r.origin - pin.origin).length() <= 0.25 + 1e-5);
                assert!((r.origin - pin.origin).dot(forward).abs() < 1e-5);
                let hit = on_plane(&r);
                assert!((hit - target).length() < 1e-4, "{hit} vs {target}");
            }
        }
        let pinhole = CameraRays::new(
            &Camera {
                lens_radius: 0.0,
                ..cam
            },
            32,
            24,
        );
        let p = Vec2::new(3.0, 4.0);
        assert_eq!(pinhole.lens_ray(p, Vec2::new(0.3, 0.7)), pinhole.ray(p));
    }

    /// Orthographic rays are parallel to the viewing direction and start on
    /// a rectangle of the given half height around the eye.
    #[test]
    fn orthographic_rays_are_parallel() {
        let cam = Camera {
            look_from: DVec3::new(0.0, 0.0, 10.0),
            projection: Projection::Orthographic { half_height: 2.0 },
            ..Camera::default()
        };
        let rays = CameraRays::new(&cam, 40, 20);
        let top_left = rays.ray(Vec2::ZERO);
        let bottom_right = rays.ray(Vec2::new(40.0, 20.0));
        assert_eq!(top_left.direction, Vec3A::NEG_Z);
        assert_eq!(bottom_right.direction, Vec3A::NEG_Z);
        assert!((top_left.origin - Vec3A::new(-4.0, 2.0, 10.0)).length() < 1e-5);
        assert!((bottom_right.origin - Vec3A::new(4.0, -2.0, 10.0)).length() < 1e-5);
    }

    /// The f-number gives radius f / 2N with the focal length of a
    /// 24 mm-tall frame: 50 mm at a vertical field of view of 27 degrees.
    #[test]
    fn f_number_sets_the_lens_radius() {
        let mut cam = Camera {
            vfov_degrees: 2.0 * (12.0f32 / 50.0).atan().to_degrees(),
            ..Camera::default()
        };
        cam.set_f_number(2.0);
        assert!(
            (cam.lens_radius - 0.0125).abs() < 1e-6,
            "{}",
            cam.lens_radius
        );
    }
}
