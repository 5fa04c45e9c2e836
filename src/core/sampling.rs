//! Sampling warps from uniform numbers to directions and points, and the
//! multiple-importance-sampling heuristic.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use crate::core::math::{orthonormal_basis, sin_cos_octant};

/// Uniform direction on the unit sphere from two numbers in `[0, 1)`.
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3A {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3A::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform point on the unit disk (Shirley-Chiu concentric mapping), as
/// `(x, y)`.
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = u * 2.0 - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    // The angle within its octant, `phi` in [-pi/4, pi/4]: the point is
    // `r (cos phi, sin phi)` (x's octants) or `r (sin phi, cos phi)` (y's).
    if o.x.abs() > o.y.abs() {
        let (s, c) = sin_cos_octant(PI / 4.0 * (o.y / o.x));
        Vec2::new(o.x * c, o.x * s)
    } else {
        let (s, c) = sin_cos_octant(PI / 4.0 * (o.x / o.y));
        Vec2::new(o.y * s, o.y * c)
    }
}

/// Cosine-weighted direction around the unit normal `n`. Unit to within
/// a few ulps (`n`, its tangents and the disk point are): not normalised
/// again, which put a square root and a division on the path tracer's
/// critical path.
#[inline]
pub fn cosine_hemisphere(n: Vec3A, u: Vec2) -> Vec3A {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    let (t, b) = orthonormal_basis(n);
    t * d.x + b * d.y + n * z
}

/// The power heuristic (exponent 2) for `a` samples of density `pa`
/// against `b` samples of density `pb`.
#[inline]
pub fn power_heuristic(a: f32, pa: f32, b: f32, pb: f32) -> f32 {
    let (x, y) = (a * pa, b * pb);
    let (x2, y2) = (x * x, y * y);
    if x2 + y2 > 0.0 && (x2 + y2).is_finite() {
        x2 / (x2 + y2)
    } else if x > y {
        1.0
    } else {
        0.0
    }
}

/// The power heuristic's weight of `a` samples of density `pa` against
/// one of density `pb`, divided by `a pa`: the factor by which one of the
/// `a` samples' contributions is multiplied, `x / (x^2 + y^2)` with `x =
/// a pa`, `y = pb`. One division where the weight and then the division by
/// the density took two, one after the other, on next-event estimation's
/// critical path. Where `x^2 + y^2` is zero or overflows: `1 / x` when `x`
/// wins (the weight is then 1), else 0.
#[inline]
pub fn power_heuristic_over_density(a: f32, pa: f32, pb: f32) -> f32 {
    let x = a * pa;
    let d = x * x + pb * pb;
    if d > 0.0 && d.is_finite() {
        x / d
    } else if x > pb {
        1.0 / x
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    #[test]
    fn power_heuristic_sums_to_one() {
        for (pa, pb) in [(1.0, 1.0), (0.3, 2.0), (5.0, 0.0), (0.0, 0.1)] {
            let a = power_heuristic(2.0, pa, 1.0, pb);
            let b = power_heuristic(1.0, pb, 2.0, pa);
            assert!((a + b - 1.0).abs() < 1e-6, "{pa} {pb}: {a} + {b}");
        }
    }

    #[test]
    fn cosine_hemisphere_mean_cosine_is_two_thirds() {
        // E[cos] under p = cos/pi is 2/3; std of cos under it is
        // sqrt(1/2 - 4/9) = 0.236, so 5 sigma over n samples is 1.18/sqrt(n).
        let n = Vec3A::new(0.3, -0.5, 0.8).normalize();
        let count = 40_000;
        let mut sum = 0.0f64;
        for i in 0..count {
            let mut s = Sampler::new(3, i, 0);
            let d = cosine_hemisphere(n, Vec2::new(s.next_f32(), s.next_f32()));
            // Not normalised again: unit within a few ulps.
            assert!((d.length() - 1.0).abs() < 1e-6, "{}", d.length());
            assert!(d.dot(n) >= -1e-6);
            sum += d.dot(n) as f64;
        }
        let mean = sum / count as f64;
        assert!(
            (mean - 2.0 / 3.0).abs() < 1.18 / (count as f64).sqrt(),
            "{mean}"
        );
    }

    /// The weight over the density equals the power heuristic's weight
    /// divided by `a pa`, within a few roundings of either; at the limits
    /// (a zero or overflowing sum of squares) it is `1 / x` or 0 as the
    /// weight is 1 or 0.
    #[test]
    fn power_heuristic_over_density_is_the_weight_over_the_density() {
        for (a, pa, pb) in [
            (1.0, 1.0, 1.0),
            (1.0, 0.3, 2.0),
            (2.0, 5.0, 0.01),
            (1.0, 1e-3, 40.0),
            (4.0, 7.5e3, 2.0),
        ] {
            let want = power_heuristic(a, pa, 1.0, pb) / (a * pa);
            let got = power_heuristic_over_density(a, pa, pb);
            assert!(
                (got - want).abs() <= 4.0 * f32::EPSILON * want,
                "{a} {pa} {pb}: {got} against {want}"
            );
        }
        assert_eq!(power_heuristic_over_density(1.0, 0.0, 0.0), 0.0);
        assert_eq!(power_heuristic_over_density(1.0, 1e30, 1.0), 1e-30);
        assert_eq!(power_heuristic_over_density(1.0, 1.0, 1e30), 0.0);
    }

    /// The octant's sine and cosine within their Taylor polynomials'
    /// truncation (below 3.2e-7 and 2.5e-8 on `[-pi/4, pi/4]`) plus a few
    /// roundings of f32 (about 6e-8 each near 1): 4e-7 on a fine grid.
    #[test]
    fn octant_sine_and_cosine_are_within_their_bound() {
        let steps = 20_000;
        let mut worst = 0.0f64;
        for i in 0..=steps {
            let x = (-1.0 + 2.0 * i as f64 / steps as f64) * std::f64::consts::FRAC_PI_4;
            let (s, c) = sin_cos_octant(x as f32);
            let x = x as f32 as f64;
            worst = worst
                .max((s as f64 - x.sin()).abs())
                .max((c as f64 - x.cos()).abs());
        }
        assert!(worst < 4e-7, "{worst}");
    }

    #[test]
    fn uniform_sphere_and_disk_are_on_their_surfaces() {
        for i in 0..1000 {
            let mut s = Sampler::new(9, i, 0);
            let u = Vec2::new(s.next_f32(), s.next_f32());
            assert!((uniform_sphere(u).length() - 1.0).abs() < 1e-5);
            assert!(concentric_disk(u).length() <= 1.0 + 1e-6);
        }
    }
}
