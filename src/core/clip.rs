//! Clipping: lines against a rectangle (Cohen-Sutherland and
//! Liang-Barsky), polygons against a convex polygon and an axis-aligned
//! box (Sutherland-Hodgman), and lines and polygons against the view
//! volume in homogeneous coordinates, before the perspective divide.
//!
//! Everything is in double precision. The kd-tree clips each triangle
//! to its node's box for exact split candidates (`accel::kdtree`); the
//! vector lines and structure overlays clip every edge to the view with
//! [`clip_line_homogeneous`] (`integrators::vector_lines`).

use glam::{DVec2, DVec3, DVec4};

/// An axis-aligned rectangle, `min <= max` on both axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    /// Lower corner.
    pub min: DVec2,
    /// Upper corner.
    pub max: DVec2,
}

/// Outcode bit: left of the rectangle (`x < min.x`).
pub const LEFT: u8 = 1;
/// Outcode bit: right of the rectangle (`x > max.x`).
pub const RIGHT: u8 = 2;
/// Outcode bit: below the rectangle (`y < min.y`).
pub const BOTTOM: u8 = 4;
/// Outcode bit: above the rectangle (`y > max.y`).
pub const TOP: u8 = 8;

/// Cohen-Sutherland outcode of `p`: which of the four outer half-planes
/// it lies in (0 inside or on the boundary).
pub fn outcode(p: DVec2, r: &Rect) -> u8 {
    let mut c = 0;
    if p.x < r.min.x {
        c |= LEFT;
    } else if p.x > r.max.x {
        c |= RIGHT;
    }
    if p.y < r.min.y {
        c |= BOTTOM;
    } else if p.y > r.max.y {
        c |= TOP;
    }
    c
}

/// Cohen-Sutherland line clipping: the part of segment `a`-`b` inside
/// `r`, or `None`. Both outcodes zero is a trivial accept, a common bit a
/// trivial reject; otherwise an outside endpoint is moved onto the
/// boundary line its outcode names (the coordinate set exactly) and the
/// test repeats. Non-finite input is rejected.
pub fn cohen_sutherland(a: DVec2, b: DVec2, r: &Rect) -> Option<(DVec2, DVec2)> {
    if !(a.is_finite() && b.is_finite()) {
        return None;
    }
    let (mut a, mut b) = (a, b);
    let (mut ca, mut cb) = (outcode(a, r), outcode(b, r));
    // Each step clears at least one bit of one endpoint for good: at most
    // four steps per endpoint.
    for _ in 0..8 {
        if ca | cb == 0 {
            return Some((a, b));
        }
        if ca & cb != 0 {
            return None;
        }
        let out = if ca != 0 { ca } else { cb };
        let (p, q) = if ca != 0 { (a, b) } else { (b, a) };
        let d = q - p;
        let moved = if out & TOP != 0 {
            DVec2::new(p.x + d.x * (r.max.y - p.y) / d.y, r.max.y)
        } else if out & BOTTOM != 0 {
            DVec2::new(p.x + d.x * (r.min.y - p.y) / d.y, r.min.y)
        } else if out & RIGHT != 0 {
            DVec2::new(r.max.x, p.y + d.y * (r.max.x - p.x) / d.x)
        } else {
            DVec2::new(r.min.x, p.y + d.y * (r.min.x - p.x) / d.x)
        };
        // Rounding can put the moved point a hair outside on the other
        // axis; clamp it onto the rectangle's span of that axis only when
        // it is that close (a real miss stays outside).
        let moved = snap(moved, r);
        if ca != 0 {
            a = moved;
            ca = outcode(a, r);
        } else {
            b = moved;
            cb = outcode(b, r);
        }
    }
    (ca | cb == 0).then_some((a, b))
}

/// Clamps coordinates within a few ulps outside `r` onto its edges.
fn snap(p: DVec2, r: &Rect) -> DVec2 {
    let tol =
        8.0 * f64::EPSILON * (r.min.abs().max(r.max.abs()).max_element() + p.abs().max_element());
    let fix = |v: f64, lo: f64, hi: f64| {
        if v < lo && v > lo - tol {
            lo
        } else if v > hi && v < hi + tol {
            hi
        } else {
            v
        }
    };
    DVec2::new(fix(p.x, r.min.x, r.max.x), fix(p.y, r.min.y, r.max.y))
}

/// Liang-Barsky line clipping: the part of segment `a`-`b` inside `r`, or
/// `None`. The segment is `a + t (b - a)` for `t` in `[0, 1]`; each of
/// the four boundaries `p_k t <= q_k` raises the entry parameter or lowers
/// the exit one, and the segment survives if entry <= exit.
pub fn liang_barsky(a: DVec2, b: DVec2, r: &Rect) -> Option<(DVec2, DVec2)> {
    if !(a.is_finite() && b.is_finite()) {
        return None;
    }
    let d = b - a;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let sides = [
        (-d.x, a.x - r.min.x),
        (d.x, r.max.x - a.x),
        (-d.y, a.y - r.min.y),
        (d.y, r.max.y - a.y),
    ];
    for (p, q) in sides {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| {
        if t == 0.0 {
            a
        } else if t == 1.0 {
            b
        } else {
            snap(a + d * t, r)
        }
    };
    Some((at(t0), at(t1)))
}

/// Signed area of a polygon (positive when counter-clockwise).
pub fn polygon_area(poly: &[DVec2]) -> f64 {
    let n = poly.len();
    if n < 3 {
        return 0.0;
    }
    0.5 * (0..n)
        .map(|i| poly[i].perp_dot(poly[(i + 1) % n]))
        .sum::<f64>()
}

/// One Sutherland-Hodgman pass: keeps the part of `poly` where
/// `inside(p) >= 0`, for an `inside` that is affine along every edge (a
/// signed distance to a line or plane). Crossing points are found by
/// interpolating `inside` along the edge, from the inside end; `place`
/// may then set coordinates exactly (onto an axis-aligned plane).
fn clip_pass<P: Copy>(
    poly: &[P],
    inside: impl Fn(P) -> f64,
    lerp: impl Fn(P, P, f64) -> P,
    out: &mut Vec<P>,
) {
    out.clear();
    let n = poly.len();
    if n == 0 {
        return;
    }
    let mut prev = poly[n - 1];
    let mut fp = inside(prev);
    for &cur in poly {
        let fc = inside(cur);
        if fc >= 0.0 {
            if fp < 0.0 {
                out.push(lerp(cur, prev, fc / (fc - fp)));
            }
            out.push(cur);
        } else if fp >= 0.0 {
            out.push(lerp(prev, cur, fp / (fp - fc)));
        }
        prev = cur;
        fp = fc;
    }
}

/// Sutherland-Hodgman: `subject` (any simple polygon) clipped to the
/// convex polygon `clip` (counter-clockwise). A concave subject may come
/// out as one polygon with zero-width bridges between its parts; its area
/// is still that of the intersection.
pub fn clip_polygon_convex(subject: &[DVec2], clip: &[DVec2]) -> Vec<DVec2> {
    let mut cur = subject.to_vec();
    let mut next = Vec::with_capacity(subject.len() + clip.len());
    let m = clip.len();
    for i in 0..m {
        let (e0, e1) = (clip[i], clip[(i + 1) % m]);
        let edge = e1 - e0;
        clip_pass(
            &cur,
            |p| edge.perp_dot(p - e0),
            |a, b, t| a + (b - a) * t,
            &mut next,
        );
        std::mem::swap(&mut cur, &mut next);
        if cur.is_empty() {
            break;
        }
    }
    cur
}

/// Sutherland-Hodgman in 3D: the convex polygon `poly` clipped to the box
/// `[lo, hi]`, against `x >= lo.x`, `x <= hi.x`, then y, then z. Crossing
/// points get the plane's coordinate exactly, so every output vertex
/// lies inside the box (the other coordinates are interpolated).
pub fn clip_polygon_box(poly: &[DVec3], lo: DVec3, hi: DVec3) -> Vec<DVec3> {
    let mut cur = poly.to_vec();
    let mut next = Vec::with_capacity(poly.len() + 6);
    for axis in 0..3 {
        for upper in [false, true] {
            let plane = if upper { hi[axis] } else { lo[axis] };
            let sign = if upper { -1.0 } else { 1.0 };
            clip_pass(
                &cur,
                |p| sign * (p[axis] - plane),
                |a, b, t| {
                    let mut p = a + (b - a) * t;
                    p[axis] = plane;
                    p
                },
                &mut next,
            );
            std::mem::swap(&mut cur, &mut next);
            if cur.is_empty() {
                return cur;
            }
        }
    }
    // Interpolated coordinates of later axes can round a hair outside
    // the planes clipped first.
    for p in &mut cur {
        *p = p.clamp(lo, hi);
    }
    cur
}

/// Smallest `w` kept by homogeneous clipping: points with `w` below it
/// (behind the camera, or on its plane) are clipped away before any
/// divide.
pub const MIN_W: f64 = 1e-9;

/// The planes of the view volume in clip space, as `inside(p) >= 0`:
/// `w >= MIN_W`, `-w <= x <= w`, `-w <= y <= w`.
fn homogeneous_planes() -> [fn(DVec4) -> f64; 5] {
    [
        |p| p.w - MIN_W,
        |p| p.w + p.x,
        |p| p.w - p.x,
        |p| p.w + p.y,
        |p| p.w - p.y,
    ]
}

/// Sutherland-Hodgman against the view volume in homogeneous (clip)
/// coordinates: `w >= MIN_W` first, then `|x| <= w` and `|y| <= w`. Run
/// before the perspective divide, so every output vertex has
/// `w >= MIN_W > 0` and can be divided ([`project`]); nothing behind
/// the camera is ever projected. Depth is not clipped.
pub fn clip_polygon_homogeneous(poly: &[DVec4]) -> Vec<DVec4> {
    let mut cur = poly.to_vec();
    let mut next = Vec::with_capacity(poly.len() + 5);
    for inside in homogeneous_planes() {
        clip_pass(&cur, inside, |a, b, t| a + (b - a) * t, &mut next);
        std::mem::swap(&mut cur, &mut next);
        if cur.is_empty() {
            break;
        }
    }
    // Interpolation rounds: put every vertex exactly inside, so that
    // `|x / w|, |y / w| <= 1` holds after the divide too.
    for p in &mut cur {
        *p = inside_view(*p);
    }
    cur
}

/// Liang-Barsky against the view volume in homogeneous coordinates: the
/// part of segment `a`-`b` with `w >= MIN_W` and `|x|, |y| <= w`, as
/// parameters `(t0, t1)` along it and the clipped end points. Every
/// plane is affine along the segment, so each one bounds the parameter
/// interval exactly as in 2D.
pub fn clip_line_homogeneous(a: DVec4, b: DVec4) -> Option<(f64, f64, DVec4, DVec4)> {
    if !(a.is_finite() && b.is_finite()) {
        return None;
    }
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for inside in homogeneous_planes() {
        let (fa, fb) = (inside(a), inside(b));
        if fa < 0.0 && fb < 0.0 {
            return None;
        }
        if fa < 0.0 {
            t0 = t0.max(fa / (fa - fb));
        } else if fb < 0.0 {
            t1 = t1.min(fa / (fa - fb));
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| inside_view(a + (b - a) * t);
    Some((t0, t1, at(t0), at(t1)))
}

/// `p` moved onto the view volume where rounding left it a hair outside.
fn inside_view(mut p: DVec4) -> DVec4 {
    p.w = p.w.max(MIN_W);
    p.x = p.x.clamp(-p.w, p.w);
    p.y = p.y.clamp(-p.w, p.w);
    p
}

/// The perspective divide of a clipped point: `(x/w, y/w, z/w)`. `None`
/// when `w < MIN_W`, so it never divides by `w <= 0`.
pub fn project(p: DVec4) -> Option<DVec3> {
    (p.w >= MIN_W).then(|| p.truncate() / p.w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outcodes_name_the_regions() {
        let r = Rect {
            min: DVec2::ZERO,
            max: DVec2::ONE,
        };
        assert_eq!(outcode(DVec2::new(0.5, 0.5), &r), 0);
        assert_eq!(outcode(DVec2::new(-1.0, 2.0), &r), LEFT | TOP);
        assert_eq!(outcode(DVec2::new(2.0, -1.0), &r), RIGHT | BOTTOM);
        assert_eq!(
            outcode(DVec2::new(1.0, 0.0), &r),
            0,
            "the boundary is inside"
        );
    }

    #[test]
    fn box_clip_of_a_triangle_through_a_corner() {
        // The triangle (0,0,0) (2,0,0) (0,2,0) against the unit box: its
        // hypotenuse x + y = 2 passes through (1, 1), the whole square remains.
        let tri = [
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.0, 2.0, 0.0),
        ];
        let out = clip_polygon_box(&tri, DVec3::ZERO, DVec3::ONE);
        let flat: Vec<DVec2> = out.iter().map(|p| p.truncate()).collect();
        assert!((polygon_area(&flat) - 1.0).abs() < 1e-15);
        // Shifted so the hypotenuse cuts the square: area 1 - 1/8.
        let tri = [
            DVec3::ZERO,
            DVec3::new(1.5, 0.0, 0.0),
            DVec3::new(0.0, 1.5, 0.0),
        ];
        let out = clip_polygon_box(&tri, DVec3::ZERO, DVec3::ONE);
        let flat: Vec<DVec2> = out.iter().map(|p| p.truncate()).collect();
        assert!(
            (polygon_area(&flat) - (1.125 - 0.25)).abs() < 1e-15,
            "{}",
            polygon_area(&flat)
        );
    }
}
