//! Sampling warps from uniform numbers to directions and points, and the
//! multiple-importance-sampling heuristic.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use crate::core::math::orthonormal_basis;

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
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, PI / 4.0 * (o.y / o.x))
    } else {
        (o.y, PI / 2.0 - PI / 4.0 * (o.x / o.y))
    };
    Vec2::new(r * theta.cos(), r * theta.sin())
}

/// Cosine-weighted direction around the unit normal `n`.
#[inline]
pub fn cosine_hemisphere(n: Vec3A, u: Vec2) -> Vec3A {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    let (t, b) = orthonormal_basis(n);
    (t * d.x + b * d.y + n * z).normalize()
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
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!(d.dot(n) >= -1e-6);
            sum += d.dot(n) as f64;
        }
        let mean = sum / count as f64;
        assert!(
            (mean - 2.0 / 3.0).abs() < 1.18 / (count as f64).sqrt(),
            "{mean}"
        );
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
