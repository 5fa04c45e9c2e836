//! A uniform grid over boxes, walked cell by cell with the 3D DDA of
//! Amanatides and Woo (1987).
//!
//! **Resolution.** pbrt-v2's rule: `3 N^(1/3)` cells per unit of the
//! largest extent of the `N` boxes' bounds, so the grid has about `27 N`
//! cells for a cube of `N` boxes; each axis gets `round(extent * density)`
//! cells, at least 1 and at most [`MAX_RESOLUTION`].
//!
//! **Cells** list every box that overlaps them (their closed boxes
//! touch), as one array of primitive indices with per-cell offsets.
//!
//! **Traversal.** The ray is clipped to the grid's bounds, its first cell
//! is the one holding the entry point, and the DDA steps along the axis
//! whose next cell boundary is nearest. Everything is computed in double
//! precision from the f32 ray, exactly the ray the primitive tests see.
//! Axes the ray does not move along (`0.0` or `-0.0`) are never stepped.
//! The watertight triangle test may accept a ray that passes up to the
//! node test's margin outside a triangle ([`crate::accel::node::margin`]),
//! so a cell's neighbours are visited too where the ray comes within that
//! margin of the shared face, edge or corner: the walk covers a tube as
//! wide as the margin, and rays along a cell boundary see both sides.
//!
//! **Closest hit.** A hit found in a cell may lie in a later cell (a
//! triangle spanning several): the walk stops only once the next cell
//! starts beyond the closest hit so far (with a few ulps of slack), so
//! equal-`t` hits are all offered and the caller's tie-break decides.
//! Each primitive is tested once per ray ([`crate::accel::mailbox`]).

use glam::{DVec3, Vec3A};

use crate::accel::mailbox::with_mailbox;
use crate::accel::node::margin;
use crate::core::math::Ray;

/// Most cells along one axis.
pub const MAX_RESOLUTION: u32 = 128;

/// Cells per unit of the largest extent per cube root of the box count.
pub const DENSITY: f64 = 3.0;

/// A uniform grid; see the module documentation.
#[derive(Clone, Debug, Default)]
pub struct Grid {
    lo: DVec3,
    hi: DVec3,
    cell: DVec3,
    res: [u32; 3],
    /// Offsets of each cell's list in `prims` (one more than cells).
    starts: Vec<u32>,
    prims: Vec<u32>,
    count: usize,
    magnitude: f32,
}

/// The cells per axis of the rule in the module documentation, for `n`
/// boxes whose bounds have extent `extent`.
pub fn resolution(n: usize, extent: DVec3) -> [u32; 3] {
    let largest = extent.max_element();
    if n == 0 || largest <= 0.0 || !largest.is_finite() {
        return [1, 1, 1];
    }
    let density = DENSITY * (n as f64).cbrt() / largest;
    std::array::from_fn(|a| ((extent[a] * density).round() as u32).clamp(1, MAX_RESOLUTION))
}

impl Grid {
    /// Builds over `boxes` (`(min, max)` per primitive; its index is the
    /// primitive's number). Inverted boxes are listed nowhere.
    pub fn build(boxes: &[(Vec3A, Vec3A)]) -> Self {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut magnitude = 0.0f32;
        for (a, b) in boxes {
            lo = lo.min(a.as_dvec3());
            hi = hi.max(b.as_dvec3());
            magnitude = magnitude.max(a.abs().max(b.abs()).max_element());
        }
        if boxes.is_empty() || lo.cmpgt(hi).any() {
            return Self {
                starts: vec![0, 0],
                res: [1, 1, 1],
                ..Self::default()
            };
        }
        let res = resolution(boxes.len(), hi - lo);
        let cell = (hi - lo) / DVec3::new(res[0] as f64, res[1] as f64, res[2] as f64);
        let mut grid = Self {
            lo,
            hi,
            cell,
            res,
            starts: Vec::new(),
            prims: Vec::new(),
            count: boxes.len(),
            magnitude,
        };
        let cells = (res[0] * res[1] * res[2]) as usize;
        // Two passes: count, then fill (counting sort by cell).
        let mut counts = vec![0u32; cells + 1];
        let ranges: Vec<Option<([u32; 3], [u32; 3])>> =
            boxes.iter().map(|(a, b)| grid.cell_range(*a, *b)).collect();
        for (c0, c1) in ranges.iter().flatten() {
            for z in c0[2]..=c1[2] {
                for y in c0[1]..=c1[1] {
                    for x in c0[0]..=c1[0] {
                        counts[grid.index([x, y, z]) + 1] += 1;
                    }
                }
            }
        }
        for i in 0..cells {
            counts[i + 1] += counts[i];
        }
        let mut fill = counts.clone();
        let mut prims = vec![0u32; counts[cells] as usize];
        for (p, r) in ranges.iter().enumerate() {
            let Some((c0, c1)) = r else { continue };
            for z in c0[2]..=c1[2] {
                for y in c0[1]..=c1[1] {
                    for x in c0[0]..=c1[0] {
                        let i = grid.index([x, y, z]);
                        prims[fill[i] as usize] = p as u32;
                        fill[i] += 1;
                    }
                }
            }
        }
        grid.starts = counts;
        grid.prims = prims;
        grid
    }

    /// Cells per axis.
    pub fn resolution(&self) -> [u32; 3] {
        self.res
    }

    /// Bounds of the grid (the union of the boxes).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        (self.lo, self.hi)
    }

    /// Bytes of the cell arrays.
    pub fn bytes(&self) -> usize {
        (self.starts.len() + self.prims.len()) * 4 + std::mem::size_of::<Self>()
    }

    /// Number of cell references (primitives counted once per cell).
    pub fn references(&self) -> usize {
        self.prims.len()
    }

    /// The primitives listed in cell `c`.
    pub fn cell_prims(&self, c: [u32; 3]) -> &[u32] {
        let i = self.index(c);
        &self.prims[self.starts[i] as usize..self.starts[i + 1] as usize]
    }

    #[inline(always)]
    fn index(&self, c: [u32; 3]) -> usize {
        ((c[2] * self.res[1] + c[1]) * self.res[0] + c[0]) as usize
    }

    /// The cell holding coordinate `v` on axis `a`, clamped to the grid.
    #[inline(always)]
    fn coord(&self, v: f64, a: usize) -> u32 {
        let c = ((v - self.lo[a]) / self.cell[a]).floor();
        if c >= 0.0 {
            (c as u32).min(self.res[a] - 1)
        } else {
            0
        }
    }

    /// Cells overlapped by the closed box `(a, b)`, or `None` if inverted
    /// or not finite.
    fn cell_range(&self, a: Vec3A, b: Vec3A) -> Option<([u32; 3], [u32; 3])> {
        if !(a.cmple(b).all() && a.is_finite() && b.is_finite()) {
            return None;
        }
        let (a, b) = (a.as_dvec3(), b.as_dvec3());
        Some((
            std::array::from_fn(|k| self.coord(a[k], k)),
            std::array::from_fn(|k| self.coord(b[k], k)),
        ))
    }

    /// Lower boundary of cell `c` on axis `a`.
    #[inline(always)]
    fn plane(&self, a: usize, c: i64) -> f64 {
        if c >= self.res[a] as i64 {
            self.hi[a]
        } else {
            self.lo[a] + c as f64 * self.cell[a]
        }
    }

    /// Walks the cells `ray` crosses within `[t_min, t_max]` in order.
    ///
    /// `visit(prim, t_max)` tests primitive `prim` (each at most once per
    /// ray) and returns the `t` of a hit it accepts (nearer than `t_max`
    /// or, for its own tie-break, equal), which becomes the new `t_max`.
    /// With `any_hit` the walk ends at the first hit. Returns whether
    /// any primitive was hit.
    pub fn traverse(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        any_hit: bool,
        mut visit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> bool {
        if self.prims.is_empty() {
            return false;
        }
        let o = ray.origin.as_dvec3();
        let d = ray.direction.as_dvec3();
        let pad = margin(ray.origin.abs().max_element(), self.magnitude) as f64;
        // Clip the ray to the grid's bounds grown by the margin.
        let (mut t0, mut t1) = (t_min as f64, t_max as f64);
        for a in 0..3 {
            let (lo, hi) = (self.lo[a] - pad, self.hi[a] + pad);
            if d[a] == 0.0 {
                if o[a] < lo || o[a] > hi {
                    return false;
                }
            } else {
                let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        if !(t0 <= t1) {
            return false;
        }
        let start = o + d * t0;
        let mut cell: [i64; 3] = std::array::from_fn(|a| self.coord(start[a], a) as i64);
        let step: [i64; 3] = std::array::from_fn(|a| {
            if d[a] > 0.0 {
                1
            } else if d[a] < 0.0 {
                -1
            } else {
                0
            }
        });
        // Parameter of the next boundary crossing on each axis.
        let next = |cell: &[i64; 3], a: usize| -> f64 {
            match step[a] {
                0 => f64::INFINITY,
                1 => (self.plane(a, cell[a] + 1) - o[a]) / d[a],
                _ => (self.plane(a, cell[a]) - o[a]) / d[a],
            }
        };
        let mut t_next: [f64; 3] = std::array::from_fn(|a| next(&cell, a));
        let mut best = t_max;
        let mut any = false;
        with_mailbox(self.count, |mb| {
            let mut t_in = t0;
            loop {
                // The axis of the next step and where the ray leaves the cell.
                let a = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                    0
                } else if t_next[1] <= t_next[2] {
                    1
                } else {
                    2
                };
                let t_out = t_next[a].min(t1);
                let continues = t_next[a] < t1;
                // This cell and, where the ray comes within the margin of a
                // face, the neighbours across it (per axis -1, 0 or +1); the
                // next cell of the walk is left to the next step.
                let mut range = [(0i64, 0i64); 3];
                for k in 0..3 {
                    let (xa, xb) = (o[k] + d[k] * t_in, o[k] + d[k] * t_out);
                    let (lo, hi) = (xa.min(xb), xa.max(xb));
                    let c = cell[k];
                    let below = c > 0 && lo - pad <= self.plane(k, c);
                    let above = c + 1 < self.res[k] as i64 && hi + pad >= self.plane(k, c + 1);
                    range[k] = (c - below as i64, c + above as i64);
                }
                let mut skip = cell;
                skip[a] += step[a];
                for z in range[2].0..=range[2].1 {
                    for y in range[1].0..=range[1].1 {
                        for x in range[0].0..=range[0].1 {
                            if continues && [x, y, z] == skip {
                                continue;
                            }
                            for &p in self.cell_prims([x as u32, y as u32, z as u32]) {
                                if !mb.first_visit(p) {
                                    continue;
                                }
                                if let Some(t) = visit(p, best) {
                                    best = t;
                                    any = true;
                                    if any_hit {
                                        return;
                                    }
                                }
                            }
                        }
                    }
                }
                if !continues {
                    return;
                }
                cell[a] += step[a];
                if cell[a] < 0 || cell[a] >= self.res[a] as i64 {
                    return;
                }
                t_in = t_out;
                t_next[a] = next(&cell, a);
                // A hit at or before `best` lies in a cell entered by now or,
                // within the margin, across the face just crossed: stop
                // once this cell starts beyond that.
                if any {
                    let b = best as f64;
                    if t_in > b + 8.0 * f32::EPSILON as f64 * b.abs() + pad / d[a].abs() {
                        return;
                    }
                }
            }
        });
        any
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the segment `o + d t`, `t` in `[t0, t1]`, meets the box
    /// `[lo, hi]` (slabs in f64).
    fn meets(o: DVec3, d: DVec3, t0: f64, t1: f64, lo: DVec3, hi: DVec3) -> bool {
        let (mut a, mut b) = (t0, t1);
        for k in 0..3 {
            if d[k] == 0.0 {
                if o[k] < lo[k] || o[k] > hi[k] {
                    return false;
                }
            } else {
                let (p, q) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
                a = a.max(p.min(q));
                b = b.min(p.max(q));
            }
        }
        a <= b
    }

    /// The walk's contract: every primitive whose box, grown by half the
    /// margin on each axis, meets the ray within `[t_min, t_max]` is
    /// offered to `visit`, once (the margin covers what the watertight
    /// test accepts outside a triangle). Slabs end 1e-4 before a cell
    /// boundary in x; rays from 1.5e3 away (margin 2e-3 to 3e-3) that do not
    /// move in x pass up to 8e-4 beyond the boundary: they never cross
    /// the slabs' cells, and only the visit of the neighbours within the
    /// margin offers those slabs.
    #[test]
    fn every_primitive_within_the_margin_is_offered() {
        let mut rng = crate::core::rng::Sampler::new(99, 0, 0);
        let mut next = || rng.next_f32();
        // 998 slabs and two corner specks: bounds the unit cube, 30 cells
        // per axis (3 * 1000^(1/3)).
        let n = 1000;
        let res = 30u32;
        let boundary = |i: u32| i as f64 / res as f64;
        let mut boxes: Vec<(Vec3A, Vec3A)> = vec![
            (Vec3A::ZERO, Vec3A::splat(1e-3)),
            (Vec3A::splat(1.0 - 1e-3), Vec3A::ONE),
        ];
        while boxes.len() < n {
            let i = 1 + (next() * (res - 1) as f32) as u32 % (res - 1);
            let x1 = (boundary(i) - 1e-4) as f32;
            let (y, z) = (next() * 0.8, next() * 0.8);
            boxes.push((
                Vec3A::new(x1 - 0.01, y, z),
                Vec3A::new(x1, y + 0.2, z + 0.2),
            ));
        }
        let grid = Grid::build(&boxes);
        assert_eq!(grid.resolution(), [res; 3]);
        let (mut beyond, mut offered_total) = (0, 0);
        for _ in 0..1000 {
            let i = 1 + (next() * (res - 1) as f32) as u32 % (res - 1);
            let x = (boundary(i) + 1e-5 + next() as f64 * 6e-4) as f32;
            let target = Vec3A::new(x, next(), next());
            let (dy, dz) = (next() - 0.5, next() - 0.5);
            let away = Vec3A::new(0.0, dy, dz).normalize_or(Vec3A::Y);
            let o = target + away * 1.5e3;
            let ray = Ray::new(o, target - o);
            assert_eq!(ray.direction.x, 0.0);
            let (t_min, t_max) = (0.0f32, 2.0f32);
            let pad = margin(o.abs().max_element(), grid.magnitude) as f64;
            assert!(pad > 1.9e-3 && pad < 0.1 / res as f64, "{pad}");
            let mut offered = vec![0u32; boxes.len()];
            grid.traverse(&ray, t_min, t_max, false, |p, _| {
                offered[p as usize] += 1;
                None
            });
            let (ro, rd) = (ray.origin.as_dvec3(), ray.direction.as_dvec3());
            for (p, (a, b)) in boxes.iter().enumerate() {
                let (a, b) = (a.as_dvec3(), b.as_dvec3());
                let half = DVec3::splat(0.5 * pad);
                if meets(ro, rd, t_min as f64, t_max as f64, a - half, b + half) {
                    assert_eq!(offered[p], 1, "box {p} within the margin of {ray:?}");
                    // Its cells end before the ray's.
                    beyond += (b.x < boundary(i) && ro.x > boundary(i)) as u32;
                }
                assert!(offered[p] <= 1, "box {p} offered twice");
            }
            offered_total += offered.iter().sum::<u32>();
        }
        // Slabs in cells the ray never enters, within the margin, occur.
        assert!(beyond > 50, "{beyond} slabs beyond a cell boundary");
        assert!(offered_total > 1000);
    }
}
