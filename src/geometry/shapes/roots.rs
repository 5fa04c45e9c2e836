//! Root solvers for the quadrics: the quadratic formula in its stable
//! form, the roots of a sphere or cylinder from the line's distance to the
//! axis, and the Newton steps that bring a root back onto the surface.

use glam::Vec3A;

use crate::core::math::Ray;

/// Roots of `a t² + 2 half_b t + c = 0` in ascending order, given the
/// quarter discriminant `disc = half_b² - a c >= 0` and `a != 0`.
///
/// Uses `q = -(half_b + sign(half_b) sqrt(disc))`, `t = q / a` and
/// `t = c / q`: `half_b` and the square root are added with equal signs,
/// so neither root suffers cancellation. `q = 0` only when `half_b = 0`
/// and `disc = 0`, i.e. a double root at `0`.
#[inline]
fn quadratic_roots(a: f32, half_b: f32, c: f32, disc: f32) -> (f32, f32) {
    let q = -(half_b + disc.sqrt().copysign(half_b));
    if q == 0.0 {
        return (0.0, 0.0);
    }
    let (t0, t1) = (q / a, c / q);
    if t0 <= t1 { (t0, t1) } else { (t1, t0) }
}

/// Roots of `a t² + 2 half_b t + c = 0`; a vanishing `a` is solved as the
/// linear equation (returning its single root twice). `None` when there is
/// no real root (or the coefficients are not finite).
#[inline]
pub(super) fn solve_quadratic(a: f32, half_b: f32, c: f32) -> Option<(f32, f32)> {
    if a == 0.0 {
        if half_b == 0.0 {
            return None;
        }
        let t = -c / (2.0 * half_b);
        return Some((t, t));
    }
    let disc = half_b * half_b - a * c;
    // NaN comes from non-finite coefficients.
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    Some(quadratic_roots(a, half_b, c, disc))
}

/// Roots of `|o + t d|² = r²` (a sphere of radius `r` around the origin;
/// with the `y` components zeroed, an infinite cylinder around `Y`).
///
/// The discriminant is computed from the distance `|l|` of the centre to
/// the line, `l = o - (o·d / d·d) d`, as `d·d (r - |l|)(r + |l|)`, which
/// stays accurate when the origin is far away compared to `r` (the usual
/// `(o·d)² - (d·d)(o·o - r²)` cancels catastrophically there). `None` for
/// a zero direction.
#[inline]
pub(super) fn centered_roots(o: Vec3A, d: Vec3A, r: f32) -> Option<(f32, f32)> {
    let a = d.dot(d);
    if a.is_nan() || a <= 0.0 {
        return None;
    }
    let half_b = o.dot(d);
    let c = o.dot(o) - r * r;
    let dist = (o - d * (half_b / a)).length();
    let disc = a * ((r - dist) * (r + dist));
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    Some(quadratic_roots(a, half_b, c, disc))
}

/// The first of the ascending `roots` strictly inside `(t_min, t_max)`
/// whose hit point is accepted by `inside` (the shape's extent).
///
/// Each root is first refined by Newton steps on the implicit function
/// `f` (which returns the value and the gradient at a point). The
/// quadratic's coefficients are large when the ray starts far away, and
/// the rounding they carry puts the hit point off the surface by far more
/// than its own ulps (seen: 2.6e-4 on a cone 10 units from the camera);
/// `f` evaluated at the hit point itself involves only small numbers, so
/// two steps bring the point back to within a few ulps of the surface and
/// shadow and secondary rays leave from the right side.
#[inline]
pub(super) fn pick_root(
    roots: (f32, f32),
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    f: impl Fn(Vec3A) -> (f32, Vec3A),
    inside: impl Fn(Vec3A) -> bool,
) -> Option<(f32, Vec3A)> {
    let refine = |mut t: f32| {
        for _ in 0..2 {
            let (value, grad) = f(ray.at(t));
            let slope = grad.dot(ray.direction);
            let step = value / slope;
            // Only small corrections: a large step means a grazing ray or
            // a vanishing gradient, where the root is better left alone.
            if step.is_finite() && step.abs() <= 1e-3 * t.abs().max(1e-3) {
                t -= step;
            } else {
                break;
            }
        }
        t
    };
    [roots.0, roots.1]
        .into_iter()
        .map(refine)
        .filter(|&t| t > t_min && t < t_max)
        .map(|t| (t, ray.at(t)))
        .find(|&(_, p)| inside(p))
}

/// One Newton step from `p` onto the implicit surface `f = 0` along the
/// gradient (`f` returns the value and the gradient); `p` itself if the
/// step is not finite.
#[inline]
pub(super) fn project(p: Vec3A, f: &impl Fn(Vec3A) -> (f32, Vec3A)) -> Vec3A {
    let (value, grad) = f(p);
    let q = p - grad * (value / grad.length_squared());
    if q.is_finite() { q } else { p }
}
