//! One conservative test of a node's eight children for a whole packet
//! of rays that point into one octant: the bound ("frustum") of the
//! packets of 8 ([`crate::accel::packet`], a filter before their lane
//! tests) and of 16 ([`crate::accel::packet16`], which descends inner
//! nodes on it alone).
//!
//! Per axis, a lane's slab distances are `(near - o_near) * inv` and
//! `(far - o_far) * inv` ([`crate::accel::node::NodeRay::test`]: a
//! difference, then a product). For the node's planes and a fixed
//! reciprocal direction, the near distance is smallest for the largest
//! `o_near` when the rays go up (`inv > 0`), for the smallest going down;
//! for a fixed difference it is linear in `inv`, so smallest at one end
//! of the lanes' range: `min(u * inv_lo, u * inv_hi)` with `u` the
//! difference at the extreme origin. The far distance is largest the
//! other way round. Rounding is monotonic, so these rounded bounds are
//! never above (below) any lane's own rounded distances: a child entered
//! by some lane is entered by the bound, no later than by that lane. The
//! bound holds for rays from one point (a pinhole camera's 4x4 block,
//! where it is as tight as the ends of the direction range allow) and for
//! rays from scattered points (shadow rays of a pixel block towards one
//! light, lens samples), looser as the origins spread.

use crate::accel::bvh8::{Node8, WIDTH};
use crate::accel::node::{max_keep, min_keep};

/// A bit set of lanes (the packets' `LaneMask`; spelled out here, which
/// the packets import, so that the two modules do not import each other).
type LaneMask = u32;

/// Bounds of the alive lanes of a packet, axis by axis (see the module
/// documentation).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Frustum {
    /// The shifted origin that gives every lane's near distance its lower
    /// bound (largest `o_near` going up, smallest going down).
    o_near: [f32; 3],
    /// The shifted origin that gives every lane's far distance its upper
    /// bound.
    o_far: [f32; 3],
    /// Smallest and largest reciprocal direction (one sign per axis).
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    /// Rows of each axis's near and far planes in [`Node8::planes`].
    near_row: [usize; 3],
    far_row: [usize; 3],
    /// Smallest interval start of the lanes.
    t_min: f32,
}

impl Frustum {
    /// The bound of the lanes in `alive` (at least one), given axis by axis
    /// as [`crate::accel::node::NodeRay`] prepares them: shifted origins
    /// `o_near` and `o_far`, reciprocal directions `inv`, and the near
    /// plane rows `near` that every alive lane shares (one octant, which
    /// the caller checks). `None` when some alive reciprocal direction is
    /// zero or not finite (a ray along an axis or an infinite direction):
    /// against an empty slot's infinite planes the products could be NaN.
    /// `AVX512` takes the reductions over 16 lanes in one register (only
    /// valid on a CPU with AVX-512F, and only for `N == 16`).
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    pub(crate) fn new<const N: usize, const AVX512: bool>(
        o_near: &[[f32; N]; 3],
        o_far: &[[f32; N]; 3],
        inv: &[[f32; N]; 3],
        near: [usize; 3],
        alive: LaneMask,
        t_min: &[f32; N],
    ) -> Option<Self> {
        let mut f = Frustum {
            o_near: [0.0; 3],
            o_far: [0.0; 3],
            inv_lo: [0.0; 3],
            inv_hi: [0.0; 3],
            near_row: near,
            far_row: near.map(|n| (n + 3) % 6),
            t_min: masked_min::<N, AVX512>(alive, t_min),
        };
        let mut bad = false;
        for a in 0..3 {
            let (lo, hi) = (
                masked_min::<N, AVX512>(alive, &inv[a]),
                masked_max::<N, AVX512>(alive, &inv[a]),
            );
            // Every lane's finite and of one sign, none zero.
            bad |= !(lo.is_finite() & hi.is_finite() & ((lo > 0.0) | (hi < 0.0)));
            (f.inv_lo[a], f.inv_hi[a]) = (lo, hi);
            // Going down (near row 3, 4 or 5), the smallest origin.
            (f.o_near[a], f.o_far[a]) = if near[a] >= 3 {
                (
                    masked_min::<N, AVX512>(alive, &o_near[a]),
                    masked_max::<N, AVX512>(alive, &o_far[a]),
                )
            } else {
                (
                    masked_max::<N, AVX512>(alive, &o_near[a]),
                    masked_min::<N, AVX512>(alive, &o_far[a]),
                )
            };
        }
        (!bad).then_some(f)
    }

    /// The children of `node` that some lane may enter before `t_max` (a
    /// bound of the lanes' interval ends), and lower bounds of the lanes'
    /// entry distances. Empty slots (infinite planes) are never entered.
    #[inline(always)]
    pub(crate) fn test<const AVX: bool>(&self, node: &Node8, t_max: f32) -> (u32, [f32; WIDTH]) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only by the AVX2 and AVX-512 entry
            // points, which run only on CPUs with AVX2 and FMA.
            #[allow(unsafe_code)]
            return unsafe { self.test_avx2(node, t_max) };
        }
        let mut enter = [self.t_min; WIDTH];
        let mut exit = [t_max; WIDTH];
        for a in 0..3 {
            let near = &node.planes[self.near_row[a]];
            let far = &node.planes[self.far_row[a]];
            let (lo, hi) = (self.inv_lo[a], self.inv_hi[a]);
            for c in 0..WIDTH {
                let u = near[c] - self.o_near[a];
                let v = far[c] - self.o_far[a];
                enter[c] = max_keep(min_keep(u * lo, u * hi), enter[c]);
                exit[c] = min_keep(max_keep(v * lo, v * hi), exit[c]);
            }
        }
        let mut mask = 0;
        for c in 0..WIDTH {
            mask |= ((enter[c] <= exit[c]) as u32) << c;
        }
        (mask, enter)
    }

    /// [`Frustum::test`] in one 8-wide AVX register: the same operations.
    ///
    /// # Safety
    /// Only on a CPU with AVX2 and FMA, inlined into an AVX2 or AVX-512
    /// entry point.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn test_avx2(&self, node: &Node8, t_max: f32) -> (u32, [f32; WIDTH]) {
        // SAFETY: the caller runs on a CPU with AVX2.
        unsafe {
            use std::arch::x86_64::*;
            let mut enter = _mm256_set1_ps(self.t_min);
            let mut exit = _mm256_set1_ps(t_max);
            for a in 0..3 {
                let near: __m256 = std::mem::transmute(node.planes[self.near_row[a]]);
                let far: __m256 = std::mem::transmute(node.planes[self.far_row[a]]);
                let lo = _mm256_set1_ps(self.inv_lo[a]);
                let hi = _mm256_set1_ps(self.inv_hi[a]);
                let u = _mm256_sub_ps(near, _mm256_set1_ps(self.o_near[a]));
                let v = _mm256_sub_ps(far, _mm256_set1_ps(self.o_far[a]));
                // `minps`/`maxps` as `min_keep`/`max_keep` (no NaN here).
                let e = _mm256_min_ps(_mm256_mul_ps(u, lo), _mm256_mul_ps(u, hi));
                let x = _mm256_max_ps(_mm256_mul_ps(v, lo), _mm256_mul_ps(v, hi));
                enter = _mm256_max_ps(e, enter);
                exit = _mm256_min_ps(x, exit);
            }
            let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit)) as u32;
            (mask, std::mem::transmute::<__m256, [f32; WIDTH]>(enter))
        }
    }
}

/// The smallest of `v`'s values in the lanes of `mask` (none NaN;
/// infinity for no lane). `AVX512` with `N == 16`: one masked reduction.
#[inline(always)]
pub(crate) fn masked_min<const N: usize, const AVX512: bool>(mask: LaneMask, v: &[f32; N]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if AVX512 && N == 16 {
        // SAFETY: `AVX512` is set only by the AVX-512 entry points, which
        // run only on CPUs with AVX-512F (`simd::use_avx512`); `v` holds
        // 16 floats.
        #[allow(unsafe_code)]
        unsafe {
            use std::arch::x86_64::*;
            let t = _mm512_loadu_ps(v.as_ptr());
            return _mm512_mask_reduce_min_ps(mask as __mmask16, t);
        }
    }
    let mut m = f32::INFINITY;
    for (l, &x) in v.iter().enumerate() {
        m = min_keep(if mask >> l & 1 == 1 { x } else { f32::INFINITY }, m);
    }
    m
}

/// The largest of `v`'s values in the lanes of `mask` (none NaN; minus
/// infinity for no lane), as [`masked_min`].
#[inline(always)]
pub(crate) fn masked_max<const N: usize, const AVX512: bool>(mask: LaneMask, v: &[f32; N]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if AVX512 && N == 16 {
        // SAFETY: as `masked_min`.
        #[allow(unsafe_code)]
        unsafe {
            use std::arch::x86_64::*;
            let t = _mm512_loadu_ps(v.as_ptr());
            return _mm512_mask_reduce_max_ps(mask as __mmask16, t);
        }
    }
    let mut m = f32::NEG_INFINITY;
    for (l, &x) in v.iter().enumerate() {
        m = max_keep(
            if mask >> l & 1 == 1 {
                x
            } else {
                f32::NEG_INFINITY
            },
            m,
        );
    }
    m
}
