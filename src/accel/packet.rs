//! Packet traversal of obvhs's CWBVH: up to [`LANES`] rays visit the tree
//! together.
//!
//! Each node's eight child boxes are decoded once and tested against every
//! active lane in a branch-free loop over structure-of-arrays lanes, which
//! the compiler turns into SIMD. Coherent rays (camera rays, shadow rays
//! towards one light) share most nodes, so a packet does one traversal's
//! bookkeeping for up to eight rays. Primitive tests stay per lane and call
//! the same kernels as single-ray traversal, so the hits are the same.

use glam::Vec3A;
use obvhs::cwbvh::CwBvh;

use crate::core::math::Ray;

/// Rays per packet.
pub const LANES: usize = 8;

/// A bit set of packet lanes.
pub type LaneMask = u32;

/// Every lane of a full packet.
pub const ALL_LANES: LaneMask = (1 << LANES) - 1;

/// Rays in structure-of-arrays form, with their search intervals.
#[derive(Clone, Copy, Debug)]
pub struct Packet {
    /// Origins, per axis.
    pub origin: [[f32; LANES]; 3],
    /// Reciprocal directions, per axis (0 where the direction component is
    /// zero or its reciprocal overflows: see `parallel`).
    pub inv_dir: [[f32; LANES]; 3],
    /// Per axis, the lanes that do not move along it: their slab test is
    /// an inside/outside test.
    pub parallel: [LaneMask; 3],
    /// Largest coordinate magnitude of any lane's origin (for the box
    /// margin, see [`crate::geometry::mesh::NODE_MARGIN_EPS`]).
    pub origin_mag: f32,
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
        let mut p = Packet {
            origin: [[0.0; LANES]; 3],
            inv_dir: [[0.0; LANES]; 3],
            parallel: [0; 3],
            origin_mag: 0.0,
            t_min: [0.0; LANES],
            // Unused lanes can never hit.
            t_max: [f32::NEG_INFINITY; LANES],
            rays: [Ray::new(Vec3A::ZERO, Vec3A::X); LANES],
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
        for a in 0..3 {
            self.origin[a][l] = r.origin[a];
            let inv = 1.0 / r.direction[a];
            if inv.is_finite() {
                self.inv_dir[a][l] = inv;
                self.parallel[a] &= !(1 << l);
            } else {
                self.inv_dir[a][l] = 0.0;
                self.parallel[a] |= 1 << l;
            }
        }
        self.origin_mag = self.origin_mag.max(r.origin.abs().max_element());
        self.t_min[l] = t_min;
        self.t_max[l] = t_max;
        self.rays[l] = r;
        self.valid |= 1 << l;
    }

    /// Slab test of one box against every lane: the mask of lanes whose
    /// interval overlaps the box, and the smallest entry distance among them.
    #[inline(always)]
    fn hit_box(&self, min: Vec3A, max: Vec3A, active: LaneMask) -> (LaneMask, f32) {
        let mut near = [0.0f32; LANES];
        let mut far = [0.0f32; LANES];
        // Plain comparisons (not f32::min/max, whose NaN handling blocks
        // vectorisation); no NaN can arise: inverse directions are finite.
        #[inline(always)]
        fn lo(a: f32, b: f32) -> f32 {
            if a < b { a } else { b }
        }
        #[inline(always)]
        fn hi(a: f32, b: f32) -> f32 {
            if a > b { a } else { b }
        }
        for l in 0..LANES {
            let mut t0 = self.t_min[l];
            let mut t1 = self.t_max[l];
            for a in 0..3 {
                let s0 = (min[a] - self.origin[a][l]) * self.inv_dir[a][l];
                let s1 = (max[a] - self.origin[a][l]) * self.inv_dir[a][l];
                // A lane parallel to the axis is not limited by its slab
                // here; the inside test below decides.
                let open = (self.parallel[a] >> l) & 1 == 1;
                let (n, f) = if open {
                    (f32::NEG_INFINITY, f32::INFINITY)
                } else {
                    (lo(s0, s1), hi(s0, s1))
                };
                t0 = hi(t0, n);
                t1 = lo(t1, f);
            }
            // The products carry one rounding each: widen by a few ulps.
            near[l] = t0 - t0.abs() * (4.0 * f32::EPSILON);
            far[l] = t1 + t1.abs() * (4.0 * f32::EPSILON);
        }
        // Lanes that do not move along an axis: inside the slab or never.
        for a in 0..3 {
            let mut m = self.parallel[a];
            while m != 0 {
                let l = m.trailing_zeros() as usize;
                m &= m - 1;
                let o = self.origin[a][l];
                if !(min[a] <= o && o <= max[a]) {
                    near[l] = f32::INFINITY;
                    far[l] = f32::NEG_INFINITY;
                }
            }
        }
        let mut mask = 0;
        let mut nearest = f32::INFINITY;
        for l in 0..LANES {
            let hit = near[l] <= far[l];
            mask |= (hit as LaneMask) << l;
            if hit && (active >> l) & 1 == 1 {
                nearest = nearest.min(near[l]);
            }
        }
        (mask & active, nearest)
    }
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
    let mut top = 1;
    stack[0].write((0, alive, f32::NEG_INFINITY));
    while top > 0 && alive != 0 {
        top -= 1;
        // SAFETY: every entry below `top` was written before `top` passed it.
        let (index, lanes, near) = unsafe { stack[top].assume_init() };
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
        // The same conservative margin as single-ray traversal, so that a
        // packet never culls a box the watertight triangle test would enter.
        let node_box = node.aabb();
        let node_mag = node_box.min.abs().max(node_box.max.abs()).max_element();
        let margin = Vec3A::splat(
            crate::geometry::mesh::NODE_MARGIN_EPS * f32::EPSILON * (packet.origin_mag + node_mag),
        );
        let mut children: [(u32, LaneMask, f32); 8] = [(0, 0, 0.0); 8];
        let mut count = 0;
        for c in 0..8 {
            if node.is_child_empty(c) {
                continue;
            }
            let b = node.child_aabb(c);
            let (hit, dist) = packet.hit_box(b.min - margin, b.max + margin, lanes);
            if hit == 0 {
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
                children[count] = (node.child_node_index(c), hit, dist);
                count += 1;
            }
        }
        // Push far to near, so the nearest child is popped first.
        children[..count].sort_unstable_by(|a, b| b.2.total_cmp(&a.2));
        for &child in &children[..count] {
            // A CWBVH is at most 32 levels deep (obvhs validates it), so at
            // most 7 * 32 + 1 entries are ever pending.
            assert!(top < STACK, "CWBVH deeper than 32 levels");
            stack[top].write(child);
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
    use obvhs::aabb::Aabb;

    #[test]
    fn box_test_matches_a_scalar_slab_test() {
        let rays = [
            Ray::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::Z),
            Ray::new(Vec3A::new(3.0, 0.0, -5.0), Vec3A::Z),
            Ray::new(Vec3A::new(0.5, 0.5, 5.0), -Vec3A::Z),
            Ray::new(Vec3A::new(0.0, -0.0, -5.0), Vec3A::new(-0.0, 0.0, 1.0)),
        ];
        let p = Packet::new(&rays, &[0.0; 4], &[f32::INFINITY; 4]);
        let (mask, near) = p.hit_box(Vec3A::splat(-1.0), Vec3A::splat(1.0), ALL_LANES);
        assert_eq!(mask, 0b1101);
        // Entry at 4, widened by a few ulps.
        assert!(near <= 4.0 && near > 4.0 - 1e-5);
        // Lanes outside `active` and empty lanes never report a hit.
        let (mask, _) = p.hit_box(Vec3A::splat(-1.0), Vec3A::splat(1.0), 0b0001);
        assert_eq!(mask, 0b0001);
        let _ = Aabb::empty();
    }
}
