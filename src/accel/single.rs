//! Single-ray traversal of obvhs's CWBVH with Prism's node test, in
//! obvhs's ordered (octant-sorted) visiting order.

use glam::UVec2;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::node::{CwBvhNode, extract_byte64};
use obvhs::faststack::{FastStack, StackStack};

use crate::accel::node::{DecodedNode, NodeRay};
use crate::core::math::Ray;

/// Pending node groups of one traversal: obvhs's fixed stack, spilling to
/// the heap past its capacity. obvhs's own stack overwrites its last entry
/// when full (its depth check runs in debug builds only), which would
/// silently lose subtrees of a tree deeper than 32 levels; such trees
/// come from degenerate input (see the deep-tree test in `geometry::mesh`). A `Vec` allocates
/// nothing until it is pushed to, so shallow trees pay one comparison.
#[derive(Default)]
struct SpillStack {
    fixed: StackStack<UVec2, 32>,
    heap: Vec<UVec2>,
}

/// Entries `StackStack<_, 32>` holds before it starts overwriting.
const FIXED_CAPACITY: usize = 31;

impl FastStack<UVec2> for SpillStack {
    #[inline(always)]
    fn push(&mut self, v: UVec2) {
        // The heap holds entries only while the fixed part is full.
        if self.fixed.len() < FIXED_CAPACITY {
            self.fixed.push(v);
        } else {
            self.heap.push(v);
        }
    }
    #[inline(always)]
    fn pop_fast(&mut self) -> UVec2 {
        if self.heap.is_empty() {
            self.fixed.pop_fast()
        } else {
            self.heap.pop().unwrap_or_default()
        }
    }
    #[inline(always)]
    fn pop(&mut self) -> Option<UVec2> {
        self.heap.pop().or_else(|| self.fixed.pop())
    }
    #[inline(always)]
    fn len(&self) -> usize {
        self.fixed.len() + self.heap.len()
    }
    #[inline(always)]
    fn is_empty(&self) -> bool {
        self.heap.is_empty() && self.fixed.is_empty()
    }
    #[inline(always)]
    fn clear(&mut self) {
        self.fixed.clear();
        self.heap.clear();
    }
}

/// The state `obvhs::traverse!` reads and writes, with a stack of any
/// depth.
struct Walk {
    stack: SpillStack,
    current_group: UVec2,
    primitive_group: UVec2,
    oct_inv4: u32,
    primitive_id: u32,
    hitmask: u32,
}

/// Conservative test of the eight children of `node`; returns the hit
/// mask in obvhs's encoding.
///
/// The eight children are tested as two groups of four in SIMD registers
/// (`glam::Vec4`) rather than one child at a time (measured: see the
/// README's measurement notes).
#[inline(always)]
fn intersect_node(node: &CwBvhNode, ray: &NodeRay, t_min: f32, t_max: f32, oct_inv4: u32) -> u32 {
    let (mut hits, _) = DecodedNode::new(node).test(ray, t_min, t_max);
    if hits == 0 {
        return 0;
    }
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut hit_mask = 0;
    while hits != 0 {
        let c = hits.trailing_zeros() as usize;
        hits &= hits - 1;
        hit_mask |= extract_byte64(child_bits8, c) << extract_byte64(bit_index8, c);
    }
    hit_mask
}

/// Traverses `bvh` with a conservative node test (see [`crate::accel::node::NODE_MARGIN_EPS`]).
///
/// `visit(slot, t_max)` tests the primitive in leaf slot `slot` (an index
/// into `bvh.primitive_indices`) and returns the `t` of a hit inside
/// `(t_min, t_max)`, which then shrinks `t_max`. With `stop_at_first` the
/// traversal ends at the first hit (shadow rays). Returns whether any
/// primitive was hit.
///
/// Used for every mesh; the top-level BVH can use it the same way.
pub fn traverse_bvh(
    bvh: &CwBvh,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    stop_at_first: bool,
    mut visit: impl FnMut(usize, f32) -> Option<f32>,
) -> bool {
    let node_ray = NodeRay::new(ray);
    let mut t_max = t_max;
    let mut any = false;
    let start = bvh.new_traversal(ray.direction);
    let mut state = Walk {
        // obvhs's empty fixed stack, with a heap part behind it.
        stack: SpillStack {
            fixed: start.stack,
            heap: Vec::new(),
        },
        current_group: start.current_group,
        primitive_group: start.primitive_group,
        oct_inv4: start.oct_inv4,
        primitive_id: 0,
        hitmask: 0,
    };
    let mut node;
    'traversal: {
        obvhs::traverse!(
            bvh,
            node,
            state,
            intersect_node(node, &node_ray, t_min, t_max, state.oct_inv4),
            {
                if let Some(t) = visit(state.primitive_id as usize, t_max) {
                    any = true;
                    if stop_at_first {
                        break 'traversal;
                    }
                    t_max = t_max.min(t);
                }
            }
        );
    }
    any
}

#[cfg(test)]
mod tests {
    use super::*;

    /// obvhs's fixed stack overwrites its last entry past 31; the spill
    /// stack must give back every entry, last in first out.
    #[test]
    fn spill_stack_keeps_every_entry() {
        let mut s = SpillStack::default();
        for i in 0..100 {
            s.push(UVec2::new(i, 0));
        }
        assert_eq!(s.len(), 100);
        for i in (0..100).rev() {
            assert_eq!(s.pop_fast(), UVec2::new(i, 0));
        }
        assert!(s.is_empty());
    }
}
