//! Measures the photon lookup of one progressive-photon-mapping iteration
//! (every query with the same radius) with the hashed grid Prism uses
//! against a balanced kd-tree (median splits on the widest axis, the
//! classic photon-map layout) and brute force: build time, query time and
//! the candidates examined per query. Photons lie on the six faces of a
//! 5.5-unit box (the Cornell box's size), queries at random points on them.
//!
//! `cargo run --release --example photon_lookup -- [PHOTONS] [RADIUS]`

use std::time::Instant;

use glam::Vec3A;
use prism::core::rng::Sampler;
use prism::transport::photon::grid::HashGrid;

/// A point on a random face of the box `[0, 5.5]^3`.
fn on_box(seed: u64, i: u32) -> Vec3A {
    let mut s = Sampler::new(seed, i, 0);
    let (face, u, v) = (
        (s.next_f32() * 6.0) as u32 % 6,
        s.next_f32() * 5.5,
        s.next_f32() * 5.5,
    );
    let w = if face % 2 == 0 { 0.0 } else { 5.5 };
    match face / 2 {
        0 => Vec3A::new(w, u, v),
        1 => Vec3A::new(u, w, v),
        _ => Vec3A::new(u, v, w),
    }
}

/// Balanced kd-tree stored implicitly: the median of each range is its
/// node, split on the range's widest axis.
struct KdTree {
    points: Vec<Vec3A>,
    axes: Vec<u8>,
}

impl KdTree {
    fn build(mut points: Vec<Vec3A>) -> Self {
        let mut axes = vec![0u8; points.len()];
        fn rec(p: &mut [Vec3A], a: &mut [u8]) {
            if p.len() <= 1 {
                return;
            }
            let (lo, hi) = p.iter().fold(
                (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)),
                |(l, h), &x| (l.min(x), h.max(x)),
            );
            let e = hi - lo;
            let axis = if e.x >= e.y && e.x >= e.z {
                0
            } else if e.y >= e.z {
                1
            } else {
                2
            };
            let m = p.len() / 2;
            p.select_nth_unstable_by(m, |x, y| x[axis].total_cmp(&y[axis]));
            a[m] = axis as u8;
            let (pl, pr) = p.split_at_mut(m);
            let (al, ar) = a.split_at_mut(m);
            rec(pl, al);
            rec(&mut pr[1..], &mut ar[1..]);
        }
        rec(&mut points, &mut axes);
        Self { points, axes }
    }

    fn query(&self, q: Vec3A, r: f32, f: &mut impl FnMut(Vec3A)) {
        fn rec(t: &KdTree, lo: usize, hi: usize, q: Vec3A, r: f32, f: &mut impl FnMut(Vec3A)) {
            if lo >= hi {
                return;
            }
            let m = lo + (hi - lo) / 2;
            let p = t.points[m];
            f(p);
            let axis = t.axes[m] as usize;
            let d = q[axis] - p[axis];
            if d <= r {
                rec(t, lo, m, q, r, f);
            }
            if d >= -r {
                rec(t, m + 1, hi, q, r, f);
            }
        }
        rec(self, 0, self.points.len(), q, r, f);
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(500_000);
    let r: f32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.05);
    let points: Vec<Vec3A> = (0..n).map(|i| on_box(1, i)).collect();
    let queries: Vec<Vec3A> = (0..200_000).map(|i| on_box(2, i)).collect();
    let r2 = r * r;
    for round in 0..3 {
        let t = Instant::now();
        let grid = HashGrid::build(points.iter().copied(), r);
        let grid_build = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (mut found, mut visited) = (0u64, 0u64);
        for &q in &queries {
            grid.candidates(q, |i| {
                visited += 1;
                found += (points[i as usize].distance_squared(q) <= r2) as u64;
            });
        }
        let grid_query = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let tree = KdTree::build(points.clone());
        let tree_build = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (mut found_t, mut visited_t) = (0u64, 0u64);
        for &q in &queries {
            tree.query(q, r, &mut |p| {
                visited_t += 1;
                found_t += (p.distance_squared(q) <= r2) as u64;
            });
        }
        let tree_query = t.elapsed().as_secs_f64();
        assert_eq!(found, found_t, "the two structures disagree");
        let nq = queries.len() as f64;
        println!(
            "round {round}: {n} photons, r {r}, {:.1} found per query | grid: build {:.1} ms, query {:.2} us, {:.1} candidates | kd-tree: build {:.1} ms, query {:.2} us, {:.1} nodes visited",
            found as f64 / nq,
            grid_build * 1e3,
            grid_query / nq * 1e6,
            visited as f64 / nq,
            tree_build * 1e3,
            tree_query / nq * 1e6,
            visited_t as f64 / nq,
        );
    }
    // Brute force on a few queries, for scale.
    let t = Instant::now();
    let mut found_b = 0u64;
    for &q in &queries[..200] {
        found_b += points
            .iter()
            .filter(|p| p.distance_squared(q) <= r2)
            .count() as u64;
    }
    println!(
        "brute force: query {:.1} us ({:.1} found per query)",
        t.elapsed().as_secs_f64() / 200.0 * 1e6,
        found_b as f64 / 200.0
    );
}
