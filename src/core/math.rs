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

/// The cross product `a x b` with both products of each component rounded
/// before their difference: the bits of glam's `Vec3A::cross` on x86-64
/// (SSE2) and of its scalar fallback. On aarch64 glam's `cross` fuses the
/// second product into the difference (NEON `vfmsq_f32`), so its last
/// bits differ there; code whose result another code path reproduces lane
/// by lane (the polygon edge test and the wavefront's batched polygons)
/// uses this one, and the two agree on every target.
#[inline(always)]
pub fn cross_rounded(a: Vec3A, b: Vec3A) -> Vec3A {
    Vec3A::new(
        a.y * b.z - a.z * b.y,
        a.z * b.x - a.x * b.z,
        a.x * b.y - a.y * b.x,
    )
}

/// `v` over its length `sqrt((x x + y y) + z z)`, each coordinate divided
/// by it: the bits of glam's `Vec3A::normalize` on x86-64 (SSE2). On
/// aarch64 glam multiplies by the reciprocal of the length instead, which
/// rounds differently; code whose result another code path reproduces
/// lane by lane (a camera's rays, one at a time and a row at a time) uses
/// this one, and the two agree on every target.
#[inline(always)]
pub fn unit_rounded(v: Vec3A) -> Vec3A {
    let len = ((v.x * v.x + v.y * v.y) + v.z * v.z).sqrt();
    Vec3A::new(v.x / len, v.y / len, v.z / len)
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

/// Coefficients of `atan(x) / x` as a polynomial in `x^2` on `[0, 1]`,
/// lowest first: a near-minimax fit of relative error below `1e-7` in
/// exact arithmetic, `2.5e-7` evaluated in `f32` (tested).
const ATAN_POLY: [f32; 8] = [
    0.999_999_9,
    -0.333_319_9,
    0.199_697_32,
    -0.140_195_2,
    0.099_143_9,
    -0.059_487_67,
    0.024_253_25,
    -0.004_693_500_7,
];

/// `atan(y / x)` in the quadrant of `(x, y)`, as [`f32::atan2`], within
/// `3e-7` relative of the exact angle (2.5 EPS; tested on a dense grid): a
/// division and a polynomial of degree 15 the core overlaps with other
/// work, where the C library's `atan2f` cost 14% of a participating-media
/// render (`assets/fog.toml`: the equiangular samples' angles and the
/// cylinders' azimuths). Where both inputs are zero or either is
/// infinite, [`f32::atan2`]; NaN gives NaN.
#[inline]
pub fn fast_atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    if !(den > 0.0 && den < f32::INFINITY) {
        return y.atan2(x);
    }
    let r = num / den;
    let s = r * r;
    let mut p = ATAN_POLY[7];
    for &c in ATAN_POLY[..7].iter().rev() {
        p = p * s + c;
    }
    let mut a = r * p;
    if ay > ax {
        a = std::f32::consts::FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = std::f32::consts::PI - a;
    }
    a.copysign(y)
}

/// `(sin x, cos x)` for `x` in `[-pi/4, pi/4]`, by their Taylor
/// polynomials to degree 7 and 8 (truncation below `3.2e-7` and `2.5e-8`
/// there): a few multiplications the core overlaps with other work,
/// where the library's `sinf`/`cosf` were a call on the sampling chain's
/// critical path.
#[inline(always)]
pub fn sin_cos_octant(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0))));
    let c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0))));
    (s, c)
}

/// `tan x` for `x` in `(-pi/2, pi/2)`, within `7e-7` relative of the
/// exact tangent of `x` (6 EPS, mostly the sine's truncation; tested):
/// the octant polynomials of [`sin_cos_octant`], past `pi/4` on the
/// complement `pi/2 - |x|` taken in two parts (so that near `pi/2` it
/// keeps the precision `x` has). Outside the interval, and for NaN,
/// [`f32::tan`].
#[inline]
pub fn fast_tan(x: f32) -> f32 {
    /// `pi/2` split as `f32` plus the rest.
    const HALF_PI_HI: f32 = std::f32::consts::FRAC_PI_2;
    const HALF_PI_LO: f32 = -4.371_139e-8;
    let ax = x.abs();
    if ax <= std::f32::consts::FRAC_PI_4 {
        let (s, c) = sin_cos_octant(x);
        s / c
    } else if ax < HALF_PI_HI {
        let (s, c) = sin_cos_octant((HALF_PI_HI - ax) + HALF_PI_LO);
        (c / s).copysign(x)
    } else {
        x.tan()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cross_rounded` rounds each product before the difference (checked
    /// against products taken exactly in f64 and rounded to f32, which a
    /// fused multiply-subtract would not match), and on x86-64 it is glam's
    /// `cross` bit for bit, so the per-ray polygon test kept its bits when
    /// it took it up.
    #[test]
    fn cross_rounded_rounds_each_product() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            // Mantissas with many bits set, magnitudes from 1e-3 to 1e3.
            let m = (s >> 40) as f32 / (1u64 << 24) as f32 + 0.5;
            let e = ((s >> 8) % 21) as i32 - 10;
            let sign = if s & 1 == 0 { 1.0 } else { -1.0 };
            sign * m * 2f32.powi(e)
        };
        let round = |p: f32, q: f32| (p as f64 * q as f64) as f32;
        let mut fused_would_differ = 0;
        for _ in 0..20_000 {
            let a = Vec3A::new(next(), next(), next());
            let b = Vec3A::new(next(), next(), next());
            let c = cross_rounded(a, b);
            let want = [
                round(a.y, b.z) - round(a.z, b.y),
                round(a.z, b.x) - round(a.x, b.z),
                round(a.x, b.y) - round(a.y, b.x),
            ];
            assert_eq!(c.to_array().map(f32::to_bits), want.map(f32::to_bits));
            fused_would_differ += ((-a.z).mul_add(b.y, round(a.y, b.z)) != c.x) as u32;
            #[cfg(target_arch = "x86_64")]
            assert_eq!(
                a.cross(b).to_array().map(f32::to_bits),
                c.to_array().map(f32::to_bits)
            );
        }
        // The check can tell: a fused difference changes many of them.
        assert!(fused_would_differ > 1000, "{fused_would_differ}");
    }

    /// `unit_rounded` divides by the length taken as `sqrt((x x + y y) +
    /// z z)` (checked against that expression written out, which a
    /// multiplication by the reciprocal would not match), and on x86-64 it
    /// is glam's `normalize` bit for bit, so a camera's rays kept their
    /// bits when they took it up.
    #[test]
    fn unit_rounded_divides_by_the_length() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 2f32.powi((s % 13) as i32 - 6)
        };
        let mut reciprocal_would_differ = 0;
        for _ in 0..20_000 {
            let v = Vec3A::new(next(), next(), next());
            if v == Vec3A::ZERO {
                continue;
            }
            let u = unit_rounded(v);
            let len = ((v.x * v.x + v.y * v.y) + v.z * v.z).sqrt();
            let want = [v.x / len, v.y / len, v.z / len];
            assert_eq!(u.to_array().map(f32::to_bits), want.map(f32::to_bits));
            reciprocal_would_differ += (v.x * (1.0 / len) != u.x) as u32;
            #[cfg(target_arch = "x86_64")]
            assert_eq!(
                v.normalize().to_array().map(f32::to_bits),
                u.to_array().map(f32::to_bits)
            );
        }
        assert!(reciprocal_would_differ > 1000, "{reciprocal_would_differ}");
    }

    /// `fast_atan2` against `f64::atan2` over every quadrant, on a dense
    /// grid of angles and magnitudes from `1e-30` to `1e30`: within
    /// `3e-7` relative of the angle (the fit's own error in `f32` is
    /// `2.4e-7` on `[0, 1]`, the quadrant's subtraction adds up to half an
    /// ulp; measured 2.58e-7), and exactly `f32::atan2` on zeros and
    /// infinities (NaN for NaN).
    #[test]
    fn fast_atan2_matches_the_exact_angle() {
        let mut worst = 0.0f64;
        for k in 0..200_000 {
            let phi =
                -std::f64::consts::PI + 2.0 * std::f64::consts::PI * (k as f64 + 0.5) / 200_000.0;
            for m in [1e-30f64, 1e-3, 1.0, 7.5, 1e30] {
                let (x, y) = ((phi.cos() * m) as f32, (phi.sin() * m) as f32);
                let exact = (y as f64).atan2(x as f64);
                let err = (fast_atan2(y, x) as f64 - exact).abs() / exact.abs().max(1e-30);
                worst = worst.max(err);
            }
        }
        assert!(worst < 3e-7, "worst relative error {worst:e}");
        for (y, x) in [
            (0.0, 0.0),
            (-0.0, 0.0),
            (0.0, -0.0),
            (-0.0, -0.0),
            (1.0, f32::INFINITY),
            (f32::INFINITY, -1.0),
            (f32::NAN, 1.0),
        ] {
            let (a, b) = (fast_atan2(y, x), y.atan2(x));
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{y} {x}"
            );
        }
    }

    /// `fast_tan` against `f64::tan` of the same `f32` argument over
    /// `(-pi/2, pi/2)`, densest near the ends: within `7e-7` relative
    /// (measured 6.65e-7).
    #[test]
    fn fast_tan_matches_the_exact_tangent() {
        let mut worst = 0.0f64;
        let mut x = 1e-20f32;
        let mut check = |x: f32| {
            let exact = (x as f64).tan();
            let err = (fast_tan(x) as f64 - exact).abs() / exact.abs();
            worst = worst.max(err);
        };
        while x < std::f32::consts::FRAC_PI_2 {
            check(x);
            check(-x);
            // The grid's step is a few hundred ulps of x, and every one
            // of the last thousand floats below pi/2.
            x = if std::f32::consts::FRAC_PI_2 - x < 1e-4 {
                x.next_up()
            } else {
                x * (1.0 + 1e-5)
            };
        }
        assert!(worst < 7e-7, "worst relative error {worst:e}");
        assert!(fast_tan(f32::NAN).is_nan());
    }
}
