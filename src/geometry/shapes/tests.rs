//! Tolerances: f32 has `EPS = 2^-23 ≈ 1.19e-7`. For a well-conditioned
//! root (ray not grazing, origin not on the surface, inputs of
//! magnitude ~1) every coefficient carries a few ulps of rounding and
//! the stable root formula adds a couple more, so `t` is within ~10 EPS
//! of the exact root relative to its size. The hand-made cases below
//! use relative `REL = 1e-5` (~84 EPS): comfortably above that, far
//! below what any wrong root or formula produces (errors of order 1).
//! Where conditioning varies (random rays, far or tiny shapes) the
//! tolerance is derived per case and explained there. References are
//! computed in f64 from the f32 inputs, independently of the code under
//! test (the quadrics from the equations in the module docs).

use super::*;
use crate::geometry::transform::{InstanceTransform, Transform};
use glam::{DVec3, Quat};

const EPS: f64 = f32::EPSILON as f64;
const REL: f64 = 1e-5;
const INF: f32 = f32::INFINITY;

fn v(x: f32, y: f32, z: f32) -> Vec3A {
    Vec3A::new(x, y, z)
}

fn ray(o: Vec3A, d: Vec3A) -> Ray {
    Ray::new(o, d)
}

fn hit(shape: &Shape, r: &Ray) -> Option<ShapeHit> {
    shape.intersect(r, 0.0, INF)
}

#[track_caller]
fn must_hit(shape: &Shape, r: &Ray) -> ShapeHit {
    hit(shape, r).unwrap_or_else(|| panic!("expected a hit: {shape:?} {r:?}"))
}

#[track_caller]
fn assert_miss(shape: &Shape, r: &Ray) {
    let h = hit(shape, r);
    assert!(h.is_none(), "expected a miss: {shape:?} {r:?}, got {h:?}");
}

#[track_caller]
fn assert_close(actual: f64, expected: f64, tol: f64, what: &str) {
    assert!(
        (actual - expected).abs() <= tol,
        "{what}: got {actual}, expected {expected} (error {}, tolerance {tol})",
        (actual - expected).abs()
    );
}

/// `t` within relative `REL` of `expected` (which is of order 1 or
/// more in all uses, hence also an absolute floor of `REL`).
#[track_caller]
fn assert_t(h: &ShapeHit, expected: f64) {
    assert_close(h.t as f64, expected, REL * expected.abs().max(1.0), "t");
}

/// Angle between `a` and `b` (both non-zero) below ~`tol` radians, same
/// orientation.
#[track_caller]
fn assert_parallel(a: DVec3, b: DVec3, tol: f64, what: &str) {
    let (a, b) = (a.normalize(), b.normalize());
    assert!(
        a.dot(b) > 0.0 && a.cross(b).length() <= tol,
        "{what}: {a} and {b} are not parallel (sin angle {}, tolerance {tol})",
        a.cross(b).length()
    );
}

fn d(v: Vec3A) -> DVec3 {
    v.as_dvec3()
}

/// Real roots of `a t² + 2 hb t + c` in f64, ascending.
fn roots64(a: f64, hb: f64, c: f64) -> Vec<f64> {
    if a == 0.0 {
        return if hb == 0.0 {
            vec![]
        } else {
            vec![-c / (2.0 * hb)]
        };
    }
    let disc = hb * hb - a * c;
    if disc < 0.0 {
        return vec![];
    }
    let q = -(hb + disc.sqrt().copysign(hb));
    if q == 0.0 {
        return vec![0.0];
    }
    let mut r = vec![q / a, c / q];
    r.sort_by(f64::total_cmp);
    r
}

/// `f(p) = Σ q_i (p_i - s_i)² + l·p + k`, negative inside, gradient
/// outward: each quadric rewritten from the module documentation.
struct Quadric {
    q: DVec3,
    s: DVec3,
    l: DVec3,
    k: f64,
}

fn quadric(shape: &Shape) -> Quadric {
    let zero = DVec3::ZERO;
    let f = |x: f32| x as f64;
    match shape {
        Shape::Sphere { radius } => Quadric {
            q: DVec3::ONE,
            s: zero,
            l: zero,
            k: -f(*radius).powi(2),
        },
        Shape::Ellipsoid { radii } => Quadric {
            q: 1.0 / (radii.as_dvec3() * radii.as_dvec3()),
            s: zero,
            l: zero,
            k: -1.0,
        },
        Shape::Cylinder { radius, .. } => Quadric {
            q: DVec3::new(1.0, 0.0, 1.0),
            s: zero,
            l: zero,
            k: -f(*radius).powi(2),
        },
        // x² + z² - (r (1 - y/h))² = x² + z² - (r/h)² (y - h)²
        Shape::Cone { radius, height } => Quadric {
            q: DVec3::new(1.0, -(f(*radius) / f(*height)).powi(2), 1.0),
            s: DVec3::new(0.0, f(*height), 0.0),
            l: zero,
            k: 0.0,
        },
        // h (x² + z²) / r² - y
        Shape::Paraboloid { radius, height } => {
            let c = f(*height) / f(*radius).powi(2);
            Quadric {
                q: DVec3::new(c, 0.0, c),
                s: zero,
                l: DVec3::new(0.0, -1.0, 0.0),
                k: 0.0,
            }
        }
        // (x² + z²)/a² - y²/c² - 1 with c chosen so that the radius is
        // `top` at |y| = half_height: 1/c² = (top²/a² - 1) / hh².
        Shape::Hyperboloid {
            waist_radius,
            top_radius,
            half_height,
        } => {
            let a2 = f(*waist_radius).powi(2);
            let inv_c2 = (f(*top_radius).powi(2) / a2 - 1.0) / f(*half_height).powi(2);
            Quadric {
                q: DVec3::new(1.0 / a2, -inv_c2, 1.0 / a2),
                s: zero,
                l: zero,
                k: -1.0,
            }
        }
        _ => unreachable!("not a quadric: {shape:?}"),
    }
}

impl Quadric {
    fn eval(&self, p: DVec3) -> f64 {
        let r = p - self.s;
        (self.q * r * r).element_sum() + self.l.dot(p) + self.k
    }

    /// Central differences: exact for a quadratic up to rounding.
    fn grad(&self, p: DVec3) -> DVec3 {
        let h = 1e-3;
        let g = |e: DVec3| (self.eval(p + e * h) - self.eval(p - e * h)) / (2.0 * h);
        DVec3::new(g(DVec3::X), g(DVec3::Y), g(DVec3::Z))
    }

    /// Size of the gradient's terms, for rounding bounds.
    fn grad_scale(&self, p: DVec3) -> f64 {
        (2.0 * self.q.abs() * (p.abs() + self.s.abs()) + self.l.abs()).length()
    }

    /// `(a, half_b, c)` of `f(o + t d)`, from samples at `t = -1, 0, 1`.
    fn coeffs(&self, o: DVec3, d: DVec3) -> (f64, f64, f64) {
        let (m, z, p) = (self.eval(o - d), self.eval(o), self.eval(o + d));
        ((p + m) / 2.0 - z, (p - m) / 4.0, z)
    }

    /// Coefficients with every term taken in absolute value: the scale
    /// of the rounding errors of the f32 coefficients.
    fn abs_coeffs(&self, o: DVec3, d: DVec3) -> (f64, f64, f64) {
        let (q, r) = (self.q.abs(), o.abs() + self.s.abs());
        (
            (q * d * d).element_sum(),
            (q * r * d.abs()).element_sum() + self.l.dot(d).abs() / 2.0,
            (q * r * r).element_sum() + self.l.dot(o).abs() + self.k.abs(),
        )
    }
}

/// Signed distance inside the documented `y` extent (infinite for closed
/// shapes).
fn extent_margin(shape: &Shape, p: DVec3) -> f64 {
    let f = |x: f32| x as f64;
    match shape {
        Shape::Cylinder { y_min, y_max, .. } => (p.y - f(*y_min)).min(f(*y_max) - p.y),
        Shape::Cone { height, .. } | Shape::Paraboloid { height, .. } => p.y.min(f(*height) - p.y),
        Shape::Hyperboloid { half_height, .. } => f(*half_height) - p.y.abs(),
        _ => f64::INFINITY,
    }
}

/// Closest f64 hit on a quadric in `(t_min, t_max)`, clipped to its
/// extent.
fn reference_t(shape: &Shape, r: &Ray, t_min: f32, t_max: f32) -> Option<f64> {
    let (o, dir) = (d(r.origin), d(r.direction));
    let (a, hb, c) = quadric(shape).coeffs(o, dir);
    roots64(a, hb, c)
        .into_iter()
        .find(|&t| t > t_min as f64 && t < t_max as f64 && extent_margin(shape, o + dir * t) >= 0.0)
}

fn sphere() -> Shape {
    Shape::Sphere { radius: 1.0 }
}
fn ellipsoid() -> Shape {
    Shape::Ellipsoid {
        radii: Vec3::new(2.0, 1.0, 0.5),
    }
}
fn cylinder() -> Shape {
    Shape::Cylinder {
        radius: 1.0,
        y_min: -1.0,
        y_max: 2.0,
    }
}
fn cone() -> Shape {
    Shape::Cone {
        radius: 1.0,
        height: 2.0,
    }
}
fn paraboloid() -> Shape {
    Shape::Paraboloid {
        radius: 1.0,
        height: 1.5,
    }
}
fn hyperboloid() -> Shape {
    Shape::Hyperboloid {
        waist_radius: 1.0,
        top_radius: 2.0,
        half_height: 1.0,
    }
}
fn square() -> Shape {
    // Counter-clockwise seen from +Y: (b - a) x (c - b) = +Y.
    Shape::Polygon {
        vertices: Arc::from(vec![
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(-1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, -1.0),
        ]),
    }
}

/// A regular pentagon of circumradius 1.2 in a tilted plane.
struct Pentagon {
    center: DVec3,
    e1: DVec3,
    e2: DVec3,
    normal: DVec3,
    radius: f64,
    shape: Shape,
}

fn pentagon() -> Pentagon {
    let normal = DVec3::new(0.3, 1.0, 0.4).normalize();
    let e1 = normal.cross(DVec3::X).normalize();
    let e2 = normal.cross(e1);
    let (center, radius) = (DVec3::new(0.2, 0.1, -0.3), 1.2);
    // (e1, e2, normal) is right-handed, so increasing angles run
    // counter-clockwise seen from the normal side.
    let vertices: Vec<Vec3> = (0..5)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / 5.0;
            (center + (e1 * a.cos() + e2 * a.sin()) * radius).as_vec3()
        })
        .collect();
    Pentagon {
        center,
        e1,
        e2,
        normal,
        radius,
        shape: Shape::Polygon {
            vertices: Arc::from(vertices),
        },
    }
}

fn quadrics() -> Vec<Shape> {
    vec![
        sphere(),
        Shape::Sphere { radius: 1.3 },
        ellipsoid(),
        cylinder(),
        cone(),
        paraboloid(),
        hyperboloid(),
        // No unit parameters, so that a wrong power of one shows.
        Shape::Ellipsoid {
            radii: Vec3::new(0.7, 1.6, 1.1),
        },
        Shape::Cylinder {
            radius: 0.8,
            y_min: -0.5,
            y_max: 0.7,
        },
        Shape::Cone {
            radius: 1.3,
            height: 0.8,
        },
        Shape::Paraboloid {
            radius: 0.7,
            height: 1.2,
        },
        Shape::Hyperboloid {
            waist_radius: 0.7,
            top_radius: 1.5,
            half_height: 1.2,
        },
    ]
}

/// One ray per shape that hits it from outside at a generic angle.
fn sample_rays() -> Vec<(Shape, Ray)> {
    let aim = |o: Vec3A, target: Vec3A| ray(o, target - o);
    let pent = pentagon();
    vec![
        (sphere(), aim(v(-3.0, 0.5, -2.0), v(0.2, 0.1, 0.0))),
        (ellipsoid(), aim(v(-4.0, 1.5, -3.0), v(0.3, 0.2, 0.0))),
        (cylinder(), aim(v(-4.0, 0.3, -2.0), v(0.0, 0.6, 0.2))),
        (cone(), aim(v(-3.0, 0.5, -1.0), v(0.0, 0.8, 0.1))),
        (paraboloid(), aim(v(-3.0, 0.2, 1.0), v(0.0, 0.9, 0.0))),
        (hyperboloid(), aim(v(-4.0, -0.3, 1.0), v(0.0, 0.2, 0.0))),
        (Shape::Plane, ray(v(1.0, 3.0, 2.0), v(-0.3, -1.0, 0.2))),
        (
            Shape::Disk { radius: 1.5 },
            aim(v(0.3, 2.0, -0.4), v(0.2, 0.0, 0.3)),
        ),
        (square(), aim(v(-0.5, 2.5, 1.5), v(0.3, 0.0, -0.2))),
        (
            pent.shape.clone(),
            aim(
                (pent.center + pent.normal * 3.0 + pent.e1).as_vec3a(),
                (pent.center + pent.e2 * 0.2).as_vec3a(),
            ),
        ),
    ]
}

#[test]
fn sample_rays_hit_where_the_reference_says() {
    for (shape, r) in sample_rays() {
        let h = must_hit(&shape, &r);
        if matches!(
            shape,
            Shape::Plane | Shape::Disk { .. } | Shape::Polygon { .. }
        ) {
            continue;
        }
        assert_t(&h, reference_t(&shape, &r, 0.0, INF).unwrap());
    }
}

// ----- sphere -------------------------------------------------------

#[test]
fn sphere_hit_from_outside() {
    let s = sphere();
    // Closed form: z² = 1 - 0.25 at the hit, t = 5 - sqrt(0.75).
    let h = must_hit(&s, &ray(v(0.0, 0.5, -5.0), v(0.0, 0.0, 1.0)));
    assert_t(&h, 5.0 - 0.75f64.sqrt());
    assert_parallel(
        d(h.normal),
        DVec3::new(0.0, 0.5, -0.75f64.sqrt()),
        1e-6,
        "n",
    );
    assert!((h.normal.length() - 1.0).abs() < 1e-6, "sphere normal is p");
    // phi = atan2(z, x) = -pi/2 -> u = 3/4; theta = acos(0.5) -> v = 1/3.
    assert!((h.uv - Vec2::new(0.75, 1.0 / 3.0)).abs().max_element() < 1e-6);

    // Generic ray against the f64 closed form (-hb - sqrt(hb² - ac)) / a.
    let s = Shape::Sphere { radius: 1.5 };
    let r = ray(v(-3.0, 2.0, 4.0), v(1.1, -0.7, -1.3));
    let (o, dir) = (d(r.origin), d(r.direction));
    let (a, hb, c) = (dir.dot(dir), o.dot(dir), o.dot(o) - 2.25);
    let h = must_hit(&s, &r);
    assert_t(&h, (-hb - (hb * hb - a * c).sqrt()) / a);
    assert_parallel(d(h.normal), o + dir * h.t as f64, 1e-5, "n");
}

#[test]
fn sphere_hit_from_inside_returns_far_root() {
    let s = sphere();
    let r = ray(v(0.2, 0.1, -0.3), v(0.3, -0.5, 0.9));
    let (o, dir) = (d(r.origin), d(r.direction));
    let (a, hb, c) = (dir.dot(dir), o.dot(dir), o.dot(o) - 1.0);
    let h = must_hit(&s, &r);
    assert_t(&h, (-hb + (hb * hb - a * c).sqrt()) / a);
    // The normal still points outward (along the ray here), unflipped.
    assert!(h.normal.dot(r.direction) > 0.0);
    // From the centre: t = r / |d|.
    let h = must_hit(&s, &ray(Vec3A::ZERO, v(0.0, 0.0, -2.0)));
    assert_t(&h, 0.5);
    // uv of the bottom pole: theta = pi -> v = 1.
    let h = must_hit(&s, &ray(Vec3A::ZERO, v(0.0, -1.0, 0.0)));
    assert!((h.uv.y - 1.0).abs() < 1e-6);
}

#[test]
fn sphere_tangent_ray() {
    let s = sphere();
    // Exactly tangent (line at distance exactly r, all values exact in
    // f32): a hit at the tangent point t = 5, normal +Y.
    let h = must_hit(&s, &ray(v(-5.0, 1.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_eq!(h.t, 5.0);
    assert_parallel(d(h.normal), DVec3::Y, 1e-6, "n");
    // Offsets of a few ulps around 1: the distance to the line is exact
    // here, so exactly the offsets <= 1 hit, near t = 5 - sqrt(1 - y²).
    let mut y = 1.0f32;
    for _ in 0..20 {
        y = f32::from_bits(y.to_bits() - 1);
    }
    for _ in 0..40 {
        let r = ray(v(-5.0, y, 0.0), v(1.0, 0.0, 0.0));
        match hit(&s, &r) {
            Some(h) => {
                assert!(y <= 1.0, "hit at offset {y}");
                let expected = 5.0 - (1.0 - (y as f64).powi(2)).sqrt();
                assert_close(h.t as f64, expected, 4.0 * 5.0 * EPS, "grazing t");
                assert!(h.normal.is_finite() && h.uv.is_finite());
            }
            None => assert!(y > 1.0, "miss at offset {y}"),
        }
        y = f32::from_bits(y.to_bits() + 1);
    }
    // Oblique nearly-tangent rays: the line's distance D to the centre
    // is r only up to rounding, so only bound what can be: no NaN, and
    // any hit lies within the root spread of a discriminant perturbed
    // by a few ulps (of r² |d|²): |t - t_c| <= sqrt(r² - D² + 8 EPS r²)/|d|.
    let dir = DVec3::new(1.0, 0.3, -0.2);
    let perp = dir.cross(DVec3::new(0.1, 1.0, 0.7)).normalize();
    for k in -20..=20 {
        let dist = 1.0 + k as f64 * 1e-7;
        let r = ray((perp * dist - dir * 4.0).as_vec3a(), dir.as_vec3a());
        let (o, dd) = (d(r.origin), d(r.direction));
        let t_c = -o.dot(dd) / dd.dot(dd);
        let dist2 = (o + dd * t_c).length_squared();
        if let Some(h) = hit(&s, &r) {
            let spread = ((1.0 - dist2).max(0.0) + 8.0 * EPS).sqrt() / dd.length();
            assert_close(h.t as f64, t_c, spread + 1e-6, "oblique grazing t");
            assert!(h.normal.is_finite() && h.uv.is_finite());
        } else {
            assert!(
                dist2 > 1.0 - 8.0 * EPS,
                "missed at distance {}",
                dist2.sqrt()
            );
        }
    }
}

#[test]
fn sphere_misses() {
    let s = sphere();
    assert_miss(&s, &ray(v(-5.0, 1.01, 0.0), v(1.0, 0.0, 0.0)));
    // Pointing away: both roots negative.
    assert_miss(&s, &ray(v(0.0, 0.0, -5.0), v(0.0, 0.0, -1.0)));
    assert_miss(&s, &ray(v(3.0, 3.0, 3.0), v(1.0, 0.0, 1.0)));
    // Degenerate zero direction.
    assert_miss(&s, &ray(v(0.0, 0.0, -5.0), Vec3A::ZERO));
    assert_miss(&s, &ray(v(0.0, 0.0, 0.5), Vec3A::ZERO));
}

#[test]
fn interval_is_open_and_far_root_is_used() {
    let s = sphere();
    // Roots exactly 4 and 6 (every intermediate is exact in f32).
    let r = ray(v(0.0, 0.0, -5.0), v(0.0, 0.0, 1.0));
    let t = |t_min, t_max| s.intersect(&r, t_min, t_max).map(|h| h.t);
    assert_eq!(t(0.0, INF), Some(4.0));
    assert_eq!(t(4.0, INF), Some(6.0), "t_min is exclusive: far root");
    assert_eq!(t(4.5, INF), Some(6.0));
    assert_eq!(t(0.0, 4.0), None, "t_max is exclusive");
    assert_eq!(t(0.0, 4.5), Some(4.0));
    assert_eq!(t(4.0, 6.0), None);
    assert_eq!(t(6.0, INF), None);
    assert_eq!(t(-INF, INF), Some(4.0));
    // Behind the origin counts when the interval allows it.
    assert_eq!(
        s.intersect(&ray(v(0.0, 0.0, 5.0), v(0.0, 0.0, 1.0)), -INF, INF)
            .map(|h| h.t),
        Some(-6.0)
    );
    // Far root of a cylinder hit through its near wall, clipped by t_min.
    let c = cylinder();
    let r = ray(v(-5.0, 0.0, 0.0), v(1.0, 0.0, 0.0));
    assert_eq!(c.intersect(&r, 0.0, INF).map(|h| h.t), Some(4.0));
    assert_eq!(c.intersect(&r, 4.0, INF).map(|h| h.t), Some(6.0));
    assert_eq!(c.intersect(&r, 0.0, 3.9).map(|h| h.t), None);
}

#[test]
fn unnormalised_directions_scale_t() {
    let mut rays = sample_rays();
    rays.push((sphere(), ray(v(0.2, 0.1, -0.3), v(0.3, -0.5, 0.9))));
    rays.push((cylinder(), ray(v(0.5, 0.0, 0.0), v(1.0, 0.2, 0.0))));
    for (shape, r) in rays {
        let h = must_hit(&shape, &r);
        // Scaling by 3 rounds each component of d (relative EPS/2), a
        // perturbation the well-conditioned root follows: REL.
        let h3 = must_hit(&shape, &ray(r.origin, r.direction * 3.0));
        assert_close(h3.t as f64, h.t as f64 / 3.0, REL * h.t as f64, "t/3");
        assert_parallel(d(h3.normal), d(h.normal), 1e-5, "normal at t/3");
        // Power-of-two scaling is exact in every operation, so the
        // results must be bit-identical (t scaled by the inverse).
        for scale in [0.25f32, 4.0, 1024.0] {
            let hs = must_hit(&shape, &ray(r.origin, r.direction * scale));
            assert_eq!(hs.t, h.t / scale, "{shape:?} scale {scale}");
            assert_eq!(hs.uv, h.uv);
            assert_parallel(d(hs.normal), d(h.normal), 1e-6, "normal");
        }
    }
}

// ----- planar shapes --------------------------------------------------

#[test]
fn plane_hits_from_both_sides() {
    let p = Shape::Plane;
    let h = must_hit(&p, &ray(v(1.0, 2.0, 3.0), v(0.5, -4.0, 0.25)));
    assert_t(&h, 0.5);
    assert_eq!(h.normal, Vec3A::Y);
    assert_eq!(h.uv, Vec2::new(1.25, 3.125));
    // From below: normal still +Y (never flipped).
    let h = must_hit(&p, &ray(v(0.0, -3.0, 0.0), v(0.0, 2.0, 1.0)));
    assert_t(&h, 1.5);
    assert_eq!(h.normal, Vec3A::Y);
    assert_miss(&p, &ray(v(0.0, 1.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_miss(&p, &ray(v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_miss(&p, &ray(v(0.0, 1.0, 0.0), v(0.0, 1.0, 0.0)));
    assert!(
        p.intersect(&ray(v(0.0, 1.0, 0.0), v(0.0, -1.0, 0.0)), 0.0, 1.0)
            .is_none()
    );
}

#[test]
fn disk_inside_outside_and_uv() {
    let disk = Shape::Disk { radius: 2.0 };
    let h = must_hit(&disk, &ray(v(1.0, 1.0, -1.0), v(0.0, -0.5, 0.0)));
    assert_t(&h, 2.0);
    assert_eq!(h.normal, Vec3A::Y);
    assert!((h.uv - Vec2::new(0.75, 0.25)).abs().max_element() < 1e-6);
    // Just inside and outside the rim (relative 1e-5, i.e. ~80 ulps,
    // well beyond the rounding of x² + z²).
    let rim = |r: f32| ray(v(r * 0.6, 1.0, r * 0.8), v(0.0, -1.0, 0.0));
    assert!(hit(&disk, &rim(2.0 * (1.0 - 1e-5))).is_some());
    assert!(hit(&disk, &rim(2.0 * (1.0 + 1e-5))).is_none());
    // Exactly on the rim counts (boundary included).
    assert!(hit(&disk, &ray(v(2.0, 1.0, 0.0), v(0.0, -1.0, 0.0))).is_some());
    assert_miss(&disk, &ray(v(0.0, 1.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_miss(&disk, &ray(v(0.0, 1.0, 0.0), v(0.0, 1.0, 0.0)));
}

#[test]
fn polygon_square_inside_outside_edges() {
    let sq = square();
    let down = |x: f32, z: f32| ray(v(x, 2.0, z), v(0.0, -1.0, 0.0));
    let h = must_hit(&sq, &down(0.3, -0.4));
    assert_t(&h, 2.0);
    // Newell normal: +Y, length twice the area.
    assert_eq!(h.normal, v(0.0, 8.0, 0.0));
    assert!((h.uv - Vec2::new(0.3, -0.4)).abs().max_element() < 1e-6);
    // From below: same normal, unflipped.
    let h = must_hit(&sq, &ray(v(0.3, -2.0, 0.4), v(0.0, 4.0, 0.0)));
    assert_t(&h, 0.5);
    assert!(h.normal.y > 0.0);
    for (x, z) in [(1.5, 0.0), (0.0, -1.5), (1.1, 1.1), (-3.0, 0.2)] {
        assert_miss(&sq, &down(x, z));
    }
    // Near each edge: inside by 1e-6 hits, outside by 1e-6 misses.
    for (x, z) in [(1.0, 0.3), (-1.0, 0.3), (0.3, 1.0), (0.3, -1.0)] {
        assert!(hit(&sq, &down(x * (1.0 - 1e-6), z * (1.0 - 1e-6))).is_some());
        assert!(hit(&sq, &down(x * (1.0 + 1e-6), z * (1.0 + 1e-6))).is_none());
        // Exactly on an edge (all exact in f32): boundary included.
        assert!(hit(&sq, &down(x, z)).is_some(), "edge point ({x}, {z})");
    }
    assert!(hit(&sq, &down(1.0, 1.0)).is_some(), "corner");
    // In the plane but parallel to it.
    assert_miss(&sq, &ray(v(-5.0, 0.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_miss(&sq, &ray(v(-5.0, 1.0, 0.0), v(1.0, 0.0, 0.0)));
}

#[test]
fn polygon_pentagon_inside_outside_edges() {
    let pent = pentagon();
    let shape = &pent.shape;
    // Ray from `origin_offset` (off the plane) to an in-plane point.
    let towards = |target: DVec3| {
        let o = target + pent.normal * 2.0 + pent.e1 * 0.7 - pent.e2 * 0.4;
        ray(o.as_vec3a(), (target - o).as_vec3a())
    };
    let h = must_hit(shape, &towards(pent.center));
    // The target is at t = 1 by construction.
    assert_t(&h, 1.0);
    assert_parallel(d(h.normal), pent.normal, 1e-6, "Newell normal");
    // The polygon uv is an isometry of its plane.
    let p2 = pent.center + pent.e1 * 0.3 - pent.e2 * 0.5;
    let h2 = must_hit(shape, &towards(p2));
    assert_close(
        (h2.uv - h.uv).length() as f64,
        (0.3f64.powi(2) + 0.5f64.powi(2)).sqrt(),
        1e-6,
        "uv distance",
    );
    // Edge between vertices 0 and 1: its midpoint is at the apothem in
    // direction 36 degrees. Relative 1e-4 is ~800 ulps of the
    // coordinates, far above rounding.
    let apothem = pent.radius * (std::f64::consts::PI / 5.0).cos();
    let ang = 36f64.to_radians();
    let dir = pent.e1 * ang.cos() + pent.e2 * ang.sin();
    let at = |r: f64| pent.center + dir * r;
    assert!(hit(shape, &towards(at(apothem * (1.0 - 1e-4)))).is_some());
    assert!(hit(shape, &towards(at(apothem * (1.0 + 1e-4)))).is_none());
    // Inside the circumcircle but outside the pentagon.
    assert!(hit(shape, &towards(at(0.95 * pent.radius))).is_none());
    // Beyond a vertex, and far away.
    assert!(hit(shape, &towards(pent.center + pent.e1 * pent.radius * 1.001)).is_none());
    assert!(hit(shape, &towards(pent.center + pent.e2 * 5.0)).is_none());
    // Near a vertex, inside.
    assert!(hit(shape, &towards(pent.center + pent.e1 * pent.radius * 0.999)).is_some());
    // Parallel to the plane.
    let o = pent.center + pent.normal * 0.5;
    assert_miss(shape, &ray(o.as_vec3a(), pent.e1.as_vec3a()));
}

#[test]
fn polygon_validate_rejects_bad_input() {
    let poly = |vs: &[[f32; 3]]| Shape::Polygon {
        vertices: vs.iter().map(|&a| Vec3::from(a)).collect(),
    };
    assert!(square().validate().is_ok());
    assert!(pentagon().shape.validate().is_ok());
    let bad = [
        ("empty", poly(&[])),
        ("one", poly(&[[0.0; 3]])),
        ("two", poly(&[[0.0; 3], [1.0, 0.0, 0.0]])),
        (
            "collinear",
            poly(&[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]),
        ),
        ("repeated", poly(&[[0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]])),
        (
            "non-planar",
            poly(&[
                [-1.0, 0.0, -1.0],
                [-1.0, 0.0, 1.0],
                [1.0, 0.3, 1.0],
                [1.0, 0.0, -1.0],
            ]),
        ),
        (
            "non-convex dart",
            poly(&[
                [-1.0, 0.0, -1.0],
                [0.0, 0.0, -0.2],
                [1.0, 0.0, -1.0],
                [0.0, 0.0, 1.0],
            ]),
        ),
        (
            "pentagram (turns left everywhere, winds twice)",
            poly(
                &(0..5)
                    .map(|k| {
                        let a = (2 * k % 5) as f32 * 2.0 * std::f32::consts::PI / 5.0;
                        [a.cos(), 0.0, -a.sin()]
                    })
                    .collect::<Vec<_>>(),
            ),
        ),
        (
            "NaN",
            poly(&[[0.0; 3], [0.0, 0.0, 1.0], [f32::NAN, 0.0, 0.0]]),
        ),
        (
            "infinite",
            poly(&[[0.0; 3], [0.0, 0.0, 1.0], [f32::INFINITY, 0.0, 0.0]]),
        ),
    ];
    // Far from the origin, a unit square is as valid as near it.
    for offset in [1e3f32, 1e4, 1e6] {
        let far = poly(&[
            [offset, 0.0, 0.0],
            [offset, 0.0, 1.0],
            [offset + 1.0, 0.0, 1.0],
            [offset + 1.0, 0.0, 0.0],
        ]);
        assert!(far.validate().is_ok(), "unit square at x = {offset}");
    }
    for (what, shape) in bad {
        assert!(shape.validate().is_err(), "{what} accepted");
        // Invalid polygons must not panic or produce NaN either.
        let h = shape.intersect(&ray(v(0.1, 1.0, 0.1), v(0.0, -1.0, 0.0)), 0.0, INF);
        assert!(h.is_none_or(|h| h.t.is_finite() && h.normal.is_finite()));
    }
}

#[test]
fn validate_rejects_bad_parameters() {
    let ok = [
        sphere(),
        Shape::Plane,
        Shape::Disk { radius: 1.0 },
        ellipsoid(),
        cylinder(),
        cone(),
        paraboloid(),
        hyperboloid(),
    ];
    for s in &ok {
        assert!(s.validate().is_ok(), "{s:?}");
    }
    for b in [f32::NAN, 0.0, -0.0, -1.0, f32::INFINITY, f32::NEG_INFINITY] {
        let cases = [
            ("radius", Shape::Sphere { radius: b }),
            ("radius", Shape::Disk { radius: b }),
            (
                "radius",
                Shape::Cylinder {
                    radius: b,
                    y_min: -1.0,
                    y_max: 1.0,
                },
            ),
            (
                "radius",
                Shape::Cone {
                    radius: b,
                    height: 1.0,
                },
            ),
            (
                "height",
                Shape::Cone {
                    radius: 1.0,
                    height: b,
                },
            ),
            (
                "radius",
                Shape::Paraboloid {
                    radius: b,
                    height: 1.0,
                },
            ),
            (
                "height",
                Shape::Paraboloid {
                    radius: 1.0,
                    height: b,
                },
            ),
            (
                "radii.x",
                Shape::Ellipsoid {
                    radii: Vec3::new(b, 1.0, 1.0),
                },
            ),
            (
                "radii.y",
                Shape::Ellipsoid {
                    radii: Vec3::new(1.0, b, 1.0),
                },
            ),
            (
                "radii.z",
                Shape::Ellipsoid {
                    radii: Vec3::new(1.0, 1.0, b),
                },
            ),
            (
                "waist_radius",
                Shape::Hyperboloid {
                    waist_radius: b,
                    top_radius: 2.0,
                    half_height: 1.0,
                },
            ),
            (
                "top_radius",
                Shape::Hyperboloid {
                    waist_radius: 1.0,
                    top_radius: b,
                    half_height: 1.0,
                },
            ),
            (
                "half_height",
                Shape::Hyperboloid {
                    waist_radius: 1.0,
                    top_radius: 2.0,
                    half_height: b,
                },
            ),
        ];
        for (name, s) in cases {
            let err = s.validate().expect_err(&format!("{s:?} accepted"));
            assert!(
                err.contains(name),
                "{s:?}: error {err:?} should name {name}"
            );
        }
    }
    let cyl = |y_min, y_max| Shape::Cylinder {
        radius: 1.0,
        y_min,
        y_max,
    };
    for (lo, hi) in [
        (1.0, 1.0),
        (2.0, 1.0),
        (f32::NAN, 1.0),
        (0.0, f32::NAN),
        (f32::NEG_INFINITY, 1.0),
        (0.0, f32::INFINITY),
    ] {
        assert!(cyl(lo, hi).validate().is_err(), "cylinder {lo}..{hi}");
    }
    let hyp = |w, t| Shape::Hyperboloid {
        waist_radius: w,
        top_radius: t,
        half_height: 1.0,
    };
    assert!(hyp(1.0, 1.0).validate().is_err());
    assert!(hyp(2.0, 1.0).validate().is_err());
}

// ----- quadrics -----------------------------------------------------

#[test]
fn cylinder_outside_inside_open_end_and_parallel() {
    let c = cylinder(); // r = 1, -1 <= y <= 2
    let h = must_hit(&c, &ray(v(-5.0, 0.5, 0.0), v(1.0, 0.0, 0.0)));
    assert_t(&h, 4.0);
    assert_parallel(d(h.normal), -DVec3::X, 1e-6, "n");
    assert_eq!(h.normal.y, 0.0);
    // phi = pi -> u = 1/2; v = (0.5 + 1) / 3.
    assert!((h.uv - Vec2::new(0.5, 0.5)).abs().max_element() < 1e-6);
    // Inside: far root (the near one, -1.5, is behind).
    let h = must_hit(&c, &ray(v(0.5, 0.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_t(&h, 0.5);
    assert_parallel(d(h.normal), DVec3::X, 1e-6, "n");
    // Generic ray from inside, f64 closed form in the xz plane.
    let r = ray(v(0.2, 0.3, -0.4), v(0.7, 0.1, 0.5));
    let (o, dir) = (d(r.origin), d(r.direction));
    let a = dir.x * dir.x + dir.z * dir.z;
    let hb = o.x * dir.x + o.z * dir.z;
    let cc = o.x * o.x + o.z * o.z - 1.0;
    assert_t(&must_hit(&c, &r), (-hb + (hb * hb - a * cc).sqrt()) / a);
    // Through the open top: the near root (x = -1 at t = 1, y = 3) is
    // above the extent, so the inside of the far wall is hit (x = 1 at
    // t = 3, y = 1), with the outward normal +X.
    let h = must_hit(&c, &ray(v(-2.0, 4.0, 0.0), v(1.0, -1.0, 0.0)));
    assert_t(&h, 3.0);
    assert_parallel(d(h.normal), DVec3::X, 1e-6, "n");
    assert!((h.uv.y - 2.0 / 3.0).abs() < 1e-6);
    // In through the top, out through the bottom without touching.
    assert_miss(&c, &ray(v(0.2, 5.0, 0.0), v(0.01, -1.0, 0.0)));
    // Parallel to the axis (a = 0): inside, outside, on the surface.
    assert_miss(&c, &ray(v(0.5, 5.0, 0.0), v(0.0, -1.0, 0.0)));
    assert_miss(&c, &ray(v(1.5, 5.0, 0.0), v(0.0, -1.0, 0.0)));
    assert_miss(&c, &ray(v(1.0, 5.0, 0.0), v(0.0, -1.0, 0.0)));
    // Above and beside the extent.
    assert_miss(&c, &ray(v(-5.0, 3.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_miss(&c, &ray(v(-5.0, 0.0, 1.5), v(1.0, 0.0, 0.0)));
}

#[test]
fn cone_known_hits_and_apex() {
    let c = cone(); // r = 1, h = 2, radius 1 - y/2
    // At y = 1 the radius is 0.5.
    let h = must_hit(&c, &ray(v(-5.0, 1.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_t(&h, 4.5);
    // Outward normal: (x, (r/h)² (h - y), z) = (-0.5, 0.25, 0).
    assert_parallel(d(h.normal), DVec3::new(-0.5, 0.25, 0.0), 1e-6, "n");
    assert!((h.uv.y - 0.5).abs() < 1e-6);
    // Above the apex the unclipped double cone is hit (radius 0.25 at
    // y = 2.5) but not the documented extent.
    let above = ray(v(-5.0, 2.5, 0.0), v(1.0, 0.0, 0.0));
    let (a, hb, cc) = quadric(&c).coeffs(d(above.origin), d(above.direction));
    assert_eq!(roots64(a, hb, cc).len(), 2, "upper nappe is on the ray");
    assert_miss(&c, &above);
    // Below the base.
    assert_miss(&c, &ray(v(-5.0, -0.5, 0.0), v(1.0, 0.0, 0.0)));
    // In through the open base, hitting the inside: 0.2 t = 0.5 (3 - t)
    // -> t = 1.5 / 0.7; the other root (t = 5, y = 4) is on the upper
    // nappe.
    let h = must_hit(&c, &ray(v(0.0, -1.0, 0.0), v(0.2, 1.0, 0.0)));
    assert_t(&h, 1.5 / 0.7);
    assert!(h.normal.x > 0.0 && h.normal.y > 0.0, "outward, unflipped");
    // Parallel to a generator (a = 0, linear case): one root, t = 0.75.
    let h = must_hit(&c, &ray(v(-1.0, 1.5, 0.0), v(0.5, -1.0, 0.0)));
    assert_t(&h, 0.75);
    // Straight down the axis hits the apex (double root t = 3), where
    // the gradient vanishes: a finite +Y normal is returned.
    let h = must_hit(&c, &ray(v(0.0, 5.0, 0.0), v(0.0, -1.0, 0.0)));
    assert_t(&h, 3.0);
    assert_eq!(h.normal, Vec3A::Y);
    // Straight up the axis from below enters through the open base and
    // reaches the apex from inside.
    assert_t(
        &must_hit(&c, &ray(v(0.0, -1.0, 0.0), v(0.0, 1.0, 0.0))),
        3.0,
    );
}

/// Rays almost parallel to a cone's generator or a paraboloid's axis:
/// `a` is tiny, `|a c| << half_b²`, and the textbook
/// `(-half_b ± sqrt(half_b² - a c)) / a` cancels to noise divided by a
/// tiny `a` (errors of order 1), while `c / q` stays well-conditioned
/// (REL).
#[test]
fn nearly_linear_quadratics_are_accurate() {
    let cases = [
        // Cone generator slope 0.5: a = (0.5 + delta)² - 0.25.
        (cone(), ray(v(-1.0, 1.5, 0.0), v(0.5 + 1e-5, -1.0, 0.0))),
        (cone(), ray(v(-1.0, 1.5, 0.0), v(0.5 - 3e-6, -1.0, 1e-6))),
        (paraboloid(), ray(v(0.3, 5.0, 0.4), v(1e-5, -1.0, -2e-5))),
        // Hyperboloid asymptote slope sqrt(3): t = 5 / (6 (sqrt 3 - 1)).
        (
            hyperboloid(),
            ray(v(-3.0, -1.0, 0.0), v(3f32.sqrt() + 1e-5, 1.0, 0.0)),
        ),
    ];
    for (shape, r) in cases {
        let expected = reference_t(&shape, &r, 0.0, INF).unwrap();
        assert_t(&must_hit(&shape, &r), expected);
    }
}

#[test]
fn ellipsoid_outside_inside() {
    let e = ellipsoid(); // radii (2, 1, 0.5)
    let h = must_hit(&e, &ray(v(-5.0, 0.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_t(&h, 3.0);
    assert_parallel(d(h.normal), -DVec3::X, 1e-6, "n");
    let h = must_hit(&e, &ray(v(0.0, 3.0, 0.0), v(0.0, -1.0, 0.0)));
    assert_t(&h, 2.0);
    assert!(h.uv.y.abs() < 1e-6, "top pole has v = 0");
    let h = must_hit(&e, &ray(v(0.0, 0.0, 4.0), v(0.0, 0.0, -2.0)));
    assert_t(&h, 1.75);
    // Generic rays against the closed form in scaled coordinates.
    for (o, dir) in [
        (v(-3.0, 1.5, 2.0), v(1.0, -0.4, -0.6)),
        (v(0.5, 0.2, 0.1), v(0.3, 0.4, -0.5)),
    ] {
        let radii = DVec3::new(2.0, 1.0, 0.5);
        let (os, ds) = (d(o) / radii, d(dir) / radii);
        let (a, hb, c) = (ds.dot(ds), os.dot(ds), os.dot(os) - 1.0);
        let sq = (hb * hb - a * c).sqrt();
        // Near root from outside (c > 0), far root from inside.
        let expected = if c > 0.0 {
            (-hb - sq) / a
        } else {
            (-hb + sq) / a
        };
        assert_t(&must_hit(&e, &ray(o, dir)), expected);
    }
    assert_miss(&e, &ray(v(-5.0, 0.0, 0.6), v(1.0, 0.0, 0.0)));
}

#[test]
fn paraboloid_known_hits() {
    let p = paraboloid(); // y = 1.5 (x² + z²), 0 <= y <= 1.5
    // At y = 0.375, x² + z² = 0.25.
    let h = must_hit(&p, &ray(v(-2.0, 0.375, 0.0), v(1.0, 0.0, 0.0)));
    assert_t(&h, 1.5);
    // Gradient of 1.5 (x² + z²) - y at (-0.5, 0.375, 0): (-1.5, -1, 0).
    assert_parallel(d(h.normal), DVec3::new(-1.5, -1.0, 0.0), 1e-6, "n");
    assert!((h.uv.y - 0.25).abs() < 1e-6);
    // Down through the open top, parallel to the axis (a = 0): the
    // surface below (0.3, 0.4) is at y = 1.5 * 0.25 = 0.375.
    let h = must_hit(&p, &ray(v(0.3, 5.0, 0.4), v(0.0, -2.0, 0.0)));
    assert_t(&h, (5.0 - 0.375) / 2.0);
    // Up from below to the vertex.
    let h = must_hit(&p, &ray(v(0.0, -3.0, 0.0), v(0.0, 1.0, 0.0)));
    assert_t(&h, 3.0);
    assert_parallel(d(h.normal), -DVec3::Y, 1e-6, "n");
    // Above the top: the surface continues there, but is clipped.
    assert_miss(&p, &ray(v(-5.0, 2.0, 0.0), v(1.0, 0.0, 0.0)));
    // Up the axis, outside the radius at the top.
    assert_miss(&p, &ray(v(1.2, -1.0, 0.0), v(0.0, 1.0, 0.0)));
    // From inside the bowl, horizontally: far wall at x = +0.5.
    assert_t(
        &must_hit(&p, &ray(v(0.0, 0.375, 0.0), v(1.0, 0.0, 0.0))),
        0.5,
    );
}

#[test]
fn hyperboloid_known_hits() {
    let hy = hyperboloid(); // x² + z² - 3 y² = 1, |y| <= 1
    let h = must_hit(&hy, &ray(v(-5.0, 0.0, 0.0), v(1.0, 0.0, 0.0)));
    assert_t(&h, 4.0);
    assert_parallel(d(h.normal), -DVec3::X, 1e-6, "n");
    // At y = 0.5: radius² = 1.75.
    let h = must_hit(&hy, &ray(v(-5.0, 0.5, 0.0), v(1.0, 0.0, 0.0)));
    assert_t(&h, 5.0 - 1.75f64.sqrt());
    assert!((h.uv.y - 0.75).abs() < 1e-6);
    // At the rim y = 1: radius 2.
    assert_t(
        &must_hit(&hy, &ray(v(0.0, 1.0, -5.0), v(0.0, 0.0, 1.0))),
        3.0,
    );
    // Vertically at x = 1.5: 3 y² = 1.25, first hit at y = -sqrt(5/12),
    // where the outward normal points away from the axis and up.
    let h = must_hit(&hy, &ray(v(1.5, -5.0, 0.0), v(0.0, 1.0, 0.0)));
    let y = -(1.25f64 / 3.0).sqrt();
    assert_t(&h, 5.0 + y);
    assert_parallel(d(h.normal), DVec3::new(1.5, -3.0 * y, 0.0), 1e-5, "n");
    // From the centre: far root at the waist.
    assert_t(&must_hit(&hy, &ray(Vec3A::ZERO, v(0.0, 0.0, 1.0))), 1.0);
    // Along the axis: no real root.
    assert_miss(&hy, &ray(v(0.0, -5.0, 0.0), v(0.0, 1.0, 0.0)));
    // Above the extent.
    assert_miss(&hy, &ray(v(-5.0, 1.5, 0.0), v(1.0, 0.0, 0.0)));
}

/// Deterministic xorshift generator for the randomised tests.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
    fn vec(&mut self, lo: f64, hi: f64) -> DVec3 {
        DVec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

/// Random rays (half aimed into the bounding box, directions of random
/// length, random intervals) against the f64 reference. Each ray's
/// tolerance is derived from first-order perturbation: the f32
/// coefficients carry rounding errors of a few (`TOL_K = 4`) EPS times
/// their terms' absolute values `(A, B, C)`, which moves a root by
/// `TOL_K EPS (A t² + 2 B |t| + C) / |f'(t)|`, plus `TOL_K EPS |t|` for
/// the root formula (observed errors stay below a quarter of this).
/// Rays whose outcome a four times larger error (`SKIP_K = 16`) could
/// flip (nearly tangent, a root next to an interval end or the
/// extent's edge) are skipped; the test checks that few are.
#[test]
fn random_rays_match_f64_reference() {
    const TOL_K: f64 = 4.0;
    const SKIP_K: f64 = 16.0;
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for shape in quadrics() {
        let quad = quadric(&shape);
        let (lo, hi) = shape.bounds().unwrap();
        let (mut checked, mut hits, mut worst) = (0, 0, 0.0f64);
        let n = 4000;
        for i in 0..n {
            let o = rng.vec(-3.0, 3.0).as_vec3a();
            let dir = if i % 2 == 0 {
                let f = rng.vec(0.0, 1.0).as_vec3a();
                (lo + (hi - lo) * f - o) * rng.range(0.2, 3.0) as f32
            } else {
                rng.vec(-1.0, 1.0).as_vec3a() * 10f32.powf(rng.range(-1.0, 1.0) as f32)
            };
            let t_min = if i % 3 == 0 {
                rng.range(-0.5, 0.5) as f32
            } else {
                0.0
            };
            let t_max = if i % 5 == 0 {
                t_min + rng.range(0.0, 3.0) as f32
            } else {
                INF
            };
            let r = ray(o, dir);
            let (od, dd) = (d(o), d(dir));
            let (a, hb, c) = quad.coeffs(od, dd);
            let (aa, ba, ca) = quad.abs_coeffs(od, dd);
            let disc = hb * hb - a * c;
            if disc.abs() <= SKIP_K * EPS * (ba * ba + aa * ca) {
                continue;
            }
            let roots = roots64(a, hb, c);
            let tol = |t: f64| {
                let terms = aa * t * t + 2.0 * ba * t.abs() + ca;
                TOL_K * EPS * (terms / (2.0 * (a * t + hb)).abs() + t.abs())
            };
            let ambiguous = roots.iter().any(|&t| {
                let tl = tol(t) * SKIP_K / TOL_K;
                let y_err = tl * dd.y.abs() + SKIP_K * EPS * (od.y.abs() + (t * dd.y).abs() + 1.0);
                (t - t_min as f64).abs() <= 2.0 * tl
                    || (t - t_max as f64).abs() <= 2.0 * tl
                    || extent_margin(&shape, od + dd * t).abs() <= 2.0 * y_err
            });
            if ambiguous {
                continue;
            }
            checked += 1;
            let expected = reference_t(&shape, &r, t_min, t_max);
            match (shape.intersect(&r, t_min, t_max), expected) {
                (None, None) => {}
                (Some(h), Some(t)) => {
                    hits += 1;
                    let err = (h.t as f64 - t).abs();
                    worst = worst.max(err / tol(t));
                    assert_close(h.t as f64, t, tol(t), &format!("{shape:?} {r:?}"));
                    // Normal vs the gradient at the same (f32) point:
                    // only the normal formula's rounding differs,
                    // ~EPS times its terms over the gradient's size.
                    let p = d(r.origin) + d(r.direction) * h.t as f64;
                    let g = quad.grad(p);
                    let ntol = 64.0 * EPS * quad.grad_scale(p) / g.length();
                    assert_parallel(d(h.normal), g, ntol, &format!("{shape:?} {r:?}"));
                    assert!(h.uv.cmpge(Vec2::ZERO).all() && h.uv.cmple(Vec2::ONE).all());
                }
                (got, expected) => {
                    panic!("{shape:?} {r:?} [{t_min}, {t_max}]: got {got:?}, expected {expected:?}")
                }
            }
        }
        assert!(
            checked > n * 9 / 10,
            "{shape:?}: only {checked} rays checked"
        );
        assert!(hits > n / 5, "{shape:?}: only {hits} hits");
        eprintln!(
            "{}: {checked} checked, {hits} hits, worst error/tolerance {worst:.3}",
            shape.kind_name()
        );
    }
}

/// Same for the planar shapes, against f64 plane intersection and
/// inside tests (tolerances: `t = N / D` with `N` and `D` each rounded
/// to a few ulps of their terms; inside/outside undecidable within a
/// few ulps of the coordinates).
#[test]
fn random_rays_match_f64_reference_planar() {
    const K: f64 = 16.0;
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    let pent = pentagon();
    let shapes: Vec<(Shape, DVec3, DVec3)> = vec![
        (Shape::Plane, DVec3::ZERO, DVec3::Y),
        (Shape::Disk { radius: 1.5 }, DVec3::ZERO, DVec3::Y),
        (square(), DVec3::ZERO, DVec3::Y),
        (pent.shape.clone(), pent.center, pent.normal),
    ];
    for (shape, point, normal) in shapes {
        let (mut checked, mut hits) = (0, 0);
        for i in 0..2000 {
            let o = rng.vec(-3.0, 3.0).as_vec3a();
            let dir = if i % 2 == 0 {
                (rng.vec(-1.8, 1.8) - (rng.vec(-1.8, 1.8) - point).dot(normal) * normal).as_vec3a()
                    - o
            } else {
                rng.vec(-1.0, 1.0).as_vec3a()
            };
            let (od, dd) = (d(o), d(dir));
            let num = normal.dot(point - od);
            let den = normal.dot(dd);
            if den.abs() < 1e-3 * dd.length() {
                continue;
            }
            let t = num / den;
            let tol = K * EPS * (t.abs() + (point.length() + od.length()) / den.abs());
            let p = od + dd * t;
            let margin = match &shape {
                Shape::Plane => f64::INFINITY,
                Shape::Disk { radius } => *radius as f64 - p.with_y(0.0).length(),
                Shape::Polygon { vertices } => (0..vertices.len())
                    .map(|j| {
                        let a = vertices[j].as_dvec3();
                        let b = vertices[(j + 1) % vertices.len()].as_dvec3();
                        (b - a).cross(p - a).dot(normal) / (b - a).length()
                    })
                    .fold(f64::INFINITY, f64::min),
                _ => unreachable!(),
            };
            let pos_err = K * EPS * (od.length() + (dd * t).length() + 2.0);
            if t.abs() <= 2.0 * tol || margin.abs() <= 2.0 * pos_err {
                continue;
            }
            checked += 1;
            match (hit(&shape, &ray(o, dir)), t > 0.0 && margin > 0.0) {
                (None, false) => {}
                (Some(h), true) => {
                    hits += 1;
                    assert_close(h.t as f64, t, tol, &format!("{shape:?} {o} {dir}"));
                    assert_parallel(d(h.normal), normal, 1e-5, "planar normal");
                }
                (got, _) => {
                    panic!("{shape:?} {o} {dir}: got {got:?}, expected t = {t}, margin {margin}")
                }
            }
        }
        assert!(
            checked > 1800 && hits > 200,
            "{shape:?}: {checked} checked, {hits} hits"
        );
    }
}

// ----- normals under instance transforms -----------------------------

fn instance() -> (Quat, Vec3, Vec3, InstanceTransform) {
    let rotation = Quat::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), 0.9);
    let (translation, scale) = (Vec3::new(1.0, -2.0, 0.5), Vec3::new(2.0, 0.5, 1.25));
    let t = Transform::from_trs_f32(translation, rotation, scale);
    assert!(t.is_valid());
    (
        rotation,
        translation,
        scale,
        InstanceTransform::new(t.relative_to(glam::DVec3::ZERO)),
    )
}

fn to_object(it: &InstanceTransform, o: Vec3A, dir: Vec3A) -> Ray {
    ray(
        it.to_object.transform_point3a(o),
        it.to_object.transform_vector3a(dir),
    )
}

/// A unit sphere under non-uniform scale and rotation is the world
/// ellipsoid `|S⁻¹ R⁻¹ (p - T)| = 1`, gradient `R S⁻² R⁻¹ (p - T)`. The
/// mapped normal must match it to ~1e-5 (a few ulps through the
/// matrices, times the scale's condition number 4, plus the hit
/// point's rounding over the smallest radius 0.5); the naive mapping by
/// the linear part itself must not.
#[test]
fn normals_under_nonuniform_scale_and_rotation() {
    let (rot, tr, sc, it) = instance();
    let (rot, tr, sc) = (rot.as_dquat(), tr.as_dvec3(), sc.as_dvec3());
    let s = sphere();
    let mut naive_worst = 0.0f64;
    let rays = [
        (v(6.0, 1.0, -3.0), v(-5.0, -3.0, 3.5)),
        (v(-4.0, 3.0, 2.0), v(5.0, -5.0, -1.5)),
        (v(1.0, 5.0, 0.5), v(0.1, -1.0, 0.05)),
        // From inside (the instance's centre), unnormalised direction.
        (v(1.0, -2.0, 0.5), v(0.3, 2.0, -1.0)),
    ];
    for (o_w, d_w) in rays {
        let h = must_hit(&s, &to_object(&it, o_w, d_w));
        let p_w = d(o_w) + d(d_w) * h.t as f64;
        let q = rot.inverse() * (p_w - tr);
        assert_close((q / sc).length(), 1.0, 1e-5, "world hit on the ellipsoid");
        let grad = rot * (q / (sc * sc));
        let n_w = it.normal(h.normal);
        assert_close(n_w.length() as f64, 1.0, 1e-6, "unit world normal");
        assert_parallel(d(n_w), grad, 1e-5, "world normal");
        let naive = d(it.to_world.matrix3 * h.normal).normalize();
        naive_worst = naive_worst.max(naive.cross(grad.normalize()).length());
    }
    assert!(
        naive_worst > 0.1,
        "test cannot tell the inverse transpose apart"
    );
}

/// For every shape under the same transform, world tangents (central
/// differences of hit points of rays offset by ±1e-3 across the ray)
/// are orthogonal to the mapped normal. Central differences are off by
/// O((h κ)²) ~ 1e-5 for curvatures κ <= 4 here, and the rounding of
/// the hit points (~1e-6) over chords of 2e-3 adds ~5e-4: tolerance
/// 2e-3, while wrong normals are off by O(0.1).
#[test]
fn world_normals_are_orthogonal_to_world_tangents() {
    let (_, _, _, it) = instance();
    for (shape, r) in sample_rays() {
        let o_w = it.to_world.transform_point3a(r.origin);
        let d_w = it.to_world.transform_vector3a(r.direction);
        let h = must_hit(&shape, &to_object(&it, o_w, d_w));
        let n_w = d(it.normal(h.normal));
        let dd = d(d_w);
        let e1 = dd.any_orthonormal_vector();
        let e2 = dd.normalize().cross(e1);
        let at = |off: DVec3| {
            let o = d(o_w) + off;
            let h = must_hit(&shape, &to_object(&it, o.as_vec3a(), d_w));
            o + dd * h.t as f64
        };
        let step = 1e-3;
        for e in [e1, e2] {
            let tangent = at(e * step) - at(-e * step);
            let c = n_w.dot(tangent.normalize()).abs();
            assert!(c < 2e-3, "{shape:?}: |n . tangent| = {c}");
        }
    }
}

// ----- numerical stability -------------------------------------------

/// The textbook f32 formula, to show what the stable one avoids.
fn naive_sphere_t(r: &Ray, radius: f32) -> Option<f32> {
    let (o, dir) = (r.origin, r.direction);
    let a = dir.dot(dir);
    let b = 2.0 * o.dot(dir);
    let c = o.dot(o) - radius * radius;
    let disc = b * b - 4.0 * a * c;
    (disc >= 0.0).then(|| (-b - disc.sqrt()) / (2.0 * a))
}

/// f64 near root of a sphere at the origin (distance-to-line form,
/// accurate in f64 for these magnitudes).
fn sphere_ref(r: &Ray, radius: f64) -> Option<f64> {
    let (o, dir) = (d(r.origin), d(r.direction));
    let a = dir.dot(dir);
    let tc = -o.dot(dir) / a;
    let dist2 = (o + dir * tc).length_squared();
    let half_chord = (radius * radius - dist2).sqrt() / a.sqrt();
    (dist2 <= radius * radius).then(|| {
        if o.length() > radius {
            tc - half_chord
        } else {
            tc + half_chord
        }
    })
}

/// Radius 1 at distance 1e6: f32 cannot place the origin better than
/// ~ulp(1e6) = 0.06, so the bound is a few ulps of 1e6: t within
/// 4 EPS (|o| / |d| + t) ≈ 1 (relative 5e-7 < 1e-6), and the hit point
/// (evaluated in f64 from the returned t) within 0.1 of the surface.
/// The textbook formula's discriminant is a difference of two rounded
/// ~1e12 values, i.e. a multiple of 65536, so it cannot represent the
/// true value 0.64 and is off by at least 0.8 in t (or misses).
#[test]
fn far_sphere_is_hit_accurately() {
    let s = sphere();
    let u = DVec3::new(2.0, -3.0, 6.0) / 7.0;
    let perp = DVec3::new(3.0, 2.0, 0.0) / 13f64.sqrt();
    for (dist, offset) in [(1e6, 0.6), (1e6, 0.0), (3e6, 0.95), (1e6, 1.01)] {
        let r = ray((u * -dist + perp * offset).as_vec3a(), u.as_vec3a());
        let expected = sphere_ref(&r, 1.0);
        let got = hit(&s, &r);
        let (Some(t_ref), Some(h)) = (expected, got) else {
            assert!(
                expected.is_none() && got.is_none(),
                "{offset}: {got:?} vs {expected:?}"
            );
            continue;
        };
        let tol = 4.0 * EPS * (d(r.origin).length() / d(r.direction).length() + t_ref);
        assert_close(h.t as f64, t_ref, tol, "far t");
        assert!((h.t as f64 - t_ref).abs() / t_ref < 1e-6);
        let p = d(r.origin) + d(r.direction) * h.t as f64;
        assert_close(p.length(), 1.0, 0.1, "far hit point on the sphere");
        assert!(h.normal.is_finite());
        if offset == 0.6 {
            assert!(
                naive_sphere_t(&r, 1.0).is_none_or(|t| (t as f64 - t_ref).abs() > 0.5),
                "the naive formula should fail here"
            );
        }
    }
}

/// Radius 1e-4 at distance 1: c = |o|² - r² rounds to 1, so the
/// textbook discriminant is 0 for every ray through the sphere's
/// neighbourhood (a "hit" at the centre even for rays that miss),
/// while the distance-to-line form resolves offsets of the radius. t is
/// within 4 EPS (|o| + t) ≈ 1e-6 (1% of the radius: the ulp of the
/// coordinates, the most f32 allows at that position).
#[test]
fn tiny_sphere_is_hit_accurately() {
    let s = Shape::Sphere { radius: 1e-4 };
    for dir in [DVec3::Z, DVec3::new(0.6, -0.3, 0.8).normalize()] {
        let perp = dir.any_orthonormal_vector();
        for offset in [0.0, 0.5e-4, 0.9e-4, 1.5e-4, 3e-4] {
            let r = ray((dir * -1.0 + perp * offset).as_vec3a(), dir.as_vec3a());
            let expected = sphere_ref(&r, 1e-4);
            match (hit(&s, &r), expected) {
                (Some(h), Some(t)) => {
                    assert_close(h.t as f64, t, 4.0 * EPS * (1.0 + t), "tiny t");
                    assert_parallel(d(h.normal), d(r.at(h.t)), 1e-6, "n");
                }
                (None, None) => {
                    if dir == DVec3::Z && offset == 1.5e-4 {
                        // |o|² = 1 + 2.25e-8 rounds to 1, so c = 1 and
                        // the textbook discriminant is exactly 0.
                        assert_eq!(naive_sphere_t(&r, 1e-4), Some(1.0));
                    }
                }
                (got, expected) => panic!("offset {offset}: {got:?} vs {expected:?}"),
            }
        }
    }
}

/// Radius 1e5 approached from 10 units away (t ≈ 10) and from inside
/// (far root ≈ 2e5): the bound is again a few ulps of the coordinates,
/// 4 EPS (|o| / |d| + t) ≈ 0.05 and 0.15, and the hit point within
/// 0.05 / 0.15 of the surface.
#[test]
fn huge_sphere_is_hit_accurately() {
    let s = Shape::Sphere { radius: 1e5 };
    for (o, dir) in [
        (v(0.0, 0.0, -100_010.0), v(1e-3, 2e-3, 1.0)),
        (v(3.0, -7.0, -100_010.0), v(0.3, 0.1, 1.0)),
        (v(0.0, 5.0, -99_990.0), v(-0.2, 0.3, 1.0)),
    ] {
        let r = ray(o, dir);
        let t_ref = sphere_ref(&r, 1e5).unwrap();
        let h = must_hit(&s, &r);
        let tol = 4.0 * EPS * (d(o).length() / d(dir).length() + t_ref);
        assert_close(h.t as f64, t_ref, tol, "huge t");
        let p = d(o) + d(dir) * h.t as f64;
        assert_close(p.length(), 1e5, tol * d(dir).length(), "huge hit point");
    }
}

#[test]
fn non_finite_input_never_produces_nan() {
    let mut shapes = quadrics();
    shapes.extend([
        Shape::Plane,
        Shape::Disk { radius: 1.0 },
        square(),
        Shape::Sphere { radius: f32::NAN },
        Shape::Cone {
            radius: 0.0,
            height: 0.0,
        },
        Shape::Paraboloid {
            radius: 0.0,
            height: 1.0,
        },
    ]);
    let bad = [f32::NAN, f32::INFINITY, -f32::INFINITY, f32::MAX, 0.0];
    for shape in &shapes {
        for &x in &bad {
            for r in [
                ray(v(x, 0.1, -3.0), v(0.0, 0.1, 1.0)),
                ray(v(0.1, 0.2, -3.0), v(x, 0.1, 1.0)),
                ray(v(0.1, 0.2, -3.0), v(0.0, x, 0.0)),
                ray(v(0.1, 0.2, -3.0), Vec3A::splat(x)),
            ] {
                for (lo, hi) in [(0.0, INF), (x, INF), (0.0, x)] {
                    if let Some(h) = shape.intersect(&r, lo, hi) {
                        assert!(
                            h.t.is_finite() && h.normal.is_finite() && h.uv.is_finite(),
                            "{shape:?} {r:?}: {h:?}"
                        );
                    }
                }
            }
        }
    }
}

/// `occludes` (shadow rays) answers exactly as `intersect(..).is_some()`,
/// and `intersect_t` gives exactly its `t`, for every shape: on random rays at ordinary and extreme scales
/// (origins and intervals up to 1e37), rays in the plane, parallel to it
/// and starting on it, disks of zero, tiny and huge radius, and hits that
/// `intersect` drops because the point overflows or the disk's `uv` is
/// NaN (a zero-radius disk hit at its centre).
#[test]
fn occludes_answers_as_intersect_does() {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    let mut cases = Vec::new();
    for i in 0..4000 {
        let scale = [1.0f32, 1e-20, 1e20, 1e37][i % 4];
        let mut o = v(next(), next(), next()) * 3.0 * scale;
        let mut d = v(next(), next(), next());
        match i % 11 {
            0 => d.y = 0.0,
            1 => o.y = 0.0,
            2 => d.y = -0.0,
            _ => {}
        }
        let interval = match i % 5 {
            0 => (0.0, INF),
            1 => (0.0, next().abs() * 10.0 * scale),
            2 => (next().abs() * scale, f32::MAX),
            3 => (-INF, INF),
            _ => (0.0, 1e-3),
        };
        cases.push((ray(o, d), interval));
    }
    let edges = [
        // Through the centre: a zero-radius disk's uv is 0 / 0.
        ray(v(0.0, 1.0, 0.0), v(0.0, -1.0, 0.0)),
        // The crossing point overflows.
        ray(v(3e38, 1.0, 0.0), v(1e9, -1e-30, 0.0)),
        ray(v(0.0, -1.0, -3e38), v(0.0, 1e-30, -1e9)),
        // In the plane, and starting on it.
        ray(v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0)),
        ray(v(1.0, 0.0, 1.0), v(0.0, 1.0, 0.0)),
    ];
    for r in edges {
        cases.push((r, (0.0, INF)));
        cases.push((r, (-INF, INF)));
    }
    let mut shapes = vec![
        Shape::Plane,
        Shape::Disk { radius: 1.0 },
        Shape::Disk { radius: 1e-30 },
        Shape::Disk { radius: 1e30 },
        Shape::Disk { radius: 0.0 },
    ];
    shapes.extend(quadrics());
    let (mut hits, mut dropped, mut total) = (0, 0, 0);
    for shape in &shapes {
        for (r, (t_min, t_max)) in &cases {
            let hit = shape.intersect(r, *t_min, *t_max);
            let full = hit.is_some();
            assert_eq!(
                shape.occludes(r, *t_min, *t_max),
                full,
                "{shape:?} {r:?} ({t_min}, {t_max})"
            );
            assert_eq!(
                shape.intersect_t(r, *t_min, *t_max).map(f32::to_bits),
                hit.map(|h| h.t.to_bits()),
                "intersect_t: {shape:?} {r:?} ({t_min}, {t_max})"
            );
            hits += full as u32;
            total += 1;
            // Crossings of y = 0 inside the interval (and the disk) that
            // `intersect` drops as non-finite.
            if !full && matches!(shape, Shape::Plane | Shape::Disk { .. }) && r.direction.y != 0.0 {
                let t = -r.origin.y / r.direction.y;
                let p = r.at(t);
                let inside = match shape {
                    Shape::Disk { radius } => !(p.x * p.x + p.z * p.z > radius * radius),
                    _ => true,
                };
                dropped += (t > *t_min && t < *t_max && inside) as u32;
            }
        }
    }
    // Both answers occur often, and dropped hits are among the cases.
    assert!(
        hits > total / 10 && hits < total * 9 / 10,
        "{hits} of {total}"
    );
    assert!(dropped >= 6, "{dropped}");
}
