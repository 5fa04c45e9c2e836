//! Packet traversal of a [`Bvh8`] with 16 lanes: the camera rays of a
//! 4x4 pixel block visit the tree together.
//!
//! The same traversal as [`crate::accel::packet`] (nearest child first by
//! the smallest entry distance of its lanes, stale subtrees skipped per
//! lane, lanes that diverge finishing alone by single-ray traversal, mixed
//! octants traced ray by ray), twice as wide: on the AVX-512 path one
//! child's test of all 16 lanes is one register per quantity, so the
//! packet's node work is shared by twice as many rays. The portable and
//! AVX2 paths run the same operations lane by lane (plain loops the
//! compiler widens). The AVX-512 path computes the slab distances with
//! fused multiply-adds (as [`NodeRay::test_fused`]), which round
//! differently by far less than the margin: the test stays conservative,
//! and since a mesh's closest hit does not depend on the order in which
//! its leaves are visited, every path gives the same hits.
//!
//! Rays that leave one point (a pinhole camera's 4x4 pixel block) test
//! inner nodes as one frustum (`accel::frustum`, the bound the packets of
//! 8 use as a filter): the eight children in one 8-wide operation for
//! the whole packet instead of eight 16-lane tests, only the children
//! that are leaves tested lane by lane. On the anchors' camera rays (100k
//! triangles, one thread, AVX-512) that took packets of 16 from 14.4 to
//! 15.0-15.4 Mrays/s with the leaves' finishing steps side by side
//! (`WatertightRay::intersect8_lanes16`), and to 16.2 with leaves that
//! few lanes reach tested lane by lane (`geometry::mesh`). Packets from
//! scattered points (shadow rays) keep the lane tests: under their looser
//! bound they visited too many nodes (see `traverse16`).

use std::mem::MaybeUninit;

use crate::accel::bvh8::{Bvh8, EMPTY, LEAF, Node8, WIDTH, leaf_index};
use crate::accel::frustum::{Frustum, masked_max};
use crate::accel::node::{NodeRay, max_keep, min_keep};
use crate::accel::packet::{LaneMask, PacketOf, for_each_lane};
use crate::accel::single::traverse_from;

/// Rays per packet.
pub const LANES16: usize = 16;

/// Every lane of a full packet.
pub const ALL_LANES16: LaneMask = (1 << LANES16) - 1;

/// A packet that has shrunk to this many lanes continues ray by ray.
const DIVERGED: u32 = 2;

/// Rays with their search intervals, lane by lane: the packet of
/// [`crate::accel::packet`] with 16 lanes.
pub type Packet16 = PacketOf<LANES16>;

/// The lanes of a packet prepared for one tree, axis by axis.
#[repr(C, align(64))]
struct Lanes {
    o_near: [[f32; LANES16]; 3],
    o_far: [[f32; LANES16]; 3],
    inv: [[f32; LANES16]; 3],
    /// `o_near * inv` and `o_far * inv`, for the fused form of the
    /// AVX-512 child test.
    o_inv: [[[f32; LANES16]; 3]; 2],
    /// Row of each axis's near plane (common to all lanes).
    near: [usize; 3],
    /// Whether every lane may use the fused form (as
    /// [`NodeRay::fused`]).
    fused: bool,
}

/// A pending subtree: child reference, lanes, smallest entry distance.
type Pending = (u32, LaneMask, f32);

/// Pending subtrees held without allocating.
const FIXED: usize = 48;

/// Visits every leaf whose box some lane's interval reaches, calling
/// `leaf(packet, lanes, leaf)` with the lanes that reach it, exactly as
/// [`crate::accel::packet::traverse`] does for 8 lanes: `leaf` shrinks
/// `packet.t_max` of the lanes it hits (closest hit) or returns the lanes
/// found blocked, which retires them. `AVX` selects the AVX2 code of the
/// single-ray fallback and `AVX512` the 16-wide child test (each only
/// valid on a CPU that has it, see [`crate::core::simd`]).
#[inline(always)]
pub fn traverse16<const AVX: bool, const AVX512: bool>(
    bvh: &Bvh8,
    packet: &mut Packet16,
    active: LaneMask,
    mut leaf: impl FnMut(&mut Packet16, LaneMask, u32) -> LaneMask,
) {
    let mut alive = active & packet.valid;
    if bvh.nodes.is_empty() || alive == 0 {
        return;
    }
    // The lanes prepared as `NodeRay::new` prepares a ray, in loops over
    // the lanes that the compiler widens (one division per axis for the
    // whole packet on the AVX-512 path). Lanes that diverge later prepare
    // their own `NodeRay`: the same values.
    let mut lanes = Lanes {
        o_near: [[0.0; LANES16]; 3],
        o_far: [[0.0; LANES16]; 3],
        inv: [[0.0; LANES16]; 3],
        o_inv: [[[0.0; LANES16]; 3]; 2],
        near: [0; 3],
        fused: true,
    };
    let mut margin = [0.0f32; LANES16];
    let mut o = [[0.0f32; LANES16]; 3];
    let mut d = [[0.0f32; LANES16]; 3];
    let mut o_mag = [0.0f32; LANES16];
    let mut fused = true;
    for (l, r) in packet.rays.iter().enumerate() {
        o_mag[l] = r.origin.abs().max_element();
        margin[l] = crate::accel::node::margin(o_mag[l], bvh.magnitude);
        for a in 0..3 {
            o[a][l] = r.origin[a];
            d[a][l] = r.direction[a];
        }
    }
    let lead = alive.trailing_zeros() as usize;
    let mut mixed = false;
    for a in 0..3 {
        let mut down: LaneMask = 0;
        for l in 0..LANES16 {
            let inv = 1.0 / d[a][l];
            let shift = margin[l].copysign(inv);
            lanes.inv[a][l] = inv;
            lanes.o_near[a][l] = o[a][l] + shift;
            lanes.o_far[a][l] = o[a][l] - shift;
            lanes.o_inv[0][a][l] = lanes.o_near[a][l] * inv;
            lanes.o_inv[1][a][l] = lanes.o_far[a][l] * inv;
            down |= (inv.is_sign_negative() as LaneMask) << l;
            // `NodeRay::fused`'s condition, for every alive lane (the
            // padding of a partial packet never enters a test's result).
            let reach = bvh.magnitude + o_mag[l] + margin[l];
            fused &= (inv.abs() * reach < 1.0e30) | (alive >> l & 1 == 0);
        }
        let down = down & alive;
        mixed |= down != 0 && down != alive;
        lanes.near[a] = a + 3 * ((down >> lead) & 1) as usize;
    }
    lanes.fused = fused;
    // Only for rays from one point: shadow rays of a pixel block (from
    // scattered points towards a light) visited so many more nodes under
    // their looser bound that the frame-loop benchmark ran 0.89-0.95x as
    // fast with it.
    let mut spread = 0u32;
    for axis in &o {
        let lead_bits = axis[lead].to_bits();
        for (l, v) in axis.iter().enumerate() {
            let m = ((alive >> l) & 1).wrapping_neg();
            spread |= (v.to_bits() ^ lead_bits) & m;
        }
    }
    let frustum = if mixed || spread != 0 || alive.count_ones() <= DIVERGED {
        None
    } else {
        Frustum::new::<LANES16, AVX512>(
            &lanes.o_near,
            &lanes.o_far,
            &lanes.inv,
            lanes.near,
            alive,
            &packet.t_min,
        )
    };
    if mixed {
        for_each_lane(
            alive,
            #[inline(always)]
            |l| {
                let ray = NodeRay::new(&packet.rays[l], bvh);
                single_lane::<AVX>(bvh, 0, &ray, packet, l, &mut leaf);
            },
        );
        return;
    }
    let mut fixed = [const { MaybeUninit::<Pending>::uninit() }; FIXED];
    let mut top = 0;
    let mut spill: Vec<Pending> = Vec::new();
    fixed[0].write((0, alive, f32::NEG_INFINITY));
    top += 1;
    loop {
        // The spill holds entries only while the fixed part is full.
        let (cur, lanes_in, near) = if top == FIXED
            && let Some(e) = spill.pop()
        {
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
        let go = not_beyond::<AVX512>(near, &packet.t_max) & lanes_in & alive;
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
                    let ray = NodeRay::new(&packet.rays[l], bvh);
                    if single_lane::<AVX>(bvh, cur, &ray, packet, l, &mut leaf) {
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
        if let Some(f) = &frustum {
            // One test of the eight children for the whole packet; the
            // lanes that reach a child are sorted out at its leaves.
            let (mut mask, enter) =
                f.test::<AVX>(node, masked_max::<LANES16, AVX512>(go, &packet.t_max));
            while mask != 0 {
                let c = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let child = node.child[c];
                // A leaf's lanes are tested one by one (16 lanes in one
                // register on the AVX-512 path): a leaf test costs many
                // node tests, and lanes that miss its box are dropped.
                let (hit, t) = if child & LEAF != 0 {
                    test_child::<AVX512>(&lanes, node, c, packet, go)
                } else {
                    (go, enter[c])
                };
                if hit == 0 {
                    continue;
                }
                let mut j = n;
                while j > 0 && found[j - 1].2 < t {
                    found[j] = found[j - 1];
                    j -= 1;
                }
                found[j] = (child, hit, t);
                n += 1;
            }
        }
        for c in 0..if frustum.is_some() { 0 } else { WIDTH } {
            let child = node.child[c];
            if child == EMPTY {
                break;
            }
            let (hit, t) = test_child::<AVX512>(&lanes, node, c, packet, go);
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
            if e.0 & LEAF == 0 {
                crate::accel::single::prefetch_bytes(
                    &bvh.nodes[e.0 as usize],
                    std::mem::size_of::<Node8>(),
                );
            }
            if top < FIXED {
                fixed[top].write(e);
                top += 1;
            } else {
                spill.push(e);
            }
        }
    }
}

/// A packet width with a traversal of its own: lets code written once
/// for packets of `N` lanes (the scene's top level,
/// [`crate::scene::RenderScene`]) run [`crate::accel::packet::traverse`]
/// on packets of 8 and [`traverse16`] on packets of 16.
pub trait PacketTraversal: Sized {
    /// Visits the leaves of `bvh` that the lanes in `active` reach, as
    /// [`traverse16`] does (`AVX512` is ignored by packets of 8).
    fn traverse_bvh<const AVX: bool, const AVX512: bool>(
        &mut self,
        bvh: &Bvh8,
        active: LaneMask,
        leaf: impl FnMut(&mut Self, LaneMask, u32) -> LaneMask,
    );
}

impl PacketTraversal for crate::accel::packet::Packet {
    #[inline(always)]
    fn traverse_bvh<const AVX: bool, const AVX512: bool>(
        &mut self,
        bvh: &Bvh8,
        active: LaneMask,
        leaf: impl FnMut(&mut Self, LaneMask, u32) -> LaneMask,
    ) {
        // The top level keeps the lane tests alone (see `packet::traverse`).
        crate::accel::packet::traverse::<AVX, false>(bvh, self, active, leaf);
    }
}

impl PacketTraversal for Packet16 {
    #[inline(always)]
    fn traverse_bvh<const AVX: bool, const AVX512: bool>(
        &mut self,
        bvh: &Bvh8,
        active: LaneMask,
        leaf: impl FnMut(&mut Self, LaneMask, u32) -> LaneMask,
    ) {
        traverse16::<AVX, AVX512>(bvh, self, active, leaf);
    }
}

/// The lanes whose `t_max` is at least `near`.
#[inline(always)]
fn not_beyond<const AVX512: bool>(near: f32, t_max: &[f32; LANES16]) -> LaneMask {
    #[cfg(target_arch = "x86_64")]
    if AVX512 {
        // SAFETY: `AVX512` is set only by the AVX-512 entry points, which
        // run only on CPUs with AVX-512F (`simd::use_avx512`).
        #[allow(unsafe_code)]
        unsafe {
            use std::arch::x86_64::*;
            let t: __m512 = std::mem::transmute(*t_max);
            return _mm512_cmp_ps_mask::<_CMP_LE_OQ>(_mm512_set1_ps(near), t) as LaneMask;
        }
    }
    let mut go = 0;
    for (l, &t) in t_max.iter().enumerate() {
        go |= ((near <= t) as LaneMask) << l;
    }
    go
}

/// Child `c` of `node` against the lanes: the lanes in `go` that enter
/// it, and their smallest entry distance. The operations of
/// [`NodeRay::test`] lane by lane.
#[inline(always)]
fn test_child<const AVX512: bool>(
    lanes: &Lanes,
    node: &Node8,
    c: usize,
    packet: &Packet16,
    go: LaneMask,
) -> (LaneMask, f32) {
    #[cfg(target_arch = "x86_64")]
    if AVX512 {
        // SAFETY: `AVX512` is set only by the AVX-512 entry points, which
        // run only on CPUs with AVX-512F (`simd::use_avx512`).
        #[allow(unsafe_code)]
        return unsafe { test_child_avx512(lanes, node, c, packet, go) };
    }
    let mut enter = packet.t_min;
    let mut exit = packet.t_max;
    for a in 0..3 {
        let n = lanes.near[a];
        let near = node.planes[n][c];
        let far = node.planes[(n + 3) % 6][c];
        for l in 0..LANES16 {
            enter[l] = max_keep((near - lanes.o_near[a][l]) * lanes.inv[a][l], enter[l]);
            exit[l] = min_keep((far - lanes.o_far[a][l]) * lanes.inv[a][l], exit[l]);
        }
    }
    let mut hit = 0;
    for l in 0..LANES16 {
        hit |= ((enter[l] <= exit[l]) as LaneMask) << l;
    }
    let hit = hit & go;
    let mut t = f32::INFINITY;
    for_each_lane(
        hit,
        #[inline(always)]
        |l| t = min_keep(enter[l], t),
    );
    (hit, t)
}

/// [`test_child`] in one 16-wide AVX-512 register.
///
/// # Safety
/// Only on a CPU with AVX-512F, inlined into an AVX-512 entry point (see
/// [`crate::core::simd`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unsafe_code)]
unsafe fn test_child_avx512(
    lanes: &Lanes,
    node: &Node8,
    c: usize,
    packet: &Packet16,
    go: LaneMask,
) -> (LaneMask, f32) {
    // SAFETY: the caller runs on a CPU with AVX-512F.
    unsafe {
        use std::arch::x86_64::*;
        let mut enter: __m512 = std::mem::transmute(packet.t_min);
        let mut exit: __m512 = std::mem::transmute(packet.t_max);
        if lanes.fused {
            // As `NodeRay::test_fma`: one fused multiply-add per slab,
            // `plane * inv - o * inv`. The distances round differently
            // from the portable path's by far less than the margin, so
            // the test stays conservative and the closest hits (which do
            // not depend on the order of a mesh's leaves) are the same.
            for a in 0..3 {
                let n = lanes.near[a];
                let near = _mm512_set1_ps(node.planes[n][c]);
                let far = _mm512_set1_ps(node.planes[(n + 3) % 6][c]);
                let inv: __m512 = std::mem::transmute(lanes.inv[a]);
                let on: __m512 = std::mem::transmute(lanes.o_inv[0][a]);
                let of: __m512 = std::mem::transmute(lanes.o_inv[1][a]);
                enter = _mm512_max_ps(_mm512_fmsub_ps(near, inv, on), enter);
                exit = _mm512_min_ps(_mm512_fmsub_ps(far, inv, of), exit);
            }
            let hit = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(go as __mmask16, enter, exit);
            if hit == 0 {
                return (0, f32::INFINITY);
            }
            let e = _mm512_mask_blend_ps(hit, _mm512_set1_ps(f32::INFINITY), enter);
            return (hit as LaneMask, _mm512_reduce_min_ps(e));
        }
        for a in 0..3 {
            let n = lanes.near[a];
            let near = _mm512_set1_ps(node.planes[n][c]);
            let far = _mm512_set1_ps(node.planes[(n + 3) % 6][c]);
            let on: __m512 = std::mem::transmute(lanes.o_near[a]);
            let of: __m512 = std::mem::transmute(lanes.o_far[a]);
            let inv: __m512 = std::mem::transmute(lanes.inv[a]);
            // `maxps`/`minps` keep the second operand over a NaN, as
            // `max_keep`/`min_keep`.
            enter = _mm512_max_ps(_mm512_mul_ps(_mm512_sub_ps(near, on), inv), enter);
            exit = _mm512_min_ps(_mm512_mul_ps(_mm512_sub_ps(far, of), inv), exit);
        }
        let hit = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(go as __mmask16, enter, exit);
        if hit == 0 {
            return (0, f32::INFINITY);
        }
        // Entries are never NaN (`maxps` keeps `t_min` over a NaN slab), so
        // the order of the minima does not matter: the lane loop's value.
        let e = _mm512_mask_blend_ps(hit, _mm512_set1_ps(f32::INFINITY), enter);
        (hit as LaneMask, _mm512_reduce_min_ps(e))
    }
}

/// Lane `l` alone through the subtree at `start`; returns whether it was
/// retired (blocked, for occlusion queries).
#[inline(always)]
fn single_lane<const AVX: bool>(
    bvh: &Bvh8,
    start: u32,
    ray: &NodeRay,
    packet: &mut Packet16,
    l: usize,
    leaf: &mut impl FnMut(&mut Packet16, LaneMask, u32) -> LaneMask,
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
                return Some(f32::NEG_INFINITY);
            }
            (packet.t_max[l] < before).then_some(packet.t_max[l])
        },
    );
    retired
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::math::Ray;
    use glam::Vec3A;
    use obvhs::aabb::Aabb;

    /// The frustum of a packet enters every child box some lane's own
    /// test enters, never later than that lane (on every SIMD path this
    /// CPU has), for rays from one point and from scattered points, and
    /// not many more for narrow fans from one point.
    #[allow(clippy::needless_range_loop)]
    #[test]
    fn frustum_enters_what_its_lanes_enter() {
        let mut s = 7u64;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        let boxes: Vec<Aabb> = (0..400)
            .map(|_| {
                let c = Vec3A::new(next(), next(), next()) * 10.0;
                let h = Vec3A::new(next().abs(), next().abs(), next().abs()) * 0.6 + 0.01;
                Aabb::new(c - h, c + h)
            })
            .collect();
        let bvh = Bvh8::build(&boxes, obvhs::BvhBuildParams::medium_build(), 1);
        let (mut lane_hits, mut frustum_hits, mut packets) = (0u32, 0u32, 0u32);
        for k in 0..300 {
            let o = Vec3A::new(next(), next(), next()) * 14.0;
            let centre = Vec3A::new(next(), next(), next()).normalize();
            // Narrow fans (camera blocks) and wide ones, from one point
            // (k % 4 < 2) or from scattered points (shadow rays).
            let spread = if k % 2 == 0 { 0.02 } else { 0.3 };
            let scatter = if k % 4 < 2 { 0.0 } else { 0.5 };
            let rays: Vec<Ray> = (0..LANES16)
                .map(|_| {
                    let d = centre + Vec3A::new(next(), next(), next()) * spread;
                    let jitter = Vec3A::new(next(), next(), next()) * scatter;
                    Ray::new(o + jitter, d.normalize())
                })
                .collect();
            let t_max: Vec<f32> = (0..LANES16)
                .map(|l| if l % 5 == 0 { 6.0 } else { f32::INFINITY })
                .collect();
            let packet = Packet16::new(&rays, &[0.0; LANES16], &t_max);
            let mut lanes = Lanes {
                o_near: [[0.0; LANES16]; 3],
                o_far: [[0.0; LANES16]; 3],
                inv: [[0.0; LANES16]; 3],
                o_inv: [[[0.0; LANES16]; 3]; 2],
                near: [0; 3],
                fused: true,
            };
            let node_rays: Vec<NodeRay> = rays.iter().map(|r| NodeRay::new(r, &bvh)).collect();
            let mut octants = Vec::new();
            for (l, nr) in node_rays.iter().enumerate() {
                for a in 0..3 {
                    lanes.o_near[a][l] = nr.o_near[a];
                    lanes.o_far[a][l] = nr.o_far[a];
                    lanes.inv[a][l] = nr.inv[a];
                    lanes.near[a] = nr.near[a] as usize;
                }
                lanes.fused &= nr.fused;
                octants.push(nr.octant);
            }
            if octants.iter().any(|&c| c != octants[0]) {
                continue;
            }
            packets += 1;
            let f = Frustum::new::<LANES16, false>(
                &lanes.o_near,
                &lanes.o_far,
                &lanes.inv,
                lanes.near,
                ALL_LANES16,
                &packet.t_min,
            )
            .expect("lanes in one octant, none along an axis");
            let reach = masked_max::<LANES16, false>(ALL_LANES16, &packet.t_max);
            for node in &bvh.nodes {
                let tests = [f.test::<false>(node, reach), {
                    #[cfg(target_arch = "x86_64")]
                    if crate::core::simd::use_avx2() {
                        f.test::<true>(node, reach)
                    } else {
                        f.test::<false>(node, reach)
                    }
                    #[cfg(not(target_arch = "x86_64"))]
                    f.test::<false>(node, reach)
                }];
                assert_eq!(tests[0].0, tests[1].0, "the SIMD paths disagree");
                let (mask, enter) = tests[0];
                if k % 4 == 0 {
                    frustum_hits += mask.count_ones();
                }
                let mut any = 0u32;
                for (l, nr) in node_rays.iter().enumerate() {
                    let (m, e) = nr.test::<false>(node, 0.0, t_max[l]);
                    any |= m;
                    for c in 0..WIDTH {
                        if (m >> c) & 1 == 1 {
                            assert!(
                                (mask >> c) & 1 == 1,
                                "packet {k}: lane {l} enters child {c}, the frustum does not"
                            );
                            assert!(
                                enter[c] <= e[c],
                                "packet {k}: the frustum enters child {c} after lane {l}"
                            );
                        }
                    }
                }
                if k % 4 == 0 {
                    lane_hits += any.count_ones();
                }
            }
        }
        assert!(packets > 150, "{packets} packets in one octant");
        // Narrow fans: the frustum is hardly wider than its lanes.
        assert!(
            (frustum_hits as f64) < lane_hits as f64 * 1.3,
            "the frustum enters {frustum_hits} children, its lanes {lane_hits}"
        );
    }
}
