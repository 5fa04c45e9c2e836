//! Closest hits and occlusion of many rays at once against every
//! triangle of a scene that is one small merged mesh (the glTF Cornell
//! box: 38 triangles, see `crate::scene::merged`), for the wavefront,
//! which has the rays of a whole bounce, and many hits' shadow rays, at
//! hand.
//!
//! The rays are sorted by the axis permutation of their watertight test
//! (six kinds), and sixteen rays of one kind meet each triangle side by
//! side, one SIMD lane each (one AVX-512 register, two AVX2 ones), instead
//! of each ray walking the BVH and testing the triangles of every leaf it
//! reaches. Before a triangle's edge test, two conservative tests skip the
//! lanes that cannot hit it within their reach: its padded bounding box
//! (slabs) and its plane (the crossing behind the origin or beyond the
//! nearest hit so far, with room for rounding). In a mesh this small the
//! walls' boxes span the scene and a ray reaches nearly every BVH leaf;
//! the lanes skip more for less.
//!
//! Each lane computes the edge test of [`WatertightRay::intersect8`] with
//! the same float operations on the same values, and a lane that passes
//! it finishes with the same function (`WatertightRay::finish_lane`: the
//! double-precision re-check near edges, the plane distance), so every
//! triangle's `t` and barycentrics are bit for bit the per-ray query's.
//! The per-ray query keeps, among equally near triangles, one chosen by
//! its leaf order and index; a ray whose nearest `t` belongs to two
//! triangles is therefore handed to it ([`RenderScene::intersect`]). The
//! answers are the per-ray queries' in every case (tested on every SIMD
//! path: `tests/kernels/bvh.rs`, `batched_triangles_give_the_per_ray_hits`).
//!
//! Measured (issue 13; 2-core AMD EPYC, path-traced
//! `assets/gltf/cornell.gltf`, 320x240, 32 spp, 16 bounces, alternating
//! runs): the wavefront in 0.83-0.86x the time on the AVX-512 path, 0.91x
//! on the AVX2 path, 0.80x on the portable one. Every triangle tested
//! without the skipping tests was no faster than the BVH (the shadow rays
//! 1.8x slower).
//!
//! The triangles of each BVH leaf are kept together with their joint box
//! (`Cluster`), tested first for the whole group: on the Cornell box
//! its nine leaves are the five walls, the ceiling with the light, and the
//! two blocks in two leaves each, so most lanes skip the blocks' 22
//! triangles at once. One thread, 8 spp, alternating pinned runs with the
//! batch without it (same images): 0.96x the time on the AVX-512 path
//! (11 pairs, ratio of medians; minima 0.95x), 0.98x on the AVX2 path.

use crate::accel::packet::LaneMask;
use crate::core::math::Ray;
use crate::geometry::mesh::MeshHit;
use crate::geometry::triangle::{PermutedLanes16, Tri8, WatertightRay};
use crate::scene::instance::{Hit, LocalHit};
use crate::scene::merged::MERGED;
use crate::scene::render_scene::RenderScene;
use glam::DVec3;

/// Merged meshes of at most this many triangles are tested in batches.
/// Every group of rays pays at least the box test of every triangle, so
/// beyond some size the BVH, which skips whole subtrees, costs less. Only
/// the Cornell box's 38 triangles were measured; the limit is a guess
/// above it.
pub const MAX_TRIANGLES: usize = 64;

/// Rays side by side.
const WIDTH: usize = 16;

/// Kinds of axis permutation ([`WatertightRay::permutation_key`] is
/// below this).
const KINDS: usize = 9;

/// Every triangle of a scene that is one small merged mesh (see the
/// module documentation).
#[derive(Clone, Debug)]
pub struct TriangleBatch<'a> {
    scene: &'a RenderScene,
    blocks: &'a [Tri8],
    /// Every triangle, in the BVH's leaf order (neighbours together;
    /// largest first measured slower, 1.01x the time).
    tris: Vec<TriCull>,
    /// The triangles of each leaf block with their joint box: a group
    /// tests a block's triangles only with the lanes that may meet it.
    clusters: Vec<Cluster>,
}

/// The triangles `tris[start..end]` of one leaf block and the smallest box
/// holding their padded boxes. A lane that this box leaves out (the same
/// test, [`Rays16::crossing`]) is left out by each triangle's own box:
/// the slab distances are monotone in the box's faces (each operation is
/// correctly rounded), so the joint box's entry is no later and its exit
/// no earlier; where a slab distance is not a number (a ray in the plane of
/// a face), the ray lies outside every triangle, which sits strictly
/// inside its padded box and so strictly inside the joint one.
#[derive(Clone, Copy, Debug)]
struct Cluster {
    lo: [f32; 3],
    hi: [f32; 3],
    start: u32,
    end: u32,
}

/// One triangle: where its corners are, and what the tests that skip
/// it read.
#[derive(Clone, Copy, Debug)]
struct TriCull {
    /// Its block in [`TriangleBatch::blocks`] and its lane there.
    block: u32,
    lane: u32,
    /// Its bounding box, padded strictly outwards ([`Rays16::crossing`]).
    lo: [f32; 3],
    hi: [f32; 3],
    /// Whether that box differs from its cluster's. When it does not (a
    /// quad's two triangles, whose boxes are the quad's), the cluster's
    /// test has already kept exactly the lanes that the triangle's own
    /// would keep, up to the closer hits found since, which its plane and
    /// edge tests still see: the box test is a filter, never the answer.
    own_box: bool,
    /// Its plane: the normal `(p1 - p0) x (p2 - p0)` rounded to f32, and
    /// `p0` ([`Rays16::crossing_plane`]).
    n: [f32; 3],
    p0: [f32; 3],
    /// The normal in f64, as the edge test's finish computes it
    /// ([`WatertightRay::finish_lane_normal`]).
    nd: DVec3,
}

/// The rays of a call sorted by permutation: `order[starts[k]..starts[k
/// + 1]]` are the indices of the rays of kind `k`.
struct Sorted {
    wt: Vec<WatertightRay>,
    order: Vec<u32>,
    starts: [usize; KINDS + 1],
}

impl Sorted {
    fn new(rays: &[Ray]) -> Self {
        let wt: Vec<WatertightRay> = rays.iter().map(WatertightRay::new).collect();
        let mut count = [0usize; KINDS];
        for w in &wt {
            count[w.permutation_key()] += 1;
        }
        let mut starts = [0usize; KINDS + 1];
        for k in 0..KINDS {
            starts[k + 1] = starts[k] + count[k];
        }
        let mut next = starts;
        let mut order = vec![0u32; rays.len()];
        for (i, w) in wt.iter().enumerate() {
            let k = w.permutation_key();
            order[next[k]] = i as u32;
            next[k] += 1;
        }
        Sorted { wt, order, starts }
    }

    /// Groups of up to [`WIDTH`] ray indices of one kind each.
    fn groups(&self) -> impl Iterator<Item = &[u32]> {
        (0..KINDS).flat_map(move |k| self.order[self.starts[k]..self.starts[k + 1]].chunks(WIDTH))
    }
}

/// Origins, directions and inverse directions of up to 16 rays, one
/// array per coordinate, for the box and plane tests that skip lanes
/// before a triangle's edge test.
struct Rays16 {
    o: [[f32; WIDTH]; 3],
    d: [[f32; WIDTH]; 3],
    inv: [[f32; WIDTH]; 3],
}

/// Relative padding of the triangles' boxes and allowance for the
/// rounding of the slab distances in [`Rays16::crossing`] (each within a
/// few `2^-24` relatively of the exact one, and of the same sign).
const BOX_SLACK: f32 = 1e-5;

impl Rays16 {
    #[inline(always)]
    fn new(group: &[u32], rays: &[Ray]) -> Self {
        let mut r = Rays16 {
            o: [[0.0; WIDTH]; 3],
            d: [[0.0; WIDTH]; 3],
            inv: [[0.0; WIDTH]; 3],
        };
        for l in 0..WIDTH {
            let ray = &rays[group[l.min(group.len() - 1)] as usize];
            for a in 0..3 {
                r.o[a][l] = ray.origin[a];
                r.d[a][l] = ray.direction[a];
                r.inv[a][l] = 1.0 / ray.direction[a];
            }
        }
        r
    }

    /// The lanes whose ray may meet the box `(lo, hi)` at a `t` in
    /// `(0, t_hi]`: a lane is left out only when, allowing for rounding,
    /// its ray misses the box, leaves it behind its origin or enters it
    /// beyond `t_hi`. The box is padded strictly outside its triangle, so
    /// a ray along a padded face (a zero direction component, where the
    /// slab distances are not numbers) misses the triangle.
    #[inline(always)]
    fn crossing<const AVX512: bool>(
        &self,
        lo: &[f32; 3],
        hi: &[f32; 3],
        t_hi: &[f32; WIDTH],
    ) -> LaneMask {
        #[cfg(target_arch = "x86_64")]
        if AVX512 {
            // SAFETY: `AVX512` is set only inside the AVX-512 entry points.
            #[allow(unsafe_code)]
            return unsafe { self.crossing_avx512(lo, hi, t_hi) };
        }
        let mut lanes = 0;
        #[allow(clippy::needless_range_loop)] // l indexes lanes of several arrays
        for l in 0..WIDTH {
            let mut near = f32::NEG_INFINITY;
            let mut far = f32::INFINITY;
            for a in 0..3 {
                let t0 = (lo[a] - self.o[a][l]) * self.inv[a][l];
                let t1 = (hi[a] - self.o[a][l]) * self.inv[a][l];
                near = near.max(t0.min(t1));
                far = far.min(t0.max(t1));
            }
            let slack = 1.0 + BOX_SLACK;
            let miss = near > far * slack || far < 0.0 || near > t_hi[l] * slack;
            lanes |= (!miss as LaneMask) << l;
        }
        lanes
    }

    /// The lanes that may cross the plane of normal `n` through `p` at a
    /// `t` in `(0, t_hi]`: a lane is left out only when the crossing is
    /// certainly behind its origin (or parallel) or beyond `t_hi` even
    /// allowing for rounding, so the triangle's exact test
    /// (`WatertightRay::finish_lane`, whose plane distance is the
    /// double-precision `n . (p0 - o) / n . d`) could not hit there.
    #[inline(always)]
    fn crossing_plane<const AVX512: bool>(
        &self,
        n: &[f32; 3],
        p: &[f32; 3],
        t_hi: &[f32; WIDTH],
    ) -> LaneMask {
        #[cfg(target_arch = "x86_64")]
        if AVX512 {
            // SAFETY: `AVX512` is set only inside the AVX-512 entry points.
            #[allow(unsafe_code)]
            return unsafe { self.crossing_plane_avx512(n, p, t_hi) };
        }
        let mut lanes = 0;
        #[allow(clippy::needless_range_loop)] // l indexes lanes of several arrays
        for l in 0..WIDTH {
            let r = [
                p[0] - self.o[0][l],
                p[1] - self.o[1][l],
                p[2] - self.o[2][l],
            ];
            let num = n[0] * r[0] + n[1] * r[1] + n[2] * r[2];
            let num_err = BOX_SLACK
                * (n[0].abs() * r[0].abs() + n[1].abs() * r[1].abs() + n[2].abs() * r[2].abs());
            let (dx, dy, dz) = (self.d[0][l], self.d[1][l], self.d[2][l]);
            let den = n[0] * dx + n[1] * dy + n[2] * dz;
            let den_err =
                BOX_SLACK * (n[0].abs() * dx.abs() + n[1].abs() * dy.abs() + n[2].abs() * dz.abs());
            let behind = (num > num_err && den < -den_err) || (num < -num_err && den > den_err);
            let beyond = num.abs() - num_err > (den.abs() + den_err) * t_hi[l] * (1.0 + BOX_SLACK);
            lanes |= ((!behind && !beyond) as LaneMask) << l;
        }
        lanes
    }

    /// [`Self::crossing`] in AVX-512 registers (the same tests).
    ///
    /// # Safety
    /// Only on a CPU with AVX-512F, inlined into an AVX-512 entry point.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn crossing_avx512(
        &self,
        lo: &[f32; 3],
        hi: &[f32; 3],
        t_hi: &[f32; WIDTH],
    ) -> LaneMask {
        // SAFETY: the caller runs on a CPU with AVX-512F.
        unsafe {
            use std::arch::x86_64::*;
            let mut near = _mm512_set1_ps(f32::NEG_INFINITY);
            let mut far = _mm512_set1_ps(f32::INFINITY);
            for a in 0..3 {
                let o = _mm512_loadu_ps(self.o[a].as_ptr());
                let inv = _mm512_loadu_ps(self.inv[a].as_ptr());
                let t0 = _mm512_mul_ps(_mm512_sub_ps(_mm512_set1_ps(lo[a]), o), inv);
                let t1 = _mm512_mul_ps(_mm512_sub_ps(_mm512_set1_ps(hi[a]), o), inv);
                near = _mm512_max_ps(near, _mm512_min_ps(t0, t1));
                far = _mm512_min_ps(far, _mm512_max_ps(t0, t1));
            }
            let slack = _mm512_set1_ps(1.0 + BOX_SLACK);
            let t_hi = _mm512_loadu_ps(t_hi.as_ptr());
            let miss = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(near, _mm512_mul_ps(far, slack))
                | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(far, _mm512_setzero_ps())
                | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(near, _mm512_mul_ps(t_hi, slack));
            (!miss) as LaneMask
        }
    }

    /// [`Self::crossing_plane`] in AVX-512 registers (the same tests).
    ///
    /// # Safety
    /// Only on a CPU with AVX-512F, inlined into an AVX-512 entry point.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn crossing_plane_avx512(
        &self,
        n: &[f32; 3],
        p: &[f32; 3],
        t_hi: &[f32; WIDTH],
    ) -> LaneMask {
        // SAFETY: the caller runs on a CPU with AVX-512F.
        unsafe {
            use std::arch::x86_64::*;
            let mut num = _mm512_setzero_ps();
            let mut num_abs = _mm512_setzero_ps();
            let mut den = _mm512_setzero_ps();
            let mut den_abs = _mm512_setzero_ps();
            for a in 0..3 {
                let na = _mm512_set1_ps(n[a]);
                let na_abs = _mm512_set1_ps(n[a].abs());
                let r = _mm512_sub_ps(_mm512_set1_ps(p[a]), _mm512_loadu_ps(self.o[a].as_ptr()));
                let d = _mm512_loadu_ps(self.d[a].as_ptr());
                num = _mm512_add_ps(num, _mm512_mul_ps(na, r));
                num_abs = _mm512_add_ps(num_abs, _mm512_mul_ps(na_abs, _mm512_abs_ps(r)));
                den = _mm512_add_ps(den, _mm512_mul_ps(na, d));
                den_abs = _mm512_add_ps(den_abs, _mm512_mul_ps(na_abs, _mm512_abs_ps(d)));
            }
            let slack = _mm512_set1_ps(BOX_SLACK);
            let num_err = _mm512_mul_ps(slack, num_abs);
            let den_err = _mm512_mul_ps(slack, den_abs);
            let gt = |a, b| _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b);
            let lt = |a, b| _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b);
            let neg = |x| _mm512_sub_ps(_mm512_setzero_ps(), x);
            let behind = (gt(num, num_err) & lt(den, neg(den_err)))
                | (lt(num, neg(num_err)) & gt(den, den_err));
            let reach = _mm512_mul_ps(
                _mm512_mul_ps(
                    _mm512_add_ps(_mm512_abs_ps(den), den_err),
                    _mm512_loadu_ps(t_hi.as_ptr()),
                ),
                _mm512_set1_ps(1.0 + BOX_SLACK),
            );
            let beyond = gt(_mm512_sub_ps(_mm512_abs_ps(num), num_err), reach);
            (!(behind | beyond)) as LaneMask & 0xffff
        }
    }
}

/// One group of up to [`WIDTH`] rays of one permutation kind, laid out
/// for the tests of [`TriangleBatch::candidates`].
struct Group {
    lanes: PermutedLanes16,
    rays: Rays16,
    /// The lanes that hold a ray of the group.
    valid: LaneMask,
}

impl Group {
    /// Inlined into the batch's SIMD entry points: out of line it ran
    /// with the baseline instruction set and returned its 1 KB through a
    /// `memcpy`.
    #[inline(always)]
    fn new(sorted: &Sorted, group: &[u32], rays: &[Ray]) -> Self {
        Group {
            lanes: PermutedLanes16::new(sorted.wt.as_slice(), group),
            rays: Rays16::new(group, rays),
            valid: if group.len() == WIDTH {
                u32::MAX >> 16
            } else {
                (1 << group.len()) - 1
            },
        }
    }
}

/// The lanes of a group that passed a triangle's edge test or need its
/// re-check (`pass`), with their edge functions `e` and bounds `b`, and
/// the triangle's block and lane there.
struct Candidates<'b> {
    pass: LaneMask,
    e: [[f32; WIDTH]; 3],
    b: [[f32; WIDTH]; 3],
    block: &'b Tri8,
    j: usize,
}

impl<'a> TriangleBatch<'a> {
    /// The batch of `scene`'s triangles, or `None` unless every bounded
    /// instance is in one merged group of at most [`MAX_TRIANGLES`]
    /// triangles with a BVH and nothing else is there (no unbounded
    /// shapes, no cut-out materials).
    pub fn new(scene: &'a RenderScene) -> Option<Self> {
        let group = scene.merged.as_ref()?;
        if !scene.tlas.unbounded.is_empty()
            || !scene.tlas.leaf_instances.is_empty()
            || scene.cutouts
        {
            return None;
        }
        let mesh = group.mesh();
        if mesh.triangle_count() > MAX_TRIANGLES {
            return None;
        }
        let blocks = mesh.leaf_blocks()?;
        let mut tris = Vec::with_capacity(mesh.triangle_count());
        let mut clusters = Vec::with_capacity(blocks.len());
        for (b, block) in blocks.iter().enumerate() {
            let start = tris.len() as u32;
            for j in 0..block.count as usize {
                let [p0, p1, p2] = block.corners(j);
                let (lo, hi) = (p0.min(p1).min(p2), p0.max(p1).max(p2));
                // Strictly outside the triangle's box on every side.
                let pad =
                    BOX_SLACK * (lo.abs().max(hi.abs()).max_element() + (hi - lo).max_element());
                let q = p0.as_dvec3();
                let n = (p1.as_dvec3() - q).cross(p2.as_dvec3() - q);
                tris.push(TriCull {
                    block: b as u32,
                    lane: j as u32,
                    lo: (lo - pad).to_array().map(f32::next_down),
                    hi: (hi + pad).to_array().map(f32::next_up),
                    own_box: true,
                    n: n.as_vec3().to_array(),
                    p0: p0.to_array(),
                    nd: n,
                });
            }
            let mine = &tris[start as usize..];
            if let Some(first) = mine.first() {
                let (mut lo, mut hi) = (first.lo, first.hi);
                for t in mine {
                    for a in 0..3 {
                        lo[a] = lo[a].min(t.lo[a]);
                        hi[a] = hi[a].max(t.hi[a]);
                    }
                }
                for t in &mut tris[start as usize..] {
                    t.own_box = t.lo != lo || t.hi != hi;
                }
                clusters.push(Cluster {
                    lo,
                    hi,
                    start,
                    end: tris.len() as u32,
                });
            }
        }
        Some(TriangleBatch {
            scene,
            blocks,
            tris,
            clusters,
        })
    }

    crate::simd_entry_wide! {
        /// Closest hits of `rays` (each searched in `(0, inf)`) into
        /// `out`: the hits [`RenderScene::intersect`] gives, bit for bit.
        pub fn intersect(&self, rays: &[Ray], out: &mut [Option<Hit>]) -> ()
            => TriangleBatch<'_>, intersect_kernel
    }

    crate::simd_entry_wide! {
        /// Whether each of `rays` is blocked between `0` and its `t_max`
        /// into `blocked`: the answers of [`RenderScene::occluded`].
        pub fn occluded(&self, rays: &[Ray], t_max: &[f32], blocked: &mut [bool]) -> ()
            => TriangleBatch<'_>, occluded_kernel
    }

    /// The lanes of `mask` in `group` that may hit triangle `tri` within
    /// `t_hi`: those its box and plane tests keep, then those its edge
    /// test passes or sends to the re-check; `None` when no lane is left.
    #[inline(always)]
    fn candidates<const AVX512: bool>(
        &self,
        tri: &TriCull,
        group: &Group,
        t_hi: &[f32; WIDTH],
        mask: LaneMask,
    ) -> Option<Candidates<'a>> {
        // (On the AVX-512 path, where the test is one register, the branch
        // cost more than the test: 1.006x the time, against 0.98x on the
        // AVX2 path; 7 pinned pairs each.)
        let near = if AVX512 || tri.own_box {
            group.rays.crossing::<AVX512>(&tri.lo, &tri.hi, t_hi) & mask
        } else {
            mask
        };
        if near == 0 {
            return None;
        }
        let near = group.rays.crossing_plane::<AVX512>(&tri.n, &tri.p0, t_hi) & near;
        if near == 0 {
            return None;
        }
        let block = &self.blocks[tri.block as usize];
        let j = tri.lane as usize;
        let (pass, e, b) = group.lanes.edges::<AVX512>(block, j);
        let pass = pass & near;
        (pass != 0).then_some(Candidates {
            pass,
            e,
            b,
            block,
            j,
        })
    }

    #[inline(always)]
    fn intersect_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        rays: &[Ray],
        out: &mut [Option<Hit>],
    ) {
        debug_assert_eq!(rays.len(), out.len());
        if rays.is_empty() {
            return;
        }
        let sorted = Sorted::new(rays);
        for group in sorted.groups() {
            let g = Group::new(&sorted, group, rays);
            let mut best_t = [f32::INFINITY; WIDTH];
            // The nearest triangle so far and its barycentrics, one array
            // each: a tuple array had its two floats stored one by one
            // and reloaded as a pair, which stalled store forwarding.
            let mut best_tri = [u32::MAX; WIDTH];
            let mut best_b1 = [0.0f32; WIDTH];
            let mut best_b2 = [0.0f32; WIDTH];
            let mut tied: LaneMask = 0;
            for cl in &self.clusters {
                let near = g.rays.crossing::<AVX512>(&cl.lo, &cl.hi, &best_t) & g.valid;
                if near == 0 {
                    continue;
                }
                for tri in &self.tris[cl.start as usize..cl.end as usize] {
                    let Some(c) = self.candidates::<AVX512>(tri, &g, &best_t, near) else {
                        continue;
                    };
                    let corners = c.block.corners(c.j);
                    let mut pass = c.pass;
                    while pass != 0 {
                        let l = pass.trailing_zeros() as usize;
                        pass &= pass - 1;
                        // Up to one ulp past a known hit, so that an equal
                        // `t` is seen (and the ray handed on).
                        let reach = if best_tri[l] == u32::MAX {
                            f32::INFINITY
                        } else {
                            best_t[l].next_up()
                        };
                        let w = &sorted.wt[group[l] as usize];
                        if let Some((t, b1, b2)) =
                            w.finish_lane_normal(corners, tri.nd, &c.e, &c.b, l, 0.0, reach)
                        {
                            if t < best_t[l] {
                                best_t[l] = t;
                                best_tri[l] = c.block.first + c.j as u32;
                                best_b1[l] = b1;
                                best_b2[l] = b2;
                                tied &= !(1 << l);
                            } else {
                                tied |= 1 << l;
                            }
                        }
                    }
                }
            }
            for (l, &i) in group.iter().enumerate() {
                let o = &mut out[i as usize];
                if tied & (1 << l) != 0 {
                    *o = self.scene.intersect(&rays[i as usize], 0.0, f32::INFINITY);
                } else if best_tri[l] == u32::MAX {
                    *o = None;
                } else {
                    let (triangle, b1, b2) = (best_tri[l], best_b1[l], best_b2[l]);
                    let t = best_t[l];
                    let local = LocalHit::Mesh(MeshHit {
                        t,
                        triangle,
                        b1,
                        b2,
                    });
                    let h = self.scene.finish_hit_inline(t, MERGED, local);
                    *o = Some(h);
                }
            }
        }
    }

    #[inline(always)]
    fn occluded_kernel<const AVX: bool, const AVX512: bool>(
        &self,
        rays: &[Ray],
        t_max: &[f32],
        blocked: &mut [bool],
    ) {
        debug_assert!(rays.len() == t_max.len() && rays.len() == blocked.len());
        if rays.is_empty() {
            return;
        }
        let sorted = Sorted::new(rays);
        for group in sorted.groups() {
            let m = group.len();
            let reach: [f32; WIDTH] = std::array::from_fn(|l| t_max[group[l.min(m - 1)] as usize]);
            let g = Group::new(&sorted, group, rays);
            let mut open = g.valid;
            'clusters: for cl in &self.clusters {
                let near = g.rays.crossing::<AVX512>(&cl.lo, &cl.hi, &reach) & open;
                if near == 0 {
                    continue;
                }
                for tri in &self.tris[cl.start as usize..cl.end as usize] {
                    let Some(c) = self.candidates::<AVX512>(tri, &g, &reach, open & near) else {
                        continue;
                    };
                    let corners = c.block.corners(c.j);
                    let mut pass = c.pass;
                    while pass != 0 {
                        let l = pass.trailing_zeros() as usize;
                        pass &= pass - 1;
                        let w = &sorted.wt[group[l] as usize];
                        if w.finish_lane_normal(corners, tri.nd, &c.e, &c.b, l, 0.0, reach[l])
                            .is_some()
                        {
                            open &= !(1 << l);
                        }
                    }
                    if open == 0 {
                        break 'clusters;
                    }
                }
            }
            for (l, &i) in group.iter().enumerate() {
                blocked[i as usize] = open & (1 << l) == 0;
            }
        }
    }
}
