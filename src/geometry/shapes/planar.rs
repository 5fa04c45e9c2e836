//! The planar shapes: the plane `y = 0`, the disk and the convex polygon,
//! with the polygon's Newell normal and the checks of its vertices.

use glam::{Vec2, Vec3, Vec3A};

use super::ShapeHit;
use crate::core::math::{Ray, cross_rounded};

/// Newell normal of a polygon (unnormalised; length is twice the area).
pub fn polygon_normal(vertices: &[Vec3]) -> Vec3 {
    let mut n = Vec3::ZERO;
    for (i, a) in vertices.iter().enumerate() {
        let b = vertices[(i + 1) % vertices.len()];
        n += Vec3::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    n
}

pub(super) fn validate_polygon(vertices: &[Vec3]) -> Result<(), String> {
    if vertices.len() < 3 {
        return Err(format!(
            "polygon needs at least 3 vertices, got {}",
            vertices.len()
        ));
    }
    if vertices.iter().any(|v| !v.is_finite()) {
        return Err("polygon vertices must be finite".into());
    }
    // Tolerances scale with the polygon's own size, measured from its
    // centroid, not with its distance from the origin.
    let centroid = vertices.iter().copied().sum::<Vec3>() / vertices.len() as f32;
    let local: Vec<Vec3> = vertices.iter().map(|v| *v - centroid).collect();
    let size = local.iter().map(|v| v.length()).fold(0.0f32, f32::max);
    let n = polygon_normal(&local);
    if !(size > 0.0 && n.length() > 1e-6 * size * size) {
        return Err("polygon has zero area".into());
    }
    let n = n.normalize();
    if local.iter().any(|v| n.dot(*v).abs() > 1e-4 * size) {
        return Err("polygon vertices are not coplanar".into());
    }
    // Convex and simple: every turn is to the left, and the turns add up
    // to one full revolution (a star polygon turns left everywhere but
    // winds twice).
    let (u, w) = {
        let u = (local[0] - n * n.dot(local[0])).normalize_or(n.any_orthonormal_vector());
        (u, n.cross(u))
    };
    let mut turning = 0.0f32;
    let count = local.len();
    for i in 0..count {
        let a = local[i];
        let b = local[(i + 1) % count];
        let c = local[(i + 2) % count];
        let (e0, e1) = (b - a, c - b);
        if e0.cross(e1).dot(n) < -1e-6 * size * size {
            return Err("polygon is not convex (or its vertices are not in order)".into());
        }
        let angle = |e: Vec3| e.dot(w).atan2(e.dot(u));
        let mut turn = angle(e1) - angle(e0);
        if turn <= -std::f32::consts::PI {
            turn += 2.0 * std::f32::consts::PI;
        } else if turn > std::f32::consts::PI {
            turn -= 2.0 * std::f32::consts::PI;
        }
        turning += turn;
    }
    if (turning - 2.0 * std::f32::consts::PI).abs() > 1e-2 {
        return Err("polygon is not convex: its edges wind around more than once (a star?)".into());
    }
    Ok(())
}

/// Parameter of the crossing with `y = 0`, if inside `(t_min, t_max)`.
#[inline]
fn hit_y0(ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, Vec3A)> {
    if ray.direction.y == 0.0 {
        return None;
    }
    let t = -ray.origin.y / ray.direction.y;
    (t > t_min && t < t_max).then(|| (t, ray.at(t)))
}

/// The plane `y = 0`; normal `+Y`, `uv = (x, z)`.
pub(super) fn intersect_plane(ray: &Ray, t_min: f32, t_max: f32) -> Option<ShapeHit> {
    let (t, p) = hit_y0(ray, t_min, t_max)?;
    Some(ShapeHit {
        t,
        point: Vec3A::new(p.x, 0.0, p.z),
        normal: Vec3A::Y,
        uv: Vec2::new(p.x, p.z),
    })
}

/// The `t` of `intersect_plane(..)` under [`Shape::intersect`]'s filter
/// of non-finite hits (as [`occludes_plane`]), without building the hit.
#[inline(always)]
pub(super) fn plane_t(ray: &Ray, t_min: f32, t_max: f32) -> Option<f32> {
    hit_y0(ray, t_min, t_max)
        .filter(|(t, p)| t.is_finite() && p.x.is_finite() && p.z.is_finite())
        .map(|(t, _)| t)
}

/// `intersect_plane(..).is_some()` under [`Shape::intersect`]'s filter
/// of non-finite hits (`t`, point `(x, 0, z)`, `uv = (x, z)`), without
/// building the hit.
#[inline(always)]
pub(super) fn occludes_plane(ray: &Ray, t_min: f32, t_max: f32) -> bool {
    hit_y0(ray, t_min, t_max)
        .is_some_and(|(t, p)| t.is_finite() && p.x.is_finite() && p.z.is_finite())
}

/// `intersect_disk(..).is_some()` under [`Shape::intersect`]'s filter of
/// non-finite hits, without building the hit: the same expressions as
/// `intersect_disk`, `uv` included (it overflows for a tiny radius).
#[inline(always)]
pub(super) fn occludes_disk(ray: &Ray, r: f32, t_min: f32, t_max: f32) -> bool {
    let Some((t, p)) = hit_y0(ray, t_min, t_max) else {
        return false;
    };
    if p.x * p.x + p.z * p.z > r * r {
        return false;
    }
    t.is_finite()
        && p.x.is_finite()
        && p.z.is_finite()
        && (p.x / r * 0.5 + 0.5).is_finite()
        && (p.z / r * 0.5 + 0.5).is_finite()
}

/// Disk of radius `r` in `y = 0` (boundary included); normal `+Y`.
pub(super) fn intersect_disk(ray: &Ray, r: f32, t_min: f32, t_max: f32) -> Option<ShapeHit> {
    let (t, p) = hit_y0(ray, t_min, t_max)?;
    if p.x * p.x + p.z * p.z > r * r {
        return None;
    }
    Some(ShapeHit {
        t,
        point: Vec3A::new(p.x, 0.0, p.z),
        normal: Vec3A::Y,
        uv: Vec2::new(p.x / r * 0.5 + 0.5, p.z / r * 0.5 + 0.5),
    })
}

/// Convex polygon: the plane through the first vertex with the Newell
/// normal `n`, then the hit point must lie on the inner side of every edge
/// (`(b - a) x (p - a) · n >= 0`, boundary included).
#[inline]
pub(super) fn intersect_polygon(
    ray: &Ray,
    vertices: &[Vec3],
    t_min: f32,
    t_max: f32,
) -> Option<ShapeHit> {
    let n = Vec3A::from(polygon_normal(vertices));
    let denom = n.dot(ray.direction);
    if denom == 0.0 || !denom.is_finite() {
        return None;
    }
    let t = n.dot(Vec3A::from(vertices[0]) - ray.origin) / denom;
    if !(t > t_min && t < t_max) {
        return None;
    }
    let p = ray.at(t);
    for (i, a) in vertices.iter().enumerate() {
        let a = Vec3A::from(*a);
        let b = Vec3A::from(vertices[(i + 1) % vertices.len()]);
        // (`cross_rounded`: the batched polygons repeat this test lane by
        // lane, and glam's `cross` rounds differently on aarch64.)
        if cross_rounded(b - a, p - a).dot(n) < 0.0 {
            return None;
        }
    }
    Some(polygon_hit(
        t,
        p,
        n,
        Vec3A::from(vertices[0]),
        polygon_uv_axes(n),
    ))
}

/// The texture axes `(u, v)` of a polygon of Newell normal `n` (see
/// [`Shape::intersect`](super::Shape::intersect)): `u` the normalised
/// projection of `+X` onto the plane (`+Z` when `n` is nearly parallel
/// to `X`), `v = u x n`.
#[inline]
pub fn polygon_uv_axes(n: Vec3A) -> (Vec3A, Vec3A) {
    let n_unit = n.normalize();
    let reference = if n_unit.x.abs() < 0.9 {
        Vec3A::X
    } else {
        Vec3A::Z
    };
    let u_axis = (reference - n_unit * n_unit.dot(reference)).normalize();
    (u_axis, u_axis.cross(n_unit))
}

/// The hit of a ray on a polygon of Newell normal `n` and first vertex
/// `v0` at parameter `t`, where the ray reaches `p`, once the plane and
/// edge tests have accepted it; `axes` are [`polygon_uv_axes`] of `n`.
/// Shared by [`Shape::intersect`](super::Shape::intersect) and the
/// batched polygon test of the wavefront
/// ([`crate::scene::polygons`]), so the two build the same hit bit for
/// bit.
#[inline]
pub fn polygon_hit(t: f32, p: Vec3A, n: Vec3A, v0: Vec3A, axes: (Vec3A, Vec3A)) -> ShapeHit {
    let (u_axis, v_axis) = axes;
    ShapeHit {
        t,
        point: p - n * (n.dot(p - v0) / n.length_squared()),
        normal: n,
        uv: Vec2::new(p.dot(u_axis), p.dot(v_axis)),
    }
}
