//! The quadrics: sphere, ellipsoid, cylinder, cone, paraboloid and
//! hyperboloid, their texture coordinates, and the re-basing of rays that
//! start far away.

use std::f32::consts::{PI, TAU};

use glam::{Vec2, Vec3, Vec3A};

use super::ShapeHit;
use super::roots::{centered_roots, pick_root, project, solve_quadratic};
use crate::core::math::{Ray, fast_atan2};

/// Intersects with the ray re-based at its point closest to `(0, y, 0)`
/// (the middle of the shape), then shifts `t` back.
///
/// The cone, paraboloid and hyperboloid are solved from the raw quadratic
/// coefficients, which for a distant origin are large numbers that cancel:
/// from 4000 units away a hyperboloid's two roots 3 units apart merged
/// into one, and the "hit" was reported 1.4 units off the surface
/// (`tests/kernels/properties.rs`). From the closest point the coefficients
/// are of the size of the shape and the distance of the line, and only
/// the one rounding of the new origin (an ulp of the old one) remains.
#[inline]
pub(super) fn rebased(
    ray: &Ray,
    y: f32,
    t_min: f32,
    t_max: f32,
    hit: impl Fn(&Ray, f32, f32) -> Option<ShapeHit>,
) -> Option<ShapeHit> {
    let d = ray.direction;
    let t0 = (Vec3A::new(0.0, y, 0.0) - ray.origin).dot(d) / d.dot(d);
    if !t0.is_finite() {
        return hit(ray, t_min, t_max);
    }
    let near = Ray::new(ray.at(t0), d);
    let mut h = hit(&near, t_min - t0, t_max - t0)?;
    h.t += t0;
    (h.t > t_min && h.t < t_max).then_some(h)
}

/// Azimuth `atan2(z, x)` mapped to `[0, 1]`.
#[inline]
fn azimuth_u(p: Vec3A) -> f32 {
    let phi = fast_atan2(p.z, p.x);
    (if phi < 0.0 { phi + TAU } else { phi }) / TAU
}

/// `(phi / 2pi, theta / pi)` of the direction `p` (not necessarily unit),
/// `theta` measured from `+Y`.
#[inline]
fn spherical_uv(p: Vec3A) -> Vec2 {
    let cos_theta = (p.y / p.length()).clamp(-1.0, 1.0);
    Vec2::new(azimuth_u(p), cos_theta.acos() / PI)
}

/// Sphere of radius `r` at the origin; normal `p`.
pub(super) fn intersect_sphere(ray: &Ray, r: f32, t_min: f32, t_max: f32) -> Option<ShapeHit> {
    let roots = centered_roots(ray.origin, ray.direction, r)?;
    let f = |p: Vec3A| ((p.length() - r) * (p.length() + r), 2.0 * p);
    let (t, p) = pick_root(roots, ray, t_min, t_max, f, |_| true)?;
    Some(ShapeHit {
        t,
        point: p * (r / p.length()),
        normal: p,
        uv: spherical_uv(p),
    })
}

/// Ellipsoid with semi-axes `radii`: the unit sphere in coordinates scaled
/// by `1 / radii` (which leaves `t` unchanged); normal `p / radii²`.
pub(super) fn intersect_ellipsoid(
    ray: &Ray,
    radii: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<ShapeHit> {
    let radii = Vec3A::from(radii);
    let roots = centered_roots(ray.origin / radii, ray.direction / radii, 1.0)?;
    let f = |p: Vec3A| {
        let q = p / radii;
        ((q.length() - 1.0) * (q.length() + 1.0), 2.0 * q / radii)
    };
    let (t, p) = pick_root(roots, ray, t_min, t_max, f, |_| true)?;
    Some(ShapeHit {
        t,
        point: {
            let q = p / radii;
            radii * (q / q.length())
        },
        normal: p / (radii * radii),
        uv: spherical_uv(p / radii),
    })
}

/// Open cylinder `x² + z² = r²`, `y_min <= y <= y_max`; normal `(x, 0, z)`.
/// Rays parallel to the axis never hit the wall.
pub(super) fn intersect_cylinder(
    ray: &Ray,
    r: f32,
    y_min: f32,
    y_max: f32,
    t_min: f32,
    t_max: f32,
) -> Option<ShapeHit> {
    let flat = Vec3A::new(1.0, 0.0, 1.0);
    let roots = centered_roots(ray.origin * flat, ray.direction * flat, r)?;
    let f = |p: Vec3A| {
        let l = (p.x * p.x + p.z * p.z).sqrt();
        ((l - r) * (l + r), Vec3A::new(2.0 * p.x, 0.0, 2.0 * p.z))
    };
    let (t, p) = pick_root(roots, ray, t_min, t_max, f, |p| {
        p.y >= y_min && p.y <= y_max
    })?;
    Some(ShapeHit {
        t,
        point: {
            let l = (p.x * p.x + p.z * p.z).sqrt();
            Vec3A::new(p.x * (r / l), p.y, p.z * (r / l))
        },
        normal: Vec3A::new(p.x, 0.0, p.z),
        uv: Vec2::new(azimuth_u(p), (p.y - y_min) / (y_max - y_min)),
    })
}

/// Open cone `x² + z² = k² (h - y)²` with `k = r / h`, `0 <= y <= h`;
/// normal (half the gradient) `(x, k² (h - y), z)`, which vanishes at the
/// apex, where `+Y` is returned instead.
pub(super) fn intersect_cone(
    ray: &Ray,
    r: f32,
    h: f32,
    t_min: f32,
    t_max: f32,
) -> Option<ShapeHit> {
    let (o, d) = (ray.origin, ray.direction);
    let k = r / h;
    let k2 = k * k;
    // Distance below the apex, Y = h - y = y0 - t d.y.
    let y0 = h - o.y;
    let a = d.x * d.x + d.z * d.z - k2 * d.y * d.y;
    let half_b = o.x * d.x + o.z * d.z + k2 * y0 * d.y;
    let c = o.x * o.x + o.z * o.z - k2 * y0 * y0;
    let roots = solve_quadratic(a, half_b, c)?;
    let f = |p: Vec3A| {
        let l = (p.x * p.x + p.z * p.z).sqrt();
        let ry = k * (h - p.y);
        (
            (l - ry) * (l + ry),
            Vec3A::new(2.0 * p.x, 2.0 * k2 * (h - p.y), 2.0 * p.z),
        )
    };
    let (t, p) = pick_root(roots, ray, t_min, t_max, f, |p| p.y >= 0.0 && p.y <= h)?;
    let normal = Vec3A::new(p.x, k2 * (h - p.y), p.z);
    Some(ShapeHit {
        t,
        point: project(p, &f),
        normal: if normal == Vec3A::ZERO {
            Vec3A::Y
        } else {
            normal
        },
        uv: Vec2::new(azimuth_u(p), p.y / h),
    })
}

/// Paraboloid `k (x² + z²) - y = 0` with `k = h / r²`, `0 <= y <= h`;
/// normal (gradient) `(2 k x, -1, 2 k z)`. Rays parallel to the axis give
/// a linear equation.
pub(super) fn intersect_paraboloid(
    ray: &Ray,
    r: f32,
    h: f32,
    t_min: f32,
    t_max: f32,
) -> Option<ShapeHit> {
    let (o, d) = (ray.origin, ray.direction);
    let k = h / (r * r);
    let a = k * (d.x * d.x + d.z * d.z);
    let half_b = k * (o.x * d.x + o.z * d.z) - 0.5 * d.y;
    let c = k * (o.x * o.x + o.z * o.z) - o.y;
    let roots = solve_quadratic(a, half_b, c)?;
    let f = |p: Vec3A| {
        (
            k * (p.x * p.x + p.z * p.z) - p.y,
            Vec3A::new(2.0 * k * p.x, -1.0, 2.0 * k * p.z),
        )
    };
    let (t, p) = pick_root(roots, ray, t_min, t_max, f, |p| p.y >= 0.0 && p.y <= h)?;
    Some(ShapeHit {
        t,
        point: project(p, &f),
        normal: Vec3A::new(2.0 * k * p.x, -1.0, 2.0 * k * p.z),
        uv: Vec2::new(azimuth_u(p), p.y / h),
    })
}

/// Hyperboloid of one sheet `x² + z² - m y² - w² = 0` where `w` is the
/// waist radius and `m = (top² - w²) / half_height²` (so the radius is
/// `top` at `y = ±half_height`), `|y| <= half_height`; normal (half the
/// gradient) `(x, -m y, z)`.
pub(super) fn intersect_hyperboloid(
    ray: &Ray,
    w: f32,
    top: f32,
    half_height: f32,
    t_min: f32,
    t_max: f32,
) -> Option<ShapeHit> {
    let (o, d) = (ray.origin, ray.direction);
    let m = (top - w) * (top + w) / (half_height * half_height);
    let a = d.x * d.x + d.z * d.z - m * d.y * d.y;
    let half_b = o.x * d.x + o.z * d.z - m * o.y * d.y;
    let c = o.x * o.x + o.z * o.z - m * o.y * o.y - w * w;
    let roots = solve_quadratic(a, half_b, c)?;
    let f = |p: Vec3A| {
        (
            p.x * p.x + p.z * p.z - m * p.y * p.y - w * w,
            Vec3A::new(2.0 * p.x, -2.0 * m * p.y, 2.0 * p.z),
        )
    };
    let (t, p) = pick_root(roots, ray, t_min, t_max, f, |p| p.y.abs() <= half_height)?;
    Some(ShapeHit {
        t,
        point: project(p, &f),
        normal: Vec3A::new(p.x, -m * p.y, p.z),
        uv: Vec2::new(azimuth_u(p), (p.y + half_height) / (2.0 * half_height)),
    })
}
