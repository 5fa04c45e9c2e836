//! Packet traversal of a [`Bvh8`]: up to [`LANES`] rays visit the tree
//! together.
//!
//! When the packet's rays share a direction octant (camera rays of a
//! pixel block, shadow rays towards one light), each node's children are
//! tested one at a time against every lane at once: structure-of-arrays
//! lanes in a branch-free loop that the compiler turns into SIMD across
//! rays. The packet does one traversal's bookkeeping for all its rays.
//! When only a lane or two still enter a subtree (the packet has
//! diverged), those lanes finish it alone with single-ray traversal
//! ([`crate::accel::single`]); a packet whose rays point into different
//! octants is traced ray by ray from the start. Leaf primitives are
//! tested per lane by the caller with the same kernels as single rays, so
//! the hits are the same.

use std::mem::MaybeUninit;

use glam::{Vec3A, Vec4};

use crate::accel::bvh8::{Bvh8, EMPTY, LEAF, Node8, WIDTH, leaf_index};
use crate::accel::frustum::Frustum;
use crate::accel::node::{NodeRay, max4, min_keep, min4};
use crate::accel::single::traverse_from;
use crate::core::math::Ray;

/// Rays per packet.
pub const LANES: usize = 8;

/// A bit set of packet lanes.
pub type LaneMask = u32;

/// Every lane of a full packet.
pub const ALL_LANES: LaneMask = (1 << LANES) - 1;

/// A packet that has shrunk to this many lanes continues ray by ray.
const DIVERGED: u32 = 2;

/// Rays with their search intervals, lane by lane, `N` lanes: [`Packet`]
/// (8) here, [`crate::accel::packet16::Packet16`] (16) for the AVX-512
/// traversal.
#[derive(Clone, Copy, Debug)]
pub struct PacketOf<const N: usize> {
    /// Interval starts.
    pub t_min: [f32; N],
    /// Interval ends; closest-hit traversal shrinks them as hits are found.
    pub t_max: [f32; N],
    /// The rays themselves.
    pub rays: [Ray; N],
    /// Lanes holding a ray.
    pub valid: LaneMask,
}

/// A packet of [`LANES`] rays.
pub type Packet = PacketOf<LANES>;

impl<const N: usize> PacketOf<N> {
    /// Packs up to `N` rays with their intervals.
    pub fn new(rays: &[Ray], t_min: &[f32], t_max: &[f32]) -> Self {
        debug_assert!(rays.len() <= N && rays.len() == t_min.len() && rays.len() == t_max.len());
        let empty = Ray::new(Vec3A::ZERO, Vec3A::X);
        let mut p = Self {
            t_min: [0.0; N],
            // Unused lanes can never hit.
            t_max: [f32::NEG_INFINITY; N],
            rays: [empty; N],
            valid: 0,
        };
        for (l, r) in rays.iter().enumerate() {
            p.set_lane(l, *r, t_min[l], t_max[l]);
        }
        p
    }

    /// Puts ray `r` in lane `l`.
    #[inline]
    pub fn set_lane(&mut self, l: usize, r: Ray, t_min: f32, t_max: f32) {
        self.t_min[l] = t_min;
        self.t_max[l] = t_max;
        self.rays[l] = r;
        self.valid |= 1 << l;
    }
}

/// The lanes of a packet prepared for one tree, axis by axis.
struct Lanes {
    o_near: [[f32; LANES]; 3],
    o_far: [[f32; LANES]; 3],
    inv: [[f32; LANES]; 3],
    /// Row of each axis's near plane (common to all lanes).
    near: [usize; 3],
}

impl Lanes {
    /// The lanes of `node_rays` (the near rows of the first lane of
    /// `alive`, whose rays share its octant).
    #[inline(always)]
    fn new(node_rays: &[NodeRay; LANES], alive: LaneMask) -> Self {
        let mut lanes = Lanes {
            o_near: [[0.0; LANES]; 3],
            o_far: [[0.0; LANES]; 3],
            inv: [[0.0; LANES]; 3],
            near: [0; 3],
        };
        for a in 0..3 {
            lanes.near[a] = node_rays[alive.trailing_zeros() as usize].near[a] as usize;
            for (l, r) in node_rays.iter().enumerate() {
                lanes.o_near[a][l] = r.o_near[a];
                lanes.o_far[a][l] = r.o_far[a];
                lanes.inv[a][l] = r.inv[a];
            }
        }
        lanes
    }
}

/// A pending subtree: child reference, lanes, smallest entry distance.
type Pending = (u32, LaneMask, f32);

/// Pending subtrees held without allocating.
const FIXED: usize = 48;

/// Visits every leaf whose box some lane's interval reaches, calling
/// `leaf(packet, lanes, leaf)` with the lanes that reach it (`leaf`
/// indexes [`Bvh8::leaves`]). For closest-hit queries `leaf` shrinks
/// `packet.t_max` of the lanes it hits, which prunes the rest of the
/// traversal; for occlusion queries it returns the lanes found blocked,
/// which retires them. Traversal ends when no lane is left.
///
/// Children are visited nearest first (by the smallest entry distance of
/// the lanes that enter them), and a popped subtree is skipped for lanes
/// that have since found a nearer hit.
///
/// With `FRUSTUM`, each node's children are first tested at once against
/// bounds of the whole packet (`Frustum`), and those no lane can enter
/// are skipped without their lane tests: the same children are entered
/// either way, so the hits do not change. It pays for closest-hit
/// packets of alike rays (camera rays in mesh BVHs); the top level and
/// shadow packets measured slower with it.
#[inline(always)]
pub fn traverse<const AVX: bool, const FRUSTUM: bool>(
    bvh: &Bvh8,
    packet: &mut Packet,
    active: LaneMask,
    mut leaf: impl FnMut(&mut Packet, LaneMask, u32) -> LaneMask,
) {
    let mut alive = active & packet.valid;
    if bvh.nodes.is_empty() || alive == 0 {
        return;
    }
    // A loop rather than `std::array::from_fn`: its closure was compiled
    // out of line, without the entry point's AVX2, and called per lane
    // (4.8% of the frame-loop benchmark's samples in `perf`).
    let mut node_rays = [NodeRay::new(&packet.rays[0], bvh); LANES];
    for (n, r) in node_rays.iter_mut().zip(&packet.rays).skip(1) {
        *n = NodeRay::new(r, bvh);
    }
    let octant = node_rays[alive.trailing_zeros() as usize].octant;
    let mut mixed = false;
    for_each_lane(
        alive,
        #[inline(always)]
        |l| mixed |= node_rays[l].octant != octant,
    );
    if mixed {
        for_each_lane(
            alive,
            #[inline(always)]
            |l| {
                single_lane::<AVX>(bvh, 0, &node_rays[l], packet, l, &mut leaf);
            },
        );
        return;
    }
    let lanes = Lanes::new(&node_rays, alive);
    // With `FRUSTUM`, children no lane can enter are left out before the
    // lane tests (closest hits in mesh BVHs: see `Frustum`; the top level
    // and shadow packets, whose rays are less alike, measured slower).
    let frustum = if FRUSTUM {
        Frustum::new::<LANES, false>(
            &lanes.o_near,
            &lanes.o_far,
            &lanes.inv,
            lanes.near,
            alive,
            &packet.t_min,
        )
    } else {
        None
    };
    // A fixed part (nothing allocated per packet) and a spill for deeper
    // stacks: the spill only holds entries while the fixed part is full.
    // The fixed part is left uninitialised (as the single-ray stack's):
    // only entries below `top` are read, and each was written.
    let mut fixed = [const { MaybeUninit::<Pending>::uninit() }; FIXED];
    let mut top = 0;
    let mut spill: Vec<Pending> = Vec::new();
    fixed[0].write((0, alive, f32::NEG_INFINITY));
    top += 1;
    loop {
        let (cur, lanes_in, near) = if let Some(e) = spill.pop() {
            e
        } else if top > 0 {
            top -= 1;
            // SAFETY: entries below `top` were written (`top` only grows
            // after a write).
            #[allow(unsafe_code)]
            unsafe {
                fixed[top].assume_init()
            }
        } else {
            break;
        };
        // Lanes still alive whose closest hit is not nearer than the node.
        let mut go = 0;
        for l in 0..LANES {
            go |= ((near <= packet.t_max[l]) as u32) << l;
        }
        let go = go & lanes_in & alive;
        if go == 0 {
            continue;
        }
        if cur & LEAF != 0 {
            alive &= !leaf(packet, go, leaf_index(cur));
            if alive == 0 {
                return;
            }
            continue;
        }
        if go.count_ones() <= DIVERGED {
            for_each_lane(
                go,
                #[inline(always)]
                |l| {
                    if single_lane::<AVX>(bvh, cur, &node_rays[l], packet, l, &mut leaf) {
                        alive &= !(1 << l);
                    }
                },
            );
            if alive == 0 {
                return;
            }
            continue;
        }
        let node: &Node8 = &bvh.nodes[cur as usize];
        let mut found: [Pending; WIDTH] = [(0, 0, 0.0); WIDTH];
        let mut n = 0;
        // A `match`, not `map_or` with a closure: a closure left out of
        // line loses the AVX2 entry point's features.
        let maybe = match &frustum {
            Some(f) => f.test::<AVX>(node, f32::INFINITY).0,
            None => u32::MAX,
        };
        for c in 0..WIDTH {
            let child = node.child[c];
            if child == EMPTY {
                break;
            }
            if maybe >> c & 1 == 0 {
                continue;
            }
            let (hit, t) = test_child::<AVX>(&lanes, node, c, packet, go);
            if hit == 0 {
                continue;
            }
            // Insertion, far to near.
            let mut j = n;
            while j > 0 && found[j - 1].2 < t {
                found[j] = found[j - 1];
                j -= 1;
            }
            found[j] = (child, hit, t);
            n += 1;
        }
        for &e in &found[..n] {
            prefetch_child(bvh, e.0);
            if top < FIXED {
                fixed[top].write(e);
                top += 1;
            } else {
                spill.push(e);
            }
        }
    }
}

/// Starts loading a pushed child: a node's rows (a leaf's primitives are
/// the caller's, read per lane later).
#[inline(always)]
fn prefetch_child(bvh: &Bvh8, r: u32) {
    if r & LEAF == 0 {
        crate::accel::single::prefetch_bytes(&bvh.nodes[r as usize], std::mem::size_of::<Node8>());
    }
}

/// Child `c` of `node` against the lanes: the lanes in `go` that enter
/// it, and their smallest entry distance (the two code paths as
/// [`NodeRay::test`]).
#[inline(always)]
fn test_child<const AVX: bool>(
    lanes: &Lanes,
    node: &Node8,
    c: usize,
    packet: &Packet,
    go: LaneMask,
) -> (LaneMask, f32) {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        // SAFETY: `AVX` is set only by the AVX2 entry points, which run
        // only on CPUs with AVX2 and FMA (`simd::use_avx2`).
        #[allow(unsafe_code)]
        return unsafe { test_child_avx2(lanes, node, c, packet, go) };
    }
    let mut enter = [
        Vec4::from_slice(&packet.t_min[..4]),
        Vec4::from_slice(&packet.t_min[4..]),
    ];
    let mut exit = [
        Vec4::from_slice(&packet.t_max[..4]),
        Vec4::from_slice(&packet.t_max[4..]),
    ];
    for a in 0..3 {
        let n = lanes.near[a];
        let near = Vec4::splat(node.planes[n][c]);
        let far = Vec4::splat(node.planes[(n + 3) % 6][c]);
        for k in 0..2 {
            let on = Vec4::from_slice(&lanes.o_near[a][4 * k..4 * k + 4]);
            let of = Vec4::from_slice(&lanes.o_far[a][4 * k..4 * k + 4]);
            let inv = Vec4::from_slice(&lanes.inv[a][4 * k..4 * k + 4]);
            enter[k] = max4((near - on) * inv, enter[k]);
            exit[k] = min4((far - of) * inv, exit[k]);
        }
    }
    let hit = (enter[0].cmple(exit[0]).bitmask() | enter[1].cmple(exit[1]).bitmask() << 4) & go;
    if hit == 0 {
        return (0, f32::INFINITY);
    }
    let e = [enter[0].to_array(), enter[1].to_array()];
    let mut t = f32::INFINITY;
    for_each_lane(
        hit,
        #[inline(always)]
        |l| t = min_keep(e[l / 4][l % 4], t),
    );
    (hit, t)
}

/// [`test_child`] in one 8-wide AVX register.
///
/// # Safety
/// Only on a CPU with AVX2 and FMA. `#[inline(always)]` without a
/// `#[target_feature]` of its own, so that it is inlined into the AVX2
/// entry point with its intrinsics (see [`crate::core::simd`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn test_child_avx2(
    lanes: &Lanes,
    node: &Node8,
    c: usize,
    packet: &Packet,
    go: LaneMask,
) -> (LaneMask, f32) {
    // SAFETY: the caller runs on a CPU with AVX2 and FMA.
    unsafe {
        use std::arch::x86_64::*;
        let mut enter: __m256 = bytemuck::cast(packet.t_min);
        let mut exit: __m256 = bytemuck::cast(packet.t_max);
        for a in 0..3 {
            let n = lanes.near[a];
            let near = _mm256_set1_ps(node.planes[n][c]);
            let far = _mm256_set1_ps(node.planes[(n + 3) % 6][c]);
            let on: __m256 = bytemuck::cast(lanes.o_near[a]);
            let of: __m256 = bytemuck::cast(lanes.o_far[a]);
            let inv: __m256 = bytemuck::cast(lanes.inv[a]);
            enter = _mm256_max_ps(_mm256_mul_ps(_mm256_sub_ps(near, on), inv), enter);
            exit = _mm256_min_ps(_mm256_mul_ps(_mm256_sub_ps(far, of), inv), exit);
        }
        let inside = _mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit);
        let hit = _mm256_movemask_ps(inside) as u32 & go;
        if hit == 0 {
            return (0, f32::INFINITY);
        }
        // The smallest entry of the lanes in `hit`, others as +inf: entries
        // are never NaN (`maxps` keeps `t_min` over a NaN slab), so the order
        // of the minima does not matter and this equals the lane loop of the
        // portable path.
        let lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        let keep = _mm256_cmpeq_epi32(
            _mm256_and_si256(_mm256_set1_epi32(hit as i32), lane_bits),
            lane_bits,
        );
        let e = _mm256_blendv_ps(
            _mm256_set1_ps(f32::INFINITY),
            enter,
            _mm256_castsi256_ps(keep),
        );
        let m = _mm_min_ps(_mm256_castps256_ps128(e), _mm256_extractf128_ps::<1>(e));
        let m = _mm_min_ps(m, _mm_movehl_ps(m, m));
        let m = _mm_min_ss(m, _mm_shuffle_ps::<0b01>(m, m));
        (hit, _mm_cvtss_f32(m))
    }
}

/// Lane `l` alone through the subtree at `start`; returns whether it was
/// retired (blocked, for occlusion queries).
#[inline(always)]
fn single_lane<const AVX: bool>(
    bvh: &Bvh8,
    start: u32,
    ray: &NodeRay,
    packet: &mut Packet,
    l: usize,
    leaf: &mut impl FnMut(&mut Packet, LaneMask, u32) -> LaneMask,
) -> bool {
    let mut retired = false;
    let (t_min, t_max) = (packet.t_min[l], packet.t_max[l]);
    traverse_from::<AVX>(
        bvh,
        start,
        ray,
        t_min,
        t_max,
        false,
        #[inline(always)]
        |leaf_index, _| {
            let before = packet.t_max[l];
            if leaf(packet, 1 << l, leaf_index) != 0 {
                retired = true;
                // Nothing is nearer than this: the traversal ends.
                return Some(f32::NEG_INFINITY);
            }
            (packet.t_max[l] < before).then_some(packet.t_max[l])
        },
    );
    retired
}

/// Calls `f` for every lane in `mask`, lowest first.
#[inline(always)]
pub fn for_each_lane(mut mask: LaneMask, mut f: impl FnMut(usize)) {
    while mask != 0 {
        let l = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        f(l);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::aabb::Aabb;

    #[test]
    fn lanes_enter_the_children_their_rays_pass_through() {
        // Two unit boxes on the x axis, at x = 0 and x = 10.
        let boxes = [
            Aabb::new(Vec3A::splat(-0.5), Vec3A::splat(0.5)),
            Aabb::new(Vec3A::new(9.5, -0.5, -0.5), Vec3A::new(10.5, 0.5, 0.5)),
        ];
        let bvh = Bvh8::build(&boxes, obvhs::BvhBuildParams::medium_build(), 1);
        // The lanes that reach each box's leaf.
        let reached = |rays: &[Ray]| {
            let mut p = Packet::new(rays, &[0.0; 4], &[f32::INFINITY; 4]);
            let mut reached = [0 as LaneMask; 2];
            traverse::<false, true>(&bvh, &mut p, ALL_LANES, |_, lanes, leaf| {
                let l = bvh.leaves[leaf as usize];
                reached[bvh.prims[l.first as usize] as usize] |= lanes;
                0
            });
            reached
        };
        // All in one octant: the packet path. Lane 3 runs parallel to x.
        let rays = [
            Ray::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::new(0.0, 0.0, 1.0)),
            Ray::new(Vec3A::new(3.0, 0.0, -5.0), Vec3A::new(0.0, 0.0, 1.0)),
            Ray::new(Vec3A::new(10.0, 0.2, -5.0), Vec3A::new(0.0, 0.0, 1.0)),
            Ray::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::new(0.0, 0.0, 1.0)),
        ];
        assert_eq!(reached(&rays), [0b1001, 0b0100]);
        // Mixed octants: ray by ray, same answer.
        let mut rays = rays;
        rays[2] = Ray::new(Vec3A::new(10.0, 0.2, 5.0), -Vec3A::Z);
        assert_eq!(reached(&rays), [0b1001, 0b0100]);
    }

    /// The frustum test leaves out only children that every lane misses
    /// (the lane test, on every node of a tree of random boxes, for
    /// packets from one point and from scattered points, portable and
    /// AVX2 alike), and it does leave out most of those.
    #[test]
    fn frustum_leaves_out_only_children_every_lane_misses() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let mut boxes = Vec::new();
        for _ in 0..400 {
            let c = Vec3A::new(next(), next(), next()) * 10.0;
            let h = Vec3A::new(next().abs(), next().abs(), next().abs()) * 0.6 + 0.01;
            boxes.push(Aabb::new(c - h, c + h));
        }
        let bvh = Bvh8::build(&boxes, obvhs::BvhBuildParams::medium_build(), 1);
        let (mut missed, mut left_out, mut packets) = (0u64, 0u64, 0);
        for trial in 0..300 {
            let o = Vec3A::new(next(), next(), next()) * 14.0;
            let d = Vec3A::new(next(), next(), next());
            let spread = if trial % 2 == 0 { 0.0 } else { 1.5 };
            let rays: Vec<Ray> = (0..LANES)
                .map(|_| {
                    let jitter = Vec3A::new(next(), next(), next());
                    let dir = d + Vec3A::new(next(), next(), next()) * 0.05;
                    Ray::new(o + jitter * spread, dir)
                })
                .collect();
            let node_rays: [NodeRay; LANES] = std::array::from_fn(|l| NodeRay::new(&rays[l], &bvh));
            if node_rays.iter().any(|r| r.octant != node_rays[0].octant) {
                continue;
            }
            let packet = Packet::new(&rays, &[0.0; LANES], &[f32::INFINITY; LANES]);
            let lanes = Lanes::new(&node_rays, ALL_LANES);
            let f = Frustum::new::<LANES, false>(
                &lanes.o_near,
                &lanes.o_far,
                &lanes.inv,
                lanes.near,
                ALL_LANES,
                &packet.t_min,
            )
            .expect("no ray along an axis");
            packets += 1;
            for node in &bvh.nodes {
                let mask = f.test::<false>(node, f32::INFINITY).0;
                #[cfg(target_arch = "x86_64")]
                if crate::core::simd::use_avx2() {
                    #[target_feature(enable = "avx2,fma")]
                    fn avx2(f: &Frustum, node: &Node8) -> u32 {
                        f.test::<true>(node, f32::INFINITY).0
                    }
                    // SAFETY: the CPU has AVX2 and FMA (checked above).
                    #[allow(unsafe_code)]
                    let m = unsafe { avx2(&f, node) };
                    assert_eq!(m, mask, "the AVX2 frustum test differs");
                }
                for c in 0..WIDTH {
                    if node.child[c] == EMPTY {
                        assert_eq!(mask >> c & 1, 0, "an empty slot was kept");
                        continue;
                    }
                    let (hit, _) = test_child::<false>(&lanes, node, c, &packet, ALL_LANES);
                    assert!(
                        hit == 0 || mask >> c & 1 == 1,
                        "trial {trial}: child {c} left out, lanes {hit:#b} enter it"
                    );
                    if hit == 0 {
                        missed += 1;
                        left_out += (mask >> c & 1 == 0) as u64;
                    }
                }
            }
        }
        assert!(packets > 100, "{packets} packets in one octant");
        assert!(
            left_out as f64 >= 0.7 * missed as f64,
            "only {left_out} of {missed} children every lane misses were left out"
        );
    }
}
