//! Panoramic cameras: every direction around one eye, laid out as an
//! equirectangular (latitude-longitude) map or as six cube faces.
//!
//! Directions are first made in the *map frame* of the environment maps
//! Prism reads ([`crate::scene::environment`]: `+Y` up, the map's centre
//! along `+X`, `u = 3/4` along `+Z`), then turned into the camera's frame:
//! map `+X` is the camera's viewing direction, `+Y` its up and `+Z` its
//! right. A camera looking along world `+X` with `+Y` up therefore renders
//! a panorama that reads back as an environment unturned; one looking
//! along world `-Z` reads back with a rotation of 90 degrees.

use glam::{Vec2, Vec3A};

use crate::core::settings::Panorama;
use crate::scene::environment::{direction_to_uv, uv_to_direction};

/// The six faces of a [`Panorama::Cubemap`] in image order: each face's
/// viewing direction, its right and its up, in the map frame.
pub const CUBE_FACES: [(Vec3A, Vec3A, Vec3A); 6] = [
    (Vec3A::X, Vec3A::Z, Vec3A::Y),
    (Vec3A::NEG_X, Vec3A::NEG_Z, Vec3A::Y),
    (Vec3A::Y, Vec3A::Z, Vec3A::NEG_X),
    (Vec3A::NEG_Y, Vec3A::Z, Vec3A::X),
    (Vec3A::Z, Vec3A::NEG_X, Vec3A::Y),
    (Vec3A::NEG_Z, Vec3A::X, Vec3A::Y),
];

/// A panorama prepared for one image size: film positions to directions
/// and back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PanoramaRays {
    kind: Panorama,
    /// The camera's viewing direction, up and right: the world directions
    /// of the map frame's `+X`, `+Y` and `+Z`.
    forward: Vec3A,
    up: Vec3A,
    right: Vec3A,
    width: f32,
    height: f32,
}

impl PanoramaRays {
    /// Prepares a `width` x `height` panorama of kind `kind` (for a cube
    /// map `width` should be `6 height`) in the frame of a camera whose
    /// unit viewing direction, up and right are `forward`, `up` and
    /// `right` (orthonormal, `right = forward x up`); see
    /// [`crate::scene::camera::CameraRays::panoramic`].
    pub fn new(kind: Panorama, [forward, up, right]: [Vec3A; 3], width: u32, height: u32) -> Self {
        Self {
            kind,
            forward,
            up,
            right,
            width: width as f32,
            height: height as f32,
        }
    }

    /// Which panorama.
    pub fn kind(&self) -> Panorama {
        self.kind
    }

    /// Unit world direction of film position `p` in pixels (`(0, 0)` the
    /// top-left corner).
    #[inline]
    pub fn direction(&self, p: Vec2) -> Vec3A {
        let m = map_direction(self.kind, p, self.width, self.height);
        (self.forward * m.x + self.up * m.y + self.right * m.z).normalize()
    }

    /// Film position of world direction `d` (need not be unit length): the
    /// inverse of [`PanoramaRays::direction`].
    pub fn film_position(&self, d: Vec3A) -> Vec2 {
        let m = Vec3A::new(d.dot(self.forward), d.dot(self.up), d.dot(self.right));
        map_film_position(self.kind, m, self.width, self.height)
    }
}

/// Unit direction in the map frame of film position `p` of a `width` x
/// `height` panorama of kind `kind`.
#[inline]
pub fn map_direction(kind: Panorama, p: Vec2, width: f32, height: f32) -> Vec3A {
    match kind {
        Panorama::Equirect => uv_to_direction(Vec2::new(p.x / width, p.y / height)).0,
        Panorama::Cubemap => {
            let face = ((p.x / height) as usize).min(5);
            let (f, r, u) = CUBE_FACES[face];
            let a = 2.0 * (p.x - face as f32 * height) / height - 1.0;
            let b = 2.0 * p.y / height - 1.0;
            (f + r * a - u * b).normalize()
        }
    }
}

/// Film position in a `width` x `height` panorama of kind `kind` of the
/// map-frame direction `m`: the inverse of [`map_direction`].
pub fn map_film_position(kind: Panorama, m: Vec3A, width: f32, height: f32) -> Vec2 {
    match kind {
        Panorama::Equirect => direction_to_uv(m.normalize()) * Vec2::new(width, height),
        Panorama::Cubemap => {
            let face = cube_face(m);
            let (f, r, u) = CUBE_FACES[face];
            let z = m.dot(f);
            let a = m.dot(r) / z;
            let b = -m.dot(u) / z;
            Vec2::new(
                (face as f32 + 0.5 * (a + 1.0)) * height,
                0.5 * (b + 1.0) * height,
            )
        }
    }
}

/// The cube face (index into [`CUBE_FACES`]) that direction `m` leaves
/// through: the axis of its largest component.
pub fn cube_face(m: Vec3A) -> usize {
    let a = m.abs();
    if a.x >= a.y && a.x >= a.z {
        if m.x >= 0.0 { 0 } else { 1 }
    } else if a.y >= a.z {
        if m.y >= 0.0 { 2 } else { 3 }
    } else if m.z >= 0.0 {
        4
    } else {
        5
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each cube face's right is its direction crossed with its up (a
    /// perspective view seen from inside, not mirrored), and neighbouring
    /// edges meet: the top edge of the front face is the bottom edge of
    /// the up face.
    #[test]
    fn cube_faces_are_right_handed_views() {
        for (f, r, u) in CUBE_FACES {
            assert_eq!(f.cross(u), r);
        }
        let top_of_front = map_direction(Panorama::Cubemap, Vec2::new(0.5, 0.0), 6.0, 1.0);
        let bottom_of_up = map_direction(Panorama::Cubemap, Vec2::new(2.5, 1.0), 6.0, 1.0);
        assert!((top_of_front - bottom_of_up).length() < 1e-6);
    }

    /// Film position to direction and back lands on the same position, for
    /// both layouts and a turned camera.
    #[test]
    fn directions_invert() {
        let forward = Vec3A::new(-3.0, 0.5, -3.0).normalize();
        let right = forward.cross(Vec3A::Y).normalize();
        let frame = [forward, right.cross(forward), right];
        for (kind, w, h) in [(Panorama::Equirect, 64, 32), (Panorama::Cubemap, 96, 16)] {
            let pano = PanoramaRays::new(kind, frame, w, h);
            for j in 0..h {
                for i in 0..w {
                    let p = Vec2::new(i as f32 + 0.5, j as f32 + 0.5);
                    let d = pano.direction(p);
                    assert!((d.length() - 1.0).abs() < 1e-5);
                    let q = pano.film_position(d);
                    assert!((p - q).length() < 2e-3, "{kind:?} {p} -> {d} -> {q}");
                }
            }
        }
    }

    /// A camera looking along world `+X` with `+Y` up renders the
    /// environment's own directions: every texel centre's direction is the
    /// environment's direction of that texel.
    #[test]
    fn equirect_is_the_environment_convention() {
        let pano = PanoramaRays::new(Panorama::Equirect, [Vec3A::X, Vec3A::Y, Vec3A::Z], 16, 8);
        for (p, want) in [
            (Vec2::new(8.0, 4.0), Vec3A::X),
            (Vec2::new(12.0, 4.0), Vec3A::Z),
            (Vec2::new(4.0, 4.0), Vec3A::NEG_Z),
            (Vec2::new(0.0, 4.0), Vec3A::NEG_X),
            (Vec2::new(8.0, 0.0), Vec3A::Y),
        ] {
            let d = pano.direction(p);
            assert!((d - want).length() < 1e-6, "{p}: {d} wanted {want}");
        }
    }
}
