//! Single-ray traversal of a [`Bvh8`]: nearest child first, with entry
//! distances on the stack so that subtrees made stale by a closer hit are
//! dropped without being tested.

use std::mem::MaybeUninit;

use crate::accel::bvh8::{Bvh8, LEAF};
use crate::accel::node::NodeRay;
use crate::core::math::Ray;

/// Entries held without allocating; deeper traversals spill to the heap.
const FIXED: usize = 32;

/// Pending subtrees: `entry distance bits << 32 | child reference`.
///
/// At most seven entries per level are pending, and nearest-first
/// traversal rarely holds more than a few; deeper stacks (large or
/// degenerate input, see the deep-tree test in `geometry::mesh`) spill to
/// a `Vec`, which allocates only when first pushed to. The fixed part is
/// left uninitialised: zeroing its 256 bytes cost about 80 instructions
/// per traversal, a tenth of all the instructions of a frame of the
/// frame-loop benchmark (callgrind), and only written entries are read.
pub(crate) struct Stack {
    fixed: [MaybeUninit<u64>; FIXED],
    len: usize,
    spill: Vec<u64>,
}

impl Stack {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            fixed: [const { MaybeUninit::uninit() }; FIXED],
            len: 0,
            spill: Vec::new(),
        }
    }

    /// The fixed part changes only while the spill is empty, so entries
    /// come back last in, first out.
    #[inline(always)]
    pub(crate) fn push(&mut self, v: u64) {
        if self.len < FIXED {
            self.fixed[self.len].write(v);
            self.len += 1;
        } else {
            self.push_spill(v);
        }
    }

    #[cold]
    #[inline(never)]
    fn push_spill(&mut self, v: u64) {
        self.spill.push(v);
    }

    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<u64> {
        if !self.spill.is_empty() {
            return self.spill.pop();
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: entries below `len` were written by `push` (`len` only
        // grows there, one written entry at a time).
        #[allow(unsafe_code)]
        Some(unsafe { self.fixed[self.len].assume_init() })
    }
}

/// A stack entry.
#[inline(always)]
pub(crate) fn entry(t: f32, child: u32) -> u64 {
    ((t.to_bits() as u64) << 32) | child as u64
}

/// The entry distance and child of a stack entry.
#[inline(always)]
pub(crate) fn unpack(e: u64) -> (f32, u32) {
    (f32::from_bits((e >> 32) as u32), e as u32)
}

/// Traverses `bvh` from node `start` with `ray` (prepared for `bvh`),
/// searching `(t_min, t_max)`.
///
/// `visit(leaf, t_max)` tests the primitives of leaf `leaf` (an index
/// into [`Bvh8::leaves`]) and returns the `t` of the nearest hit inside
/// `(t_min, t_max)`, which then shrinks `t_max`. With `any_hit` the
/// traversal ends at the first hit (shadow rays). Returns whether any
/// primitive was hit.
///
/// At each node the entered children are sorted by entry distance; the
/// nearest is visited next and the others are stacked with their
/// distances, so a popped entry farther than the closest hit found since
/// is dropped.
#[inline(always)]
pub fn traverse_from<const AVX: bool>(
    bvh: &Bvh8,
    start: u32,
    ray: &NodeRay,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    visit: impl FnMut(u32, f32) -> Option<f32>,
) -> bool {
    traverse_from_with::<AVX, false>(bvh, start, ray, t_min, t_max, any_hit, visit, |_| {})
}

/// [`traverse_from`] with `prefetch_leaf(leaf)`, called for a leaf that
/// will be visited soon (it was entered beside a sibling), to start
/// loading what its visit reads. Nodes entered beside a sibling are
/// prefetched the same way. With `FUSED` the nodes are tested with
/// [`NodeRay::test_fused`]: only for queries whose hits do not depend on
/// the order in which leaves are visited.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn traverse_from_with<const AVX: bool, const FUSED: bool>(
    bvh: &Bvh8,
    start: u32,
    ray: &NodeRay,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    visit: impl FnMut(u32, f32) -> Option<f32>,
    prefetch_leaf: impl Fn(u32),
) -> bool {
    if FUSED && AVX && ray.fused {
        walk::<AVX, true>(bvh, start, ray, t_min, t_max, any_hit, visit, prefetch_leaf)
    } else {
        walk::<AVX, false>(bvh, start, ray, t_min, t_max, any_hit, visit, prefetch_leaf)
    }
}

/// [`traverse_from_with`]'s loop; with `FMA`, every node is tested in the
/// fused form ([`NodeRay::test_fma_known`]: the ray allows it).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn walk<const AVX: bool, const FMA: bool>(
    bvh: &Bvh8,
    start: u32,
    ray: &NodeRay,
    t_min: f32,
    mut t_max: f32,
    any_hit: bool,
    mut visit: impl FnMut(u32, f32) -> Option<f32>,
    prefetch_leaf: impl Fn(u32),
) -> bool {
    let prefetch = |r: u32| {
        if r & LEAF == 0 {
            prefetch_bytes(
                &bvh.nodes[r as usize],
                std::mem::size_of::<crate::accel::bvh8::Node8>(),
            );
        } else {
            prefetch_leaf(r & !LEAF);
        }
    };
    if bvh.nodes.is_empty() {
        return false;
    }
    let mut stack = Stack::new();
    let mut any = false;
    let mut cur = start;
    loop {
        if cur & LEAF == 0 {
            let node = &bvh.nodes[cur as usize];
            let (mask, enter) = if FMA {
                ray.test_fma_known::<AVX>(node, t_min, t_max)
            } else {
                ray.test::<AVX>(node, t_min, t_max)
            };
            if mask != 0 {
                let first = mask.trailing_zeros() as usize;
                let rest = mask & (mask - 1);
                if rest == 0 {
                    cur = node.child[first];
                    continue;
                }
                let second = rest.trailing_zeros() as usize;
                if rest & (rest - 1) == 0 {
                    // Two children: the farther one waits.
                    let (a, b) = (
                        (enter[first], node.child[first]),
                        (enter[second], node.child[second]),
                    );
                    let (near, far) = if b.0 < a.0 { (b, a) } else { (a, b) };
                    if PREFETCH {
                        prefetch(far.1);
                        prefetch(near.1);
                    }
                    stack.push(entry(far.0, far.1));
                    cur = near.1;
                    continue;
                }
                // Three or more: sort far to near (insertion sort of at
                // most eight), stack all but the nearest.
                let mut buf = [(0.0f32, 0u32); 8];
                let mut n = 0;
                let mut m = mask;
                while m != 0 {
                    let c = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let item = (enter[c], node.child[c]);
                    if PREFETCH {
                        prefetch(item.1);
                    }
                    let mut j = n;
                    while j > 0 && buf[j - 1].0 < item.0 {
                        buf[j] = buf[j - 1];
                        j -= 1;
                    }
                    buf[j] = item;
                    n += 1;
                }
                for &(t, c) in &buf[..n - 1] {
                    stack.push(entry(t, c));
                }
                cur = buf[n - 1].1;
                continue;
            }
        } else if let Some(t) = visit(cur & !LEAF, t_max) {
            any = true;
            if any_hit {
                return true;
            }
            t_max = t_max.min(t);
        }
        // Next pending subtree that a hit has not made stale.
        loop {
            let Some(e) = stack.pop() else {
                return any;
            };
            let (t, c) = unpack(e);
            if t <= t_max {
                cur = c;
                break;
            }
        }
    }
}

/// Writes into `order` the indices of `rays` grouped by direction octant
/// (the signs of the direction's components, `-0.0` counted negative),
/// keeping their order inside each octant: a counting sort in two passes.
///
/// Tracing incoherent rays one at a time in this order instead of as
/// given keeps the traversal's branches (which child is nearer, which
/// slab plane is entered first) the same from one ray to the next while
/// neighbouring rays still start close together; hits do not change, only
/// the order in which rays are traced. Measured in `prism bench rays`
/// (mode `binned`, see the README).
pub fn octant_order(rays: &[Ray], order: &mut Vec<u32>) {
    let octant = |r: &Ray| {
        let d = r.direction;
        (d.x.is_sign_negative() as usize)
            | ((d.y.is_sign_negative() as usize) << 1)
            | ((d.z.is_sign_negative() as usize) << 2)
    };
    let mut start = [0u32; 9];
    for r in rays {
        start[octant(r) + 1] += 1;
    }
    for o in 1..9 {
        start[o] += start[o - 1];
    }
    order.clear();
    order.resize(rays.len(), 0);
    for (i, r) in rays.iter().enumerate() {
        let o = octant(r);
        order[start[o] as usize] = i as u32;
        start[o] += 1;
    }
}

/// Whether traversal prefetches the children it enters beside a sibling
/// (the farther ones wait on the stack, so their loads overlap the work on
/// the nearer ones). Measured on the anchors' 100k mesh, one thread, rays
/// per CPU second: bounce rays +15% (single) and +11% (packets of 8),
/// camera rays unchanged.
const PREFETCH: bool = true;

/// Starts loading the `bytes` bytes at `p` into the cache (nothing on
/// targets without a prefetch instruction).
#[inline(always)]
pub fn prefetch_bytes<T>(p: &T, bytes: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = (p as *const T).cast::<i8>();
        let mut off = 0;
        while off < bytes {
            // SAFETY: a prefetch never faults nor changes memory; SSE is
            // part of the x86-64 baseline.
            #[allow(unsafe_code)]
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(off));
            }
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (p, bytes);
}

/// [`traverse_from`] from the root, preparing `ray` for `bvh`.
#[inline(always)]
pub fn traverse<const AVX: bool>(
    bvh: &Bvh8,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    visit: impl FnMut(u32, f32) -> Option<f32>,
) -> bool {
    let node_ray = NodeRay::new(ray, bvh);
    traverse_from::<AVX>(bvh, 0, &node_ray, t_min, t_max, any_hit, visit)
}

/// [`traverse`] with [`traverse_from_with`]'s leaf prefetch, and nodes
/// tested with [`NodeRay::test_fused`]: for mesh BVHs, whose closest hit
/// does not depend on the order of the leaves (equal `t` goes to the
/// lowest triangle index) and whose any-hit answer does not either.
#[inline(always)]
pub fn traverse_with<const AVX: bool>(
    bvh: &Bvh8,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    visit: impl FnMut(u32, f32) -> Option<f32>,
    prefetch_leaf: impl Fn(u32),
) -> bool {
    let node_ray = NodeRay::new(ray, bvh);
    traverse_from_with::<AVX, true>(
        bvh,
        0,
        &node_ray,
        t_min,
        t_max,
        any_hit,
        visit,
        prefetch_leaf,
    )
}

/// [`traverse`] with a visitor per primitive: `visit(slot, t_max)` tests
/// the primitive at `bvh.prims[slot]` (leaves' primitives in order).
#[inline(always)]
pub fn traverse_bvh<const AVX: bool>(
    bvh: &Bvh8,
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    mut visit: impl FnMut(usize, f32) -> Option<f32>,
) -> bool {
    traverse::<AVX>(
        bvh,
        ray,
        t_min,
        t_max,
        any_hit,
        #[inline(always)]
        |leaf, mut t_max| {
            let l = bvh.leaves[leaf as usize];
            let mut best = None;
            for slot in l.first..l.first + l.count {
                if let Some(t) = visit(slot as usize, t_max) {
                    if any_hit {
                        return Some(t);
                    }
                    t_max = t_max.min(t);
                    best = Some(t_max);
                }
            }
            best
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    /// The octant order is a stable sort of the rays by the signs of
    /// their direction components (checked against the standard library's
    /// stable sort), `-0.0` counted as negative.
    #[test]
    fn octant_order_is_a_stable_sort_by_direction_signs() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let comp = |v: u64| match v % 5 {
            0 => 0.0,
            1 => -0.0,
            2 => 1.5,
            3 => -2.0,
            _ => f32::MIN_POSITIVE,
        };
        let rays: Vec<Ray> = (0..1000)
            .map(|_| {
                let d = Vec3A::new(comp(next()), comp(next()), comp(next()));
                Ray::new(Vec3A::ZERO, d)
            })
            .collect();
        let key = |r: &Ray| {
            let d = r.direction;
            (d.x.to_bits() >> 31) | ((d.y.to_bits() >> 31) << 1) | ((d.z.to_bits() >> 31) << 2)
        };
        let mut expect: Vec<u32> = (0..rays.len() as u32).collect();
        expect.sort_by_key(|&i| key(&rays[i as usize]));
        let mut order = vec![7; 3];
        octant_order(&rays, &mut order);
        assert_eq!(order, expect);
        octant_order(&[], &mut order);
        assert!(order.is_empty());
    }

    /// The stack gives back every entry, last in first out, past its
    /// fixed part.
    #[test]
    fn stack_keeps_every_entry() {
        let mut s = Stack::new();
        for i in 0..200u32 {
            s.push(entry(i as f32, i));
        }
        for i in (0..200u32).rev() {
            assert_eq!(unpack(s.pop().unwrap()), (i as f32, i));
        }
        assert!(s.pop().is_none());
        // Interleaved pushes and pops across the boundary.
        for i in 0..70u32 {
            s.push(entry(0.0, i));
        }
        assert_eq!(unpack(s.pop().unwrap()).1, 69);
        s.push(entry(0.0, 1000));
        assert_eq!(unpack(s.pop().unwrap()).1, 1000);
        for i in (0..69u32).rev() {
            assert_eq!(unpack(s.pop().unwrap()).1, i);
        }
    }
}
