//! Form factors between patches, by two estimators.
//!
//! * **Ray cast** (the default): `F_ij = U_ij V_ij`. The unoccluded term
//!   `U_ij` averages over patch `i` the *analytic* form factor from a
//!   differential area at a point of `i` to the triangle `j` (Lambert's
//!   contour formula, after clipping `j` to the half-space above the
//!   point), by the midpoint rule on `i`'s `K = 4^l` sub-triangles,
//!   for pairs closer than [`NEAR_DISTANCE`] times the sum of their sizes
//!   each split further (up to [`MAX_EXTRA_DEPTH`] times) while the term
//!   at its centroid and the mean at its corners differ by more than
//!   [`QUADRATURE_TOLERANCE`] of the patch: that happens near a touching
//!   neighbour, where the term is least smooth. The visibility `V_ij` is
//!   measured by `K` rays, from the sub-triangles' centroids `x_k` to `K`
//!   points of `j` (its own sub-triangles' centroids, paired by an index
//!   shift that depends on `i + j`), each weighted by the point term at
//!   its origin: `V_ij = sum_k F(x_k) v_k / sum_k F(x_k)`. Unoccluded
//!   pairs are exact up to the quadrature.
//! * **Hemicube** (Cohen and Greenberg 1985): a half-cube of `res x res`
//!   pixels on top and `res x res/2` on each side, centred at the patch's
//!   centroid; each pixel's delta form factor goes to the patch seen
//!   through it. We find that patch by casting a ray through the pixel's
//!   centre (instead of rasterising every patch with a z-buffer): the
//!   same sampling of the hemisphere, with exact visibility per pixel.
//!
//! The ray-cast estimate is reciprocal by construction: each unordered
//! pair is estimated once, as the area form factor
//! `G_ij = (A_i U_ij + A_j U_ji) / 2 * V_ij` (the unoccluded term from
//! both sides, averaged; the visibility, which is symmetric, from one set
//! of rays), and `F_ij = G_ij / A_i`, `F_ji = G_ij / A_j`, so
//! `A_i F_ij = A_j F_ji` holds to rounding. Both unoccluded terms are
//! accurate, so rows still sum to 1 in a closed scene. The hemicube's rows are kept as they are: a hemicube
//! at the centroid misjudges touching neighbours (the form factor at the
//! centre is not the patch's mean), and averaging the two directions
//! would spread that error into the row sums, which the hemicube gets
//! right up to its pixel sampling. Progressive refinement with hemicubes
//! shoots with `F_ji = A_i F_ij / A_j`, as Cohen et al. (1988) did.
//!
//! The matrix is stored sparse (compressed rows): pairs that cannot see
//! each other (each behind the other's plane) take no memory.

use std::f32::consts::PI;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::Vec3A;
use rayon::prelude::*;

use super::patches::{Patches, centroid, split_corners};
use crate::core::math::{Ray, orthonormal_basis};
use crate::core::optics::offset_origin_relative;
use crate::geometry::mesh::Mesh;

pub use crate::core::radiosity::Estimator;

/// The form factor matrix, rows in compressed sparse form.
#[derive(Clone, Debug, Default)]
pub struct FormFactors {
    /// Row `i` is `cols[offsets[i]..offsets[i + 1]]`.
    pub offsets: Vec<usize>,
    /// Column (receiving patch) of each entry, increasing within a row.
    pub cols: Vec<u32>,
    /// `F_ij` of each entry.
    pub vals: Vec<f32>,
}

impl FormFactors {
    /// Entries `(j, F_ij)` of row `i`.
    #[inline]
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f32)> + '_ {
        let r = self.offsets[i]..self.offsets[i + 1];
        self.cols[r.clone()]
            .iter()
            .zip(&self.vals[r])
            .map(|(&j, &f)| (j as usize, f))
    }

    /// `F_ij` (zero when not stored).
    pub fn get(&self, i: usize, j: usize) -> f32 {
        let r = self.offsets[i]..self.offsets[i + 1];
        match self.cols[r.clone()].binary_search(&(j as u32)) {
            Ok(k) => self.vals[r.start + k],
            Err(_) => 0.0,
        }
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Stored entries.
    pub fn entries(&self) -> usize {
        self.cols.len()
    }

    /// Bytes of the stored matrix.
    pub fn bytes(&self) -> usize {
        self.offsets.len() * std::mem::size_of::<usize>() + self.cols.len() * 8
    }

    /// Builds the matrix from sparse rows sorted by column, as they are.
    pub fn from_rows(rows: Vec<Vec<(u32, f32)>>) -> Self {
        let mut out = FormFactors {
            offsets: vec![0],
            ..Default::default()
        };
        for row in rows {
            for (j, f) in row {
                out.cols.push(j);
                out.vals.push(f);
            }
            out.offsets.push(out.cols.len());
        }
        out
    }

    /// Builds the reciprocal matrix from the upper triangle of the area
    /// form factors `G_ij = A_i F_ij = A_j F_ji` (`upper[i]` holds the
    /// entries `(j, G_ij)` for `j > i`, sorted): `F_ij = G_ij / A_i`.
    pub fn from_symmetric(upper: Vec<Vec<(u32, f32)>>, area: &[f32]) -> Self {
        let n = upper.len();
        // lower[j] holds (i, G_ij) for i < j, i increasing.
        let mut lower: Vec<Vec<(u32, f32)>> = vec![Vec::new(); n];
        for (i, row) in upper.iter().enumerate() {
            for &(j, g) in row {
                lower[j as usize].push((i as u32, g));
            }
        }
        let mut out = FormFactors {
            offsets: vec![0],
            ..Default::default()
        };
        for i in 0..n {
            for &(j, g) in lower[i].iter().chain(&upper[i]) {
                out.cols.push(j);
                out.vals.push(g / area[i]);
            }
            out.offsets.push(out.cols.len());
        }
        out
    }
}

/// Clips polygon `poly` to the half-space `n . (y - x) > 0`.
fn clip_above(poly: &[Vec3A], x: Vec3A, n: Vec3A, out: &mut Vec<Vec3A>) {
    out.clear();
    let k = poly.len();
    for a in 0..k {
        let (p, q) = (poly[a], poly[(a + 1) % k]);
        let (dp, dq) = (n.dot(p - x), n.dot(q - x));
        if dp > 0.0 {
            out.push(p);
        }
        if (dp > 0.0) != (dq > 0.0) && dp != dq {
            let t = dp / (dp - dq);
            out.push(p + (q - p) * t);
        }
    }
}

/// Unoccluded form factor from a differential area at `x` with unit
/// normal `n` to the convex polygon `poly` lying in front of it (Lambert's
/// contour integral): `1/(2 pi) |sum_k angle_k n . unit(R_k x R_k+1)|`.
pub fn point_to_polygon(x: Vec3A, n: Vec3A, poly: &[Vec3A]) -> f32 {
    let k = poly.len();
    let mut sum = 0.0f32;
    for a in 0..k {
        let r0 = (poly[a] - x).normalize_or_zero();
        let r1 = (poly[(a + 1) % k] - x).normalize_or_zero();
        let c = r0.cross(r1);
        let len = c.length();
        if len > 0.0 {
            let angle = len.atan2(r0.dot(r1));
            sum += angle * n.dot(c) / len;
        }
    }
    sum.abs() / (2.0 * PI)
}

/// Form factor from point `x` (normal `n`) to the part of triangle `tri`
/// above its tangent plane, with `scratch` for the clipped polygon.
#[inline]
pub fn point_to_triangle(x: Vec3A, n: Vec3A, tri: &[Vec3A; 3], scratch: &mut Vec<Vec3A>) -> f32 {
    clip_above(tri, x, n, scratch);
    if scratch.len() < 3 {
        return 0.0;
    }
    point_to_polygon(x, n, scratch)
}

/// The centroids of the `4^level` sub-triangles of `tri` (its midpoint
/// subdivision `level` times), in a fixed order.
pub fn quadrature_points(tri: [Vec3A; 3], level: u32) -> Vec<Vec3A> {
    sub_triangles(tri, level).iter().map(centroid).collect()
}

/// The `4^level` sub-triangles of `tri`, in a fixed order.
pub fn sub_triangles(tri: [Vec3A; 3], level: u32) -> Vec<[Vec3A; 3]> {
    let mut tris = vec![tri];
    for _ in 0..level {
        tris = tris.into_iter().flat_map(split_corners).collect();
    }
    tris
}

/// True when patch `j` lies wholly on or behind the plane of patch `i`.
#[inline]
fn behind(ci: &[Vec3A; 3], ni: Vec3A, cj: &[Vec3A; 3]) -> bool {
    let o = centroid(ci);
    let size = (ci[1] - ci[0]).length().max((ci[2] - ci[0]).length());
    let eps = 1e-5 * size;
    cj.iter().all(|&y| ni.dot(y - o) <= eps)
}

/// Pairs whose centroids are closer than this times the sum of their
/// sizes (longest edges) integrate the unoccluded term adaptively; the
/// others use the midpoint rule on the quadrature level's pieces.
pub const NEAR_DISTANCE: f32 = 4.0;

/// Longest edge of a triangle.
#[inline]
fn size(c: &[Vec3A; 3]) -> f32 {
    (c[1] - c[0])
        .length()
        .max((c[2] - c[1]).length())
        .max((c[0] - c[2]).length())
}

/// Deepest extra subdivision of the sending patch for the unoccluded term.
pub const MAX_EXTRA_DEPTH: u32 = 6;

/// A piece of the sending patch is subdivided when its share of the
/// patch's area times the difference between the point form factor at
/// its centroid and the mean at its corners exceeds this.
pub const QUADRATURE_TOLERANCE: f32 = 2e-6;

/// Point form factor from `x` (normal `ni`) to triangle `cj` (normal
/// `nj`, centroid `oj`): zero unless `j` faces `x`.
#[inline]
fn point_term(
    x: Vec3A,
    ni: Vec3A,
    cj: &[Vec3A; 3],
    nj: Vec3A,
    oj: Vec3A,
    scratch: &mut Vec<Vec3A>,
) -> f32 {
    if nj.dot(x - oj) <= 0.0 {
        return 0.0;
    }
    point_to_triangle(x, ni, cj, scratch)
}

/// The unoccluded form factor from the piece `t` of the sending patch,
/// `weight` being its share of the patch's area: the point term at its
/// centroid, subdivided where the term changes over the piece (near a
/// touching neighbour, where it is least smooth).
#[allow(clippy::too_many_arguments)]
fn unoccluded(
    t: [Vec3A; 3],
    weight: f32,
    depth: u32,
    ni: Vec3A,
    cj: &[Vec3A; 3],
    nj: Vec3A,
    oj: Vec3A,
    scratch: &mut Vec<Vec3A>,
) -> f32 {
    let fc = point_term(centroid(&t), ni, cj, nj, oj, scratch);
    if depth < MAX_EXTRA_DEPTH {
        let corners: f32 = t
            .iter()
            .map(|&x| point_term(x, ni, cj, nj, oj, scratch))
            .sum::<f32>()
            / 3.0;
        if weight * (fc - corners).abs() > QUADRATURE_TOLERANCE {
            return split_corners(t)
                .into_iter()
                .map(|c| unoccluded(c, 0.25 * weight, depth + 1, ni, cj, nj, oj, scratch))
                .sum();
        }
    }
    weight * fc
}

/// The unoccluded term `U_ij` over the pieces `pieces` of `i` (midpoint
/// rule, adaptive when `near`), and the point terms at their centroids
/// `xs` (written to `fx`).
#[allow(clippy::too_many_arguments)]
fn unoccluded_term(
    ni: Vec3A,
    cj: &[Vec3A; 3],
    nj: Vec3A,
    pieces: &[[Vec3A; 3]],
    xs: &[Vec3A],
    near: bool,
    fx: &mut Vec<f32>,
    scratch: &mut Vec<Vec3A>,
) -> f32 {
    let oj = centroid(cj);
    fx.clear();
    fx.extend(xs.iter().map(|&x| point_term(x, ni, cj, nj, oj, scratch)));
    let k = xs.len() as f32;
    if near {
        pieces
            .iter()
            .map(|&t| unoccluded(t, 1.0 / k, 0, ni, cj, nj, oj, scratch))
            .sum()
    } else {
        fx.iter().sum::<f32>() / k
    }
}

/// The visibility `V_ij`: rays from the centroids `xs` of `i`'s pieces
/// to the paired points `ys` of `j`, weighted by the point terms `fx`.
fn visibility(
    occluders: &Mesh,
    ni: Vec3A,
    cj: &[Vec3A; 3],
    xs: &[Vec3A],
    ys: &[Vec3A],
    fx: &[f32],
    shift: usize,
) -> f32 {
    let k = xs.len();
    let oj = centroid(cj);
    let (mut seen, mut total) = (0.0f32, 0.0f32);
    let mut clipped = Vec::with_capacity(6);
    for (a, (&x, &f)) in xs.iter().zip(fx).enumerate() {
        if f <= 0.0 {
            continue;
        }
        total += f;
        let mut y = ys[(a + shift) % k];
        if ni.dot(y - x) <= 0.0 {
            // The paired point is below x's horizon: aim at the visible
            // part of j instead.
            clip_above(cj, x, ni, &mut clipped);
            y = clipped.iter().copied().sum::<Vec3A>() / clipped.len().max(1) as f32;
        }
        if !occluders.occluded(&Ray::new(x, y - x), 1e-4, 1.0 - 1e-4) {
            seen += f;
        }
    }
    if total <= 0.0 {
        // No centroid sees j although part of the patch does: one ray
        // from the patch's centre to j's decides.
        let x = xs.iter().copied().sum::<Vec3A>() / k as f32;
        let visible = !occluders.occluded(&Ray::new(x, oj - x), 1e-4, 1.0 - 1e-4);
        return if visible { 1.0 } else { 0.0 };
    }
    seen / total
}

/// Row `i` of the ray-cast estimate for `j > i` only, as sorted sparse
/// entries of the reciprocal area form factor
/// `G_ij = (A_i U_ij + A_j U_ji) / 2 * V_ij` (visibility is symmetric, so
/// each pair casts its rays once).
fn ray_cast_row(
    patches: &Patches,
    occluders: &Mesh,
    points: &[Vec<Vec3A>],
    pieces: &[Vec<[Vec3A; 3]>],
    i: usize,
) -> Vec<(u32, f32)> {
    let ci = patches.corners(i);
    let ni = patches.normal(i);
    let oi = centroid(&ci);
    let si = size(&ci);
    let (mut fi, mut fj) = (Vec::new(), Vec::new());
    let mut scratch = Vec::with_capacity(6);
    let mut row = Vec::new();
    for j in i + 1..patches.len() {
        let cj = patches.corners(j);
        let nj = patches.normal(j);
        if behind(&ci, ni, &cj) || behind(&cj, nj, &ci) {
            continue;
        }
        let near = (centroid(&cj) - oi).length() < NEAR_DISTANCE * (si + size(&cj));
        let uij = unoccluded_term(
            ni,
            &cj,
            nj,
            &pieces[i],
            &points[i],
            near,
            &mut fi,
            &mut scratch,
        );
        let uji = unoccluded_term(
            nj,
            &ci,
            ni,
            &pieces[j],
            &points[j],
            near,
            &mut fj,
            &mut scratch,
        );
        // The same sum whichever row computes it.
        let g = 0.5 * (patches.area[i] * uij + patches.area[j] * uji);
        if !(g > 0.0) {
            continue;
        }
        let v = visibility(occluders, ni, &cj, &points[i], &points[j], &fi, i + j);
        let g = g * v;
        if g > 0.0 {
            row.push((j as u32, g));
        }
    }
    row
}

/// Which patch a ray from a patch's surface hits first: the base
/// triangle hit (the occluder mesh is built from the base triangles in
/// order), the side facing the ray, and the patch there.
#[inline]
pub fn patch_hit(
    patches: &Patches,
    occluders: &Mesh,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
) -> Option<(u32, f32, f32, f32)> {
    let h = occluders.intersect(ray, t_min, t_max)?;
    let base = occluders.input_triangle(h.triangle as usize);
    let n = patches.bases[base as usize].normal;
    let side = if ray.direction.dot(n) < 0.0 { 0 } else { 1 };
    let (p, u, v) = patches.locate(base, side, h.b1, h.b2)?;
    Some((p, u, v, h.t))
}

/// Row `i` of the hemicube estimate at resolution `res` (even).
fn hemicube_row(patches: &Patches, occluders: &Mesh, res: u32, i: usize) -> Vec<(u32, f32)> {
    let n = patches.normal(i);
    let o = offset_origin_relative(centroid(&patches.corners(i)), n);
    let (t, b) = orthonormal_basis(n);
    let mut dense: Vec<(u32, f32)> = Vec::new();
    let da = 4.0 / (res as f32 * res as f32);
    let step = 2.0 / res as f32;
    let mut add = |dir: Vec3A, df: f32| {
        if let Some((p, ..)) = patch_hit(patches, occluders, &Ray::new(o, dir), 0.0, f32::INFINITY)
            && p as usize != i
        {
            dense.push((p, df));
        }
    };
    for py in 0..res {
        let y = -1.0 + (py as f32 + 0.5) * step;
        for px in 0..res {
            let x = -1.0 + (px as f32 + 0.5) * step;
            let r2 = x * x + y * y + 1.0;
            add(t * x + b * y + n, da / (PI * r2 * r2));
        }
    }
    for (axis, other) in [(t, b), (-t, b), (b, t), (-b, t)] {
        for pz in 0..res / 2 {
            let z = (pz as f32 + 0.5) * step;
            for py in 0..res {
                let y = -1.0 + (py as f32 + 0.5) * step;
                let r2 = y * y + z * z + 1.0;
                add(axis + other * y + n * z, z * da / (PI * r2 * r2));
            }
        }
    }
    // Sum the pixels per patch, in patch order.
    dense.sort_by_key(|e| e.0);
    let mut row: Vec<(u32, f32)> = Vec::new();
    for (p, f) in dense {
        match row.last_mut() {
            Some(last) if last.0 == p => last.1 += f,
            _ => row.push((p, f)),
        }
    }
    row
}

/// How the form factors are estimated, with the estimator's quality.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FormFactorMethod {
    /// Ray cast with `4^level` points per patch (and as many rays per pair).
    Raycast {
        /// Quadrature level: 0 (the centroid), 1 (four points), 2, 3.
        level: u32,
    },
    /// Hemicube of `resolution` pixels across its top face.
    Hemicube {
        /// Pixels across the top face (even).
        resolution: u32,
    },
}

/// Computes the reciprocal form factor matrix of `patches`, rows in
/// parallel (each row is a pure function of the patches, so the result
/// does not depend on the thread count). `occluders` is the mesh of the
/// base triangles, in order. `progress(rows)` is called as rows finish.
pub fn compute(
    patches: &Patches,
    occluders: &Mesh,
    method: FormFactorMethod,
    progress: &(dyn Fn(u64) + Sync),
) -> FormFactors {
    let n = patches.len();
    let done = AtomicU64::new(0);
    let tick = || {
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        if d % 64 == 0 || d == n as u64 {
            progress(if d % 64 == 0 { 64 } else { d % 64 });
        }
    };
    match method {
        FormFactorMethod::Raycast { level } => {
            let pieces: Vec<Vec<[Vec3A; 3]>> = (0..n)
                .into_par_iter()
                .map(|p| sub_triangles(patches.corners(p), level))
                .collect();
            let points: Vec<Vec<Vec3A>> = pieces
                .par_iter()
                .map(|t| t.iter().map(centroid).collect())
                .collect();
            let upper: Vec<Vec<(u32, f32)>> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let r = ray_cast_row(patches, occluders, &points, &pieces, i);
                    tick();
                    r
                })
                .collect();
            FormFactors::from_symmetric(upper, &patches.area)
        }
        FormFactorMethod::Hemicube { resolution } => {
            let rows: Vec<Vec<(u32, f32)>> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let r = hemicube_row(patches, occluders, resolution, i);
                    tick();
                    r
                })
                .collect();
            FormFactors::from_rows(rows)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square at distance 1 seen from the point below its corner
    /// has F = (1/2pi)(2 (1/sqrt2) atan(1/sqrt2)) per the standard
    /// corner formula; checked here against four quarter squares summed
    /// (additivity of the contour integral).
    #[test]
    fn point_to_polygon_is_additive_and_matches_the_closed_form() {
        let x = Vec3A::ZERO;
        let n = Vec3A::Y;
        let sq = |x0: f32, z0: f32, s: f32| {
            [
                Vec3A::new(x0, 1.0, z0),
                Vec3A::new(x0 + s, 1.0, z0),
                Vec3A::new(x0 + s, 1.0, z0 + s),
                Vec3A::new(x0, 1.0, z0 + s),
            ]
        };
        // Corner formula for a rectangle a x b at height c above a corner:
        // F = 1/(2pi) [A atan(b A) + B atan(a B)], A = 1/sqrt(a^2+c^2)... with
        // a = b = c = 1: F = (1/2pi) 2 (1/sqrt2) atan(1/sqrt2).
        let exact = (1.0 / (2.0 * PI)) * 2.0 * (0.5f32).sqrt() * (0.5f32).sqrt().atan();
        let f = point_to_polygon(x, n, &sq(0.0, 0.0, 1.0));
        assert!((f - exact).abs() < 1e-6, "{f} vs {exact}");
        let quarters: f32 = [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5)]
            .iter()
            .map(|&(a, b)| point_to_polygon(x, n, &sq(a, b, 0.5)))
            .sum();
        assert!((quarters - f).abs() < 1e-6);
    }
}
