//! The clipping kernels against each other and against independent
//! oracles: Cohen-Sutherland against Liang-Barsky on a million segments
//! and against point sampling; Sutherland-Hodgman's area against an exact
//! slice integration of the intersection; idempotence; homogeneous
//! clipping keeps `w > 0`.

use glam::{DVec2, DVec3, DVec4};
use prism::core::clip::{
    MIN_W, Rect, clip_line_homogeneous, clip_polygon_box, clip_polygon_convex,
    clip_polygon_homogeneous, cohen_sutherland, liang_barsky, polygon_area, project,
};

use crate::common::rng::SplitMix64 as Rng;

fn f(rng: &mut Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

fn pt(rng: &mut Rng, lo: f64, hi: f64) -> DVec2 {
    DVec2::new(lo + (hi - lo) * f(rng), lo + (hi - lo) * f(rng))
}

fn inside(p: DVec2, r: &Rect, tol: f64) -> bool {
    p.cmpge(r.min - tol).all() && p.cmple(r.max + tol).all()
}

/// A million random segments (many crossing, many outside, some
/// axis-aligned or degenerate): both algorithms accept the same ones and
/// return the same end points within a derived tolerance (a few roundings
/// of the coordinates, 1e-12 here); a sampling oracle on every 50th.
#[test]
fn cohen_sutherland_and_liang_barsky_agree() {
    let mut rng = Rng(1);
    let r = Rect {
        min: DVec2::new(-1.0, -0.5),
        max: DVec2::new(2.0, 1.5),
    };
    let tol = 1e-12;
    let (mut accepted, mut partial) = (0, 0);
    for k in 0..1_000_000 {
        let a = pt(&mut rng, -3.0, 4.0);
        let mut b = pt(&mut rng, -3.0, 4.0);
        match k % 10 {
            0 => b.x = a.x,
            1 => b.y = a.y,
            2 => b = a,
            _ => {}
        }
        let cs = cohen_sutherland(a, b, &r);
        let lb = liang_barsky(a, b, &r);
        match (cs, lb) {
            (None, None) => {}
            (Some((c0, c1)), Some((l0, l1))) => {
                accepted += 1;
                partial += (c0 != a || c1 != b) as u32;
                assert!(
                    c0.distance(l0) <= tol && c1.distance(l1) <= tol,
                    "segment {a} {b}: CS {c0} {c1}, LB {l0} {l1}"
                );
                assert!(
                    inside(c0, &r, 0.0) && inside(c1, &r, 0.0),
                    "{c0} {c1} outside"
                );
            }
            _ => {
                // Only a segment touching the rectangle within rounding may
                // differ: check it grazes.
                let (p, q) = cs.or(lb).unwrap();
                assert!(
                    p.distance(q) <= 1e-9,
                    "segment {a} {b}: CS {cs:?}, LB {lb:?}"
                );
            }
        }
        if k % 50 == 0 {
            // Sampling oracle: samples inside the rectangle lie on the
            // clipped part, and some sample is inside if the clip is long.
            let clip = lb;
            let n = 200;
            let mut any_inside = false;
            for i in 0..=n {
                let s = a + (b - a) * (i as f64 / n as f64);
                if inside(s, &r, 0.0) {
                    any_inside = true;
                    let (p, q) =
                        clip.unwrap_or_else(|| panic!("{a} {b}: sample {s} inside, clip empty"));
                    // On segment p-q: distance to it within rounding.
                    let d = q - p;
                    let t = if d.length_squared() > 0.0 {
                        ((s - p).dot(d) / d.length_squared()).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    assert!(
                        (p + d * t).distance(s) <= 1e-9,
                        "{a} {b}: sample {s} off the clip {p} {q}"
                    );
                }
            }
            if let Some((p, q)) = clip
                && p.distance(q) > 2.0 * a.distance(b) / n as f64
            {
                assert!(any_inside, "{a} {b}: clip {p} {q} but no sample inside");
            }
        }
    }
    assert!(
        accepted > 200_000 && partial > 100_000,
        "{accepted} {partial}"
    );
}

/// Length of the vertical slice of polygon `poly` at `x` (even-odd).
fn slice(poly: &[DVec2], x: f64, other: Option<(f64, f64)>) -> Vec<(f64, f64)> {
    let mut ys = Vec::new();
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a.x <= x) != (b.x <= x) {
            ys.push(a.y + (b.y - a.y) * (x - a.x) / (b.x - a.x));
        }
    }
    ys.sort_by(f64::total_cmp);
    let mut out = Vec::new();
    for c in ys.chunks(2) {
        if let [lo, hi] = c {
            let (lo, hi) = match other {
                Some((a, b)) => (lo.max(a), hi.min(b)),
                None => (*lo, *hi),
            };
            if hi > lo {
                out.push((lo, hi));
            }
        }
    }
    out
}

fn seg_cross_x(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> Option<f64> {
    let r = b - a;
    let s = d - c;
    let den = r.perp_dot(s);
    if den == 0.0 {
        return None;
    }
    let t = (c - a).perp_dot(s) / den;
    let u = (c - a).perp_dot(r) / den;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some(a.x + r.x * t)
}

/// Area of `subject` (simple) inside the convex `clip`, by integrating
/// the length of vertical slices: between consecutive vertex and edge
/// crossing abscissae the length is linear in x, so the midpoint rule is
/// exact there.
fn intersection_area(subject: &[DVec2], clip: &[DVec2]) -> f64 {
    let mut xs: Vec<f64> = subject.iter().chain(clip).map(|p| p.x).collect();
    for i in 0..subject.len() {
        for j in 0..clip.len() {
            let (a, b) = (subject[i], subject[(i + 1) % subject.len()]);
            let (c, d) = (clip[j], clip[(j + 1) % clip.len()]);
            xs.extend(seg_cross_x(a, b, c, d));
        }
    }
    xs.sort_by(f64::total_cmp);
    let mut area = 0.0;
    for w in xs.windows(2) {
        let dx = w[1] - w[0];
        if dx <= 0.0 {
            continue;
        }
        let x = 0.5 * (w[0] + w[1]);
        let Some(&c) = slice(clip, x, None).first() else {
            continue;
        };
        area += dx
            * slice(subject, x, Some(c))
                .iter()
                .map(|(a, b)| b - a)
                .sum::<f64>();
    }
    area
}

/// A random star-shaped (generally concave) polygon, counter-clockwise:
/// jittered angles around a centre, no two consecutive more than pi
/// apart (which keeps it simple), at random radii.
fn star(rng: &mut Rng, n: usize) -> Vec<DVec2> {
    let c = pt(rng, -0.5, 0.5);
    let angles: Vec<f64> = (0..n)
        .map(|i| (i as f64 + 0.4 * f(rng)) / n as f64 * std::f64::consts::TAU)
        .collect();
    angles
        .iter()
        .map(|&a| c + DVec2::new(a.cos(), a.sin()) * (0.2 + f(rng)))
        .collect()
}

/// A random convex polygon, counter-clockwise: points on an ellipse.
fn convex(rng: &mut Rng, n: usize) -> Vec<DVec2> {
    let c = pt(rng, -0.5, 0.5);
    let (rx, ry) = (0.3 + f(rng), 0.3 + f(rng));
    let mut angles: Vec<f64> = (0..n).map(|_| f(rng) * std::f64::consts::TAU).collect();
    angles.sort_by(f64::total_cmp);
    angles.dedup();
    angles
        .iter()
        .map(|&a| c + DVec2::new(rx * a.cos(), ry * a.sin()))
        .collect()
}

#[test]
fn sutherland_hodgman_area_equals_the_intersection_area() {
    let mut rng = Rng(2);
    let mut nonempty = 0;
    for k in 0..3000 {
        let subject = if k % 2 == 0 {
            star(&mut rng, 3 + k % 9)
        } else {
            convex(&mut rng, 3 + k % 7)
        };
        let clip = convex(&mut rng, 3 + (k / 2) % 8);
        let out = clip_polygon_convex(&subject, &clip);
        let got = polygon_area(&out);
        let want = intersection_area(&subject, &clip);
        assert!(
            (got - want).abs() <= 1e-12 * (1.0 + want),
            "case {k}: clipped area {got}, intersection {want}"
        );
        nonempty += (want > 1e-3) as u32;
        // Idempotent: clipping again changes nothing but rounding.
        let again = clip_polygon_convex(&out, &clip);
        assert!(
            (polygon_area(&again) - got).abs() <= 1e-12,
            "case {k}: not idempotent"
        );
        // Vertices may move along an edge lying on the clip boundary (a
        // concave subject's bridges), but stay on the first result's outline.
        for p in &again {
            let on_outline = (0..out.len()).any(|i| {
                let (a, b) = (out[i], out[(i + 1) % out.len()]);
                let d = b - a;
                let t = if d.length_squared() > 0.0 {
                    ((*p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (a + d * t).distance(*p) <= 1e-12
            });
            assert!(
                on_outline,
                "case {k}: new vertex {p} off the first result's outline"
            );
        }
    }
    assert!(nonempty > 1500, "{nonempty}");
}

#[test]
fn box_clipping_is_exact_inside_and_idempotent() {
    let mut rng = Rng(3);
    let (lo, hi) = (DVec3::new(-0.5, -0.2, 0.0), DVec3::new(0.6, 0.7, 0.4));
    let mut kept = 0;
    for _ in 0..20_000 {
        let tri = [0; 3].map(|_| DVec3::new(f(&mut rng), f(&mut rng), f(&mut rng)) * 2.0 - 1.0);
        let out = clip_polygon_box(&tri, lo, hi);
        for p in &out {
            assert!(
                p.cmpge(lo).all() && p.cmple(hi).all(),
                "{p} outside the box"
            );
            // On the triangle's plane.
            let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
            assert!(
                n.dot(*p - tri[0]).abs() <= 1e-12 * n.length(),
                "{p} off the plane"
            );
        }
        kept += !out.is_empty() as u32;
        assert_eq!(
            clip_polygon_box(&out, lo, hi),
            out,
            "box clipping is not idempotent"
        );
    }
    assert!(kept > 2000, "{kept}");
}

/// Random polygons and segments in clip space, in front of, across and
/// behind the camera plane: every output vertex has `w >= MIN_W`, so the
/// divide is always defined, and projects into the view square.
#[test]
fn homogeneous_clipping_never_divides_by_nonpositive_w() {
    let mut rng = Rng(4);
    let mut straddling = 0;
    let mut r = || f(&mut rng) * 4.0 - 2.0;
    for k in 0..20_000 {
        let poly: Vec<DVec4> = (0..3 + k % 3)
            .map(|_| DVec4::new(r(), r(), r(), r()))
            .collect();
        let behind = poly.iter().filter(|p| p.w <= 0.0).count();
        straddling += (behind > 0 && behind < poly.len()) as u32;
        let out = clip_polygon_homogeneous(&poly);
        for p in &out {
            assert!(p.w >= MIN_W, "vertex {p} with w below the minimum");
            let q = project(*p).expect("projectable");
            assert!(
                q.x.abs() <= 1.0 + 1e-9 && q.y.abs() <= 1.0 + 1e-9,
                "{q} outside the view"
            );
        }
        if poly.iter().all(|p| p.w <= 0.0) {
            assert!(out.is_empty(), "a polygon behind the camera survived");
        }
        let (a, b) = (poly[0], poly[1]);
        if let Some((t0, t1, p, q)) = clip_line_homogeneous(a, b) {
            assert!(p.w >= MIN_W && q.w >= MIN_W);
            assert!(0.0 <= t0 && t0 <= t1 && t1 <= 1.0);
            // Points inside the view volume along the segment lie in [t0, t1].
            for i in 0..=64 {
                let t = i as f64 / 64.0;
                let s = a + (b - a) * t;
                if s.w >= MIN_W && s.x.abs() <= s.w && s.y.abs() <= s.w {
                    assert!(
                        t >= t0 - 1e-9 && t <= t1 + 1e-9,
                        "{a} {b}: t = {t} inside but outside [{t0}, {t1}]"
                    );
                }
            }
        }
    }
    assert!(straddling > 5000, "{straddling}");
    assert_eq!(project(DVec4::new(1.0, 1.0, 1.0, 0.0)), None);
    assert_eq!(project(DVec4::new(1.0, 1.0, 1.0, -1.0)), None);
}
