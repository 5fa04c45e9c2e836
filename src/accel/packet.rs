//! Packet traversal of obvhs's CWBVH: up to [`LANES`] rays visit the tree
//! together.
//!
//! Each node's eight child boxes are decoded once and tested against every
//! active lane in a branch-free loop over structure-of-arrays lanes, which
//! the compiler turns into SIMD. Coherent rays (camera rays, shadow rays
//! towards one light) share most nodes, so a packet does one traversal's
//! bookkeeping for up to eight rays. Primitive tests stay per lane and call
//! the same kernels as single-ray traversal, so the hits are the same.

use glam::{Vec3A, Vec4};
use obvhs::cwbvh::CwBvh;

use crate::accel::node::{DecodedNode, NodeRay, present_children};
use crate::core::math::Ray;

/// Rays per packet.
pub const LANES: usize = 8;

/// A bit set of packet lanes.
pub type LaneMask = u32;

/// Every lane of a full packet.
pub const ALL_LANES: LaneMask = (1 << LANES) - 1;

/// Rays with their search intervals, lane by lane.
#[derive(Clone, Copy, Debug)]
pub struct Packet {
    /// The rays prepared for the node test.
    node_rays: [NodeRay; LANES],
    /// Interval starts.
    pub t_min: [f32; LANES],
    /// Interval ends; closest-hit traversal shrinks them as hits are found.
    pub t_max: [f32; LANES],
    /// The rays themselves, for primitive tests.
    pub rays: [Ray; LANES],
    /// Lanes holding a ray.
    pub valid: LaneMask,
}

impl Packet {
    /// Packs up to [`LANES`] rays with their intervals.
    pub fn new(rays: &[Ray], t_min: &[f32], t_max: &[f32]) -> Self {
        debug_assert!(
            rays.len() <= LANES && rays.len() == t_min.len() && rays.len() == t_max.len()
        );
        let empty = Ray::new(Vec3A::ZERO, Vec3A::X);
        let mut p = Packet {
            node_rays: [NodeRay::new(&empty); LANES],
            t_min: [0.0; LANES],
            // Unused lanes can never hit.
            t_max: [f32::NEG_INFINITY; LANES],
            rays: [empty; LANES],
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
        self.node_rays[l] = NodeRay::new(&r);
        self.t_min[l] = t_min;
        self.t_max[l] = t_max;
        self.rays[l] = r;
        self.valid |= 1 << l;
    }

    /// The node test of every lane in `active` against the children of
    /// `node`: per child, the lanes that enter it and the smallest entry
    /// distance among them.
    #[inline(always)]
    fn test_node(&self, node: &DecodedNode, active: LaneMask) -> ([LaneMask; 8], [f32; 8]) {
        // Byte `l` of `masks`: the children lane `l` enters. Entry
        // distances are folded per register, without branches.
        let mut masks = 0u64;
        let mut near = [Vec4::INFINITY; 2];
        for_each_lane(active, |l| {
            let (hit, enter) = node.test_lanes(&self.node_rays[l], self.t_min[l], self.t_max[l]);
            masks |= ((hit[0].bitmask() | hit[1].bitmask() << 4) as u64) << (8 * l);
            for k in 0..2 {
                near[k] = Vec4::select(hit[k], near[k].min(enter[k]), near[k]);
            }
        });
        // Transpose the 8x8 bit matrix: byte `c` becomes the lanes that
        // enter child `c`.
        let t = transpose8x8(masks);
        let lanes = std::array::from_fn(|c| ((t >> (8 * c)) & 0xff) as LaneMask);
        let near = std::array::from_fn(|c| near[c / 4][c % 4]);
        (lanes, near)
    }
}

/// Transposes an 8x8 bit matrix held as eight bytes (bit `j` of byte `i`
/// becomes bit `i` of byte `j`), by three rounds of block swaps.
#[inline(always)]
fn transpose8x8(mut x: u64) -> u64 {
    let t = (x ^ (x >> 7)) & 0x00aa_00aa_00aa_00aa;
    x ^= t ^ (t << 7);
    let t = (x ^ (x >> 14)) & 0x0000_cccc_0000_cccc;
    x ^= t ^ (t << 14);
    let t = (x ^ (x >> 28)) & 0x0000_0000_f0f0_f0f0;
    x ^= t ^ (t << 28);
    x
}

/// Most node entries a traversal stack holds (depth times eight children).
const STACK: usize = 32 * 8;

/// Visits every leaf primitive slot whose box some lane's interval
/// reaches, calling `leaf(packet, lanes, slot)` with the lanes that reach
/// it; `slot` indexes `bvh.primitive_indices`. For closest-hit queries
/// `leaf` shrinks `packet.t_max` of the lanes it hits, which prunes the
/// rest of the traversal; for occlusion queries it returns the lanes found
/// blocked, which retires them. Traversal ends when no lane is left.
///
/// Children are visited nearest first (by the packet's smallest entry
/// distance), and a popped node is skipped when no lane can still reach it.
pub fn traverse(
    bvh: &CwBvh,
    packet: &mut Packet,
    active: LaneMask,
    mut leaf: impl FnMut(&mut Packet, LaneMask, usize) -> LaneMask,
) {
    if bvh.nodes.is_empty() {
        return;
    }
    let mut alive = active & packet.valid;
    // Left uninitialised: zeroing 3 KB per traversal cost more than the
    // traversal of a small tree. Only entries below `top` are ever read.
    let mut stack = [const { std::mem::MaybeUninit::<(u32, LaneMask, f32)>::uninit() }; STACK];
    let mut spill: Vec<(u32, LaneMask, f32)> = Vec::new();
    let mut top = 1;
    stack[0].write((0, alive, f32::NEG_INFINITY));
    while top > 0 && alive != 0 {
        top -= 1;
        let (index, lanes, near) = if top >= STACK {
            spill.pop().expect("spilled entries above the fixed stack")
        } else {
            // SAFETY: every entry below `top` (and below STACK) was written
            // before `top` passed it.
            #[allow(unsafe_code)]
            unsafe {
                stack[top].assume_init()
            }
        };
        let lanes = lanes & alive;
        if lanes == 0 {
            continue;
        }
        // Skip when every lane has since found a hit nearer than the node.
        let mut reachable = false;
        for l in 0..LANES {
            reachable |= (lanes >> l) & 1 == 1 && near <= packet.t_max[l];
        }
        if !reachable {
            continue;
        }
        let node = &bvh.nodes[index as usize];
        let present = present_children(node);
        let (hit_lanes, near) = packet.test_node(&DecodedNode::new(node), lanes);
        let mut children: [(u32, LaneMask, f32); 8] = [(0, 0, 0.0); 8];
        let mut count = 0;
        for c in 0..8 {
            let hit = hit_lanes[c];
            if (present >> c) & 1 == 0 || hit == 0 {
                continue;
            }
            if node.is_leaf(c) {
                let (first, n) = node.child_primitives(c);
                for slot in first..first + n {
                    let lanes = hit & alive;
                    if lanes != 0 {
                        alive &= !leaf(packet, lanes, slot as usize);
                    }
                }
            } else {
                children[count] = (node.child_node_index(c), hit, near[c]);
                count += 1;
            }
        }
        // Push far to near, so the nearest child is popped first.
        children[..count].sort_unstable_by(|a, b| b.2.total_cmp(&a.2));
        for &child in &children[..count] {
            // Trees up to 32 levels deep fit the fixed stack (at most
            // 7 * 32 + 1 entries are pending); deeper ones, which only
            // degenerate input produces, spill to the heap. obvhs checks
            // depth in debug builds only.
            if top < STACK {
                stack[top].write(child);
            } else {
                spill.push(child);
            }
            top += 1;
        }
    }
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

    #[test]
    fn bit_matrix_transpose() {
        let mut s = 99u64;
        for _ in 0..100 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let t = transpose8x8(s);
            for i in 0..8 {
                for j in 0..8 {
                    assert_eq!((s >> (8 * i + j)) & 1, (t >> (8 * j + i)) & 1);
                }
            }
        }
    }

    #[test]
    fn lanes_enter_the_children_their_rays_pass_through() {
        use crate::accel::build::{BuildQuality, build_bvh};
        use obvhs::aabb::Aabb;
        // Two unit boxes on the x axis, at x = 0 and x = 10.
        let boxes = [
            Aabb::new(Vec3A::splat(-0.5), Vec3A::splat(0.5)),
            Aabb::new(Vec3A::new(9.5, -0.5, -0.5), Vec3A::new(10.5, 0.5, 0.5)),
        ];
        let bvh = build_bvh(&boxes, BuildQuality::Medium);
        let rays = [
            Ray::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::Z),
            Ray::new(Vec3A::new(3.0, 0.0, -5.0), Vec3A::Z),
            Ray::new(Vec3A::new(10.0, 0.2, 5.0), -Vec3A::Z),
            Ray::new(Vec3A::new(0.0, -0.0, -5.0), Vec3A::new(-0.0, 0.0, 1.0)),
        ];
        let mut p = Packet::new(&rays, &[0.0; 4], &[f32::INFINITY; 4]);
        let mut reached = [0 as LaneMask; 2];
        traverse(&bvh, &mut p, ALL_LANES, |_, lanes, slot| {
            reached[bvh.primitive_indices[slot] as usize] |= lanes;
            0
        });
        assert_eq!(reached, [0b1001, 0b0100]);
    }
}
