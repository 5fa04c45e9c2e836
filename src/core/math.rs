//! Rays, colours and small vector helpers shared by every kernel.

use glam::{Vec3, Vec3A};

/// Linear RGB radiance or reflectance.
pub type Color = Vec3;

/// A ray `origin + t * direction`; intersection routines take the open
/// interval `(t_min, t_max)` of `t` they search.
///
/// The direction is not required to be normalised: rays transformed into
/// object space keep the world-space parameter `t`, so their direction is
/// scaled by the inverse transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3A,
    /// Direction (any non-zero length).
    pub direction: Vec3A,
}

impl Ray {
    /// A ray from `origin` along `direction`.
    #[inline]
    pub fn new(origin: Vec3A, direction: Vec3A) -> Self {
        Self { origin, direction }
    }

    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3A {
        self.origin + self.direction * t
    }
}

/// Whether all `rays` point into one octant (the same signs of their
/// direction components): the packets worth tracing together; the others
/// cost less one ray at a time.
#[inline(always)]
pub fn one_octant(rays: &[Ray]) -> bool {
    let octant = |r: &Ray| {
        let d = r.direction;
        (d.x.is_sign_negative() as u8)
            | (d.y.is_sign_negative() as u8) << 1
            | (d.z.is_sign_negative() as u8) << 2
    };
    let Some(first) = rays.first() else {
        return true;
    };
    let first = octant(first);
    rays.iter().all(|r| octant(r) == first)
}

/// Whether every ray of `rays` starts at the same point, bit for bit (the
/// camera rays of a pinhole).
pub fn one_origin(rays: &[Ray]) -> bool {
    let Some(first) = rays.first() else {
        return true;
    };
    let bits = |r: &Ray| r.origin.to_array().map(f32::to_bits);
    rays.iter().all(|r| bits(r) == bits(first))
}

/// A ray cone (Akenine-Möller et al., "Texture Level of Detail Strategies
/// for Real-Time Ray Tracing", Ray Tracing Gems 2019): the footprint a
/// ray stands for, a cone of `width` at the ray's origin widening by
/// `spread` (radians, small-angle) per unit of distance. Texture lookups
/// at a hit pick their mipmap level from the cone's width there.
///
/// Camera rays get the pixel's cone ([`crate::scene::camera::CameraRays::cone`]);
/// perfectly specular reflection and refraction carry the cone on
/// (surface curvature is ignored); any other bounce drops it
/// ([`RayCone::NONE`]), so those lookups read the full-resolution texture.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RayCone {
    /// Width of the footprint at the ray's origin (world units).
    pub width: f32,
    /// Growth of the width per unit of distance.
    pub spread: f32,
}

impl RayCone {
    /// No footprint: lookups read the full-resolution texture.
    pub const NONE: RayCone = RayCone {
        width: 0.0,
        spread: 0.0,
    };

    /// The cone after travelling `distance`: its width there, same spread.
    #[inline]
    pub fn at(self, distance: f32) -> RayCone {
        RayCone {
            width: self.width + self.spread * distance,
            spread: self.spread,
        }
    }
}

/// Builds an orthonormal basis `(t, b)` around the unit vector `n`
/// (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
#[inline]
pub fn orthonormal_basis(n: Vec3A) -> (Vec3A, Vec3A) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3A::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3A::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Luminance of a linear Rec.709 colour.
#[inline]
pub fn luminance(c: Color) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Largest component, used for contribution thresholds.
#[inline]
pub fn max_component(c: Color) -> f32 {
    c.x.max(c.y).max(c.z)
}
