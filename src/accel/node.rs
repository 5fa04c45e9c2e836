//! The conservative node test: one ray against the eight float child
//! boxes of a [`Node8`], shared by single-ray ([`crate::accel::single`]),
//! packet ([`crate::accel::packet`]) and stream ([`crate::accel::stream`])
//! traversal, so the three can never disagree about which boxes a ray
//! enters. (Single rays in mesh BVHs may use [`NodeRay::test_fused`] on
//! the AVX2 path, whose distances round differently: the boxes it enters
//! can differ only within rounding, far inside the margin, and the hits
//! are the same.)

use glam::{Vec3A, Vec4};

use crate::accel::bvh8::{Bvh8, Node8, WIDTH};
use crate::core::math::Ray;

/// Rounding margin of the node test, in units of `f32::EPSILON` times the
/// larger coordinate magnitude of the ray origin and the tree.
///
/// The watertight triangle test accepts a ray when its *rounded* sheared
/// coordinates put it inside the triangle. Those coordinates are
/// differences `vertex - origin` followed by a shear, which carry about
/// 2 EPS (|vertex| + |origin|) of absolute error, so an accepted ray may
/// pass outside the exact triangle, and outside its exact box, by that
/// much. This matters at shared edges and vertices: the consistent edge
/// functions give the ray to exactly one of the neighbours, and if that
/// neighbour's box were culled the ray would pass through the mesh. Boxes
/// are therefore grown by 16 EPS (|origin| + |tree|) per axis. The margin
/// is computed once per ray from the largest coordinate of the whole tree
/// ([`Bvh8::magnitude`]), so it is never smaller than a margin taken per
/// node. It also covers the rounding of the slab distances themselves:
/// each is one difference and one product, off by at most 2 EPS of
/// (|plane| + |origin| + margin) / |direction|, an eighth of the margin's
/// own contribution. (obvhs's own node test pads nothing, ignores `tmin`
/// and rejects every box closer than `t = 1e-4`, a scene-scale epsilon;
/// both made rays leak through closed meshes.)
pub const NODE_MARGIN_EPS: f32 = 16.0;

/// The margin of a ray from `origin_magnitude` against a tree whose
/// coordinates reach `tree_magnitude`.
#[inline(always)]
pub fn margin(origin_magnitude: f32, tree_magnitude: f32) -> f32 {
    NODE_MARGIN_EPS * f32::EPSILON * (origin_magnitude + tree_magnitude)
}

/// Per direction octant (bit `a` set when axis `a` points down): the
/// rows of [`Node8::planes`] holding each axis's near and far planes
/// (`a` and `3 + a` for an axis pointing up, swapped for one pointing
/// down).
const ROWS: [([u8; 3], [u8; 3]); 8] = {
    let mut t = [([0u8; 3], [0u8; 3]); 8];
    let mut o = 0;
    while o < 8 {
        let mut a = 0;
        while a < 3 {
            let down = (o >> a) & 1;
            t[o].0[a] = (a + 3 * down) as u8;
            t[o].1[a] = (a + 3 * (1 - down)) as u8;
            a += 1;
        }
        o += 1;
    }
    t
};

/// Larger of `a` and `b`, `b` when either is NaN (one `maxps`).
///
/// Slab distances are NaN only for a ray that does not move along an
/// axis and starts exactly on a (grown) plane: `0 * inf`. Passing them as
/// `a` ignores them, which keeps the box: conservative.
#[inline(always)]
pub fn max_keep(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// Smaller of `a` and `b`, `b` when either is NaN (one `minps`).
#[inline(always)]
pub fn min_keep(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// A ray prepared for node tests: per axis the rows of the near and far
/// planes (by the direction's sign), the origin shifted by the margin
/// towards each, and the reciprocal direction (infinite on axes the ray
/// does not move along).
#[derive(Clone, Copy, Debug)]
pub struct NodeRay {
    /// Origin minus the margin's shift, for near planes.
    pub o_near: [f32; 3],
    /// Origin plus the margin's shift, for far planes.
    pub o_far: [f32; 3],
    /// `1 / direction`.
    pub inv: [f32; 3],
    /// Row in [`Node8::planes`] of each axis's near plane.
    pub near: [u8; 3],
    /// Row of each axis's far plane.
    pub far: [u8; 3],
    /// Octant of the direction: bit `a` set when axis `a` points down.
    pub octant: u8,
    /// `o_near * inv` and `o_far * inv`, for [`Self::test_fused`].
    pub o_inv: [[f32; 3]; 2],
    /// Whether [`Self::test_fused`] may use the fused form: every `inv`
    /// finite and no product of a coordinate with it near overflow.
    pub fused: bool,
    /// Byte offsets in [`Node8::planes`] of the rows `near` and `far`
    /// name (`32 * row`, each below `6 * 32`): private, so that only
    /// [`Self::with_magnitude`] writes them, which [`Self::near_row`] and
    /// [`Self::far_row`] rely on.
    near_off: [usize; 3],
    far_off: [usize; 3],
}

/// The row of `node.planes` at byte offset `off`, read without a bounds
/// check or a multiplication by the row size (at every node of every
/// ray: four fewer instructions per node than indexing by row number).
///
/// # Safety
/// `off` must be 32 times a row number below 6 (a `NodeRay`'s
/// `near_off` or `far_off`).
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn row_at(node: &Node8, off: usize) -> &[f32; WIDTH] {
    debug_assert!(off.is_multiple_of(32) && off < 6 * 32);
    // SAFETY: by the caller's contract the 32 bytes at `off` are one whole
    // row of the `[[f32; 8]; 6]` array `planes`, aligned as its rows are.
    unsafe {
        &*node
            .planes
            .as_ptr()
            .cast::<u8>()
            .add(off)
            .cast::<[f32; WIDTH]>()
    }
}

impl NodeRay {
    /// The row of `node`'s near planes on axis `a` (0, 1 or 2).
    #[inline(always)]
    pub fn near_row<'a>(&self, node: &'a Node8, a: usize) -> &'a [f32; WIDTH] {
        // SAFETY: `near_off` is set only by `with_magnitude`, to 32 times a
        // row number below 6.
        #[allow(unsafe_code)]
        unsafe {
            row_at(node, self.near_off[a])
        }
    }

    /// The row of `node`'s far planes on axis `a` (0, 1 or 2).
    #[inline(always)]
    pub fn far_row<'a>(&self, node: &'a Node8, a: usize) -> &'a [f32; WIDTH] {
        // SAFETY: as in `near_row`.
        #[allow(unsafe_code)]
        unsafe {
            row_at(node, self.far_off[a])
        }
    }

    /// Prepares `ray` for the nodes of `bvh`.
    #[inline(always)]
    pub fn new(ray: &Ray, bvh: &Bvh8) -> Self {
        Self::with_magnitude(ray, bvh.magnitude)
    }

    /// Prepares `ray` for a tree whose coordinates reach `magnitude`.
    ///
    /// The three axes are prepared side by side in one SSE register, and
    /// the plane rows come from a table indexed by the direction's octant:
    /// the same IEEE operations on the same values as axis by axis, in
    /// about half the instructions (a bounce ray's preparation was a tenth
    /// of its instructions, callgrind on the anchors' 100k mesh).
    #[inline(always)]
    pub fn with_magnitude(ray: &Ray, magnitude: f32) -> Self {
        let o = ray.origin;
        let o_mag = o.abs().max_element();
        let m = margin(o_mag, magnitude);
        let reach = magnitude + o_mag + m;
        let inv = Vec3A::ONE / ray.direction;
        // The near plane of a grown box is lo - m for rays going up:
        // (lo - m - o) inv = (lo - (o + m)) inv; hi + m going down.
        // `o + (-m)` is `o - m` bit for bit.
        let shift = Vec3A::splat(m).copysign(inv);
        let (o_near, o_far) = (o + shift, o - shift);
        let octant = inv.is_negative_bitmask() as usize & 7;
        let (near, far) = ROWS[octant];
        NodeRay {
            o_near: o_near.to_array(),
            o_far: o_far.to_array(),
            inv: inv.to_array(),
            near,
            far,
            octant: octant as u8,
            o_inv: [(o_near * inv).to_array(), (o_far * inv).to_array()],
            fused: (inv.abs() * reach).cmplt(Vec3A::splat(1.0e30)).all(),
            near_off: near.map(|r| 32 * r as usize),
            far_off: far.map(|r| 32 * r as usize),
        }
    }

    /// Tests the interval `(t_min, t_max)` against the eight children of
    /// `node`: bit `c` of the mask is set when the ray enters child `c`'s
    /// box grown by the margin, and `enter[c]` is the distance at which it
    /// does (at least `t_min`). Empty slots are never entered. `AVX`
    /// selects the AVX2 code (only valid on a CPU that has it, see
    /// [`crate::core::simd`]); both give the same bits.
    #[inline(always)]
    pub fn test<const AVX: bool>(
        &self,
        node: &Node8,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [f32; WIDTH]) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only by the AVX2 entry points, which run
            // only on CPUs with AVX2 and FMA (`simd::use_avx2`).
            #[allow(unsafe_code)]
            return unsafe { self.test_avx2(node, t_min, t_max) };
        }
        self.test_portable(node, t_min, t_max)
    }

    /// [`Self::test`] with each slab distance computed as one fused
    /// multiply-add, `plane * inv - o * inv`, on the AVX2 path (where the
    /// ray allows it, see [`Self::fused`]); [`Self::test`] otherwise.
    ///
    /// The distances differ from [`Self::test`]'s by rounding only: the
    /// product `o * inv` rounds by half an ulp of `|o| / |d|` and the
    /// fused result by half an ulp of `t`, together far less than the
    /// margin's 16 EPS of `|o|` and the tree's magnitude over `|d|`. So
    /// the test stays conservative and a closest-hit query whose result
    /// does not depend on the order of its leaves (mesh BVHs: equal `t`
    /// goes to the lowest triangle index) gets the same hits; boxes within
    /// rounding of the ray's interval may be entered or not, and entries
    /// within rounding of each other may swap.
    #[inline(always)]
    pub fn test_fused<const AVX: bool>(
        &self,
        node: &Node8,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [f32; WIDTH]) {
        #[cfg(target_arch = "x86_64")]
        if AVX && self.fused {
            // SAFETY: `AVX` is set only by the AVX2 entry points, which run
            // only on CPUs with AVX2 and FMA (`simd::use_avx2`).
            #[allow(unsafe_code)]
            return unsafe { self.test_fma(node, t_min, t_max) };
        }
        self.test::<AVX>(node, t_min, t_max)
    }

    /// [`Self::test_fused`] for a ray whose [`Self::fused`] is set: the
    /// fused form without checking the flag at every node.
    #[inline(always)]
    pub fn test_fma_known<const AVX: bool>(
        &self,
        node: &Node8,
        t_min: f32,
        t_max: f32,
    ) -> (u32, [f32; WIDTH]) {
        debug_assert!(self.fused);
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `test_fused`.
            #[allow(unsafe_code)]
            return unsafe { self.test_fma(node, t_min, t_max) };
        }
        self.test::<AVX>(node, t_min, t_max)
    }

    /// [`Self::test_fused`]'s fused form in one 8-wide AVX register.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 and FMA, inlined into an AVX2 entry point
    /// (as [`Self::test_avx2`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn test_fma(&self, node: &Node8, t_min: f32, t_max: f32) -> (u32, [f32; WIDTH]) {
        // SAFETY: the caller runs on a CPU with AVX2 and FMA.
        unsafe {
            use std::arch::x86_64::*;
            let mut tn = [_mm256_setzero_ps(); 3];
            let mut tf = [_mm256_setzero_ps(); 3];
            for a in 0..3 {
                let near: __m256 = bytemuck::cast(*self.near_row(node, a));
                let far: __m256 = bytemuck::cast(*self.far_row(node, a));
                let inv = _mm256_set1_ps(self.inv[a]);
                tn[a] = _mm256_fmsub_ps(near, inv, _mm256_set1_ps(self.o_inv[0][a]));
                tf[a] = _mm256_fmsub_ps(far, inv, _mm256_set1_ps(self.o_inv[1][a]));
            }
            // The fused form runs only with finite `inv`: no slab distance
            // is NaN, so the maxima and minima can be taken as a tree (a
            // shorter chain of dependent operations) with the same result.
            let enter = _mm256_max_ps(
                _mm256_max_ps(tn[0], tn[1]),
                _mm256_max_ps(tn[2], _mm256_set1_ps(t_min)),
            );
            let exit = _mm256_min_ps(
                _mm256_min_ps(tf[0], tf[1]),
                _mm256_min_ps(tf[2], _mm256_set1_ps(t_max)),
            );
            let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit)) as u32;
            (mask, bytemuck::cast(enter))
        }
    }

    /// [`Self::test`] in two 4-wide halves (SSE2 on x86-64).
    #[inline(always)]
    fn test_portable(&self, node: &Node8, t_min: f32, t_max: f32) -> (u32, [f32; WIDTH]) {
        let mut enter = [Vec4::splat(t_min); 2];
        let mut exit = [Vec4::splat(t_max); 2];
        for a in 0..3 {
            let near = self.near_row(node, a);
            let far = self.far_row(node, a);
            let on = Vec4::splat(self.o_near[a]);
            let of = Vec4::splat(self.o_far[a]);
            let inv = Vec4::splat(self.inv[a]);
            for k in 0..2 {
                let n = Vec4::new(
                    near[4 * k],
                    near[4 * k + 1],
                    near[4 * k + 2],
                    near[4 * k + 3],
                );
                let f = Vec4::new(far[4 * k], far[4 * k + 1], far[4 * k + 2], far[4 * k + 3]);
                enter[k] = max4((n - on) * inv, enter[k]);
                exit[k] = min4((f - of) * inv, exit[k]);
            }
        }
        let mask = enter[0].cmple(exit[0]).bitmask() | enter[1].cmple(exit[1]).bitmask() << 4;
        let (e0, e1) = (enter[0].to_array(), enter[1].to_array());
        (
            mask,
            [e0[0], e0[1], e0[2], e0[3], e1[0], e1[1], e1[2], e1[3]],
        )
    }

    /// [`Self::test`] in one 8-wide AVX register.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 and FMA. `#[inline(always)]` without a
    /// `#[target_feature]` of its own, so that it is inlined into the AVX2
    /// entry point with its intrinsics (see [`crate::core::simd`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn test_avx2(&self, node: &Node8, t_min: f32, t_max: f32) -> (u32, [f32; WIDTH]) {
        // SAFETY: the caller runs on a CPU with AVX2 and FMA.
        unsafe {
            use std::arch::x86_64::*;
            let mut enter = _mm256_set1_ps(t_min);
            let mut exit = _mm256_set1_ps(t_max);
            for a in 0..3 {
                let near: __m256 = bytemuck::cast(*self.near_row(node, a));
                let far: __m256 = bytemuck::cast(*self.far_row(node, a));
                let inv = _mm256_set1_ps(self.inv[a]);
                let tn = _mm256_mul_ps(_mm256_sub_ps(near, _mm256_set1_ps(self.o_near[a])), inv);
                let tf = _mm256_mul_ps(_mm256_sub_ps(far, _mm256_set1_ps(self.o_far[a])), inv);
                // max(a, b) = a > b ? a : b, as `max_keep`.
                enter = _mm256_max_ps(tn, enter);
                exit = _mm256_min_ps(tf, exit);
            }
            let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit)) as u32;
            (mask, bytemuck::cast(enter))
        }
    }
}

/// [`max_keep`] lane by lane (one `maxps`, whose NaN rule is exactly
/// that of `max_keep`).
#[inline(always)]
pub fn max4(a: Vec4, b: Vec4) -> Vec4 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::_mm_max_ps;
        // SAFETY: SSE is part of the x86-64 baseline: every x86-64 CPU has it.
        #[allow(unsafe_code)]
        Vec4::from(unsafe { _mm_max_ps(a.into(), b.into()) })
    }
    #[cfg(not(target_arch = "x86_64"))]
    Vec4::select(a.cmpgt(b), a, b)
}

/// [`min_keep`] lane by lane (one `minps`).
#[inline(always)]
pub fn min4(a: Vec4, b: Vec4) -> Vec4 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::_mm_min_ps;
        // SAFETY: SSE is part of the x86-64 baseline: every x86-64 CPU has it.
        #[allow(unsafe_code)]
        Vec4::from(unsafe { _mm_min_ps(a.into(), b.into()) })
    }
    #[cfg(not(target_arch = "x86_64"))]
    Vec4::select(a.cmplt(b), a, b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;
    use obvhs::aabb::Aabb;

    /// The test against a plain f64 slab test on the child boxes of a
    /// built tree: every box the exact test enters is entered
    /// (conservative), and boxes far from the ray are not.
    #[test]
    fn node_test_is_conservative_and_tight() {
        let mut boxes = Vec::new();
        let mut s = 1u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        for _ in 0..200 {
            let c = Vec3A::new(next(), next(), next()) * 10.0;
            let h = Vec3A::new(next().abs(), next().abs(), next().abs()) * 0.5 + 0.01;
            boxes.push(Aabb::new(c - h, c + h));
        }
        let bvh = Bvh8::build(&boxes, obvhs::BvhBuildParams::medium_build(), 1);
        let (mut entered, mut exact_hits) = (0, 0);
        for r in 0..300 {
            let o = Vec3A::new(next(), next(), next()) * 15.0;
            let mut d = Vec3A::new(next(), next(), next());
            if r % 7 == 0 {
                d.x = 0.0;
            }
            if r % 11 == 0 {
                d.y = -0.0;
            }
            let ray = Ray::new(o, d.normalize());
            let nr = NodeRay::new(&ray, &bvh);
            for node in &bvh.nodes {
                let (mask, _) = nr.test::<false>(node, 0.0, f32::INFINITY);
                for c in 0..WIDTH {
                    if node.child[c] == crate::accel::bvh8::EMPTY {
                        assert_eq!((mask >> c) & 1, 0, "an empty slot was entered");
                        continue;
                    }
                    let (lo, hi) = node.child_box(c);
                    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                    for a in 0..3 {
                        let (lo, hi) = (lo[a] as f64, hi[a] as f64);
                        let (o, d) = (ray.origin[a] as f64, ray.direction[a] as f64);
                        if d == 0.0 {
                            if o < lo || o > hi {
                                t0 = f64::INFINITY;
                            }
                        } else {
                            let (s0, s1) = ((lo - o) / d, (hi - o) / d);
                            t0 = t0.max(s0.min(s1));
                            t1 = t1.min(s0.max(s1));
                        }
                    }
                    let exact = t0 <= t1;
                    exact_hits += exact as u32;
                    entered += (mask >> c) & 1;
                    assert!(
                        !exact || (mask >> c) & 1 == 1,
                        "ray {r} misses a child box it passes through"
                    );
                }
            }
        }
        // The margin is a few ulps: the test enters hardly more boxes
        // than the exact one.
        assert!(
            entered as f64 <= exact_hits as f64 * 1.01 + 5.0,
            "{entered} vs {exact_hits}"
        );
    }

    /// The ray's preparation, axis by axis in plain scalar code (the
    /// definition), against `with_magnitude`'s side-by-side form: the same
    /// bits for rays in every octant, with zero and negative-zero
    /// direction components, far origins and huge trees.
    #[test]
    fn preparation_matches_the_scalar_definition() {
        let mut s = 7u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        for r in 0..2000 {
            let scale = [1.0, 1.0e-3, 1.0e4, 3.0e7][r % 4];
            let o = Vec3A::new(next(), next(), next()) * scale;
            let mut d = Vec3A::new(next(), next(), next());
            match r % 9 {
                0 => d.x = 0.0,
                1 => d.y = -0.0,
                2 => d.z = 1.0e-38,
                _ => {}
            }
            let magnitude = [0.5, 100.0, 1.0e20][r % 3];
            let got = NodeRay::with_magnitude(&Ray::new(o, d), magnitude);
            let om = o.abs().max_element();
            let m = margin(om, magnitude);
            let reach = magnitude + om + m;
            let mut octant = 0;
            let mut fused = true;
            for a in 0..3 {
                let inv = 1.0 / d[a];
                let down = inv.is_sign_negative();
                let shift = m.copysign(inv);
                let bits = |x: f32| x.to_bits();
                assert_eq!(bits(got.inv[a]), bits(inv), "ray {r} axis {a}");
                assert_eq!(bits(got.o_near[a]), bits(o[a] + shift));
                assert_eq!(bits(got.o_far[a]), bits(o[a] - shift));
                assert_eq!(bits(got.o_inv[0][a]), bits((o[a] + shift) * inv));
                assert_eq!(bits(got.o_inv[1][a]), bits((o[a] - shift) * inv));
                assert_eq!(got.near[a], a as u8 + 3 * down as u8);
                assert_eq!(got.far[a], a as u8 + 3 * !down as u8);
                assert_eq!(got.near_off[a], 32 * got.near[a] as usize);
                assert_eq!(got.far_off[a], 32 * got.far[a] as usize);
                octant |= (down as u8) << a;
                fused &= inv.abs() * reach < 1.0e30;
            }
            assert_eq!(got.octant, octant, "ray {r}");
            assert_eq!(got.fused, fused, "ray {r}");
        }
    }

    /// A ray that does not move along an axis and starts exactly on a
    /// grown plane gives `0 * inf = NaN` there; the box must be kept.
    #[test]
    fn parallel_ray_on_a_plane_keeps_the_box() {
        let boxes = [Aabb::new(Vec3A::ZERO, Vec3A::ONE)];
        let bvh = Bvh8::build(&boxes, obvhs::BvhBuildParams::medium_build(), 1);
        let m = margin(0.0, bvh.magnitude);
        for x in [-m, 0.0, 0.5, 1.0] {
            let ray = Ray::new(Vec3A::new(x, 0.5, -3.0), Vec3A::Z);
            let (mask, _) =
                NodeRay::new(&ray, &bvh).test::<false>(&bvh.nodes[0], 0.0, f32::INFINITY);
            assert_eq!(mask & 1, 1, "x = {x}");
        }
        let ray = Ray::new(Vec3A::new(1.1, 0.5, -3.0), Vec3A::Z);
        let (mask, _) = NodeRay::new(&ray, &bvh).test::<false>(&bvh.nodes[0], 0.0, f32::INFINITY);
        assert_eq!(mask & 1, 0);
    }
}
