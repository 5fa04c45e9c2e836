//! Stream traversal of a [`Bvh8`]: a whole set of rays (the wavefront's
//! rays that reach one mesh) descends the tree together.
//!
//! Each node is read once per visit and tested against every ray of
//! the stream that reached it; the rays that enter each child are written
//! to that child's own list, so a child is visited once for all of its
//! rays instead of once per ray. The box test per ray is the same
//! conservative test as single-ray traversal ([`crate::accel::node`]),
//! leaf primitives are tested by the caller's kernel, so a stream finds
//! the same closest hits as tracing its rays one at a time (up to which of
//! two primitives at exactly the same distance is reported). Children are
//! visited in one order for the whole stream, nearest first along the
//! rays' summed direction; [`crate::scene::RenderScene::intersect_stream`]
//! groups rays by direction octant so that this order is near to far for
//! each ray too (measured: see the README's measurement notes).
//!
//! Against one-ray traversal, which tests each node's eight children in
//! SIMD registers as well, a stream saves the per-ray traversal bookkeeping
//! and visits fewer nodes per ray (leaves first); it gains most on
//! coherent rays.
//!
//! This module knows nothing of ECS scheduling; it is a kernel like
//! [`crate::accel::packet`].

use glam::Vec3A;

use crate::accel::bvh8::{Bvh8, EMPTY, LEAF, Node8, WIDTH, leaf_index};
use crate::accel::node::NodeRay;
use crate::core::math::Ray;

/// A stream of rays (per ray: origin, reciprocal direction and search
/// interval), with the buffers its traversal needs; reused between streams
/// so nothing is allocated per ray once it has grown.
#[derive(Clone, Debug, Default)]
pub struct Stream {
    /// Per ray: the ray prepared for the node test of the tree being
    /// traversed.
    node_rays: Vec<NodeRay>,
    /// Sum of the ray directions (child visiting order).
    direction_sum: Vec3A,
    /// The rays, for primitive tests.
    pub rays: Vec<Ray>,
    /// Interval starts.
    pub t_min: Vec<f32>,
    /// Interval ends; closest-hit traversal shrinks them as hits are found.
    pub t_max: Vec<f32>,
    /// Ray lists of pending nodes, stacked.
    ids: Vec<u32>,
    /// Pending nodes: (node index, start in `ids`, length).
    stack: Vec<(u32, u32, u32)>,
    /// Child hit masks of the rays of the node being visited.
    masks: Vec<u8>,
}

impl Stream {
    /// Empties the stream (keeping its buffers).
    pub fn clear(&mut self) {
        self.node_rays.clear();
        self.rays.clear();
        self.t_min.clear();
        self.t_max.clear();
        self.direction_sum = Vec3A::ZERO;
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.node_rays.capacity() * size_of::<NodeRay>()
            + self.rays.capacity() * size_of::<Ray>()
            + (self.t_min.capacity() + self.t_max.capacity()) * size_of::<f32>()
            + (self.ids.capacity() + 3 * self.stack.capacity()) * size_of::<u32>()
            + self.masks.capacity()
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.rays.len()
    }

    /// True when the stream holds no ray.
    pub fn is_empty(&self) -> bool {
        self.rays.is_empty()
    }

    /// Adds `ray`, searched in `(t_min, t_max)`.
    pub fn push(&mut self, ray: Ray, t_min: f32, t_max: f32) {
        self.direction_sum += ray.direction;
        self.rays.push(ray);
        self.t_min.push(t_min);
        self.t_max.push(t_max);
    }
}

/// Traverses `bvh` with every ray of `stream` (closest-hit order per
/// stream, see the module documentation).
///
/// `leaf(leaf, ids, stream)` tests the primitives of leaf `leaf` (an
/// index into [`Bvh8::leaves`]) against the rays `ids` of the stream that
/// reach it, and shrinks their `t_max` on hits, which prunes the rest of
/// their traversal.
#[inline(always)]
pub fn traverse<const AVX: bool>(
    bvh: &Bvh8,
    stream: &mut Stream,
    mut leaf: impl FnMut(u32, &[u32], &mut Stream),
) {
    let n = stream.len();
    if bvh.nodes.is_empty() || n == 0 {
        return;
    }
    let mut node_rays = std::mem::take(&mut stream.node_rays);
    node_rays.clear();
    node_rays.extend(stream.rays.iter().map(|r| NodeRay::new(r, bvh)));
    let mut ids = std::mem::take(&mut stream.ids);
    let mut stack = std::mem::take(&mut stream.stack);
    let mut masks = std::mem::take(&mut stream.masks);
    ids.clear();
    ids.extend(0..n as u32);
    stack.clear();
    stack.push((0, 0, n as u32));
    let dir = stream.direction_sum;
    while let Some((index, start, len)) = stack.pop() {
        let (start, len) = (start as usize, len as usize);
        // Lists above this one belong to nodes already visited.
        ids.truncate(start + len);
        let node = &bvh.nodes[index as usize];
        masks.clear();
        masks.resize(len, 0);
        node_masks::<AVX>(
            node,
            &ids[start..start + len],
            &node_rays,
            &stream.t_min,
            &stream.t_max,
            &mut masks,
        );
        let mut counts = [0u32; WIDTH];
        for m in masks.iter() {
            let mut b = *m as u32;
            while b != 0 {
                counts[b.trailing_zeros() as usize] += 1;
                b &= b - 1;
            }
        }
        // Children nearest first along the stream's direction.
        let mut order = [0u8; WIDTH];
        let mut key = [0f32; WIDTH];
        let mut count = 0;
        for c in 0..WIDTH {
            if counts[c] == 0 || node.child[c] == EMPTY {
                continue;
            }
            let (lo, hi) = node.child_box(c);
            key[c] = (lo + hi).dot(dir);
            order[count] = c as u8;
            count += 1;
        }
        order[..count].sort_unstable_by(|&a, &b| key[a as usize].total_cmp(&key[b as usize]));
        let is_leaf = |c: u8| node.child[c as usize] & LEAF != 0;
        // Every child's ray list, in one pass.
        let base = ids.len();
        // Regions in stack order: inner children farthest first, so a
        // popped node's list is the last pending one; then the leaves.
        let mut offset = [0usize; WIDTH];
        let mut total = base;
        for &c in order[..count].iter().rev() {
            if !is_leaf(c) {
                offset[c as usize] = total;
                total += counts[c as usize] as usize;
            }
        }
        for &c in &order[..count] {
            if is_leaf(c) {
                offset[c as usize] = total;
                total += counts[c as usize] as usize;
            }
        }
        ids.resize(total, 0);
        for k in 0..len {
            let mut b = masks[k] as u32;
            let r = ids[start + k];
            while b != 0 {
                let c = b.trailing_zeros() as usize;
                b &= b - 1;
                ids[offset[c]] = r;
                offset[c] += 1;
            }
        }
        // Leaves first, nearest first: their hits shrink the intervals
        // before the inner children are visited.
        for &c in &order[..count] {
            if !is_leaf(c) {
                continue;
            }
            let c = c as usize;
            let list = offset[c] - counts[c] as usize..offset[c];
            leaf(leaf_index(node.child[c]), &ids[list], stream);
        }
        // Inner children, pushed farthest first so the nearest is popped
        // first.
        for &c in order[..count].iter().rev() {
            if is_leaf(c) {
                continue;
            }
            let c = c as usize;
            let from = offset[c] - counts[c] as usize;
            stack.push((node.child[c], from as u32, counts[c]));
        }
    }
    stream.node_rays = node_rays;
    stream.ids = ids;
    stream.stack = stack;
    stream.masks = masks;
}

/// `masks[k]`: the children of `node` that ray `ids[k]` enters. Out of
/// line, with its own AVX2 entry: inlined into the stream traversal the
/// node test loop measured 10-17 % slower (register pressure in the
/// larger function).
#[inline(never)]
fn node_masks<const AVX: bool>(
    node: &Node8,
    ids: &[u32],
    node_rays: &[NodeRay],
    t_min: &[f32],
    t_max: &[f32],
    masks: &mut [u8],
) {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        #[target_feature(enable = "avx2,fma")]
        fn fast(
            node: &Node8,
            ids: &[u32],
            node_rays: &[NodeRay],
            t_min: &[f32],
            t_max: &[f32],
            masks: &mut [u8],
        ) {
            node_masks_loop::<true>(node, ids, node_rays, t_min, t_max, masks)
        }
        // SAFETY: `AVX` is set only by the AVX2 entry points, which run
        // only on CPUs with AVX2 and FMA (`simd::use_avx2`).
        #[allow(unsafe_code)]
        return unsafe { fast(node, ids, node_rays, t_min, t_max, masks) };
    }
    node_masks_loop::<false>(node, ids, node_rays, t_min, t_max, masks)
}

/// The loop of [`node_masks`], a plain loop so that the node test is
/// inlined into its code path (see [`crate::core::simd`]).
#[inline(always)]
fn node_masks_loop<const AVX: bool>(
    node: &Node8,
    ids: &[u32],
    node_rays: &[NodeRay],
    t_min: &[f32],
    t_max: &[f32],
    masks: &mut [u8],
) {
    for k in 0..ids.len() {
        let r = ids[k] as usize;
        let (hits, _) = node_rays[r].test::<AVX>(node, t_min[r], t_max[r]);
        masks[k] = hits as u8;
    }
}
