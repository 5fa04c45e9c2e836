//! Property tests: the f32 intersection kernels against f64 evaluations of
//! the same formulas, on random rays and shapes, and `offset_origin`.
//!
//! Error bounds. A kernel's `t` is compared with the f64 root `t64` as
//!
//! ```text
//! |t32 - t64| <= K * EPS * (|t64| + |o| / |d| + size / |d|) / cos
//! ```
//!
//! where `EPS = f32::EPSILON`, `size` is the shape's extent and `cos` the
//! cosine between the ray and the surface normal at the f64 hit. The
//! reasoning: the f32 hit point is correct to a few roundings of the
//! coordinates involved (the origin, the hit point, the shape's size), and
//! a positional error `e` normal to the surface moves the hit by `e / cos`
//! along the ray, that is by `e / (cos |d|)` in `t`. `K = 64` leaves a wide
//! margin over the largest ratio seen (the tests do not print it; a
//! regression to an unstable formula exceeds it by orders of magnitude, as
//! the naive quadratic does for far origins).
//!
//! Excluded, by stated criteria, are the cases where f32 cannot decide the
//! answer: grazing rays (`cos < 0.05`), hits within `1e-3` (relative to the
//! shape's size) of the edge of a shape's extent or of a polygon's or
//! triangle's boundary, origins within `1e-3 * size` of the surface, and
//! near-double roots (two real roots, or a complex pair of a grazing ray,
//! closer than `1e-3 * size / |d|`), and misses by less than the kernel's
//! positional error `K * EPS * (|o| + size)` (the distance from the
//! surface of the line's extremum of `f`, to first order).
//! Everywhere else the f32 kernel must agree with f64 on *whether* it hits
//! and on *which* root.

use std::sync::Arc;

use glam::{DVec3, Quat, Vec3, Vec3A};
use prism::core::math::Ray;
use prism::core::optics::{OFFSET_ULPS, offset_origin, offset_origin_relative};
use prism::geometry::mesh::WatertightRay;
use prism::geometry::shapes::Shape;
use proptest::prelude::*;

const EPS: f64 = f32::EPSILON as f64;
const K: f64 = 64.0;
const MIN_COS: f64 = 0.05;
const MARGIN: f64 = 1e-3;

fn d64(v: Vec3A) -> DVec3 {
    Vec3::from(v).as_dvec3()
}

fn vec3(range: std::ops::Range<f32>) -> impl Strategy<Value = Vec3> {
    (range.clone(), range.clone(), range).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A direction (not unit: lengths from 1e-2 to 1e2, as object-space rays
/// of scaled instances have).
fn direction() -> impl Strategy<Value = Vec3> {
    (vec3(-1.0..1.0), -2.0f32..2.0)
        .prop_filter("non-zero", |(v, _)| v.length() > 1e-2)
        .prop_map(|(v, e)| v.normalize() * 10f32.powf(e))
}

/// An origin at distance 10^e from the shape, e in [-0.5, 3].
fn origin() -> impl Strategy<Value = Vec3> {
    (vec3(-1.0..1.0), -0.5f32..3.0)
        .prop_filter("non-zero", |(v, _)| v.length() > 1e-2)
        .prop_map(|(v, e)| v.normalize() * 10f32.powf(e))
}

/// f64 model of a shape: implicit function and gradient, and extent test.
struct Model {
    f: Box<dyn Fn(DVec3) -> f64>,
    grad: Box<dyn Fn(DVec3) -> DVec3>,
    /// Signed margin of a point inside the extent (negative outside), in
    /// the shape's length units.
    extent: Box<dyn Fn(DVec3) -> f64>,
    size: f64,
    centre: DVec3,
}

/// The quadric's roots for the ray in f64. The quadratic `f(o + t d)` is
/// recovered exactly from three samples, taken around the line's point
/// closest to the shape's centre and one shape size apart, so that the
/// samples are of the shape's own magnitude (sampled from a far origin they
/// would cancel even in f64).
fn roots(m: &Model, o: DVec3, d: DVec3) -> Vec<f64> {
    // The f32 kernel's positional error at this origin (the numerator of
    // `check`'s tolerance, times `|d|`).
    let position_error = K * EPS * (o.length() + m.size);
    let t0 = (m.centre - o).dot(d) / d.length_squared();
    let o = o + d * t0;
    let s = m.size / d.length();
    let (fm, f0, fp) = ((m.f)(o - d * s), (m.f)(o), (m.f)(o + d * s));
    // In the variable u = (t - t0) / s.
    let a = (fp + fm - 2.0 * f0) / 2.0;
    let b = (fp - fm) / 2.0;
    let c = f0;
    let us = if a.abs() <= 1e-12 * (b.abs() + c.abs()) {
        if b != 0.0 { vec![-c / b] } else { vec![] }
    } else {
        let disc = b * b - 4.0 * a * c;
        // A complex pair as close together as a near-double root (u is in
        // shape sizes) is a ray grazing the surface: its real part counted
        // twice, for the near-double-root exclusion to skip it. Likewise a
        // ray that misses the surface by less than the f32 kernel's
        // positional error: at the line's point nearest the surface (the
        // quadratic's extremum, where `f` is `-disc / 4a`), `|f| / |grad
        // f|` is its distance to first order. Far origins and thin shapes
        // make such a miss a wide complex pair (a miss by 1e-4 of a
        // 0.15-thick ellipsoid seen from 3,000 units away).
        if disc < 0.0 {
            let u = -b / (2.0 * a);
            let grazing = (-disc).sqrt() / a.abs() < MARGIN;
            let near_miss =
                || (-disc / (4.0 * a)).abs() / (m.grad)(o + d * (u * s)).length() < position_error;
            if grazing || near_miss() {
                return vec![t0 + u * s, t0 + u * s];
            }
            return vec![];
        }
        let q = -0.5 * (b + disc.sqrt().copysign(b));
        let mut r = vec![q / a, c / q];
        r.sort_by(|x, y| x.partial_cmp(y).unwrap());
        r
    };
    us.into_iter().map(|u| t0 + u * s).collect()
}

enum Expect {
    /// The test cannot decide (excluded case).
    Skip,
    Miss,
    Hit {
        t: f64,
        cos: f64,
    },
}

/// The f64 answer for a quadric, or `Skip` when the ray is in an excluded
/// case.
fn expect_quadric(m: &Model, o: DVec3, d: DVec3) -> Expect {
    let dl = d.length();
    // Refine each root with Newton steps in f64 (the coefficients above come
    // from differences of f, exact enough for a start).
    let rs: Vec<f64> = roots(m, o, d)
        .into_iter()
        .map(|mut t| {
            for _ in 0..3 {
                let p = o + d * t;
                let slope = (m.grad)(p).dot(d);
                if slope != 0.0 {
                    t -= (m.f)(p) / slope;
                }
            }
            t
        })
        .collect();
    if rs.len() == 2 && (rs[1] - rs[0]).abs() * dl < MARGIN * m.size {
        return Expect::Skip;
    }
    for &t in &rs {
        let p = o + d * t;
        if (t * dl).abs() < MARGIN * m.size {
            return Expect::Skip;
        }
        if t <= 0.0 {
            continue;
        }
        let e = (m.extent)(p);
        if e.abs() < MARGIN * m.size {
            return Expect::Skip;
        }
        if e < 0.0 {
            continue;
        }
        let cos = (m.grad)(p).normalize().dot(d / dl).abs();
        if cos < MIN_COS {
            return Expect::Skip;
        }
        return Expect::Hit { t, cos };
    }
    Expect::Miss
}

fn check(shape: &Shape, expect: Expect, ray: &Ray) -> Result<(), TestCaseError> {
    let got = shape.intersect(ray, 0.0, f32::INFINITY);
    let (o, d) = (d64(ray.origin), d64(ray.direction));
    let size = {
        let (lo, hi) = shape.bounds().unwrap_or((Vec3A::ZERO, Vec3A::ONE));
        d64(hi - lo).max_element()
    };
    match expect {
        Expect::Skip => {}
        Expect::Miss => prop_assert!(
            got.is_none(),
            "{shape:?} hit {got:?} where f64 misses, {ray:?}"
        ),
        Expect::Hit { t, cos } => {
            let h = got.ok_or_else(|| {
                TestCaseError::fail(format!("{shape:?} missed where f64 hits at {t}, {ray:?}"))
            })?;
            let tol = K * EPS * (t.abs() + (o.length() + size) / d.length()) / cos;
            prop_assert!(
                (h.t as f64 - t).abs() <= tol,
                "{shape:?}: t32 = {} vs t64 = {t} (tol {tol:e}, cos {cos}), {ray:?}",
                h.t
            );
            prop_assert!(h.normal.is_finite() && h.uv.is_finite());
        }
    }
    Ok(())
}

fn quadric_model(shape: &Shape) -> Model {
    match shape.clone() {
        Shape::Sphere { radius } => {
            let r = radius as f64;
            Model {
                f: Box::new(move |p| p.length_squared() - r * r),
                grad: Box::new(|p| 2.0 * p),
                extent: Box::new(|_| f64::INFINITY),
                size: r,
                centre: DVec3::ZERO,
            }
        }
        Shape::Ellipsoid { radii } => {
            let r = radii.as_dvec3();
            Model {
                f: Box::new(move |p| (p / r).length_squared() - 1.0),
                grad: Box::new(move |p| 2.0 * p / (r * r)),
                extent: Box::new(|_| f64::INFINITY),
                size: r.max_element(),
                centre: DVec3::ZERO,
            }
        }
        Shape::Cylinder {
            radius,
            y_min,
            y_max,
        } => {
            let (r, lo, hi) = (radius as f64, y_min as f64, y_max as f64);
            Model {
                f: Box::new(move |p| p.x * p.x + p.z * p.z - r * r),
                grad: Box::new(|p| DVec3::new(2.0 * p.x, 0.0, 2.0 * p.z)),
                extent: Box::new(move |p| (p.y - lo).min(hi - p.y)),
                size: r.max(hi - lo),
                centre: DVec3::new(0.0, 0.5 * (lo + hi), 0.0),
            }
        }
        Shape::Cone { radius, height } => {
            let (r, h) = (radius as f64, height as f64);
            let k2 = (r / h) * (r / h);
            Model {
                f: Box::new(move |p| p.x * p.x + p.z * p.z - k2 * (h - p.y) * (h - p.y)),
                grad: Box::new(move |p| DVec3::new(2.0 * p.x, 2.0 * k2 * (h - p.y), 2.0 * p.z)),
                extent: Box::new(move |p| p.y.min(h - p.y)),
                size: r.max(h),
                centre: DVec3::new(0.0, 0.5 * h, 0.0),
            }
        }
        Shape::Paraboloid { radius, height } => {
            let (r, h) = (radius as f64, height as f64);
            let k = h / (r * r);
            Model {
                f: Box::new(move |p| k * (p.x * p.x + p.z * p.z) - p.y),
                grad: Box::new(move |p| DVec3::new(2.0 * k * p.x, -1.0, 2.0 * k * p.z)),
                extent: Box::new(move |p| p.y.min(h - p.y)),
                size: r.max(h),
                centre: DVec3::new(0.0, 0.5 * h, 0.0),
            }
        }
        Shape::Hyperboloid {
            waist_radius,
            top_radius,
            half_height,
        } => {
            let (w, t, hh) = (waist_radius as f64, top_radius as f64, half_height as f64);
            let m = (t * t - w * w) / (hh * hh);
            Model {
                f: Box::new(move |p| p.x * p.x + p.z * p.z - m * p.y * p.y - w * w),
                grad: Box::new(move |p| DVec3::new(2.0 * p.x, -2.0 * m * p.y, 2.0 * p.z)),
                extent: Box::new(move |p| hh - p.y.abs()),
                size: t.max(2.0 * hh),
                centre: DVec3::ZERO,
            }
        }
        other => panic!("not a quadric: {other:?}"),
    }
}

/// Random quadrics with parameters spanning two orders of magnitude.
fn quadric() -> impl Strategy<Value = Shape> {
    let len = || (-1.0f32..1.0).prop_map(|e| 10f32.powf(e));
    prop_oneof![
        len().prop_map(|radius| Shape::Sphere { radius }),
        (len(), len(), len()).prop_map(|(a, b, c)| Shape::Ellipsoid {
            radii: Vec3::new(a, b, c)
        }),
        (len(), len(), -1.0f32..1.0).prop_map(|(radius, h, y0)| Shape::Cylinder {
            radius,
            y_min: y0,
            y_max: y0 + h,
        }),
        (len(), len()).prop_map(|(radius, height)| Shape::Cone { radius, height }),
        (len(), len()).prop_map(|(radius, height)| Shape::Paraboloid { radius, height }),
        (len(), 1.1f32..3.0, len()).prop_map(|(w, f, half_height)| Shape::Hyperboloid {
            waist_radius: w,
            top_radius: w * f,
            half_height,
        }),
    ]
}

/// One case of `quadrics_match_f64`: a ray from `from` (in shape sizes
/// from the centre) aimed at the point `aim` of the bounding box (in half
/// extents), direction of length `10^len`.
fn aimed_quadric_ray(shape: &Shape, from: Vec3, aim: Vec3, len: f32) -> Result<(), TestCaseError> {
    let (lo, hi) = shape.bounds().unwrap();
    let centre = (lo + hi) * 0.5;
    let half = (hi - lo) * 0.5;
    let size = (hi - lo).max_element();
    let target = centre + half * Vec3A::from(aim);
    let o = centre + Vec3A::from(from) * size;
    let d = (target - o).normalize() * 10f32.powf(len);
    let ray = Ray::new(o, d);
    let m = quadric_model(shape);
    check(shape, expect_quadric(&m, d64(o), d64(d)), &ray)
}

/// A case `quadrics_match_f64` once drew (CI, stop 57): a ray from about
/// 3,000 units away grazing a thin ellipsoid (cosine 0.003), which the f32
/// kernel hits and f64 misses by about 1e-4, less than the kernel's
/// positional error there. Excluded as a near miss; before that exclusion
/// the case failed.
#[test]
fn far_grazing_miss_of_a_thin_ellipsoid_is_excluded() {
    let shape = Shape::Ellipsoid {
        radii: Vec3::new(0.14836305, 1.3341385, 3.3253531),
    };
    let from = Vec3::new(252.9947, -395.1806, -53.262596);
    let aim = Vec3::new(-0.5162322, 1.0894126, 0.18055613);
    aimed_quadric_ray(&shape, from, aim, -0.08093561).unwrap();
}

proptest! {
    #![proptest_config(crate::common::prop::config(4000))]

    /// Rays aimed near the shape (at a random point of its bounding box)
    /// from near and far.
    #[test]
    fn quadrics_match_f64(shape in quadric(), from in origin(), aim in vec3(-1.2..1.2), len in -2.0f32..2.0) {
        aimed_quadric_ray(&shape, from, aim, len)?;
    }

    /// Arbitrary directions (most miss) from origins inside and outside.
    #[test]
    fn quadrics_match_f64_any_direction(shape in quadric(), o in vec3(-3.0..3.0), d in direction()) {
        let ray = Ray::new(o.into(), d.into());
        let m = quadric_model(&shape);
        check(&shape, expect_quadric(&m, o.as_dvec3(), d.as_dvec3()), &ray)?;
    }

    #[test]
    fn disk_matches_f64(radius in 0.1f32..10.0, from in origin(), aim in vec3(-1.5..1.5), len in -2.0f32..2.0) {
        let shape = Shape::Disk { radius };
        let target = Vec3A::new(aim.x * radius, 0.0, aim.z * radius);
        let o = Vec3A::from(from) * radius;
        let d = (target - o).normalize() * 10f32.powf(len);
        let ray = Ray::new(o, d);
        let (o64, d64v) = (d64(o), d64(d));
        let expect = if d64v.y == 0.0 {
            Expect::Skip
        } else {
            let t = -o64.y / d64v.y;
            let p = o64 + d64v * t;
            let r = (p.x * p.x + p.z * p.z).sqrt();
            let cos = (d64v.y / d64v.length()).abs();
            if cos < MIN_COS || (r - radius as f64).abs() < MARGIN * radius as f64 || (t * d64v.length()).abs() < MARGIN * radius as f64 {
                Expect::Skip
            } else if t > 0.0 && r < radius as f64 {
                Expect::Hit { t, cos }
            } else {
                Expect::Miss
            }
        };
        check(&shape, expect, &ray)?;
    }

    /// Regular polygons of 3 to 9 sides in a random plane.
    #[test]
    fn polygon_matches_f64(
        sides in 3usize..10,
        radius in 0.1f32..10.0,
        axis in vec3(-1.0..1.0),
        angle in 0.0f32..std::f32::consts::TAU,
        offset in vec3(-5.0..5.0),
        from in origin(),
        aim in vec3(-1.5..1.5),
    ) {
        prop_assume!(axis.length() > 0.1);
        let rot = Quat::from_axis_angle(axis.normalize(), angle);
        let vertices: Vec<Vec3> = (0..sides)
            .map(|i| {
                let a = std::f32::consts::TAU * i as f32 / sides as f32;
                offset + rot * Vec3::new(a.cos() * radius, 0.0, -a.sin() * radius)
            })
            .collect();
        let shape = Shape::Polygon { vertices: Arc::from(vertices.clone()) };
        prop_assume!(shape.validate().is_ok());
        let target = offset + rot * Vec3::new(aim.x * radius, 0.0, aim.z * radius);
        let o = offset + from * radius;
        let ray = Ray::new(o.into(), (target - o).into());
        let (o64, d64v) = (o.as_dvec3(), (target - o).as_dvec3());
        let v64: Vec<DVec3> = vertices.iter().map(|v| v.as_dvec3()).collect();
        let n = (v64[1] - v64[0]).cross(v64[2] - v64[0]).normalize();
        let t = n.dot(v64[0] - o64) / n.dot(d64v);
        let p = o64 + d64v * t;
        // Smallest signed distance to the edges (positive inside).
        let inside = (0..sides)
            .map(|i| {
                let (a, b) = (v64[i], v64[(i + 1) % sides]);
                n.cross(b - a).normalize().dot(p - a)
            })
            .fold(f64::INFINITY, f64::min);
        let cos = (n.dot(d64v) / d64v.length()).abs();
        let expect = if cos < MIN_COS
            || inside.abs() < MARGIN * radius as f64
            || (t * d64v.length()).abs() < MARGIN * radius as f64
        {
            Expect::Skip
        } else if t > 0.0 && inside > 0.0 {
            Expect::Hit { t, cos }
        } else {
            Expect::Miss
        };
        check(&shape, expect, &ray)?;
    }

    /// The watertight triangle test against f64 Moeller-Trumbore: `t` and
    /// the barycentrics.
    #[test]
    fn triangle_matches_f64(
        p0 in vec3(-1.0..1.0),
        p1 in vec3(-1.0..1.0),
        p2 in vec3(-1.0..1.0),
        scale in -3.0f32..3.0,
        shift in vec3(-1e3..1e3),
        from in origin(),
        aim in (-0.2f32..1.2, -0.2f32..1.2),
    ) {
        let s = 10f32.powf(scale);
        let [p0, p1, p2] = [p0, p1, p2].map(|p| shift + p * s);
        let (a, b, c) = (p0.as_dvec3(), p1.as_dvec3(), p2.as_dvec3());
        let n = (b - a).cross(c - a);
        let longest = (b - a).length().max((c - a).length()).max((c - b).length());
        // Not a sliver: area at least 5 % of the longest edge squared.
        prop_assume!(n.length() > 0.1 * longest * longest);
        let target = p0 + (p1 - p0) * aim.0 + (p2 - p0) * aim.1;
        let o = target + from * s;
        let d = target - o;
        let ray = Ray::new(o.into(), d.into());
        let got = WatertightRay::new(&ray).intersect(p0.into(), p1.into(), p2.into(), 0.0, f32::INFINITY);
        let (o64, d64v) = (o.as_dvec3(), d.as_dvec3());
        // Moeller-Trumbore in f64.
        let (e1, e2) = (b - a, c - a);
        let pv = d64v.cross(e2);
        let det = e1.dot(pv);
        let tv = o64 - a;
        let b1 = tv.dot(pv) / det;
        let qv = tv.cross(e1);
        let b2 = d64v.dot(qv) / det;
        let t = e2.dot(qv) / det;
        let cos = (n.normalize().dot(d64v.normalize())).abs();
        let margin = b1.min(b2).min(1.0 - b1 - b2);
        prop_assume!(cos >= MIN_COS && margin.abs() >= MARGIN && (t * d64v.length()).abs() >= MARGIN * longest);
        if t > 0.0 && margin > 0.0 {
            let (t32, u, v) = got.ok_or_else(|| TestCaseError::fail(format!("missed, f64 t = {t}")))?;
            let tol = K * EPS * (t.abs() + (o64.length() + a.length() + longest) / d64v.length()) / cos;
            prop_assert!((t32 as f64 - t).abs() <= tol, "t32 {t32} vs {t} (tol {tol:e})");
            // Barycentrics: the same positional error over the triangle's
            // size (`longest`), amplified by at most 1/(area/longest^2) <= 10.
            let btol = 10.0 * K * EPS * (o64.length() + a.length() + longest) / (longest * cos);
            prop_assert!((u as f64 - b1).abs() <= btol && (v as f64 - b2).abs() <= btol,
                "barycentrics ({u}, {v}) vs ({b1}, {b2}) (tol {btol:e})");
        } else {
            prop_assert!(got.is_none(), "hit {got:?} where f64 misses (t {t}, margin {margin})");
        }
    }

    /// `offset_origin` and `offset_origin_relative` always move the point
    /// to the requested side of the plane through it, by a bounded amount,
    /// at every magnitude from 1e-30 to 1e30 (loaders reject coordinates
    /// beyond 1e15) and for exact zeros of either sign.
    #[test]
    fn offset_origin_moves_to_the_requested_side(
        mant in vec3(-1.0..1.0),
        exp in (-30i32..30, -30i32..30, -30i32..30),
        zero in 0u8..8,
        n in vec3(-1.0..1.0),
    ) {
        prop_assume!(n.length() > 1e-3);
        let n = Vec3A::from(n.normalize());
        let mut p = Vec3A::new(
            mant.x * 10f32.powi(exp.0),
            mant.y * 10f32.powi(exp.1),
            mant.z * 10f32.powi(exp.2),
        );
        // Exact zeros (either sign) in some components.
        if zero & 1 != 0 { p.x = 0.0; }
        if zero & 2 != 0 { p.y = -0.0; }
        if zero & 4 != 0 { p.z = 0.0; }
        for side in [n, -n] {
            // Wachter-Binder: at most 256 ulps per coordinate, 2^-16 near 0.
            let q = offset_origin(p, side);
            prop_assert!(q.is_finite());
            let moved = (d64(q) - d64(p)).dot(d64(side));
            prop_assert!(moved > 0.0, "offset_origin({p}, {side}) = {q} is not on the requested side");
            let bound = (p.abs() * (512.0 * f32::EPSILON)).max(Vec3A::splat(1.0 / 32768.0));
            prop_assert!((q - p).abs().cmple(bound).all(), "offset {} too large for {p}", q - p);
            // Relative: OFFSET_ULPS ulps of the largest coordinate (plus the
            // rounding of the addition).
            let q = offset_origin_relative(p, side);
            prop_assert!(q.is_finite());
            let moved = (d64(q) - d64(p)).dot(d64(side));
            prop_assert!(moved > 0.0, "offset_origin_relative({p}, {side}) = {q} is not on the requested side");
            let m = p.abs().max_element().max(f32::MIN_POSITIVE);
            let bound = Vec3A::splat(2.0 * OFFSET_ULPS * f32::EPSILON * m);
            prop_assert!((q - p).abs().cmple(bound).all(), "relative offset {} too large for {p}", q - p);
        }
    }
}
