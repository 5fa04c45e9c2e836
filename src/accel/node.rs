//! The conservative node test: one decode of a CwBvh node's eight child
//! boxes and one slab test of a ray against them, shared by single-ray
//! ([`crate::accel::single`]), packet ([`crate::accel::packet`]) and
//! stream ([`crate::accel::stream`]) traversal, so the three can never
//! disagree about which boxes a ray enters.

use glam::{BVec4A, Vec3A, Vec4};
use obvhs::cwbvh::node::CwBvhNode;

use crate::core::math::Ray;

/// Rounding margin of the node test, in units of `f32::EPSILON` times the
/// larger coordinate magnitude of the ray origin and the node.
///
/// The watertight triangle test accepts a ray when its *rounded* sheared
/// coordinates put it inside the triangle. Those coordinates are
/// differences `vertex - origin` followed by a shear, which carry about
/// 2 EPS (|vertex| + |origin|) of absolute error, so an accepted ray may
/// pass outside the exact triangle, and outside its exact box, by that
/// much. This matters at shared edges and vertices: the consistent edge
/// functions give the ray to exactly one of the neighbours, and if that
/// neighbour's box were culled the ray would pass through the mesh. Boxes
/// are therefore grown by 16 EPS (|origin| + |node|) per axis, which also
/// covers the rounding of the slab computation itself and of the
/// quantised child boxes. (obvhs's own node test pads nothing, ignores
/// `tmin` and rejects every box closer than `t = 1e-4`, a scene-scale
/// epsilon; both made rays leak through closed meshes.)
pub const NODE_MARGIN_EPS: f32 = 16.0;

/// Relative widening of the slab distances: each carries one or two
/// roundings.
const WIDEN: f32 = 4.0 * f32::EPSILON;

/// A ray prepared for node tests: origin with its largest coordinate
/// magnitude, and reciprocal direction with the axes it does not move
/// along.
#[derive(Clone, Copy, Debug)]
pub struct NodeRay {
    /// Origin; `w` is its largest coordinate magnitude.
    origin: Vec4,
    /// Reciprocal direction (0 on axes whose reciprocal is not finite);
    /// the bits of `w` flag those axes.
    inv_dir: Vec4,
}

impl NodeRay {
    /// Prepares `ray`.
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        let mut parallel = 0u32;
        let mut inv = [0.0; 3];
        for (a, inv) in inv.iter_mut().enumerate() {
            let i = 1.0 / ray.direction[a];
            if i.is_finite() {
                *inv = i;
            } else {
                parallel |= 1 << a;
            }
        }
        Self {
            origin: ray.origin.extend(ray.origin.abs().max_element()),
            inv_dir: Vec4::new(inv[0], inv[1], inv[2], f32::from_bits(parallel)),
        }
    }
}

/// The eight child boxes of one CwBvh node as floats (quantised
/// coordinates, the node's origin and scale), four children per register.
#[derive(Clone, Copy, Debug)]
pub struct DecodedNode {
    q_lo: [[Vec4; 2]; 3],
    q_hi: [[Vec4; 2]; 3],
    p: Vec3A,
    extent: Vec3A,
    /// Largest coordinate magnitude of the node's box.
    mag: f32,
}

impl DecodedNode {
    /// Decodes `node`.
    #[inline(always)]
    pub fn new(node: &CwBvhNode) -> Self {
        let extent = node.compute_extent();
        let p = Vec3A::from(node.p);
        let quads = |q: &[u8; 8]| {
            [
                Vec4::new(q[0] as f32, q[1] as f32, q[2] as f32, q[3] as f32),
                Vec4::new(q[4] as f32, q[5] as f32, q[6] as f32, q[7] as f32),
            ]
        };
        Self {
            q_lo: [
                quads(&node.child_min_x),
                quads(&node.child_min_y),
                quads(&node.child_min_z),
            ],
            q_hi: [
                quads(&node.child_max_x),
                quads(&node.child_max_y),
                quads(&node.child_max_z),
            ],
            p,
            extent,
            mag: p.abs().max((p + extent * 255.0).abs()).max_element(),
        }
    }

    /// Twice the centre of child `c`'s box (a sort key for visiting
    /// children along a direction).
    #[inline(always)]
    pub fn child_centre2(&self, c: usize) -> Vec3A {
        let (k, i) = (c / 4, c % 4);
        let axis = |a: usize| {
            let lo = self.q_lo[a][k][i] * self.extent[a] + self.p[a];
            let hi = self.q_hi[a][k][i] * self.extent[a] + self.p[a];
            lo + hi
        };
        Vec3A::new(axis(0), axis(1), axis(2))
    }

    /// Conservative slab test of `ray`'s interval `(t_min, t_max)` against
    /// the eight children, four per register: lane `c % 4` of mask
    /// `c / 4` is set when the interval overlaps child `c`'s box grown by the margin of [`NODE_MARGIN_EPS`]
    /// (empty children's bits are meaningless: mask them with
    /// [`present_children`]). The second value holds, per child, the
    /// (widened) distance at which the ray enters it.
    ///
    /// Plane distances are one multiply-add from the quantised
    /// coordinates; the reassociation's rounding (a few ulps of
    /// |origin - node| / |direction|) is far inside the margin.
    #[inline(always)]
    pub fn test_lanes(&self, ray: &NodeRay, t_min: f32, t_max: f32) -> ([BVec4A; 2], [Vec4; 2]) {
        let margin = NODE_MARGIN_EPS * f32::EPSILON * (ray.origin.w + self.mag);
        let parallel = ray.inv_dir.w.to_bits();
        let mut enter = [Vec4::splat(t_min); 2];
        let mut exit = [Vec4::splat(t_max); 2];
        for a in 0..3 {
            let (p, o) = (self.p[a], ray.origin[a]);
            if parallel & (1 << a) != 0 {
                // The ray does not move along this axis: inside the slab or not.
                let e = Vec4::splat(self.extent[a]);
                let ov = Vec4::splat(o);
                let (base_lo, base_hi) = (Vec4::splat(p - margin), Vec4::splat(p + margin));
                for k in 0..2 {
                    let inside = (self.q_lo[a][k] * e + base_lo).cmple(ov)
                        & ov.cmple(self.q_hi[a][k] * e + base_hi);
                    enter[k] = Vec4::select(inside, enter[k], Vec4::INFINITY);
                    exit[k] = Vec4::select(inside, exit[k], Vec4::NEG_INFINITY);
                }
            } else {
                let inv = ray.inv_dir[a];
                let scale = Vec4::splat(self.extent[a] * inv);
                let off_lo = Vec4::splat((p - margin - o) * inv);
                let off_hi = Vec4::splat((p + margin - o) * inv);
                for k in 0..2 {
                    let t_lo = self.q_lo[a][k] * scale + off_lo;
                    let t_hi = self.q_hi[a][k] * scale + off_hi;
                    let (near, far) = if inv >= 0.0 {
                        (t_lo, t_hi)
                    } else {
                        (t_hi, t_lo)
                    };
                    enter[k] = enter[k].max(near);
                    exit[k] = exit[k].min(far);
                }
            }
        }
        let mut hit = [BVec4A::FALSE; 2];
        for k in 0..2 {
            enter[k] -= enter[k].abs() * WIDEN;
            let x = exit[k] + exit[k].abs() * WIDEN;
            hit[k] = enter[k].cmple(x);
        }
        (hit, enter)
    }

    /// [`Self::test_lanes`] as a bit mask: bit `c` set when the ray enters
    /// child `c` (see there), with the entry distances.
    #[inline(always)]
    pub fn test(&self, ray: &NodeRay, t_min: f32, t_max: f32) -> (u32, [Vec4; 2]) {
        let (hit, enter) = self.test_lanes(ray, t_min, t_max);
        (hit[0].bitmask() | hit[1].bitmask() << 4, enter)
    }
}

/// The children of `node` that exist, as a bit mask.
#[inline(always)]
pub fn present_children(node: &CwBvhNode) -> u32 {
    let mut present = 0u32;
    for c in 0..8 {
        if !node.is_child_empty(c) {
            present |= 1 << c;
        }
    }
    present
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The decoded test against a plain f64 slab test on boxes built by
    /// obvhs: every box the exact test enters is entered (conservative),
    /// and boxes far from the ray are not.
    #[test]
    fn node_test_is_conservative_and_tight() {
        use crate::accel::build::{BuildQuality, build_bvh};
        use obvhs::aabb::Aabb;
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
        let bvh = build_bvh(&boxes, BuildQuality::Medium);
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
            let nr = NodeRay::new(&ray);
            for node in &bvh.nodes {
                let dn = DecodedNode::new(node);
                let (mask, _) = dn.test(&nr, 0.0, f32::INFINITY);
                let mask = mask & present_children(node);
                for c in 0..8 {
                    if node.is_child_empty(c) {
                        continue;
                    }
                    let b = node.child_aabb(c);
                    // f64 slab test on the decoded box.
                    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                    for a in 0..3 {
                        let (lo, hi) = (b.min[a] as f64, b.max[a] as f64);
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
}
