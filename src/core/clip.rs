//! Line clipping: the parametric range of a 2D segment inside an
//! axis-aligned rectangle (Liang and Barsky 1984).

use glam::Vec2;

/// The parameter range `[t0, t1]` of the segment `a + t (b - a)`,
/// `t` in `[0, 1]`, that lies inside the rectangle `[lo, hi]` (boundary
/// included), or `None` when no part of it does.
pub fn clip_segment(a: Vec2, b: Vec2, lo: Vec2, hi: Vec2) -> Option<(f32, f32)> {
    let d = b - a;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    // Each boundary as p t <= q: p < 0 enters, p > 0 leaves.
    for (p, q) in [
        (-d.x, a.x - lo.x),
        (d.x, hi.x - a.x),
        (-d.y, a.y - lo.y),
        (d.y, hi.y - a.y),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some((t0, t1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_are_clipped_to_the_rectangle() {
        let (lo, hi) = (Vec2::ZERO, Vec2::new(10.0, 5.0));
        // Inside: untouched.
        assert_eq!(
            clip_segment(Vec2::new(1.0, 1.0), Vec2::new(9.0, 4.0), lo, hi),
            Some((0.0, 1.0))
        );
        // Crossing the left and right sides.
        let (t0, t1) = clip_segment(Vec2::new(-10.0, 2.0), Vec2::new(20.0, 2.0), lo, hi).unwrap();
        assert!((t0 - 1.0 / 3.0).abs() < 1e-6 && (t1 - 2.0 / 3.0).abs() < 1e-6);
        // Outside, parallel to a side, and passing a corner.
        assert_eq!(
            clip_segment(Vec2::new(-1.0, 6.0), Vec2::new(11.0, 6.0), lo, hi),
            None
        );
        assert_eq!(
            clip_segment(Vec2::new(-2.0, 4.0), Vec2::new(4.0, 10.0), lo, hi),
            None
        );
        // Brute force against sampling along random-ish segments.
        for k in 0..200 {
            let f = |i: u32| ((k * 7919 + i * 104_729) % 1000) as f32 / 1000.0 * 30.0 - 10.0;
            let (a, b) = (Vec2::new(f(1), f(2)), Vec2::new(f(3), f(4)));
            let inside = |t: f32| {
                let p = a + (b - a) * t;
                p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y
            };
            let got = clip_segment(a, b, lo, hi);
            for i in 0..=1000 {
                let t = i as f32 / 1000.0;
                let want = inside(t);
                let within = got.is_some_and(|(t0, t1)| t >= t0 - 1e-4 && t <= t1 + 1e-4);
                let strictly = got.is_some_and(|(t0, t1)| t > t0 + 1e-4 && t < t1 - 1e-4);
                assert!(
                    !want || within,
                    "segment {k} at {t}: inside but clipped away"
                );
                assert!(want || !strictly, "segment {k} at {t}: outside but kept");
            }
        }
    }
}
